"""The schedule in a running host (docs/SCHEDULER.md, docs/HOST.md): the
table the status shows is even and never puts two devices in one slice;
admission control turns away a board that does not fit and disturbs no one;
boards of one machine share a driver and are dropped together; a driver can
change its level while running; GET /api/schedule and vmac schedule show
each service's deadline violation vector (seed 002)."""

import signal

from harness import plain_pass_too, undisturbed

# A driver that drives nothing and reports how many boards it sees.
PROBE_LUA = """-- probe: no outputs; publishes the number of boards and its level
local driver = { name = "probe", version = "1.0", io = { x = "di0", lamp = "do0" },
	variables = { boards = {}, level = {} } }
function driver.tick(dev, inputs)
	dev.vars.boards = #dev.boards
	dev.vars.level = dev.level
end
return driver
"""

# Two boards, one machine: the switch on the board with minor id 1 lights the
# lamp on the primary board (minor 0).
PAIR_LUA = """-- pair: a switch on one board, a lamp on the other
local driver = { name = "pair", version = "2.1",
	io = { lamp = "do0", switch = { "di0", board = 1 } },
	variables = { boards = {}, switch = {} } }
function driver.tick(dev, inputs)
	dev.vars.boards = #dev.boards
	dev.vars.switch = inputs.switch
	dev.out.lamp = inputs.switch == true
end
return driver
"""

# Starts at level 4 and asks for level 5 after ten ticks (slower: a longer
# watchdog goes to the board first).
SHIFTER_LUA = """-- shifter: changes its own level at run time
local driver = { name = "shifter", version = "1", level = 4, io = {}, variables = { answer = {} } }
local ticks = 0
function driver.tick(dev, inputs)
	ticks = ticks + 1
	if ticks == 10 then
		local ok, why = dev:set_level(5)
		dev.vars.answer = ok and "ok" or why
	end
end
return driver
"""


def served_rows(d, slots_per_block):
    """The (slot of the block, slice) pairs a device is served in."""
    period = 1 << d["level"]
    return {(row, d["slice"]) for row in range(d["slot"], slots_per_block, period)}


def check_table(s):
    """The invariants of docs/SCHEDULER.md on one status."""
    sched = s["schedule"]
    load = sched["slot_load"]
    assert len(load) == sched["slots_per_block"], "slot_load has %d entries for %d slots" % (
        len(load), sched["slots_per_block"])
    assert max(load) - min(load) <= 1, "uneven table: slot loads %d..%d" % (min(load), max(load))
    taken = {}
    for d in s["devices"]:
        if d["slot"] is None:
            continue
        assert 0 <= d["slice"] < sched["slices_per_slot"], "%s in slice %d of %d" % (
            d["name"], d["slice"], sched["slices_per_slot"])
        assert d["slot"] < (1 << d["level"]), "%s at level %d in slot %d" % (d["name"], d["level"], d["slot"])
        for cell in served_rows(d, sched["slots_per_block"]):
            assert cell not in taken, "%s and %s share slot %d slice %d" % (taken[cell], d["name"], *cell)
            taken[cell] = d["name"]
    per_slot = [0] * sched["slots_per_block"]
    for row, _ in taken:
        per_slot[row] += 1
    assert per_slot == load, "slot_load %s does not match the devices' places %s" % (load, per_slot)


def test_status_shows_an_even_table(t):
    host = t.host(drivers=t.drivers(probe=PROBE_LUA), settings={"max_level": 5})
    t.board("generic", "p", driver="probe", count=7)
    names = ["p-%d" % i for i in range(1, 8)]
    s = host.wait_running(names)
    s = host.wait_status(lambda s: all(host.device(n, s)["slot"] is not None for n in names), 30,
                         "every probe in the table")
    check_table(s)
    sched = s["schedule"]
    assert sched["slots_per_block"] == 32 and sched["slices_per_slot"] == 5, "schedule %r" % sched
    assert sched["slot_us"] == sched["slice_us"] * sched["slices_per_slot"], "slot_us %r" % sched
    assert sched["capacity_used"] == 7 * 2, "7 devices at level 4 of 5 use 14 slice-slots, status says %d" % (
        sched["capacity_used"])
    for n in names:
        d = host.device(n, s)
        assert d["level"] == 4 and d["period_us"] == 16 * sched["slot_us"], "%s level %r period %r" % (
            n, d["level"], d["period_us"])
        assert d["driver_version"] == "1.0", "%s driver_version %r" % (n, d["driver_version"])
    # Still even after devices come and go.
    t.board("generic", "q", driver="probe", count=3)
    s = host.wait_running(names + ["q-1", "q-2", "q-3"], invariant=undisturbed(names))
    check_table(s)


def test_admission_turns_away_what_does_not_fit(t):
    # One slice per slot, 4 slots per block, devices at level 1: room for two.
    settings = {"slice_us": 50000, "slices_per_slot": 1, "max_level": 2, "default_level": 1}
    host = t.host(drivers=t.drivers(probe=PROBE_LUA), settings=settings)
    t.board("generic", "a", driver="probe")
    t.board("generic", "b", driver="probe")
    host.wait_running(["a", "b"])
    since = host.last_event_seq()
    late = t.board("generic", "c", driver="probe")
    event = host.wait_event("schedule_full", "c", after_seq=since, invariant=undisturbed(["a", "b"]))
    assert "schedule full: need level 1" in event["text"] and "free capacity 0 of 4" in event["text"], (
        "schedule_full event unclear: %r" % event["text"])
    s = host.wait_status(lambda s: (host.device("c", s) or {}).get("state") == "sleeping", 30, "c sleeping",
                         undisturbed(["a", "b"]))
    assert "schedule full" in (host.device("c", s)["note"] or ""), "status note: %r" % host.device("c", s)["note"]
    assert s["counters"]["schedule_full"] >= 1, "counters.schedule_full not counted"
    late.wait_line(r"^c: state sleeping ", 30, what="'state sleeping' on the refused board")
    assert not late.find_lines(r"outputs digital=0x(?!00)"), "a refused board switched an output on"
    check_table(s)


def test_boards_of_one_machine_share_a_driver_and_fall_together(t):
    host = t.host(drivers=t.drivers(pair=PAIR_LUA))
    # The first board of a machine to attach is its primary (DRIVERS.md).
    main = t.board("generic", "pair-a", driver="pair", major=77, minor=0)
    host.wait_running(["pair-a"])
    aux = t.board("generic", "pair-b", driver="pair", major=77, minor=1, commands=True)
    s = host.wait_running(["pair-a", "pair-b"])
    s = host.wait_status(lambda s: host.device("pair-a", s)["variables"].get("boards") == 2, 30,
                         "the driver seeing two boards")
    assert host.device("pair-b", s)["machine"] == "pair-a", "pair-b not in pair-a's machine: %r" % (
        host.device("pair-b", s)["machine"])
    assert host.device("pair-b", s)["variables"] == {}, "variables shown on a board that is not the primary"
    assert host.device("pair-a", s)["level"] == host.device("pair-b", s)["level"], "boards of one machine at two levels"
    mark = len(main.lines["stdout"])
    aux.send("pair-b di0 1")
    main.wait_line(r"^pair-a: outputs digital=0x01 ", 30, since=mark, what="the lamp on pair-a lit by pair-b's switch")
    since = host.last_event_seq()
    mark = len(main.lines["stdout"])
    aux.kill()
    host.wait_event("dropped", "pair-b", after_seq=since)
    event = host.wait_event("dropped", "pair-a", after_seq=since)
    assert "pair-b, a board of the same machine" in event["text"], "pair-a's drop says %r" % event["text"]
    main.wait_line(r"^pair-a: outputs digital=0x00 pwm=0", 30, since=mark,
                   what="pair-a's outputs off when its partner board went away")
    # The remaining board comes back alone; the driver sees one board.
    s = host.wait_status(lambda s: host.device("pair-a", s)["state"] == "running"
                         and host.device("pair-a", s)["variables"].get("boards") == 1, 30,
                         "pair-a running again as a machine of one board")


def test_driver_changes_its_level(t):
    host = t.host(drivers=t.drivers(shifter=SHIFTER_LUA))
    t.board("generic", "shift", driver="shifter")
    host.wait_running(["shift"])
    event = host.wait_event("level", "shift")
    assert "level 4 -> 5" in event["text"], "level event says %r" % event["text"]
    s = host.wait_status(lambda s: host.device("shift", s)["level"] == 5
                         and host.device("shift", s)["slot"] is not None, 30, "shift at level 5",
                         undisturbed(["shift"]))
    assert host.device("shift", s)["variables"]["answer"] == "ok", "set_level answered %r" % (
        host.device("shift", s)["variables"]["answer"])
    served = host.device("shift", s)["served"]
    host.wait_status(lambda s: host.device("shift", s)["served"] > served + 20, 60,
                     "shift served at its new level", undisturbed(["shift"]))
    check_table(host.last)


def test_schedule_shows_each_services_deadline_violations(t):
    # miss_limit high: a board that stops answering stays in the table, its
    # misses counted rather than dropping it.
    host = t.host(drivers=t.drivers(probe=PROBE_LUA), settings={"miss_limit": 1000})
    quiet = t.board("generic", "quiet", driver="probe")
    t.board("generic", "steady", driver="probe")
    host.wait_running(["quiet", "steady"])
    table = host.get("/api/schedule")
    entries = {e["name"]: e for row in table["timeline"] for e in row["devices"]}
    assert entries["quiet"]["violations"] == {"misses": 0, "misses_host": 0, "driver_late": 0, "last": None}, (
        "a board that has missed nothing: %r" % entries["quiet"])
    # A stopped board cannot answer: every service of it misses its deadline.
    quiet.signal(signal.SIGSTOP)
    try:
        host.wait_status(lambda s: host.device("quiet", s)["misses"] >= 3, 30, "quiet missing three replies")
    finally:
        quiet.signal(signal.SIGCONT)
    s = host.wait_status(lambda s: host.device("quiet", s)["served"] > host.device("quiet", s)["misses"] + 5, 30,
                         "quiet answering again")
    misses = host.device("quiet", s)["misses"]
    table = host.get("/api/schedule")
    entries = {e["name"]: e for row in table["timeline"] for e in row["devices"]}
    v = entries["quiet"]["violations"]
    assert v["misses"] >= 3 and v["misses_host"] == 0 and v["driver_late"] == 0, "quiet's vector: %r" % v
    assert v["misses"] + v["misses_host"] >= misses, "the vector (%r) counts fewer than the status's %d misses" % (
        v, misses)
    assert v["last"]["kind"] == "miss" and v["last"]["ago_s"] >= 0, "quiet's last violation: %r" % v["last"]
    steady = entries["steady"]["violations"]
    if steady["last"] is None:  # a busy machine may have made steady miss too
        assert [x["name"] for x in table["violated"]] == ["quiet"], "violated: %r" % table["violated"]
    by_name = {x["name"]: x for x in table["violated"]}
    assert by_name["quiet"]["kind"] == "miss" and by_name["quiet"]["slot"] == host.device("quiet", s)["slot"], (
        "quiet in violated: %r" % by_name["quiet"])
    ages = [x["ago_s"] for x in table["violated"]]
    assert ages == sorted(ages), "violated is not the latest first: %r" % table["violated"]

    # vmac schedule shows the same table for people.
    rc, out, err = t.run([t.path("vmac"), "schedule", "--http", host.http], "vmac-schedule")
    assert rc == 0, "vmac schedule exited %d: %s" % (rc, err)
    line = next((ln for ln in out.splitlines() if " quiet " in ln and "probe" not in ln), None)
    assert line and int(line.split()[-3]) >= 3, "vmac schedule's line for quiet: %r in\n%s" % (line, out)
    assert "deadline violations, the latest first:" in out and "quiet" in out.split("latest first:")[1], out


@plain_pass_too("the shipped vmacd's ticks in time at 1 kHz")
def test_a_light_driver_at_one_khz_has_its_outputs_in_time(t):
    """Five boards every 1 ms slot, each its own machine of the light probe
    driver: a tick's outputs go with the machine's next service. A worker
    that ends a tick just after the tick that would have collected it must
    not make every later tick a slot late: the next reply collects the done
    tick (jobs.c, bus_collect_done_tick), so a late tick stays one. Before
    that, one late tick left the machine a slot behind for good: 40 to 90 %
    of the ticks late at 1 kHz on the shared 2-core VM (PERFORMANCE.md),
    and a machine once behind had every tick late from then on. How many
    ticks a loaded machine's wake-ups make late is not the host's to say
    (29 % in one make test), so the test judges that signature: over the
    second 5,000 services, each machine's ticks, by the host's own counts,
    are not all late. The probe's budget is 20 ms, not the default 2: with
    it, a tick is judged stalled 3 ms into it once its worker had 0.75 ms
    more CPU, which the sanitized build's worker once spent in a light tick
    on a loaded machine ("tick still running after 4.04 ms"; a garbage
    collection, most likely); how the bus judges a stall is test_stall's."""
    host = t.host(drivers=t.drivers(probe=PROBE_LUA),
                  settings={"slice_us": 200, "slices_per_slot": 5, "default_level": 0, "max_level": 1,
                            "reply_deadline_us": 1000, "miss_limit": 1000, "driver.probe.budget_us": 20000})
    t.board("generic", "fast", driver="probe", count=5)
    names = ["fast-%d" % i for i in range(1, 6)]
    host.wait_running(names)

    def late_and_served(s):
        return {n: (host.device(n, s).get("driver_late", 0), host.device(n, s)["served"]) for n in names}

    def total_served(s):
        return sum(served for _, served in late_and_served(s).values())

    served0 = total_served(host.wait_status(lambda s: True, 10, "a status"))
    half = late_and_served(host.wait_status(lambda s: total_served(s) - served0 >= 5000, 30,
                                            "5,000 services of the five boards"))
    end = late_and_served(host.wait_status(lambda s: total_served(s) - served0 >= 10000, 30,
                                           "10,000 services of the five boards"))
    behind = []
    for n in names:
        late, served = end[n][0] - half[n][0], end[n][1] - half[n][1]
        assert served >= 500, "%s was served %d times of the second 5,000 services" % (n, served)
        if late >= served * 9 // 10:
            behind.append("%s %d of %d" % (n, late, served))
    assert not behind, "machines a slot behind for good, their ticks' outputs late at nearly every service " \
        "of the second 5,000: %s" % ", ".join(behind)
