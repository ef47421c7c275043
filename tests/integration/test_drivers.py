"""Boards whose driver is missing, does not load, fails at run time or never
returns: each such device is put aside (sleeping or errant, outputs off) and
the rest of the kitchen runs on undisturbed."""

import re

from harness import KITCHEN_NAMES, undisturbed

BROKEN_LUA = """-- broken: a syntax error on line 3
local driver = { name = "broken", version = "1", io = {} }
function driver.tick(dev, inputs
end
return driver
"""

# Fails soon after attaching, so the device stays errant a good while before
# the next discovery re-attaches it (docs/HOST.md: a dropped board is attached
# again when it answers discovery) and the status poll sees it errant.
CRASHY_LUA = """-- crashy: drives output 0 for a few ticks, then fails
local ticks = 0
local driver = { name = "crashy", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	ticks = ticks + 1
	if ticks > 2 then error("boom") end
	dev.out.lamp = true
end
return driver
"""

RUNAWAY_LUA = """-- runaway: drives output 0 once, then never returns from tick
local ticks = 0
local driver = { name = "runaway", version = "1", io = { lamp = "do0" } }
function driver.tick(dev, inputs)
	ticks = ticks + 1
	if ticks > 2 then
		while true do end
	end
	dev.out.lamp = true
end
return driver
"""


def line_of(source, text):
    """1-based number of the first line of source containing text."""
    return next(i for i, l in enumerate(source.splitlines(), 1) if text in l)


def test_missing_driver_sleeps(t):
    host = t.host()
    t.kitchen(host)
    since = host.last_event_seq()
    board = t.board("generic", "stray-1", driver="nosuchdriver")
    event = host.wait_event("driver_missing", "stray-1", after_seq=since, invariant=undisturbed(KITCHEN_NAMES))
    assert "nosuchdriver" in event["text"], "driver_missing event does not name the driver: %r" % event["text"]
    host.wait_status(lambda s: (host.device("stray-1", s) or {}).get("state") == "sleeping", 30,
                     "stray-1 sleeping", undisturbed(KITCHEN_NAMES))
    board.wait_line(r"^stray-1: state sleeping ", 30, what="'state sleeping'")
    assert host.alive(), "vmacd died over a missing driver"
    served = {n: host.device(n)["served"] for n in KITCHEN_NAMES}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 5 for n in KITCHEN_NAMES), 30,
                     "the kitchen served after the missing driver", undisturbed(KITCHEN_NAMES))
    assert host.device("stray-1")["outputs"]["digital"] == [False] * 7, "a sleeping device shows outputs on"
    assert not board.find_lines(r"outputs digital=0x(?!00)"), "stray-1 switched an output on"


def test_broken_driver_sleeps(t):
    host = t.host(drivers=t.drivers(broken=BROKEN_LUA))
    t.kitchen(host)
    since = host.last_event_seq()
    board = t.board("generic", "broken-1", driver="broken")
    event = host.wait_event("driver_error", "broken-1", after_seq=since, invariant=undisturbed(KITCHEN_NAMES))
    assert re.search(r"broken\.lua:\d+:", event["text"]), (
        "driver_error event gives no file and line: %r" % event["text"])
    host.wait_status(lambda s: (host.device("broken-1", s) or {}).get("state") == "sleeping", 30,
                     "broken-1 sleeping", undisturbed(KITCHEN_NAMES))
    board.wait_line(r"^broken-1: state sleeping ", 30, what="'state sleeping'")
    assert not board.find_lines(r"outputs digital=0x(?!00)"), "broken-1 switched an output on"
    assert host.alive(), "vmacd died over a driver with a syntax error"


def test_crashy_driver_is_dropped(t):
    host = t.host(drivers=t.drivers(crashy=CRASHY_LUA))
    t.kitchen(host)
    since = host.last_event_seq()
    board = t.board("generic", "crashy-1", driver="crashy")
    # The driver drives output 0 until it fails...
    on = board.wait_line(r"^crashy-1: outputs digital=0x01 ", 30, what="'outputs digital=0x01'")
    where = "crashy.lua:%d: boom" % line_of(CRASHY_LUA, 'error("boom")')
    event = host.wait_event("driver_error", "crashy-1", after_seq=since, invariant=undisturbed(KITCHEN_NAMES))
    assert where in event["text"], "driver_error event does not say %r: %r" % (where, event["text"])
    dropped = host.wait_event("dropped", "crashy-1", after_seq=since, invariant=undisturbed(KITCHEN_NAMES))
    assert dropped["seq"] > event["seq"], "crashy-1 dropped before its driver failed"
    # ...then the board is told to go safe.
    board.wait_line(r"^crashy-1: outputs digital=0x00 pwm=0", 30, since=on.index + 1,
                    what="'outputs digital=0x00' after the failure")
    board.wait_line(r"^crashy-1: state (unknown|sleeping) ", 30, since=on.index + 1,
                    what="'state unknown' after the failure")
    host.wait_status(lambda s: host.device("crashy-1", s)["state"] in ("errant", "sleeping"), 30,
                     "crashy-1 errant or sleeping", undisturbed(KITCHEN_NAMES))
    assert host.alive(), "vmacd died over a failing driver"


def test_runaway_driver_is_dropped(t):
    host = t.host(drivers=t.drivers(runaway=RUNAWAY_LUA))
    t.kitchen(host)
    since = host.last_event_seq()
    board = t.board("generic", "runaway-1", driver="runaway")
    on = board.wait_line(r"^runaway-1: outputs digital=0x01 ", 30, what="'outputs digital=0x01'")
    event = host.wait_event("driver_error", "runaway-1", text="time budget exceeded", after_seq=since,
                            invariant=undisturbed(KITCHEN_NAMES))
    assert "runaway.lua:" in event["text"], "driver_error event does not name runaway.lua: %r" % event["text"]
    host.wait_event("dropped", "runaway-1", after_seq=event["seq"] - 1, invariant=undisturbed(KITCHEN_NAMES))
    board.wait_line(r"^runaway-1: outputs digital=0x00 pwm=0", 30, since=on.index + 1,
                    what="'outputs digital=0x00' after the overrun")
    assert host.alive(), "vmacd died over a driver that never returns"
    served = {n: host.device(n)["served"] for n in KITCHEN_NAMES}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 5 for n in KITCHEN_NAMES), 30,
                     "the kitchen served after the runaway driver", undisturbed(KITCHEN_NAMES))
    # core/driver/protect.c formats "time budget exceeded (N instructions)".
    assert re.search(r"time budget exceeded \(\d+ instructions\)", event["text"]), (
        "the budget message is mangled: %r" % event["text"].splitlines()[0])


def test_every_plant_runs_its_shipped_driver(t):
    # docs/BOARD.md: a board announces the driver named after its plant, and
    # scripts/drivers/ ships one for each.
    host = t.host()
    plants = ("washer", "dishwasher", "lights", "generic")
    for plant in plants:
        t.board(plant, plant + "-1")
    names = [p + "-1" for p in plants]

    def no_driver_trouble(s):
        trouble = host.find_events("driver_missing") + host.find_events("driver_error")
        assert not trouble, "a shipped driver is missing or broken: %s" % trouble[0]["text"]

    host.wait_running(names, timeout_s=30, invariant=no_driver_trouble)
    for plant in plants:
        assert host.device(plant + "-1")["driver"] == plant, "%s-1 announced driver %r" % (
            plant, host.device(plant + "-1")["driver"])
