"""make bench, fieldbus: protocol version 2 (docs/PROTOCOL.md, "Version 2"),
three ways of serving the same boards side by side in one run (udp-unicast,
udp-cyclic, eth-cyclic): host CPU per device per tick, capacity, and
eth-cyclic's tick lateness next to cyclictest. Run through bench.py
(--only fieldbus); the shared helpers are bench.py's."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

from bench import (BENCH_LUA, PRIORITY, ROOT, THESIS_TABLE3, bare, board_wrapper, cpu_awake, cpu_seconds, cyclictest,  # noqa: F401
                   fresh, schedule_for, thread_seconds, with_ctx)
from harness import Context, Skip  # noqa: E402,F401

# ---------------------------------------------------------------------------
# fieldbus: protocol version 2 (docs/PROTOCOL.md, "Version 2"), three ways of
# serving the same boards, side by side in one run.

FIELDBUS_MODES = ("udp-unicast", "udp-cyclic", "eth-cyclic")
MAX_DEVICES_DEFAULT, MAX_DEVICES_RANGE = 1024, 4096  # vmacd's max_devices: default and top of its range (HOST.md)


def eth_unavailable(args):
    """Why eth-cyclic cannot run here (None when it may): root for the
    namespace and the veth pair, and a vmac-board that speaks --bus eth:
    (firmware/posix/ may be in the middle of a rework). The namespace
    itself is tried by the first measurement (harness.Context.eth_link)."""
    if os.geteuid() != 0:
        return "needs root (network namespace, veth pair, CAP_NET_RAW)"
    if not shutil.which("ip"):
        return "no ip command (Debian package iproute2)"
    p = subprocess.run([os.path.join(args.bin, "vmac-board"), "--help"], capture_output=True, text=True, timeout=30)
    if "eth:" not in p.stdout + p.stderr:
        return "this vmac-board has no --bus eth: (see its --help)"
    return None


def proc_cpu(pid):
    try:
        return cpu_seconds(pid)
    except OSError:  # the process is gone: its figure is lost, not the run
        return float("nan")


def run_seconds(pid):
    """Seconds on a CPU of every thread of a process, from the nanoseconds of
    /proc/PID/task/*/schedstat: a cross-check of utime+stime, which /proc
    gives only in clock ticks (10 ms: 3% of a 10 s window at 3% CPU)."""
    return thread_seconds(pid)


def fieldbus_kitchen(ctx, mode, boards, period_us, driver=None, keyed=True, board_extra=()):
    """vmacd and one vmac-board --count `boards` (running benchprobe, or
    driver: (name, source, {its host settings})) on the bus of `mode`, every
    board running; returns (host, board process). keyed: the boards enrolled
    and given their keys (harness.Context.board), else none (the host then
    needs bus_trust open). board_extra: more vmac-board arguments. Raises
    Skip when eth-cyclic cannot make its namespace."""
    name, source, extra = driver or ("benchprobe", BENCH_LUA, {})
    source = source or BENCH_LUA
    settings = {"reply_deadline_us": period_us, "realtime": "true", "cpu_awake": cpu_awake(),
                "watchdog_ms": max(500, 4 * period_us // 1000), "discovery_period_ms": 200,
                "max_devices": min(MAX_DEVICES_RANGE, max(MAX_DEVICES_DEFAULT, boards + 8))}
    settings.update(schedule_for(boards, period_us))
    settings.update(extra)
    host_bus = board_bus = None
    wrapper = board_wrapper()
    if mode == "udp-unicast":
        settings["cyclic"] = "false"
    elif mode == "eth-cyclic":
        host_if, ns, board_if = ctx.eth_link()  # removed by ctx.cleanup(), whatever happens
        host_bus, board_bus = "eth:" + host_if, "eth:" + board_if
        wrapper = ("ip", "netns", "exec", ns) + wrapper
    host = ctx.host(drivers=ctx.drivers(**{name: source}), settings=settings, bus=host_bus)
    # --late-us = the reply deadline: every line it prints is a reply the
    # board itself sent too late to be in time, whatever the host did.
    board = ctx.board("generic", "b", count=boards, driver=name, wrapper=wrapper, bus=board_bus,
                      extra=("--late-us", str(period_us)) + tuple(board_extra), keyed=keyed)
    wait_attached(host, boards, timeout_s=30 + boards / 50)
    return host, board


def wait_attached(host, boards, timeout_s, stalled_s=10):
    """Every one of `boards` devices running. Fails with a short account (how
    many run, how many are still attaching, the host's events_lost) when that
    does not come within timeout_s, or when no more attach for stalled_s."""
    deadline = time.monotonic() + timeout_s
    best, since = -1, time.monotonic()
    while True:
        s = host.status()
        states = {}
        for d in s["devices"]:
            states[d["state"]] = states.get(d["state"], 0) + 1
        running = states.get("running", 0)
        if running >= boards:
            return s
        if running > best:
            best, since = running, time.monotonic()
        now = time.monotonic()
        if now > deadline or now - since > stalled_s:
            raise AssertionError("%d of %d boards running after %.0f s (%s; the host's events_lost %d)" % (
                running, boards, timeout_s - (deadline - now),
                ", ".join("%d %s" % (n, k) for k, n in sorted(states.items())), s["counters"]["events_lost"]))
        time.sleep(0.5)  # between two looks at the status


def fresh_status(host):
    """A status the bus thread has just published (it does so every 100 ms):
    the window's edges within a few milliseconds, so that the board's late
    lines and the host's counters cover the same window."""
    first = host.status()
    while True:
        s = host.status()
        if s["uptime_s"] != first["uptime_s"]:
            return s
        time.sleep(0.005)  # until the next publication, at most 100 ms away


def late_since(before, after):
    """A machine's driver_late over a window (status, devices[]): its count
    restarts when the machine attaches again (after a drop), and then all
    of it is the window's (counted short if it grew past the old count)."""
    now, then = after.get("driver_late", 0), (before or {}).get("driver_late", 0)
    return now - then if now >= then else now


def fieldbus_run(ctx, mode, boards, period_us, seconds, driver=None, keyed=True, board_extra=()):
    """`boards` boards served in `mode` for `seconds` of steady state: the
    figures of that window (driver, keyed, board_extra: as fieldbus_kitchen's)."""
    host, board = fieldbus_kitchen(ctx, mode, boards, period_us, driver, keyed, board_extra)
    before = fresh_status(host)
    late_mark = board.mark()
    cpu0, run0, bcpu0, t0 = cpu_seconds(host.pid), run_seconds(host.pid), proc_cpu(board.pid), time.monotonic()
    time.sleep(seconds)  # the measurement window itself, not a synchronisation
    after = fresh_status(host)
    cpu1, run1, bcpu1, t1 = cpu_seconds(host.pid), run_seconds(host.pid), proc_cpu(board.pid), time.monotonic()
    late = board.find_lines(r": late reply seq ", since=late_mark)
    ticks = after["tick"]["count"] - before["tick"]["count"]
    c0, c1 = before["counters"], after["counters"]
    served0 = {d["name"]: d["served"] for d in before["devices"]}
    served = sum(d["served"] - served0.get(d["name"], 0) for d in after["devices"])
    window_s = after["uptime_s"] - before["uptime_s"]  # the two snapshots' own times
    per_device = boards and window_s * 1e6 / period_us  # services each device is due in the window
    # The devices that ran the whole window without a miss: were they served
    # at their rate? Less means the host itself fell behind (a board that
    # missed is dropped and re-attached, and so is served less anyway).
    before_by_name = {d["name"]: d for d in before["devices"]}
    steady = [d["served"] - before_by_name[d["name"]]["served"] for d in after["devices"]
              if d["state"] == "running" and d["name"] in before_by_name
              and before_by_name[d["name"]]["state"] == "running" and d["misses"] == before_by_name[d["name"]]["misses"]]
    services = {}
    for d in after["devices"]:
        key = "%s v%s" % (d.get("service"), d.get("protocol"))
        services[key] = services.get(key, 0) + 1
    return {
        "mode": mode, "boards": boards, "period_us": period_us, "seconds": seconds, "ticks": ticks,
        "skipped_ticks": after["tick"]["skipped"] - before["tick"]["skipped"],
        "misses": c1["misses"] - c0["misses"],
        "misses_host": c1.get("misses_host", 0) - c0.get("misses_host", 0),
        "devices_missed": sum(1 for d in after["devices"] if d["misses"]),
        "devices_missed_host": sum(1 for d in after["devices"] if d.get("misses_host")),
        "drops": c1["drops"] - c0["drops"],
        "driver_late": sum(late_since(before_by_name.get(d["name"]), d) for d in after["devices"]),
        "late_replies_host": c1["late_replies"] - c0["late_replies"],
        "late_replies_board": len(late), "late_reply_example": late[0].text if late else None,
        "running_at_end": sum(1 for d in after["devices"] if d["state"] == "running"),
        "authenticated_at_end": sum(1 for d in after["devices"] if d["state"] == "running" and d.get("authenticated")),
        "services": services,
        "served": served,
        "served_ratio": served / max(1.0, boards * per_device),
        "served_ratio_steady": sum(steady) / max(1.0, len(steady) * per_device) if steady else None,
        "bus": after["bus"]["group"],
        "realtime": after["bus"]["realtime"],
        "lateness_us": after["tick"]["lateness_us"],
        "cpu_us_per_device_tick": (cpu1 - cpu0) * 1e6 / max(1, ticks * boards),
        "cpu_us_per_service": (cpu1 - cpu0) * 1e6 / max(1, served),
        "run_us_per_device_tick": (run1 - run0) * 1e6 / max(1, ticks * boards),
        "host_cpu_share": (cpu1 - cpu0) / (t1 - t0),
        "board_cpu_share": (bcpu1 - bcpu0) / (t1 - t0),
    }


def fieldbus_measure(args, state, mode, name, fn):
    """fn(ctx) in a fresh context, or {"skipped": why} for eth-cyclic where it
    cannot run (said once, remembered), or {"error": ...}: one mode failing
    never stops the others."""
    if mode == "eth-cyclic" and state.get("eth_skipped"):
        return {"skipped": state["eth_skipped"]}
    try:
        return with_ctx(args, name, fn)
    except Skip as e:
        state["eth_skipped"] = str(e)
        print("    %s: SKIPPED: %s" % (mode, e), flush=True)
        return {"skipped": str(e)}
    except AssertionError as e:  # boards that did not start or attach
        return {"error": str(e)[:300]}
    except Exception as e:  # noqa: BLE001 (a program that died, a refused setting: this mode's figure only)
        return {"error": "%s: %s" % (type(e).__name__, str(e)[:300])}


def fieldbus_probe_line(r):
    steady = r["served_ratio_steady"]
    return ("%d misses (%d the host's), %d drops, served %.1f%% (%s without a miss), %d late replies by the "
            "board, lateness p99 %d us, CPU vmacd %.0f%% board %.0f%%" % (
                r["misses"], r["misses_host"], r["drops"], 100 * r["served_ratio"],
                "%.1f%%" % (100 * steady) if steady is not None else "none", r["late_replies_board"],
                r["lateness_us"]["p99"], 100 * r["host_cpu_share"], 100 * r["board_cpu_share"]))


def fieldbus_blame(r):
    """Who failed a probe: 'attach' (the boards never all ran), 'host' (a
    miss the host caused, or devices that missed nothing served below their
    rate: the host fell behind), 'boards' (misses the host did not cause:
    replies late or lost), or None when the probe passed."""
    if "error" in r:
        return "attach"
    host = r["misses_host"] > 0 or (r["served_ratio_steady"] is not None and r["served_ratio_steady"] < 0.99)
    passed = (r["misses"] == 0 and r["drops"] == 0 and r["running_at_end"] == r["boards"]
              and r["served_ratio"] >= 0.99)
    if passed:
        return None
    return "host" if host else "boards"


def fieldbus_capacity(args, state, mode, rate_hz, window_s):
    """The capacity probe of `capacity`, for one mode: from the thesis's
    figure, doubling then bisecting N, each probe `window_s` long. A probe
    passes with zero misses, zero drops, every board running and served at
    its rate (no slot skipped for good); misses the host caused
    (misses_host) are kept apart from the boards'. A probe failed by the
    boards alone (misses, none the host's, while it served every other
    device at its rate) is run once more before N counts as failed: on a
    shared machine one late wake-up of the board process is a miss, and the
    search is about N, not about that one wake-up."""
    period_us = 1000000 // rate_hz
    # What the host can be asked for at all: its device table (max_devices
    # at most 4,096, 8 spare) and one slice of at least 1 us per board.
    limits = {MAX_DEVICES_RANGE - 8: "max_devices' range ends at %d" % MAX_DEVICES_RANGE,
              period_us: "slices of at least 1 us: at most %d boards every %d us" % (period_us, period_us)}
    if args.max_boards:
        limits[args.max_boards] = "--max-boards %d" % args.max_boards
    limit = min(limits)
    probes = []

    def ok(n, again=False):
        r = fieldbus_measure(args, state, mode, "fb-%s-%d-%d" % (mode, rate_hz, n),
                             lambda c: fieldbus_run(c, mode, n, period_us, window_s))
        r["boards"], r["again"] = n, again
        probes.append(r)
        if "skipped" in r:
            return None
        r["blame"] = fieldbus_blame(r)
        if "error" in r:
            print("    %5d boards at %4d Hz, %s: did not attach (%s)" % (n, rate_hz, mode, r["error"][:160]),
                  flush=True)
            return False
        print("    %5d boards at %4d Hz, %s%s: %s%s" % (
            n, rate_hz, mode, " (again)" if again else "", fieldbus_probe_line(r),
            "; failed: the %s" % r["blame"] if r["blame"] else ""), flush=True)
        if r["blame"] == "boards" and not again:
            return ok(n, again=True)
        return r["blame"] is None

    lo, hi, n = 0, None, min(THESIS_TABLE3[rate_hz], limit)
    while n <= limit:
        good = ok(n)
        if good is None:
            return {"mode": mode, "rate_hz": rate_hz, "skipped": state["eth_skipped"]}
        if good:
            lo = n
            if n == limit:
                break
            n = min(n * 2, limit)
        else:
            hi = n
            break
    for _ in range(args.bisect if hi is not None else 0):
        if hi - lo <= max(1, lo // 10):
            break
        mid = (lo + hi) // 2
        if ok(mid):
            lo = mid
        else:
            hi = mid
    # The largest probe in which the host did all its part (no miss of its
    # own, every device that missed nothing served at its rate; any miss the
    # boards'): what the host could serve had the board simulator kept up.
    host_clean = max([p["boards"] for p in probes if p.get("blame", "attach") in (None, "boards")] or [0])
    failing = next((p for p in reversed(probes) if p["boards"] == hi), None)
    out = {"mode": mode, "rate_hz": rate_hz, "max_boards": lo, "first_failing": hi, "window_s": window_s,
           "first_failing_blame": failing and failing.get("blame"),
           "first_failing_error": failing and failing.get("error"),
           "host_clean_max": host_clean, "misses_host_total": sum(p.get("misses_host", 0) for p in probes),
           "board_failures": sum(1 for p in probes if p.get("blame") == "boards"),
           "max_devices": min(MAX_DEVICES_RANGE, max(MAX_DEVICES_DEFAULT, max(p["boards"] for p in probes) + 8)),
           "probes": probes}
    if hi is None:
        out["limit"] = "not reached: stopped at %d boards (%s)" % (limit, limits[limit])
    return out


def others_running():
    """vmacd, vmac-board, cyclictest processes this run did not start (it has
    started none yet): a neighbour that would share the two cores."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open("/proc/%s/comm" % pid) as f:
                comm = f.read().strip()
        except OSError:
            continue
        if comm in ("vmacd", "vmac-board", "cyclictest", "bare_loop"):
            found.append("%s %s" % (comm, pid))
    return found


def note_others():
    """others_running(), said when there are any: figures measured beside
    them shared the CPUs."""
    others = others_running()
    if others:
        print("    note: already running here, sharing the CPUs: %s%s" % (
            ", ".join(others[:8]), " and %d more" % (len(others) - 8) if len(others) > 8 else ""), flush=True)
    return others


def attempt(run):
    """run()'s result, or {"error": why} when it failed (boards that did not
    attach, values that never came, a program that died, a refused
    setting); harness.Skip goes to the caller."""
    try:
        return run()
    except Skip:
        raise
    except AssertionError as e:
        return {"error": str(e)[:300]}
    except Exception as e:  # noqa: BLE001
        return {"error": "%s: %s" % (type(e).__name__, str(e)[:300])}


def fieldbus(args):
    """Protocol version 2 in three modes (FIELDBUS_MODES), one run."""
    t_start = time.monotonic()
    state = {}
    others = others_running()
    if others:
        print("    note: already running here, sharing the CPUs: %s%s" % (
            ", ".join(others[:8]), " and %d more" % (len(others) - 8) if len(others) > 8 else ""), flush=True)
    why = eth_unavailable(args)
    if why:
        state["eth_skipped"] = why
        print("    eth-cyclic: SKIPPED: %s" % why, flush=True)
    out = {"modes": list(FIELDBUS_MODES), "cost": [], "capacity": [], "others_at_start": others,
           "loadavg_at_start": open("/proc/loadavg").read().split()[:3]}

    # 1. Host CPU per device per tick, same boards and period in every mode,
    # next to bare_loop (UDP unicast, sendmmsg/recvmmsg, nothing else).
    for boards, period_us in ((100, 10000), (10, 1000)):
        row = {"boards": boards, "period_us": period_us, "modes": {}}
        for mode in FIELDBUS_MODES:
            print("fieldbus cost: %s, %d boards at %d Hz, %d s" % (mode, boards, 1000000 // period_us, args.seconds),
                  flush=True)
            r = fieldbus_measure(args, state, mode, "fb-cost-%s-%d" % (mode, boards),
                                 lambda c: fieldbus_run(c, mode, boards, period_us, args.seconds))
            if "cpu_us_per_device_tick" in r:
                print("    %.2f us per device per tick (on-CPU time %.2f); %s" % (
                    r["cpu_us_per_device_tick"], r["run_us_per_device_tick"], fieldbus_probe_line(r)), flush=True)
            elif "error" in r:
                print("    %s: FAILED: %s" % (mode, r["error"]), flush=True)
            row["modes"][mode] = r
        print("fieldbus cost: bare_loop, %d boards at %d Hz, %d s" % (boards, 1000000 // period_us, args.seconds),
              flush=True)
        try:
            b = with_ctx(args, "fb-bare-%d" % boards, lambda c: bare(c, args.bare, boards, period_us, args.seconds))
        except (AssertionError, OSError) as e:  # no bare_loop built, boards that did not start
            b = {"error": str(e)[:300]}
        row["bare_loop"] = b
        print("    %s" % ("%.2f us per device per tick" % b["cpu_us_per_device_tick"] if "error" not in b
                          else "FAILED: " + b["error"]), flush=True)
        cost = {m: row["modes"][m].get("cpu_us_per_device_tick") for m in FIELDBUS_MODES}
        for cyc in ("udp-cyclic", "eth-cyclic"):
            if cost["udp-unicast"] and cost[cyc]:
                row["unicast_over_%s" % cyc] = cost["udp-unicast"] / cost[cyc]
        out["cost"].append(row)

    # 3. Tick lateness of the bus thread with eth-cyclic (10 boards at 1 kHz,
    # from the run above) next to cyclictest at the same period and priority.
    print("fieldbus lateness: cyclictest -p %d -i 1000, %d s" % (PRIORITY, args.seconds), flush=True)
    out["cyclictest_1khz"] = cyclictest(1000, args.seconds)

    # 2. Capacity at 1 kHz and 100 Hz: shorter probes so that the whole
    # search of six fits (--seconds 10: 5 s per probe).
    window_s = max(2, args.seconds // 2)
    for rate in (1000, 100):
        for mode in FIELDBUS_MODES:
            print("fieldbus capacity: %s at %d Hz (%d s per probe)" % (mode, rate, window_s), flush=True)
            c = fieldbus_capacity(args, state, mode, rate, window_s)
            c["thesis_table3"] = THESIS_TABLE3[rate]
            out["capacity"].append(c)
    out["thesis_table3"] = THESIS_TABLE3
    out["eth_skipped"] = state.get("eth_skipped")
    out["elapsed_s"] = time.monotonic() - t_start
    out["loadavg_at_end"] = open("/proc/loadavg").read().split()[:3]
    return out



def report_fieldbus(fb):
    modes = fb["modes"]

    def cell(x, fmt="%.2f us"):
        if "skipped" in x:
            return "SKIPPED"
        if "error" in x:
            return "FAILED"
        return fmt % x["cpu_us_per_device_tick"]

    print("\nfieldbus (protocol version 2), host CPU per device per tick (vmacd utime+stime / (ticks x devices)):")
    print("  %-22s %12s %12s %12s %12s   %s" % ("", *modes, "bare loop", "unicast/cyclic udp, eth"))
    for row in fb["cost"]:
        b = row["bare_loop"]
        print("  %-22s %12s %12s %12s %12s   %s, %s" % (
            "%d boards at %d Hz" % (row["boards"], 1000000 // row["period_us"]),
            *(cell(row["modes"][m]) for m in modes),
            "%.2f us" % b["cpu_us_per_device_tick"] if "error" not in b else "FAILED",
            "%.2f" % row["unicast_over_udp-cyclic"] if "unicast_over_udp-cyclic" in row else "-",
            "%.2f" % row["unicast_over_eth-cyclic"] if "unicast_over_eth-cyclic" in row else "-"))
        for m in modes:
            x = row["modes"][m]
            if "skipped" in x or "error" in x:
                print("    %s: %s" % (m, x.get("skipped") and "SKIPPED: " + x["skipped"] or "FAILED: " + x["error"]))
            else:
                print("    %-11s %s" % (m + ":", fieldbus_probe_line(x)))
    print("  goal (issue 17): cyclic <= 1.5 us per device per tick, unicast/cyclic >= 8")
    ct = fb.get("cyclictest_1khz", {})
    eth = next((row["modes"]["eth-cyclic"] for row in fb["cost"] if row["period_us"] == 1000), None)
    if eth and "lateness_us" in eth:
        lat = eth["lateness_us"]
        print("fieldbus tick lateness, eth-cyclic, 10 boards at 1 kHz: p50 %d us, p99 %d us, p99.9 %d us, max %d us "
              "(%s)" % (lat["p50"], lat["p99"], lat["p999"], lat["max"],
                        "SCHED_FIFO" if eth["realtime"] else "normal scheduling"))
    elif eth:
        print("fieldbus tick lateness, eth-cyclic: %s" % (eth.get("skipped") and "SKIPPED: " + eth["skipped"]
                                                          or "FAILED: " + eth.get("error", "")))
    if "error" in ct:
        print("cyclictest: %s" % ct["error"])
    elif ct:
        print("cyclictest at 1 kHz, same run:                         p50 %d us, p99 %d us, p99.9 %d us, max %d us" % (
            ct["p50"], ct["p99"], ct["p999"], ct["max"]))
        if eth and "lateness_us" in eth:
            print("ratio vmacd (eth-cyclic) / cyclictest: p99 %.2f, max %.2f" % (
                eth["lateness_us"]["p99"] / max(1, ct["p99"]), eth["lateness_us"]["max"] / max(1, ct["max"])))
    print("thesis Table 3: %s (10 Hz is measured by `capacity`, not here)" % ", ".join(
        "%d @ %d Hz" % (n, hz) for hz, n in sorted(THESIS_TABLE3.items(), reverse=True)))
    for c in fb["capacity"]:
        head = "fieldbus capacity at %4d Hz, %-11s" % (c["rate_hz"], c["mode"] + ":")
        if "skipped" in c:
            print("%s SKIPPED: %s" % (head, c["skipped"]))
            continue
        if c["first_failing"]:
            why = {"attach": "did not all attach: %s" % (c.get("first_failing_error") or "")[:120],
                   "host": "the host fell behind", "boards": "misses of the boards, none the host's"}
            failed = "%d failed (%s)" % (c["first_failing"], why.get(c["first_failing_blame"], "?"))
        else:
            failed = c["limit"]
        print("%s %5d boards with zero misses (thesis Table 3: %d); %s; in its %d probes: %d misses the host's, "
              "%d failed by the boards alone; largest probe where the host did all its part: %d%s" % (
                  head, c["max_boards"], c["thesis_table3"], failed, len(c["probes"]), c["misses_host_total"],
                  c.get("board_failures", 0), c["host_clean_max"],
                  "; max_devices raised to %d" % c["max_devices"] if c["max_devices"] > MAX_DEVICES_DEFAULT else ""))
    print("fieldbus: %.0f s in all; capacity probes of %d s each; load average %s at the start, %s at the end%s" % (
        fb["elapsed_s"], fb["capacity"][0].get("window_s", 0) if fb["capacity"] else 0,
        "/".join(fb["loadavg_at_start"]), "/".join(fb["loadavg_at_end"]),
        "; %d programs of ours already running (%s)" % (len(fb["others_at_start"]), ", ".join(fb["others_at_start"][:4]))
        if fb["others_at_start"] else ""))

