"""Trust on the wire (issue #30; docs/SECURITY.md; docs/PROTOCOL.md,
"Authenticated frames"): the host attaches only boards whose announcement
proves their enrolled key, seals every frame of their sessions, and ignores
what does not prove the session's key; a board ignores a host frame that
does not. A board without a key waits for approval. The Python side here
seals and checks frames with libsodium's SipHash (PyNaCl): the other side's
reading of the specification, not the host's code.

Every test's real boards are keyed and enrolled by the harness (vmac board
enroll --local, vmac-board --key-dir), as on any host with bus_trust
enrolled, the default."""

import os
import re
import socket
import struct
import time

import frames
from fake_board import FakeBoard
from frames import SYS, UPDATE, parse, seal
from harness import LOADED, Skip, bus_socket, post, sender_socket, undisturbed, until

FORGED = 20  # forged or replayed frames sent in each attempt


def need_nacl():
    if frames.NACL is None:
        raise Skip("PyNaCl (Debian python3-nacl) is missing: the tests' own sealed frames need libsodium's SipHash")


def address(text):
    host, port = text.rsplit(":", 1)
    return host, int(port)


def services(board):
    """The UPDATEs and IDLEs a FakeBoard obeyed."""
    return len(board.updates) + board.idles


def enroll_api(host, token, board, key=None):
    """POST /api/boards/BOARD: (status, answer)."""
    body = {} if key is None else {"key": key.hex()}
    code, text = post(host, "/api/boards/" + board, token, json_bytes(body))
    return code, text


def json_bytes(o):
    import json
    return json.dumps(o).encode()


def test_a_keyed_board_of_our_own_attaches_with_every_frame_sealed(t):
    """The host's sealing read by libsodium: a board we wrote, given a key
    through the API, attaches; the REGISTER and every UPDATE the host sends
    open under the session's keys as PROTOCOL.md derives them."""
    need_nacl()
    host = t.host()
    code, text = enroll_api(host, t.token, "peer-1")
    assert code == 200, "enrolling peer-1 over the API answered %d: %s" % (code, text)
    import json
    key = bytes.fromhex(json.loads(text)["key"])
    peer = FakeBoard(t.bus, "peer-1", "lights", 4242, key=key)
    try:
        s = host.wait_running(["peer-1"])
        assert host.device("peer-1", s)["authenticated"] is True, "peer-1 runs but is not marked authenticated"
        until(lambda: services(peer) >= 20, 10,
              lambda: "20 UPDATEs opened under the session's key (only %d)" % services(peer))
        assert peer.bad == 0, "%d frames from the host did not open under the session's keys" % peer.bad
        # The board's replies, replayed: refused by their counters.
        before = host.status()["counters"]["auth_failed"]
        old = list(peer.sent_replies[-5:])
        for frame, to in old * (FORGED // 5):
            peer.sock.sendto(frame, to)
        s = host.wait_status(lambda st: st["counters"]["auth_failed"] >= before + FORGED, 10,
                             "the replayed replies counted", invariant=undisturbed(["peer-1"]))
        host.wait_event("auth", text="replay")
        assert host.device("peer-1", s)["state"] == "running"
    finally:
        peer.close()


def test_a_spoofing_board_takes_over_nothing(t):
    """A process on the bus answers discovery with the running washer's
    identity: unsealed, sealed with a key of its own, and under another
    name. The washer is never dropped, the spoofer never gets a REGISTER,
    and every attempt is counted."""
    need_nacl()
    host = t.host()
    t.board("washer", "washer-1")
    s = host.wait_running(["washer-1"])
    washer = host.device("washer-1", s)
    before = s["counters"]
    spoofers = [FakeBoard(t.bus, "washer-1", "washer", washer["major"]),
                FakeBoard(t.bus, "washer-1", "washer", washer["major"], key=os.urandom(16)),
                FakeBoard(t.bus, "evil", "washer", washer["major"], key=os.urandom(16))]
    try:
        host.wait_status(lambda st: st["counters"]["discoveries"] >= before["discoveries"] + 5, 30,
                         "five discoveries", invariant=undisturbed(["washer-1"]))
    finally:
        for p in spoofers:
            p.close()
    after = host.status()
    assert [p.registers for p in spoofers] == [0, 0, 0], \
        "a spoofer got a REGISTER (unsealed, wrong key, other name): %r" % [p.registers for p in spoofers]
    assert after["counters"]["auth_failed"] - before["auth_failed"] >= 10, \
        "the spoofed announcements were not counted: auth_failed %d -> %d" % (before["auth_failed"],
                                                                               after["counters"]["auth_failed"])
    assert after["counters"]["takeover_refused"] > before["takeover_refused"], \
        "the announcement under another name was not refused as a take-over"
    assert not host.find_events("dropped", "washer-1"), "the washer was dropped: %r" % host.find_events("dropped")
    assert host.device("evil", after) is None or host.device("evil", after)["state"] == "waiting", \
        "the spoofer 'evil' got further than waiting: %r" % host.device("evil", after)
    assert host.find_events("auth"), "no auth event said what was refused"


def lights_record(t, host):
    """The lights board's address and device id, as the host has them."""
    d = host.device("lights-1", host.status())
    return address(d["address"]), d["id"]


def counter_line(board, name):
    """The value of counter name in vmac-board's last report ("NAME: frames
    ok N, ..., auth_failed N")."""
    found = re.findall(r"\b%s (\d+)" % re.escape(name), board.text("stdout") + board.text("stderr"))
    return int(found[-1]) if found else None


def test_a_forged_or_replayed_host_frame_moves_no_output(t):
    """Frames sent to a keyed board as if from the host: UPDATEs turning
    every output on, unsealed or sealed with a wrong key, and the host's own
    CYCLIC frames replayed after the lights went off. The board obeys none:
    its outputs stay as the driver set them, and it counts each."""
    need_nacl()
    host = t.host()
    board = t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    token = t.token
    code, text = post(host, "/api/devices/lights-1/input", token, json_bytes({"name": "kitchen", "value": True}))
    assert code == 200, "turning the kitchen lights on answered %d: %s" % (code, text)
    host.wait_status(lambda s: any(host.device("lights-1", s)["outputs"]["digital"]), 10, "a light on")
    # The host's CYCLIC frames now carry the light on: keep some that hold
    # the board's record (a sealed frame: header, first, counter, then
    # records of 14 bytes; an empty record's tag is 0).
    offset = host.device("lights-1")["offset"]
    grp = bus_socket(t.bus, 0.2)
    captured = []
    try:
        deadline = time.monotonic() + 30 * LOADED  # a capture, not a wait: until does not fit
        while len(captured) < FORGED and time.monotonic() < deadline:
            try:
                data, _ = grp.recvfrom(2048)
            except socket.timeout:
                continue
            got = parse(data)
            if not got or got[0].channel != SYS or got[0].op != frames.CYCLIC or not got[0].flags & frames.AUTH:
                continue
            first = struct.unpack_from(">H", data, frames.HDR_LEN)[0]
            at = frames.CYCLIC_SEALED_HEAD + 14 * (offset - first)
            if first <= offset < first + got[0].len and data[at:at + 2] != b"\0\0":
                captured.append(data)
    finally:
        grp.close()
    assert len(captured) >= FORGED, "only %d sealed CYCLIC frames with the board's record in %d s" % (
        len(captured), 30 * LOADED)
    code, text = post(host, "/api/devices/lights-1/input", token, json_bytes({"name": "all_off"}))
    assert code == 200, "all_off answered %d: %s" % (code, text)
    host.wait_status(lambda s: not any(host.device("lights-1", s)["outputs"]["digital"]), 10, "every light off")
    to, device_id = lights_record(t, host)
    s, group = sender_socket(t.bus)
    try:
        on = struct.pack(">Bh", 0x7F, 1000)  # every output the lights board has, valid: only the MAC is wrong
        for i in range(FORGED):
            update = frames.frame(UPDATE, on, device_id=device_id, seq=1000 + i)
            s.sendto(update, to)  # unsealed
            s.sendto(seal(update, 1 << 30, os.urandom(16)), to)  # sealed with a key not the session's
            s.sendto(captured[i], group)  # an old CYCLIC frame of the host's, light on
        # The board's replies carry what it drives: judged over the next services.
        for _ in range(20):
            st = host.status()
            d = host.device("lights-1", st)
            assert not any(d["outputs"]["digital"]) and d["outputs"]["pwm"] == 0, \
                "a forged or replayed frame moved the board's outputs: %r" % d["outputs"]
            undisturbed(["lights-1"])(st)
            time.sleep(0.05)
    finally:
        s.close()
    board.signal(15)
    assert board.wait_exit(10) == 0, "vmac-board did not stop cleanly"
    failed = counter_line(board, "auth_failed")
    assert failed is not None, "vmac-board's exit report has no auth_failed counter"
    assert failed >= 3 * FORGED, "the board counted %d frames that failed authentication, %d were sent" % (
        failed, 3 * FORGED)


def test_a_board_without_a_key_waits_for_approval_then_runs_once_enrolled(t):
    """The enrollment flow from the command line: an unknown board is
    listed as waiting (status, event, vmac board list) and gets no driver;
    vmac board enroll --out makes its key; given it, the board runs,
    authenticated. Rotation: a new key (--replace) keeps the running session
    until the board restarts, and then only the new key works. Removal
    drops it at once."""
    host = t.host()
    first = t.board("lights", "lamp", keyed=False)
    host.wait_event("waiting", "lamp")
    s = host.wait_status(lambda st: host.device("lamp", st) is not None, 10, "lamp in the status")
    d = host.device("lamp", s)
    assert d["state"] == "waiting" and "vmac board enroll lamp" in d["note"], "lamp: %r" % d
    assert d["driver_version"] == "", "a waiting board has a driver loaded: %r" % d
    code, out, err = t.run([t.path("vmac"), "board", "list", "--http", host.http], "list")
    assert code == 0 and "waiting for approval" in out and "lamp" in out, "vmac board list: %s %s" % (out, err)
    key1 = os.path.join(t.logdir, "lamp.key")
    code, out, err = t.run([t.path("vmac"), "board", "enroll", "lamp", "--out", key1, "--http", host.http], "enroll")
    assert code == 0, "vmac board enroll lamp failed (%d): %s" % (code, err)
    assert oct(os.stat(key1).st_mode & 0o777) == "0o600", "the key file is not private: %o" % os.stat(key1).st_mode
    host.wait_event("enrolled", "lamp")
    first.signal(15)
    first.wait_exit(10)
    lamp = t.board("lights", "lamp", keyed=False, extra=("--key-file", key1))
    s = host.wait_running(["lamp"])
    assert host.device("lamp", s)["authenticated"] is True, "lamp runs unauthenticated"
    # Rotation.
    key2 = os.path.join(t.logdir, "lamp2.key")
    code, out, err = t.run([t.path("vmac"), "board", "enroll", "lamp", "--replace", "--out", key2, "--http",
                            host.http], "rotate")
    assert code == 0, "vmac board enroll --replace failed (%d): %s" % (code, err)
    seq = host.last_event_seq()
    # The running session goes on through three discoveries (the host's
    # count): no drop but for a reply a loaded machine's board sent late.
    found = host.status()["counters"]["discoveries"]
    host.wait_status(lambda s: s["counters"]["discoveries"] >= found + 3, 30, "three discoveries after the rotation")
    host.status()
    drops = [e["text"] for e in host.find_events("dropped", "lamp", after_seq=seq) if "no reply" not in e["text"]]
    assert not drops, "a key rotation dropped the running board: %s" % drops
    seq = host.last_event_seq()
    lamp.signal(15)
    lamp.wait_exit(10)
    host.wait_event("dropped", "lamp", after_seq=seq)  # it said nothing: its replies stopped
    seq = host.last_event_seq()
    old = t.board("lights", "lamp", keyed=False, extra=("--key-file", key1))
    host.wait_event("auth", text="lamp", after_seq=seq)
    assert host.device("lamp", host.status())["state"] != "running", "the board with the old key runs again"
    old.signal(15)
    old.wait_exit(10)
    t.board("lights", "lamp", keyed=False, extra=("--key-file", key2))
    host.wait_running(["lamp"])
    # Removal.
    seq = host.last_event_seq()
    code, out, err = t.run([t.path("vmac"), "board", "remove", "lamp", "--http", host.http], "remove")
    assert code == 0, "vmac board remove failed (%d): %s" % (code, err)
    host.wait_event("dropped", "lamp", text="key was removed", after_seq=seq)


SLOW_LOAD_LUA = """local x = 0
for i = 1, %d do x = x + i %% 7 end -- a file that takes a while to load, every time
return { name = "slowload", version = "1", io = { lamp = "do0" }, tick = function() end }
"""
SLOW_BOARDS = 8


def test_a_key_enrolled_while_many_drivers_load_is_taken_before_they_end(t):
    """The host's main thread loads drivers and looks at the store's keys:
    while boards keep it loading (here 8 machines whose driver file takes
    about half a second to run, each a load of its own), a key enrolled
    with vmac board enroll --local is still taken between two loads, not
    after the last (enroll() waits for the host to hold it)."""
    host = t.host(drivers=t.drivers(slowload=SLOW_LOAD_LUA % 100000000),
                  settings={"driver.slowload.budget_us": 200000, "driver.slowload.instructions": 100000000})
    t.board("generic", "slow", driver="slowload", count=SLOW_BOARDS)
    names = ["slow-%d" % i for i in range(1, SLOW_BOARDS + 1)]
    host.wait_status(lambda st: any(host.device(n, st) for n in names), 30, "a slow board attaching")
    t.enroll(["late-1"])
    # A board whose machine has its driver has a driver_version: the
    # loads not yet done are the boards without one (or not seen yet).
    s = host.status()
    unloaded = [n for n in names if not (host.device(n, s) or {}).get("driver_version")]
    assert len(unloaded) >= 2, (
        "the key was taken only once the loads had (nearly) ended: %d of %d drivers still to load (%s)" % (
            len(unloaded), SLOW_BOARDS, ", ".join(unloaded)))
    host.wait_running(names, 120)


def test_bad_enrollments_are_refused_with_a_reason(t):
    host = t.host()
    read = t.make_token("read")
    for path, body, want in (("/api/boards/bad.name", {}, 400), ("/api/boards/x", {"key": "00"}, 400),
                             ("/api/boards/x", {"key": "zz" * 16}, 400), ("/api/boards/x", [], 400),
                             ("/api/boards/..", {}, 404)):
        code, text = post(host, path, t.token, json_bytes(body))
        assert code == want, "POST %s %r answered %d, not %d: %s" % (path, body, code, want, text)
    code, text = post(host, "/api/boards/x", read, json_bytes({}))
    assert code == 403, "a read token enrolled a board (%d): %s" % (code, text)
    assert post(host, "/api/boards/x", t.token, json_bytes({}))[0] == 200
    code, text = post(host, "/api/boards/x", t.token, json_bytes({}))
    assert code == 409 and "replace" in text, "enrolling twice answered %d: %s" % (code, text)
    code, text = post(host, "/api/boards/nobody/remove", t.token, b"")
    assert code == 404, "removing a board never enrolled answered %d: %s" % (code, text)
    code, out, err = t.run([t.path("vmac"), "board", "enroll", "a", "b", "--http", host.http], "two")
    assert code == 2 and "--key-dir" in err, "two boards without --key-dir: %d %s" % (code, err)
    bad = os.path.join(t.logdir, "bad.key")
    with open(bad, "w") as f:
        f.write("not a key\n")
    code, out, err = t.run([t.path("vmac"), "board", "enroll", "a", "--key-file", bad, "--http", host.http], "bad")
    assert code == 1 and "32 hex digits" in err, "a bad key file: %d %s" % (code, err)


def test_an_open_bus_says_so_and_still_authenticates_enrolled_boards(t):
    """bus_trust open: a warning at start says anyone on the segment can
    speak for a board without a key; such a board attaches unauthenticated
    beside an enrolled one, which is still sealed."""
    host = t.host(settings={"bus_trust": "open"})
    warning = host.wait_event("warning", text="bus_trust is open")
    assert "anyone on the bus segment" in warning["text"], "the warning does not say why: %r" % warning["text"]
    assert host.status()["bus_trust"] == "open"
    t.board("lights", "plain-1", keyed=False)
    t.board("lights", "sealed-1")
    s = host.wait_running(["plain-1", "sealed-1"])
    assert host.device("plain-1", s)["authenticated"] is False, "an unkeyed board runs as authenticated"
    assert host.device("sealed-1", s)["authenticated"] is True, "an enrolled board runs unauthenticated on an open bus"
