"""make bench, recorder: what the flight recorder (docs/RECORDING.md,
recorder_s) and periodic checkpoints (docs/DRIVERS.md "Recovery after a
restart", checkpoint_s) cost the host, each next to the same host with it
off, in one run. Run through bench.py (--only recorder); the helpers are
bench.py's and fieldbus.py's.

  cost    host CPU per device per tick, 100 boards at 100 Hz over udp-cyclic
          (the default bus, the cheapest in fieldbus.py): recorder_s=60
          and checkpoint_s=1 (each alone), next to both off; the three run
          in turn, 3 to 5 rounds, each ratio taken within its round, on
          vmacd's on-CPU time (schedstat) as well as utime+stime
  memory  vmacd's VmRSS with 1,000 boards at 10 Hz, recorder_s=60 next to
          recorder_s=0: MiB, MiB per machine, and whether it moves: 20 and
          30 s after every board runs, and again once every ring has
          wrapped (recorder_s after attach; vmacd with realtime locks its
          memory, so a ring is resident from its allocation)"""

import os
import sqlite3
import statistics
import time

from bench import board_wrapper, cpu_seconds, schedule_for, with_ctx
from fieldbus import MAX_DEVICES_DEFAULT, fresh_status, others_running, run_seconds, wait_attached

# A driver with a little state, as an appliance keeps (its programme, its
# step, a count): periodic checkpoints encode dev.state, and an empty one
# would cost next to nothing. The same driver in every configuration.
RECPROBE_LUA = """local driver = { name = "recprobe", version = "1", io = { switch = "di0", lamp = "do0" },
	variables = { lamp = {} } }
function driver.attach(dev)
	dev.state.programme = "cotton 40"
	dev.state.step = "wash"
	dev.state.step_started = 0
	dev.state.ticks = 0
	dev.state.lamp = false
	dev.state.temperatures = { 20.5, 21.0, 21.5, 22.0 }
end
function driver.tick(dev, inputs)
	local s = dev.state
	s.ticks = s.ticks + 1
	s.lamp = inputs.switch
	dev.out.lamp = inputs.switch
	dev.vars.lamp = inputs.switch
end
return driver
"""

# The configurations of the cost part: name -> the settings that differ.
COST_CONFIGS = (("off", {"recorder_s": 0, "checkpoint_s": 0}),
                ("recorder", {"recorder_s": 60, "checkpoint_s": 0}),
                ("checkpoints", {"recorder_s": 0, "checkpoint_s": 1}))
ROUNDS_MIN, ROUNDS_MAX = 3, 5  # 5 rounds of 10 s windows, 3 of 60 s (make bench)
COST_BOARDS, COST_PERIOD_US = 100, 10000
MEM_BOARDS, MEM_PERIOD_US, MEM_RECORDER_S = 1000, 100000, 60
MEM_SAMPLES_S = (20, 30)  # after every board runs: the two samples 10 s apart
MEM_AFTER_WRAP_S = (5, 15)  # and these after recorder_s, when every ring has wrapped


def proc_status_kib(pid, key):
    """A 'kB' line of /proc/PID/status (VmRSS, VmHWM), in KiB."""
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return None


def proc_io(pid):
    """write_bytes (to the disk) and syscw of /proc/PID/io: the store's writes."""
    out = {}
    with open("/proc/%d/io" % pid) as f:
        for line in f:
            k, v = line.split(":")
            out[k] = int(v)
    return out


def checkpoint_ages(logdir):
    """Seconds since each machine's newest checkpoint in the host's store
    (vmac.db in its state folder, read-only): proof that they are written,
    and how often. [] when there are none."""
    path = os.path.join(logdir, "vmac.db")
    if not os.path.exists(path):
        return []
    db = sqlite3.connect("file:%s?mode=ro" % path, uri=True, timeout=5)
    try:
        rows = db.execute("SELECT time FROM checkpoints").fetchall()
    finally:
        db.close()
    now = time.time()
    return sorted(now - t for (t,) in rows)


def kitchen(ctx, boards, period_us, settings):
    """vmacd and one vmac-board --count `boards` running recprobe over UDP
    (cyclic, the default), every board running; returns the host."""
    values = {"reply_deadline_us": period_us, "realtime": "true",
              "watchdog_ms": max(500, 4 * period_us // 1000), "discovery_period_ms": 200,
              "max_devices": max(MAX_DEVICES_DEFAULT, boards + 8)}
    values.update(schedule_for(boards, period_us))
    values.update(settings)
    host = ctx.host(drivers=ctx.drivers(recprobe=RECPROBE_LUA), settings=values)
    ctx.board("generic", "b", count=boards, driver="recprobe", wrapper=board_wrapper(),
              extra=("--late-us", str(period_us)))
    wait_attached(host, boards, timeout_s=30 + boards / 50)
    return host


def cost_run(ctx, name, settings, seconds):
    """COST_BOARDS boards at COST_PERIOD_US for `seconds` of steady state
    with `settings`: vmacd's CPU per device per tick over that window."""
    host = kitchen(ctx, COST_BOARDS, COST_PERIOD_US, settings)
    before = fresh_status(host)
    cpu0, run0, io0, t0 = cpu_seconds(host.pid), run_seconds(host.pid), proc_io(host.pid), time.monotonic()
    time.sleep(seconds)  # the measurement window itself, not a synchronisation
    after = fresh_status(host)
    cpu1, run1, io1, t1 = cpu_seconds(host.pid), run_seconds(host.pid), proc_io(host.pid), time.monotonic()
    ages = checkpoint_ages(ctx.logdir)
    ticks = after["tick"]["count"] - before["tick"]["count"]
    device_ticks = max(1, ticks * COST_BOARDS)
    return {
        "config": name, "settings": settings, "boards": COST_BOARDS, "period_us": COST_PERIOD_US,
        "seconds": seconds, "ticks": ticks,
        "misses": after["counters"]["misses"] - before["counters"]["misses"],
        "misses_host": after["counters"].get("misses_host", 0) - before["counters"].get("misses_host", 0),
        "drops": after["counters"]["drops"] - before["counters"]["drops"],
        "running_at_end": sum(1 for d in after["devices"] if d["state"] == "running"),
        "lateness_us": after["tick"]["lateness_us"],
        "cpu_us_per_device_tick": (cpu1 - cpu0) * 1e6 / device_ticks,
        "run_us_per_device_tick": (run1 - run0) * 1e6 / device_ticks,
        "host_cpu_share": (cpu1 - cpu0) / (t1 - t0),
        "rss_mib_at_end": proc_status_kib(host.pid, "VmRSS") / 1024,
        "disk_write_kib_per_s": (io1["write_bytes"] - io0["write_bytes"]) / 1024 / (t1 - t0),
        "write_calls_per_s": (io1["syscw"] - io0["syscw"]) / (t1 - t0),
        "checkpointed_machines": len(ages),
        "checkpoint_age_s": {"p50": statistics.median(ages), "max": ages[-1]} if ages else None,
    }


def memory_run(ctx, recorder_s):
    """MEM_BOARDS boards at MEM_PERIOD_US with recorder_s: vmacd's VmRSS at
    MEM_SAMPLES_S after the last board runs, then MEM_AFTER_WRAP_S after
    recorder_s (every ring wrapped), the same times whether on or off."""
    t_start = time.monotonic()
    host = kitchen(ctx, MEM_BOARDS, MEM_PERIOD_US, {"recorder_s": recorder_s, "checkpoint_s": 0})
    t0 = time.monotonic()
    attach_s = t0 - t_start
    rss0 = proc_status_kib(host.pid, "VmRSS")
    before = host.status()
    at = list(MEM_SAMPLES_S) + [MEM_RECORDER_S + s for s in MEM_AFTER_WRAP_S]
    samples = []
    for s in at:
        time.sleep(max(0.0, t0 + s - time.monotonic()))  # until the sample's time after all ran
        samples.append({"after_s": s, "rss_kib": proc_status_kib(host.pid, "VmRSS")})
        print("      recorder_s=%d, %2d s after all %d ran: VmRSS %.1f MiB" % (
            recorder_s, s, MEM_BOARDS, samples[-1]["rss_kib"] / 1024), flush=True)
    after = host.status()
    return {
        "recorder_s": recorder_s, "boards": MEM_BOARDS, "period_us": MEM_PERIOD_US,
        "attach_s": attach_s, "rss_kib_all_running": rss0, "samples": samples,
        "hwm_kib": proc_status_kib(host.pid, "VmHWM"),
        "misses": after["counters"]["misses"] - before["counters"]["misses"],
        "drops": after["counters"]["drops"] - before["counters"]["drops"],
        "running_at_end": sum(1 for d in after["devices"] if d["state"] == "running"),
        "host_cpu_s": cpu_seconds(host.pid),
    }


def guarded(args, name, fn):
    """fn(ctx) in a fresh context, or {"error": ...}: one configuration
    failing never stops the others."""
    try:
        return with_ctx(args, name, fn)
    except AssertionError as e:  # boards that did not start or attach
        return {"error": str(e)[:300]}
    except Exception as e:  # noqa: BLE001 (a program that died, a refused setting)
        return {"error": "%s: %s" % (type(e).__name__, str(e)[:300])}


def recorder(args):
    """The cost part then the memory part, one run."""
    t_start = time.monotonic()
    others = others_running()
    if others:
        print("    note: already running here, sharing the CPUs: %s%s" % (
            ", ".join(others[:8]), " and %d more" % (len(others) - 8) if len(others) > 8 else ""), flush=True)
    out = {"others_at_start": others, "loadavg_at_start": open("/proc/loadavg").read().split()[:3],
           "rounds": []}

    # 1. CPU: the three configurations in turn, in 3 to 5 rounds, so that
    # each ratio compares runs under a minute apart, not the start of the
    # bench with its end; each round starts with the next configuration, so
    # that none always runs first.
    rounds = max(ROUNDS_MIN, min(ROUNDS_MAX, 100 // max(1, args.seconds)))
    for rnd in range(1, rounds + 1):
        row = {}
        first = (rnd - 1) % len(COST_CONFIGS)
        for name, settings in COST_CONFIGS[first:] + COST_CONFIGS[:first]:
            print("recorder cost, round %d/%d: %s (%s), %d boards at %d Hz, %d s" % (
                rnd, rounds, name, ", ".join("%s=%s" % kv for kv in sorted(settings.items())), COST_BOARDS,
                1000000 // COST_PERIOD_US, args.seconds), flush=True)
            r = guarded(args, "rec-cost-%s-%d" % (name, rnd), lambda c: cost_run(c, name, settings, args.seconds))
            if "error" in r:
                print("    FAILED: %s" % r["error"], flush=True)
            else:
                print("    %.3f us per device per tick on the CPU (utime+stime %.2f), vmacd %.0f%% of a CPU, "
                      "%d misses, %d drops, VmRSS %.1f MiB, disk writes %.0f KiB/s%s" % (
                          r["run_us_per_device_tick"], r["cpu_us_per_device_tick"], 100 * r["host_cpu_share"],
                          r["misses"], r["drops"], r["rss_mib_at_end"], r["disk_write_kib_per_s"],
                          ", %d machines checkpointed, newest %.1f s old at most" % (
                              r["checkpointed_machines"], r["checkpoint_age_s"]["max"])
                          if r["checkpoint_age_s"] else ""), flush=True)
            row[name] = r
        out["rounds"].append(row)

    def ratios(name, key):
        return [rw[name][key] / rw["off"][key] for rw in out["rounds"]
                if key in rw[name] and key in rw["off"] and rw["off"][key] > 0]

    # The ratio is taken on the on-CPU time (schedstat, nanoseconds): vmacd
    # uses a few percent of a CPU, and utime+stime, in 10 ms clock ticks,
    # would be a few dozen ticks per 10 s window: too coarse for a few percent.
    out["ratio"] = {}
    for name, _ in COST_CONFIGS[1:]:
        run, cpu = ratios(name, "run_us_per_device_tick"), ratios(name, "cpu_us_per_device_tick")
        out["ratio"][name] = {"on_cpu": run, "on_cpu_median": statistics.median(run) if run else None,
                              "utime_stime": cpu, "utime_stime_median": statistics.median(cpu) if cpu else None}

    # 2. Memory: 1,000 machines, recorder on and off, the same timeline.
    out["memory"] = {}
    for recorder_s in (MEM_RECORDER_S, 0):
        print("recorder memory: recorder_s=%d, %d boards at %d Hz, samples at %s s after all run" % (
            recorder_s, MEM_BOARDS, 1000000 // MEM_PERIOD_US,
            ", ".join(str(s) for s in list(MEM_SAMPLES_S) + [MEM_RECORDER_S + s for s in MEM_AFTER_WRAP_S])),
            flush=True)
        r = guarded(args, "rec-mem-%d" % recorder_s, lambda c: memory_run(c, recorder_s))
        if "error" in r:
            print("    FAILED: %s" % r["error"], flush=True)
        out["memory"]["on" if recorder_s else "off"] = r
    out["elapsed_s"] = time.monotonic() - t_start
    out["loadavg_at_end"] = open("/proc/loadavg").read().split()[:3]
    return out


def report_recorder(r):
    print("\nflight recorder and checkpoints, host CPU per device per tick (vmacd's on-CPU time from schedstat / "
          "(ticks x devices); utime+stime in brackets), %d boards at %d Hz, udp-cyclic:" % (
              COST_BOARDS, 1000000 // COST_PERIOD_US))
    print("  %-6s %-28s %-28s %-28s" % ("round", *(n for n, _ in COST_CONFIGS)))
    for i, rw in enumerate(r["rounds"], 1):
        cells = []
        for name, _ in COST_CONFIGS:
            x = rw[name]
            cells.append("FAILED" if "error" in x else "%.3f us (%.2f), %d misses" % (
                x["run_us_per_device_tick"], x["cpu_us_per_device_tick"], x["misses"]))
        print("  %-6d %-28s %-28s %-28s" % (i, *cells))
    for name, settings in COST_CONFIGS[1:]:
        q = r["ratio"][name]
        if q["on_cpu_median"] is None:
            print("  %s / off: no figure (a run failed)" % name)
            continue
        print("  %-11s / off: %.3f, median of the rounds' %s (utime+stime: %.3f, rounds %s)" % (
            name, q["on_cpu_median"], ", ".join("%.3f" % x for x in q["on_cpu"]), q["utime_stime_median"],
            ", ".join("%.3f" % x for x in q["utime_stime"])))
    ck = [rw["checkpoints"] for rw in r["rounds"] if "error" not in rw["checkpoints"]]
    off = [rw["off"] for rw in r["rounds"] if "error" not in rw["off"]]
    if ck and off:
        print("  checkpoint_s=1: disk writes %s KiB/s (off: %s), %d of %d machines checkpointed, newest at most "
              "%.1f s old" % ("/".join("%.0f" % x["disk_write_kib_per_s"] for x in ck),
                              "/".join("%.0f" % x["disk_write_kib_per_s"] for x in off),
                              ck[-1]["checkpointed_machines"], COST_BOARDS,
                              max(x["checkpoint_age_s"]["max"] for x in ck if x["checkpoint_age_s"])))
    print("  goal (issue 21): the recorder costs at most a few percent")
    m = r.get("memory", {})
    on, off = m.get("on"), m.get("off")
    print("flight recorder memory, vmacd VmRSS, %d boards at %d Hz (one machine each):" % (
        MEM_BOARDS, 1000000 // MEM_PERIOD_US))
    for label, x in (("recorder_s=%d" % MEM_RECORDER_S, on), ("recorder_s=0", off)):
        if not x:
            continue
        if "error" in x:
            print("  %-14s FAILED: %s" % (label, x["error"]))
            continue
        s = x["samples"]
        print("  %-14s %s; %.1f KiB per machine at %d s; %d misses, %d drops, %d running at the end (attach %.0f s)" % (
            label, ", ".join("%d s %.1f MiB" % (p["after_s"], p["rss_kib"] / 1024) for p in s),
            s[0]["rss_kib"] / x["boards"], s[0]["after_s"], x["misses"], x["drops"], x["running_at_end"],
            x["attach_s"]))
    if on and off and "error" not in on and "error" not in off:
        diff = [(a["after_s"], (a["rss_kib"] - b["rss_kib"]) / 1024) for a, b in zip(on["samples"], off["samples"])]
        print("  the recorder's part (on - off): %s; per machine %s KiB" % (
            ", ".join("%d s %.1f MiB" % d for d in diff),
            "/".join("%.1f" % (d[1] * 1024 / MEM_BOARDS) for d in diff)))
        for label, x in (("on", on), ("off", off)):
            s = x["samples"]
            print("  growth, recorder %-3s: %d to %d s %+.1f MiB; %d to %d s (every ring wrapped) %+.1f MiB" % (
                label, s[0]["after_s"], s[1]["after_s"], (s[1]["rss_kib"] - s[0]["rss_kib"]) / 1024,
                s[2]["after_s"], s[3]["after_s"], (s[3]["rss_kib"] - s[2]["rss_kib"]) / 1024))
    print("recorder: %.0f s in all; load average %s at the start, %s at the end%s" % (
        r["elapsed_s"], "/".join(r["loadavg_at_start"]), "/".join(r["loadavg_at_end"]),
        "; %d programs of ours already running (%s)" % (len(r["others_at_start"]), ", ".join(r["others_at_start"][:4]))
        if r["others_at_start"] else ""))
