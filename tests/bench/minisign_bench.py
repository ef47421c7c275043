"""make bench, minisign: what checking a bundle's minisign signature costs
(core/bundle/minisign.c), per MiB of the bundle, next to BLAKE2b-512 alone
over the same bytes in the same run (tests/bench/minisign_verify.c, built
beside bare_loop). Run through bench.py (--only minisign).

  verify_ED  a prehashed signature (minisign -S's default): the hash and
             two Ed25519 checks; its ratio to BLAKE2b is what vmac adds
  verify_Ed  a legacy signature (minisign -S -l): Ed25519 over the file
  fixed      the two Ed25519 checks and the parse, once a bundle (us)

Over a 4 MiB file (VMAC_BUNDLE_MAX, the largest bundle)."""

import json
import os
import subprocess

MIB = 4


def minisign(args):
    """build/bench/minisign_verify --json, or {"error": why}."""
    exe = os.path.join(os.path.dirname(args.bare), "minisign_verify")
    if not os.access(exe, os.X_OK):
        return {"error": "%s not built (make %s)" % (exe, exe)}
    p = subprocess.run([exe, str(MIB), "--json"], capture_output=True, text=True, timeout=300)
    if p.returncode != 0:
        return {"error": "minisign_verify exited %d: %s" % (p.returncode, p.stderr.strip()[:300])}
    return json.loads(p.stdout)


def report_minisign(m):
    print("\nminisign signatures, checked over %s MiB (tests/bench/minisign_verify.c, median of %s runs):" % (
        m.get("mib", MIB), m.get("repeats", "?")))
    if "error" in m:
        print("  FAILED: %s" % m["error"])
        return
    us, q = m["us_per_mib"], m["ratio_to_blake2b"]
    print("  %-44s %8.1f us/MiB" % ("BLAKE2b-512 alone (the baseline)", us["blake2b"]))
    print("  %-44s %8.1f us/MiB  %.3f x BLAKE2b" % ("vmac_minisign_verify, ED (prehashed)", us["verify_ED"],
                                                    q["verify_ED"]))
    print("  %-44s %8.1f us/MiB  %.3f x BLAKE2b" % ("vmac_minisign_verify, Ed (legacy)", us["verify_Ed"],
                                                    q["verify_Ed"]))
    print("  %-44s %8.1f us once a bundle" % ("the two Ed25519 checks and the parse", m["fixed_us"]))
