"""Hot reload on a running host (docs/API.md "Drivers", docs/CLI.md "vmac
reload"): a new version takes over at a slot boundary with the old one's
state; a version that does not compile or whose manifest is wrong is refused
and nothing changes; a version that fails on probation goes back by itself;
`vmac rollback` goes back by hand; every version is kept; a neighbouring
machine misses nothing."""

import json
import os
import re
import signal
import shutil
import threading
import time
import urllib.error
import urllib.request

from harness import fetch_recording, plain_pass_only, recording_id, undisturbed, until

# A driver for a lights board that counts its ticks in dev.state, holds its
# relay from dev.state, and says which version runs. VERSION and the body of
# BOOM are filled in per version.
COUNTER = """
local VERSION = "%(version)s"
local driver = {
	name = "counter",
	version = VERSION,
	level = 3,
	io = { relay = "do0" },
	variables = { ticks = {}, version = {}, migrated = {}, relay = { set = true } },
}

function driver.attach(dev)
	dev.state.ticks = 0
	dev.state.relay = false
	dev.vars.migrated = false
end

function driver.tick(dev, inputs)
	dev.state.ticks = dev.state.ticks + 1
	dev.vars.ticks, dev.vars.version = dev.state.ticks, VERSION
	dev.vars.relay = dev.state.relay
	dev.out.relay = dev.state.relay
	%(boom)s
end

function driver.input(dev, name, value)
	dev.state.relay = value == true
	return true
end

function driver.migrate(dev, old)
	dev.state.ticks, dev.state.relay = old.ticks, old.relay
	dev.vars.migrated = true
end

return driver
"""


def counter(version, boom=""):
    return COUNTER % {"version": version, "boom": boom}


def first_version_active(t, host):
    """GET /api/drivers/counter once its first version (the folder's) is the
    active one again, as the store records a rollback: the answer."""
    seen = [None]

    def active():
        seen[0] = call(host, "GET", "/api/drivers/counter", t.token)[1]
        return seen[0]["active"] == seen[0]["versions"][0]["id"]

    until(active, 10, lambda: "the first version active again: %r" % seen[0])
    return seen[0]


def call(host, method, path, token, data=None, content_type="text/x-lua"):
    """(HTTP status, parsed JSON answer)."""
    req = urllib.request.Request("http://%s%s" % (host.http, path), data=data, method=method)
    if data is not None:
        req.add_header("Content-Type", content_type)
    if token:
        req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}")


def start(t):
    """A host with the counter driver (1.0.0) running on lamp-1 and the
    lights driver on lights-1 beside it; the relay of lamp-1 switched on."""
    host = t.host(drivers=t.drivers(counter=counter("1.0.0")))
    t.board("lights", "lamp-1", driver="counter")
    t.board("lights", "lights-1")
    host.wait_running(["lamp-1", "lights-1"])
    code, body = call(host, "POST", "/api/devices/lamp-1/input", t.token,
                      json.dumps({"name": "relay", "value": True}).encode(), "application/json")
    assert code == 200, "switching the counter's relay on: %d %r" % (code, body)
    host.wait_status(lambda s: host.device("lamp-1", s)["outputs"]["digital"][0] is True, 10, "lamp-1's relay on")
    return host


def write(t, name, text):
    path = os.path.join(t.logdir, name)
    with open(path, "w") as f:
        f.write(text)
    return path


def test_reload_keeps_state_and_disturbs_nobody(t):
    host = start(t)
    before = host.device("lamp-1", host.wait_status(
        lambda s: host.device("lamp-1", s)["variables"].get("ticks", 0) > 20, 10, "lamp-1 counting"))
    seq = host.last_event_seq()
    path = write(t, "counter.lua", counter("2.0.0"))
    rc, out, err = t.run([t.path("vmac"), "reload", "--http", host.http, "--probation", "0", path], "reload")
    assert rc == 0, "vmac reload failed (exit %d): %s %s" % (rc, out, err)
    assert "counter 2.0.0 is active" in out and "lamp-1" in out and "switched" in out, \
        "vmac reload did not report the switch: %r" % out

    s = host.wait_status(lambda s: host.device("lamp-1", s)["variables"].get("version") == "2.0.0", 10,
                         "lamp-1 running 2.0.0", invariant=undisturbed(["lamp-1", "lights-1"]))
    d = host.device("lamp-1", s)
    assert d["driver_version"] == "2.0.0", "status still says driver_version %r" % d["driver_version"]
    assert d["variables"]["migrated"] is True, "the new version's migrate() did not run"
    assert d["variables"]["ticks"] >= before["variables"]["ticks"], \
        "the tick count started over (%r after %r): dev.state was not handed over" % (
            d["variables"]["ticks"], before["variables"]["ticks"])
    assert d["outputs"]["digital"][0] is True, "the relay went off across the reload"
    undisturbed(["lamp-1", "lights-1"])(s)
    host.wait_event("reloaded", "lamp-1", "1.0.0 -> 2.0.0", after_seq=seq)

    code, body = call(host, "GET", "/api/drivers/counter", t.token)
    assert code == 200 and body["active"] > 0, "GET /api/drivers/counter: %d %r" % (code, body)
    states = [(v["version"], v["state"]) for v in body["versions"]]
    assert states == [("1.0.0", "replaced"), ("2.0.0", "active")], \
        "versions kept (the folder's that ran, then the upload): %r" % states
    assert body["versions"][0]["origin"] == "folder" and body["versions"][1]["origin"] == "upload", \
        "the versions' origins: %r" % [v["origin"] for v in body["versions"]]
    assert len(body["versions"][1]["hash"]) == 64 and body["versions"][1]["deployed_by"], \
        "a version without its hash or who deployed it: %r" % body["versions"][1]


def test_broken_versions_are_refused_and_change_nothing(t):
    host = start(t)
    read = t.make_token("read")
    operate = t.make_token("operate")
    good = counter("2.0.0").encode()
    cases = [
        ("no token", call(host, "POST", "/api/drivers/counter", None, good), 401, "token"),
        ("a read token", call(host, "POST", "/api/drivers/counter", read, good), 403, "scope deploy"),
        ("an operate token", call(host, "POST", "/api/drivers/counter", operate, good), 403, "scope deploy"),
        ("a syntax error", call(host, "POST", "/api/drivers/counter", t.token,
                                counter("2.0.0").replace("return driver", "return driver end").encode()), 400,
         "counter.lua:"),
        ("an error while loading", call(host, "POST", "/api/drivers/counter", t.token,
                                        b'error("no")\n' + good), 400, "counter.lua:1"),
        ("a manifest naming another driver", call(host, "POST", "/api/drivers/counter", t.token,
                                                  good.replace(b'name = "counter"', b'name = "other"')), 400,
         "name is 'other'"),
        ("a manifest with a bad channel", call(host, "POST", "/api/drivers/counter", t.token,
                                               good.replace(b'"do0"', b'"do9"')), 400, "do9"),
        ("an empty body", call(host, "POST", "/api/drivers/counter", t.token, b""), 400, "bundle"),
        ("a bad probation", call(host, "POST", "/api/drivers/counter?probation=-1", t.token, good), 400,
         "probation"),
        ("an attach that fails", call(host, "POST", "/api/drivers/counter", t.token,
                                      counter("2.0.0").replace("dev.state.ticks = 0\n", "error('nope')\n", 1)
                                      .encode()), 409, "nope"),
    ]
    problems = ["%s: HTTP %d %r, expected %d mentioning %r" % (what, got[0], got[1], code, text)
                for what, got, code, text in cases if got[0] != code or text not in got[1].get("error", "")]
    assert not problems, "\n".join(problems)
    s = host.status()
    d = host.device("lamp-1", s)
    assert d["state"] == "running" and d["driver_version"] == "1.0.0", \
        "a refused upload changed the machine: %s %s" % (d["state"], d["driver_version"])
    assert d["outputs"]["digital"][0] is True, "a refused upload turned the relay off"
    code, body = call(host, "GET", "/api/drivers/counter", t.token)
    assert body["active"] == body["versions"][0]["id"], "a refused version became active: %r" % body
    assert [v["state"] for v in body["versions"]] == ["active", "refused"], \
        "only the folder's version that runs and the one that failed to take over (refused) are kept: %r" % (
            body["versions"],)


def test_a_version_failing_on_probation_goes_back(t):
    host = start(t)
    seq = host.last_event_seq()
    level = host.device("lamp-1", host.status())["level"]
    # The failing tick asks for a slower level first: a call that failed
    # changes no level (DRIVERS.md, dev:set_level).
    bad = counter("2.0.0", boom="if dev.state.ticks > 40 then dev:set_level(dev.level + 1); "
                                "error('boom at tick ' .. dev.state.ticks) end")
    code, body = call(host, "POST", "/api/drivers/counter?probation=30", t.token, bad.encode())
    assert code == 200 and body["probation_s"] == 30, "uploading 2.0.0: %d %r" % (code, body)
    e = host.wait_event("rolled_back", "lamp-1", after_seq=seq, timeout_s=30)
    assert "boom at tick" in e["text"] and "2.0.0" in e["text"], "the rollback event does not say why: %r" % e
    s = host.wait_status(lambda s: host.device("lamp-1", s)["variables"].get("version") == "1.0.0", 10,
                         "lamp-1 back on 1.0.0")
    d = host.device("lamp-1", s)
    assert d["state"] == "running", "lamp-1 was dropped instead of rolled back: %s" % d["state"]
    assert d["level"] == level, "lamp-1 at level %d after the rollback, not its %d: the failed tick's " \
        "dev:set_level was made" % (d["level"], level)
    assert d["variables"]["ticks"] > 40, "the old version did not take the state back: ticks %r" % (
        d["variables"]["ticks"],)
    # The old version's outputs are its own from its first tick after taking
    # over (the status may be published between the switch and that tick).
    s = host.wait_status(lambda s: host.device("lamp-1", s)["outputs"]["digital"][0] is True, 5,
                         "the relay on again after the rollback")
    undisturbed(["lights-1"])(s)
    assert not host.find_events("dropped", "lamp-1", after_seq=seq), "lamp-1 was dropped"
    # The event is said before the store records the rollback (a write
    # that waits for the disk): asked until it is there.
    body = first_version_active(t, host)
    assert [v["state"] for v in body["versions"]] == ["active", "rolled_back"], \
        "the store does not say the version was rolled back to the folder's: %r" % body
    # Its recording names the version that failed and when it took over,
    # and replays from there to the same failure.
    rec = host.wait_event("recording", "lamp-1", after_seq=seq, timeout_s=30)
    path = fetch_recording(t, host, recording_id(rec), "probation.rec")
    with open(path) as f:
        header = json.loads(f.readline())
    assert header["driver_version"] == "2.0.0" and header.get("took_over_t", 0) > header["attach_t"], (
        "the recording of the probation failure does not name 2.0.0 and when it took over: %r" % {
            k: header.get(k) for k in ("driver_version", "version_id", "took_over_t", "attach_t")})
    rc, out, err = t.run([t.path("vmac"), "test", "--replay", path], "replay")
    assert rc == 1 and "took over at" in out and "the same tick as in the recording" in out, (
        "the replay of 2.0.0 does not fail as recorded (exit %d): %s%s" % (rc, out, err))


def test_rollback_by_hand_and_the_version_list(t):
    host = start(t)
    for version in ("2.0.0", "3.0.0"):
        code, body = call(host, "POST", "/api/drivers/counter?probation=0", t.token, counter(version).encode())
        assert code == 200, "uploading %s: %d %r" % (version, code, body)
    host.wait_status(lambda s: host.device("lamp-1", s)["driver_version"] == "3.0.0", 10, "lamp-1 on 3.0.0")

    rc, out, err = t.run([t.path("vmac"), "rollback", "--http", host.http, "counter"], "rollback")
    assert rc == 0 and "2.0.0" in out, "vmac rollback to 2.0.0 failed (exit %d): %s %s" % (rc, out, err)
    host.wait_status(lambda s: host.device("lamp-1", s)["driver_version"] == "2.0.0", 10, "lamp-1 back on 2.0.0")
    rc, out, err = t.run([t.path("vmac"), "rollback", "--http", host.http, "counter"], "rollback")
    assert rc == 0, "vmac rollback to the file failed (exit %d): %s %s" % (rc, out, err)
    s = host.wait_status(lambda s: host.device("lamp-1", s)["driver_version"] == "1.0.0", 10,
                         "lamp-1 back on the file's 1.0.0")
    assert host.device("lamp-1", s)["outputs"]["digital"][0] is True, "the relay went off across the rollbacks"
    rc, out, err = t.run([t.path("vmac"), "rollback", "--http", host.http, "counter"], "rollback")
    assert rc == 1 and "no earlier version that ran" in err, "a rollback with nothing to go back to: exit %d %r" % (
        rc, err)

    rc, out, err = t.run([t.path("vmac"), "drivers", "--http", host.http, "counter"], "drivers")
    assert rc == 0, "vmac drivers failed: %s" % err
    lines = [line.split() for line in out.splitlines() if line.split() and line.split()[0].isdigit()]
    assert [(x[2], x[3]) for x in lines] == [("1.0.0", "active"), ("2.0.0", "rolled_back"),
                                             ("3.0.0", "rolled_back")], \
        "vmac drivers shows: %r" % out


def test_a_board_attaching_later_loads_the_active_version(t):
    host = start(t)
    code, body = call(host, "POST", "/api/drivers/counter?probation=0", t.token, counter("2.0.0").encode())
    assert code == 200, "uploading 2.0.0: %d %r" % (code, body)
    t.board("lights", "lamp-2", driver="counter", major=77)
    s = host.wait_running(["lamp-2"])
    assert host.device("lamp-2", s)["driver_version"] == "2.0.0", \
        "a board attaching after the reload got %r" % host.device("lamp-2", s)["driver_version"]


def washer_copy(t, version):
    """A drivers folder holding the shipped washer and its programmes, its
    version made `version`: the path of its washer.lua."""
    root = os.path.join(os.path.dirname(__file__), "..", "..", "scripts")
    folder = os.path.join(t.logdir, "washer-%s" % version)
    shutil.copytree(os.path.join(root, "cycles", "washer"), os.path.join(folder, "cycles", "washer"))
    with open(os.path.join(root, "drivers", "washer.lua")) as f:
        src = f.read()
    assert re.search(r'version = "[^"]+"', src), "the shipped washer declares no version"
    path = os.path.join(folder, "washer.lua")
    with open(path, "w") as f:
        f.write(re.sub(r'version = "[^"]+"', 'version = "%s"' % version, src, count=1))
    return path


@plain_pass_only("a reload's migrate under the sanitizers: the other reload tests, whose drivers migrate")
def test_a_running_wash_continues_across_a_reload(t):
    """The shipped washer, mid-wash, reloaded with its own file: the cycle
    goes on in the same step with the time it had left, then on to the
    next steps (not back to the start)."""
    host = t.host(settings={"driver.washer.param.time_scale": "0.05"})
    board = t.board("washer", "washer-1", commands=True)
    board.send("washer-1 fill_rate_lps 5")  # the plant's tap wide open: the fills take a second or two
    board.wait_line(r"^washer-1: fill_rate_lps 5", 10, what="the fill rate set")
    board.send("washer-1 door 1")
    host.wait_status(lambda s: (host.device("washer-1", s) or {}).get("variables", {}).get("door") == "closed", 30,
                     "the washer attached, its door seen closed")
    code, body = call(host, "POST", "/api/devices/washer-1/cycle", t.token,
                      json.dumps({"action": "start", "program": "quick"}).encode(), "application/json")
    assert code == 200, "start quick: %d %r" % (code, body)
    s = host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("step") == "wash"
                         and host.device("washer-1", s)["variables"].get("time_left_s", 0) > 3, 120,
                         "the quick programme washing")
    left = host.device("washer-1", s)["variables"]["time_left_s"]
    seq = host.last_event_seq()
    path = washer_copy(t, "1.2.99")
    rc, out, err = t.run([t.path("vmac"), "reload", "--http", host.http, path], "reload")
    assert rc == 0, "vmac reload washer.lua mid-wash: exit %d %s %s" % (rc, out, err)
    host.wait_event("reloaded", "washer-1", after_seq=seq)
    s = host.status()
    v = host.device("washer-1", s)["variables"]
    assert v["state"] == "running" and v["step"] == "wash", "after the reload: state %s, step %s" % (v["state"],
                                                                                                    v["step"])
    assert v["time_left_s"] <= left + 0.5, "the wash started over: %.1f s left after, %.1f s before" % (
        v["time_left_s"], left)
    assert host.device("washer-1", s)["outputs"]["digital"][3], "the door lock opened across the reload"
    steps = ["wash"]  # the steps seen after the reload, in order

    def no_restart(s):
        step = host.device("washer-1", s)["variables"].get("step")
        if step != steps[-1]:
            steps.append(step)
        assert host.device("washer-1", s)["state"] == "running", "the washer was dropped"

    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("step") == "rinse", 180,
                     "the quick programme rinsing", invariant=no_restart)
    assert steps == ["wash", "drain", "fill", "rinse"], \
        "the cycle did not go on from the wash after the reload: steps %r" % steps
    assert not host.find_events("dropped", "washer-1", after_seq=seq), "the washer was dropped"


def test_activating_a_kept_version(t):
    host = start(t)
    ids = {}
    for version in ("2.0.0", "3.0.0"):
        code, body = call(host, "POST", "/api/drivers/counter?probation=0", t.token, counter(version).encode())
        assert code == 200, "uploading %s: %d %r" % (version, code, body)
        ids[version] = body["id"]
    rc, out, err = t.run([t.path("vmac"), "activate", "--host", host.http, "--probation", "0", "counter",
                          str(ids["2.0.0"])], "activate")
    assert rc == 0 and "counter 2.0.0 is active" in out, "vmac activate: exit %d %s %s" % (rc, out, err)
    s = host.wait_status(lambda s: host.device("lamp-1", s)["driver_version"] == "2.0.0", 10, "lamp-1 on 2.0.0")
    assert host.device("lamp-1", s)["variables"]["migrated"] is True, "activate did not migrate"
    code, body = call(host, "GET", "/api/drivers/counter", t.token)
    versions = [(v["version"], v["state"]) for v in body["versions"]]
    assert versions == [("1.0.0", "replaced"), ("2.0.0", "replaced"), ("3.0.0", "replaced"), ("2.0.0", "active")], \
        "the list after activating: %r" % versions
    assert body["versions"][1]["hash"] == body["versions"][3]["hash"], "the activated copy has another hash"
    rc, out, err = t.run([t.path("vmac"), "activate", "--host", host.http, "counter", "9999"], "activate")
    assert rc == 1 and "no version 9999" in err, "activating a version that does not exist: %d %r" % (rc, err)


PAUSE_MS = 3000  # VMAC_TEST_DEPLOY_PAUSE_MS: long enough for a board to be found, announce and attach


def paused_host(t, pause_ms=PAUSE_MS):
    """start(t) with every deploy and rollback paused pause_ms between
    switching the machines and writing the store (core/reload/deploy.c,
    test_pause): the moment a board attaching would load the old version
    from the store."""
    os.environ["VMAC_TEST_DEPLOY_PAUSE_MS"] = str(pause_ms)
    try:  # vmacd inherits the runner's environment
        return start(t)
    finally:
        del os.environ["VMAC_TEST_DEPLOY_PAUSE_MS"]


def deploy_paused(t, host, driver, text):
    """POST text as a new version of driver in the background, and wait
    until the host says the deploy is paused between its steps. Returns
    the calling thread and the list its answer goes in."""
    answer = []
    mark = host.mark("stderr")

    def deploy():
        try:
            answer.append(call(host, "POST", "/api/drivers/%s?probation=0" % driver, t.token, text.encode()))
        except OSError as e:  # the host stopped meanwhile (a test that stops it): no answer
            answer.append((None, repr(e)))

    caller = threading.Thread(target=deploy, daemon=True)
    caller.start()
    host.wait_line(r"deploy of %s paused" % driver, 30, since=mark, stream="stderr", what="the deploy's test pause")
    return caller, answer


def attach_during(t, host, method, path, data=None):
    """Call method path in the background; once the host says it is paused
    between the deploy's steps, start a new machine (lamp-2, major 77) of
    the counter driver. Returns the call's (status, answer) and lamp-2's
    status once running."""
    answer = []
    mark = host.mark("stderr")
    caller = threading.Thread(target=lambda: answer.append(call(host, method, path, t.token, data)), daemon=True)
    caller.start()
    host.wait_line(r"deploy of counter paused", 30, since=mark, stream="stderr", what="the deploy's test pause")
    t.board("lights", "lamp-2", driver="counter", major=77)
    caller.join(60)
    assert answer, "%s %s did not answer within 60 s" % (method, path)
    s = host.wait_running(["lamp-2"], timeout_s=30)
    return answer[0], host.device("lamp-2", s)


def test_a_board_attaching_during_a_deploy_gets_the_new_version(t):
    host = paused_host(t)
    (code, body), lamp2 = attach_during(t, host, "POST", "/api/drivers/counter?probation=0",
                                        counter("2.0.0").encode())
    assert code == 200, "uploading 2.0.0: %d %r" % (code, body)
    assert lamp2["driver_version"] == "2.0.0", \
        "lamp-2 attached while 2.0.0 was being deployed and runs %r" % lamp2["driver_version"]
    s = host.wait_status(lambda s: host.device("lamp-2", s)["variables"].get("version") == "2.0.0", 10,
                         "lamp-2 ticking with 2.0.0")
    assert host.device("lamp-1", s)["driver_version"] == "2.0.0", "lamp-1 is not on 2.0.0"


def test_a_board_attaching_during_a_rollback_gets_the_version_rolled_back_to(t):
    host = paused_host(t)
    for version in ("2.0.0", "3.0.0"):  # no board attaches during these: nothing waits for the pause
        code, body = call(host, "POST", "/api/drivers/counter?probation=0", t.token, counter(version).encode())
        assert code == 200, "uploading %s: %d %r" % (version, code, body)
    (code, body), lamp2 = attach_during(t, host, "POST", "/api/drivers/counter/rollback")
    assert code == 200, "rolling back to 2.0.0: %d %r" % (code, body)
    assert lamp2["driver_version"] == "2.0.0", \
        "lamp-2 attached while 3.0.0 was being rolled back to 2.0.0 and runs %r" % lamp2["driver_version"]
    assert host.device("lamp-1", host.status())["driver_version"] == "2.0.0", "lamp-1 is not back on 2.0.0"


def test_a_probation_rollback_waits_for_a_deploy_under_way(t):
    """A version failing on probation goes back at once on the bus, but the
    store records it under the deploy lock (core/reload/deploy.c,
    vmac_deploy_rolled_back): during another deploy it waits for that to
    end, so the two never interleave their writes."""
    pause_ms = 6000  # the failure, its event and a look at the store all fall within it, even under ASan
    host = paused_host(t, pause_ms)
    boom = counter("2.0.0", boom="if not dev.state.relay then error('boom: relay off') end")
    code, body = call(host, "POST", "/api/drivers/counter?probation=60", t.token, boom.encode())
    assert code == 200, "uploading 2.0.0 on probation: %d %r" % (code, body)
    seq = host.last_event_seq()

    # A deploy of another driver, paused between its steps (it holds the lock).
    with open(os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "drivers", "lights.lua")) as f:
        lights = re.sub(r'version = "[^"]+"', 'version = "9.9.9"', f.read(), count=1)  # a new version: no no-op
    caller, answer = deploy_paused(t, host, "lights", lights)

    # 2.0.0 fails on lamp-1 meanwhile: the bus rolls it back at once.
    code, body = call(host, "POST", "/api/devices/lamp-1/input", t.token,
                      json.dumps({"name": "relay", "value": False}).encode(), "application/json")
    host.wait_event("rolled_back", "lamp-1", "boom: relay off", after_seq=seq, timeout_s=pause_ms / 1000)
    code, body = call(host, "GET", "/api/drivers/counter", t.token)
    in_deploy = caller.is_alive()
    assert in_deploy, "the deploy of lights ended before the store could be looked at (pause too short)"
    states = [(v["version"], v["state"]) for v in body["versions"]]
    assert states == [("1.0.0", "replaced"), ("2.0.0", "active")], \
        "the store recorded the probation rollback in the middle of another deploy: %r" % states

    caller.join(60)
    assert answer and answer[0][0] == 200, "deploying lights: %r" % answer
    body = first_version_active(t, host)
    assert [v["state"] for v in body["versions"]] == ["active", "rolled_back"], \
        "the store does not record the rollback once the deploy is over: %r" % body
    assert host.device("lamp-1", host.status())["driver_version"] == "1.0.0", "lamp-1 is not back on 1.0.0"


def test_dot_names_are_no_drivers(t):
    """'.' and '..' (and any name starting with a dot) are no driver's or
    device's name: refused by the routes, nothing compiled or stored."""
    from harness import post
    host = t.host()
    for name in ("..", ".", ".hidden"):
        code, text = post(host, "/api/drivers/" + name, t.token, b"return {}", "text/x-lua")
        assert code in (400, 404), "POST /api/drivers/%s answered %d %s" % (name, code, text[:200])
        try:
            host.get("/api/drivers/" + name)
            raise AssertionError("GET /api/drivers/%s answered 200" % name)
        except urllib.error.HTTPError as e:
            assert e.code in (400, 404), "GET /api/drivers/%s answered %d" % (name, e.code)
    versions = host.get("/api/drivers")
    assert not any(d.get("name", "").startswith(".") for d in versions.get("drivers", [])), (
        "a dot name was stored: %r" % versions)


def test_a_stop_during_a_deploy_does_not_wait_for_the_bus_thread(t):
    """SIGTERM while a deploy is under way: the bus thread ends, and the
    deploy's requests left (here lamp-1's going back, lamp-2 having
    refused the new version) are answered at once "the host is stopping",
    not after each waited SWAP_TIMEOUT_MS for a bus thread that is gone."""
    host = paused_host(t, 1000)
    t.board("lights", "lamp-2", driver="counter", major=77)
    host.wait_running(["lamp-2"])
    refuses = counter("2.0.0").replace("function driver.migrate(dev, old)",
                                       "function driver.migrate(dev, old)\n\tif dev.name == 'lamp-2' then "
                                       "error('lamp-2 will not') end")
    deploy_paused(t, host, "counter", refuses)
    host.signal(signal.SIGTERM)
    rc = host.wait_exit(30)
    assert rc == 0, "vmacd exited with %r when stopped during a deploy" % rc
    text = host.text()
    assert "did not take the request within" not in text, (
        "a request of the deploy waited out its time for a bus thread that had ended: %s" % text[-800:])
