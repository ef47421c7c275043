#!/usr/bin/env python3
"""Writes the seed corpus of fuzz_bundle.c: bundles of shipped drivers as
`vmac bundle` makes them (the washer with its programmes, the lights with
counter 7), and broken ones a host must refuse, each damaged in one way
(a byte of a member changed, cut short, bytes after its end, bundle.json
not first). Run from the source tree after make, when a driver or the
bundle format changes:
    python3 tests/fuzz/make_bundle_corpus.py build/bin/vmac tests/fuzz/corpus-bundle
"""
import os
import subprocess
import sys
import tempfile


def bundle(vmac, driver, *extra):
    """The bytes vmac bundle makes of scripts/drivers/DRIVER.lua."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, driver + ".vbundle")
        subprocess.run([vmac, "bundle", "scripts/drivers/%s.lua" % driver, "-o", out] + list(extra), check=True,
                       stdout=subprocess.DEVNULL)
        with open(out, "rb") as f:
            return f.read()


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: make_bundle_corpus.py VMAC OUT_DIR")
    vmac, out = sys.argv[1], sys.argv[2]
    washer, lights = bundle(vmac, "washer"), bundle(vmac, "lights", "--counter", "7")
    changed = bytearray(washer)
    changed[len(washer) // 2] ^= 0x20  # in washer.lua's text: its hash no longer matches
    # The members' order swapped: the first header and data block (bundle.json) after the second.
    second = 512 + ((int(lights[124:135], 8) + 511) // 512) * 512
    size = int(lights[second + 124:second + 135], 8)
    end = second + 512 + ((size + 511) // 512) * 512
    swapped = lights[second:end] + lights[:second] + lights[end:]
    seeds = {
        "washer.vbundle": washer,
        "lights.vbundle": lights,
        "washer-changed-byte.vbundle": bytes(changed),
        "washer-cut.vbundle": washer[:3000],
        "lights-bytes-after-end.vbundle": lights + b"more",
        "lights-bundle-json-second.vbundle": swapped,
    }
    os.makedirs(out, exist_ok=True)
    for name, data in seeds.items():
        with open(os.path.join(out, name), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
