"""Junk on the host's own bus address: every datagram is counted as
malformed under the right reason, and the host and its boards carry on;
and a board's replies of an earlier session are counted as stale."""

import functools
import random
import socket
import time

from fake_board import FakeBoard
from frames import ANNOUNCE, DISCOVER, ERROR, IDLE, REGISTER, SYS, UPDATE, announce, frame, inputs, outputs, parse, \
    patch, register, reply
from harness import KITCHEN_NAMES, undisturbed, until

TOTAL = 10000
BATCH = 500

# The junk's frames unless one says otherwise: device 0x00010000, seq 1, a
# board's reply (or, where that is the fault, the host's request); an
# ANNOUNCE names a washer junk-1.
junk_reply = functools.partial(reply, device_id=0x00010000, seq=1)
junk_request = functools.partial(frame, device_id=0x00010000, seq=1)
junk_announce = functools.partial(announce, driver=b"washer", board=b"junk-1")


class Junk:
    """Makes datagrams the host must reject, each with the reason it must
    count it under (core/host/bus.h, vmac_malformed_reason_names)."""

    def __init__(self, rnd, stale_announce_seq):
        self.rnd = rnd
        self.stale_seq = stale_announce_seq
        self.kinds = [getattr(self, k) for k in sorted(dir(self)) if k.startswith("k_")]

    def make(self):
        return self.rnd.choice(self.kinds)()

    def unknown_id(self):
        # Never a device this host gave out (ids are generation << 16 | slot,
        # slots < max_devices); the sender address would not match anyway.
        return self.rnd.randint(0x40000000, 0xFFFFFFFF)

    def k_random_bytes(self):
        data = bytearray(self.rnd.getrandbits(8) for _ in range(self.rnd.randint(0, 200)))
        if data and data[0] == ord("V"):
            data[0] = 0
        return bytes(data), "short" if len(data) < 13 else "magic"

    def k_truncated(self):
        whole = junk_reply(UPDATE, inputs(), device_id=self.unknown_id())
        cut = self.rnd.randint(0, len(whole) - 1)
        return whole[:cut], "short" if cut < 13 else "length"

    def k_bad_magic(self):
        magic = self.rnd.choice([b"MV", b"VN", b"\0\0", b"vm"])
        return patch(junk_reply(UPDATE, inputs()), "magic", magic), "magic"

    def k_wrong_version(self):
        return patch(junk_reply(UPDATE, inputs()), "version", self.rnd.choice([0, 3, 0x7F, 0xFF])), "version"

    def k_length_mismatch(self):
        good = junk_reply(UPDATE, inputs(), device_id=self.unknown_id())
        choice = self.rnd.randint(0, 3)
        if choice == 0:
            return patch(junk_reply(UPDATE, inputs()), "len", self.rnd.choice([0, 11, 13, 96])), "length"
        if choice == 1:
            return patch(junk_reply(UPDATE, inputs()), "len", self.rnd.randint(97, 255)), "length"
        if choice == 2:
            return good + b"\0", "length"
        return good[:-1], "length"

    def k_oversize(self):
        data = bytes(self.rnd.getrandbits(8) for _ in range(self.rnd.randint(97, 187)))
        return patch(junk_reply(UPDATE, data), "len", 96), "length"

    def k_unknown_op(self):
        choice = self.rnd.randint(0, 3)
        if choice == 0:
            return junk_reply(self.rnd.randint(0x07, 0xFF), b""), "op"
        if choice == 1:  # a channel that does not exist
            return patch(junk_reply(UPDATE, inputs()), "channel", self.rnd.randint(0x01, 0xFE)), "op"
        if choice == 2:  # DISCOVER is never a reply; no other system op exists
            return junk_reply(self.rnd.choice([DISCOVER, 0x02, 0x11, 0x7F]), b"", channel=SYS, device_id=0), "op"
        return patch(junk_reply(UPDATE, inputs()), "flags", self.rnd.choice([0x04, 0x05, 0x80, 0xFD])), "op"

    def k_request(self):
        choice = self.rnd.randint(0, 3)
        if choice == 0:
            return junk_request(DISCOVER, b"", channel=SYS, device_id=0), "not_reply"
        if choice == 1:
            return junk_request(UPDATE, outputs(0x01, 0)), "not_reply"
        if choice == 2:
            return junk_request(REGISTER, register(1, 0, 500)), "not_reply"
        return junk_request(IDLE, b""), "not_reply"

    def k_unknown_device(self):
        dev = self.unknown_id()
        choice = self.rnd.randint(0, 3)
        if choice == 0:
            return junk_reply(UPDATE, inputs(digital=0xFF, analog=(4095, 0)), device_id=dev), "unknown_sender"
        if choice == 1:
            return junk_reply(IDLE, inputs(), device_id=dev), "unknown_sender"
        if choice == 2:
            return junk_reply(REGISTER, b"", device_id=dev), "unknown_sender"
        return junk_reply(ERROR, bytes([1, UPDATE]), device_id=dev), "unknown_sender"

    def k_stale_announce(self):
        return junk_reply(ANNOUNCE, junk_announce(), channel=SYS, device_id=0, seq=self.stale_seq), "stale_seq"

    def k_bad_name(self):
        choice = self.rnd.randint(0, 4)
        if choice == 0:
            data = junk_announce(driver=b"../etc/passwd")
        elif choice == 1:
            data = junk_announce(board=b"bo\x07rd")
        elif choice == 2:
            data = junk_announce(driver=b"wa sher")
        elif choice == 3:
            data = junk_announce(board=b"")
        else:
            data = junk_announce(driver=b"d" * 32)
        return junk_reply(ANNOUNCE, data, channel=SYS, device_id=0, seq=self.stale_seq), "name"

    def k_bad_value(self):
        choice = self.rnd.randint(0, 4)
        if choice == 0:
            return junk_reply(UPDATE, inputs(analog=(4096, 0))), "value"
        if choice == 1:
            return junk_reply(UPDATE, inputs(applied_digital=0x80)), "value"
        if choice == 2:
            return junk_reply(ERROR, bytes([self.rnd.choice([0, 4, 0xFF]), UPDATE])), "value"
        if choice == 3:  # system frame with a device id
            return junk_reply(ANNOUNCE, junk_announce(), channel=SYS, device_id=7, seq=self.stale_seq), "value"
        return junk_reply(ANNOUNCE, junk_announce(caps=(9, 7, 2, 1, 1)), channel=SYS, device_id=0,
                          seq=self.stale_seq), "value"

    def k_bad_payload(self):
        choice = self.rnd.randint(0, 2)
        if choice == 0:
            return junk_reply(UPDATE, inputs()[:11]), "payload"
        if choice == 1:
            return junk_reply(REGISTER, b"\0"), "payload"
        return junk_reply(ANNOUNCE, junk_announce()[:-1], channel=SYS, device_id=0, seq=self.stale_seq), "payload"


def test_malformed_flood(t):
    host = t.host()
    t.kitchen(host)
    before = host.status()
    host_ip, host_port = before["bus"]["host_addr"].rsplit(":", 1)
    target = (host_ip, int(host_port))
    # ANNOUNCE replies must answer the latest DISCOVER; one discovery every
    # 300 ms would take hours to reach this sequence number.
    seed = random.SystemRandom().randrange(1 << 32)
    rnd = random.Random(seed)
    junk = Junk(rnd, (before["counters"]["discoveries"] + 30000) & 0xFFFF)
    base = before["counters"]["malformed_frames"]
    base_reasons = dict(before["counters"]["malformed_by_reason"])
    expected = {}
    started = time.monotonic()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sent = 0
        while sent < TOTAL:
            for _ in range(min(BATCH, TOTAL - sent)):
                data, reason = junk.make()
                expected[reason] = expected.get(reason, 0) + 1
                sock.sendto(data, target)
                sent += 1

            def counted(s, want=base + sent):
                got = s["counters"]["malformed_frames"]
                assert got <= want, "malformed_frames grew by %d after %d junk datagrams (seed %d)" % (
                    got - base, sent, seed)
                return got == want

            host.wait_status(counted, 60, "malformed_frames grown by %d (seed %d)" % (sent, seed),
                             undisturbed(KITCHEN_NAMES))
    finally:
        sock.close()
    elapsed_s = time.monotonic() - started

    after = host.status()
    assert host.alive(), "vmacd died under the flood"
    assert after["counters"]["malformed_frames"] - base == TOTAL, "malformed_frames grew by %d, expected %d" % (
        after["counters"]["malformed_frames"] - base, TOTAL)
    got = {r: after["counters"]["malformed_by_reason"][r] - base_reasons[r] for r in base_reasons}
    for reason in sorted(set(got) | set(expected)):
        assert got.get(reason, 0) == expected.get(reason, 0), (
            "malformed_by_reason.%s grew by %d, expected %d (seed %d; all: got %s, sent %s)"
            % (reason, got.get(reason, 0), expected.get(reason, 0), seed, got, expected))
    undisturbed(KITCHEN_NAMES)(after)
    assert after["counters"]["announces"] == before["counters"]["announces"], "a junk ANNOUNCE was accepted"
    assert len(after["devices"]) == 3, "junk created devices: %s" % [d["name"] for d in after["devices"]]
    # Reported at most once a second, not once a datagram.
    reports = host.find_lines(r"\[malformed\]", stream="stderr")
    assert len(reports) <= elapsed_s + 2, "%d malformed-frame reports in %.1f s" % (len(reports), elapsed_s)
    # And the bus still serves.
    served = {n: host.device(n, after)["served"] for n in KITCHEN_NAMES}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 5 for n in KITCHEN_NAMES), 30,
                     "every device served after the flood", undisturbed(KITCHEN_NAMES))


def test_a_late_reply_of_a_boards_earlier_session_is_stale(t):
    """A reply of a board's earlier session, from the address its slot
    holds, is a stale one (PROTOCOL.md, malformed_by_reason), not a sender
    the host does not know: a board that lost its session and announced
    again may still have replies of the old one on their way."""
    host = t.host(settings={"bus_trust": "open"})  # a board of ours, without a key
    board = FakeBoard(t.bus, "lamp-1", "lights", 1)
    try:
        until(lambda: board.device_id and any(parse(f)[0].op == UPDATE for f, _ in board.sent_replies), 30,
              "an UPDATE answered in lamp-1's first session")
        first = board.device_id
        old = [(f, to) for f, to in board.sent_replies if parse(f)[0].op == UPDATE][-1]
        board.device_id = 0  # it lost its session: it announces at the next DISCOVER
        until(lambda: board.device_id not in (0, first), 30, "lamp-1 in a new session")
        before = host.status()["counters"]
        for _ in range(5):
            board.sock.sendto(*old)
        after = host.wait_status(lambda s: s["counters"]["malformed_frames"] >= before["malformed_frames"] + 5, 30,
                                 "the five replies of the earlier session counted")["counters"]
    finally:
        board.close()
    grew = {r: after["malformed_by_reason"][r] - before["malformed_by_reason"][r] for r in before["malformed_by_reason"]}
    assert grew["unknown_sender"] == 0 and grew["stale_seq"] >= 5, \
        "replies of lamp-1's earlier session (device %#x, now %#x) were counted as %s" % (
            first, board.device_id, {r: n for r, n in grew.items() if n})


def test_a_reply_from_a_board_waiting_for_approval_is_a_strangers(t):
    """A board waiting for approval has no session: a reply it sends for
    its entry's slot, from the address the entry holds, is a sender the host
    does not know (PROTOCOL.md, malformed_by_reason), never a late reply of
    an earlier session, and it attaches nothing."""
    host = t.host()  # bus_trust enrolled: a board without a key waits
    board = FakeBoard(t.bus, "stranger-1", "lights", 1)
    hosts = []
    announce = board._announce

    def noting_the_host(h, nonce, src):
        hosts.append(src)
        announce(h, nonce, src)
    board._announce = noting_the_host
    try:
        host.wait_status(lambda s: any(d["name"] == "stranger-1" and d["state"] == "waiting" for d in s["devices"]),
                         30, "stranger-1 waiting for approval")
        until(lambda: hosts, 30, "a DISCOVER stranger-1 answered")
        before = host.status()["counters"]
        # Its entry's slot is one of the first; the generations of a session.
        sent = 0
        for slot in range(4):
            for generation in (1, 2):
                board.sock.sendto(reply(UPDATE, inputs(), device_id=generation << 16 | slot, seq=1),
                                  hosts[-1])
                sent += 1
        after = host.wait_status(lambda s: s["counters"]["malformed_frames"] >= before["malformed_frames"] + sent, 30,
                                 "the %d replies counted" % sent)
    finally:
        board.close()
    grew = {r: after["counters"]["malformed_by_reason"][r] - before["malformed_by_reason"][r]
            for r in before["malformed_by_reason"]}
    assert grew["stale_seq"] == 0 and grew["unknown_sender"] >= sent, \
        "replies of a board waiting for approval were counted as %s" % {r: n for r, n in grew.items() if n}
    assert [d["state"] for d in after["devices"] if d["name"] == "stranger-1"] == ["waiting"], \
        "stranger-1 is no longer waiting: %r" % after["devices"]
