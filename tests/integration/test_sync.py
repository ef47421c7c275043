"""Board clocks disciplined by the host's SYNC frames (docs/TIME.md,
docs/PROTOCOL.md "SYNC"): vmacd with clock_sync_ms on, vmac-board processes
whose simulated counters run fast and slow by 200 ppm, seconds apart, with
20 us of receive jitter. Each board locks onto the host's clock, says so
with its own timestamp, and holds over, then is lost, when the host stops.
Boards that cannot use SYNC (version 1) and boards started as before (no
clock options) are served as ever and count nothing malformed."""

import re
import signal

from harness import KITCHEN, KITCHEN_NAMES

# 1 ms slots so that a SYNC goes out every millisecond (at most one a tick),
# the rate the clock's filter is made for; the tests' relaxed deadlines stay.
SYNC_SETTINGS = {"clock_sync_ms": 1, "slice_us": 200, "slices_per_slot": 5}

# name: (--clock-ppm, --clock-offset s, --clock-seed)
CLOCKS = {"washer-1": (200, 3.5, 1), "dish-1": (-200, -2.25, 2), "lights-1": (75, 0.75, 3)}
JITTER_US = 20

LOCK_WITHIN_MS = 5000  # first SYNC to locked, by the board's own clock lines (about 1.5 s measured)
OFFSET_TOLERANCE_S = 0.05  # the offset has drifted by at most 200 ppm x the seconds since the start
# The first frequency estimate can be 20 ppm off when the clock locks (its
# bound is about time, not frequency: 20 ppm is 0.3 us a 16 ms window); the
# servo has taken it within a few ppm by the time SYNC stops, 3 s later.
DRIFT_AT_LOCK_PPM = 50
DRIFT_AT_HOLDOVER_PPM = 10

CLOCK_LINE = re.compile(r"^(\S+): clock (\w+)(?:, offset ([-+][0-9.]+) s, drift ([-+][0-9.]+) ppm, "
                        r"bound ([0-9.]+) us)?(?:, acting on arrival)?; at (\d+) ms$")
COUNTERS = re.compile(r"^(\S+): frames ok (\d+), malformed (\d+), ignored (\d+), watchdog trips (\d+), "
                      r"auth_failed (\d+)$")
CLOCK_STATUS = re.compile(r"^(\S+): clock (\w+).*; sync accepted (\d+), rejected (\d+), ignored (\d+)$")


def clock_line(board, name, state, timeout_s, since=0):
    line = board.wait_line(r"^%s: clock %s\b" % (re.escape(name), state), timeout_s, since=since,
                           what="'clock %s'" % state)
    m = CLOCK_LINE.match(line.text)
    assert m, "%s: a clock line not as BOARD.md says: %r" % (name, line.text)
    return m, line


def latest_state(board, name):
    lines = board.find_lines(r"^%s: clock \w+" % re.escape(name))
    return lines[-1].text.split()[2].rstrip(",;") if lines else None


def test_boards_lock_onto_the_host_and_are_lost_when_it_stops(t):
    host = t.host(settings=SYNC_SETTINGS)
    boards = {}
    for plant, name in KITCHEN:
        ppm, offset_s, seed = CLOCKS[name]
        boards[name] = t.board(plant, name, extra=["--clock-ppm", str(ppm), "--clock-offset", str(offset_s),
                                                   "--clock-jitter-us", str(JITTER_US), "--clock-seed", str(seed)])
    host.wait_running(KITCHEN_NAMES)
    marks = {}
    for name, board in boards.items():
        ppm, offset_s, _ = CLOCKS[name]
        locking, _ = clock_line(board, name, "locking", 30)
        locked, line = clock_line(board, name, "locked", 30)
        took_ms = int(locked.group(6)) - int(locking.group(6))
        assert took_ms <= LOCK_WITHIN_MS, "%s locked %d ms after its first SYNC, more than %d" % (
            name, took_ms, LOCK_WITHIN_MS)
        offset, drift, bound = float(locked.group(3)), float(locked.group(4)), float(locked.group(5))
        assert abs(offset - offset_s) <= OFFSET_TOLERANCE_S, \
            "%s locked at an offset of %.6f s, its counter is %.2f s ahead" % (name, offset, offset_s)
        assert abs(drift - ppm) <= DRIFT_AT_LOCK_PPM, \
            "%s locked with a drift of %+.1f ppm, its counter runs %+d ppm" % (name, drift, ppm)
        assert bound <= 10.0, "%s says locked with a bound of %.1f us (locked: within 10 us)" % (name, bound)
        marks[name] = line.index + 1
    c = host.status()["counters"]
    assert c["syncs"] > 0, "the host counts no SYNC sent: %r" % c
    assert c["malformed_frames"] == 0, "the host counted frames of its bus as malformed: %r" % (
        c["malformed_by_reason"],)
    # 3000 more SYNC frames (3 s): the servo learns the frequency it will
    # hold over on. A board may leave locked for a window whose bound
    # passes 20 us (seen under ASan on a loaded VM), or hold over when the
    # shared machine held the host's bus thread or the board's process off
    # the CPU for 50 ms (no SYNC taken for that long is what holdover
    # means), but is never lost while SYNC comes, and is locked again
    # before the host stops.
    host.wait_status(lambda st: st["counters"]["syncs"] >= c["syncs"] + 3000, 60, "3000 more SYNC frames")
    host.wait_status(lambda st: all(latest_state(b, n) == "locked" for n, b in boards.items()), 30,
                     "every board locked")
    for name, board in boards.items():
        assert not board.find_lines(r"^%s: clock lost" % re.escape(name), since=marks[name]), \
            "%s was lost while SYNC came: %r" % (
                name, [l.text for l in board.find_lines(r"^%s: clock" % name, since=marks[name])])
        marks[name] = board.find_lines(r"^%s: clock " % re.escape(name))[-1].index + 1

    stopped_in = {name: latest_state(board, name) for name, board in boards.items()}
    host.signal(signal.SIGTERM)
    host.wait_exit(30)
    for name, board in boards.items():
        if stopped_in[name] != "locked":
            # It had just left locked for a window (a busy machine, above):
            # without SYNC from there it is lost, with no holdover first.
            clock_line(board, name, "lost", 90, since=marks[name])
            continue
        holdover, _ = clock_line(board, name, "holdover", 10, since=marks[name])
        lost, _ = clock_line(board, name, "lost", 90, since=marks[name])
        held_ms = int(lost.group(6)) - int(holdover.group(6))
        assert held_ms >= 1000, "%s held over only %d ms without SYNC before it was lost" % (name, held_ms)
        assert float(holdover.group(5)) <= 50.0, "%s went holdover with a bound of %s us, past lost's 50" % (
            name, holdover.group(5))
        ppm = CLOCKS[name][0]
        assert abs(float(holdover.group(4)) - ppm) <= DRIFT_AT_HOLDOVER_PPM, \
            "%s holds over at a drift of %s ppm, its counter runs %+d ppm" % (name, holdover.group(4), ppm)


def test_version_1_and_plain_boards_are_unaffected(t):
    host = t.host(settings=SYNC_SETTINGS)
    old = t.board("lights", "lights-1", extra=["--protocol", "1"])
    plain = t.board("washer", "washer-1")
    host.wait_running(["lights-1", "washer-1"])
    s = host.status()
    assert host.device("lights-1", s)["protocol"] == 1, "lights-1 is not served in version 1"
    # SYNC is on the bus: the plain board (its counter CLOCK_MONOTONIC) locks on it.
    clock_line(plain, "washer-1", "locked", 30)
    served = host.device("lights-1")["served"]
    host.wait_status(lambda st: host.device("lights-1", st)["served"] > served + 20, 30,
                     "the version-1 board served 20 times more")
    c = host.status()["counters"]
    assert c["malformed_frames"] == 0, "the host counted frames as malformed: %r" % (c["malformed_by_reason"],)

    for name, board in (("lights-1", old), ("washer-1", plain)):
        board.signal(signal.SIGTERM)
        assert board.wait_exit(30) == 0, "%s did not exit cleanly" % name
        counters = [COUNTERS.match(l.text) for l in board.find_lines(r"^%s: frames ok " % name)]
        assert counters and counters[-1], "%s printed no counters at exit" % name
        assert int(counters[-1].group(2)) > 0 and int(counters[-1].group(3)) == 0, \
            "%s: %s (want frames ok, none malformed)" % (name, counters[-1].group(0))
        status = [CLOCK_STATUS.match(l.text) for l in board.find_lines(r"^%s: clock .*; sync accepted" % name)]
        assert status and status[-1], "%s printed no clock line at exit" % name
        if name == "lights-1":
            assert status[-1].group(2) == "unsynced" and int(status[-1].group(3)) == 0 and \
                int(status[-1].group(5)) > 0, \
                "the version-1 board: %s (want unsynced, SYNC ignored)" % status[-1].group(0)
        else:
            assert int(status[-1].group(3)) > 0 and int(status[-1].group(5)) == 0, \
                "the plain board: %s (want SYNC accepted)" % status[-1].group(0)


def test_boards_lock_onto_the_host_on_raw_ethernet(t):
    """SYNC as an Ethernet broadcast; the boards' receive times from the
    packet ring (root: a veth pair and a namespace, else SKIP)."""
    host_if, ns, board_if = t.eth_link()
    host = t.host(bus="eth:" + host_if, settings=SYNC_SETTINGS)
    board = t.board("lights", "lights", count=2, bus="eth:" + board_if, wrapper=("ip", "netns", "exec", ns),
                    extra=["--clock-ppm", "-150", "--clock-offset", "-1.5", "--clock-jitter-us", str(JITTER_US)])
    host.wait_running(["lights-1", "lights-2"])
    for name in ("lights-1", "lights-2"):
        locking, _ = clock_line(board, name, "locking", 30)
        locked, _ = clock_line(board, name, "locked", 30)
        took_ms = int(locked.group(6)) - int(locking.group(6))
        assert took_ms <= LOCK_WITHIN_MS, "%s locked %d ms after its first SYNC, more than %d" % (
            name, took_ms, LOCK_WITHIN_MS)
        assert abs(float(locked.group(3)) + 1.5) <= OFFSET_TOLERANCE_S and \
            abs(float(locked.group(4)) + 150) <= DRIFT_AT_LOCK_PPM, \
            "%s locked at %s (its counter: -1.5 s, -150 ppm)" % (name, locked.group(0))
    c = host.status()["counters"]
    assert c["syncs"] > 0 and c["malformed_frames"] == 0, "host counters: %r" % c
