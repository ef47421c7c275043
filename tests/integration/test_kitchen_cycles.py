"""The demo kitchen's programmes end to end, with the real host, the shipped
drivers and cycle scripts, and the mock boards' simulated plants: a whole
washer programme, the door opened mid-wash, cancel, the dishwasher with its
door, and the lights. Cycles are shortened by the drivers' time_scale param
(docs/DRIVERS.md, host setting driver.NAME.param.KEY) and faster valves."""

from harness import plain_pass_only, undisturbed

STILL_RPM = 10       # the driver's own threshold is 2 RPM; published values lag up to 0.2 s at 50 RPM/s
SETTLE_S = 0.5       # the status shows the outputs a board applied, a period or two behind the inputs
DOOR_LEVEL_L = 5.0   # washer param door_level_l (default)
LOCK_BIT, DOOR_LOCKED_BIT = 3, 1

WASHER_STEPS = ["lock", "fill", "wash", "drain", "fill", "rinse", "drain", "spin", "unlock"]


def washer_host(t, extra=None):
    settings = {"driver.washer.param.time_scale": "0.002", "driver.washer.param.program": "quick",
                "driver.dishwasher.param.time_scale": "0.02", "driver.dishwasher.param.program": "rinse"}
    settings.update(extra or {})
    return t.host(settings=settings)


def door_guard(host):
    """Invariant on every status: the washer never lets its door unlock while
    the drum turns or the water is above the door. Right after the door is
    closed the lock needs a period to come on (the status shows the outputs
    applied at the last reply), so a door closed for less than SETTLE_S is
    not judged."""
    closed_since = [None]

    def check(s):
        d = host.device("washer-1", s)
        if not d or d["state"] != "running":
            return
        v = d["variables"]
        lock_on = d["outputs"]["digital"][LOCK_BIT]
        door_closed = d["inputs"]["digital"][0]
        level = d["inputs"]["analog"][0] / 100.0
        if not door_closed:
            closed_since[0] = None
            return
        if closed_since[0] is None:
            closed_since[0] = s["uptime_s"]
        if s["uptime_s"] - closed_since[0] >= SETTLE_S and not lock_on:
            assert abs(v.get("drum_rpm") or 0) < STILL_RPM, (
                "door unlocked with the drum at %.1f RPM (step %s)" % (v.get("drum_rpm"), v.get("step")))
            assert level <= DOOR_LEVEL_L + 0.2, "door unlocked with %.2f l of water (step %s)" % (level, v.get("step"))

    return check


def both(*checks):
    def check(s):
        for c in checks:
            c(s)
    return check


def washer_var(host, s, name):
    return host.device("washer-1", s)["variables"].get(name)


def start_washer(t, host, boards):
    boards["washer-1"].send("washer-1 fill_rate_lps 5")
    boards["washer-1"].wait_line(r"^washer-1: fill_rate_lps 5", 10, what="the fill rate set")
    boards["washer-1"].send("washer-1 start")
    host.wait_status(lambda s: washer_var(host, s, "state") == "running", 30, "the washer running",
                     door_guard(host))


@plain_pass_only("the wash programme under the sanitizers: test-drivers' washer tests run it to its end")
def test_washer_runs_a_whole_programme(t):
    host = washer_host(t)
    boards = t.kitchen(host, commands=True)
    others = ["dish-1", "lights-1"]
    since = host.last_event_seq()
    start_washer(t, host, boards)
    seen = []

    def record(s):
        door_guard(host)(s)
        undisturbed(others)(s)
        step = washer_var(host, s, "step")
        if step and step != "-" and (not seen or seen[-1] != step):
            seen.append(step)

    s = host.wait_status(lambda s: washer_var(host, s, "state") == "done", 120, "the quick programme done", record)
    # Every step seen, in programme order (a short one may fall between polls).
    it = iter(WASHER_STEPS)
    assert all(step in it for step in seen), "steps out of order: %s (programme %s)" % (seen, WASHER_STEPS)
    for step in ("fill", "wash", "drain", "spin"):
        assert step in seen, "step %s never seen; saw %s" % (step, seen)
    assert washer_var(host, s, "cycle") == "quick", "cycle variable %r" % washer_var(host, s, "cycle")
    assert host.find_events("level", "washer-1", "level 5 -> 4", since), "the washer did not speed up to level 4"
    host.wait_status(lambda s: host.device("washer-1", s)["level"] == 5, 30, "the washer back at level 5")
    s = host.wait_status(lambda s: host.device("washer-1", s)["outputs"] == {"digital": [False] * 7, "pwm": 0}
                         and not host.device("washer-1", s)["inputs"]["digital"][DOOR_LOCKED_BIT], 10,
                         "every output off and the door unlocked after the programme")
    d = host.device("washer-1", s)
    assert d["inputs"]["analog"][0] < 50, "water left in the tub: %d counts" % d["inputs"]["analog"][0]


@plain_pass_only("the door interlock under the sanitizers: test-drivers' washer door tests")
def test_washer_door_opened_mid_wash(t):
    host = washer_host(t, {"driver.washer.param.time_scale": "0.01"})
    boards = t.kitchen(host, commands=True)
    washer = boards["washer-1"]
    start_washer(t, host, boards)
    host.wait_status(lambda s: washer_var(host, s, "step") == "wash" and (washer_var(host, s, "drum_rpm") or 0) > 30,
                     60, "the drum washing", door_guard(host))
    mark = len(washer.lines["stdout"])
    washer.send("washer-1 door_release")
    washer.wait_line(r"^washer-1: outputs digital=0x00 pwm=0", 10, since=mark,
                     what="every output off with the door open")
    s = host.wait_status(lambda s: washer_var(host, s, "state") == "paused", 10, "the programme paused")
    assert washer_var(host, s, "paused_by") == "door open", "paused by %r" % washer_var(host, s, "paused_by")
    washer.send("washer-1 door 1")
    # Closed again: locked first, then the wash goes on where it was.
    washer.wait_line(r"^washer-1: outputs digital=0x(08|18) ", 10, since=mark, what="the door lock on again")
    host.wait_status(lambda s: washer_var(host, s, "state") == "running" and washer_var(host, s, "step") == "wash",
                     20, "the wash resumed", door_guard(host))
    host.wait_status(lambda s: washer_var(host, s, "state") == "done", 180, "the programme done after the door",
                     door_guard(host))


@plain_pass_only("cancel and drain under the sanitizers: test-drivers' washer cancel tests")
def test_washer_cancel_stops_and_drains(t):
    host = washer_host(t, {"driver.washer.param.time_scale": "0.01"})
    boards = t.kitchen(host, commands=True)
    start_washer(t, host, boards)
    host.wait_status(lambda s: washer_var(host, s, "step") == "wash" and (washer_var(host, s, "drum_rpm") or 0) > 30,
                     60, "the drum washing", door_guard(host))
    boards["washer-1"].send("washer-1 cancel")
    host.wait_status(lambda s: washer_var(host, s, "state") == "cancelling", 10, "the programme cancelling")
    s = host.wait_status(lambda s: washer_var(host, s, "state") == "cancelled", 90, "the programme cancelled",
                         door_guard(host))
    s = host.wait_status(lambda s: host.device("washer-1", s)["outputs"] == {"digital": [False] * 7, "pwm": 0}, 10,
                         "every output off and the door unlocked after the cancel")
    d = host.device("washer-1", s)
    assert d["inputs"]["digital"][2], "the tub is not empty after cancel (tub-empty input off)"


def dish_var(host, s, name):
    return host.device("dish-1", s)["variables"].get(name)


@plain_pass_only("the dishwasher under the sanitizers: test-drivers' dishwasher tests")
def test_dishwasher_runs_and_honours_its_door(t):
    host = washer_host(t)
    boards = t.kitchen(host, commands=True)
    dish = boards["dish-1"]
    dish.send("dish-1 fill_rate_lps 5")
    dish.wait_line(r"^dish-1: fill_rate_lps 5", 10, what="the fill rate set")
    dish.send("dish-1 start")
    host.wait_status(lambda s: dish_var(host, s, "step") == "rinse", 60, "the dishwasher rinsing",
                     undisturbed(["washer-1", "lights-1"]))
    mark = len(dish.lines["stdout"])
    dish.send("dish-1 door 0")
    dish.wait_line(r"^dish-1: outputs digital=0x00 pwm=0", 10, since=mark, what="every output off with the door open")
    s = host.wait_status(lambda s: dish_var(host, s, "state") == "paused", 10, "the programme paused")
    assert dish_var(host, s, "paused_by") == "door open", "paused by %r" % dish_var(host, s, "paused_by")
    dish.send("dish-1 door 1")
    host.wait_status(lambda s: dish_var(host, s, "state") == "done", 90, "the rinse programme done",
                     undisturbed(["washer-1", "lights-1"]))
    s = host.wait_status(lambda s: host.device("dish-1", s)["outputs"]["digital"] == [False] * 7, 10,
                         "every dishwasher output off at the end")
    d = host.device("dish-1", s)
    assert d["inputs"]["analog"][0] < 10, "water left: %d counts" % d["inputs"]["analog"][0]


def test_lights_publish_their_state(t):
    host = washer_host(t)
    boards = t.kitchen(host, commands=True)
    s = host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("kitchen") is False, 10,
                         "the lights published off")
    boards["lights-1"].send("lights-1 toggle1 1")
    s = host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("kitchen") is True, 10,
                         "the kitchen light published on")
    assert host.device("lights-1", s)["variables"]["dining"] is False, "dining light on without its switch"
    boards["lights-1"].send("lights-1 toggle2 1")
    host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("dining") is True
                     and host.device("lights-1", s)["outputs"]["digital"][:2] == [True, True], 10,
                     "both lights on, published and driven")
