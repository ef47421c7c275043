#!/usr/bin/env python3
"""make bench: vmac's timing figures, each next to a baseline measured in the
same run on the same machine, reported as ratios.

  lateness  tick lateness of vmacd with 10 boards at 1 kHz, next to cyclictest
            (rt-tests) at the same period and priority
  capacity  the most boards (one vmac-board --count N) served at 1 kHz, 100 Hz
            and 10 Hz with zero missed deadlines, next to the thesis's Table 3
  cost      host CPU microseconds per device per tick, next to bare_loop (the
            same sendmmsg/recvmmsg exchange with no drivers and no policy)
  vtest     vmac test: wall seconds for one virtual hour of washing
            (tests/bench/washer_hour.lua), alone and in the demo kitchen,
            as a ratio to real time; and of drying (tests/bench/dryer_hour.lua:
            the kitchen's dryer with its plant in Lua), next to the washer's
  ui        tick lateness of vmacd with 10 boards at 1 kHz while 50 web UI
            clients read GET /api/live, next to the same host with none
  reload    hot reload: 1,000 reloads of a driver running on 10 of 100
            boards at 10 Hz; missed deadlines during the reloads next to
            the same window without reloads, and the reload latency (request
            to every machine switched)
  fieldbus  protocol version 2, three ways of serving the same boards side by
            side: udp-unicast (cyclic=false: one UPDATE per device), udp-cyclic
            (one CYCLIC frame per slot to the multicast group) and eth-cyclic
            (raw Ethernet over a veth pair, the boards in a network namespace
            of their own; needs root, else SKIPPED). Host CPU per device per
            tick next to bare_loop, capacity at 1 kHz and 100 Hz next to the
            thesis's Table 3 (misses the host caused told apart from the
            boards'), and eth-cyclic's tick lateness next to cyclictest
  qemu      the firmware on a Cortex-M3 in QEMU (tests/bench/qemu_board.py;
            needs root, qemu-system-arm and make firmware, else SKIPPED): its
            reply time next to vmac-board's on the same raw-Ethernet bridge,
            and the highest rate one QEMU board holds with zero misses
  recorder  the flight recorder and checkpoints (tests/bench/recorder.py):
            host CPU per device per tick, 100 boards at 100 Hz, with
            recorder_s=60 and with checkpoint_s=1, each next to both off in
            the same round (3 to 5 rounds); vmacd's RSS with 1,000 boards at
            10 Hz, recorder_s=60 next to 0, over time
  ethring   raw Ethernet's receive ring next to recvmmsg on eth-cyclic
            (tests/bench/ethring.py): host CPU per device per tick, 100
            boards at 1 kHz, alternating rounds (root, else SKIPPED)
  mqtt      MQTT through Mosquitto (tests/bench/mqtt_bench.py): 1,000
            boards at 10 Hz, a variable changing at every tick, MQTT on
            next to off in alternating rounds: value messages per second
            to a subscriber, tick lateness p99 on/off, host CPU, misses;
            then the precision throttle: the kitchen with a wash running,
            the washer's temperature at precision 6 next to 1, its messages
            per second and the changes that reached the subscriber
            (mosquitto and python3-paho-mqtt, else SKIPPED); mqtt-kitchen:
            that second part alone
  workers   drivers on driver workers next to a vmacd that ran them on its
            bus thread (--base-bin; tests/bench/workers.py): host CPU per
            device per tick at 100 boards and 1 kHz, how the tick lateness
            grows with drivers that burn CPU, the washer's driver on one
            worker next to two (else SKIPPED)
  metrics   GET /metrics (tests/bench/metrics_bench.py): 1,000 boards at
            10 Hz, a scrape a second (a read token, one kept-alive
            connection, as Prometheus scrapes) and 20 a second (a
            magnifier) next to no scrape, in turn in each round: the time
            of one scrape (ms), its size, and tick lateness p99 scraped/none
  auth      authenticated frames (tests/bench/auth.py): ns per frame and per
            record of sealing and opening next to encoding the same request
            (tests/bench/auth_frames.c), and host CPU per device per tick, 100
            boards at 1 kHz on eth-cyclic, keyed next to bus_trust open with
            boards without keys, alternating rounds (root, else SKIPPED)
  minisign  checking a bundle's minisign signature (tests/bench/minisign_bench.py):
            us per MiB of a prehashed (ED) and a legacy (Ed) signature next to
            BLAKE2b-512 alone over the same 4 MiB (tests/bench/minisign_verify.c)
  plant     one step of a plant model in Lua (tests/bench/plant_bench.py), the
            kitchen's dryer, at 1 kHz as vmac-board steps it, next to the C
            washer in the same run (tests/bench/plant_step.c), us a step
  sync      the boards' disciplined clocks, simulated (tests/bench/sync_bench.py):
            the spread of the true instants at which ten boards act on one
            host instant, next to acting on arrival in the same run
            (tests/bench/clock_sync.c); --seconds of simulated time. Then
            the host CPU clock sync adds per device tick: vmacd with 10
            keyed vmac-boards at 1 kHz, clock_sync_ms 1 next to 0,
            alternating rounds (VMAC_BENCH_SYNC_ROUNDS, 8) of windows of
            --seconds (10 at most), the median ratio and its 90 % interval
  bundle    deploying a bundle (tests/bench/bundle_bench.py): upload to
            switched of 100 bundles of the washer, unsigned and signed with
            minisign, next to 100 uploads of the washer's Lua text alone (its
            programmes inlined), interleaved on one vmacd, median and p95;
            with --before-bin DIR also the washer.lua reload of a vmacd from
            before bundles, on a second host beside

usage: bench.py --bin build/bin --bare build/bench/bare_loop [--seconds S]
                [--only lateness,capacity,cost,vtest,reload,ui,fieldbus,qemu,recorder,ethring,mqtt,workers,auth,
                        metrics,minisign,bundle,plant,sync,mqtt-kitchen]
                [--base-bin DIR] [--before-bin DIR]
                [--cpu-awake true|false]   (vmacd's cpu_awake beside cyclictest; default true)
Writes build/bench/results.json and prints a table. Numbers, never pass/fail."""

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
from harness import Context, Skip  # noqa: E402  (the integration tests' process handling)

PRIORITY = 50  # vmacd's bus thread asks for SCHED_FIFO 50; cyclictest gets the same


def cpu_awake():
    """vmacd's cpu_awake where a part compares it with cyclictest, which
    keeps the CPUs out of deep idle states as cpu_awake does: "true" unless
    --cpu-awake false (docs/PERFORMANCE.md, "Tick lateness")."""
    return os.environ.get("VMAC_BENCH_CPU_AWAKE", "true")
THESIS_TABLE3 = {1000: 10, 100: 100, 10: 1000}
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def cpu_seconds(pid):
    """utime + stime of a process, from /proc."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def thread_seconds(pid, names=None):
    """On-CPU seconds (schedstat, in nanoseconds) of a process's threads
    whose name is one of names (e.g. ("vmac-bus",)), or of all of them."""
    total = 0
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            if names is not None:
                with open("/proc/%d/task/%s/comm" % (pid, tid)) as f:
                    if f.read().strip() not in names:
                        continue
            with open("/proc/%d/task/%s/schedstat" % (pid, tid)) as f:
                total += int(f.read().split()[0])
        except OSError:  # a thread that ended meanwhile
            pass
    return total / 1e9


def board_wrapper():
    """Real boards answer in microseconds on their own hardware; the mock
    boards share this machine with the host. Run them at SCHED_FIFO one below
    the host's bus thread when that is allowed, so the figures measure the
    host, not the board process's wake-up latency."""
    chrt = shutil.which("chrt")
    if chrt and subprocess.run([chrt, "-f", str(PRIORITY - 1), "true"], capture_output=True).returncode == 0:
        return (chrt, "-f", str(PRIORITY - 1))
    return ()


def schedule_for(boards, period_us):
    """Host settings that serve `boards` boards every `period_us`: the lowest
    level L with room (at most 256 slices per slot), slots of period / 2^L,
    and a slice count that divides the slot evenly (docs/SCHEDULER.md).
    Where no level splits the period exactly (more than 2,000 boards at
    100 Hz), the closest within 1% (3,200 at 100 Hz: 32 slots of 312 us, a
    period of 9,984 us). A slice is at least 1 us, so never more boards than
    microseconds in the period: ValueError."""
    best = None
    for level in range(0, 13):
        need = -(-boards // (1 << level))
        slot_us = period_us >> level
        if need > 256 or slot_us < 1:
            continue
        for slices in range(need, 257):
            if slot_us % slices:
                continue
            error = abs((slot_us << level) - period_us) / period_us
            if best is None or error < best[0]:
                best = (error, level, slices, slot_us)
            break
        if best and best[0] == 0:
            break
    if best is None or best[0] > 0.01:
        raise ValueError("no schedule serves %d boards every %d us (slices of at least 1 us)" % (boards, period_us))
    _, level, slices, slot_us = best
    return {"slice_us": slot_us // slices, "slices_per_slot": slices, "max_level": max(level, 1),
            "default_level": level}


# The driver every bench board runs: reads a switch, drives a lamp, publishes
# one variable. A small real driver, so the cost includes a Lua call per tick.
BENCH_LUA = """local driver = { name = "benchprobe", version = "1", io = { switch = "di0", lamp = "do0" },
	variables = { lamp = {} } }
function driver.tick(dev, inputs)
	dev.out.lamp = inputs.switch
	dev.vars.lamp = inputs.switch
end
return driver
"""


# --set KEY=VALUE: host settings on top of the bench's own, for a kitchen
# measured with a setting changed (e.g. clock_sync_ms=1, docs/TIME.md).
HOST_SETTINGS = {}


def start_kitchen(ctx, boards, period_us, deadline_us, extra=None):
    settings = {"reply_deadline_us": deadline_us, "realtime": "true", "cpu_awake": cpu_awake(),
                "watchdog_ms": max(500, 4 * period_us // 1000), "discovery_period_ms": 200,
                "max_devices": max(1024, boards + 8)}
    settings.update(schedule_for(boards, period_us))
    settings.update(HOST_SETTINGS)
    settings.update(extra or {})
    host = ctx.host(drivers=ctx.drivers(benchprobe=BENCH_LUA), settings=settings)
    ctx.board("generic", "b", count=boards, driver="benchprobe", wrapper=board_wrapper())
    names = ["b-%d" % i for i in range(1, boards + 1)] if boards > 1 else ["b"]
    host.wait_running(names, timeout_s=120)
    return host, names


def run_host(ctx, boards, period_us, seconds, deadline_us=None, extra=None):
    """vmacd serving `boards` boards for `seconds` of steady state (extra:
    settings on top of the bench's and --set's); returns the figures of
    that window."""
    host, names = start_kitchen(ctx, boards, period_us, deadline_us or period_us, extra)
    before = host.status()
    cpu0, bus0 = cpu_seconds(host.pid), thread_seconds(host.pid, ("vmac-bus",))
    time.sleep(seconds)  # the measurement window itself, not a synchronisation
    cpu1, bus1 = cpu_seconds(host.pid), thread_seconds(host.pid, ("vmac-bus",))
    after = host.status()
    ticks = after["tick"]["count"] - before["tick"]["count"]
    running = sum(1 for d in after["devices"] if d["state"] == "running")
    misses = after["counters"]["misses"] - before["counters"]["misses"]
    misses_host = after["counters"]["misses_host"] - before["counters"]["misses_host"]
    return {
        "boards": boards,
        "period_us": period_us,
        "seconds": seconds,
        "ticks": ticks,
        "misses": misses,
        "misses_host": misses_host,
        # A board that missed (a simulated board held off this machine's
        # CPUs) costs the host a drop, a recording and a re-attach: the
        # host's figures of that window measure the board, not the host.
        "comparable": misses == misses_host,
        "drops": after["counters"]["drops"] - before["counters"]["drops"],
        "running_at_end": running,
        "realtime": after["bus"]["realtime"],
        "lateness_us": after["tick"]["lateness_us"],
        "cpu_us_per_device_tick": (cpu1 - cpu0) * 1e6 / max(1, ticks * boards),
        "bus_cpu_us_per_device_tick": (bus1 - bus0) * 1e6 / max(1, ticks * boards),  # its bus thread's part
    }


def cyclictest(period_us, seconds):
    """cyclictest at the same period and priority; percentiles from its histogram."""
    exe = shutil.which("cyclictest")
    if not exe:
        return {"error": "cyclictest not installed (Debian package rt-tests)"}
    out = subprocess.run([exe, "-q", "-m", "-p", str(PRIORITY), "-i", str(period_us), "-D", str(seconds),
                          "-h", "20000", "-t", "1"], capture_output=True, text=True).stdout
    hist, maxv = [], 0
    for line in out.splitlines():
        m = re.match(r"^(\d+)\s+(\d+)$", line)
        if m:
            hist.append((int(m.group(1)), int(m.group(2))))
        m = re.match(r"^# Max Latencies:\s+(\d+)", line)
        if m:
            maxv = int(m.group(1))
    total = sum(c for _, c in hist)
    if not total:
        return {"error": "cyclictest printed no histogram", "output": out[-500:]}

    def q(frac):
        want, seen = frac * total, 0
        for us, c in hist:
            seen += c
            if seen >= want:
                return us
        return maxv

    return {"p50": q(0.5), "p99": q(0.99), "p999": q(0.999), "max": maxv, "samples": total}


def bare(ctx, bare_exe, boards, period_us, seconds):
    ctx.board("generic", "b", count=boards, wrapper=board_wrapper())
    rc, out, err = ctx.run([bare_exe, "--bus", ctx.bus, "--boards", str(boards), "--period-us", str(period_us),
                            "--seconds", str(seconds)], "bare_loop", timeout_s=seconds + 60)
    if rc != 0:
        return {"error": "bare_loop exited %d: %s" % (rc, err.strip())}
    r = json.loads(out)
    r["cpu_us_per_device_tick"] = r["cpu_s"] * 1e6 / max(1, r["ticks"] * boards)
    return r


def fresh(args, name):
    logdir = tempfile.mkdtemp(prefix="vmac-bench-%s-" % name, dir=args.logs)
    return Context(args.bin, logdir)


def with_ctx(args, name, fn):
    ctx = fresh(args, name)
    try:
        return fn(ctx)
    finally:
        ctx.cleanup()


def capacity(args, rate_hz):
    """Largest N (doubling, then bisecting) served for args.seconds with no miss."""
    period_us = 1000000 // rate_hz

    def ok(n):
        try:
            r = with_ctx(args, "cap%d-%d" % (rate_hz, n), lambda c: run_host(c, n, period_us, args.seconds))
        except AssertionError as e:  # could not even attach them all
            print("    %5d boards at %4d Hz: did not attach (%s)" % (n, rate_hz, str(e)[:80]), flush=True)
            return False
        good = r["misses"] == 0 and r["drops"] == 0 and r["running_at_end"] == n
        print("    %5d boards at %4d Hz: %d misses, %d drops, lateness p99 %d us" % (
            n, rate_hz, r["misses"], r["drops"], r["lateness_us"]["p99"]), flush=True)
        return good

    max_boards = args.max_boards or 2000
    lo, hi, n = 0, None, 10
    while n <= max_boards:
        if ok(n):
            lo, n = n, n * 2
        else:
            hi = n
            break
    if hi is None:
        return {"rate_hz": rate_hz, "max_boards": lo, "limit": "not reached (--max-boards %d)" % max_boards}
    for _ in range(args.bisect):
        if hi - lo <= max(1, lo // 10):
            break
        mid = (lo + hi) // 2
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return {"rate_hz": rate_hz, "max_boards": lo, "first_failing": hi}


def vtest(args):
    """Wall seconds of each test of washer_hour.lua and dryer_hour.lua (one
    virtual hour each: the washer with its plant in C, the kitchen's dryer
    from examples/kitchen with its plant in Lua), best of three runs (the
    figure is the program's speed, not the machine's neighbours); JUnit
    gives the per-test times. lua_plant_ratio: the dryer's hour over the
    washer's, each alone."""
    import xml.etree.ElementTree as ET
    bench = os.path.join(ROOT, "tests", "bench")
    runs = [[os.path.join(bench, "washer_hour.lua")],
            ["--drivers", os.path.join(ROOT, "examples", "kitchen"), os.path.join(bench, "dryer_hour.lua")]]
    best = {}
    for run in range(3):
        for i, argv in enumerate(runs):
            junit = os.path.join(args.logs, "vtest-%d-%d.xml" % (run, i))
            p = subprocess.run([os.path.join(args.bin, "vmac"), "test", "--junit", junit] + argv,
                               capture_output=True, text=True, timeout=600)
            if p.returncode != 0:
                return {"error": "vmac test %s failed (exit %d): %s" % (argv[-1], p.returncode,
                                                                      (p.stdout + p.stderr)[-500:])}
            for case in ET.parse(junit).getroot().iter("testcase"):
                t = float(case.get("time"))
                best[case.get("name")] = min(t, best.get(case.get("name"), t))
    washer, dryer = best.get("an hour of washing, the washer alone"), best.get("an hour of drying, the dryer alone")
    return {"virtual_s": 3600, "wall_s": best,
            "lua_plant_ratio": dryer / washer if washer and dryer else None}


RELOAD_LUA = """local driver = { name = "reloadprobe", version = "%d", io = { switch = "di0", lamp = "do0" },
	variables = { ticks = {} } }
function driver.attach(dev) dev.state.ticks = 0 end
function driver.tick(dev, inputs)
	dev.state.ticks = dev.state.ticks + 1
	dev.vars.ticks = dev.state.ticks
	dev.out.lamp = inputs.switch
end
function driver.migrate(dev, old) dev.state.ticks = old.ticks end
return driver
"""


def reload_bench(args, reloads=1000, boards=100, reloaded=10, period_us=100000):
    """`reloads` hot reloads of reloadprobe (on `reloaded` of `boards` boards)."""
    import urllib.request

    def run(ctx):
        settings = {"reply_deadline_us": period_us, "realtime": "true", "watchdog_ms": max(500, 4 * period_us // 1000),
                    "discovery_period_ms": 200, "max_devices": 1024}
        settings.update(schedule_for(boards, period_us))
        host = ctx.host(drivers=ctx.drivers(benchprobe=BENCH_LUA, reloadprobe=RELOAD_LUA % 0), settings=settings)
        ctx.board("generic", "b", count=boards - reloaded, driver="benchprobe", wrapper=board_wrapper())
        ctx.board("generic", "r", count=reloaded, driver="reloadprobe", wrapper=board_wrapper())
        names = ["b-%d" % i for i in range(1, boards - reloaded + 1)] + ["r-%d" % i for i in range(1, reloaded + 1)]
        host.wait_running(names, timeout_s=120)

        def counters():
            c = host.status()["counters"]
            return c["misses"], c["drops"]

        # The reloads, then a window of the same length without any.
        m0, d0 = counters()
        latencies, failed = [], 0
        t0 = time.monotonic()
        for i in range(1, reloads + 1):
            req = urllib.request.Request("http://%s/api/drivers/reloadprobe?probation=0" % host.http,
                                         data=(RELOAD_LUA % i).encode(), method="POST")
            req.add_header("Authorization", "Bearer " + ctx.token)
            start = time.monotonic()
            try:
                with urllib.request.urlopen(req, timeout=60) as r:
                    answer = json.loads(r.read())
                ok = all(m["ok"] for m in answer["machines"]) and len(answer["machines"]) == reloaded
            except Exception:  # noqa: BLE001 (a refused reload is counted, not fatal)
                ok = False
            latencies.append(time.monotonic() - start)
            failed += not ok
            if i % 100 == 0:
                print("    %d reloads, last %.1f ms" % (i, latencies[-1] * 1e3), flush=True)
        window = time.monotonic() - t0
        m1, d1 = counters()
        time.sleep(window)  # the same window without reloads: the baseline, not a synchronisation
        m2, d2 = counters()
        latencies.sort()
        q = lambda f: latencies[min(len(latencies) - 1, int(f * len(latencies)))] * 1e3  # noqa: E731
        final = host.device("r-1", host.status())
        return {"reloads": reloads, "boards": boards, "reloaded_boards": reloaded, "period_us": period_us,
                "window_s": window, "refused": failed,
                "misses_during": m1 - m0, "drops_during": d1 - d0,
                "misses_baseline": m2 - m1, "drops_baseline": d2 - d1,
                "latency_ms": {"p50": q(0.5), "p99": q(0.99), "max": latencies[-1] * 1e3},
                "final_version": final and final["driver_version"],
                "ticks_kept": final and final["variables"].get("ticks")}
    return with_ctx(args, "reload", run)


def ui_clients(args, clients=50):
    """The same host twice (10 boards at 1 kHz): once alone, once with
    `clients` readers of GET /api/live. The clients are plain sockets read
    by one thread (a browser would be on another machine: the figure is the
    host's cost, not the clients')."""
    import selectors
    import socket

    def run(ctx, n):
        host, _ = start_kitchen(ctx, 10, 1000, 1000)
        addr, port = host.http.rsplit(":", 1)
        sel = selectors.DefaultSelector()
        counts = {}
        for i in range(n):
            sock = socket.create_connection((addr, int(port)))
            sock.sendall(("GET /api/live HTTP/1.1\r\nHost: %s\r\nAuthorization: Bearer %s\r\n\r\n" % (
                host.http, ctx.token)).encode())
            sock.setblocking(False)
            sel.register(sock, selectors.EVENT_READ, i)
            counts[i] = 0
        before = host.status()
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:  # the measurement window: read whatever comes
            for key, _ in sel.select(timeout=0.5):
                data = key.fileobj.recv(1 << 16)
                counts[key.data] += data.count(b"data: ")
        after = host.status()
        for key in list(sel.get_map().values()):
            key.fileobj.close()
        return {"clients": n, "lateness_us": after["tick"]["lateness_us"],
                "misses": after["counters"]["misses"] - before["counters"]["misses"],
                "messages_per_client_per_s": sum(counts.values()) / max(1, n) / args.seconds if n else 0,
                "realtime": after["bus"]["realtime"]}

    alone = with_ctx(args, "ui0", lambda c: run(c, 0))
    loaded = with_ctx(args, "ui%d" % clients, lambda c: run(c, clients))
    return {"alone": alone, "with_clients": loaded,
            "ratio": {"p99": loaded["lateness_us"]["p99"] / max(1, alone["lateness_us"]["p99"]),
                      "max": loaded["lateness_us"]["max"] / max(1, alone["lateness_us"]["max"])}}


def main():
    # tests/bench/fieldbus.py uses this file's helpers: imported here, not at the top.
    from fieldbus import FIELDBUS_MODES, fieldbus, report_fieldbus

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bin", default="build/bin")
    p.add_argument("--bare", default="build/bench/bare_loop")
    p.add_argument("--seconds", type=int, default=60, help="length of each measurement (default 60)")
    p.add_argument("--only",
                   default="lateness,cost,capacity,vtest,reload,ui,fieldbus,qemu,recorder,ethring,mqtt,workers,auth,"
                           "metrics,minisign,bundle,plant,sync")
    p.add_argument("--base-bin", default=None,
                   help="workers: a folder with a vmacd of the code that ran drivers on its bus thread")
    p.add_argument("--before-bin", default=None,
                   help="bundle: a build/bin folder of the code before bundles (1096c82), its reload beside")
    p.add_argument("--cpu-awake", choices=("true", "false"), default="true",
                   help="vmacd's cpu_awake where lateness is compared with cyclictest (default true: like for like)")
    p.add_argument("--max-boards", type=int, default=None,
                   help="most boards a capacity search tries (default 2000; fieldbus: 4088, max_devices' range)")
    p.add_argument("--bisect", type=int, default=3, help="bisection steps per capacity search")
    p.add_argument("--out", default="build/bench/results.json")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a vmacd setting on top of the bench's where it starts the 10-board kitchen (lateness, "
                        "cost, ui, metrics...), e.g. clock_sync_ms=1")
    args = p.parse_args()
    for kv in args.set:
        key, _, value = kv.partition("=")
        HOST_SETTINGS[key] = value
    os.environ["VMAC_BENCH_CPU_AWAKE"] = args.cpu_awake  # read by cpu_awake(), here and in fieldbus.py
    # A SIGTERM unwinds like Ctrl-C: every context's cleanup runs (the
    # fieldbus's network namespace and veth pair are removed).
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    args.logs = os.path.join(os.path.dirname(args.out) or ".", "logs")
    os.makedirs(args.logs, exist_ok=True)
    only = set(args.only.split(","))
    results = {"machine": {"cpus": os.cpu_count(), "kernel": os.uname().release}, "seconds": args.seconds}

    if "lateness" in only or "cost" in only:
        print("lateness and cost: vmacd, 10 boards at 1 kHz, %d s" % args.seconds, flush=True)
        host = with_ctx(args, "lateness", lambda c: run_host(c, 10, 1000, args.seconds))
        results["vmacd_10_at_1khz"] = host
        if "lateness" in only:
            print("lateness: cyclictest -p %d -i 1000, %d s" % (PRIORITY, args.seconds), flush=True)
            ct = cyclictest(1000, args.seconds)
            results["cyclictest_1khz"] = ct
            if "error" not in ct:
                lat = host["lateness_us"]
                results["lateness_ratio"] = {
                    "p99": lat["p99"] / max(1, ct["p99"]),
                    "max": lat["max"] / max(1, ct["max"]),
                }
        if "cost" in only:
            print("cost: bare_loop, 10 boards at 1 kHz, %d s" % args.seconds, flush=True)
            b = with_ctx(args, "bare", lambda c: bare(c, args.bare, 10, 1000, args.seconds))
            results["bare_loop_10_at_1khz"] = b
            if "error" not in b:
                results["cost_ratio"] = host["cpu_us_per_device_tick"] / max(1e-9, b["cpu_us_per_device_tick"])

    if "capacity" in only:
        results["capacity"] = []
        for rate in (1000, 100, 10):
            print("capacity at %d Hz (%d s per probe)" % (rate, args.seconds), flush=True)
            c = capacity(args, rate)
            c["thesis_table3"] = THESIS_TABLE3[rate]
            results["capacity"].append(c)

    if "vtest" in only:
        print("vtest: one virtual hour of washing, alone and in the kitchen, and of drying (best of 3)", flush=True)
        results["vtest"] = vtest(args)

    if "ui" in only:
        print("ui: 10 boards at 1 kHz, alone and with 50 web UI clients, %d s each" % args.seconds, flush=True)
        results["ui"] = ui_clients(args)

    if "fieldbus" in only:
        print("fieldbus: protocol version 2, %s" % ", ".join(FIELDBUS_MODES), flush=True)
        results["fieldbus"] = fieldbus(args)

    if "qemu" in only:
        from qemu_board import qemu
        print("qemu: the firmware in QEMU, reply time and highest rate, %d s windows" % args.seconds, flush=True)
        results["qemu"] = qemu(args)

    if "recorder" in only:
        from recorder import recorder
        print("recorder: the flight recorder and checkpoints, on next to off, %d s windows" % args.seconds, flush=True)
        results["recorder"] = recorder(args)

    if "ethring" in only:
        from ethring import ethring
        print("ethring: raw Ethernet's receive ring next to recvmmsg, %d s windows" % args.seconds, flush=True)
        results["ethring"] = ethring(args)

    if "auth" in only:
        from auth import auth
        print("auth: authenticated frames, the codec alone and host CPU keyed next to open, %d s windows" %
              args.seconds, flush=True)
        results["auth"] = auth(args)

    if "workers" in only:
        from workers import workers
        print("workers: drivers on driver workers next to --base-bin's vmacd, %d s windows" % args.seconds,
              flush=True)
        results["workers"] = workers(args)

    if "mqtt" in only:
        from mqtt_bench import mqtt
        print("mqtt: 1000 boards at 10 Hz through Mosquitto, MQTT on next to off, then the kitchen's precision "
              "throttle off next to on, %d s windows" % args.seconds, flush=True)
        results["mqtt"] = mqtt(args)
    elif "mqtt-kitchen" in only:
        from mqtt_bench import mqtt_kitchen
        print("mqtt-kitchen: the kitchen's precision throttle off next to on, %d s windows" % args.seconds, flush=True)
        results["mqtt"] = mqtt_kitchen(args)

    if "metrics" in only:
        from metrics_bench import metrics
        print("metrics: 1000 boards at 10 Hz, GET /metrics 1 and 20 times a second next to none, %d s windows" %
              args.seconds, flush=True)
        results["metrics"] = metrics(args)

    if "minisign" in only:
        from minisign_bench import minisign
        print("minisign: checking a signature, us per MiB next to BLAKE2b-512 alone", flush=True)
        results["minisign"] = minisign(args)

    if "plant" in only:
        from plant_bench import plant
        print("plant: one step of the dryer's Lua plant at 1 kHz, next to the C washer", flush=True)
        results["plant"] = plant(args)

    if "sync" in only:
        from sync_bench import sync
        print("sync: ten boards acting on one host instant by their clocks, next to on arrival (simulated); "
              "then vmacd's CPU with clock sync on next to off, alternating rounds", flush=True)
        results["sync"] = sync(args, lambda name, secs, extra: with_ctx(
            args, name, lambda c: run_host(c, 10, 1000, secs, extra=extra)))

    if "bundle" in only:
        from bundle_bench import bundle
        print("bundle: upload to switched, 100 uploads each of the washer's text, its bundle and its signed "
              "bundle, interleaved", flush=True)
        results["bundle"] = bundle(args)

    if "reload" in only:
        print("reload: 1000 hot reloads of a driver on 10 of 100 boards at 10 Hz", flush=True)
        results["reload"] = reload_bench(args)

    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(results, f, indent=2)
    report(results)
    print("\nresults: %s" % args.out)


def report(r):
    print("\n== vmac bench (%d cpus, kernel %s, %d s windows)" % (r["machine"]["cpus"], r["machine"]["kernel"],
                                                                   r["seconds"]))
    h = r.get("vmacd_10_at_1khz")
    if h:
        lat = h["lateness_us"]
        print("vmacd tick lateness, 10 boards at 1 kHz: p50 %d us, p99 %d us, p99.9 %d us, max %d us "
              "(%s; %d misses)" % (lat["p50"], lat["p99"], lat["p999"], lat["max"],
                                   "SCHED_FIFO" if h["realtime"] else "normal scheduling", h["misses"]))
    ct = r.get("cyclictest_1khz")
    if ct:
        if "error" in ct:
            print("cyclictest: %s" % ct["error"])
        else:
            print("cyclictest at 1 kHz:                  p50 %d us, p99 %d us, p99.9 %d us, max %d us" % (
                ct["p50"], ct["p99"], ct["p999"], ct["max"]))
    if "lateness_ratio" in r:
        print("ratio vmacd / cyclictest: p99 %.2f, max %.2f" % (r["lateness_ratio"]["p99"],
                                                                  r["lateness_ratio"]["max"]))
    b = r.get("bare_loop_10_at_1khz")
    if h and not h.get("comparable", True):
        print("  NOT COMPARABLE: the boards missed %d times in that window (the host %d); the host's figures of "
              "that window measure the boards" % (h["misses"] - h["misses_host"], h["misses_host"]))
    if h and b and "error" not in b:
        print("host CPU per device per tick: vmacd %.2f us, bare loop %.2f us, ratio %.2f%s" % (
            h["cpu_us_per_device_tick"], b["cpu_us_per_device_tick"], r["cost_ratio"],
            "" if h.get("comparable", True) else " (not comparable: the boards missed)"))
    for c in r.get("capacity", []):
        print("capacity at %4d Hz: %5d boards with zero misses (thesis Table 3: %d)%s" % (
            c["rate_hz"], c["max_boards"], c["thesis_table3"],
            "; %d failed" % c["first_failing"] if c.get("first_failing") else " " + c.get("limit", "")))
    v = r.get("vtest")
    if v:
        if "error" in v:
            print("vmac test: %s" % v["error"])
        for name, wall in sorted(v.get("wall_s", {}).items()):
            print("vmac test, %s: 1 virtual hour in %.2f s of wall time (%.0fx real time)" % (
                name, wall, v["virtual_s"] / max(1e-9, wall)))
        if v.get("lua_plant_ratio"):
            print("vmac test, the dryer's hour (Lua plant) over the washer's (C plant): %.2f (goal: at most 2)" % (
                v["lua_plant_ratio"]))
    u = r.get("ui")
    if u:
        a, w = u["alone"]["lateness_us"], u["with_clients"]["lateness_us"]
        print("tick lateness, 10 boards at 1 kHz: alone p50 %d, p99 %d, p99.9 %d, max %d us; with %d web UI clients "
              "(%.1f messages/s each) p50 %d, p99 %d, p99.9 %d, max %d us; ratio p99 %.2f, max %.2f; misses %d / %d" % (
                  a["p50"], a["p99"], a["p999"], a["max"], u["with_clients"]["clients"],
                  u["with_clients"]["messages_per_client_per_s"], w["p50"], w["p99"], w["p999"], w["max"],
                  u["ratio"]["p99"], u["ratio"]["max"], u["alone"]["misses"], u["with_clients"]["misses"]))
    rl = r.get("reload")
    if rl:
        print("hot reload: %d reloads of a driver on %d of %d boards at %d Hz in %.1f s: %d misses, %d drops "
              "(the same window without reloads: %d misses, %d drops); %d refused; latency p50 %.1f ms, "
              "p99 %.1f ms, max %.1f ms (request to all %d switched); last version %s, tick count kept %s" % (
                  rl["reloads"], rl["reloaded_boards"], rl["boards"], 1000000 // rl["period_us"], rl["window_s"],
                  rl["misses_during"], rl["drops_during"], rl["misses_baseline"], rl["drops_baseline"],
                  rl["refused"], rl["latency_ms"]["p50"], rl["latency_ms"]["p99"], rl["latency_ms"]["max"],
                  rl["reloaded_boards"], rl["final_version"], rl["ticks_kept"]))

    fb = r.get("fieldbus")
    if fb:
        from fieldbus import report_fieldbus
        report_fieldbus(fb)
    if r.get("qemu"):
        from qemu_board import report_qemu
        report_qemu(r["qemu"])
    if r.get("recorder"):
        from recorder import report_recorder
        report_recorder(r["recorder"])
    if r.get("ethring"):
        from ethring import report_ethring
        report_ethring(r["ethring"])
    if r.get("auth"):
        from auth import report_auth
        report_auth(r["auth"])
    if r.get("mqtt"):
        from mqtt_bench import report_mqtt
        report_mqtt(r["mqtt"])
    if r.get("workers"):
        from workers import report_workers
        report_workers(r["workers"])
    if r.get("metrics"):
        from metrics_bench import report_metrics
        report_metrics(r["metrics"])
    if r.get("minisign"):
        from minisign_bench import report_minisign
        report_minisign(r["minisign"])
    if r.get("plant"):
        from plant_bench import report_plant
        report_plant(r["plant"])
    if r.get("sync"):
        from sync_bench import report_sync
        report_sync(r["sync"])
    if r.get("bundle"):
        from bundle_bench import report_bundle
        report_bundle(r["bundle"])


if __name__ == "__main__":
    main()
