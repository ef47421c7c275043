"""The flight recorder end to end (issue 21, docs/RECORDING.md), with the
real vmacd and vmac-board: a driver failure and a drop each leave a
recording in the host's store; `vmac recordings` lists them, `vmac
recording get ID` fetches one, `vmac test --replay FILE` replays it against
the recorded driver or another one, and `vmac recording to-test FILE` turns
it into a test file. A damaged file is refused with the reason, and the
store keeps only the newest recordings_max."""

import hashlib
import json
import os
import re
import signal
import subprocess
import urllib.error
import urllib.request

from harness import fetch_recording, http_code, recording_id

# A driver for a generic board that counts items in batches of seven: with
# its switch (di0) on it lights do0 and shows on do1 whether the batch in
# progress is more than half full. Its bug: a full batch (the encoder at a
# multiple of 7) leaves nothing in progress, and the table of fill levels
# has no entry for 0, so the tick raises, but only with the switch on, on
# that rare count.
RARE = """-- rare: batches of seven items, %(what)s
local driver = {
	name = "rare",
	version = "%(version)s",
	io = { switch = "di0", count = "encoder", lamp = "do0", half_full = "do1" },
	variables = { ticks = {} },
}

local FILL = { [1] = 1, [2] = 2, [3] = 3, [4] = 4, [5] = 5, [6] = 6%(zero)s }

function driver.tick(dev, inputs)
	dev.state.ticks = (dev.state.ticks or 0) + 1
	dev.vars.ticks = dev.state.ticks
	dev.out.lamp = inputs.switch
	if inputs.switch then
		local in_progress = FILL[inputs.count %% 7]
		dev.out.half_full = in_progress * 2 > 7
	else
		dev.out.half_full = false
	end
end

return driver
"""
BUGGY = RARE % {"what": "raises on a full batch", "version": "1.0.0", "zero": ""}
FIXED = RARE % {"what": "a full batch is an empty one", "version": "1.0.1", "zero": ", [0] = 0"}



def driver_dir(t, folder, **files):
    """A --drivers folder of this test's own under its log directory,
    holding NAME.lua for every NAME=source given."""
    path = os.path.join(t.logdir, folder)
    os.makedirs(path, exist_ok=True)
    for name, source in files.items():
        with open(os.path.join(path, name + ".lua"), "w") as f:
            f.write(source)
    return path


def vmac(t, *argv, token=None, stdout_file=None, timeout_s=120):
    """Run build/bin/vmac with argv: (exit code, stdout, stderr). token:
    $VMAC_TOKEN (default the test's deploy token); stdout_file: a path the
    standard output goes to, byte for byte, as with '> FILE'."""
    env = dict(os.environ, VMAC_TOKEN=token if token is not None else t.token)
    out = open(stdout_file, "wb") if stdout_file else subprocess.PIPE
    try:
        p = subprocess.run([t.path("vmac")] + list(argv), stdout=out, stderr=subprocess.PIPE, env=env,
                           timeout=timeout_s)
    finally:
        if stdout_file:
            out.close()
    text = "" if stdout_file else p.stdout.decode("utf-8", "replace")
    return p.returncode, text, p.stderr.decode("utf-8", "replace")


def fetch(t, host, rec_id, name, token=None):
    return fetch_recording(t, host, rec_id, name, token)


def parse(path):
    """A recording file as (header, records, end): JSON objects, in order."""
    with open(path, "rb") as f:
        lines = [json.loads(l) for l in f.read().decode("utf-8").splitlines()]
    assert lines and lines[0].get("format") == "vmac-recording", "%s does not start with a recording header" % path
    assert "end" in lines[-1], "%s does not end with its end line" % path
    return lines[0], lines[1:-1], lines[-1]


def http_post(host, path, body, token):
    req = urllib.request.Request("http://%s%s" % (host.http, path), data=json.dumps(body).encode(), method="POST")
    req.add_header("Content-Type", "application/json")
    req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def test_a_driver_failing_on_a_rare_input_becomes_a_failing_test(t):
    """The three commands from a drop to a failing test (docs/RECORDING.md):

        vmac recording get ID > rare.rec
        vmac test --replay rare.rec                        # exit 1: FAILS at tick N, the same as recorded
        vmac recording to-test rare.rec > rare_test.lua    # then: vmac test --drivers DIR rare_test.lua

    and, with the fix in FIXED_DIR, `vmac test --replay rare.rec --drivers
    FIXED_DIR` exits 0 and `vmac test --drivers FIXED_DIR rare_test.lua`
    passes, while against the buggy folder the test fails."""
    buggy = driver_dir(t, "buggy", rare=BUGGY)
    fixed = driver_dir(t, "fixed", rare=FIXED)
    host = t.host(drivers=buggy)
    board = t.board("generic", "rare-1", driver="rare", commands=True)
    host.wait_running(["rare-1"])
    since = host.last_event_seq()
    # Ordinary counts with the switch on: no trouble.
    board.send("rare-1 encoder 3")
    board.send("rare-1 di0 1")
    board.wait_line(r"^rare-1: outputs digital=0x01 ", 30, what="the lamp on, batch not yet half full")
    board.send("rare-1 encoder 12")
    board.wait_line(r"^rare-1: outputs digital=0x03 ", 30, what="lamp and half-full on")
    host.wait_status(lambda s: host.device("rare-1", s)["variables"].get("ticks", 0) >= 20, 30,
                     "rare-1 running 20 ticks")
    # The rare count: a full batch (14) with the switch on.
    board.send("rare-1 encoder 14")
    error = host.wait_event("driver_error", "rare-1", after_seq=since)
    assert "attempt to perform arithmetic" in error["text"], "not the driver's bug: %r" % error["text"]
    rec_event = host.wait_event("recording", "rare-1", after_seq=since)
    board.send("rare-1 di0 0")  # no more failures once it attaches again
    rec_id = recording_id(rec_event)

    # vmac recordings lists it, with a read token.
    read = t.make_token("read")
    rc, out, err = vmac(t, "recordings", "--http", host.http, token=read)
    assert rc == 0, "vmac recordings failed (exit %d): %s" % (rc, err)
    row = next((l for l in out.splitlines() if re.match(r"\s*%d\s" % rec_id, l)), None)
    assert row, "vmac recordings does not list recording %d: %r" % (rec_id, out)
    assert "rare-1" in row and "rare 1.0.0" in row and "driver error" in row, (
        "the listing of recording %d lacks the machine, driver, version or reason: %r" % (rec_id, row))

    path = fetch(t, host, rec_id, "rare.rec", token=read)
    header, records, _ = parse(path)
    assert header["machine"] == "rare-1" and header["driver"] == "rare" and header["driver_version"] == "1.0.0", (
        "header: %r" % {k: header.get(k) for k in ("machine", "driver", "driver_version")})
    assert header["complete"] is True, "a recording of a few seconds lost its first ticks"
    assert "FILL" in header.get("source", ""), "the recording does not carry the driver's source"
    errors = [r for r in records if r.get("event") == "error"]
    assert errors, "the recording has no error event: %r" % records[-5:]
    # The tick that failed is recorded too, just before the error: the
    # replay must fail at that tick, counted from the first.
    failed_tick = sum(1 for r in records if "tick" in r and r["t"] <= errors[0]["t"])
    last_tick = [r for r in records if "tick" in r and r["t"] <= errors[0]["t"]][-1]
    assert last_tick["tick"][0]["in"][0] & 1 and last_tick["tick"][0]["in"][3] == 14, (
        "the failing tick's inputs are not the switch on at 14: %r" % last_tick)

    # Against the recorded driver: it fails at the same tick.
    rc, out, err = vmac(t, "test", "--replay", path)
    assert rc == 1, "replay against the buggy driver exited %d, not 1: %s%s" % (rc, out, err)
    m = re.search(r"FAILS at tick (\d+) \(([\d.]+) s\)(.*)", out)
    assert m, "the replay does not say where it fails: %r" % out
    assert int(m.group(1)) == failed_tick, "replay fails at tick %s, the recording failed at tick %d: %r" % (
        m.group(1), failed_tick, out)
    assert "the same tick as in the recording" in m.group(3), "the replay does not see the same failure: %r" % out
    assert "attempt to perform arithmetic" in out, "the replay does not show the driver's error: %r" % out
    # Against the fixed driver: the recorded failure is gone.
    rc, out, err = vmac(t, "test", "--replay", path, "--drivers", fixed)
    assert rc == 0, "replay against the fixed driver exited %d, not 0: %s%s" % (rc, out, err)
    assert "this one does not" in out, "the replay does not say the failure is gone: %r" % out

    # The recording as a test file a driver author keeps.
    test_file = os.path.join(t.logdir, "rare_test.lua")
    rc, _, err = vmac(t, "recording", "to-test", path, stdout_file=test_file)
    assert rc == 0, "vmac recording to-test failed (exit %d): %s" % (rc, err)
    rc, out, err = vmac(t, "test", "--drivers", fixed, test_file)
    assert rc == 0, "the recording's test fails against the fixed driver (exit %d): %s%s" % (rc, out, err)
    rc, out, err = vmac(t, "test", "--drivers", buggy, test_file)
    assert rc == 1, "the recording's test does not fail against the buggy driver (exit %d): %s%s" % (rc, out, err)
    assert "FAILS at tick %d" % failed_tick in out + err, (
        "the recording's test does not fail at tick %d: %s%s" % (failed_tick, out, err))

    # A crafted recording, its hash made again: a reason with a line of
    # code in it stays in the test's comment; a driver that is a path is
    # refused by both readers.
    def crafted(**header_fields):
        with open(path, "rb") as f:
            lines = f.read().split(b"\n")
        head = json.loads(lines[0])
        head.update(header_fields)
        lines[0] = json.dumps(head, separators=(",", ":")).encode()
        end = next(i for i, l in enumerate(lines) if l.startswith(b'{"end"'))
        body = b"\n".join(lines[:end]) + b"\n"
        tail = json.loads(lines[end])
        tail["end"]["blake2b"] = hashlib.blake2b(body, digest_size=32).hexdigest()
        return write_bytes(t, "crafted.rec", body + json.dumps(tail, separators=(",", ":")).encode() + b"\n")

    injected = os.path.join(t.logdir, "injected_test.lua")
    rc, _, err = vmac(t, "recording", "to-test", crafted(reason="x\nerror('injected')\n--"), stdout_file=injected)
    assert rc == 0, "to-test of a recording with a multi-line reason failed (exit %d): %s" % (rc, err)
    with open(injected) as f:
        code = [l for l in f.read().split("replay [")[0].splitlines() if l.strip() and not l.startswith("--")]
    assert all(l.startswith("test(") for l in code), "the recording's reason became code: %r" % code
    bad = crafted(driver="../../x")
    for argv in (("test", "--replay", bad), ("recording", "to-test", bad)):
        rc, out, err = vmac(t, *argv)
        assert rc == 2 and "not a name" in out + err, "vmac %s took a recording whose driver is a path: %d %s%s" % (
            argv[0], rc, out, err)


WASHER_SETTINGS = {"driver.washer.param.time_scale": "0.02", "driver.washer.param.program": "quick"}
MOTOR_ON_BIT = 4  # washer.lua: motor_on = "do4"


def test_a_board_stopped_mid_wash_is_recorded_and_replays_exactly(t):
    """The shipped washer driver and its programme files (vmac.cycles())
    mid-wash when its board stops answering (SIGSTOP): the host drops it,
    the recording holds the last ticks' inputs (water in the drum, the
    motor on), the miss with the time its request was sent, and the drop;
    `vmac test --replay FILE` reproduces every recorded output."""
    host = t.host(settings=WASHER_SETTINGS)
    board = t.board("washer", "washer-1", commands=True)
    host.wait_running(["washer-1"])
    board.send("washer-1 fill_rate_lps 5")
    board.wait_line(r"^washer-1: fill_rate_lps 5", 10, what="the fill rate set")
    since = host.last_event_seq()
    # Started by operator input (the API), which the recording keeps too:
    # refused with the door open, taken once it is closed.
    start = {"name": "start", "value": "quick"}
    board.send("washer-1 door 0")  # the plant starts with its door closed
    host.wait_status(lambda s: host.device("washer-1", s)["variables"].get("door") == "open", 30,
                     "the driver saying the door is open")
    code, body = http_post(host, "/api/devices/washer-1/input", start, t.token)
    assert code == 409 and "door" in body, "the washer did not refuse to start with its door open: %d %s" % (
        code, body)
    board.send("washer-1 door 1")
    host.wait_status(lambda s: host.device("washer-1", s)["inputs"]["digital"][0], 30, "the door closed")
    code, body = http_post(host, "/api/devices/washer-1/input", start, t.token)
    assert code == 200, "the washer refused to start: %d %s" % (code, body)

    def washing(s):
        d = host.device("washer-1", s)
        return (d["variables"].get("step") == "wash" and d["outputs"]["digital"][MOTOR_ON_BIT]
                and (d["variables"].get("drum_rpm") or 0) > 20)

    host.wait_status(washing, 60, "the washer washing, its motor on and the drum turning")
    board.signal(signal.SIGSTOP)
    try:
        drop = host.wait_event("dropped", "washer-1", after_seq=since)
        rec_event = host.wait_event("recording", "washer-1", after_seq=since)
    finally:
        board.signal(signal.SIGCONT)
    assert "dropped" in rec_event["text"], "the recording is not said to be of the drop: %r" % rec_event["text"]
    path = fetch(t, host, recording_id(rec_event), "washer.rec")
    header, records, end = parse(path)

    assert header["driver"] == "washer" and header["driver_version"] == "1.2.0", "header: %r" % header["driver"]
    assert header["complete"] is True, "a recording of seconds since attach lost its first ticks"
    assert header["reason"].startswith("dropped"), "reason %r" % header["reason"]
    params = {r["name"]: r["value"] for r in records if r.get("event") == "param"}
    assert params.get("time_scale") == 0.02 and params.get("program") == "quick", (
        "the params at attach are not the host's settings: %r" % params)
    ticks = [r for r in records if "tick" in r]
    assert len(ticks) > 20, "only %d ticks recorded" % len(ticks)
    # The last ticks: water in the drum (ai0, 0.01 l a count) and the motor on.
    last = ticks[-1]["tick"][0]
    level_counts, applied_digital = last["in"][1], last["in"][4]
    out_digital = last["out"][0]
    assert level_counts > 0, "the last tick's water level is %d counts, not above 0" % level_counts
    assert out_digital >> MOTOR_ON_BIT & 1, "the last tick's outputs 0x%02x do not hold the motor on" % out_digital
    assert applied_digital >> MOTOR_ON_BIT & 1, (
        "the board did not report the motor on in the last tick (applied 0x%02x)" % applied_digital)
    inputs = [r for r in records if r.get("event") == "input"]
    assert [(r["name"], r["value"], r["code"] > 0) for r in inputs] == [("start", "quick", True)] * 1 + [
        ("start", "quick", False)] and inputs[1]["code"] == 0, (
        "the operator's start is not recorded as refused, then accepted: %r" % inputs)
    assert any(r["tick"][0]["in"][3] != 0 for r in ticks), "the drum never turned in the recording"
    misses = [r for r in records if r.get("event") == "miss"]
    assert misses, "no miss event in the recording: %r" % records[-4:]
    miss = misses[-1]
    assert miss["sent_ns"] > 0, "the miss has no time its request was sent: %r" % miss
    assert miss["received_ns"] == 0 or miss["received_ns"] >= miss["sent_ns"], (
        "the miss's reply time is before its request: %r" % miss)
    drops = [r for r in records if r.get("event") == "drop"]
    assert drops and drops[-1]["t"] >= miss["t"], "no drop event after the miss: %r" % records[-4:]
    assert records[-1].get("event") == "drop", "the recording does not end with the drop: %r" % records[-1]
    assert end["end"]["lines"] == len(records), "the end line counts %d lines, there are %d" % (
        end["end"]["lines"], len(records))
    assert drop["seq"] <= rec_event["seq"], "the recording came before the drop"

    rc, out, err = vmac(t, "test", "--replay", path)
    assert rc == 0, "the replay of the washer differs from the recording (exit %d):\n%s%s" % (rc, out, err)
    m = re.search(r"(\d+) ticks and (\d+) operator inputs replayed: every output as recorded", out)
    assert m, "the replay does not say every output is as recorded: %r" % out
    assert int(m.group(1)) == len(ticks), "the replay ran %s ticks, the recording has %d" % (m.group(1), len(ticks))
    assert int(m.group(2)) == 2, "the replay fed %s operator inputs, the recording has 2" % m.group(2)


def rare_failure_recording(t, name="rare.rec"):
    """A host running the buggy rare driver on rare-1, made to fail once
    (switch on, a full batch): (host, the fetched recording's path, its id)."""
    host = t.host(drivers=driver_dir(t, "buggy", rare=BUGGY))
    board = t.board("generic", "rare-1", driver="rare", commands=True)
    host.wait_running(["rare-1"])
    since = host.last_event_seq()
    board.send("rare-1 encoder 7")
    board.send("rare-1 di0 1")
    rec_event = host.wait_event("recording", "rare-1", after_seq=since)
    board.send("rare-1 di0 0")
    rec_id = recording_id(rec_event)
    return host, fetch(t, host, rec_id, name), rec_id


def write_bytes(t, name, data):
    path = os.path.join(t.logdir, name)
    with open(path, "wb") as f:
        f.write(data)
    return path


def test_a_damaged_recording_gets_a_clear_error(t):
    """docs/RECORDING.md: a truncated or corrupted file, or one that is no
    recording, cannot be replayed (exit 2) and the message names the
    problem; the API answers 404 for a recording it does not have and 401
    without a token."""
    host, path, rec_id = rare_failure_recording(t)
    with open(path, "rb") as f:
        good = f.read()
    rc, out, err = vmac(t, "test", "--replay", path)
    assert rc == 1, "the intact recording does not replay its failure (exit %d): %s%s" % (rc, out, err)

    # A digit of a tick's input changed: still JSON, but not what was hashed.
    lines = good.split(b"\n")
    tick_at = next(i for i, l in enumerate(lines) if b'"tick"' in l)
    flip_at = sum(len(l) + 1 for l in lines[:tick_at]) + lines[tick_at].index(b'"in":[') + len(b'"in":[')
    flipped = bytearray(good)
    flipped[flip_at] = ord("7") if flipped[flip_at] != ord("7") else ord("6")
    no_recording = b"-- a driver, not a recording\nreturn {}\n"
    cases = [
        ("truncated at half", good[:len(good) // 2], r"recording truncated"),
        ("without its end line", b"\n".join(lines[:-2]) + b"\n", r"recording truncated: no end line"),
        ("with one byte changed", bytes(flipped), r"recording damaged: its hash does not match"),
        ("a Lua file", no_recording, r"not a vmac recording"),
        ("empty", b"", r"not a vmac recording \(empty\)"),
    ]
    for what, data, message in cases:
        bad = write_bytes(t, "bad.rec", data)
        rc, out, err = vmac(t, "test", "--replay", bad)
        assert rc == 2, "a recording %s: vmac test --replay exited %d, not 2: %s%s" % (what, rc, out, err)
        assert re.search(message, out + err), "a recording %s: the replay does not say %r: %r" % (
            what, message, out + err)
        rc, out, err = vmac(t, "recording", "to-test", bad)
        assert rc == 2 and re.search(message, err), (
            "a recording %s: vmac recording to-test exited %d (not 2) or does not say %r: %r" % (
                what, rc, message, out + err))
        assert not out, "vmac recording to-test wrote a test of a recording %s: %r" % (what, out[:200])

    read = t.make_token("read")
    assert http_code(host, "/api/recordings/%d" % rec_id, read) == 200, "recording %d is not there" % rec_id
    assert http_code(host, "/api/recordings/999", read) == 404, "GET /api/recordings/999 is not a 404"
    assert http_code(host, "/api/recordings", None) == 401, "GET /api/recordings without a token is not a 401"
    assert http_code(host, "/api/recordings/%d" % rec_id, None) == 401, (
        "GET /api/recordings/ID without a token is not a 401")
    rc, _, err = vmac(t, "recording", "get", "--http", host.http, "999", token=read,
                      stdout_file=os.path.join(t.logdir, "none.rec"))
    assert rc == 1 and "404" in err and "no such recording" in err, (
        "vmac recording get 999 exited %d: %r" % (rc, err))


def test_recordings_are_bounded(t):
    """With recordings_max=3 the store keeps the three newest recordings
    of five drops; the older ones are gone from the list and the API."""
    host = t.host(settings={"recordings_max": "3"})
    board = t.board("generic", "io-1")
    kept = []
    since = 0
    for n in range(5):
        # Attached again (a fresh attach: a board stopped while it registers
        # is dropped before its driver ran, with nothing to record).
        host.wait_event("attached", "io-1", after_seq=since)
        host.wait_running(["io-1"])
        since = host.last_event_seq()
        board.signal(signal.SIGSTOP)
        try:
            rec_event = host.wait_event("recording", "io-1", after_seq=since)
        finally:
            board.signal(signal.SIGCONT)
        assert "dropped" in rec_event["text"], "drop %d: recording event %r" % (n + 1, rec_event["text"])
        kept.append(recording_id(rec_event))
    assert len(set(kept)) == 5, "five drops did not make five recordings: %r" % kept

    rc, out, err = vmac(t, "recordings", "--http", host.http)
    assert rc == 0, "vmac recordings failed (exit %d): %s" % (rc, err)
    listed = [int(l.split()[0]) for l in out.splitlines() if l.strip()]
    assert listed == sorted(kept[2:], reverse=True), (
        "vmac recordings lists %r, not the three newest of %r, newest first:\n%s" % (listed, kept, out))
    read = t.make_token("read")
    for gone in kept[:2]:
        assert http_code(host, "/api/recordings/%d" % gone, read) == 404, "recording %d was not removed" % gone
    for rec_id in kept[2:]:
        assert http_code(host, "/api/recordings/%d" % rec_id, read) == 200, "recording %d is gone" % rec_id


# A driver whose outputs depend on what it counted: from the 80th tick on,
# the lamp is on every fifth tick of the count in dev.state (so a version
# that starts counting afresh cannot match a recording taken later).
COUNTING = """-- counting: the lamp on every fifth tick from the 80th
local driver = { name = "counting", version = "%(version)s", io = { lamp = "do0" } }
function driver.attach(dev)
	dev.state.n = 0
end
function driver.tick(dev, inputs)
	dev.state.n = dev.state.n + 1
	dev.out.lamp = dev.state.n >= 80 and dev.state.n %% 5 == 0
end
%(migrate)s
return driver
"""
COUNTING_MIGRATES = COUNTING % {"version": "1.0.0", "migrate": "function driver.migrate(dev, old)\n"
                                "\tdev.state.n = old.n or 0\nend"}
COUNTING_FORGETS = COUNTING % {"version": "1.0.1", "migrate": ""}


def test_a_wrapped_recording_replays_from_the_state_it_holds(t):
    """A ring far shorter than the machine's life (recorder_s 2: 64 ticks at
    100 ms) with checkpoints every second: `vmac record` captures a
    recording that starts mid-life and carries the driver's dev.state from
    the oldest checkpoint the ring still covers; the replay resumes from it
    through migrate and reproduces every output after it. The same
    recording against a version without migrate starts afresh and differs."""
    drivers = driver_dir(t, "drivers", counting=COUNTING_MIGRATES)
    host = t.host(drivers=drivers, settings={"recorder_s": 2, "checkpoint_s": 1})
    t.board("generic", "count-1", driver="counting")
    host.wait_running(["count-1"])
    host.wait_status(lambda s: host.device("count-1", s)["served"] >= 150, 60, "count-1 served 150 ticks")
    since = host.last_event_seq()
    code, body = http_post(host, "/api/devices/count-1/record", {}, t.token)
    assert code == 200, "POST /api/devices/count-1/record: %d %s" % (code, body)
    rec_event = host.wait_event("recording", "count-1", after_seq=since)
    path = fetch(t, host, recording_id(rec_event), "counting.rec")
    header, records, _ = parse(path)
    ticks = [r for r in records if "tick" in r]
    assert header["complete"] is False, "a 64-tick ring after 150 ticks says it holds every tick since attach"
    assert "state" in header, "a wrapped recording carries no dev.state: %r" % sorted(header)
    after = [r for r in ticks if r["t"] > header["state"]["t"]]
    assert ticks[0]["t"] <= header["state"]["t"] and len(after) >= 20, (
        "the state (at %d ns) is not inside the recording's ticks (%d .. %d ns), %d ticks after it" % (
            header["state"]["t"], ticks[0]["t"], ticks[-1]["t"], len(after)))
    lamp = [r["tick"][0]["out"][0] & 1 for r in after]
    assert 0 < sum(lamp) < len(lamp), "the lamp never changes in the ticks replayed: %r" % lamp

    rc, out, err = vmac(t, "test", "--replay", path)
    assert rc == 0, "the wrapped recording does not replay from its state (exit %d):\n%s%s" % (rc, out, err)
    assert "resumes from its dev.state" in out, "the replay does not say it resumes from the state: %r" % out
    m = re.search(r"(\d+) ticks and \d+ operator inputs replayed: every output as recorded", out)
    assert m and int(m.group(1)) == len(after), "the replay ran %s ticks, %d follow the state: %r" % (
        m and m.group(1), len(after), out)

    other = driver_dir(t, "forgets", counting=COUNTING_FORGETS)
    rc, out, err = vmac(t, "test", "--replay", path, "--drivers", other)
    assert rc == 1 and "has no migrate" in out and "DIFFERS at tick" in out, (
        "a version without migrate replayed the wrapped recording as recorded (exit %d):\n%s%s" % (rc, out, err))
