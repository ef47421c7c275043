"""make bench, sync: ten boards' disciplined clocks (firmware/clock.c)
acting on one host instant, next to the same boards acting when the frame
arrives, in one simulated run (tests/bench/clock_sync.c, built beside
bare_loop; docs/TIME.md, "The numbers"). Run through bench.py (--only
sync); --seconds is the simulated time. The goal (issue #35): the timed
spread's p99 at most 10 us."""

import json
import os
import subprocess


def sync(args):
    """build/bench/clock_sync --json --seconds S, or {"error": why}."""
    exe = os.path.join(os.path.dirname(args.bare), "clock_sync")
    if not os.access(exe, os.X_OK):
        return {"error": "%s not built (make %s)" % (exe, exe)}
    p = subprocess.run([exe, "--json", "--seconds", str(args.seconds)], capture_output=True, text=True, timeout=600)
    if p.returncode != 0:
        return {"error": "clock_sync exited %d: %s" % (p.returncode, p.stderr.strip()[:300])}
    return json.loads(p.stdout)


def report_sync(m):
    print("\nclock sync, simulated (tests/bench/clock_sync.c): %s boards of -100..+100 ppm, %s us receive jitter, "
          "sync at %s Hz, the host's send lateness p50 47 / p99 134 us, %s s:" % (
              m.get("boards", "?"), m.get("jitter_us", "?"), m.get("rate_hz", "?"), m.get("seconds", "?")))
    if "error" in m:
        print("  FAILED: %s" % m["error"])
        return
    print("  %-22s %30s   %s" % ("", "spread of a tick's instants", "off the intended instant"))
    print("  %-22s %9s %9s %9s   %9s %9s us" % ("", "p50", "p99", "max", "p99", "max"))
    for name, key in (("timed (host instant)", "timed"), ("on arrival (today)", "arrival")):
        f = m[key]
        print("  %-22s %9.2f %9.2f %9.2f   %9.2f %9.2f" % (
            name, f["spread_p50_ns"] / 1e3, f["spread_p99_ns"] / 1e3, f["spread_max_ns"] / 1e3,
            f["off_p99_ns"] / 1e3, f["off_max_ns"] / 1e3))
    print("  spread p99, on arrival / timed: %.1f (goal: timed p99 <= 10 us); %d actions fell back to arrival" % (
        m["spread_p99_ratio"], m["timed"]["fallbacks"]))
    print("  every board locked %.3f s after its first frame at the latest; 1 s without frames: error %.2f us, "
          "bound %.2f us; %.1f ns per sample fed" % (
              m["lock_max_s"], m["holdover_1s_error_ns"] / 1e3, m["holdover_1s_bound_ns"] / 1e3, m["feed_ns"]))
