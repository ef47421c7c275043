"""Boards acting at the host's instants (docs/TIME.md, "Time-triggered I/O";
docs/PROTOCOL.md, "Time-triggered I/O"): the test plays the host over UDP
itself (DISCOVER, REGISTER, OFFSET, TIMED CYCLIC frames), vmacd with
clock_sync_ms 1 only sends the SYNC frames the boards' clocks lock onto
(the boards are registered by the test before vmacd starts, so it never
discovers them). The boards run without --clock-* options: each counter is
CLOCK_MONOTONIC itself, so the true instant of each action is in the
boards' own --io-log, never judged by when the test looked."""

import os
import re
import signal
import socket
import statistics
import struct
import time

from frames import (CLOCK_ARRIVAL, CLOCK_STATES, CYCLIC_DUE, DEV, DISCOVER, OFFSET, REGISTER, REPLY, SHUTDOWN, SYS,
                    TIMED, UPDATE, cyclic, frame, latch, parse, register, u16)
from harness import LOADED, sender_socket

SYNC_SETTINGS = {"clock_sync_ms": 1, "slice_us": 200, "slices_per_slot": 5}
# vmacd as the SYNC source of unkeyed boards the test serves: only an open
# bus carries the plain SYNC (docs/PROTOCOL.md, "The sealed SYNC").
SYNC_SOURCE = dict(SYNC_SETTINGS, bus_trust="open")
WATCHDOG_MS = 60000  # the test's session outlives any stall of this shared machine
AHEAD_NS = 50000000  # instants 50 ms after the send: the frame is there long before
FRAMES = 30  # at least; more while fewer than TIMED_WANT were answered at the instant by every board
SETTLE = 10  # the first frames (half a second after locking) are served but not judged: the servo settles
TIMED_WANT = 20  # frames after SETTLE whose every answer says it was latched by the clock, not on arrival
SPREAD_NS = 10000  # the issue's goal: two boards' true instants within 10 us
# From the intended instant: the clocks' error, plus the path's least delay
# (vmacd's send stamp to the kernel's receive stamp: one-way, no board can
# tell it from an offset, docs/TIME.md "The clock model"), which both
# boards share; 3 to 11 us measured on the shared 2-core VM.
OFF_NS = 25000
IO_LINE = re.compile(r"^(\S+) (out|latch) (instant|arrival|late|overrun) true=(-?\d+) host=(\d+) done=(-?\d+) "
                     r"digital=0x([0-9a-f]{2}) pwm=(-?\d+) clock=(\w+)$")


class Host:
    """The test's side of the bus: one UDP socket, multicast out on loopback."""

    def __init__(self, bus):
        self.sock, self.group = sender_socket(bus)
        self.sock.settimeout(5)
        self.boards = {}  # name: (address, device_id, tag)
        self.seq = 0

    def close(self):
        self.sock.close()

    def recv(self, timeout_s=30, loaded=True):
        """The next (header, data, payload, address) from a board, skipping
        what is not a reply; within LOADED times timeout_s, as the harness's
        waits (it blocks in recvfrom: until does not fit), or with loaded
        false, timeout_s as it is (discover's window between two DISCOVERs)."""
        if loaded:
            timeout_s *= LOADED
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            assert left > 0, "no reply from a board in %d s" % timeout_s
            self.sock.settimeout(left)
            payload, addr = self.sock.recvfrom(2048)
            got = parse(payload)
            if got and got[0].flags & REPLY:
                return got[0], got[1], payload, addr

    def discover(self, names):
        """DISCOVER until every board of names has announced; their addresses."""
        found = {}
        while set(found) != set(names):
            self.sock.sendto(frame(DISCOVER, channel=SYS, seq=1), self.group)
            try:
                while set(found) != set(names):
                    h, data, _, addr = self.recv(1, loaded=False)
                    if h.channel == SYS:
                        board = data[1 + data[0] + 8 + 1:1 + data[0] + 8 + 1 + data[1 + data[0] + 8]].decode()
                        major, minor = struct.unpack(">II", data[1 + data[0]:1 + data[0] + 8])
                        found[board] = (addr, major, minor)
            except (AssertionError, socket.timeout):
                pass
        return found

    def join(self, names):
        """Each board of names registered (version 2, a long watchdog) and
        given its offset: slot i + 1, generation 3."""
        for i, (name, (addr, major, minor)) in enumerate(sorted(self.discover(names).items())):
            device_id = (3 << 16) | (i + 1)
            self.request(addr, REGISTER, register(major, minor, WATCHDOG_MS), device_id)
            h, data = self.request(addr, OFFSET, u16(i + 1), device_id)
            assert struct.unpack(">H", data)[0] == i + 1, "%s echoed offset %r" % (name, data)
            self.boards[name] = (addr, device_id, 3)

    def request(self, addr, op, data, device_id):
        self.seq += 1
        self.sock.sendto(frame(op, data, device_id=device_id, seq=self.seq, version=2), addr)
        while True:
            h, got, _, _ = self.recv()
            if h.channel == DEV and h.seq == self.seq and h.device_id == device_id:
                assert h.op == op, "answered op 0x%02x to op 0x%02x" % (h.op, op)
                return h, got

    def timed(self, outputs, at_ns):
        """One TIMED CYCLIC to the group: each board's record (DUE) with
        outputs[name] = (digital, pwm), both instants at_ns; returns the seq."""
        self.seq += 1
        records = [(0, 0, 0, 0)] * (len(self.boards) + 1)
        for name, (_, device_id, tag) in self.boards.items():
            records[device_id & 0xFFFF] = (tag, CYCLIC_DUE) + outputs[name]
        self.sock.sendto(cyclic(records, seq=self.seq, out_at=at_ns, in_at=at_ns), self.group)
        return self.seq

    def answers(self, seq):
        """Every board's TIMED answer to frame seq: {name: Latch}."""
        by_id = {device_id: name for name, (_, device_id, _) in self.boards.items()}
        got = {}
        while len(got) < len(self.boards):
            h, data, payload, _ = self.recv()
            if h.seq != seq or h.device_id not in by_id:
                continue
            assert h.op == UPDATE and h.flags == REPLY | TIMED and len(payload) == 46, \
                "%s answered a TIMED CYCLIC with flags 0x%02x, %d bytes (want 0x05, 46)" % (
                    by_id[h.device_id], h.flags, len(payload))
            got[by_id[h.device_id]] = latch(data)
        return got

    def shutdown(self, name):
        addr, device_id, _ = self.boards[name]
        self.request(addr, SHUTDOWN, b"\x00", device_id)


def io_log(path):
    """The --io-log's lines, each a dict."""
    rows = []
    with open(path) as f:
        for text in f:
            m = IO_LINE.match(text.rstrip("\n"))
            assert m, "an --io-log line not as BOARD.md says: %r" % text
            rows.append({"board": m.group(1), "what": m.group(2), "how": m.group(3), "true": int(m.group(4)),
                         "host": int(m.group(5)), "done": int(m.group(6)), "digital": int(m.group(7), 16),
                         "pwm": int(m.group(8)), "clock": m.group(9)})
    return rows


def start_board(t, name, clock=(), count=None):
    log = os.path.join(t.logdir, name + ".io.log")
    return t.board("generic", name, keyed=False, count=count, extra=["--io-log", log] + list(clock)), log


def stop(board):
    board.signal(signal.SIGTERM)
    assert board.wait_exit(30) == 0, "a board did not exit cleanly"


def test_two_boards_change_their_outputs_at_one_host_instant(t):
    """Counters CLOCK_MONOTONIC itself: the clocks see one kernel's stamps."""
    two_boards_at_one_instant(t, {"axis-a": (), "axis-b": ()})


def test_two_boards_of_other_oscillators_change_their_outputs_at_one_host_instant(t):
    """Simulated oscillators 400 ppm and seconds apart, 20 us of receive
    jitter each (their own random streams): the true instant is when each
    counter reaches the instant's local time (the oscillator's inverse)."""
    two_boards_at_one_instant(t, {
        "axis-a": ("--clock-ppm", "200", "--clock-offset", "3.5", "--clock-jitter-us", "20", "--clock-seed", "1"),
        "axis-b": ("--clock-ppm", "-200", "--clock-offset", "-2.25", "--clock-jitter-us", "20", "--clock-seed", "2")})


def test_three_boards_of_one_process_change_their_outputs_at_one_host_instant(t):
    """vmac-board --count 3: the loop wakes for each board's instant."""
    two_boards_at_one_instant(t, {"axis": ()}, count=3)


def two_boards_at_one_instant(t, clocks, count=None):
    """clocks: {process name: its --clock-* options}; count: boards per
    process (NAME-1..NAME-count), else one named NAME."""
    procs = {name: start_board(t, name, clocks[name], count) for name in sorted(clocks)}
    boards = {}  # board name: (its process, its process's io-log)
    for name, proc in procs.items():
        for board in (["%s-%d" % (name, i) for i in range(1, count + 1)] if count else [name]):
            boards[board] = proc
    names = sorted(boards)
    host = Host(t.bus)
    try:
        host.join(names)
        t.host(settings=SYNC_SOURCE)  # SYNC only: it never sees the boards, already known
        for name, (board, _) in boards.items():
            board.wait_line(r"^%s: clock locked" % name, 60, what="%s's clock locked" % name)
        # A clock the loaded machine holds out of locked acts on arrival and
        # says so in its answers: frames go on (a minute at most) until
        # TIMED_WANT were answered by every board's clock.
        instants, timed, k = [], 0, 0
        deadline = time.monotonic() + 60 * LOADED
        while k < FRAMES or (timed < TIMED_WANT and time.monotonic() < deadline):
            at = time.monotonic_ns() + AHEAD_NS
            digital = 1 << (k % 7)
            seq = host.timed({name: (digital, 10 * (k % 100)) for name in names}, at)
            answers = host.answers(seq)
            instants.append((at, digital, answers))
            if k >= SETTLE and not any(a.clock & CLOCK_ARRIVAL for a in answers.values()):
                timed += 1
            k += 1
        # Outputs waiting when a SHUTDOWN comes are never driven (an instant
        # a second ahead: the SHUTDOWNs are sent right after, but a loaded
        # machine once held this script past 50 ms between the two).
        at = time.monotonic_ns() + 20 * AHEAD_NS
        host.timed({name: (0x7F, 1000) for name in names}, at)
        for name in names:
            host.shutdown(name)
        while time.monotonic_ns() < at + 2 * AHEAD_NS:  # past the cancelled instant, with room
            time.sleep(0.05)
        for name, (board, _) in boards.items():
            board.wait_line(r"^%s: acting at host instants$" % name, 10, what="'acting at host instants'")
        for board, _ in procs.values():
            stop(board)
    finally:
        host.close()

    rows = {name: [r for r in io_log(path) if r["board"] == name] for name, (_, path) in boards.items()}
    for name in names:
        # (on arrival, a clock not usable on a busy machine: driven before the SHUTDOWN, not waiting)
        assert not [r for r in rows[name] if r["host"] == at and r["how"] == "instant"], \
            "%s drove outputs a SHUTDOWN had cancelled: %r" % (name, [r for r in rows[name] if r["host"] == at])
        for r in rows[name]:
            # at an instant, never before it (for the others, true is the frame's arrival on the board's
            # counter, which --clock-jitter-us makes later than the kernel's stamp, maybe than done)
            assert r["how"] != "instant" or r["done"] >= r["true"], "%s acted %d ns before its instant: %r" % (
                name, r["true"] - r["done"], r)
    served, spreads, offs, lates = 0, [], [], []
    for at, digital, answers in instants[SETTLE:]:
        outs = {}
        for name in names:
            a = answers[name]
            state = CLOCK_STATES[a.clock & 7]
            if a.clock & CLOCK_ARRIVAL:
                continue  # this shared machine held a board's clock out of locked: said, and allowed
            assert state in ("locked", "holdover"), "%s acted at the instant with its clock %s" % (name, state)
            assert a.applied_digital == digital, "%s latched with 0x%02x applied, want 0x%02x" % (
                name, a.applied_digital, digital)
            out = [r for r in rows[name] if r["what"] == "out" and r["host"] == at]
            latched = [r for r in rows[name] if r["what"] == "latch" and r["host"] == at]
            assert len(latched) == 1, "%s's io-log of instant %d: %r" % (name, at, latched)
            if latched[0]["how"] == "instant":
                # latched_at is the clock's reading at the latch: a window closed since the frame came
                # may have moved the line by up to its bound
                assert abs(a.latched_at - at) <= a.bound_ns + 1000, \
                    "%s says it latched %d ns off the instant (its bound %d ns)" % (name, a.latched_at - at, a.bound_ns)
            else:  # late: the frame came after its instant (a stalled sender), latched on arrival
                assert latched[0]["how"] == "late" and a.latched_at >= at, "%s latched %r, answering %r" % (
                    name, latched[0], a)
            assert len(out) == 1 and out[0]["digital"] == digital, "%s's io-log of instant %d: %r" % (name, at, out)
            if out[0]["how"] == "instant":
                outs[name] = out[0]
        if len(outs) < len(names):
            continue
        served += 1
        trues = [r["true"] for r in outs.values()]
        spreads.append(max(trues) - min(trues))
        offs += [tr - at for tr in trues]
        lates += [r["done"] - r["true"] for r in outs.values()]
    judged = len(instants) - SETTLE
    assert served >= TIMED_WANT // 2, "only %d of %d frames were served at the instant by every board (%d answered " \
        "by every board's clock)" % (served, judged, timed)
    print("timed: %d of %d frames at the instant by every board; spread p50 %.2f max %.2f us; off the "
          "intended instant p50 %+.2f max |%.2f| us; wake-up after the instant p50 %.1f max %.1f us" % (
              served, judged, statistics.median(spreads) / 1e3, max(spreads) / 1e3, statistics.median(offs) / 1e3,
              max(abs(o) for o in offs) / 1e3, statistics.median(lates) / 1e3, max(lates) / 1e3))
    assert max(spreads) <= SPREAD_NS, "two boards' true instants %d ns apart (goal %d)" % (max(spreads), SPREAD_NS)
    assert max(abs(o) for o in offs) <= OFF_NS, "a board acted %d ns off the intended instant" % max(offs, key=abs)


def test_a_board_without_a_usable_clock_acts_on_arrival_and_says_so(t):
    board, path = start_board(t, "axis-c")
    host = Host(t.bus)
    try:
        host.join(["axis-c"])
        at = time.monotonic_ns() + 5 * 10**9  # far ahead: on arrival is long before it
        seq = host.timed({"axis-c": (0x05, -250)}, at)
        a = host.answers(seq)["axis-c"]
        board.wait_line(r"^axis-c: acting on arrival \(clock unsynced\)$", 10, what="'acting on arrival'")
        stop(board)
    finally:
        host.close()
    assert a.clock == CLOCK_ARRIVAL | 0, "clock byte 0x%02x, want ARRIVAL | unsynced" % a.clock
    assert a.latched_at == 0 and a.bound_ns == 0xFFFFFFFF and a.offset_ns == 0, \
        "an unsynced board claims a latch time, bound or offset: %r" % (a,)
    assert a.applied_digital == 0x05 and a.applied_pwm == -250, "applied %r, want the record's 0x05/-250" % (a,)
    rows = io_log(path)
    assert [(r["what"], r["how"]) for r in rows] == [("out", "arrival"), ("latch", "arrival")], rows
    assert all(r["done"] < at for r in rows), "acted on arrival, yet at or after the instant: %r" % rows
    counters = board.find_lines(r"^axis-c: timed \d+, on arrival 1, late 0, overrun 0$")
    assert counters, "no timed counters line at exit"


def test_a_board_whose_clock_is_lost_falls_back_to_arrival_and_says_so(t):
    """The host's SYNC stops: the board holds over, still acting at the
    instants, then is lost (its bound past 50 us, some 20 s later) and acts
    on arrival, saying so in its answer (ARRIVAL, lost) and its log."""
    board, path = start_board(t, "axis-d")
    host = Host(t.bus)
    try:
        host.join(["axis-d"])
        vmacd = t.host(settings=SYNC_SOURCE)
        board.wait_line(r"^axis-d: clock locked", 60, what="the clock locked")
        for _ in range(FRAMES):  # until one is served at its instant (a busy machine may unlock a window)
            at = time.monotonic_ns() + AHEAD_NS
            locked = host.answers(host.timed({"axis-d": (0x01, 0)}, at))["axis-d"]
            if not locked.clock & CLOCK_ARRIVAL:
                break
        mark = board.mark()  # a clock lost while it was first locking said so already
        vmacd.signal(signal.SIGTERM)
        assert vmacd.wait_exit(30) == 0, "vmacd did not exit cleanly"
        board.wait_line(r"^axis-d: clock lost, acting on arrival", 120, since=mark, what="the clock lost")
        late = time.monotonic_ns() + 5 * 10**9
        lost = host.answers(host.timed({"axis-d": (0x02, 0)}, late))["axis-d"]
        board.wait_line(r"^axis-d: acting on arrival \(clock lost\)$", 10, since=mark,
                        what="'acting on arrival (clock lost)'")
        stop(board)
    finally:
        host.close()
    assert not locked.clock & CLOCK_ARRIVAL, "acted on arrival with its clock locked: %r" % (locked,)
    assert lost.clock == CLOCK_ARRIVAL | 4 and lost.latched_at == 0, "a lost clock's answer: %r" % (lost,)
    assert lost.applied_digital == 0x02, "applied 0x%02x, want 0x02 driven on arrival" % lost.applied_digital
    rows = io_log(path)
    assert [(r["how"], r["clock"]) for r in rows if r["host"] == late] == [("arrival", "lost")] * 2, rows
    assert all(r["done"] < late for r in rows if r["host"] == late), "acted on arrival, yet after the instant"


PRESS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "vtest", "drivers", "press.lua")


def test_vmacd_and_two_boards_of_one_machine_act_at_one_instant(t):
    """End to end: vmacd (clock_sync_ms 1) runs a press of two keyed boards
    (tests/vtest/drivers/press.lua toggles a clamp on each every tick) on
    simulated oscillators 300 ppm and 4 s apart with 20 us of receive
    jitter; it sends its sealed SYNC and the machine's records in sealed
    TIMED frames of the phase-aligned pattern; both boards drive every
    change at the same instant, by their own --io-log."""
    press_at_one_instant(t, SYNC_SETTINGS, "vmacd and a press of two boards")


def test_vmacd_and_two_boards_served_by_unicast_act_at_one_instant_beside_a_version_1_board(t):
    """The same press with cyclic off: vmacd serves each board by a sealed
    TIMED UPDATE (docs/PROTOCOL.md, "The TIMED UPDATE"), the boards, given
    an offset for their MAC in the sealed SYNC, act at its instants; a
    board of protocol 1 beside them keeps its plain UPDATEs (it can never
    read a TIMED form) and is served without a drop (a rare miss of its
    process on this loaded machine aside)."""
    old_log = os.path.join(t.logdir, "old-1.io.log")
    old = t.board("generic", "old-1", extra=["--protocol", "1", "--io-log", old_log])
    status = press_at_one_instant(t, dict(SYNC_SETTINGS, cyclic="false"), "vmacd and a press of two boards by unicast",
                                  ["old-1"])
    devices = {d["name"]: d for d in status["devices"]}
    for name in ("press-0", "press-1"):
        assert devices[name]["service"] == "unicast", "%s is served by %s, not by unicast" % (
            name, devices[name]["service"])
    o = devices["old-1"]
    assert o["state"] == "running" and o["protocol"] == 1 and o["timing"]["timed"] is False and o["clock"] is None, \
        "the version-1 board: state %s, protocol %s, timing %r, clock %r" % (
            o["state"], o["protocol"], o["timing"], o["clock"])
    # Unaffected: no miss the host caused (the board's own, on a loaded
    # machine, are load, and a run of them a drop).
    assert o["misses_host"] == 0 and o["misses"] * 2 <= o["served"] and o["served"] >= 100, \
        "the version-1 board beside the timed press: misses %d (the host's %d), drops %d, served %d" % (
            o["misses"], o["misses_host"], o["drops"], o["served"])
    stop(old)
    assert io_log(old_log) == [], "the version-1 board acted on a TIMED service"


def press_at_one_instant(t, settings, what, others=()):
    """vmacd with settings runs the press of two keyed boards on simulated
    oscillators 300 ppm and 4 s apart with 20 us of receive jitter; every
    change both boards drove at the instant (from half a second after
    both did) within SPREAD_NS of each other, with the same outputs, by
    their --io-log. others: boards of the test's already started, running
    too. Returns vmacd's status, taken before the boards stop."""
    with open(PRESS) as f:
        drivers = t.drivers(press=f.read())
    host = t.host(drivers=drivers, settings=settings)
    logs, procs = {}, {}
    for minor, clock in ((0, ("--clock-ppm", "150", "--clock-offset", "2", "--clock-jitter-us", "20",
                              "--clock-seed", "3")),
                         (1, ("--clock-ppm", "-150", "--clock-offset", "-2", "--clock-jitter-us", "20",
                              "--clock-seed", "4"))):
        name = "press-%d" % minor
        logs[name] = os.path.join(t.logdir, name + ".io.log")
        procs[name] = t.board("generic", name, driver="press", major=7, minor=minor,
                              extra=["--io-log", logs[name]] + list(clock))
    host.wait_running(sorted(procs) + list(others))
    for name, board in procs.items():
        board.wait_line(r"^%s: acting at host instants$" % name, 60, what="%s acting at host instants" % name)
    def instants():
        """Each board's changes driven at the instant, by host instant, from
        its own log; and the host instants both drove at, but the first 25
        (the first half second: the servo settles)."""
        rows = {name: {r["host"]: r for r in io_log(path) if r["what"] == "out" and r["how"] == "instant"}
                for name, path in logs.items()}
        return rows, sorted(set(rows["press-0"]) & set(rows["press-1"]))[25:]

    # Changes (a 16 ms period) until 100 instants both boards drove at:
    # about two seconds, longer on a loaded machine, where a board's frame
    # may come too late for an instant (it then acts on arrival, or not).
    # Counted by the boards' own logs, not by when the test looks.
    deadline = time.monotonic() + 60 * LOADED  # then the assertions below say what came: until does not fit
    while time.monotonic() < deadline and len(instants()[1]) < 100:
        time.sleep(0.2)
    status = host.status()
    for board in procs.values():
        stop(board)
    rows, both = instants()
    assert len(both) >= 100, "only %d instants at which both boards drove at the instant: %r" % (
        len(both), {name: len(r) for name, r in rows.items()})
    spreads = sorted(abs(rows["press-0"][h]["true"] - rows["press-1"][h]["true"]) for h in both)
    for h in both:
        assert rows["press-0"][h]["digital"] == rows["press-1"][h]["digital"], \
            "the two clamps drove different outputs at instant %d: %r %r" % (h, rows["press-0"][h], rows["press-1"][h])
    print("%s: %d instants, spread p50 %.2f p99 %.2f max %.2f us" % (
        what, len(spreads), spreads[len(spreads) // 2] / 1e3, spreads[len(spreads) * 99 // 100] / 1e3,
        spreads[-1] / 1e3))
    assert spreads[-1] <= SPREAD_NS, "the two boards of one machine drove %d ns apart (goal %d)" % (
        spreads[-1], SPREAD_NS)
    devices = {d["name"]: d for d in status["devices"]}
    for name in procs:
        c, timing = devices[name]["clock"], devices[name]["timing"]
        assert c and c["state"] in ("locked", "holdover") and timing["pattern"] == "phase" and timing["timed"], \
            "the status of %s: clock %r, timing %r" % (name, c, timing)
    return status
