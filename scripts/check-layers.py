#!/usr/bin/env python3
"""The layers, enforced (docs/ARCHITECTURE.md): a module may use the modules
after it in the Makefile's MODULES, never one before it. Reads every
module's archive with nm (which symbols each object needs, which module
defines them) and every include of core/ and firmware/ ("../X/..."), and
exits 1 naming each arrow that runs upward. The Makefile runs it before it
links anything."""
import argparse
import os
import re
import subprocess
import sys


def module_dir(m):
    return "firmware" if m == "board" else f"core/{m}"


def nm(path, which):
    """(object, symbol) of each line of `nm -g -A which path`."""
    out = subprocess.run(["nm", "-g", "-A", which, path], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        # ARCHIVE:OBJECT:ADDRESS TYPE NAME (ADDRESS blank for undefined)
        where, _, symbol = line.rpartition(" ")
        obj = where.split(":")[1] if where.count(":") >= 2 else "?"
        yield obj, symbol


def archive_symbols(path):
    """(defined, needed): defined symbol -> object; object -> needed symbols."""
    defined = {sym: obj for obj, sym in nm(path, "--defined-only")}
    needed = {}
    for obj, sym in nm(path, "--undefined-only"):
        needed.setdefault(obj, set()).add(sym)
    return defined, needed


def link_arrows(lib, modules):
    rank = {m: i for i, m in enumerate(modules)}
    owner = {}
    needs = {}
    for m in modules:
        path = os.path.join(lib, f"lib{m}.a")
        if not os.path.exists(path):
            sys.exit(f"check-layers: {path} is missing (build the archives first)")
        defined, needed = archive_symbols(path)
        for sym, obj in defined.items():
            owner[sym] = (m, obj)
        needs[m] = needed
    bad = []
    for m, objs in needs.items():
        for obj, syms in objs.items():
            for sym in sorted(syms):
                if sym in owner and rank[owner[sym][0]] < rank[m]:
                    bad.append(f"{m}/{obj} calls {sym} of {owner[sym][0]}/{owner[sym][1]}")
    return bad


INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

# Files of a program folder that any module may include and link: leaves
# that use nothing of the project. The simulator's oscillator (POSIX, double,
# libm) runs vmac-board's board counters and vmac test's (core/vtest/clocks.c).
SHARED_LEAVES = {"firmware/posix/oscillator.h"}


def include_arrows(modules):
    # The programs sit above every module.
    programs = ["core/vmacd", "core/cli", "firmware/posix", "firmware/mcu"]
    rank = {m: i for i, m in enumerate(programs + modules)}
    by_dir = {module_dir(m): m for m in modules}
    by_dir.update({p: p for p in programs})
    bad = []
    for m in modules:
        d = module_dir(m)
        for root, dirs, files in os.walk(d):
            if m == "board":  # firmware/ holds programs too (posix/, mcu/)
                dirs[:] = [x for x in dirs if x == "plants"]
            for f in files:
                if not f.endswith((".c", ".h")):
                    continue
                path = os.path.join(root, f)
                with open(path, encoding="utf-8") as src:
                    text = src.read()
                for inc in INCLUDE.findall(text):
                    target = os.path.normpath(os.path.join(root, inc))
                    if target in SHARED_LEAVES:
                        continue
                    tdir = os.path.dirname(target)
                    while tdir and tdir not in by_dir:
                        tdir = os.path.dirname(tdir)
                    t = by_dir.get(tdir)
                    if t is not None and rank[t] < rank[m]:
                        bad.append(f"{path} includes {inc} ({t} is above {m})")
    return bad


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--lib", required=True, help="folder of the libMODULE.a archives")
    ap.add_argument("--modules", required=True, help="the modules, top to bottom (the Makefile's MODULES)")
    args = ap.parse_args()
    modules = args.modules.split()
    bad = link_arrows(args.lib, modules) + include_arrows(modules)
    if bad:
        print("check-layers: a lower layer uses a higher one (MODULES: " + " ".join(modules) + "):", file=sys.stderr)
        for b in bad:
            print("  " + b, file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
