#!/usr/bin/env python3
"""Writes the seed corpus of fuzz_values.c: programs of operations on its
fixed driver, spelled with the names below (the byte format is in
fuzz_values.c, LLVMFuzzerTestOneInput). Run after changing that format:
    python3 tests/fuzz/make_values_corpus.py tests/fuzz/corpus-values
"""
import os
import struct
import sys

NAMES = ["lamp", "pump", "motor", "door", "level", "count", "temp", "flow", "aux", "probe", "far", "far_in",
         "speed", "label", "ok", "t1", "t2", "t3", "fill_l", "mode", "on", "gain", "step", "start", "stop",
         "out", "vars", "params", "state", "boards", "tick_raise", "input_raise", "why", "got", "time", "", "name"]
OP = {"set": 0, "tick": 1, "input": 2, "params": 3, "restore": 4, "add_board": 5, "level": 6, "persists": 7}
TABLE = {"out": 0, "vars": 1, "params": 2, "state": 3, "dev": 4}
MINOR = {0: 0, 7: 1, 0xFFFFFFFF: 2, 1: 3}
TABLE_VALUE, FUNCTION_VALUE = object(), object()  # a new table {}, a C function


def name(n):
    if n in NAMES:
        return bytes([NAMES.index(n)])
    raw = n.encode()
    return bytes([255, len(raw)]) + raw  # raw bytes: length % 40


def number(x):
    return bytes([255]) + struct.pack("<d", x)  # 8 raw bytes


def host(v):
    """A host value (struct vmac_value)."""
    if v is None:
        return bytes([0])
    if isinstance(v, bool):
        return bytes([2, int(v)])
    if isinstance(v, (int, float)):
        return bytes([1]) + number(float(v))
    raw = v.encode()
    return bytes([3, 255, len(raw)]) + raw


def lua(v):
    """A Lua value (push_lua_value)."""
    if v is None:
        return bytes([0])
    if v is True:
        return bytes([1])
    if v is False:
        return bytes([2])
    if isinstance(v, (int, float)):
        return bytes([3]) + number(float(v))
    if v == TABLE_VALUE:
        return bytes([7])
    if v == FUNCTION_VALUE:
        return bytes([9])
    raw = v.encode()
    return bytes([5, len(raw)]) + raw


def program(primary, *ops):
    out = bytes([MINOR[primary]])
    for op in ops:
        kind, args = op[0], op[1:]
        out += bytes([OP[kind]])
        if kind == "set":
            out += bytes([TABLE[args[0]]]) + name(args[1]) + (args[2] if isinstance(args[2], bytes) else lua(args[2]))
        elif kind == "tick":
            dt, boards = args[0], args[1:]
            out += bytes([dt])
            for digital, a0, a1, enc in boards:
                out += bytes([digital, a0, a1, enc >> 8 & 255, enc & 255])
        elif kind in ("input", "restore"):
            out += name(args[0]) + host(args[1])
        elif kind == "add_board":
            out += bytes([MINOR[args[0]]])
        elif kind == "level":
            out += bytes([args[0]])
        elif kind == "persists":
            out += name(args[0])
    return out


TICK = ("tick", 16, (0xFF, 10, 20, 0x1234), (0x08, 0, 255, 0), (0, 0, 0, 0))
SEEDS = {
    "machine": program(
        0, ("add_board", 7), ("add_board", 0xFFFFFFFF),
        ("set", "out", "lamp", True), ("set", "out", "motor", 1000), ("set", "out", "aux", True),
        ("set", "out", "far", False), ("set", "vars", "speed", 600), ("set", "vars", "label", "a"),
        ("set", "vars", "t1", 1.5), ("set", "vars", "ok", True), TICK, ("params",),
        ("input", "speed", 10), ("input", "fill_l", 7), ("input", "mode", "quick"), ("input", "start", None),
        ("set", "state", "ok", True), ("input", "t3", True), ("input", "stop", None), ("input", "label", "c"),
        ("restore", "fill_l", 3), ("restore", "mode", "eco"), ("restore", "on", True), ("restore", "gain", 2),
        ("persists", "fill_l"), ("persists", "gain"), ("level", 3), TICK, ("params",)),
    "bad_digital": program(0, ("set", "out", "lamp", 1), TICK),
    "bad_pwm": program(7, ("set", "out", "motor", 1000.5), TICK, ("set", "out", "motor", float("inf")), TICK),
    "bad_var": program(0, ("set", "vars", "speed", TABLE_VALUE), TICK),
    "long_var": program(0, ("set", "vars", "label", "x" * 90), TICK, ("set", "vars", "t3", "y" * 63), TICK),
    "replaced": program(0, ("set", "dev", "out", 5), TICK),
    "vars_replaced": program(0, ("set", "dev", "vars", False), TICK),
    "params_replaced": program(0, ("set", "dev", "params", TABLE_VALUE), ("params",), ("input", "fill_l", 1),
                               ("restore", "fill_l", 2), ("params",)),
    "param_values": program(0, ("set", "params", "fill_l", FUNCTION_VALUE), ("set", "params", "mode", "z" * 80),
                            ("set", "params", "on", TABLE_VALUE), ("params",)),
    "input_raise": program(0, ("set", "state", "input_raise", TABLE_VALUE), ("input", "start", None)),
    "input_raise_string": program(0, ("set", "state", "input_raise", "no"), ("input", "speed", 3)),
    "tick_raise": program(0, ("set", "state", "tick_raise", 42), TICK),
    "refusals": program(0, ("set", "state", "ok", False), ("set", "state", "why", 12), ("input", "start", "eco"),
                        ("set", "state", "why", TABLE_VALUE), ("input", "stop", None), ("input", "ok", 1),
                        ("input", "nothing", 1), ("input", "speed", 5000), ("input", "label", "z"),
                        ("input", "step", 4), ("input", "step", True), ("input", "fill_l", "ten"),
                        ("input", "on", 1), ("input", "gain", None), ("input", "lamp", True)),
    "restores": program(0, ("restore", "gain", 1), ("restore", "fill_l", 11), ("restore", "fill_l", "x"),
                        ("restore", "mode", "nope"), ("restore", "on", 0), ("restore", "nothing", 1)),
    "boards": program(0xFFFFFFFF, ("add_board", 0), ("add_board", 0), ("add_board", 7), ("add_board", 1),
                      ("set", "out", "far", True), ("set", "out", "lamp", True), ("set", "out", "aux", True),
                      ("tick", 1, (1, 2, 3, 4), (5, 6, 7, 8), (9, 10, 11, 12), (13, 14, 15, 16))),
}

if __name__ == "__main__":
    folder = sys.argv[1] if len(sys.argv) > 1 else "tests/fuzz/corpus-values"
    os.makedirs(folder, exist_ok=True)
    for seed, data in SEEDS.items():
        with open(os.path.join(folder, seed), "wb") as f:
            f.write(data)
