"""The host's SYNC frames as they leave it, for the two-step SYNC's test
(test_sync.py) and its measurement (tests/bench/sync_stamps.py): a
listener on the bus (UDP: the discovery group; raw Ethernet: an AF_PACKET
socket on the host's own interface, which sees what the host sends), and
the frames read back as streams (the plain SYNC, each sealed chunk), each
frame's prev_tx_ns set against the host_ns of the frame before it in its
stream (docs/PROTOCOL.md, "SYNC"; docs/TIME.md, "The two-step SYNC")."""

import socket
import struct
import threading

import frames
from harness import LOADED, bus_socket

SYNC_OP = 0x05
ETH_P_ALL = 0x0003
PLAIN_LEN = frames.HDR_LEN + 16  # header, host_ns, prev_tx_ns
SEALED_HEAD = frames.SYNC_SEALED_HEAD


class Capture:
    """Every SYNC frame the host sends from now on (every system frame it
    sends, with everything=True), in a thread of its own: on UDP the
    group's (bus "GROUP:PORT"), on raw Ethernet (bus "eth:IFACE", IFACE in
    this namespace) the interface's outgoing ones."""

    def __init__(self, bus, everything=False):
        self.got = []
        self.stop = False
        self.everything = everything
        self.heard = threading.Condition()
        if bus.startswith("eth:"):
            # ETH_P_ALL: only such a socket is given the frames sent out
            self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
            self.sock.bind((bus[4:], ETH_P_ALL))
            self.sock.settimeout(0.1)
            self.eth = True
        else:
            self.sock = bus_socket(bus, 0.1)
            self.eth = False
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        while not self.stop:
            try:
                data = self.sock.recv(2048)
            except socket.timeout:
                continue
            if self.eth:
                if data[12:14] != struct.pack(">H", frames.ETH_P_VMAC):
                    continue
                data = data[14:]
            if len(data) < frames.HDR_LEN or data[10] != frames.SYS or data[3] & frames.REPLY:
                continue
            if data[11] == SYNC_OP:
                data = data[:SEALED_HEAD + 8 * data[12] if data[3] & frames.AUTH else PLAIN_LEN]
            elif not self.everything:
                continue
            with self.heard:
                self.got.append(data)
                if len(self.got) % 100 == 0:  # a waiter's look costs a pass over them all
                    self.heard.notify_all()

    def wait(self, predicate, timeout_s, what):
        """Until predicate(frames heard so far) holds, looked at every 100
        frames, or AssertionError naming what after timeout_s (times the
        harness's LOADED, as its own waits)."""
        with self.heard:
            if not self.heard.wait_for(lambda: predicate(self.got), timeout_s * LOADED):
                raise AssertionError("%s not heard within %d s (%d frames heard)" % (what, timeout_s * LOADED,
                                                                                   len(self.got)))

    def syncs(self, sealed, got=None):
        """The sealed SYNC frames heard (or of got), or the plain ones."""
        return [d for d in (self.got if got is None else got)
                if d[11] == SYNC_OP and bool(d[3] & frames.AUTH) == sealed]

    def close(self):
        self.stop = True
        self.thread.join(5)
        self.sock.close()


def streams(got):
    """{stream: [(seq, host_ns, prev_tx_ns), ...]} in the order sent:
    stream "plain", or the sealed chunk's first offset."""
    out = {}
    for f in got:
        seq = struct.unpack_from(">H", f, 4)[0]
        host_ns, prev_tx_ns = struct.unpack_from(">QQ", f, frames.HDR_LEN)
        key = struct.unpack_from(">H", f, SEALED_HEAD - 2)[0] if f[3] & frames.AUTH else "plain"
        out.setdefault(key, []).append((seq, host_ns, prev_tx_ns))
    return out


def lateness(frames_of_stream):
    """(named, followers, deltas): of the frames that follow their stream's
    previous one at once (seq + 1), how many name a transmit time, and for
    each that does, prev_tx_ns less the previous frame's host_ns (ns): what
    the one-step host_ns missed."""
    named, followers, deltas = 0, 0, []
    for (seq0, host0, _), (seq1, _, prev1) in zip(frames_of_stream, frames_of_stream[1:]):
        if (seq0 + 1) & 0xFFFF != seq1:
            continue
        followers += 1
        if prev1:
            named += 1
            deltas.append(prev1 - host0)
    return named, followers, deltas


def percentile(values, p):
    s = sorted(values)
    return s[min(len(s) - 1, int(len(s) * p / 100))] if s else None
