#!/usr/bin/env python3
"""Where every miss comes from (issue 17, item 5).

Runs vmacd with N mock boards at a period for a while, every miss dropping
its device (zero tolerance: each miss is one `dropped` event), and lines up
each miss with the board's own account of that request. Both programs use
CLOCK_MONOTONIC on this machine:

  host   the drop event: "... seq S ... (sent at T0 ns[, received at T3 ns])"
  board  vmac-board's late-reply line for seq S: "request in at T1 ns, reply
         out at T2 ns" (printed when T2 - T1 > --late-us)

and attributes the miss to

  host       the host's own fault (misses_host: a request the kernel refused)
  board      the board process answered late by its own clock (T2 - T1 took
             most of the window: this machine did not run it in time)
  to-board   the request reached the board late (T1 - T0: kernel and wire)
  to-host    the reply came back late (T3 - T2)
  unknown    the board answered in time by its own clock (no late line) and
             nothing else is known (the reply was lost, or arrived after the
             host had judged it)

usage: miss_trace.py --bin build/bin [--boards 10] [--period-us 1000]
                     [--seconds 30] [--bus udp|eth] [--cyclic true|false]
"""

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import urllib.request

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
from harness import Context, Skip  # noqa: E402
from bench import board_wrapper  # noqa: E402

HOST_RE = re.compile(r"seq (\d+) .*?sent at (\d+) ns(?:, received at (\d+) ns)?")
BOARD_RE = re.compile(r"^(\S+): late reply seq (\d+): request in at (\d+) ns, reply out at (\d+) ns")

PROBE_LUA = """local driver = { name = "benchprobe", version = "1", io = { switch = "di0", lamp = "do0" } }
function driver.tick(dev, inputs) dev.out.lamp = inputs.switch end
return driver
"""


def events(host, token):
    out, after = [], 0
    while True:
        req = urllib.request.Request("http://%s/api/events/log?after=%d&limit=1000" % (host.http, after),
                                     headers={"Authorization": "Bearer " + token})
        with urllib.request.urlopen(req, timeout=30) as r:
            page = json.load(r)["events"]
        if not page:
            return out
        out += page
        after = page[-1]["seq"]


def attribute(drops, board_lines, window_ns):
    """[(device, seq, cause, detail)] for every drop that was a miss."""
    late = {(m.group(1), int(m.group(2))): (int(m.group(3)), int(m.group(4))) for m in board_lines}
    rows = []
    for e in drops:
        m = HOST_RE.search(e["text"])
        if not m:
            continue  # dropped for another reason (an ERROR reply, a driver failure)
        seq, t0, t3 = int(m.group(1)), int(m.group(2)), m.group(3) and int(m.group(3))
        if "the host's fault" in e["text"]:
            rows.append((e["device"], seq, "host", "the kernel refused the request"))
            continue
        b = late.get((e["device"], seq))
        if not b:
            rows.append((e["device"], seq, "unknown", "no late-reply line from the board"))
            continue
        t1, t2 = b
        parts = {"to-board": t1 - t0, "board": t2 - t1}
        if t3:
            parts["to-host"] = t3 - t2
        cause = max(parts, key=parts.get)
        rows.append((e["device"], seq, cause, ", ".join("%s %.0f us" % (k, v / 1e3) for k, v in parts.items())))
    return rows


def main():
    ap = argparse.ArgumentParser(description="Attribute every miss of a run to host, board or wire.")
    ap.add_argument("--bin", default=os.path.join(os.path.dirname(__file__), "..", "..", "build", "bin"))
    ap.add_argument("--boards", type=int, default=10)
    ap.add_argument("--period-us", type=int, default=1000)
    ap.add_argument("--seconds", type=float, default=30)
    ap.add_argument("--bus", choices=["udp", "eth"], default="udp")
    ap.add_argument("--cyclic", choices=["true", "false"], default="true")
    ap.add_argument("--late-us", type=int, default=0, help="the boards' threshold (default: a quarter period)")
    args = ap.parse_args()

    logdir = tempfile.mkdtemp(prefix="vmac-misstrace-")
    ctx = Context(os.path.abspath(args.bin), logdir)
    try:
        # The boards at SCHED_FIFO one below the host's bus thread where
        # allowed, as bench.py runs them (board_wrapper).
        bus, board_bus, wrap = None, None, tuple(board_wrapper())
        if args.bus == "eth":
            host_if, ns, board_if = ctx.eth_link()
            bus, board_bus, wrap = "eth:" + host_if, "eth:" + board_if, ("ip", "netns", "exec", ns) + wrap
        period = args.period_us
        settings = {"slice_us": max(1, period // max(args.boards, 10)), "slices_per_slot": max(args.boards, 10),
                    "max_level": 1, "default_level": 0, "reply_deadline_us": period, "miss_limit": 1,
                    "watchdog_ms": max(500, 4 * period // 1000), "discovery_period_ms": 200,
                    "cyclic": args.cyclic, "realtime": "true"}
        host = ctx.host(drivers=ctx.drivers(benchprobe=PROBE_LUA), settings=settings, bus=bus)
        late_us = args.late_us or max(1, period // 4)
        board = ctx.board("generic", "b", count=args.boards, driver="benchprobe", bus=board_bus, wrapper=wrap,
                          extra=("--late-us", str(late_us)))
        names = ["b-%d" % i for i in range(1, args.boards + 1)]
        host.wait_running(names, timeout_s=120)
        first = host.last_event_seq()
        s0 = host.status()
        time.sleep(args.seconds)
        s1 = host.status()
        drops = [e for e in events(host, ctx.token) if e["seq"] > first and e["kind"] == "dropped"]
        lines = [m for m in (BOARD_RE.match(l.text) for l in board.find_lines(r"late reply")) if m]
        rows = attribute(drops, lines, period * 1000)
        served = sum(d["served"] for d in s1["devices"]) - sum(d["served"] for d in s0["devices"])
        misses = s1["counters"]["misses"] - s0["counters"]["misses"]
        host_misses = s1["counters"].get("misses_host", 0) - s0["counters"].get("misses_host", 0)
        causes = {}
        for r in rows:
            causes[r[2]] = causes.get(r[2], 0) + 1
        print("%d boards at %.0f Hz on %s (cyclic %s), %.0f s: %d served, %d misses (%d the host's own), "
              "tick lateness p99 %d us" % (args.boards, 1e6 / period, args.bus, args.cyclic, args.seconds, served,
                                           misses, host_misses, s1["tick"]["lateness_us"]["p99"]))
        print("attributed: " + (", ".join("%s %d" % kv for kv in sorted(causes.items())) or "no misses"))
        for r in rows[:20]:
            print("  %s seq %d: %s (%s)" % r)
        print(json.dumps({"served": served, "misses": misses, "misses_host": host_misses, "causes": causes}))
        return 0
    except Skip as e:
        print("SKIPPED: %s" % e)
        return 0
    finally:
        ctx.cleanup()


if __name__ == "__main__":
    sys.exit(main())
