"""Drivers' output on a running host (docs/CLI.md, "vmac logs"; docs/DRIVERS.md,
"variables"): `vmac logs` shows a machine's dev:event lines as info and the
host's warning about a cut text value as warn, by machine and level, and -f
follows new ones; a text variable past 63 bytes arrives cut with its mark."""

import json

CHATTY_LUA = """-- chatty: says hello, a beat every second, and keeps a long text
local driver = { name = "chatty", version = "1", io = { lamp = "do0" },
	variables = { msg = {} } }
local beats = 0
function driver.attach(dev)
	dev:event("hello from chatty")
end
function driver.tick(dev, inputs)
	if inputs.time >= beats + 1 then
		beats = beats + 1
		dev:event("beat " .. beats)
	end
	dev.vars.msg = "a message of more than sixty-three bytes, " .. string.rep("\\226\\130\\172", 20)
end
return driver
"""

MARK = "\u2026"


def logs(t, host, base, *args):
    return t.start([t.path("vmac"), "logs", "--http", host.http] + list(args), base)


def test_logs_show_a_machines_output_by_level_and_follow(t):
    host = t.host(drivers=t.drivers(chatty=CHATTY_LUA))
    t.board("generic", "chatty-1", driver="chatty")
    t.board("lights", "lights-1")
    host.wait_running(["chatty-1", "lights-1"])
    warned = host.wait_event("warning", "chatty-1", text="dev.vars.msg")
    assert "102 bytes" in warned["text"], "the cut warning does not give the length: %r" % warned["text"]

    # The variable as the status shows it (the warning may come before the
    # status copy has it): cut between characters, marked.
    s = host.wait_status(lambda s: host.device("chatty-1", s)["variables"].get("msg") is not None, 10,
                         "dev.vars.msg in the status")
    msg = host.device("chatty-1", s)["variables"]["msg"]
    assert msg.endswith(MARK) and len(msg.encode()) <= 63, "dev.vars.msg as published: %r (%d bytes)" % (
        msg, len(msg.encode()))
    assert msg.startswith("a message of more than sixty-three bytes, \u20ac"), "the cut text lost its start: %r" % msg

    # Follow: what the host keeps, then new beats as they come.
    follow = logs(t, host, "logs-follow", "-f", "chatty-1")
    follow.wait_line(r"^\d\d:\d\d:\d\d info  chatty-1: hello from chatty$", 30, what="the driver's hello, as info")
    follow.wait_line(r"^\d\d:\d\d:\d\d warn  chatty-1: dev\.vars\.msg: a text of 102 bytes was cut to 63", 30,
                     what="the cut warning, as warn")
    beat = follow.wait_line(r"info  chatty-1: beat (\d+)$", 30, what="a beat")
    last = int(beat.text.rsplit(" ", 1)[1])
    follow.wait_line(r"info  chatty-1: beat %d$" % (last + 2), 30, since=beat.index + 1,
                     what="a beat that came after the stream opened")
    assert follow.alive(), "vmac logs -f ended by itself"

    # Without -f: the kept lines, then it stops; --level warn leaves info out.
    rc, out, err = t.run([t.path("vmac"), "logs", "--http", host.http, "--level", "warn"], "logs-warn")
    assert rc == 0, "vmac logs --level warn exited %d: %s" % (rc, err)
    lines = out.splitlines()
    assert any("warn  chatty-1: dev.vars.msg" in l for l in lines), "no cut warning in %r" % lines
    assert not any(" info " in l for l in lines), "--level warn printed info lines: %r" % lines

    # Another machine's logs do not show chatty's; --json gives the events.
    rc, out, err = t.run([t.path("vmac"), "logs", "--http", host.http, "lights-1"], "logs-lights")
    assert rc == 0 and "chatty" not in out, "vmac logs lights-1 exited %d, printed %r" % (rc, out)
    rc, out, err = t.run([t.path("vmac"), "logs", "--http", host.http, "--json", "chatty-1"], "logs-json")
    events = [json.loads(l) for l in out.splitlines()]
    assert rc == 0 and events and all(e["device"] == "chatty-1" for e in events), (
        "vmac logs --json chatty-1 exited %d: %r" % (rc, events))
    assert {e["kind"] for e in events} == {"driver", "warning"}, "kinds shown: %r" % {e["kind"] for e in events}

    rc, out, err = t.run([t.path("vmac"), "logs", "--http", host.http, "--level", "loud"], "logs-bad-level")
    assert rc == 2 and "info, warn or error" in err, "vmac logs --level loud: exit %d, %r" % (rc, err)
