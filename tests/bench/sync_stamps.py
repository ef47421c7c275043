"""The two-step SYNC measured (docs/TIME.md, "The two-step SYNC"): what the
one-step host_ns misses, and what that does to boards of different SYNC
frames. vmacd at clock_sync_ms 1 (1 ms slots, bus_trust open) with an
unkeyed board (the plain SYNC) and a keyed one (its sealed chunk), each a
vmac-board whose counter is CLOCK_MONOTONIC itself, on raw Ethernet over a
veth pair (root; else that part is skipped) and on UDP loopback. Per
round, for the two-step (the default) and the one-step
(VMAC_SYNC_ONE_STEP=1, the host asks no stamps), alternating:

  - each stream's prev_tx_ns less its previous frame's host_ns, p50 / p99 /
    max, from the frames on the wire (two-step rounds only): the kernel's
    transmit time after the host's stamp;
  - each board's clock offset once locked and after --seconds (its counter
    less its idea of host time: the path and whatever its host time
    missed), and the keyed board's less the unkeyed one's: the bias
    between boards of the sealed frame and of the plain one.

  python3 tests/bench/sync_stamps.py --bin build/bin [--seconds 5] [--rounds 3]

Standalone (not in make bench): it needs root for the veth pair."""

import argparse
import os
import re
import shutil
import signal
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
from harness import Context, Skip  # noqa: E402
from sync_wire import Capture, lateness, percentile, streams  # noqa: E402

SETTINGS = {"clock_sync_ms": 1, "slice_us": 200, "slices_per_slot": 5, "bus_trust": "open"}
OFFSET = re.compile(r"^(\S+): clock (\w+), offset ([-+][0-9.]+) s")


def offset_at_exit(board, name):
    board.signal(signal.SIGTERM)
    board.wait_exit(30)
    lines = [OFFSET.match(line.text) for line in board.find_lines(r"^%s: clock \w+, offset " % name)]
    lines = [m for m in lines if m]
    return float(lines[-1].group(3)) * 1e9 if lines else None


def one_run(ctx, transport, one_step, seconds):
    """{"offsets": {name: ns}, "bias_ns": sealed - plain, "streams": {key: [p50, p99, max, named %]}}."""
    wrapper, host_bus, board_bus = (), ctx.bus, ctx.bus
    if transport == "eth":
        host_if, ns, board_if = ctx.eth_link()
        wrapper, host_bus, board_bus = ("ip", "netns", "exec", ns), "eth:" + host_if, "eth:" + board_if
    if one_step:
        os.environ["VMAC_SYNC_ONE_STEP"] = "1"
    else:
        os.environ.pop("VMAC_SYNC_ONE_STEP", None)
    try:
        host = ctx.host(bus=host_bus, settings=SETTINGS)
    finally:
        os.environ.pop("VMAC_SYNC_ONE_STEP", None)
    plain = ctx.board("lights", "plain-1", keyed=False, bus=board_bus, wrapper=wrapper)
    sealed = ctx.board("lights", "sealed-1", bus=board_bus, wrapper=wrapper)
    host.wait_running(["plain-1", "sealed-1"])
    for name, board in (("plain-1", plain), ("sealed-1", sealed)):
        board.wait_line(r"^%s: clock locked" % name, 30, what="%s locked" % name)
    heard = Capture(host_bus)
    time.sleep(seconds)
    heard.close()
    out = {"offsets": {}, "streams": {}}
    for name, board in (("plain-1", plain), ("sealed-1", sealed)):
        out["offsets"][name] = offset_at_exit(board, name)
    if None not in out["offsets"].values():
        out["bias_ns"] = out["offsets"]["sealed-1"] - out["offsets"]["plain-1"]
    for key, frames_of in streams(heard.got).items():
        named, followers, deltas = lateness(frames_of)
        if deltas:
            out["streams"]["plain" if key == "plain" else "sealed"] = [
                percentile(deltas, 50), percentile(deltas, 99), max(deltas), 100.0 * named / max(1, followers)]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", required=True)
    ap.add_argument("--seconds", type=float, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    for transport in ("eth", "udp"):
        print("%s:" % transport, flush=True)
        for rnd in range(args.rounds):
            for one_step in (False, True):
                logdir = tempfile.mkdtemp(prefix="vmac-bench-stamps-")
                ctx = Context(args.bin, logdir)
                try:
                    r = one_run(ctx, transport, one_step, args.seconds)
                except Skip as e:
                    print("  SKIPPED: %s" % e, flush=True)
                    break
                finally:
                    ctx.cleanup()
                shutil.rmtree(logdir, ignore_errors=True)
                mode = "one-step" if one_step else "two-step"
                lat = "; ".join("%s prev_tx - host_ns p50 %.1f p99 %.1f max %.1f us (%.0f %% named)" % (
                    k, v[0] / 1e3, v[1] / 1e3, v[2] / 1e3, v[3]) for k, v in sorted(r["streams"].items()))
                print("  round %d %-8s offsets plain %s sealed %s us, sealed - plain %s us%s" % (
                    rnd + 1, mode, fmt(r["offsets"]["plain-1"]), fmt(r["offsets"]["sealed-1"]),
                    fmt(r.get("bias_ns")), "; " + lat if lat else ""), flush=True)
            else:
                continue
            break


def fmt(ns):
    return "?" if ns is None else "%+.1f" % (ns / 1e3)


if __name__ == "__main__":
    main()
