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
import sys

from frames import ANNOUNCE, DEV, DISCOVER, ETH_P_VMAC, OFFSET, REGISTER, REPLY, SIZE, SYS, announce, ethernet, parse, \
    reply, u16


def mac_bytes(text):
    return bytes(int(x, 16) for x in text.split(":"))


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
        eth = s.recv(2048)
        dst, src, parsed = eth[0:6], eth[6:12], parse(eth[14:])
        if parsed is None or dst not in (me, b"\xff" * 6) or parsed[0].flags & REPLY:
            continue
        h, data = parsed
        if h.channel == SYS and h.op == DISCOVER:
            answer = reply(ANNOUNCE, announce(args.driver.encode(), args.name.encode(), args.major, 0), channel=SYS,
                           seq=h.seq, version=2)
        elif h.channel == DEV and dst == me and h.op == REGISTER:
            answer = reply(REGISTER, b"", device_id=h.device_id, seq=h.seq, version=h.version)
        elif h.channel == DEV and dst == me and h.op == SIZE:
            size = 8 if args.mode == "size" else 6
            answer = reply(SIZE, bytes([size]), device_id=h.device_id, seq=h.seq, version=h.version)
        elif h.channel == DEV and dst == me and h.op == OFFSET:
            given = int.from_bytes(data, "big")
            answer = reply(OFFSET, u16((given + 1) & 0xFFFF), device_id=h.device_id, seq=h.seq, version=h.version)
            print("eth_peer: given offset %d, confirmed %d" % (given, (given + 1) & 0xFFFF), flush=True)
        else:
            continue
        s.send(ethernet(src, me, answer, pad=True))
        print("eth_peer: answered op 0x%02x" % h.op, flush=True)


if __name__ == "__main__":
    sys.exit(main())
