#!/usr/bin/env python3
"""The Cortex-M3 firmware's cost per authenticated frame (docs/PERFORMANCE.md,
"Authenticated frames on the Cortex-M3"): runs tests/bench/mcu_auth.c's
image in QEMU's lm3s6965evb with one instruction per translation block
(-singlestep) and the execution trace on (-d exec,nochain), so that each
trace line is one instruction the CPU executed; counts the instructions
between the bench's marks, and turns each into cycles with the Cortex-M3's
timing table (ARM DDI 0337, "Instruction timings"), as a lower and an upper
bound where the table gives a range.

    make mcu-auth-bench          (or: mcu_auth.py build/firmware/mcu-auth-bench.elf)

QEMU's model of the LM3S6965 has no cycle counter (no DWT) and its SysTick
follows the host's clock, not the instructions; the count is exact, the
cycles a model: the LM3S6965 runs its flash with no wait state at 50 MHz,
so the table's timings hold with P (a pipeline refill after a taken branch)
from 1 to 3. Bounds: lower, P = 1, a load or store after another load or
store pipelined (1 cycle), IT folded, long multiplies and divides at their
fastest; upper, P = 3, every load and store 2 cycles, IT 1 cycle, long
multiplies 5, divides 12."""

import os
import re
import subprocess
import sys
import tempfile

RUNS = 32  # mcu_auth.c
PHASES = (("UPDATE (unicast), unkeyed", 0), ("CYCLIC, record due, unkeyed", 1),
          ("UPDATE (unicast), keyed", 2), ("CYCLIC, record due, keyed", 3))
MHZ = 50
TRACE_RE = re.compile(r"^Trace \d+: 0x[0-9a-f]+ \[[0-9a-f]+/([0-9a-f]+)/")
INSN_RE = re.compile(r"^\s*([0-9a-f]+):\s+((?:[0-9a-f]{4}\s?){1,2})\s+(\S+)\s*(.*)$")


def disassembly(elf):
    """{address: (mnemonic, operands, size)} of every instruction."""
    out = subprocess.run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf], capture_output=True,
                         text=True, check=True).stdout
    raw = subprocess.run(["arm-none-eabi-objdump", "-d", elf], capture_output=True, text=True, check=True).stdout
    sizes = {}
    for line in raw.splitlines():
        m = INSN_RE.match(line)
        if m:
            sizes[int(m.group(1), 16)] = len(m.group(2).replace(" ", "")) // 2
    insns = {}
    for line in out.splitlines():
        m = re.match(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$", line)
        if m and int(m.group(1), 16) in sizes:
            insns[int(m.group(1), 16)] = (m.group(2), m.group(3), sizes[int(m.group(1), 16)])
    return insns


def symbol(elf, name):
    out = subprocess.run(["arm-none-eabi-nm", elf], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2] == name:
            return int(parts[0], 16) & ~1
    sys.exit("mcu_auth.py: no symbol %s in %s" % (name, elf))


def registers(operands):
    """How many registers a register list {r4, r5-r7, lr} names."""
    inside = operands[operands.index("{") + 1:operands.index("}")]
    n = 0
    for part in inside.split(","):
        part = part.strip()
        if "-" in part:
            a, b = part.split("-")
            n += int(b.strip()[1:]) - int(a.strip()[1:]) + 1
        elif part:
            n += 1
    return n


BRANCHES = re.compile(r"^(b|bl|bx|blx|cbz|cbnz)(eq|ne|cs|hs|cc|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le|al)?(\.[nw])?$")


def cycles(mnemonic, operands, taken, after_memory):
    """(lower, upper) cycles of one executed instruction."""
    base = mnemonic.split(".")[0]
    if BRANCHES.match(mnemonic):
        return (2, 4) if taken else (1, 1)
    if base in ("push", "pop", "stmia", "stmdb", "ldmia", "ldmdb", "stm", "ldm"):
        n = 1 + registers(operands)
        return (n + 1, n + 3) if "pc" in operands and base in ("pop", "ldm", "ldmia") else (n, n)
    if base.startswith(("ldrd", "strd")):
        return (3, 3)
    if base.startswith(("ldr", "str")):
        if "pc" in operands.split(",")[0]:
            return (3, 5)
        return (1 if after_memory else 2, 2)
    if base in ("umull", "smull", "umlal", "smlal"):
        return (3, 5)
    if base in ("udiv", "sdiv"):
        return (2, 12)
    if base in ("mla", "mls"):
        return (2, 2)
    if base.startswith("it"):
        return (0, 1)
    return (1, 1)


def main():
    elf = sys.argv[1] if len(sys.argv) > 1 else "build/firmware/mcu-auth-bench.elf"
    insns = disassembly(elf)
    mark = symbol(elf, "bench_mark")
    with tempfile.TemporaryDirectory() as tmp:
        trace = os.path.join(tmp, "trace.log")
        p = subprocess.run(["qemu-system-arm", "-M", "lm3s6965evb", "-display", "none", "-monitor", "none",
                            "-serial", "none", "-nic", "none", "-semihosting-config", "enable=on,target=native",
                            "-singlestep", "-d", "exec,nochain", "-D", trace, "-kernel", elf],
                           timeout=600, capture_output=True)
        if p.returncode != 0:
            sys.exit("mcu_auth.py: the bench failed in QEMU (exit %d: not every frame answered?)" % p.returncode)
        pcs = []
        with open(trace) as f:
            for line in f:
                m = TRACE_RE.match(line)
                if m:
                    pcs.append(int(m.group(1), 16))
    hits = [i for i, pc in enumerate(pcs) if pc == mark]
    if len(hits) != 2 * len(PHASES) + 1:
        sys.exit("mcu_auth.py: %d marks in the trace, expected %d" % (len(hits), 2 * len(PHASES) + 1))
    unknown = sum(1 for pc in pcs[hits[0]:hits[-1]] if pc not in insns)
    if unknown:
        sys.exit("mcu_auth.py: %d executed instructions not in the disassembly" % unknown)
    print("%-30s %14s %20s %12s" % ("frame", "instructions", "cycles (low..high)", "us @ 50 MHz"))
    results = []
    for name, k in PHASES:
        start, end = hits[2 * k], hits[2 * k + 1]
        n, low, high, after_memory = 0, 0, 0, False
        for i in range(start, end):
            pc = pcs[i]
            mnemonic, operands, size = insns.get(pc, ("?", "", 2))
            taken = pcs[i + 1] != pc + size
            lo, hi = cycles(mnemonic, operands, taken, after_memory)
            after_memory = mnemonic.split(".")[0].startswith(("ldr", "str")) and not mnemonic.startswith(
                ("ldrd", "strd"))
            n, low, high = n + 1, low + lo, high + hi
        results.append((n / RUNS, low / RUNS, high / RUNS))
        print("%-30s %14.0f %9.0f..%-9.0f %5.1f..%-5.1f" % (name, n / RUNS, low / RUNS, high / RUNS,
                                                             low / RUNS / MHZ, high / RUNS / MHZ))
    for name, plain, keyed in (("UPDATE", results[0], results[2]), ("CYCLIC", results[1], results[3])):
        print("%-30s %+14.0f %+9.0f..%-+9.0f" % ("keyed - unkeyed, " + name, keyed[0] - plain[0],
                                                 keyed[1] - plain[1], keyed[2] - plain[2]))
    print("(per frame, mean of %d; the bench's loop, a few instructions a frame, included)" % RUNS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
