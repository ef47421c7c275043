"""The tests' own board on the UDP bus, written in Python from
docs/PROTOCOL.md (the other side's reading of it, not vmac-board's code):
FakeBoard announces, registers, answers the host's requests and its
records of CYCLIC frames, plain or TIMED, and, keyed, seals and opens
frames as "Authenticated frames" says. It keeps what it was served and
counts what did not open, so a test can judge the host by what reached
the board. The frames themselves are laid out by frames.py.

Used by test_timed.py (the host's instants) and test_trust.py (the host's
sealing, and boards that spoof a running one)."""

import socket
import struct
import threading
import time

import frames
from frames import (ANNOUNCE, DEV, DISCOVER, IDLE, OFFSET, REGISTER, REPLY, SHUTDOWN, SIZE, SYS, TIMED, UPDATE,
                    WATCHDOG, announce, inputs, parse, read_cyclic, read_sync, reply, timed_inputs)
from harness import bus_socket

RECORD_BYTES = 6  # the SIZE it answers: a version-2 record (tag, flags, digital, pwm)
TIMED_UPDATE_LEN = 19  # out_at, in_at, then the outputs (PROTOCOL.md, "The TIMED UPDATE")


class FakeBoard:
    """A board named name, of driver, major and minor, firmware (major,
    minor), announcing and answering in protocol version (1: unicast
    UPDATEs; 2: SIZE, OFFSET and its records of CYCLIC frames too).

    key None: a board without a key. key (16 bytes): it seals its ANNOUNCE
    with key when the DISCOVER carries a nonce, takes a session only from a
    REGISTER that opens under the session's keys, then obeys only frames
    sealed with to_board whose counter is above the last it obeyed, and
    seals every reply with to_host; anything else it ignores and counts in
    bad (with the CYCLIC records for it whose MAC does not open). A key
    that is not the enrolled one, or another board's name, makes a spoofer.

    Its inputs read digital_in. A TIMED service (a record or an UPDATE) is
    answered with a TIMED reply latched at in_at, sent answer_after_latch_s
    after in_at by CLOCK_MONOTONIC, the host's clock on this machine. On
    SHUTDOWN it forgets its session and announces again.

    What it keeps: served, every record of its own it was served, as
    (CyclicFrame, the last SYNC's host_ns before it or None); updates, every
    unicast UPDATE of its session as (Header, out_at, in_at), the instants
    None when not TIMED; idles and registers (every REGISTER that came,
    opened or not), counts; sent_replies, every (frame, address) it sent
    in a session, for replays."""

    def __init__(self, bus, name, driver, major, minor=0, firmware=(1, 0), version=1, key=None, digital_in=0,
                 answer_after_latch_s=0.0):
        self.name, self.driver, self.major, self.minor, self.firmware = name, driver, major, minor, firmware
        self.version, self.key, self.digital_in = version, key, digital_in
        self.answer_after_latch_s = answer_after_latch_s
        self.nonce = bytes(8)  # the nonce of the DISCOVER its sealed ANNOUNCE answered
        self.to_board = self.to_host = None  # the session's keys
        self.tx = 0  # the counter of its last sealed reply
        self.rx = 0  # the counter of the host's last frame it obeyed
        self.device_id = 0  # 0: no session
        self.offset = None
        self.host = None  # where replies to CYCLIC records go: the host's unicast address
        self.served, self.updates, self.sent_replies = [], [], []
        self.idles = self.registers = self.bad = 0
        self.lock = threading.Lock()  # the session's keys and tx, shared by both threads
        self.group = bus_socket(bus, 0.2)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.stop = False
        self.threads = [threading.Thread(target=self._group, daemon=True),
                        threading.Thread(target=self._unicast, daemon=True)]
        for th in self.threads:
            th.start()

    def close(self):
        self.stop = True
        for th in self.threads:
            th.join(5)
        self.group.close()
        self.sock.close()

    def _send(self, frame, to=None):
        """frame to the host (to, else its unicast address), sealed in a
        session: one lock, so a sealed reply's counter only grows on the wire."""
        with self.lock:
            to = to or self.host
            if self.to_host is not None:
                self.tx += 1
                frame = frames.seal(frame, self.tx, self.to_host)
            self.sent_replies.append((frame, to))
            self.sock.sendto(frame, to)

    def _latch_reply(self, in_at, device_id, seq, to=None):
        """The TIMED reply to a service latched at in_at, answer_after_latch_s after it."""
        wait = (in_at / 1e9 + self.answer_after_latch_s) - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self._send(frames.frame(UPDATE, timed_inputs(in_at, digital=self.digital_in), device_id=device_id, seq=seq,
                                flags=REPLY | TIMED, version=2), to)

    def _group(self):
        """The group's frames: SYNC stamps kept, DISCOVERs answered without
        a session, its own due records of CYCLIC frames answered."""
        last_sync = None
        while not self.stop:
            try:
                data, src = self.group.recvfrom(2048)
            except socket.timeout:
                continue
            except OSError:
                return
            sync = read_sync(data)
            if sync is not None:
                last_sync = sync
                continue
            got = parse(data)
            if got and got[0].channel == SYS and got[0].op == DISCOVER:
                if not self.device_id:
                    self._announce(got[0], got[1], src)
                continue
            record = self._own_record(data)
            if record is not None:
                self.served.append((record, last_sync))
                if record.flags & TIMED:
                    self._latch_reply(record.in_at, self.device_id, record.seq)
                else:
                    self._send(reply(UPDATE, inputs(digital=self.digital_in), device_id=self.device_id,
                                     seq=record.seq, version=2))

    def _announce(self, h, nonce, src):
        frame = reply(ANNOUNCE, announce(self.driver.encode(), self.name.encode(), major=self.major, minor=self.minor,
                                         firmware=self.firmware), channel=SYS, seq=h.seq, version=self.version)
        if self.key is not None and len(nonce) == frames.NONCE_LEN:
            self.nonce = nonce
            frame = frames.seal(frame, 0, self.key, nonce)
        self.sock.sendto(frame, src)

    def _own_record(self, data):
        """The CyclicFrame of data when it holds this board's record, due
        (and, keyed, opening under to_board); else None."""
        if self.key is None:
            c = read_cyclic(data)
        else:
            sealed = frames.read_cyclic_sealed(data)
            c = sealed and sealed[0]
        if not c or self.offset is None or not c.first <= self.offset < c.first + len(c.records):
            return None
        tag, flags, _, _ = c.records[self.offset - c.first]
        if tag != self.device_id >> 16 or not flags & frames.CYCLIC_DUE:
            return None
        if self.key is not None and not frames.record_opens(sealed[1], self.offset, *sealed[2][self.offset - c.first],
                                                            self.to_board):
            self.bad += 1
            return None
        return c

    def _unicast(self):
        """The host's requests to its own address: REGISTER, then those of its session."""
        while not self.stop:
            try:
                data, src = self.sock.recvfrom(2048)
            except socket.timeout:
                continue
            except OSError:
                return
            got = parse(data)
            if not got or got[0].channel != DEV:
                continue
            h, body = got
            if h.op == REGISTER:
                self._register(h, data, src)
            elif self._obeys(h, data):
                self.host = src
                self._request(h, body, src)

    def _register(self, h, data, src):
        self.registers += 1
        if self.key is not None:
            to_board, to_host = frames.session_keys(self.key, self.nonce, h.device_id)
            if not frames.opens(data, to_board):
                self.bad += 1
                return
            with self.lock:
                self.to_board, self.to_host, self.tx = to_board, to_host, 0
            self.rx = frames.counter_of(data)
        self.device_id, self.offset, self.host = h.device_id, None, src
        self._send(reply(REGISTER, device_id=h.device_id, seq=h.seq, version=self.version), src)

    def _obeys(self, h, data):
        """Whether a request other than REGISTER is of its session: keyed,
        sealed with to_board above the last counter (else counted in bad,
        as a keyed board cannot tell another session's from a forgery)."""
        if self.key is not None:
            if not frames.opens(data, self.to_board or bytes(16)) or frames.counter_of(data) <= self.rx:
                self.bad += 1
                return False
            self.rx = frames.counter_of(data)
        return bool(self.device_id) and h.device_id == self.device_id

    def _request(self, h, body, src):
        if h.op == SIZE:
            self._send(reply(SIZE, bytes([RECORD_BYTES]), device_id=h.device_id, seq=h.seq, version=self.version), src)
        elif h.op == OFFSET:
            self.offset = struct.unpack(">H", body)[0]
            self._send(reply(OFFSET, body, device_id=h.device_id, seq=h.seq, version=self.version), src)
        elif h.op == UPDATE:
            self._update(h, body, src)
        elif h.op == IDLE:
            self.idles += 1
            self._send(reply(IDLE, inputs(digital=self.digital_in), device_id=h.device_id, seq=h.seq,
                             version=self.version), src)
        elif h.op == WATCHDOG:
            self._send(reply(WATCHDOG, device_id=h.device_id, seq=h.seq, version=self.version), src)
        elif h.op == SHUTDOWN:
            self._send(reply(SHUTDOWN, device_id=h.device_id, seq=h.seq, version=self.version), src)
            self.device_id, self.offset = 0, None
            with self.lock:
                self.to_board = self.to_host = None

    def _update(self, h, body, src):
        """A unicast UPDATE kept and answered; a TIMED one (its instants
        before the outputs) as a TIMED record. A TIMED UPDATE of another
        length is not as PROTOCOL.md says: kept, unanswered (a miss)."""
        if not h.flags & TIMED:
            self.updates.append((h, None, None))
            self._send(reply(UPDATE, inputs(digital=self.digital_in), device_id=h.device_id, seq=h.seq,
                             version=self.version), src)
            return
        out_at, in_at = struct.unpack_from(">QQ", body) if len(body) == TIMED_UPDATE_LEN else (None, None)
        self.updates.append((h, out_at, in_at))
        if in_at is not None:
            self._latch_reply(in_at, h.device_id, h.seq, src)
