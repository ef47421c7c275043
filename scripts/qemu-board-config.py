#!/usr/bin/env python3
"""Set the identity of a copy of the LM3S6965 board firmware: board name,
driver, plant, MAC, ids and key, in the identity block the firmware reads at
start (flash address 0x100, 128 bytes, magic "VMCF"; docs/BOARD.md,
"Firmware on a microcontroller", and firmware/mcu/lm3s6965/config.h). So
several boards run side by side in QEMU from one build, each its own name
and MAC.

    qemu-board-config.py IMAGE -o OUT [--name N] [--plant KIND] [--driver D]
                         [--mac MAC] [--major N] [--minor N] [--protocol V]
                         [--quiet | --verbose] [--key-file FILE | --no-key]
    qemu-board-config.py IMAGE --show

IMAGE is the .elf (the block is its section .vmac_config) or the .bin (the
block at offset 0x100). What is not given keeps its value, but --name
without --mac sets the MAC back to the one derived from the name
(02:h1:h2:h3:00:01, the FNV-1a hash of the name, as vmac-board), and
--plant without --driver announces the plant's own driver. Every field is
checked as the firmware checks it; a refused value changes nothing (exit 2).
Prints the identity written (or shown), one 'key=value' per line with
--show; of the key only whether there is one (keyed yes or no).

--key-file FILE makes the board keyed (docs/PROTOCOL.md, "Authenticated
frames"): FILE holds its 16-byte key as `vmac board enroll --out FILE`
writes it, 32 hex digits and at most one newline. The copy then holds the
key: it is written readable by its owner only. --no-key removes a key."""

import argparse
import os
import re
import struct
import sys

MAGIC = b"VMCF"
# Version 2 holds the key in bytes version 1 reserved: a version-1 block
# (firmware built before keys) is read and written as version 1, unkeyed.
VERSIONS = (1, 2)
SIZE = 128
ADDR = 0x100
LAYOUT = struct.Struct("<4sHH32s32s16s6sBBII16s8s")  # config.h, struct vmac_mcu_config
MAJOR_SET, QUIET, KEYED = 0x01, 0x02, 0x04
KEY_FILE = re.compile(rb"\A[0-9A-Fa-f]{32}\n?\Z")
PLANTS = ("washer", "dishwasher", "lights", "generic")
NAME = re.compile(r"^[A-Za-z0-9_-]{1,31}$")
assert LAYOUT.size == SIZE


def fail(text):
    print("qemu-board-config: " + text, file=sys.stderr)
    sys.exit(2)


def fnv1a(text):
    h = 2166136261
    for b in text.encode():
        h = ((h ^ b) * 16777619) & 0xFFFFFFFF
    return h


def mac_from_name(name):
    h = fnv1a(name)
    return bytes([0x02, (h >> 16) & 0xFF, (h >> 8) & 0xFF, h & 0xFF, 0, 1])


def mac_text(mac):
    return ":".join("%02x" % b for b in mac)


def block_offset(image, path):
    """Where the block is in the file: the ELF section .vmac_config, or 0x100
    of a raw image."""
    if image[:4] != b"\x7fELF":
        return ADDR
    if image[4] != 1 or image[5] != 1:
        fail("%s: not a 32-bit little-endian ELF file" % path)
    shoff, = struct.unpack_from("<I", image, 0x20)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", image, 0x2E)

    def section(i):
        return struct.unpack_from("<IIIIII", image, shoff + i * shentsize)

    strtab = section(shstrndx)[4]
    for i in range(shnum):
        name_off, _, _, addr, offset, size = section(i)
        end = image.index(b"\0", strtab + name_off)
        if image[strtab + name_off:end] == b".vmac_config":
            if addr != ADDR or size != SIZE:
                fail("%s: section .vmac_config at 0x%x, %d bytes; expected 0x%x, %d" % (path, addr, size, ADDR, SIZE))
            return offset
    fail("%s: no section .vmac_config (not a vmac-board-lm3s6965 image?)" % path)


def text_field(raw):
    return raw.split(b"\0", 1)[0].decode("ascii", "replace")


def read_block(image, offset, path):
    if len(image) < offset + SIZE:
        fail("%s: too short to hold the identity block at 0x%x" % (path, offset))
    f = list(LAYOUT.unpack_from(image, offset))
    if f[0] != MAGIC or f[1] not in VERSIONS or f[2] != SIZE:
        fail("%s: no identity block of version 1 or 2 at 0x%x (magic %r, version %d, size %d)" % (
            path, offset, f[0], f[1], f[2]))
    flags = f[8] if f[1] >= 2 else f[8] & ~KEYED
    return {
        "version": f[1], "board": text_field(f[3]), "driver": text_field(f[4]), "plant": text_field(f[5]),
        "mac": f[6], "protocol": f[7] or 2, "flags": flags, "major": f[9], "minor": f[10],
        "key": f[11] if flags & KEYED else bytes(16),
    }


def read_key(path):
    """The 16-byte key of a key file (vmac board enroll --out FILE)."""
    try:
        with open(path, "rb") as f:
            text = f.read(64)
            mode = os.fstat(f.fileno()).st_mode
    except OSError as e:
        fail("key file %s: %s" % (path, e.strerror))
    if not KEY_FILE.match(text):
        fail("key file %s: not a key (want 32 hex digits, the 16-byte key, then at most one newline)" % path)
    if mode & 0o077:
        print("qemu-board-config: warning: key file %s has mode %04o: group or others may read or change "
              "the board's key (chmod 600 %s)" % (path, mode & 0o7777, path), file=sys.stderr)
    return bytes.fromhex(text.decode().strip())


def check(b):
    for key in ("board", "driver"):
        if not NAME.match(b[key]):
            fail("%s name %r: 1..31 of A-Z a-z 0-9 _ -" % (key, b[key]))
    if b["plant"] not in PLANTS:
        fail("plant %r: one of %s" % (b["plant"], ", ".join(PLANTS)))
    if b["protocol"] not in (1, 2):
        fail("protocol %r: 1 or 2" % b["protocol"])
    if b["mac"] != bytes(6) and b["mac"][0] & 1:
        fail("MAC %s is a group address; a board needs a unicast one" % mac_text(b["mac"]))
    for key in ("major", "minor"):
        if not 0 <= b[key] <= 0xFFFFFFFF:
            fail("%s %d: 0..4294967295" % (key, b[key]))


def describe(b):
    """What the firmware will run with: (key, value) pairs."""
    mac = b["mac"] if b["mac"] != bytes(6) else mac_from_name(b["board"])
    major = b["major"] if b["flags"] & MAJOR_SET else fnv1a(b["board"])
    return [("board", b["board"]), ("driver", b["driver"]), ("plant", b["plant"]), ("mac", mac_text(mac)),
            ("major", "%d" % major), ("minor", "%d" % b["minor"]), ("protocol", "%d" % b["protocol"]),
            ("quiet", "yes" if b["flags"] & QUIET else "no"), ("keyed", "yes" if b["flags"] & KEYED else "no")]


def parse_mac(text):
    m = re.match(r"^([0-9A-Fa-f]{2})(:[0-9A-Fa-f]{2}){5}$", text)
    if not m:
        fail("--mac wants six hex bytes like 02:00:00:00:00:01, got %r" % text)
    mac = bytes(int(x, 16) for x in text.split(":"))
    if mac == bytes(6):
        fail("--mac 00:00:00:00:00:00 is no station address")
    return mac


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("image", help="build/firmware/vmac-board-lm3s6965.elf or .bin")
    ap.add_argument("-o", "--out", help="the patched copy to write")
    ap.add_argument("--show", action="store_true", help="print the block and write nothing")
    ap.add_argument("--name", help="board name (default: as in IMAGE)")
    ap.add_argument("--plant", choices=PLANTS)
    ap.add_argument("--driver", help="driver announced (default: the plant's)")
    ap.add_argument("--mac", help="station address, e.g. 02:00:00:00:00:07 (default: derived from the name)")
    ap.add_argument("--major", type=lambda v: int(v, 0), help="major id (default: the FNV-1a hash of the name)")
    ap.add_argument("--minor", type=lambda v: int(v, 0))
    ap.add_argument("--protocol", type=int, choices=(1, 2))
    quiet = ap.add_mutually_exclusive_group()
    quiet.add_argument("--quiet", action="store_true", help="log only state changes and safety events")
    quiet.add_argument("--verbose", action="store_true", help="log every output change too (as built)")
    keyed = ap.add_mutually_exclusive_group()
    keyed.add_argument("--key-file", help="keyed: the board's key, 32 hex digits (vmac board enroll --out FILE)")
    keyed.add_argument("--no-key", action="store_true", help="unkeyed: remove the key (as built)")
    args = ap.parse_args()
    if not args.show and not args.out:
        fail("say where the patched copy goes (-o OUT), or --show")

    try:
        with open(args.image, "rb") as f:
            image = bytearray(f.read())
    except OSError as e:
        fail("%s: %s" % (args.image, e.strerror))
    offset = block_offset(image, args.image)
    b = read_block(image, offset, args.image)
    if args.show:
        for key, value in describe(b):
            print("%s=%s" % (key, value))
        return 0

    if args.name is not None:
        b["board"] = args.name
        b["mac"] = bytes(6)
    if args.plant is not None:
        b["plant"] = args.plant
        b["driver"] = args.plant
    if args.driver is not None:
        b["driver"] = args.driver
    if args.mac is not None:
        b["mac"] = parse_mac(args.mac)
    if args.major is not None:
        b["major"] = args.major
        b["flags"] |= MAJOR_SET
    if args.minor is not None:
        b["minor"] = args.minor
    if args.protocol is not None:
        b["protocol"] = args.protocol
    if args.quiet:
        b["flags"] |= QUIET
    if args.verbose:
        b["flags"] &= ~QUIET
    if args.key_file is not None:
        if b["version"] < 2:
            fail("%s: identity block of version 1: its firmware predates keys (build it again)" % args.image)
        b["key"] = read_key(args.key_file)
        b["flags"] |= KEYED
    if args.no_key:
        b["key"] = bytes(16)
        b["flags"] &= ~KEYED
    check(b)
    LAYOUT.pack_into(image, offset, MAGIC, b["version"], SIZE, b["board"].encode(), b["driver"].encode(),
                     b["plant"].encode(), b["mac"], b["protocol"], b["flags"], b["major"], b["minor"], b["key"],
                     bytes(8))
    try:
        # A copy that holds a key is as secret as the key file.
        fd = os.open(args.out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if b["flags"] & KEYED else 0o666)
        with os.fdopen(fd, "wb") as f:
            if b["flags"] & KEYED:
                os.fchmod(f.fileno(), 0o600)
            f.write(image)
    except OSError as e:
        fail("%s: %s" % (args.out, e.strerror))
    print("qemu-board-config: %s: %s" % (args.out, ", ".join("%s %s" % kv for kv in describe(b))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
