"""Keyed boards on the board's side (docs/BOARD.md, "Keyed boards"):
vmac-board reads each board's key from the file `vmac board enroll --out
FILE` writes (--key-file, --key-dir), refuses a file that is not one, and a
keyed board answers only a DISCOVER with a nonce, its ANNOUNCE sealed with
that key, ignores and counts (auth_failed) what does not open, and never
attaches to a host that does not hold its key (it waits for approval
there). The boards here bring their own key files (keyed=False: the
harness enrolls none for them); test_trust.py has the host's side."""

import os
import random
import socket
import struct
import time

import frames
from frames import AUTH, DISCOVER, REGISTER, SYS, frame, opens, parse, register
from harness import Skip, sender_socket

EXIT_S = 30
KEY_HEX = "00112233445566778899AABBCCDDeeff"
KEY = bytes.fromhex(KEY_HEX)
TRAILER = frames.TRAILER.size


def key_file(t, name, text, mode=0o600):
    path = os.path.join(t.logdir, name)
    with open(path, "wb") as f:
        f.write(text if isinstance(text, bytes) else text.encode())
    os.chmod(path, mode)
    return path


def board_argv(t, *extra):
    return [t.path("vmac-board"), "--bus", t.bus, "--no-realtime"] + list(extra)


def test_a_key_file_that_is_not_one_is_refused_naming_the_file(t):
    # The file format of docs/BOARD.md: 32 hex digits, at most one newline.
    bad = {
        "short.key": KEY_HEX[:30] + "\n",
        "long.key": KEY_HEX + "00\n",
        "hex.key": KEY_HEX[:10] + "g" + KEY_HEX[11:] + "\n",
        "two-newlines.key": KEY_HEX + "\n\n",
        "crlf.key": KEY_HEX + "\r\n",
        "space.key": " " + KEY_HEX + "\n",
        "empty.key": "",
    }
    problems = []
    for name, text in sorted(bad.items()):
        path = key_file(t, name, text)
        rc, out, err = t.run(board_argv(t, "--key-file", path), "bad-" + name, EXIT_S)
        if rc != 2 or path not in err or "hex digit" not in err:
            problems.append("%s: exit %d, %r" % (name, rc, err.strip()))
        if KEY_HEX[:8].lower() in (out + err).lower():
            problems.append("%s: the key's digits were printed" % name)
    missing = os.path.join(t.logdir, "no-such.key")
    rc, _, err = t.run(board_argv(t, "--key-file", missing), "missing-key", EXIT_S)
    if rc != 2 or missing not in err or "No such file" not in err:
        problems.append("a missing key file: exit %d, %r" % (rc, err.strip()))
    rc, _, err = t.run(board_argv(t, "--key-file", t.logdir), "dir-key", EXIT_S)
    if rc != 2 or "not a regular file" not in err:
        problems.append("a folder as key file: exit %d, %r" % (rc, err.strip()))
    good = key_file(t, "good.key", KEY_HEX + "\n")
    rc, _, err = t.run(board_argv(t, "--key-file", good, "--key-dir", t.logdir), "both", EXIT_S)
    if rc != 2 or "--key-dir" not in err:
        problems.append("--key-file with --key-dir: exit %d, %r" % (rc, err.strip()))
    rc, _, err = t.run(board_argv(t, "--key-file", good, "--count", "2"), "count", EXIT_S)
    if rc != 2 or "--key-dir" not in err:
        problems.append("--key-file with --count 2: exit %d, %r" % (rc, err.strip()))
    # --key-dir: every board's NAME.key, the first missing one named.
    key_file(t, "k-1.key", KEY_HEX + "\n")
    rc, _, err = t.run(board_argv(t, "--key-dir", t.logdir, "--name", "k", "--count", "2"), "dir-missing", EXIT_S)
    if rc != 2 or os.path.join(t.logdir, "k-2.key") not in err:
        problems.append("--key-dir without k-2.key: exit %d, %r" % (rc, err.strip()))
    assert not problems, "; ".join(problems)


def test_keyed_boards_start_say_so_and_warn_of_an_open_key_file(t):
    quiet = key_file(t, "quiet.key", KEY_HEX)  # no newline: as valid as with one
    board = t.board("generic", "keyed", extra=["--key-file", quiet, "--no-realtime"], keyed=False)
    board.wait_line(r"^vmac-board: keyed: the board answers only a host that authenticates \(key file %s\)$"
                    % quiet, 10, what="the keyed line")
    assert "warning" not in board.text("stderr"), "a key file of mode 0600 was warned about: %r" % (
        board.text("stderr"))
    os.makedirs(os.path.join(t.logdir, "keys"))
    for i in (1, 2):
        key_file(t, "keys/open-%d.key" % i, KEY_HEX.lower() + "\n", mode=0o644)
    many = t.board("generic", "open", count=2, extra=["--key-dir", os.path.join(t.logdir, "keys"),
                                                      "--no-realtime"], keyed=False)
    many.wait_line(r"^vmac-board: keyed: the boards answer only a host that authenticates", 10,
                   what="the keyed line")
    for i in (1, 2):
        many.wait_line(r"^vmac-board: warning: key file \S*open-%d\.key has mode 0644: group or others may read "
                       r"or change the board's key" % i, 10, stream="stderr", what="the warning for open-%d.key" % i)
    for p in (board, many):
        assert KEY_HEX[:8].lower() not in (p.text("stdout") + p.text("stderr")).lower(), "the key was printed"


class Peer:
    """A UDP socket on the test's bus that speaks as a host would, frame by
    frame: discovery to the group, requests to a board's own address."""

    def __init__(self, t):
        self.sock, self.group = sender_socket(t.bus)
        t.cleanups.append(self.sock.close)

    def replies(self, wait_s):
        """Every (frame, address) that came within wait_s."""
        got, end = [], time.monotonic() + wait_s
        while time.monotonic() < end:
            self.sock.settimeout(max(0.01, end - time.monotonic()))
            try:
                got.append(self.sock.recvfrom(2048))
            except socket.timeout:
                break
        return got


def test_a_keyed_board_answers_only_a_discover_with_a_nonce_sealed_with_its_key(t):
    if frames.NACL is None:
        raise Skip("PyNaCl (Debian python3-nacl) is missing: the ANNOUNCE's MAC is checked with libsodium's SipHash")
    path = key_file(t, "k.key", KEY_HEX + "\n")
    board = t.board("generic", "sealed", major=0x1234, extra=["--key-file", path, "--no-realtime"], commands=True,
                    keyed=False)
    peer = Peer(t)
    peer.sock.sendto(frame(DISCOVER, b"", channel=SYS, seq=1), peer.group)
    got = peer.replies(1.5)
    assert not got, "a keyed board answered a DISCOVER without a nonce: %r" % (got,)

    nonce = bytes(random.getrandbits(8) for _ in range(8))
    for attempt in range(5):  # multicast on lo: the first may go before the board's membership settles
        peer.sock.sendto(frame(DISCOVER, nonce, channel=SYS, seq=2 + attempt), peer.group)
        # an answer to an earlier attempt, late on a loaded machine, is not this one's
        got = [r for r in peer.replies(1.0) if parse(r[0]) and parse(r[0])[0].seq == 2 + attempt]
        if got:
            break
    assert len(got) == 1, "a DISCOVER with a nonce: %d answers, expected the board's ANNOUNCE" % len(got)
    announce, address = got[0]
    h, _ = parse(announce)
    assert h.flags & AUTH and len(announce) == 13 + h.len + TRAILER, "the ANNOUNCE is not sealed: flags 0x%02x, " \
        "%d bytes for len %d" % (h.flags, len(announce), h.len)
    counter = struct.unpack_from(">Q", announce, 13 + h.len)[0]
    assert counter == 0, "the ANNOUNCE's counter is %d, expected 0" % counter
    assert opens(announce, KEY, nonce), \
        "the ANNOUNCE's MAC is not SipHash-2-4 under the key file's key over the frame and the nonce"

    # A REGISTER unsealed, and one sealed with a MAC of nobody's: silence,
    # no session, both counted.
    peer.sock.sendto(frame(REGISTER, register(0x1234, 0, 500), device_id=0x00010001, seq=9), address)
    forged = frame(REGISTER, register(0x1234, 0, 500), device_id=0x00010001, seq=10, flags=AUTH)
    peer.sock.sendto(forged + struct.pack(">Q", 1) + bytes(8), address)
    got = [r for r in peer.replies(1.0) if not parse(r[0]) or parse(r[0])[0].seq not in range(2, 7)]  # no late ANNOUNCE
    assert not got, "a keyed board answered a REGISTER it cannot open: %r" % (got,)
    mark = board.mark()
    board.send("status")
    line = board.wait_line(r"^sealed: frames ok ", 10, since=mark, what="the counters after 'status'")
    assert line.text.endswith("auth_failed 2"), "after two REGISTERs that do not open: %r" % line.text
    assert not board.find_lines(r"^sealed: state known"), "a REGISTER that does not open gave a session"


def test_a_keyed_board_never_attaches_to_a_host_without_its_key(t):
    path = key_file(t, "k.key", KEY_HEX + "\n")
    host = t.host()
    keyed = t.board("lights", "keyed-1", extra=["--key-file", path], keyed=False)
    t.board("lights", "enrolled-1")
    host.wait_running(["enrolled-1"], timeout_s=30)
    # The host sends a nonce with every DISCOVER: the keyed board answers,
    # sealed with a key the host does not hold, and is held back.
    host.wait_event("waiting", "keyed-1")
    d = host.device("keyed-1", host.status())
    assert d is None or d.get("state") != "running", "a keyed board runs on a host that does not hold its key"
    assert d is None or "key this host does not hold" in (d.get("note") or ""), "keyed-1: %r" % d
    assert not keyed.find_lines(r"^keyed-1: state known"), "the keyed board took a session"
    keyed.signal(2)
    assert keyed.wait_exit(EXIT_S) == 0, "the keyed board did not exit cleanly on SIGINT"
    line = keyed.find_lines(r"^keyed-1: frames ok ")
    assert line and line[-1].text.endswith(", auth_failed 0"), "no counters line at exit: %r" % (
        keyed.text("stdout")[-400:],)
