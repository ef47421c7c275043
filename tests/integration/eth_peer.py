"""A misbehaving board on raw Ethernet, for tests/integration/test_eth.py.

Runs inside the boards' network namespace (ip netns exec NS python3 eth_peer.py
...) with an AF_PACKET socket on IFACE, and does one of:

  offset   announce as a version-2 board, register, answer SIZE with 6 and
           OFFSET with the offset it was given plus one (a board that
           confirms the wrong offset)
  size     the same, but answer SIZE with 8 (a board wanting other records)
  junk     send the frames given as hex on the command line (--frame HEX,
           the whole Ethernet frame from the destination MAC on) and exit

It prints one line per thing it did, so the test can wait for them.
"""

import argparse
import socket
import struct
import sys

ETH_P_VMAC = 0x88B5
SYS, DEV = 0xFF, 0x00
DISCOVER, ANNOUNCE = 0x01, 0x10
REGISTER, SIZE, OFFSET = 0x00, 0x07, 0x08
REPLY = 0x01


def mac_bytes(text):
    return bytes(int(x, 16) for x in text.split(":"))


def vmac(op, data=b"", channel=DEV, device_id=0, seq=0, flags=REPLY, version=2):
    return b"VM" + struct.pack(">BBHIBBB", version, flags, seq, device_id, channel, op, len(data)) + data


def announce(driver, board, major, minor):
    return (bytes([len(driver)]) + driver + struct.pack(">II", major, minor) + bytes([len(board)]) + board +
            bytes([1, 0, 8, 7, 2, 1, 1]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["offset", "size", "junk"])
    ap.add_argument("--iface", required=True)
    ap.add_argument("--mac", default="02:00:00:00:ee:01", help="this peer's source MAC")
    ap.add_argument("--driver", default="generic")
    ap.add_argument("--name", default="peer-1")
    ap.add_argument("--major", type=int, default=4242)
    ap.add_argument("--frame", action="append", default=[], help="junk: a whole Ethernet frame as hex")
    args = ap.parse_args()

    s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_VMAC))
    s.bind((args.iface, ETH_P_VMAC))
    me = mac_bytes(args.mac)
    print("eth_peer: %s on %s as %s" % (args.mode, args.iface, args.mac), flush=True)

    if args.mode == "junk":
        for h in args.frame:
            s.send(bytes.fromhex(h))
        print("eth_peer: sent %d frames" % len(args.frame), flush=True)
        return 0

    while True:
        frame = s.recv(2048)
        if len(frame) < 14 + 13:
            continue
        dst, src, payload = frame[0:6], frame[6:12], frame[14:]
        if dst not in (me, b"\xff" * 6) or payload[0:2] != b"VM" or payload[3] & REPLY:
            continue
        version, _flags, seq, device_id, channel, op, n = struct.unpack(">BBHIBBB", payload[2:13])
        data = payload[13:13 + n]
        if channel == SYS and op == DISCOVER:
            answer = vmac(ANNOUNCE, announce(args.driver.encode(), args.name.encode(), args.major, 0), SYS, 0, seq)
        elif channel == DEV and dst == me and op == REGISTER:
            answer = vmac(REGISTER, b"", DEV, device_id, seq, version=version)
        elif channel == DEV and dst == me and op == SIZE:
            answer = vmac(SIZE, bytes([8 if args.mode == "size" else 6]), DEV, device_id, seq, version=version)
        elif channel == DEV and dst == me and op == OFFSET:
            given = struct.unpack(">H", data)[0]
            answer = vmac(OFFSET, struct.pack(">H", (given + 1) & 0xFFFF), DEV, device_id, seq, version=version)
            print("eth_peer: given offset %d, confirmed %d" % (given, (given + 1) & 0xFFFF), flush=True)
        else:
            continue
        answer += b"\0" * max(0, 46 - len(answer))
        s.send(src + me + struct.pack(">H", ETH_P_VMAC) + answer)
        print("eth_peer: answered op 0x%02x" % op, flush=True)


if __name__ == "__main__":
    sys.exit(main())
