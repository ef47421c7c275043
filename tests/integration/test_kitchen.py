"""The demo kitchen (washer, dishwasher, lights) against a real host: attach,
a board that stops answering, and the two ways the host can go away."""

import json
import re
import signal
import time

from harness import KITCHEN, KITCHEN_NAMES, TIMING, undisturbed, watchdog_trip

EXPECTED_DRIVER = {"washer-1": "washer", "dish-1": "dishwasher", "lights-1": "lights"}


def test_kitchen_attaches(t):
    host = t.host()
    for plant, name in KITCHEN:
        t.board(plant, name)
    # A few discovery periods on a healthy machine; generous for a slow one.
    first = host.wait_running(KITCHEN_NAMES, timeout_s=30)
    for name, driver in EXPECTED_DRIVER.items():
        d = host.device(name, first)
        assert d["driver"] == driver, "%s runs driver %r, expected %r" % (name, d["driver"], driver)
        assert d["misses_host"] == 0, "%s missed %d replies by the host's fault while attaching" % (
            name, d["misses_host"])
    served = {n: host.device(n, first)["served"] for n in KITCHEN_NAMES}
    host.wait_status(
        lambda s: all(host.device(n, s)["served"] > served[n] + 10 for n in KITCHEN_NAMES),
        30,
        "served counters of every device growing",
        undisturbed(KITCHEN_NAMES),
    )
    for name in KITCHEN_NAMES:
        assert host.find_events("attached", name), "no 'attached' event for %s" % name

    rc, out, err = t.run([t.path("vmac"), "status", "--http", host.http], "vmac-status")
    assert rc == 0, "vmac status exited %d: %s" % (rc, err)
    for name, driver in EXPECTED_DRIVER.items():
        row = [l for l in out.splitlines() if l.split()[:1] == [name]]
        assert row, "vmac status lists no row for %s:\n%s" % (name, out)
        fields = row[0].split()
        assert fields[1] == driver and fields[3] == "running", "vmac status row for %s is %r" % (name, row[0])
        assert re.match(r"^\d+\.\d+\.\d+$", fields[2]), "no driver version in the row for %s: %r" % (name, row[0])

    rc, out, err = t.run([t.path("vmac"), "status", "--http", host.http, "--json"], "vmac-status-json")
    assert rc == 0, "vmac status --json exited %d: %s" % (rc, err)
    try:
        raw = json.loads(out)
    except ValueError as e:
        raise AssertionError("vmac status --json printed no valid JSON (%s): %.200s" % (e, out))
    assert sorted(d["name"] for d in raw["devices"]) == sorted(KITCHEN_NAMES), (
        "vmac status --json lists devices %s" % [d["name"] for d in raw["devices"]])
    assert raw["bus"]["group"] == t.bus, "status reports bus %r, started on %r" % (raw["bus"]["group"], t.bus)


def test_stopped_board_is_dropped_and_others_undisturbed(t):
    host = t.host()
    boards = t.kitchen(host)
    others = ["dish-1", "lights-1"]
    since = host.last_event_seq()

    boards["washer-1"].signal(signal.SIGSTOP)
    try:
        host.wait_status(lambda s: host.device("washer-1", s)["state"] == "errant", 30,
                         "washer-1 errant after SIGSTOP", undisturbed(others))
        dropped = host.wait_event("dropped", "washer-1", after_seq=since, invariant=undisturbed(others))
        assert "washer-1" in dropped["text"], "the dropped event does not name washer-1: %r" % dropped["text"]
        # Let the bus run on a while with washer-1 gone: the others must not notice.
        served = host.device("lights-1")["served"]
        host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 25, 30,
                         "lights-1 served while washer-1 is stopped", undisturbed(others))
    finally:
        boards["washer-1"].signal(signal.SIGCONT)

    attached = host.wait_event("attached", "washer-1", after_seq=dropped["seq"], invariant=undisturbed(others))
    assert attached, "washer-1 never re-attached"
    host.wait_running(["washer-1"], invariant=undisturbed(others))
    host.status()
    undisturbed(others)(host.last)


def lights_on(host, lights):
    """Flip wall switch 1 of lights-1 and wait for the kitchen light output."""
    # The driver toggles on a change between two ticks: let it see the switch
    # off first (its first tick publishes the lights, off).
    host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("kitchen") is False, 30,
                     "the lights driver's first tick (a switch flipped before it is no change)")
    mark = lights.mark()
    lights.send("lights-1 toggle1 1")
    lights.wait_line(r"^lights-1: outputs digital=0x01 ", 30, since=mark, what="'outputs digital=0x01'")


def test_host_kill9_boards_go_safe(t):
    host = t.host()
    boards = t.kitchen(host, commands=True)
    lights_on(host, boards["lights-1"])
    marks = {n: b.mark() for n, b in boards.items()}

    killed = time.monotonic()
    host.signal(signal.SIGKILL)
    limit_s = (TIMING["watchdog_ms"] + 2000) / 1000.0
    trips = {}
    for name, board in boards.items():
        trips[name] = trip = watchdog_trip(board, name, marks[name])
        took = trip.off_s - killed  # the board's own clock, not when the line was read
        assert took < limit_s, "%s tripped its watchdog %.2f s after the host died (limit %.2f s)" % (
            name, took, limit_s)
    # The light goes off in the watchdog's turn: the next outputs line.
    off = boards["lights-1"].wait_line(r"^lights-1: outputs ", 30, since=trips["lights-1"].line.index + 1,
                                       what="the outputs after the watchdog")
    assert off.text.endswith(" digital=0x00 pwm=0"), "lights-1 drives %r after its watchdog" % off.text
    assert host.wait_exit(10) == -signal.SIGKILL, "vmacd did not die of SIGKILL"

    # A new host on the same bus attaches them again, outputs off until the
    # drivers say otherwise (the lights driver starts with every light off).
    marks = {n: b.mark() for n, b in boards.items()}
    again = t.host()
    again.wait_running(KITCHEN_NAMES)
    for name, board in boards.items():
        board.wait_line(r"^%s: state known " % name, 30, since=marks[name], what="'state known' after the restart")
    served = again.device("lights-1")["served"]
    again.wait_status(lambda s: again.device("lights-1", s)["served"] > served + 10, 30,
                      "lights-1 served by the new host", undisturbed(KITCHEN_NAMES))
    relit = boards["lights-1"].find_lines(r"outputs digital=0x(?!00)", since=marks["lights-1"])
    assert not relit, "lights-1 switched a light on under the new host: %r" % relit[0].text


def test_host_sigterm_boards_go_safe(t):
    host = t.host()
    boards = t.kitchen(host, commands=True)
    lights_on(host, boards["lights-1"])
    marks = {n: b.mark() for n, b in boards.items()}

    host.signal(signal.SIGTERM)
    rc = host.wait_exit(60)
    assert rc == 0, "vmacd exited %d on SIGTERM, expected 0" % rc
    assert "putting every board in its safe state" in host.text(), "vmacd did not log the safe stop"
    for name, board in boards.items():
        board.wait_line(r"^%s: state unknown " % name, 30, since=marks[name], what="'state unknown'")
    boards["lights-1"].wait_line(r"^lights-1: outputs digital=0x00 pwm=0", 30, since=marks["lights-1"],
                                 what="'outputs digital=0x00'")
    for name, board in boards.items():
        outputs = board.find_lines(r"^%s: outputs " % name)
        assert not outputs or "digital=0x00 pwm=0" in outputs[-1].text, (
            "%s ended with %r" % (name, outputs[-1].text))
