"""vmac-board --plant-file (docs/BOARD.md, "Plant models in Lua" and "What
it prints"): a plant model in Lua behind real boards that a real vmacd
serves. The driver's outputs drive the plant and what the plant computes
reaches the host; operator actions change it, refusals say why; an unsafe
episode is said once, even with --quiet; a plant that fails stops alone
while every board goes on being served; a file that does not load is
refused at start; SIGTERM turns every output off; --time-scale runs plant
time faster, judged by the plant's own clock read through an input."""

import os
import re
import signal

from harness import TIMING, Proc, undisturbed

# The driver of the machine: heater and drum on from the first tick, the
# plant's `heating` published, and a start press latched (a button holds
# its input 0.5 s: a latch makes it visible to any status poll).
DRIVER = """-- dryer: drives heater and drum, publishes what the plant says back
local driver = {
	name = "dryer", version = "1",
	io = { heater = "do0", drum = "do1", door_closed = "di0", start_button = "di1", heating = "di2" },
	variables = { heating = {}, started = {} },
}
function driver.tick(dev, inputs)
	dev.out.heater = true
	dev.out.drum = true
	dev.vars.heating = inputs.heating
	if inputs.start_button then dev.vars.started = true end
end
return driver
"""

# The plant: heats while the heater is on and the door closed; its clock
# input (the encoder) counts tenths of a second of plant time (os.clock());
# `alarm` set non-zero makes every step unsafe; `break_after N` makes the
# Nth step from then raise.
PLANT = """-- plants/dryer.lua: the tests' dryer
return {
	name = "dryer",
	io = {
		heater = "do0", drum = "do1",
		door_closed = "di0", start_button = "di1", heating = "di2",
		temp_c = { "ai0", scale = 0.05, offset = -20 },
		clock_ds = "encoder",
	},
	state = { temp_c = 20, door_closed = true, start_button = false, heating = false, clock_ds = 0,
	          alarm = 0, break_after = -1 },
	step = function(p, dt, out)
		p.clock_ds = math.floor(os.clock() * 10)
		p.heating = out.heater and p.door_closed
		if p.heating then p.temp_c = math.min(p.temp_c + 5 * dt, 150) end
		if p.break_after > 0 then
			p.break_after = p.break_after - 1
			if p.break_after == 0 then error("the drum bearing broke") end
		end
		if p.alarm ~= 0 then return "heater on with the drum still" end
	end,
	actions = {
		door = function(p, v)
			if v ~= 0 and v ~= 1 then return false, "door takes 0 (open) or 1 (closed)" end
			p.door_closed = v == 1
		end,
		start = "start_button",
	},
}
"""

NAMES = ["dryer-1", "dryer-2"]
DOOR, START, HEATING = 0, 1, 2  # digital inputs
LATE_US = str(TIMING["reply_deadline_us"] // 4)


def line_of(source, text):
    """1-based number of the first line of source containing text."""
    return next(i for i, l in enumerate(source.splitlines(), 1) if text in l)


def dryer_folder(t, plant=PLANT):
    """A drivers folder with the dryer's driver and plants/dryer.lua:
    (folder, path of the plant file)."""
    folder = t.drivers(dryer=DRIVER)
    os.makedirs(os.path.join(folder, "plants"), exist_ok=True)
    path = os.path.join(folder, "plants", "dryer.lua")
    with open(path, "w") as f:
        f.write(plant)
    return folder, path


def inputs(host, name, s):
    """The raw inputs the host last read from board name: {digital, analog, encoder}."""
    return (host.device(name, s) or {}).get("inputs") or {"digital": [False] * 8, "analog": [0, 0], "encoder": 0}


def digital(host, name, s, bit):
    return bool(inputs(host, name, s)["digital"][bit])


def clock_ds(host, name, s):
    """The plant's clock (tenths of a second of plant time) as the host read it."""
    return inputs(host, name, s)["encoder"]


def variable(host, name, s, var):
    return ((host.device(name, s) or {}).get("variables") or {}).get(var)


def dryer_boards(t, plant, count=2, extra=()):
    """One vmac-board process running count dryer boards from the plant
    file, with --commands."""
    return t.board("generic", "dryer", count=count, commands=True, extra=["--plant-file", plant] + list(extra))


def quiet_board(t, plant, name, extra=()):
    """One keyed vmac-board with --quiet and --commands: it prints no start-up
    banner, so the caller waits for the host to run it."""
    t.enroll([name])
    argv = [t.path("vmac-board"), "--plant-file", plant, "--name", name, "--bus", t.bus, "--key-dir", t.keys,
            "--late-us", LATE_US, "--quiet", "--commands"] + list(extra)
    p = Proc(t._name(name), argv, t.logdir, stdin=True)
    t.procs.append(p)
    return p


def test_plant_file_drives_the_host_and_takes_actions(t):
    folder, plant = dryer_folder(t)
    host = t.host(drivers=folder)
    board = dryer_boards(t, plant)
    host.wait_running(NAMES)
    # The driver turns the heater on; the plant's `heating`, computed from
    # that output, comes back as di2 and as the driver's variable.
    host.wait_status(lambda s: all(digital(host, n, s, HEATING) and variable(host, n, s, "heating") is True
                                   for n in NAMES), 30, "both dryers heating, seen by the host",
                     undisturbed(NAMES))
    temp = inputs(host, "dryer-1", host.last)["analog"][0]
    host.wait_status(lambda s: inputs(host, "dryer-1", s)["analog"][0] > temp + 20, 30,
                     "dryer-1's temperature rising under its heater", undisturbed(NAMES))

    # An operator opens dryer-1's door: it stops heating, dryer-2 does not.
    board.send("dryer-1 door 0")
    board.wait_line(r"^dryer-1: door 0$", 30, what="the door action answered")
    host.wait_status(lambda s: not digital(host, "dryer-1", s, DOOR) and not digital(host, "dryer-1", s, HEATING)
                     and variable(host, "dryer-1", s, "heating") is False, 30,
                     "dryer-1's door open and its heating off", undisturbed(NAMES))
    s = host.status()
    assert digital(host, "dryer-2", s, DOOR) and digital(host, "dryer-2", s, HEATING), (
        "dryer-2 changed with dryer-1's door: %r" % inputs(host, "dryer-2", s))

    # Refusals say why and change nothing.
    board.send("dryer-1 door 7")
    line = board.wait_line(r"^dryer-1: refused door 7", 30, what="the refusal of door 7")
    assert line.text == ("dryer-1: refused door 7: the dryer plant refuses door = 7: "
                         "door takes 0 (open) or 1 (closed)"), "the refusal line: %r" % line.text
    board.send("dryer-2 sauna 1")
    line = board.wait_line(r"^dryer-2: refused sauna 1", 30, what="the refusal of an unknown action")
    assert "no action or state field 'sauna'" in line.text and "door" in line.text and "alarm" in line.text, (
        "an unknown action's refusal does not list the actions and fields: %r" % line.text)

    # A button press reaches the driver (it latches it) on that board only.
    board.send("dryer-2 start 1")
    board.wait_line(r"^dryer-2: start 1$", 30, what="the start action answered")
    s = host.wait_status(lambda s: variable(host, "dryer-2", s, "started") is True, 30,
                         "dryer-2's driver seeing the start button", undisturbed(NAMES))
    assert variable(host, "dryer-1", s, "started") is None, "dryer-1's driver saw dryer-2's button"
    assert not digital(host, "dryer-1", s, DOOR), "a refused or other board's action changed dryer-1's door"


def test_plant_file_unsafe_episode_said_once_even_quiet(t):
    folder, plant = dryer_folder(t)
    host = t.host(drivers=folder)
    board = quiet_board(t, plant, "dryer-1")
    host.wait_running(["dryer-1"])

    def ran_on(since_ds, tenths, what):
        """Wait until the plant's own clock is tenths past since_ds."""
        return clock_ds(host, "dryer-1", host.wait_status(
            lambda s: clock_ds(host, "dryer-1", s) >= since_ds + tenths, 30, what, undisturbed(["dryer-1"])))

    board.send("dryer-1 alarm 1")
    board.wait_line(r"^dryer-1: alarm 1$", 30, what="the alarm action answered")
    ack = clock_ds(host, "dryer-1", host.status())
    board.wait_line(r"^dryer UNSAFE: dryer-1 heater on with the drum still, episode 1$", 30,
                    what="the first unsafe episode's line")
    ran_on(ack, 15, "1.5 s of plant time into the first episode")
    board.send("dryer-1 alarm 0")
    board.wait_line(r"^dryer-1: alarm 0$", 30, what="the alarm cleared")
    ran_on(clock_ds(host, "dryer-1", host.status()), 5, "0.5 s of safe plant time")
    board.send("dryer-1 alarm 1")
    board.wait_line(r"^dryer-1: alarm 1$", 30, what="the alarm set again")
    board.wait_line(r"^dryer UNSAFE: dryer-1 heater on with the drum still, episode 2$", 30,
                    what="the second unsafe episode's line")
    ran_on(clock_ds(host, "dryer-1", host.status()), 15, "1.5 s of plant time into the second episode")

    board.signal(signal.SIGTERM)
    assert board.wait_exit(30) == 0, "vmac-board did not stop cleanly on SIGTERM"
    unsafe = [l.text for l in board.find_lines(r"UNSAFE")]
    assert len(unsafe) == 2, "two unsafe episodes should print two lines, got %d: %r" % (len(unsafe), unsafe)
    chatty = board.find_lines(r"^dryer-1: (state known|outputs) ")
    assert not chatty, "--quiet printed %r" % chatty[0].text


def test_plant_file_failure_stops_one_board_only(t):
    folder, plant = dryer_folder(t)
    host = t.host(drivers=folder)
    board = dryer_boards(t, plant)
    host.wait_running(NAMES)
    host.wait_status(lambda s: all(clock_ds(host, n, s) > 5 for n in NAMES), 30, "both plants running",
                     undisturbed(NAMES))
    since = host.last_event_seq()
    board.send("dryer-1 break_after 5")
    line = board.wait_line(r"^dryer-1: plant failed: ", 30, what="dryer-1's plant failing")
    where = "plants/dryer.lua:%d: the drum bearing broke" % line_of(PLANT, 'error("the drum bearing broke")')
    assert where in line.text and line.text.endswith("; its inputs hold their last values"), (
        "the failure line does not say %r and that the inputs hold: %r" % (where, line.text))

    # Both boards go on being served, dryer-1 with its plant's last inputs
    # (read once the host has served it a few times since the failure).
    s = host.status()
    served = {n: host.device(n, s)["served"] for n in NAMES}
    s = host.wait_status(lambda s: host.device("dryer-1", s)["served"] > served["dryer-1"] + 3, 30,
                         "dryer-1 served after its plant failed", undisturbed(NAMES))
    served = {n: host.device(n, s)["served"] for n in NAMES}
    held, ticking = clock_ds(host, "dryer-1", s), clock_ds(host, "dryer-2", s)
    s = host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 20 for n in NAMES)
                         and clock_ds(host, "dryer-2", s) > ticking + 10, 30,
                         "both boards served on after dryer-1's plant failed", undisturbed(NAMES))
    assert clock_ds(host, "dryer-1", s) == held, "dryer-1's inputs moved after its plant failed: clock %d, was %d" % (
        clock_ds(host, "dryer-1", s), held)
    assert digital(host, "dryer-1", s, HEATING), "dryer-1's held inputs lost the plant's last heating"
    dropped = host.find_events("dropped", after_seq=since)
    assert not dropped, "a board was dropped: %r" % dropped[0]["text"]
    assert len(board.find_lines(r"plant failed")) == 1, "the failure was said more than once"
    assert not board.find_lines(r"^dryer-2: plant failed"), "dryer-2's plant failed too"

    board.send("dryer-1 door 0")
    line = board.wait_line(r"^dryer-1: refused door 0", 30, what="an action on the failed plant refused")
    assert "has failed" in line.text and "the drum bearing broke" in line.text, "the refusal: %r" % line.text
    board.send("dryer-2 door 0")
    board.wait_line(r"^dryer-2: door 0$", 30, what="dryer-2 still taking actions")
    traceback = board.find_lines(r"stack traceback|^\s")
    assert not traceback, "vmac-board printed a traceback's lines: %r" % traceback[0].text


def test_plant_file_that_does_not_load_exits_2(t):
    board = t.path("vmac-board")
    folder = os.path.join(t.logdir, "plants")
    os.makedirs(folder)
    cases = [
        ("a syntax error", "return {\n\tio = {},\n\tstep = function(p, dt, out\nend }\n", "broken.lua:4:"),
        ("no step", "return { io = { lamp = 'do0' } }\n", "broken.lua: plant: step must be a function"),
        ("a raise at load", "local x = 1\nerror('no dryer today')\n", "broken.lua:2: no dryer today"),
        ("print at load", "print('hi')\nreturn {}\n", "broken.lua:1:"),
    ]
    problems = []
    for what, source, want in cases:
        path = os.path.join(folder, "broken.lua")
        with open(path, "w") as f:
            f.write(source)
        rc, out, err = t.run([board, "--plant-file", path, "--bus", t.bus, "--no-realtime"], "broken")
        if rc != 2 or "vmac-board: --plant-file: " not in err or want not in err or len(err.splitlines()) != 1:
            problems.append("%s: exit %d, stderr %r (expected exit 2 and one line saying %r)" % (what, rc, err,
                                                                                                 want))
        if "on bus" in out:
            problems.append("%s: boards started: %r" % (what, out))
    missing = os.path.join(folder, "nosuch.lua")
    rc, out, err = t.run([board, "--plant-file", missing, "--bus", t.bus, "--no-realtime"], "missing")
    if rc != 2 or "nosuch.lua" not in err:
        problems.append("a missing file: exit %d, stderr %r" % (rc, err))
    assert not problems, "\n".join(problems)


def test_plant_file_sigterm_turns_every_output_off(t):
    folder, plant = dryer_folder(t)
    host = t.host(drivers=folder)
    board = dryer_boards(t, plant)
    host.wait_running(NAMES)
    for n in NAMES:
        board.wait_line(r"^%s: outputs digital=0x03 " % n, 30, what="%s's heater and drum on" % n)
    # A failed plant's board goes safe too.
    board.send("dryer-1 break_after 2")
    board.wait_line(r"^dryer-1: plant failed: ", 30, what="dryer-1's plant failing")
    mark = board.mark()
    board.signal(signal.SIGTERM)
    assert board.wait_exit(30) == 0, "vmac-board did not exit 0 on SIGTERM"
    for n in NAMES:
        outputs = board.find_lines(r"^%s: outputs " % n, since=mark)
        assert outputs and outputs[-1].text.startswith("%s: outputs digital=0x00 pwm=0" % n), (
            "%s did not turn its outputs off on SIGTERM: %r" % (n, [l.text for l in outputs]))
    board.wait_line(r"^vmac-board: stopped by signal %d, all outputs off$" % signal.SIGTERM, 5, since=mark,
                    what="the stop line")


def test_plant_file_time_scale_runs_plant_time_faster(t):
    """Two processes of the same plant, one at --time-scale 20: their own
    clocks, read by the host in the same status, move 20 to 1."""
    folder, plant = dryer_folder(t)
    host = t.host(drivers=folder)
    t.board("generic", "slow", extra=["--plant-file", plant])
    t.board("generic", "fast", extra=["--plant-file", plant, "--time-scale", "20"])
    names = ["slow", "fast"]
    s = host.wait_running(names)
    start = {n: clock_ds(host, n, s) for n in names}
    s = host.wait_status(lambda s: clock_ds(host, "slow", s) >= start["slow"] + 30, 60,
                         "3 s of the slow plant's time", undisturbed(names))
    slow, fast = (clock_ds(host, n, s) - start[n] for n in names)
    ratio = fast / float(slow)
    assert 12 <= ratio <= 30, ("at --time-scale 20 the plant's clock ran %d tenths while the other's ran %d: "
                               "%.1f times as fast" % (fast, slow, ratio))


# The same plant under `vmac test` (virtual time): board { plant = "dryer" }
# finds plants/dryer.lua in the drivers folder.
VTEST = """test("the Lua plant heats under the driver", function()
	local b = board { name = "dryer-1", plant = "dryer" }
	run_until(function() return b.state == "running" end, 5, "the dryer attached")
	run_until(function() return b.var.heating == true end, 5, "the driver sees the plant heating")
	run_for(10)
	expect(b.plant.temp_c > 60, "heated to " .. tostring(b.plant.temp_c))
	b:set("door", 0)
	run_until(function() return b.var.heating == false end, 2, "the open door stops the heating")
	expect(not b:try_set("door", 7), "door 7 refused")
	b:set("start", 1)
	run_until(function() return b.var.started == true end, 2, "the button reached the driver")
end)
test("unsafe episodes are counted", function()
	local b = board { name = "dryer-1", plant = "dryer" }
	run_until(function() return b.state == "running" end, 5, "the dryer attached")
	b:set("alarm", 1) run_for(1) b:set("alarm", 0) run_for(1) b:set("alarm", 1) run_for(1)
	expect(b.plant.unsafe_episodes == 2, "unsafe episodes: " .. tostring(b.plant.unsafe_episodes))
end)
test("a failing plant fails the test", function()
	local b = board { name = "dryer-1", plant = "dryer" }
	run_until(function() return b.state == "running" end, 5, "the dryer attached")
	b:set("break_after", 3)
	run_for(1)
end)
"""


def test_plant_file_in_vmac_test(t):
    folder, _ = dryer_folder(t)
    tests = os.path.join(t.logdir, "tests")
    os.makedirs(tests)
    with open(os.path.join(tests, "dryer_test.lua"), "w") as f:
        f.write(VTEST)
    rc, out, err = t.run([t.path("vmac"), "test", "--drivers", folder, tests], "vtest", 120)
    assert rc == 1, "vmac test: exit %d, expected 1 (one test fails on purpose)\n%s%s" % (rc, out, err)
    for name in ("the Lua plant heats under the driver", "unsafe episodes are counted"):
        assert re.search(r"ok\s+%s" % re.escape(name), out), "%r did not pass:\n%s%s" % (name, out, err)
    where = "plants/dryer.lua:%d: the drum bearing broke" % line_of(PLANT, 'error("the drum bearing broke")')
    assert re.search(r"FAIL\s+a failing plant fails the test", out) and where in out, (
        "the failing plant's test does not fail saying %r:\n%s%s" % (where, out, err))
