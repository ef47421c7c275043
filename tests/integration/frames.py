"""vmac frames for the Python tests, laid out in one place (docs/PROTOCOL.md,
"Frame layout"; the C tests' twin is tests/unit/frames.h).

frame() and reply() write any header and data, in range or not; the data
builders (inputs, outputs, register, u16, announce) write a payload field by
field. A test that needs a frame the host must refuse builds it right and
then corrupts it, with patch() or a slice, so the corruption is what the
reader sees. parse() reads a header back, ethernet() wraps a frame for raw
Ethernet.

Authenticated frames (docs/PROTOCOL.md, "Authenticated frames"): seal()
and opens() with the MAC of libsodium's SipHash-2-4 through PyNaCl
(python3-nacl), the other side's reading of the specification, not ours;
session_keys() the keys of a session.

Used by test_malformed.py, test_eth.py, test_trust.py, fake_board.py (the
tests' own board on the UDP bus) and eth_peer.py here,
and by tests/soak/soak.py (which puts this folder on sys.path, as for
harness)."""

import collections
import struct
import sys

MAGIC = b"VM"
HEADER = struct.Struct(">2sBBHIBBB")  # magic, version, flags, seq, device_id, channel, op, len
HDR_LEN = HEADER.size  # 13
REPLY = 0x01  # flags bit 0: set on every frame a board sends
AUTH = 0x02  # flags bit 1: an authenticated frame (a counter and a MAC follow its data)
TRAILER = struct.Struct(">Q8s")  # counter (u64), MAC
NONCE_LEN = 8
TIMED = 0x04  # flags bit 2: a CYCLIC carrying host instants, and a board's answer to one

SYS, DEV = 0xFF, 0x00  # the system channel and the device channel
DISCOVER, CYCLIC, SYNC, ANNOUNCE = 0x01, 0x04, 0x05, 0x10  # ops of the system channel
REGISTER, SHUTDOWN, UPDATE, ERROR, IDLE, SLEEP, WATCHDOG, SIZE, OFFSET, OFFSET_GET = range(10)  # device channel

ETH_P_VMAC = 0x88B5  # the EtherType of raw Ethernet (protocol version 2)
ETH_MIN_PAYLOAD = 46  # shorter payloads are padded with zeros

# Each header field's offset and size in bytes, for patch().
FIELDS = {"magic": (0, 2), "version": (2, 1), "flags": (3, 1), "seq": (4, 2), "device_id": (6, 4),
          "channel": (10, 1), "op": (11, 1), "len": (12, 1)}

Header = collections.namedtuple("Header", "version flags seq device_id channel op len")


def frame(op, data=b"", channel=DEV, device_id=0, seq=0, flags=0, version=1):
    """A frame: the 13-byte header with len = len(data), then data. Flags 0
    make it the host's request; nothing is checked."""
    return HEADER.pack(MAGIC, version, flags, seq, device_id, channel, op, len(data)) + data


def reply(op, data=b"", **fields):
    """A board's frame: frame() with the REPLY flag."""
    return frame(op, data, flags=REPLY, **fields)


def patch(whole, field, value):
    """whole with one header field overwritten (value: bytes of the field's
    size, or an int written big-endian in it), every other byte as it was."""
    offset, size = FIELDS[field]
    if isinstance(value, int):
        value = value.to_bytes(size, "big")
    assert len(value) == size, "%s is %d bytes, not %d" % (field, size, len(value))
    return whole[:offset] + value + whole[offset + size:]


def outputs(digital=0, pwm=0):
    """UPDATE request data (3 bytes): digital outputs, pwm in per-mille."""
    return struct.pack(">Bh", digital, pwm)


def inputs(digital=0, analog=(0, 0), encoder=0, applied_digital=0, pwm=0):
    """UPDATE and IDLE reply data (12 bytes): the inputs, then the outputs
    the board drives now."""
    return struct.pack(">BHHiBh", digital, analog[0], analog[1], encoder, applied_digital, pwm)


def register(major, minor, watchdog_ms):
    """REGISTER request data (10 bytes)."""
    return struct.pack(">IIH", major, minor, watchdog_ms)


def u16(value):
    """The data of SLEEP (seconds), WATCHDOG (ms) and OFFSET (the offset)."""
    return struct.pack(">H", value)


def announce(driver, board, major=1, minor=0, firmware=(1, 0), caps=(8, 7, 2, 1, 1)):
    """ANNOUNCE data: driver and board are bytes (any, so a test can send a
    name the host must refuse); caps are digital inputs, digital outputs,
    analog inputs, PWM outputs, encoders."""
    return (bytes([len(driver)]) + driver + struct.pack(">II", major, minor) + bytes([len(board)]) + board +
            bytes(firmware) + bytes(caps))


def sync(host_ns, seq=0):
    """A SYNC frame (version 2): the host's CLOCK_MONOTONIC in ns."""
    return frame(SYNC, struct.pack(">Q", host_ns), channel=SYS, seq=seq, version=2)


def cyclic(records, first=0, seq=0, out_at=None, in_at=None):
    """A CYCLIC frame (version 2) of records for offsets first, first + 1..:
    each (tag, flags, digital, pwm), tag 0 an empty record. With out_at
    (and in_at, default out_at): TIMED, carrying those host instants (ns)
    (docs/PROTOCOL.md, "Time-triggered I/O")."""
    timed = out_at is not None
    head = HEADER.pack(MAGIC, 2, TIMED if timed else 0, seq, 0, SYS, CYCLIC, len(records)) + u16(first)
    if timed:
        head += struct.pack(">QQ", out_at, out_at if in_at is None else in_at)
    return head + b"".join(struct.pack(">HBBh", *r) for r in records)


CYCLIC_DUE = 0x01  # a record's flag: answer this frame
CLOCK_ARRIVAL = 0x80  # a TIMED answer's clock byte: acted on arrival, not at the instants
CLOCK_STATES = ("unsynced", "locking", "locked", "holdover", "lost")
Latch = collections.namedtuple("Latch", "digital analog0 analog1 encoder applied_digital applied_pwm latched_at clock "
                                        "bound_ns offset_ns")
LATCH = struct.Struct(">BHHiBhQBIq")  # the 33 data bytes of a TIMED answer


def latch(data):
    """The 33 data bytes of a TIMED answer (an UPDATE reply, flags REPLY |
    TIMED) as a Latch: the inputs, applied, latched_at, the clock byte (its
    state in bits 0-2, CLOCK_ARRIVAL), bound_ns and offset_ns."""
    return Latch(*LATCH.unpack(data))


def parse(payload):
    """(Header, data) of a vmac frame, data being the len bytes after the
    header (a CYCLIC's len counts records: read those from payload); None
    when payload is shorter than a header or has another magic."""
    if len(payload) < HDR_LEN:
        return None
    magic, *fields = HEADER.unpack_from(payload)
    if magic != MAGIC:
        return None
    header = Header(*fields)
    return header, payload[HDR_LEN:HDR_LEN + header.len]


def ethernet(dst, src, payload, pad=False):
    """An Ethernet frame of EtherType 0x88B5 from MAC src to MAC dst (6 bytes
    each) carrying payload; pad: zeros up to the 46-byte minimum payload, as
    a board's network interface sends it."""
    if pad:
        payload += bytes(max(0, ETH_MIN_PAYLOAD - len(payload)))
    return dst + src + struct.pack(">H", ETH_P_VMAC) + payload


def _nacl_hash():
    """nacl.hash of the python3 running the tests, else Debian's
    (python3-nacl: its extension is built for the stable ABI, so it loads
    in a python3 of another origin too). None without either."""
    try:
        import nacl.hash
        return nacl.hash
    except ImportError:
        pass
    if "/usr/lib/python3/dist-packages" not in sys.path:
        sys.path.append("/usr/lib/python3/dist-packages")
    try:
        import nacl.hash
        return nacl.hash
    except ImportError:
        return None


NACL = _nacl_hash()


def siphash(key, message, wide=False):
    """libsodium's SipHash-2-4 of message under the 16-byte key: 8 bytes, or
    16 (SipHash-2-4-128) when wide."""
    import nacl.encoding
    f = NACL.siphashx24 if wide else NACL.siphash24
    return f(message, key=key, encoder=nacl.encoding.RawEncoder)


def seal(whole, counter, key, extra=b""):
    """whole (a frame) authenticated: the AUTH flag set, counter and the MAC
    of every byte so far and extra (an ANNOUNCE's: the DISCOVER's nonce)
    appended."""
    flagged = whole[:3] + bytes([whole[3] | AUTH]) + whole[4:] + struct.pack(">Q", counter)
    return flagged + siphash(key, flagged + extra)


def opens(whole, key, extra=b""):
    """Whether the authenticated frame whole verifies under key."""
    return (len(whole) >= HDR_LEN + TRAILER.size and whole[3] & AUTH and
            siphash(key, whole[:-8] + extra) == whole[-8:])


# A sealed SYNC's bytes before its MACs: header, host_ns, prev_tx_ns, counter
# (u64), first (docs/PROTOCOL.md, "The sealed SYNC").
SYNC_SEALED_HEAD = HDR_LEN + 8 + 8 + 8 + 2
# A sealed CYCLIC's bytes before its records when not TIMED: header, first,
# counter (u64).
CYCLIC_SEALED_HEAD = HDR_LEN + 2 + 8


def counter_of(whole):
    """The counter of an authenticated frame (not CYCLIC)."""
    return TRAILER.unpack(whole[-TRAILER.size:])[0]


def session_keys(key, nonce, device_id):
    """(to_board, to_host): the keys of the session of device_id that began
    with the DISCOVER carrying nonce."""
    tail = nonce + struct.pack(">I", device_id)
    return siphash(key, b"vmac-to-board" + tail, True), siphash(key, b"vmac-to-host" + tail, True)



# Time-triggered I/O (docs/PROTOCOL.md, "Time-triggered I/O"): the host's
# side reads TIMED CYCLIC frames and answers with TIMED replies. Kept in
# functions of their own (the boards' side may add its own beside them).
TIMED = 0x04  # flags bit 2
SYNC = 0x05  # op of the system channel
CyclicFrame = collections.namedtuple("CyclicFrame", "flags seq first out_at in_at records")


def read_cyclic(payload):
    """A plain or TIMED, unsealed CYCLIC frame as CyclicFrame (records: a
    list of (tag, flags, digital, pwm), record i for offset first + i;
    out_at and in_at None when not TIMED); None for anything else."""
    got = parse(payload)
    if not got or got[0].channel != SYS or got[0].op != CYCLIC or got[0].flags & AUTH:
        return None
    h = got[0]
    first, = struct.unpack_from(">H", payload, HDR_LEN)
    at = HDR_LEN + 2
    out_at = in_at = None
    if h.flags & TIMED:
        out_at, in_at = struct.unpack_from(">QQ", payload, at)
        at += 16
    records = [struct.unpack_from(">HBBh", payload, at + 6 * i) for i in range(h.len)]
    return CyclicFrame(h.flags, h.seq, first, out_at, in_at, records)


def read_sync(payload):
    """The host_ns of a SYNC frame, or None."""
    got = parse(payload)
    if not got or got[0].channel != SYS or got[0].op != SYNC or len(payload) < HDR_LEN + 8:
        return None
    return struct.unpack_from(">Q", payload, HDR_LEN)[0]


def timed_inputs(latched_at, state=2, arrival=False, bound_ns=1500, offset_ns=3500000000, **fields):
    """A TIMED UPDATE reply's data (33 bytes): inputs(**fields), then the
    latch time (host ns), the clock byte, the bound and the offset."""
    return inputs(**fields) + struct.pack(">QBIq", latched_at, state | (0x80 if arrival else 0), bound_ns,
                                          offset_ns)


def read_cyclic_sealed(payload):
    """A sealed (AUTH) CYCLIC frame, plain or TIMED: (CyclicFrame whose
    records are (tag, flags, digital, pwm), the bytes every record's MAC
    covers first, [(record's 6 bytes, its MAC)]); None for anything else."""
    got = parse(payload)
    if not got or got[0].channel != SYS or got[0].op != CYCLIC or not got[0].flags & AUTH:
        return None
    h = got[0]
    first, = struct.unpack_from(">H", payload, HDR_LEN)
    at = CYCLIC_SEALED_HEAD
    out_at = in_at = None
    if h.flags & TIMED:
        out_at, in_at = struct.unpack_from(">QQ", payload, at)
        at += 16
    raw = [(payload[at + 14 * i:at + 14 * i + 6], payload[at + 14 * i + 6:at + 14 * i + 14]) for i in range(h.len)]
    records = [struct.unpack(">HBBh", r) for r, _ in raw]
    return CyclicFrame(h.flags, h.seq, first, out_at, in_at, records), payload[:at], raw


def record_opens(head, offset, record, mac, key):
    """Whether a sealed CYCLIC record's MAC verifies under key (the
    session's to_board): over the frame's head, the offset and the record."""
    return siphash(key, head + struct.pack(">H", offset) + record) == mac
