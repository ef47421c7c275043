"""Operator input over the HTTP API (docs/API.md, "POST
/api/devices/NAME/input"): it reaches the driver through the bus thread and
the board's outputs follow; a token without the operate scope, a bad body,
an unknown device or a name the driver refuses change nothing."""

import json
import os
import subprocess
import urllib.error
import urllib.request


def post(host, path, body, token, raw=None):
    """(status code, parsed JSON answer) of POST path with a JSON body."""
    data = raw if raw is not None else json.dumps(body).encode()
    req = urllib.request.Request("http://%s%s" % (host.http, path), data=data, method="POST")
    req.add_header("Content-Type", "application/json")
    if token:
        req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}")


def kitchen_light(host, s=None):
    """(relay output, published variable) of the kitchen light; (None, None)
    before lights-1 is there."""
    d = host.device("lights-1", s)
    if d is None:
        return None, None
    return d["outputs"]["digital"][0], d["variables"].get("kitchen")


def test_operator_input_switches_a_light(t):
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    operate = t.make_token("operate")

    code, body = post(host, "/api/devices/lights-1/input", {"name": "kitchen", "value": True}, operate)
    assert code == 200 and body.get("ok") is True, "switching the kitchen light on: %d %r" % (code, body)
    host.wait_status(lambda s: kitchen_light(host, s) == (True, True), 5,
                     "the kitchen relay on and published after the input")

    code, body = post(host, "/api/devices/lights-1/input", {"name": "all_off"}, operate)
    assert code == 200, "the all_off command: %d %r" % (code, body)
    host.wait_status(lambda s: kitchen_light(host, s) == (False, False), 5, "every relay off after all_off")


def test_refused_input_changes_nothing(t):
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_status(lambda s: kitchen_light(host, s) == (False, False), 30,
                     "lights-1 running, its kitchen light published off")
    read, operate = t.make_token("read"), t.make_token("operate")
    path = "/api/devices/lights-1/input"
    on = {"name": "kitchen", "value": True}

    cases = [
        ("no token", post(host, path, on, None), 401, "token"),
        ("a read token", post(host, path, on, read), 403, "scope operate"),
        ("a name the driver does not know", post(host, path, {"name": "sauna", "value": True}, operate), 409,
         "sauna"),
        ("a device that is not running", post(host, "/api/devices/nosuch-1/input", on, operate), 404,
         "not running"),
        ("a body that is not JSON", post(host, path, None, operate, raw=b"kitchen=1"), 400, "expected"),
        ("a value that is a table", post(host, path, {"name": "kitchen", "value": {"a": 1}}, operate), 400,
         "expected"),
        ("a body over 64 KiB", post(host, path, None, operate, raw=b" " * 70000), 413, "64 KiB"),
    ]
    problems = ["%s: HTTP %d %r, expected %d mentioning %r" % (what, got[0], got[1], code, text)
                for what, got, code, text in cases if got[0] != code or text not in got[1].get("error", "")]
    assert not problems, "\n".join(problems)
    s = host.status()
    assert kitchen_light(host, s) == (False, False), "a refused request changed the light: %r" % (
        kitchen_light(host, s),)
    assert host.device("lights-1", s)["state"] == "running", "a refused request disturbed the board"


def test_a_wash_started_over_the_api(t):
    host = t.host(settings={"driver.washer.param.time_scale": "0.01"})
    t.board("washer", "washer-1")
    host.wait_status(lambda s: (host.device("washer-1", s) or {}).get("variables", {}).get("door") == "closed", 30,
                     "the washer attached, its door seen closed")
    operate = t.make_token("operate")
    code, body = post(host, "/api/devices/washer-1/input", {"name": "start", "value": "quick"}, operate)
    assert code == 200, "start quick: %d %r" % (code, body)
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("state") == "running", 10,
                     "the washer running the quick programme")
    code, body = post(host, "/api/devices/washer-1/input", {"name": "start", "value": "quick"}, operate)
    assert code == 409 and "already running" in body.get("error", ""), "a second start: %d %r" % (code, body)
    code, body = post(host, "/api/devices/washer-1/input", {"name": "cancel"}, operate)
    assert code == 200, "cancel: %d %r" % (code, body)
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("state") in ("cancelling", "cancelled"),
                     10, "the washer cancelling")


def test_the_console_answers_line_by_line(t):
    """vmac console from a pipe, vmac get and vmac set (docs/CLI.md,
    "Console"): answers in order on one line per input line, errors as
    NAME#CODE, the exit code 1 when any submessage failed."""
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    vmac = t.path("vmac")
    env = dict(os.environ, VMAC_HTTP=host.http, VMAC_TOKEN=t.make_token("operate"))

    def run(args, stdin=None, token=None):
        e = dict(env, VMAC_TOKEN=token) if token else env
        p = subprocess.run([vmac] + args, input=stdin, capture_output=True, text=True, env=e, timeout=30)
        return p.returncode, p.stdout, p.stderr

    rc, out, err = run(["set", "lights-1.kitchen:true"])
    assert (rc, out) == (0, "lights-1.kitchen:true\n"), "vmac set: exit %d, %r %r" % (rc, out, err)
    host.wait_status(lambda s: kitchen_light(host, s) == (True, True), 5, "the kitchen light on after vmac set")
    rc, out, err = run(["get", "lights-1.kitchen", "lights-1.tv"])
    assert (rc, out) == (0, "lights-1.kitchen:true lights-1.tv:false\n"), "vmac get: exit %d, %r %r" % (rc, out, err)

    rc, out, err = run(["console", "--quiet"], stdin="lights-1.tv:true lights-1.sauna:1 nosuch-1.x? lights-1.tv>1 "
                       "bad\nlights-1.all_off!\n\n")
    assert out == "lights-1.tv:true lights-1.sauna#3 nosuch-1.x#2 lights-1.tv#6 bad#1\nlights-1.all_off!\n", (
        "vmac console answers: %r" % out)
    assert rc == 1 and err == "", "vmac console --quiet: exit %d, stderr %r" % (rc, err)
    host.wait_status(lambda s: kitchen_light(host, s) == (False, False), 5, "every relay off after all_off!")

    rc, out, err = run(["set", "lights-1.tv:true"], token=t.make_token("read"))
    assert (rc, out) == (1, "lights-1.tv#7\n") and "scope operate" in err, (
        "vmac set with a read token: exit %d, %r %r" % (rc, out, err))
    assert not host.device("lights-1", host.status())["outputs"]["digital"][2], "a read token switched the TV on"
    rc, out, err = run(["set"])
    assert rc == 2 and "usage" in err, "vmac set without a submessage: exit %d, %r" % (rc, err)


def test_the_console_through_the_api(t):
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("tv") is False, 5, "tv published")
    read, operate = t.make_token("read"), t.make_token("operate")
    code, body = post(host, "/api/console", None, operate, raw=b"lights-1.kitchen:true lights-1.tv?\n\nx.y!\n")
    assert code == 200, "POST /api/console: %d %r" % (code, body)
    assert [line["answer"] for line in body["lines"]] == ["lights-1.kitchen:true lights-1.tv:false", "x.y#2"], \
        "console answers: %r" % body
    assert body["errors"] == 1 and "not running" in body["lines"][1]["errors"][0], \
        "the error and its message: %r" % body
    host.wait_status(lambda s: kitchen_light(host, s) == (True, True), 5, "the kitchen light on")
    code, body = post(host, "/api/console", None, read, raw=b"lights-1.kitchen? lights-1.tv:true")
    assert code == 200 and body["lines"][0]["answer"] == "lights-1.kitchen:true lights-1.tv#7", \
        "a read token reads but does not set: %d %r" % (code, body)
    assert not host.device("lights-1", host.status())["outputs"]["digital"][2], "a read token switched the TV on"
    code, body = post(host, "/api/console", None, None, raw=b"lights-1.kitchen?")
    assert code == 401, "the console without a token: %d %r" % (code, body)


def test_devices_and_cycles_endpoints(t):
    host = t.host(settings={"driver.washer.param.time_scale": "0.01"})
    t.board("washer", "washer-1")
    t.board("lights", "lights-1")
    host.wait_running(["washer-1", "lights-1"])
    host.wait_status(lambda s: (host.device("washer-1", s) or {}).get("variables", {}).get("door") == "closed", 30,
                     "the washer attached, its door seen closed")
    names = sorted(d["name"] for d in host.get("/api/devices")["devices"])
    assert names == ["lights-1", "washer-1"], "GET /api/devices: %r" % names
    one = host.get("/api/devices/washer-1")
    assert one["name"] == "washer-1" and one["params"]["program"] == "normal", "GET /api/devices/washer-1: %r" % one
    try:
        host.get("/api/devices/nosuch-1")
        raise AssertionError("GET /api/devices/nosuch-1 answered 200")
    except urllib.error.HTTPError as e:
        assert e.code == 404, "GET /api/devices/nosuch-1: %d" % e.code

    operate = t.make_token("operate")
    cycle = "/api/devices/washer-1/cycle"
    for body, want, text in [({"action": "explode"}, 400, "expected"),
                             ({"action": "pause", "program": "quick"}, 400, "start only"),
                             ({"action": "start", "program": "nosuch"}, 409, "no programme")]:
        code, answer = post(host, cycle, body, operate)
        assert code == want and text in answer.get("error", ""), "%r: %d %r" % (body, code, answer)
    code, answer = post(host, "/api/devices/lights-1/cycle", {"action": "start"}, operate)
    assert code == 409, "a cycle on the lights, which have none: %d %r" % (code, answer)
    assert host.device("washer-1", host.status())["variables"]["state"] == "idle", "a refused start started"

    code, answer = post(host, cycle, {"action": "start", "program": "quick"}, operate)
    assert code == 200, "start quick: %d %r" % (code, answer)
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("state") == "running", 10, "running")
    code, answer = post(host, cycle, {"action": "pause"}, operate)
    assert code == 200, "pause: %d %r" % (code, answer)
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("state") == "paused", 10, "paused")
    code, answer = post(host, cycle, {"action": "resume"}, operate)
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("state") == "running", 10,
                     "running again")
    code, answer = post(host, cycle, {"action": "cancel"}, operate)
    assert code == 200, "cancel: %d %r" % (code, answer)
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("state") in ("cancelling", "cancelled"),
                     10, "the washer cancelling")
