"""vmac test, the driver test runner (docs/TESTING.md), used the way a
person uses it: on the shipped driver tests, on files that fail on purpose
(tests/vtest/cases/), and on a driver of one's own in a folder of one's own."""

import os
import re
import shutil
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CASES = os.path.join(ROOT, "tests", "vtest", "cases")
EXIT_S = 120  # the shipped driver tests take about a second; this is a bound, not a measure


def vtest(t, base, *args, cwd_files=None, timeout_s=EXIT_S):
    """Run vmac test with args: (exit code, stdout, stderr)."""
    rc, out, err = t.run([t.path("vmac"), "test"] + list(args), base, timeout_s)
    assert rc is not None and rc >= 0, "vmac test %s: killed by a signal (%s)\n%s" % (" ".join(args), rc, err)
    return rc, out, err


def case(name):
    return os.path.join(CASES, name + ".lua")


def test_shipped_driver_tests_pass(t):
    rc, out, err = vtest(t, "vtest-shipped", os.path.join(ROOT, "tests", "drivers"))
    assert rc == 0, "the shipped driver tests fail (exit %d):\n%s%s" % (rc, out[-3000:], err)
    m = re.search(r"^(\d+) tests, 0 failed; .* of virtual time", out, re.M)
    assert m and int(m.group(1)) >= 20, "no summary line with the test count:\n%s" % out[-500:]


def test_failures_name_the_line(t):
    """Each way a test file can fail is one failure, reported at the line
    that caused it, and the run exits 1."""
    expected = {
        "syntax": (r"syntax\.lua:3", r"unexpected symbol"),
        "load_error": (r"load_error\.lua:4", r"attempt to index local 't'"),
        "expect": (r"expect\.lua:6", r"one plus one: expected 3, got 2"),
        "always": (r"always\.lua:7", r"always: the kitchen light stays off \(declared at \S*always\.lua:5\) "
                   r"was violated at 0\.\d+ s"),
    }
    problems = []
    for name, (at, message) in expected.items():
        rc, out, err = vtest(t, "vtest-" + name, case(name))
        if rc != 1:
            problems.append("%s: exit %d, expected 1" % (name, rc))
        if not re.search(r"^\s+at \S*" + at + r"$", out, re.M):
            problems.append("%s: no 'at ...%s' line:\n%s" % (name, at, out))
        if not re.search(message, out):
            problems.append("%s: the report does not say %r:\n%s" % (name, message, out))
    assert not problems, "\n".join(problems)

    # An always() on the clock alone is checked between frames as well: it
    # fails at 0.5 s, not at the next service of the board after it.
    rc, out, err = vtest(t, "vtest-always-time", case("always_time"))
    m = re.search(r"was violated at ([0-9.]+) s", out)
    assert rc == 1 and m, "always_time.lua: exit %d, no violation reported:\n%s" % (rc, out)
    assert 0.5 <= float(m.group(1)) <= 0.511, "the clock's always was first seen violated at %s s, not by 0.51 s" % (
        m.group(1))

    # A file that does not load runs none of its tests.
    rc, out, err = vtest(t, "vtest-load-error-list", "--list", case("load_error"))
    assert "never runs" not in out, "a test of a file that failed to load is listed:\n%s" % out

    # The report of a failure in a virtual world shows the board's recent
    # services and the events.
    rc, out, err = vtest(t, "vtest-always-details", case("always"))
    for text in ("lights-1: host says running", "services (board's view)", "attached"):
        assert text in out, "the failure report lacks %r:\n%s" % (text, out)


def test_always_with_a_grace(t):
    """always(..., {within = ...}): the door interlock of the dishwasher
    holds within 2 periods of its driver and not at the instant the door
    opens; a grace shorter than that, or a condition that stays false,
    fails when the grace runs out, at the tick it ran out."""
    rc, out, err = vtest(t, "vtest-always-within", case("always_within"))
    assert rc == 1, "always_within.lua: exit %d, expected 1\n%s%s" % (rc, out, err)
    assert re.search(r"ok\s+off within 2 periods of the door opening", out), (
        "the interlock with a grace of 2 periods fails:\n%s" % out)
    opened = re.search(r"FAIL\s+off at the moment the door opens\n.*\n\s+always: nothing runs with the door open "
                       r"\(declared at \S*always_within\.lua:24\) was violated at ([0-9.]+) s", out)
    assert opened, "the interlock without a grace does not fail at the door's opening:\n%s" % out
    door_s = float(opened.group(1))
    short = re.search(r"FAIL\s+off within 1 ms of the door opening\n\s+at \S*always_within\.lua:34\n\s+always: .* "
                      r"was violated at ([0-9.]+) s, tick \d+: false since ([0-9.]+) s, longer than its grace of "
                      r"0\.001 s", out)
    assert short, "a grace of 1 ms is not reported as run out:\n%s" % out
    assert float(short.group(2)) == door_s and abs(float(short.group(1)) - (door_s + 0.001)) < 1e-6, (
        "the 1 ms grace did not run out 1 ms after the door opened (%s s):\n%s" % (door_s, short.group(0)))
    stays = re.search(r"FAIL\s+a grace does not excuse a condition that stays false\n.*\n\s+always: the door stays "
                      r"closed .* was violated at ([0-9.]+) s, tick \d+: false since ([0-9.]+) s, longer than its "
                      r"grace of 0\.5 s", out)
    assert stays and abs(float(stays.group(1)) - float(stays.group(2)) - 0.5) < 1e-6, (
        "a condition false for good is not reported 0.5 s after it turned false:\n%s" % out)


def test_the_report_shows_the_tests_actions(t):
    """A failure's report puts what the test did among the board's
    services: the door opened, and no service since (the next a period
    away); or the first service after it marked, with how long after."""
    rc, out, err = vtest(t, "vtest-report-actions", "--history", "3", "--filter", "the moment",
                         case("always_within"))
    assert rc == 1, "exit %d, expected 1\n%s%s" % (rc, out, err)
    assert "last 3 services (board's view), with the test's actions (>>; * the first service after one):" in out, (
        "the report does not announce the test's actions:\n%s" % out)
    assert re.search(r"\n\s+0\.0670 >> input\(\"start\", \"normal\"\): accepted\n(\s+39\.\d+    cancel_button=\S+ "
                     r"door_closed=1 .*\n){3}\s+39\.\d+ >> open_door\(\)  \(no service of this board since: the next "
                     r"within its period, 32 ms\)\n", out), (
        "the report does not show the start, three services, then the door opened with no service since:\n%s" % out)

    rc, out, err = vtest(t, "vtest-report-mark", "--history", "20", "--filter", "stays false", case("always_within"))
    assert rc == 1, "exit %d, expected 1\n%s%s" % (rc, out, err)
    assert re.search(r"\n\s+39\.\d+ >> open_door\(\)\n\s+39\.\d+ \*  \S.* door_closed=0 .*  \(\* [0-9.]+ ms after "
                     r"open_door\(\)\)\n", out), "the first service after the door opened is not marked:\n%s" % out


def test_the_report_says_which_values_are_timer_copies(t):
    """A variable declared update = "timer:N" is shown as the copy it is:
    its period and how long ago it was published (never longer than the
    period); one published as it changes has no such note."""
    rc, out, err = vtest(t, "vtest-report-timers", "--filter", "the moment", case("always_within"))
    assert rc == 1, "exit %d, expected 1\n%s%s" % (rc, out, err)
    line = re.search(r"^\s+variables: (.*)$", out, re.M)
    assert line, "the report shows no variables:\n%s" % out
    problems = []
    for name, every_s in (("level_l", 0.5), ("time_left_s", 1)):
        m = re.search(r"\b%s=\S+ \(timer %g s: published ([0-9.]+) s ago\)" % (name, every_s), line.group(1))
        if not m:
            problems.append("%s (timer:%g) is not shown as a timer copy with its age" % (name, every_s))
        elif float(m.group(1)) > every_s:
            problems.append("%s was published %s s ago, longer than its period %g s" % (name, m.group(1), every_s))
    if not re.search(r"\bstep=wash(?! \()", line.group(1)):
        problems.append("step (published as it changes) is not shown plainly")
    assert not problems, "\n".join(problems) + "\n" + line.group(0)


def test_every_runs_test_side_behaviour(t):
    """every(dt, fn): fn at every dt of virtual time while the clock runs,
    until :stop(); a person opening the door every 5 s; an error in fn
    fails at fn's line, a dt that is not > 0 at the caller's."""
    rc, out, err = vtest(t, "vtest-every", case("every"))
    assert rc == 1, "every.lua: exit %d, expected 1\n%s%s" % (rc, out, err)
    for name in ("every calls fn at its times while the clock runs", "a person opens and closes the door every 5 s"):
        assert re.search(r"ok\s+%s" % re.escape(name), out), "%r fails:\n%s" % (name, out)
    assert re.search(r"FAIL\s+an error in fn fails at fn's line\n\s+at \S*every\.lua:37\n\s+every \(declared at "
                     r"\S*every\.lua:36\): its fn raised: \S*every\.lua:37: the person tripped\n", out), (
        "the error in fn is not reported at fn's line:\n%s" % out)
    assert re.search(r"virtual time 1\.500000 s", out), "the error in fn did not stop the test at 1.5 s:\n%s" % out
    assert re.search(r"FAIL\s+every needs seconds > 0\n\s+at \S*every\.lua:43\n\s+every\(seconds, fn\): seconds "
                     r"must be a number > 0, not 0\n", out), "every(0, fn) is not refused at its line:\n%s" % out
    assert "runner.lua" not in out, "a line of the runner shows:\n%s" % out


def test_api_mistakes_are_the_tests_line(t):
    """A mistake in the use of the test API (an unknown plant, a bad
    argument) fails the test at the test file's line, naming the mistake,
    and no line of the runner shows."""
    expected = [
        ("an unknown plant", 4, "board{...}: unknown plant 'dryer': no plants/dryer.lua in the drivers folder "
         "(none: --drivers DIR), and no C plant of that name (washer, dishwasher, lights, generic)"),
        ("an action that is not a name", 9, "b:set(action, value): the action must be a name, not 7"),
        ("an action the plant does not have", 14, "lights-1: the lights plant refuses doorbell = 1"),
        ("run_for without seconds", 19, 'run_for(seconds): seconds must be a number >= 0, not "ten"'),
        ("an input value that is a table", 24, 'b:input("kitchen", value): the value must be nil, a boolean, '
         "a number or a string, not a table"),
        ("an unknown wire fault", 29, "faults: unknown key 'lose'"),
        ("a grace that is not a time", 33, 'always: within = "soon": expected seconds'),
        ("a mistake inside a helper of the test file", 41, "board{...}: params must be a table"),
    ]
    rc, out, err = vtest(t, "vtest-api-errors", case("api_errors"))
    assert rc == 1, "api_errors.lua: exit %d, expected 1\n%s%s" % (rc, out, err)
    problems = []
    for name, line, message in expected:
        if not re.search(r"FAIL\s+%s\n\s+at \S*api_errors\.lua:%d\n\s+%s" % (re.escape(name), line, re.escape(message)),
                         out):
            problems.append("%r: not reported at line %d with %r" % (name, line, message))
    if "runner.lua" in out:
        problems.append("a line of the runner shows")
    assert not problems, "\n".join(problems) + "\n" + out


def test_runaway_tests_are_stopped(t):
    rc, out, err = vtest(t, "vtest-endless", "--timeout", "1", case("endless"))
    assert rc == 1, "an endless test: exit %d, expected 1\n%s%s" % (rc, out, err)
    assert re.search(r"FAIL\s+spins forever\n\s+at \S*endless\.lua:4\n\s+the test took more than 1 s of wall time",
                     out), "the endless loop is not reported at its line:\n%s" % out
    assert re.search(r"ok\s+runs after the endless one", out), "the test after the endless one did not run:\n%s" % out

    rc, out, err = vtest(t, "vtest-long", "--time-limit", "30", case("long"))
    assert rc == 1, "a test past --time-limit: exit %d, expected 1\n%s" % (rc, out)
    assert "ran past the virtual-time limit of 30 s" in out, "the time limit is not named:\n%s" % out
    assert re.search(r"virtual time 30\.0+ s", out), "the test did not stop at the limit:\n%s" % out


def test_what_did_not_run_does_not_pass(t):
    """A test that checked nothing fails and says so; a file whose top level
    never ends is stopped by --timeout and reported as that file's failure."""
    rc, out, err = vtest(t, "vtest-nothing", case("checks_nothing"))
    assert rc == 1, "a test that checks nothing: exit %d, expected 1\n%s%s" % (rc, out, err)
    assert re.search(r"FAIL\s+only runs the clock\n\s+at \S*checks_nothing\.lua:2\n\s+the test checked nothing", out), (
        "the test that checks nothing is not reported as such:\n%s" % out)
    assert re.search(r"ok\s+checks one thing", out), "the test that checks something did not pass:\n%s" % out

    rc, out, err = vtest(t, "vtest-endless-file", "--timeout", "1", case("endless_file"), case("expect"),
                         timeout_s=60)
    assert rc == 1, "a file that never loads: exit %d, expected 1\n%s%s" % (rc, out, err)
    assert re.search(r"FAIL\s+\(loading the file\)[\s\S]*loading the file took more than 1 s of wall time", out), (
        "the endless top level is not reported:\n%s" % out)
    assert re.search(r"^\S*expect\.lua$", out, re.M), "the next file's tests did not run:\n%s" % out


def test_a_creeping_driver_fails_alone(t):
    """A driver that fills its heap, catching every refusal, is dropped for
    its memory cap and nothing else ends: its test goes on to its end (no
    ok for a body that never finished), and the next test runs."""
    home = os.path.join(t.logdir, "creep")
    os.makedirs(os.path.join(home, "drivers"))
    os.makedirs(os.path.join(home, "tests"))
    with open(os.path.join(home, "drivers", "creep.lua"), "w") as f:
        f.write("""return { name = "creep", version = "1.0.0", io = { do0 = "do0", di0 = "di0" },
  tick = function(dev, inputs) G = G or {} N = (N or 0) + 1
    for i = 1, 400 do if not pcall(function() G[#G+1] = {N, i} end) then break end end end }
""")
    with open(os.path.join(home, "tests", "creep_test.lua"), "w") as f:
        f.write("""test("the creeping driver is dropped for its memory", function()
	local b = board { name = "creep-1", plant = "generic", driver = "creep" }
	run_until(function() return b.state == "running" end, 5, "creep attached")
	run_until(function() return b.state ~= "running" end, 120, "creep dropped")
	expect_event({ kind = "driver_error", text = "memory cap exceeded" }, "the reason")
end)
test("the next test runs", function()
	expect(true, "this test ran")
end)
""")
    rc, out, err = vtest(t, "vtest-creep", "--drivers", os.path.join(home, "drivers"), os.path.join(home, "tests"))
    assert re.search(r"ok\s+the creeping driver is dropped for its memory", out), (
        "the creeping driver's test did not pass (exit %d):\n%s%s" % (rc, out, err))
    assert re.search(r"ok\s+the next test runs", out), "the next test did not run:\n%s" % out
    assert rc == 0, "vmac test exit %d with both tests passing:\n%s%s" % (rc, out, err)


def test_output_formats(t):
    rc, out, err = vtest(t, "vtest-tap", "--tap", case("expect"))
    assert rc == 1, "--tap with a failing test: exit %d" % rc
    lines = out.splitlines()
    assert lines[:2] == ["TAP version 13", "1..2"], "no TAP header and plan:\n%s" % out
    assert re.match(r"ok 1 - \S*expect\.lua: adds$", lines[2]), "first TAP line: %r" % lines[2]
    assert re.match(r"not ok 2 - \S*expect\.lua: adds wrongly$", lines[3]), "second TAP line: %r" % lines[3]
    assert re.search(r"^  at: \S*expect\.lua:6$", out, re.M), "no YAML 'at' for the failure:\n%s" % out

    junit = os.path.join(t.logdir, "junit.xml")
    rc, out, err = vtest(t, "vtest-junit", "--junit", junit, case("expect"), case("lossy"))
    assert rc == 1, "--junit with a failing test: exit %d" % rc
    root = ET.parse(junit).getroot()
    assert root.tag == "testsuites" and root.get("tests") == "3" and root.get("failures") == "1", (
        "JUnit totals: %r" % root.attrib)
    cases = {c.get("name"): c for c in root.iter("testcase")}
    assert set(cases) == {"adds", "adds wrongly", "lights over a lossy link"}, "JUnit test cases: %s" % list(cases)
    failure = cases["adds wrongly"].find("failure")
    assert failure is not None and "expected 3, got 2" in failure.get("message"), "JUnit failure: %r" % (
        failure.attrib if failure is not None else None)
    assert cases["adds"].find("failure") is None, "a passing test has a failure in JUnit"

    trace = os.path.join(t.logdir, "trace.csv")
    rc, out, err = vtest(t, "vtest-trace", "--trace", trace, case("lossy"))
    assert rc == 0, "lossy.lua fails (exit %d):\n%s" % (rc, out)
    with open(trace) as f:
        rows = f.read().splitlines()
    assert rows[0] == "test,time_s,board,io,value", "trace header: %r" % rows[0]
    kitchen = [r for r in rows[1:] if ",lights-1,kitchen," in r]
    assert kitchen and all(r.startswith('"') and "lights over a lossy link" in r for r in kitchen), (
        "trace rows do not name the test: %r" % kitchen[:2])
    assert any(r.endswith(",1") for r in kitchen), "the trace never shows the kitchen light on"


def test_selection_and_seed(t):
    rc, out, err = vtest(t, "vtest-list", "--list", "--filter", "wrongly", case("expect"), case("lossy"))
    assert rc == 0 and out.strip().endswith("expect.lua: adds wrongly") and len(out.splitlines()) == 1, (
        "--list --filter: exit %d, printed %r" % (rc, out))
    rc, out, err = vtest(t, "vtest-filter", "--filter", "adds wrongly", case("expect"))
    assert rc == 1 and "FAIL  adds wrongly" in out and "ok    adds " not in out, "--filter ran:\n%s" % out

    # A run is a function of its seed: the same seed gives the same trace of
    # a lossy link, another seed another one.
    traces = []
    for i, seed in enumerate(("7", "7", "8")):
        path = os.path.join(t.logdir, "seed-%d.csv" % i)
        rc, out, err = vtest(t, "vtest-seed-%d" % i, "--seed", seed, "--trace", path, case("lossy"))
        assert rc == 0, "lossy.lua with --seed %s fails:\n%s" % (seed, out)
        with open(path) as f:
            traces.append(f.read())
    assert traces[0] == traces[1], "two runs with --seed 7 differ"
    assert traces[0] != traces[2], "--seed 7 and --seed 8 give the same trace of a lossy link"


def test_board_clocks_lock_and_repeat_under_a_seed(t):
    """Board clocks in virtual time (tests/vtest/cases/clocks.lua): two
    boards at +-100 ppm and seconds apart lock onto the virtual bus's SYNC
    within 2 s, read back their offsets and bounds, hold over, are lost and
    lock again, track a step of drift; the same seed prints the same numbers,
    another seed others; mistakes in the clock API fail at the test's line."""
    runs = []
    for i, seed in enumerate(("5", "5", "6")):
        rc, out, err = vtest(t, "vtest-clocks-%d" % i, "--seed", seed, case("clocks"))
        assert rc == 1, "clocks.lua --seed %s: exit %d, expected 1 (two tests fail on purpose)\n%s%s" % (
            seed, rc, out, err)
        runs.append(out)
    out = runs[0]
    for name in ("two boards at +-100 ppm, seconds apart, lock within 2 s",
                 "without SYNC a board holds over within its bound, then is lost",
                 "a step of drift (temperature) is tracked",
                 "a board without a clock of its own has a perfect one; SYNC is off unless asked",
                 "a perfect clock locks onto SYNC"):
        assert re.search(r"ok\s+%s" % re.escape(name), out), "%r fails:\n%s" % (name, out)
    for name, line, message in (
            ("a clock beyond 1000 ppm", 91, "board{...}: clock: ppm must be in -1000..1000, got 5000"),
            ("a clock step out of range", 96, "b:clock_step: a step of 200 ppm takes the drift from 900 to 1100 ppm, "
             "beyond +-1000")):
        assert re.search(r"FAIL\s+%s\n\s+at \S*clocks\.lua:%d\n\s+%s" % (re.escape(name), line, re.escape(message)),
                         out), "%r: not reported at line %d with %r:\n%s" % (name, line, message, out)
    assert "runner.lua" not in out, "a line of the runner shows:\n%s" % out

    m = re.search(r"^clock locked after ([\d.]+) s$", out, re.M)
    assert m and float(m.group(1)) <= 2.0, "the two boards did not lock within 2 s:\n%s" % out
    for board, offset in (("lights-1", 2.5), ("lights-2", -3.25)):
        m = re.search(r"^clock %s at lock: locked offset (-?[\d.]+) s bound ([\d.]+) us error (-?[\d.]+) us" % board,
                      out, re.M)
        assert m, "no clock line of %s at lock:\n%s" % (board, out)
        got, bound, error = (float(g) for g in m.groups())
        assert abs(got - offset) < 1e-3, "%s's offset at lock: %.9f s, set %g s" % (board, got, offset)
        assert 0 < bound <= 10 and abs(error) <= bound, "%s at lock: bound %.3f us, error %.3f us" % (
            board, bound, error)

    def numbers(text):
        return [ln for ln in text.splitlines() if ln.startswith("clock ")]
    assert len(numbers(runs[0])) >= 8, "too few clock lines:\n%s" % runs[0]
    assert numbers(runs[0]) == numbers(runs[1]), "two runs with --seed 5 differ:\n%s\n---\n%s" % (
        "\n".join(numbers(runs[0])), "\n".join(numbers(runs[1])))
    assert numbers(runs[0]) != numbers(runs[2]), "--seed 5 and --seed 6 print the same clocks:\n%s" % (
        "\n".join(numbers(runs[0])))


def test_two_boards_of_one_machine_act_at_one_instant(t):
    """Time-triggered I/O in virtual time (tests/vtest/cases/timed.lua): a
    press of two boards 200 ppm and seconds apart; once their clocks lock,
    every output change happens on both within 10 us (the case asserts it,
    per instant); without clock sync no TIMED frame goes out; a tick that
    waited for the one before it has no board's inputs sampled after its
    time."""
    rc, out, err = vtest(t, "vtest-timed", "--drivers", os.path.join(ROOT, "tests", "vtest", "drivers"),
                         case("timed"))
    assert rc == 0, "timed.lua: exit %d\n%s%s" % (rc, out, err)
    m = re.search(r"^timed spread: (\d+) instants compared, worst ([\d.]+) us$", out, re.M)
    assert m and int(m.group(1)) >= 100 and float(m.group(2)) <= 10.0, \
        "the two boards' output instants were not compared, or are more than 10 us apart:\n%s" % out


def test_an_input_the_driver_fails_in_is_never_reported_taken(t):
    """Operator input in virtual time (tests/vtest/cases/inputs.lua): taken,
    refused with the driver's reason, and failed in, which b:try_input
    reports as refused, with the driver's error, and which drops the
    machine, its board safe."""
    rc, out, err = vtest(t, "vtest-inputs", "--drivers", os.path.join(ROOT, "tests", "vtest", "drivers"),
                         case("inputs"))
    assert rc == 0, "inputs.lua: exit %d\n%s%s" % (rc, out, err)


def test_a_driver_of_ones_own(t):
    """What docs/TESTING.md walks through: a driver and its test in a folder
    of one's own, run with --drivers."""
    home = os.path.join(t.logdir, "mine")
    os.makedirs(os.path.join(home, "drivers"))
    os.makedirs(os.path.join(home, "tests"))
    with open(os.path.join(home, "drivers", "blinker.lua"), "w") as f:
        f.write("""-- Blinks do0 at 1 Hz while di0 is on.
local driver = {
	name = "blinker", version = "0.1.0", level = 5,
	io = { enable = "di0", lamp = "do0" },
	variables = { blinks = {} },
}
local last
function driver.attach(dev) dev.vars.blinks = 0 end
function driver.tick(dev, inputs)
	local on = inputs.enable and math.floor(inputs.time * 2) % 2 == 0
	if on and not last then dev.vars.blinks = dev.vars.blinks + 1 end
	last = on
	dev.out.lamp = on
end
return driver
""")
    with open(os.path.join(home, "tests", "blinker_test.lua"), "w") as f:
        f.write("""test("blinks once a second while enabled", function()
	local b = board { name = "blink-1", plant = "generic", driver = "blinker" }
	run_until(function() return b.state == "running" end, 5, "the blinker attached")
	expect(not b.out.lamp, "dark while disabled")
	b:set("di0", 1)
	run_for(10)
	expect_near(b.var.blinks, 10, 1, "blinks in 10 s")
	b:set("di0", 0)
	run_for(1)
	expect(not b.out.lamp, "dark once disabled")
end)
""")
    drivers, tests = os.path.join(home, "drivers"), os.path.join(home, "tests")
    rc, out, err = vtest(t, "vtest-mine", "--drivers", drivers, tests)
    assert rc == 0, "the user's driver test fails (exit %d):\n%s%s" % (rc, out, err)
    assert re.search(r"ok\s+blinks once a second while enabled", out), out

    # Without --drivers the host has no blinker: the test says so.
    rc, out, err = vtest(t, "vtest-mine-missing", tests)
    assert rc == 1, "without --drivers: exit %d, expected 1\n%s" % (rc, out)
    assert "blinker" in out, "the failure does not name the missing driver:\n%s" % out


HEATER_DRIVER = """-- Heats to 60 degC while the lid is closed (a plant of its own below).
return {
	name = "heater", version = "0.1.0", level = 5,
	io = { element = "do0", lid_closed = "di0", temp_c = { "ai0", scale = 0.05, offset = -20 } },
	variables = { temp_c = { unit = "degC" } },
	tick = function(dev, inputs)
		dev.out.element = inputs.lid_closed and inputs.temp_c < 60
		dev.vars.temp_c = inputs.temp_c
	end,
}
"""

HEATER_PLANT = """-- The heater's physics: an element that warms a pot, a lid, a noisy sensor.
return {
	io = { element = "do0", lid_closed = "di0", temp_c = { "ai0", scale = 0.05, offset = -20 } },
	state = { temp_c = 20, true_c = 20, lid_closed = true, noise = 0, broken = false },
	step = function(p, dt, out)
		if p.broken then error("the model broke") end
		p.true_c = p.true_c + dt * ((out.element and 3 or 0) - 0.02 * (p.true_c - 20))
		p.temp_c = p.true_c + p.noise * (math.random() - 0.5)
		if out.element and not p.lid_closed then return "element on with the lid open" end
	end,
	actions = {
		lid = function(p, v)
			if v ~= 0 and v ~= 1 then return false, "lid takes 0 (open) or 1 (closed)" end
			p.lid_closed = v == 1
		end,
	},
}
"""

HEATER_TEST = """test("heats to 60 with the lid closed, stops with it open", function()
	local b = board { name = "pot-1", plant = "heater" }
	run_until(function() return b.state == "running" end, 5, "the heater attached")
	eventually(function() return b.plant.true_c > 59 end, 120, "the pot reached 60")
	expect(b.plant.unsafe_episodes == 0, "no unsafe episode with the lid closed")
	b:set("lid", 0)
	run_for(1)
	expect(b.plant.unsafe_episodes == 1, "opening the lid with the element on is one episode")
	expect(not b.plant.lid_closed, "the lid is open")
	expect(not b:try_set("lid", 7), "lid 7 is refused")
	b:set("noise", 2)
	run_for(1)
	print("temp_c=" .. b.plant.temp_c)
end)
test("a refused action says why", function()
	local b = board { name = "pot-1", plant = "heater" }
	b:set("lid", 7)
end)
test("a plant that breaks fails the test at its line", function()
	local b = board { name = "pot-1", plant = "heater" }
	b:set("broken", 1)
	run_for(5)
end)
"""


def test_a_plant_of_ones_own(t):
    """A driver with a plant model in Lua of its own (docs/BOARD.md, "Plant
    models in Lua"): board{plant=} finds DIR/plants/NAME.lua, the driver's
    outputs drive it, its actions, refusals, unsafe episodes and fields are
    the test's; a plant that breaks fails the test naming the plant file's
    line; math.random follows --seed."""
    home = os.path.join(t.logdir, "plant")
    for sub in ("plants", "tests"):
        os.makedirs(os.path.join(home, sub), exist_ok=True)
    with open(os.path.join(home, "heater.lua"), "w") as f:
        f.write(HEATER_DRIVER)
    with open(os.path.join(home, "plants", "heater.lua"), "w") as f:
        f.write(HEATER_PLANT)
    with open(os.path.join(home, "tests", "heater_test.lua"), "w") as f:
        f.write(HEATER_TEST)
    test_file = os.path.join(home, "tests", "heater_test.lua")
    rc, out, err = vtest(t, "vtest-plant", "--drivers", home, "--seed", "3", test_file)
    assert rc == 1, "expected exit 1 (two tests fail on purpose), got %d:\n%s%s" % (rc, out, err)
    assert re.search(r"ok\s+heats to 60 with the lid closed", out), "the plant's test fails:\n%s" % out
    refused = re.search(r"FAIL\s+a refused action says why\n\s+at (\S+):(\d+)\n\s+(.*)", out)
    assert refused and refused.group(1).endswith("heater_test.lua") and refused.group(2) == "17", (
        "the refusal is not reported at the test's line 17:\n%s" % out)
    assert "the heater plant refuses lid = 7: lid takes 0 (open) or 1 (closed)" in refused.group(3), refused.group(3)
    broke = re.search(r"FAIL\s+a plant that breaks fails the test at its line\n\s+at (\S+):(\d+)\n\s+(.*)", out)
    assert broke and broke.group(2) == "22", "the plant's failure is not at the test's line 22 (run_for):\n%s" % out
    assert re.search(r"the heater plant of board pot-1 failed: \S*plants/heater\.lua:6: the model broke",
                     broke.group(3)), broke.group(3)

    # The same seed gives the same noise, another seed other noise.
    temps = []
    for seed in ("3", "3", "4"):
        rc, out, err = vtest(t, "vtest-plant-seed-" + seed, "--drivers", home, "--seed", seed, "--filter",
                             "heats to 60", test_file)
        assert rc == 0, "seed %s: exit %d\n%s%s" % (seed, rc, out, err)
        m = re.search(r"temp_c=([-\d.]+)", out)
        assert m, "the test printed no temperature:\n%s" % out
        temps.append(m.group(1))
    assert temps[0] == temps[1], "the same seed gave other noise: %s" % temps
    assert temps[0] != temps[2], "seeds 3 and 4 gave the same noise: %s" % temps


def test_programmes_come_from_the_drivers_folder(t):
    """A driver's programmes (vmac.cycles()) come from DIR/cycles/NAME/,
    inside the --drivers folder DIR, when it holds that folder, else from
    the shipped scripts/cycles/NAME/; a driver that finds none fails to load
    with an error naming the folder (docs/DRIVERS.md, "Cycles as scripts")."""
    home = os.path.join(t.logdir, "mine")
    drivers, tests = os.path.join(home, "drivers"), os.path.join(home, "tests")
    os.makedirs(drivers)
    os.makedirs(tests)
    shutil.copy(os.path.join(ROOT, "scripts", "drivers", "washer.lua"), drivers)
    with open(os.path.join(tests, "programmes_test.lua"), "w") as f:
        f.write("""test("the washer attaches", function()
	local w = board { name = "washer-1", plant = "washer" }
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached and idle")
end)
""")

    # No DIR/cycles/washer/: the shipped programmes.
    rc, out, err = vtest(t, "vtest-shipped-programmes", "--drivers", drivers, tests)
    assert rc == 0, "a washer of one's own with the shipped programmes fails (exit %d):\n%s%s" % (rc, out, err)

    # An empty DIR/cycles/washer/: no programmes, and the error says where it looked.
    mine = os.path.join(drivers, "cycles", "washer")
    os.makedirs(mine)
    rc, out, err = vtest(t, "vtest-no-programmes", "--drivers", drivers, tests)
    assert rc == 1, "a washer with no programmes: exit %d, expected 1\n%s%s" % (rc, out, err)
    want = "no programmes for washer in %s/" % mine
    assert want in out, "the failure does not say %r:\n%s" % (want, out[-2000:])

    # DIR/cycles/washer/ with one programme: that one, not the shipped ones.
    with open(os.path.join(mine, "normal.lua"), "w") as f:
        f.write("return function(w) w.drain() end\n")
    with open(os.path.join(tests, "programmes_test.lua"), "a") as f:
        f.write("""test("its one programme is the folder's", function()
	local w = board { name = "washer-1", plant = "washer" }
	run_until(function() return w.var.state == "idle" end, 5, "the washer attached and idle")
	local ok, why = w:try_input("start", "quick")
	expect(not ok and tostring(why):find("quick", 1, true), "quick refused, got: " .. tostring(why))
	w:input("start", "normal")
	run_until(function() return w.var.step == "drain" end, 60, "the folder's normal programme draining")
end)
""")
    rc, out, err = vtest(t, "vtest-own-programmes", "--drivers", drivers, tests)
    assert rc == 0, "a washer with a programme of its own fails (exit %d):\n%s%s" % (rc, out, err)


def test_bad_usage(t):
    rc, out, err = vtest(t, "vtest-help", "--help")
    assert rc == 0 and out.startswith("usage: vmac test"), "--help: exit %d, %r" % (rc, out[:100])
    for args, mention in ((["--seed"], "--seed needs a value"), (["--timeout", "-1"], "--timeout"),
                          (["--no-such"], "unknown option '--no-such'"),
                          (["/nonexistent/x_test.lua"], "no such file or folder"),
                          (["--drivers", "/nonexistent"], "no such folder"),
                          (["--junit", "/nonexistent/dir/j.xml", case("expect")], "--junit")):
        rc, out, err = vtest(t, "vtest-bad", *args)
        assert rc == 2, "vmac test %s: exit %d, expected 2 (bad usage)\n%s" % (" ".join(args), rc, err)
        assert mention in err, "vmac test %s: stderr does not say %r: %r" % (" ".join(args), mention, err)
