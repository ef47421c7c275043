"""make bench, workers: drivers on driver workers (docs/HOST.md, "Threads
and time") next to a vmacd that runs them on its bus thread (--base-bin: a
build of the code before, e.g. `git worktree add /tmp/base ec76250 && make
-C /tmp/base`), in alternating rounds of one run:

  cost      host CPU per device per tick, 100 boards at 1 kHz, eth-cyclic
            and udp-cyclic, the light benchprobe driver: workers / base
  burn      tick lateness p99 with 100 boards every 64 ms in 1 ms slots
            whose drivers each burn about 200 us of CPU per tick, next to
            the same boards with the light driver: how much the bus's
            lateness grows with driver work, workers and base
  threads   100 boards every 16 ms whose drivers burn about 200 us a tick
            (1.25 CPUs of driver work), driver_threads 1 next to 2 (no
            base): ticks whose outputs came late (driver_late), served
            ratio, host CPU

Run through bench.py (--only workers --base-bin DIR). VMAC_BENCH_WORKERS
(e.g. "cost") runs only the parts it names, VMAC_BENCH_ROUNDS that many
rounds (3): the cost alone, repeated, while changing the hand-over."""

import os
import statistics
import tempfile

from fieldbus import fieldbus_run
from harness import Context, Skip

ROUNDS = int(os.environ.get("VMAC_BENCH_ROUNDS", "3"))
PARTS = os.environ.get("VMAC_BENCH_WORKERS", "cost,burn,threads").split(",")

# About 200 us of interpreted Lua per tick on this machine (the JIT is off
# in the sandbox); the measured CPU per device per tick says what it was.
BURN_LUA = """local driver = { name = "burner", version = "1", io = { switch = "di0", lamp = "do0" },
	variables = { lamp = {} } }
function driver.tick(dev, inputs)
	local x = 0
	for i = 1, 40000 do x = x + i % 7 end
	dev.out.lamp = inputs.switch and x > 0
	dev.vars.lamp = inputs.switch
end
return driver
"""
BURN_SETTINGS = {"driver.burner.instructions": 10000000, "driver.burner.budget_us": 0}
# 100 boards every 64 ms in 1 ms slots (level 6: one or two boards a
# slot), so that the drivers' work of a slot falls between two ticks.
BURN_PERIOD_US = 64000
BURN_SCHEDULE = {"slice_us": 100, "slices_per_slot": 10, "default_level": 6, "max_level": 6}
BURN = ("burner", BURN_LUA, dict(BURN_SETTINGS, **BURN_SCHEDULE))
LIGHT = ("benchprobe", None, BURN_SCHEDULE)
LIGHT_OPEN = ("benchprobe", None, {"bus_trust": "open"})


def bindir_with(base_vmacd, bindir):
    """A folder whose vmacd is base_vmacd and whose vmac-board is this
    build's: the same boards, only the host differs. Its vmac is the base's
    when there is one beside base_vmacd: it makes the state folder (vmac
    board enroll --local), whose database the base vmacd must be able to
    read (a newer schema it refuses)."""
    d = tempfile.mkdtemp(prefix="vmac-bench-base-bin-")
    os.symlink(os.path.abspath(base_vmacd), os.path.join(d, "vmacd"))
    base_vmac = os.path.join(os.path.dirname(base_vmacd), "vmac")
    os.symlink(os.path.abspath(base_vmac if os.path.exists(base_vmac) else os.path.join(bindir, "vmac")),
               os.path.join(d, "vmac"))
    os.symlink(os.path.abspath(os.path.join(bindir, "vmac-board")), os.path.join(d, "vmac-board"))
    return d


def run_with(args, bindir, name, fn):
    logdir = tempfile.mkdtemp(prefix="vmac-bench-%s-" % name, dir=args.logs)
    ctx = Context(bindir, logdir)
    try:
        return fn(ctx)
    finally:
        ctx.cleanup()


def pick(r):
    return {k: r[k] for k in ("cpu_us_per_device_tick", "misses", "misses_host", "drops", "lateness_us",
                              "served_ratio", "driver_late", "ticks", "boards")}


def workers(args):
    if not args.base_bin:
        print("    workers: SKIPPED: no --base-bin (a build of the code that ran drivers on the bus thread)",
              flush=True)
        return {"skipped": "no --base-bin"}
    base = bindir_with(os.path.join(args.base_bin, "vmacd"), args.bin)
    out = {"cost": [], "burn": [], "threads": []}
    for rnd in range(ROUNDS):
        for mode in ("eth-cyclic", "udp-cyclic") if "cost" in PARTS else ():
            row = {"mode": mode}
            try:
                for which, bindir in (("base", base), ("workers", args.bin)):
                    # Unkeyed boards for both: the base knows no keys; this
                    # build then needs bus_trust open (the base no such setting).
                    drv = LIGHT_OPEN if which == "workers" else None
                    r = run_with(args, bindir, "workers-cost-%s-%s-%d" % (which, mode, rnd),
                                 lambda c: fieldbus_run(c, mode, 100, 1000, args.seconds, drv, keyed=False))
                    row[which] = pick(r)
                    print("    round %d %-10s %-7s %.3f us per device per tick, %d misses (%d the host's), "
                          "%d of %d ticks driver_late" % (
                              rnd + 1, mode, which, r["cpu_us_per_device_tick"], r["misses"], r["misses_host"],
                              r["driver_late"], r["ticks"] * r["boards"]), flush=True)
            except Skip as e:
                print("    %s: SKIPPED: %s" % (mode, e), flush=True)
                continue
            row["ratio"] = row["workers"]["cpu_us_per_device_tick"] / max(1e-9, row["base"]["cpu_us_per_device_tick"])
            out["cost"].append(row)
        if "burn" not in PARTS:
            continue
        row = {}
        for which, bindir in (("base", base), ("workers", args.bin)):
            for load, driver in (("light", LIGHT), ("burn", BURN)):
                if which == "workers":  # unkeyed, as in the cost part
                    driver = driver[:2] + (dict(driver[2], bus_trust="open"),)
                r = run_with(args, bindir, "workers-burn-%s-%s-%d" % (which, load, rnd),
                             lambda c: fieldbus_run(c, "udp-cyclic", 100, BURN_PERIOD_US, args.seconds, driver,
                                                    keyed=False))
                row["%s_%s" % (which, load)] = pick(r)
                print("    round %d burn %-7s %-5s lateness p99 %d us, max %d us, %.1f us CPU per device per tick, "
                      "%d misses" % (rnd + 1, which, load, r["lateness_us"]["p99"], r["lateness_us"]["max"],
                                     r["cpu_us_per_device_tick"], r["misses"]), flush=True)
        for which in ("base", "workers"):
            row["%s_growth_p99" % which] = (row["%s_burn" % which]["lateness_us"]["p99"] /
                                            max(1, row["%s_light" % which]["lateness_us"]["p99"]))
        out["burn"].append(row)
    for threads in (1, 2) if "threads" in PARTS else ():
        drv = ("burner", BURN_LUA, dict(BURN_SETTINGS, driver_threads=threads, slice_us=100, slices_per_slot=10,
                                        default_level=4, max_level=4))
        try:
            r = run_with(args, args.bin, "workers-threads-%d" % threads,
                         lambda c: fieldbus_run(c, "udp-cyclic", 100, 16000, args.seconds, drv))
        except (Skip, AssertionError) as e:
            out["threads"].append({"threads": threads, "error": str(e)[:300]})
            continue
        out["threads"].append(dict(pick(r), threads=threads, driver_late=r["driver_late"], ticks=r["ticks"]))
        print("    burners x100 every 16 ms, driver_threads %d: %d late ticks in %d, served %.3f, "
              "%.1f us CPU per device per tick, %d misses" % (threads, r["driver_late"], r["ticks"] * 100 // 16,
                                                             r["served_ratio"], r["cpu_us_per_device_tick"],
                                                             r["misses"]), flush=True)
    for mode in ("eth-cyclic", "udp-cyclic"):
        ratios = [r["ratio"] for r in out["cost"] if r["mode"] == mode]
        if ratios:
            out["cost_ratio_median_" + mode] = statistics.median(ratios)
    if out["burn"]:
        out["burn_growth_median"] = {w: statistics.median(r["%s_growth_p99" % w] for r in out["burn"])
                                     for w in ("base", "workers")}
    return out


def report_workers(w):
    if w.get("skipped"):
        print("workers: SKIPPED: %s" % w["skipped"])
        return
    for mode in ("eth-cyclic", "udp-cyclic"):
        if "cost_ratio_median_" + mode in w:
            print("drivers on workers / on the bus thread, host CPU per device per tick, 100 boards at 1 kHz %s: "
                  "median %.2f (%s)" % (mode, w["cost_ratio_median_" + mode], ", ".join(
                      "%.2f" % r["ratio"] for r in w["cost"] if r["mode"] == mode)))
    if "burn_growth_median" in w:
        g = w["burn_growth_median"]
        print("tick lateness p99 with drivers burning ~200 us / with light drivers, 100 boards every 64 ms: "
              "on the bus thread %.2f, on workers %.2f" % (g["base"], g["workers"]))
    for t in w.get("threads", []):
        if "error" in t:
            print("burners x100 every 16 ms, driver_threads %d: %s" % (t["threads"], t["error"]))
        else:
            print("burners x100 every 16 ms, driver_threads %d: %d driver ticks late of %d, served %.3f, "
                  "%.1f us CPU per device per tick, %d misses" % (
                      t["threads"], t["driver_late"], t["ticks"] * 100 // 16, t["served_ratio"],
                      t["cpu_us_per_device_tick"], t["misses"]))
