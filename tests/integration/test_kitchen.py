"""The demo kitchen (washer, dishwasher, lights, and the dryer of
examples/kitchen/ with its plant in Lua) against a real host: attach, a
board that stops answering, the two ways the host can go away, and `make
run`'s own script starting all four."""

import json
import os
import re
import signal
import socket
import time
import urllib.request

from harness import (DRYER_PLANT, EXAMPLES_KITCHEN, KITCHEN, KITCHEN_NAMES, POLL_S, TIMING, Proc, undisturbed,
                     watchdog_trip)

EXPECTED_DRIVER = {"washer-1": "washer", "dish-1": "dishwasher", "lights-1": "lights", "dryer-1": "dryer"}
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_kitchen_attaches(t):
    host = t.host(drivers=EXAMPLES_KITCHEN)
    for plant, name in KITCHEN:
        t.board(plant, name)
    t.board(None, "dryer-1", plant_file=DRYER_PLANT)
    names = KITCHEN_NAMES + ["dryer-1"]
    # A few discovery periods on a healthy machine; generous for a slow one.
    first = host.wait_running(names, timeout_s=30)
    for name, driver in EXPECTED_DRIVER.items():
        d = host.device(name, first)
        assert d["driver"] == driver, "%s runs driver %r, expected %r" % (name, d["driver"], driver)
        assert d["misses_host"] == 0, "%s missed %d replies by the host's fault while attaching" % (
            name, d["misses_host"])
    served = {n: host.device(n, first)["served"] for n in names}
    host.wait_status(
        lambda s: all(host.device(n, s)["served"] > served[n] + 10 for n in names),
        30,
        "served counters of every device growing",
        undisturbed(names),
    )
    for name in names:
        assert host.find_events("attached", name), "no 'attached' event for %s" % name
    dryer = host.device("dryer-1")
    assert abs(dryer["variables"].get("temp_c", 0) - 20) < 1 and dryer["variables"].get("door_open") is False, (
        "the dryer's Lua plant at rest reads %r" % dryer["variables"])

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
    assert sorted(d["name"] for d in raw["devices"]) == sorted(names), (
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


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_make_run_starts_four_machines(t):
    """scripts/run-kitchen.sh, what `make run` runs: vmacd and four boards,
    the dryer from examples/kitchen with its Lua plant; the help names it;
    a line typed for dryer-1 reaches its board; TERM stops everything with
    every board safe. Its own bus, port and state folder; the demo's
    settings otherwise (10 ms deadline, two misses drop a machine, clock
    sync on, so every board has a clock in the status), so a
    board this shared machine holds off may drop and come back: judged is
    that all four come to run together."""
    state = os.path.join(t.logdir, "kitchen")
    http = "127.0.0.1:%d" % free_port()
    env = dict(os.environ, VMAC_STATE=state, VMAC_HTTP=http, VMAC_BUS=t.bus, VMAC_TIME_SCALE="0.05",
               VMAC_SET="realtime=false")
    kitchen = Proc(t._name("run-kitchen"), [os.path.join(ROOT, "scripts", "run-kitchen.sh"), t.bindir], t.logdir,
                   stdin=True, env=env)
    t.procs.append(kitchen)
    kitchen.wait_line(r"^The demo kitchen is running", 60, what="the kitchen's help")
    kitchen.wait_line(r"^    dryer-1 start 1 ", 10, what="the help line starting the dryer")
    with open(os.path.join(state, "token")) as f:
        token = f.read().strip()

    def devices():
        req = urllib.request.Request("http://%s/api/status" % http, headers={"Authorization": "Bearer " + token})
        with urllib.request.urlopen(req, timeout=10) as r:
            return {d["name"]: d for d in json.loads(r.read())["devices"]}

    def wait(predicate, what, timeout_s=60):
        deadline, last = time.monotonic() + timeout_s, {}
        while True:
            try:
                last = devices()
            except OSError:
                pass
            if predicate(last):
                return last
            assert kitchen.alive(), "run-kitchen.sh ended while waiting for %s: %s" % (what, kitchen.text("stdout"))
            assert time.monotonic() < deadline, "%s not seen within %.0f s; devices: %s" % (
                what, timeout_s, {n: d["state"] for n, d in last.items()})
            time.sleep(POLL_S)

    kitchen_names = ["washer-1", "dishwasher-1", "lights-1", "dryer-1"]
    running = wait(lambda ds: all(ds.get(n, {}).get("state") == "running" for n in kitchen_names),
                   "the four machines running")
    assert sorted(running) == sorted(kitchen_names), "make run's kitchen has %s" % sorted(running)
    drivers = {n: running[n]["driver"] for n in kitchen_names}
    assert drivers == {"washer-1": "washer", "dishwasher-1": "dishwasher", "lights-1": "lights",
                       "dryer-1": "dryer"}, "the kitchen's drivers: %s" % drivers
    assert all(running[n].get("authenticated") for n in kitchen_names), "a board of the kitchen is not sealed: %s" % {
        n: running[n].get("authenticated") for n in kitchen_names}
    # The demo runs clock sync: every board is served in TIMED frames and
    # its TIMED replies give it a clock in the status (locked or not: on
    # this loaded machine a board may still act on arrival now and then).
    # (A board dropped meanwhile keeps its clock until it announces again,
    # untimed while it has no machine: all three at once are waited for.)
    wait(lambda ds: all((ds.get(n) or {}).get("state") == "running" and ds[n].get("clock") and
                        ds[n]["timing"]["timed"] for n in kitchen_names), "every board running, timed, with a clock")

    kitchen.send("dryer-1 start 1")
    wait(lambda ds: ds.get("dryer-1", {}).get("variables", {}).get("state") == "running",
         "the dryer started by its typed start button")

    # The boards' lines, kept with their time in STATE/boards.log, read by
    # vmac logs --board-log beside the host's: a refused action is a warn.
    logs = [t.path("vmac"), "logs", "--http", http, "--token-file", os.path.join(state, "token"), "--board-log",
            os.path.join(state, "boards.log")]
    follow = Proc(t._name("logs-boards"), logs + ["-f", "dryer-1"], t.logdir)
    t.procs.append(follow)
    kitchen.send("dryer-1 spin 3")
    kitchen.wait_line(r"^dryer-1: refused spin 3: ", 30, what="the dryer's refusal of an unknown action")
    follow.wait_line(r"^\d\d:\d\d:\d\d warn  dryer-1: refused spin 3: the dryer plant refuses spin = 3: no action",
                     30, what="vmac logs -f showing the board's refusal as warn, with the time make run kept")
    once = Proc(t._name("logs-boards-once"), logs + ["--level", "warn"], t.logdir)
    t.procs.append(once)
    assert once.wait_exit(30) == 0, "vmac logs --board-log did not stop by itself: %s" % once.text("stderr")
    lines = once.text("stdout").splitlines()
    assert any(re.match(r"^\d\d:\d\d:\d\d warn  dryer-1: refused spin 3", l) for l in lines), (
        "vmac logs --level warn --board-log left out the refusal: %s" % lines)
    assert not any(" info  " in l for l in lines), "--level warn showed info lines: %s" % lines

    mark = kitchen.mark()
    kitchen.signal(signal.SIGTERM)
    kitchen.wait_line(r"^run-kitchen: stopped", 60, since=mark, what="'run-kitchen: stopped'")
    assert kitchen.wait_exit(30) == 0, "run-kitchen.sh did not exit 0 on TERM"
    safe = kitchen.find_lines(r"^vmac-board: stopped by signal \d+, all outputs off", since=mark)
    assert len(safe) == 4, "%d of the four boards said they stopped with their outputs off: %s" % (
        len(safe), kitchen.text("stdout").splitlines()[-12:])
