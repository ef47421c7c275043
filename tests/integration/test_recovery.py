"""Recovery after a host crash (docs/DRIVERS.md "Recovery after a restart"):
vmacd is killed with SIGKILL while a washer runs its programme, and started
again on the same state folder. Each time the board's watchdog must turn
every output off, the store must pass SQLite's integrity check, and the
restarted host must either resume the programme from its checkpoint or
cancel it (stop, drain, unlock). Through it all the door is never unlocked
while the drum turns or the water is above the door: the simulated washer's
safety monitor prints no "washer UNSAFE:" line (its PTC door lock holds the
door while the host is away, docs/BOARD.md) and the host's status keeps
test_kitchen_cycles' door guard. Old and damaged checkpoints:
test_checkpoints.py.

The 50 crashes take about two minutes and run beside the other tests: each
trial judges the watchdog by the board's own clock (harness.watchdog_trip),
not by when the harness read its line, and the restart only against a
bound (RESTART_S); make test ran them beside the soak and the sanitizer
build all along."""

import os
import random
import signal
import sqlite3
import statistics
import sys
import time

from harness import Trip, plain_pass_too, sanitized, takes_about, watchdog_trip
from test_kitchen_cycles import DOOR_LEVEL_L, DOOR_LOCKED_BIT, LOCK_BIT, WASHER_STEPS, door_guard
from threads import schedstat, thread_of

TRIALS = 50
SANITIZED_TRIALS = 3
KILL_AFTER_S = (0.3, 1.6)   # a trial's kill comes this long after the programme runs again
LOCK_RELEASE_S = 20         # the PTC lock holds this long after the watchdog: longer than any restart here
SHORT_LOCK_RELEASE_S = 8    # enough for the 2 s an old checkpoint waits, and quicker to see the door released
# The boards' watchdog: shorter than the harness's 1.5 s (quicker trials, and
# a valve left open by a crashed host fills less), 3.5 periods of the
# washer's idle level: longer than 3 periods, so it is what the boards get.
WATCHDOG_MS = 700
WATCHDOG_S = WATCHDOG_MS / 1000.0
TRIP_LINE = r"^washer-1: watchdog: no frame for \d+ ms, outputs off"
# The crash trials' valves. At 1 l/s the water a valve adds between the
# checkpoint and the watchdog (at most checkpoint_s + the watchdog) is about
# the 2 l the washer accepts when it resumes: a killed fill resumes, and the
# programme gets through every step, spin too. From FAST_FILL_TRIAL on, 5 l/s:
# a killed fill has more water than its checkpoint, which a fill accepts (its
# valves ran until the watchdog); a drain or a cancel that was under way goes
# on. The quick programme's steps at time_scale 0.02: a 4.8 s wash, a 2.4 s
# spin.
SLOW_FILL_LPS, FAST_FILL_LPS, FAST_FILL_TRIAL = 1, 5, 31
TRIAL_TIME_SCALE = "0.02"
# Judged by the board's own clock (its trip line's times against the kill's
# moment, both CLOCK_MONOTONIC): the board looks every 5 ms, and reads the
# host's last frames a moment after they came; the rest covers a board that
# could not have real-time scheduling, held off the CPU by a busy machine.
WATCHDOG_LATE_S = 0.3
RESTART_S = 30              # a restarted host has its washer running within this
TUB_EMPTY_BIT = 2
CLEANUP_STEPS = ["stop", "drain", "unlock"]  # the washer's cancel: stop the drum, drain, unlock
STEPS = {"running": WASHER_STEPS, "cancelling": CLEANUP_STEPS}
ENDED = ("done", "cancelled")
RECENT_S = 0.25             # a step shown this shortly before a kill may not be in the store yet


def recovery_host(t, settings=None):
    """vmacd on the test's state folder (the same across restarts), saving
    checkpoints every second, the washer's quick programme shortened; with
    real-time scheduling, as a host is run (docs/HOST.md, `realtime`):
    its bus thread above the board programs' SCHED_FIFO 30, not a normal
    thread that a loaded machine held off for 937 ms while its boards ran
    (a clean-clone make test, early_trip's message)."""
    values = {"checkpoint_s": 1, "watchdog_ms": WATCHDOG_MS, "driver.washer.param.program": "quick",
              "driver.washer.param.time_scale": "0.01", "realtime": "true"}
    values.update(settings or {})
    return t.host(settings=values)


def washer_board(t, lock_release_s=LOCK_RELEASE_S, fill_lps=5):
    """The washer board, with operator commands: valves of fill_lps each, and
    a PTC door lock that holds lock_release_s after its solenoid goes off."""
    board = t.board("washer", "washer-1", commands=True)
    for action, value in (("fill_rate_lps", fill_lps), ("lock_release_s", lock_release_s)):
        board.send("washer-1 %s %s" % (action, value))
        board.wait_line(r"^washer-1: %s %s$" % (action, value), 10, what="%s set to %s" % (action, value))
    return board


def washer(host, s):
    return host.device("washer-1", s)


def var(host, s, name):
    """A variable the washer publishes, None while it is not attached."""
    d = washer(host, s)
    return d["variables"].get(name) if d and d["state"] == "running" else None


def level_l(host, s):
    return washer(host, s)["inputs"]["analog"][0] / 100.0


def start_programme(host, board, invariant):
    """Press the start button; returns the status showing the programme running."""
    board.send("washer-1 start")
    return host.wait_status(lambda s: var(host, s, "state") == "running", 30, "the programme started", invariant)


def assert_safe_board(board, when):
    """The plant's safety monitor never saw the door unlocked while the drum
    turned or the water was above the door."""
    unsafe = board.find_lines(r"^washer UNSAFE:") + board.find_lines(r"^washer UNSAFE:", stream="stderr")
    assert not unsafe, "%s: the board reports the door unlocked when it must not be: %s" % (
        when, "; ".join(l.text for l in unsafe))


def store_is_sound(t, when):
    """PRAGMA integrity_check of the state folder's vmac.db, opened read-only."""
    path = os.path.join(t.logdir, "vmac.db")
    con = sqlite3.connect("file:%s?mode=ro" % path, uri=True, timeout=10)
    try:
        rows = con.execute("PRAGMA integrity_check").fetchall()
    finally:
        con.close()
    assert rows == [("ok",)], "%s: the store fails its integrity check: %s" % (when, rows)


def last_outputs(board, before=None):
    """The board's outputs as it last printed them (before line index
    before, if given), e.g. 'digital=0x18 pwm=45'."""
    lines = [l for l in board.find_lines(r"^washer-1: outputs ") if before is None or l.index < before]
    return lines[-1].text.split("outputs ", 1)[1] if lines else "digital=0x00 pwm=0"


def early_trip(host, board, mark, when):
    """Fails when the board's watchdog tripped in its session with the
    running host, before line mark (the kill's): the host stopped serving
    it. Says what the host's status says of its bus and of the board."""
    known = board.find_lines(r"^washer-1: state known ")
    since = known[-1].index if known else 0
    trips = [line for line in board.find_lines(TRIP_LINE, since=since) if line.index < mark]
    if not trips:
        return
    trip = Trip(trips[-1])
    s = host.status()
    washer = next((d for d in s["devices"] if d["name"] == "washer-1"), {})
    raise AssertionError(
        "%s: washer-1's watchdog tripped before the kill, the host running: no frame for %d ms (last at %d ms, "
        "off at %d ms, the board's clock; the kill at %d ms). The host's status: tick %s, realtime %s; washer-1 %s; "
        "its bus thread since its start: %s" % (
            when, trip.off_ms - trip.last_frame_ms, trip.last_frame_ms, trip.off_ms, time.monotonic() * 1000,
            s.get("tick"), s.get("bus", {}).get("realtime"),
            {k: washer.get(k) for k in ("state", "level", "slot", "period_us", "misses", "misses_host", "note")},
            bus_thread_times(host)))


def bus_thread_times(host):
    """What the kernel says of vmacd's bus thread: how long it ran and how
    long it waited, runnable, for a CPU; a stall with little waiting was
    the host's own (blocked), not the machine's."""
    try:
        ran_ns, waited_ns, slices = schedstat(host.popen.pid, thread_of(host.popen.pid, "vmac-bus"))
    except (OSError, AssertionError) as e:
        return "not read (%s)" % e
    return "ran %.0f ms, waited for a CPU %.0f ms, %d times on a CPU" % (ran_ns / 1e6, waited_ns / 1e6, slices)


def crash(t, host, board, when, late_s=WATCHDOG_LATE_S):
    """SIGKILL vmacd; the board's watchdog must turn every output off within
    its period of the kill, by the board's own clock. Returns the seconds
    from the kill to the outputs going off."""
    mark = board.mark()
    early_trip(host, board, mark, when)
    killed_at = time.monotonic()
    host.signal(signal.SIGKILL)
    rc = host.wait_exit(10)
    host.kill()  # reaps it and closes its logs
    assert rc == -signal.SIGKILL, "%s: vmacd exited with %s, not by SIGKILL" % (when, rc)
    trip = watchdog_trip(board, "washer-1", mark, WATCHDOG_S + 10)
    took_s = trip.off_s - killed_at
    assert trip.period_s <= WATCHDOG_S, "%s: the board's watchdog is %.3f s, the host set %.3f s" % (
        when, trip.period_s, WATCHDOG_S)
    assert trip.off_ms - trip.last_frame_ms >= trip.period_ms, "%s: the watchdog tripped %d ms after the last " \
        "frame, before its period of %d ms" % (when, trip.off_ms - trip.last_frame_ms, trip.period_ms)
    assert took_s <= trip.period_s + late_s, "%s: the watchdog turned the outputs off %.2f s after the kill " \
        "(period %.2f s; its last frame came %.2f s after the kill; the board's clock)" % (
            when, took_s, trip.period_s, trip.last_frame_s - killed_at)
    # The watchdog's turn also prints the outputs, off, if they were not.
    if last_outputs(board, before=trip.line.index) != "digital=0x00 pwm=0":
        off = board.wait_line(r"^washer-1: outputs ", 10, since=trip.line.index + 1,
                              what="the outputs after the watchdog")
        assert off.text.endswith(" digital=0x00 pwm=0"), "%s: after the watchdog the board drives %s" % (
            when, off.text.split("outputs ", 1)[1])
    store_is_sound(t, when)
    return took_s


class Programme:
    """Where the washer's programme is, followed on every status across
    restarts: its phase (running: the programme's steps; cancelling: the
    cancel's stop, drain, unlock) and its position in that phase's steps.
    Steps come in order (a short one may fall between polls); after a
    restart the position goes on from where the store's checkpoint was."""

    def __init__(self, host):
        self.host = host
        self.phase = None   # running, cancelling, done, cancelled (None: not started)
        self.pos = None     # index into STEPS[phase]
        self.history = []   # (time.monotonic, phase, pos) on this host
        self.cancels = self.finished = 0
        self.ends = 0       # programmes seen ending, done or cancelled, as ended() wants

    def on_new_host(self, host):
        self.host = host
        self.history = []

    def check(self, s):
        v = washer(self.host, s)
        if not v or v["state"] != "running" or v["variables"].get("state") is None:
            return
        state, step = v["variables"]["state"], v["variables"].get("step")
        if state in ("paused", "failed", "idle") and self.phase is not None:
            raise AssertionError("the washer's programme is %s (step %s, error %r, water %.1f l) after %s" % (
                state, step, v["variables"].get("error"), level_l(self.host, s), self.where()))
        if state in ENDED:
            if self.phase in STEPS:
                self.ended(state, s)
            return
        if state not in STEPS or step not in STEPS[state]:
            return
        steps = STEPS[state]
        if state != self.phase:  # a new programme, or its cancel: from the first step
            assert state == "cancelling" or self.phase in (None,) + ENDED, \
                "the programme runs again after its cancel began (%s)" % self.where()
            if state == "running":
                self.history = []  # the store's position is this programme's from now on
            self.phase, self.pos = state, steps.index(step)
            self.cancels += state == "cancelling"
        else:
            later = [i for i in range(self.pos, len(steps)) if steps[i] == step]
            assert later, "step %s of %s after %s: out of order (%s)" % (step, state, self.where(), steps)
            self.pos = later[0]
        self.history.append((time.monotonic(), self.phase, self.pos))

    def ended(self, state, s):
        """A programme ended: done after it ran, cancelled after its cancel,
        and either way with the tub empty."""
        assert state == "done" if self.phase == "running" else state == "cancelled", \
            "the programme ended %s from %s" % (state, self.where())
        d = washer(self.host, s)
        assert d["inputs"]["digital"][TUB_EMPTY_BIT], "the programme %s with %.1f l in the tub" % (
            state, level_l(self.host, s))
        self.finished += state == "done"
        self.ends += 1
        self.phase, self.pos = state, None

    def active(self):
        return self.phase in STEPS

    def step(self):
        return STEPS[self.phase][self.pos] if self.active() else None

    def where(self):
        return "%s at step %s" % (self.phase, self.step()) if self.active() else str(self.phase)

    def settled_before(self, killed_at):
        """(phase, position) the store holds at least: the last one shown
        RECENT_S before the kill (a step change is checkpointed at once; the
        main thread writes it a moment later)."""
        settled = [(phase, pos) for at, phase, pos in self.history if at <= killed_at - RECENT_S]
        return settled[-1] if settled else (self.phase, 0)

    def resumed_from(self, phase_before, pos_before, s):
        """After a restart: 'resumed' (the same programme, no step back) or
        'drained' (cancelling); anything else fails."""
        v = washer(self.host, s)["variables"]
        state, step = v["state"], v["step"]
        if state == "running" and phase_before == "running":
            assert v.get("cycle") == "quick", "resumed programme %r, not quick" % v.get("cycle")
            later = [i for i in range(pos_before, len(WASHER_STEPS)) if WASHER_STEPS[i] == step]
            assert later, "resumed at step %s, back from %s (step %d of %s)" % (
                step, WASHER_STEPS[pos_before], pos_before, WASHER_STEPS)
            self.phase, self.pos = "running", later[0]
            self.history.append((time.monotonic(), self.phase, self.pos))
            return "resumed"
        if state == "cancelling" and step in CLEANUP_STEPS:
            self.phase, self.pos = "cancelling", CLEANUP_STEPS.index(step)  # a cancel's cleanup starts over
            self.cancels += phase_before == "running"
            self.history.append((time.monotonic(), self.phase, self.pos))
            return "drained"
        raise AssertionError("after the restart the washer is %s at step %s (error %r, water %.1f l), was %s at "
                             "step %s" % (state, step, v.get("error"), level_l(self.host, s), phase_before,
                                          STEPS.get(phase_before, ["-"] * 9)[pos_before]))


class CrashLoop:
    """Test 1's crash trials: the washer's board, the host of the moment (a
    new one after every kill), the door guard on its statuses and the
    programme followed across them."""

    def __init__(self, t, seed):
        self.t, self.rnd = t, random.Random(seed)
        self.host = self.new_host()
        self.board = washer_board(t, fill_lps=SLOW_FILL_LPS)
        self.fill_lps = SLOW_FILL_LPS
        self.host.wait_running(["washer-1"])
        self.programme = Programme(self.host)
        self.guard = door_guard(self.host)
        start_programme(self.host, self.board, self.check)
        self.ended_before_kill = 0  # kills that came just after a programme ended: trials repeated

    def set_fill(self, lps):
        self.board.send("washer-1 fill_rate_lps %s" % lps)
        self.board.wait_line(r"^washer-1: fill_rate_lps %s$" % lps, 10, what="the fill rate set to %s" % lps)
        self.fill_lps = lps

    def new_host(self):
        return recovery_host(self.t, {"driver.washer.param.time_scale": TRIAL_TIME_SCALE})

    def check(self, s):
        self.guard(s)
        self.programme.check(s)

    def lock_off_at_the_end(self):
        """After a programme's end: the door lock's solenoid off."""
        host = self.host
        host.wait_status(lambda s: not washer(host, s)["outputs"]["digital"][LOCK_BIT], 10,
                         "the door lock off at the end", self.guard)

    def run_to_kill_point(self):
        """Let the programme run a random while; one that ends (or reaches
        its last step, unlock) is followed by a new one. Returns the status
        of the kill point."""
        host, programme = self.host, self.programme
        kill_at = time.monotonic() + self.rnd.uniform(*KILL_AFTER_S)
        while True:
            s = host.wait_status(lambda s: time.monotonic() >= kill_at or not programme.active()
                                 or programme.step() == "unlock", 120, "the kill point", self.check)
            if programme.active() and programme.step() != "unlock":
                return s
            if programme.active():  # in its last step: let it end
                host.wait_status(lambda s: not programme.active(), 60, "the programme's end", self.check)
            self.lock_off_at_the_end()
            start_programme(host, self.board, self.check)
            kill_at = max(kill_at, time.monotonic() + KILL_AFTER_S[0])

    def trial(self, when):
        """Kill the host at a random point of the programme and start a new
        one. Returns (outcome, where it was killed, seconds from the new
        host's start to the programme running, seconds from the kill to the
        watchdog), or None when the programme had ended before the kill."""
        s = self.run_to_kill_point()
        phase_before, pos_before = self.programme.settled_before(time.monotonic())
        killed = "%s (%.1f l)" % (self.programme.where(), level_l(self.host, s))
        try:
            watchdog_s = crash(self.t, self.host, self.board, "the kill")
            started_at = time.monotonic()
            self.host = host = self.new_host()
            self.programme.on_new_host(host)
            self.guard = door_guard(host)
            s = host.wait_status(lambda s: var(host, s, "running") is True or var(host, s, "state") in ENDED,
                                 RESTART_S, "the washer's programme running again", self.guard)
            running_s = time.monotonic() - started_at
            if var(host, s, "state") in ENDED:
                # It ended between the last status and the kill (its last
                # step is short): nothing to recover.
                assert (phase_before, STEPS[phase_before][pos_before]) in (
                    ("running", "spin"), ("running", "unlock"), ("cancelling", "drain"), ("cancelling", "unlock")), \
                    "after the restart the programme is %s" % var(host, s, "state")
                self.programme.check(s)
                self.ended_before_kill += 1
                self.lock_off_at_the_end()
                start_programme(host, self.board, self.check)
                return None
            outcome = self.programme.resumed_from(phase_before, pos_before, s)
            # The host ran recover(); the driver says what it did: resumed, or cancelling and why.
            host.wait_event("recovered", "washer-1", "recover() ran", timeout_s=10, invariant=self.guard)
            host.wait_event("driver", "washer-1", "recovered: resuming" if outcome == "resumed" else "cancelling",
                            timeout_s=10, invariant=self.guard)
            assert_safe_board(self.board, "after the restart")
        except AssertionError as e:
            raise AssertionError("%s, killed %s: %s" % (when, killed, e))
        return outcome, killed, running_s, watchdog_s


@takes_about(140)
@plain_pass_too("all TRIALS crashes (the sanitizer pass crashes SANITIZED_TRIALS times)")
def test_the_washer_survives_50_host_crashes(t):
    seed = random.SystemRandom().randrange(1 << 30)
    loop = CrashLoop(t, seed)
    # Under the sanitizers (make test-asan runs every test again with
    # build/asan/bin) 3 trials look for memory errors on the same paths; the
    # 50 that judge the behaviour run in the plain build.
    under_asan = sanitized(t.path("vmacd"))
    trials_wanted = SANITIZED_TRIALS if under_asan else TRIALS
    trials = []  # (outcome, where killed, restart to running s, kill to watchdog s)
    with open(os.path.join(t.logdir, "recovery-trials.txt"), "w") as record:
        while len(trials) < trials_wanted:
            n = len(trials) + 1
            if n >= FAST_FILL_TRIAL and loop.fill_lps != FAST_FILL_LPS:
                loop.set_fill(FAST_FILL_LPS)
            result = loop.trial("trial %d of %d (seed %d)" % (n, trials_wanted, seed))
            if result:
                trials.append(result)
                record.write("trial %d: killed %s, %s at %s, restart to running %.2f s, watchdog %.2f s after the "
                             "kill\n" % ((n, result[1], result[0], loop.programme.where()) + result[2:]))
                record.flush()

        # A programme killed into runs to its end: done, or cancelled with
        # the tub drained, and the lock off. The 50 trials go through about
        # a programme and a quarter, so one usually ended among them (each
        # end is judged as it comes); if none did, the last one runs to its
        # end now, up to a minute of plant physics. Not under the
        # sanitizers: there that minute runs C paths the trials have run
        # (checkpoints, resume); the plain pass judges the end, and
        # test-drivers runs whole programmes, host crashes among them, under
        # the sanitizers in virtual time.
        if not under_asan and not loop.programme.ends:
            host = loop.host
            host.wait_status(lambda s: not loop.programme.active(), 180, "the last programme's end", loop.check)
            loop.lock_off_at_the_end()
        assert_safe_board(loop.board, "after %d trials (seed %d)" % (trials_wanted, seed))
        outcomes = [r[0] for r in trials]
        running_s, watchdog_s = [r[2] for r in trials], [r[3] for r in trials]
        resumed, drained = outcomes.count("resumed"), outcomes.count("drained")
        assert resumed + drained == trials_wanted, "outcomes: %s" % outcomes
        summary = "recovery: %d/%d trials safe, %d resumed, %d drained, restart-to-running p50 %.2f s max %.2f s" % (
            len(trials), trials_wanted, resumed, drained, statistics.median(running_s), max(running_s))
        detail = "recovery: seed %d; kill to outputs off (watchdog %.1f s) p50 %.2f s max %.2f s; %d programmes " \
            "done, %d cancels drained, %d ends seen, %d kills just after a programme ended (repeated)" % (
                seed, WATCHDOG_S, statistics.median(watchdog_s), max(watchdog_s), loop.programme.finished,
                loop.programme.cancels, loop.programme.ends, loop.ended_before_kill)
        record.write(summary + "\n" + detail + "\n")
    print(summary + "\n" + detail, file=sys.stderr, flush=True)  # the runner keeps a worker's stdout for itself
