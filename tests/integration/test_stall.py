"""No driver can hold the bus (docs/DRIVERS.md "Isolation", docs/HOST.md
"Threads"): every call into a driver runs on a driver worker, and a call
that runs past its limit (a tick past its period, an input or a take-over
past its budget) is judged by the bus thread, not by the driver: the
driver fails, named with what it was doing, its board is told to go safe,
its worker is given up, and the machines beside it never notice. Each
staller here spends seconds inside library calls the instruction budget
cannot interrupt (its host gives it a billion instructions and no
wall-clock budget, so that nothing but the bus's judgement stops it)."""

import json
import os
import re
import signal
import sys
import threading
import time

from harness import Skip, post, undisturbed
from threads import threads

NEIGHBOURS = ["lights-1", "washer-1"]

# Seconds of string.find calls, each one a C call of about a millisecond
# over a 60 KB string, from where the trigger says.
STALLER = """-- %(name)s: stalls its worker in %(where)s
local driver = { name = "%(name)s", version = "%(version)s", level = 0,
	io = { lamp = "do0" }, variables = { v = {} },
	commands = { go = {} } }
local s = string.rep("a", 60000)
local function stall()
	local n = 0
	for _ = 1, %(rounds)d do
		if string.find(s, "a.b") then n = n + 1 end
	end
	return n
end
function driver.tick(dev, inputs)
	dev.out.lamp = true
	dev.vars.v = %(tick)s
end
function driver.input(dev, name, value)
	%(input)s
	return true
end
function driver.migrate(dev, old)
	%(migrate)s
end
function driver.detach(dev)
	%(detach)s
end
return driver
"""


def staller(name, where, version="1", rounds=3000):
    return STALLER % {
        "name": name, "where": where, "version": version, "rounds": rounds,
        "tick": "stall()" if where == "tick" else "1",
        "input": "dev:event('stalling') stall()" if where == "input" else "",
        "migrate": "stall()" if where == "migrate" else "",
        "detach": "stall() stall()" if where == "detach" else "",
    }


def settings(*names):
    s = {"sleep_s": 1}
    for n in names:
        s["driver.%s.instructions" % n] = 1000000000
        s["driver.%s.budget_us" % n] = 0
    return s


def neighbours(t, host):
    t.board("lights", "lights-1")
    t.board("washer", "washer-1")
    host.wait_running(NEIGHBOURS)


def lamp_never_on(board, name):
    lines = board.find_lines(r"outputs digital=")
    assert not lines or "digital=0x00 pwm=0" in lines[-1].text, "%s left an output on: %s" % (
        name, lines[-1].text)


def test_a_stalled_tick_fails_its_driver_and_no_one_else_notices(t):
    host = t.host(drivers=t.drivers(staller=staller("staller", "tick")), settings=settings("staller"))
    neighbours(t, host)
    board = t.board("generic", "stall-1", driver="staller")
    quiet = undisturbed(NEIGHBOURS)
    e = host.wait_event("driver_error", "stall-1", "stalled", timeout_s=30, invariant=quiet)
    assert "tick still running after" in e["text"] and "string.find" in e["text"], (
        "the stall is not named with what the driver was doing: %r" % e["text"])
    host.wait_event("dropped", "stall-1", "its driver stalled", timeout_s=10, invariant=quiet)
    board.wait_line(r"^stall-1: state (unknown|sleeping) ", 10, what="stall-1 told to go safe")
    lamp_never_on(board, "stall-1")
    # When it announces itself again, the version that stalled is not loaded.
    e = host.wait_event("driver_error", "stall-1", "not loaded again until a new version", timeout_s=30,
                        invariant=quiet)
    served = {n: host.device(n)["served"] for n in NEIGHBOURS}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 20 for n in NEIGHBOURS), 30,
                     "the neighbours served on", quiet)
    lateness = host.status()["tick"]["lateness_us"]["max"]
    assert lateness < 1000000, "the bus thread was held for %d us while a driver stalled" % lateness
    host.signal(signal.SIGTERM)
    rc = host.wait_exit(10)
    assert rc == 0, "vmacd exited with %r when stopped: %s" % (rc, host.text()[-600:])


def test_many_machines_stalling_at_once_leave_the_neighbours_running(t):
    """Ten machines whose drivers stall their ticks all at once, on a host
    with one driver worker: each stuck worker is given up and a new one
    takes the rest, more than the host had room for before (eight), and
    the lights, the washer beside them never notice (DRIVERS.md,
    "Isolation")."""
    names = ["st%d" % i for i in range(10)]
    drivers = {n: staller(n, "tick", rounds=1500) for n in names}
    host = t.host(drivers=t.drivers(**drivers), settings=dict(settings(*names), driver_threads=1))
    neighbours(t, host)
    quiet = undisturbed(NEIGHBOURS)
    for n in names:
        t.board("generic", n + "-1", driver=n)
    host.wait_status(lambda s: len(host.find_events("dropped", text="its driver stalled")) == len(names), 60,
                     "all ten stalled machines dropped", quiet)
    short = host.find_events("dropped", text="short of workers")
    assert not short, "machines dropped for want of a worker: %r" % [e["text"] for e in short]
    served = {n: host.device(n)["served"] for n in NEIGHBOURS}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 20 for n in NEIGHBOURS), 30,
                     "the neighbours served on", quiet)


def test_a_stall_in_detach_does_not_hold_up_the_stop(t):
    host = t.host(drivers=t.drivers(stopper=staller("stopper", "detach")), settings=settings("stopper"))
    neighbours(t, host)
    board = t.board("generic", "stop-1", driver="stopper")
    host.wait_running(["stop-1"])
    host.signal(signal.SIGTERM)
    rc = host.wait_exit(10)
    assert rc == 0, "vmacd exited with %r: %s" % (rc, host.text()[-600:])
    board.wait_line(r"^stop-1: state (unknown|sleeping) ", 10, what="stop-1 told to go safe")


def test_a_stall_in_input_answers_the_operator_and_drops_only_its_machine(t):
    host = t.host(drivers=t.drivers(inputter=staller("inputter", "input")), settings=settings("inputter"))
    neighbours(t, host)
    t.board("generic", "in-1", driver="inputter")
    host.wait_running(["in-1"])
    code, text = post(host, "/api/devices/in-1/input", t.token, json.dumps({"name": "go", "value": True}).encode())
    assert code == 502 and "input still running after" in text, (
        "the stalled input was answered %d %s" % (code, text[:300]))
    quiet = undisturbed(NEIGHBOURS)
    host.wait_event("dropped", "in-1", "its driver stalled", timeout_s=10, invariant=quiet)
    quiet(host.status())


def test_an_input_within_its_drivers_own_budget_is_not_judged_stalled(t):
    """A driver given a longer budget of its own (driver.NAME.budget_us)
    has it for an input too: the bus's limit for anything but a tick is
    75 of the driver's own budgets, not of driver_budget_us (HOST.md,
    "Threads and time"). An input of some 0.3 s, with 5 s of budget."""
    own = dict(settings("slowin"), **{"driver.slowin.budget_us": 5000000})
    host = t.host(drivers=t.drivers(slowin=staller("slowin", "input", rounds=300)), settings=own)
    t.board("generic", "in-1", driver="slowin")
    host.wait_running(["in-1"])
    code, text = post(host, "/api/devices/in-1/input", t.token, json.dumps({"name": "go", "value": True}).encode())
    assert code == 200, "an input within its driver's own budget was answered %d %s" % (code, text[:300])
    assert host.device("in-1", host.status())["state"] == "running", "the machine did not go on after its input"


def test_a_stall_in_a_reloads_migrate_is_refused_and_drops_only_its_machine(t):
    host = t.host(drivers=t.drivers(migrator=staller("migrator", "none")), settings=settings("migrator"))
    neighbours(t, host)
    t.board("generic", "mig-1", driver="migrator")
    host.wait_running(["mig-1"])
    code, text = post(host, "/api/drivers/migrator", t.token,
                      staller("migrator", "migrate", version="2").encode(), "text/x-lua")
    assert code >= 400 and "still running after" in text, (
        "the upload whose migrate stalled was answered %d %s" % (code, text[:400]))
    quiet = undisturbed(NEIGHBOURS)
    e = host.wait_event("driver_error", "mig-1", "stalled", timeout_s=10, invariant=quiet)
    assert "take-over" in e["text"], "the stall does not say it was the take-over: %r" % e["text"]
    host.wait_event("dropped", "mig-1", "its driver stalled", timeout_s=10, invariant=quiet)


def test_a_held_host_shows_in_its_tick_lateness(t):
    """The bus thread's lateness counts from the first tick it missed: a
    host held for a second (SIGSTOP) never looks healthy in the status."""
    host = t.host()
    t.board("lights", "lights-1")
    before = host.wait_running(["lights-1"])["tick"]["skipped"]
    host.signal(signal.SIGSTOP)
    try:
        time.sleep(1.0)  # the hold itself, not a wait for an event: nothing runs in the host meanwhile
    finally:
        host.signal(signal.SIGCONT)
    # The first status published after the hold counts the slots it skipped.
    s = host.wait_status(lambda s: s["tick"]["skipped"] > before, 10, "a status after the hold")
    late = s["tick"]["lateness_us"]["max"]
    assert late >= 900000, "held for 1 s, the bus thread's lateness max is only %d us" % late


COUNTER = """local driver = { name = "counter", version = "1", level = 0, io = { lamp = "do0" }, variables = { n = {} } }
local n = 0
function driver.tick(dev, inputs) n = n + 1; dev.vars.n = n end
return driver
"""


def test_a_worker_stalled_by_a_dropped_machine_is_given_up_too(t):
    """The board of a machine whose input is stalling its (only) worker
    goes away: the machine is dropped at once, and the call it left behind
    still holds the worker past its limit, so the worker is given up and a
    machine that attaches afterwards runs on the spare. The board must go
    before the call's limit: driver_budget_us 100 ms makes it 7.5 s (75
    budgets), and the call runs for some 20 s of CPU, so that a loaded
    machine's slow kill does not let the bus judge the call stalled first
    (a driver_error, no orphan), nor the call end before its limit."""
    st = dict(settings("inputter"), driver_threads=1, driver_budget_us=100000)
    host = t.host(drivers=t.drivers(inputter=staller("inputter", "input", rounds=20000), counter=COUNTER),
                  settings=st)
    board = t.board("generic", "in-1", driver="inputter")
    host.wait_running(["in-1"])
    answers = {}

    def operator():
        answers["go"] = post(host, "/api/devices/in-1/input", t.token,
                             json.dumps({"name": "go", "value": True}).encode())

    op = threading.Thread(target=operator)
    op.start()
    host.wait_event("driver", "in-1", "stalling", timeout_s=10)  # said by input() as it begins to stall
    board.kill()
    host.wait_event("dropped", "in-1", timeout_s=10)
    op.join(30)
    assert not op.is_alive(), "the operator's input was never answered"
    code, text = answers["go"]
    assert code in (404, 502), "the input to a dropped machine was answered %d %s" % (code, text[:200])
    e = host.wait_event("warning", None, "kept its worker past its limit", timeout_s=30)
    assert "inputter" in e["text"], "the warning does not name the driver: %r" % e["text"]
    t.board("generic", "c-1", driver="counter")
    host.wait_status(lambda s: ((host.device("c-1", s) or {}).get("variables", {}).get("n") or 0) > 20, 10,
                     "a new machine ticking on the spare worker")


# A tick of library calls of a few milliseconds each (backtracking over
# 1.2 KB), each of which looks at the clock first, as the cost model has
# costly calls do: given a budget of 20 ms, it is ended after about 25 ms
# on a CPU.
PATTERN_LOOP = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "escape",
                            "pattern_loop.lua")

# Holds CPU 0 at SCHED_FIFO 45 (above the workers, below the bus thread)
# for argv[1] ms, lets it go for argv[2] ms, and again, until it is killed.
HOLDER = """import os, sys, time
os.sched_setaffinity(0, {0})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(45))
hold, gap = float(sys.argv[1]) / 1000, float(sys.argv[2]) / 1000
print("holding", flush=True)
while True:
    until = time.monotonic() + hold
    while time.monotonic() < until:
        pass
    time.sleep(gap)
"""


def held_worker(t, name, source, budget_us, level, hold_ms, gap_ms):
    """A host with one driver worker, pinned to CPU 0, that the HOLDER
    holds hold_ms of every hold_ms + gap_ms, and a board named NAME-1 of
    driver name (source, its budget budget_us, no instruction budget) at
    level (1 ms slots): [host, holder, board]."""
    host = t.host(drivers=t.drivers(**{name: source}),
                  settings={"slice_us": 200, "slices_per_slot": 5, "default_level": level,
                            "reply_deadline_us": 20000, "sleep_s": 1, "driver_threads": 1,
                            "driver.%s.budget_us" % name: budget_us, "driver.%s.instructions" % name: 1000000000})
    workers = threads(host.popen.pid, "vmac-worker")
    assert workers, "no vmac-worker thread in vmacd"
    for tid in workers:
        os.sched_setaffinity(tid, {0})
    holder = t.start([sys.executable, "-c", HOLDER, str(hold_ms), str(gap_ms)], "holder")
    holder.wait_line(r"^holding$", 10, what="the holder on CPU 0")
    return [host, holder, t.board("generic", name + "-1", driver=name)]


def test_a_held_worker_is_judged_by_the_cpu_it_had(t):
    """The bus charges a driver only the CPU its worker had past the limit
    (HOST.md, "Threads and time"). The worker is pinned to CPU 0, which a
    real-time busy loop holds; one test, as two would hold CPU 0 at once.
    1. Held off: tests/escape/pattern_loop.lua, budget 20 ms, period 128
       ms, CPU 0 held 150 ms of every 165. A tick starts in a gap, runs
       at most 15 ms of its 25, is held past its limit, and runs again:
       its own budget ends it ("time budget exceeded") within a gap or
       two, before its worker has had the quarter of the limit (32 ms) of
       CPU the bus would fail it for ("stalled").
    2. Shared: the same driver, CPU 0 held 3 ms of every 5. Its worker
       has under half of any stretch of time, and its budget still ends
       the tick, once the worker had a quarter of the budget of CPU past
       it (DRIVERS.md, "The callbacks"), before the bus would judge it
       stalled.
    3. Stuck: a tick inside library calls with no budget, period 256 ms,
       CPU 0 held 10 ms of every 13. Its worker has under half of any
       stretch of time, and the bus still fails it once it had a quarter
       of the limit (64 ms) of CPU, well before ten limits, the bound for
       a worker that never runs."""
    if os.cpu_count() < 2 or os.geteuid() != 0:
        raise Skip("needs two CPUs (CPU 0 is held, the bus thread runs on another) and root (SCHED_FIFO)")
    with open(PATTERN_LOOP) as f:
        source = f.read()
    for hold_ms, gap_ms, how in ((150, 15, "held off its CPU"), (3, 2, "on a shared CPU")):
        procs = held_worker(t, "pattern_loop", source, 20000, 7, hold_ms, gap_ms)
        host, holder = procs[:2]
        errors = lambda: host.find_events("driver_error", "pattern_loop-1")  # noqa: E731
        stalled = lambda: [e["text"] for e in errors() if "stalled" in e["text"]]  # noqa: E731 (not loaded again)
        host.wait_status(lambda s: len(errors()) >= 3 or stalled(), 30, "three failed ticks of pattern_loop-1 " + how)
        assert holder.alive(), "the holder ended: %s" % holder.text()
        texts = [e["text"] for e in errors()]
        assert not stalled(), "a tick %s was judged stalled: %s" % (how, stalled())
        assert all("time budget exceeded" in x for x in texts), "a tick %s failed otherwise than by its budget: %s" % (
            how, texts)
        for p in procs:
            p.kill()

    host, holder, _ = held_worker(t, "stuck", staller("stuck", "tick").replace("level = 0", "level = 8"), 0, 8, 10, 3)
    e = host.wait_event("driver_error", "stuck-1", "stalled", timeout_s=30)
    assert holder.alive(), "the holder ended: %s" % holder.text()
    m = re.search(r"tick still running after ([\d.e+]+) ms \(its limit ([\d.e+]+) ms\)", e["text"])  # %.3g
    assert m, "the stall does not say how long the tick ran: %r" % e["text"]
    after_ms, limit_ms = float(m.group(1)), float(m.group(2))
    assert after_ms < 10 * limit_ms, "a tick stuck on a CPU was judged only after %.0f ms (its limit %.0f ms)" % (
        after_ms, limit_ms)
