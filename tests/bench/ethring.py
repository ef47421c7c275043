"""make bench, ethring: raw Ethernet's receive ring (PACKET_RX_RING, the
default) next to recvmmsg (VMAC_ETH_RECVMMSG=1, what vmacd falls back to)
on the same eth-cyclic bus: host CPU per device per tick, 100 boards at
1 kHz, alternating rounds, one run. Run through bench.py (--only ethring);
needs what eth-cyclic needs (root, network namespaces), else SKIPPED."""

import os
import statistics

from bench import with_ctx
from fieldbus import fieldbus_run
from harness import Skip

ROUNDS = 3
BOARDS = 100
PERIOD_US = 1000


def ethring(args):
    """{"rounds": [{"ring": r, "recvmmsg": r, "ratio": ring/recvmmsg}], "ratio_median": m} or {"skipped": why}."""
    rounds = []
    try:
        for rnd in range(ROUNDS):
            row = {}
            for mode in ("ring", "recvmmsg"):
                if mode == "recvmmsg":
                    os.environ["VMAC_ETH_RECVMMSG"] = "1"  # inherited by vmacd (and the boards)
                else:
                    os.environ.pop("VMAC_ETH_RECVMMSG", None)
                r = with_ctx(args, "ethring-%s-%d" % (mode, rnd),
                             lambda c: fieldbus_run(c, "eth-cyclic", BOARDS, PERIOD_US, args.seconds))
                row[mode] = {k: r[k] for k in ("cpu_us_per_device_tick", "misses", "misses_host", "drops")}
                print("    round %d %-8s %.3f us per device per tick, %d misses (%d the host's)" % (
                    rnd + 1, mode, r["cpu_us_per_device_tick"], r["misses"], r["misses_host"]), flush=True)
            row["ratio"] = row["ring"]["cpu_us_per_device_tick"] / max(1e-9, row["recvmmsg"]["cpu_us_per_device_tick"])
            rounds.append(row)
    except Skip as e:
        print("    ethring: SKIPPED: %s" % e, flush=True)
        return {"skipped": str(e)}
    finally:
        os.environ.pop("VMAC_ETH_RECVMMSG", None)
    return {"boards": BOARDS, "period_us": PERIOD_US, "rounds": rounds,
            "ratio_median": statistics.median(r["ratio"] for r in rounds)}


def report_ethring(e):
    if e.get("skipped"):
        print("ethring: SKIPPED: %s" % e["skipped"])
        return
    print("eth-cyclic receive, %d boards at %d Hz: ring / recvmmsg host CPU per device per tick, median of %d "
          "rounds %.2f (%s)" % (e["boards"], 1000000 // e["period_us"], len(e["rounds"]), e["ratio_median"],
                                ", ".join("%.2f" % r["ratio"] for r in e["rounds"])))
