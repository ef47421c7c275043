"""make bench, bundle: what deploying a bundle costs (issue 32, "Numbers";
docs/DRIVERS.md, "Bundles"; docs/PERFORMANCE.md, "Bundles: upload to
switched, and the signature check"). One vmacd with the shipped washer on
a washer board, beside the rest of the kitchen (dishwasher, lights) and
OTHERS generic boards, all at their drivers' own rates in the host's
default 1 ms slots (the washer idles every 32 ms, a generic board every
16 ms). Three kinds of upload of the washer, UPLOADS of each, interleaved
in rounds (each round one of each, each round starting with the next
kind, so drift and what the previous upload left behind hit all alike;
one round of warm-up first, not counted):

  text      the baseline, "today's driver-only reload": the washer's Lua
            text alone, the body `vmac reload washer.lua` sent before
            bundles. On a host with bundles a Lua text alone is a bundle
            of that one file without programmes, and the washer needs its
            programmes (vmac.cycles() raises without them), so the text is
            washer.lua with its three programmes written into it in
            vmac.cycles()'s place: the same Lua compiled in the same
            sandbox as before bundles, when the host read the programmes
            from its disk, but for three small files read. A smaller driver
            that needs no programmes (bench.py's reloadprobe) would measure
            another driver; the washer's text without its programmes does
            not load.
  bundle    `vmac bundle` of a copy of scripts/drivers/washer.lua and
            scripts/cycles/washer/, unsigned: what the bundle adds is the
            tar's parse, every member's BLAKE2b-256 hash and a larger
            stored blob
  signed    the same bundles signed with minisign (prehashed ED, a key of
            minisign -G -W), the host given the key in deploy_keys (and
            deploy_require_signature=no, so that the others still go): what
            the signature check adds

With --before-bin DIR (a build/bin of the code before bundles, 1096c82),
a fourth kind on a second host of that build beside the first, with the
same boards, in the same rounds:

  before    washer.lua's text alone to that host, which reads the washer's
            programmes from its disk: the reload as it was. Each round it
            also takes two uploads that are not timed, so that both hosts
            keep as many versions at every round (a deploy's time grows with
            the versions its driver has kept: docs/PERFORMANCE.md)

Each upload is a new version (1.2.0+text.N, +bundle.N, +signed.N), so every
one is stored and switched to; ?probation=0, so each old instance is freed.
The figure is "upload to switched": from before the connection to the
POST's answer, which comes when every machine of the driver has switched
(docs/API.md, "Drivers: hot reload"), median and p95 of each kind, the
medians of its first and last fifth, and the ratios of the medians. Run
through bench.py (--only bundle); the helpers are bench.py's and fieldbus.py's."""

import base64
import http.client
import json
import os
import shutil
import statistics
import subprocess
import tempfile
import time

from bench import ROOT, board_wrapper, with_ctx
from fieldbus import attempt, fresh_status, note_others
from harness import Context

UPLOADS = 100
OTHERS = 20  # generic boards beside the kitchen
KINDS = ("text", "bundle", "signed")
RATIOS = (("bundle", "text"), ("signed", "bundle"), ("text", "before"), ("bundle", "before"))
FIGURES = ("median_ms", "p95_ms", "first_fifth_ms", "last_fifth_ms")  # what a ratio is taken of
# The host's defaults (docs/HOST.md): 1 ms slots, a 4 ms reply deadline.
SETTINGS = {"slice_us": 100, "slices_per_slot": 10, "default_level": 4, "reply_deadline_us": 4000,
            "watchdog_ms": 500, "discovery_period_ms": 200, "realtime": "true"}


def read(path):
    with open(path) as f:
        return f.read()


def washer_source(version):
    """scripts/drivers/washer.lua at `version`."""
    src, old = read(os.path.join(ROOT, "scripts", "drivers", "washer.lua")), 'version = "1.2.0"'
    if old not in src:
        raise AssertionError("scripts/drivers/washer.lua no longer says %s: update bundle_bench.py" % old)
    return src.replace(old, 'version = "%s"' % version, 1)


def inlined_text(version):
    """washer.lua at `version` with its programmes in vmac.cycles()'s place,
    each file's chunk run where the host would run it."""
    cycles = os.path.join(ROOT, "scripts", "cycles", "washer")
    table = "{\n%s}" % "".join("\t[%r] = (function()\n%s\nend)(),\n" % (name[:-4], read(os.path.join(cycles, name)))
                               for name in sorted(os.listdir(cycles)) if name.endswith(".lua"))
    return washer_source(version).replace("vmac.cycles()", table, 1)


def make_bundle(vmac, work, version, key=None):
    """A bundle of the washer at `version` (and its .minisig, signed with
    key): (bundle bytes, signature text or None)."""
    src = os.path.join(work, "src")
    if not os.path.isdir(src):
        shutil.copytree(os.path.join(ROOT, "scripts", "cycles", "washer"), os.path.join(src, "cycles", "washer"))
    with open(os.path.join(src, "washer.lua"), "w") as f:
        f.write(washer_source(version))
    out = os.path.join(work, "washer-%s.vbundle" % version)
    p = subprocess.run([vmac, "bundle", os.path.join(src, "washer.lua"), "-o", out], capture_output=True, text=True,
                       timeout=60)
    if p.returncode != 0:
        raise AssertionError("vmac bundle failed (exit %d): %s" % (p.returncode, p.stderr.strip()[:300]))
    sig = None
    if key:
        p = subprocess.run(["minisign", "-S", "-s", key, "-m", out, "-t",
                            "vmac-bundle name=washer version=%s counter=0" % version], capture_output=True, text=True,
                           timeout=60)
        if p.returncode != 0:
            raise AssertionError("minisign -S failed (exit %d): %s" % (p.returncode, p.stderr.strip()[:300]))
        with open(out + ".minisig", "rb") as f:
            sig = base64.b64encode(f.read()).decode()
    with open(out, "rb") as f:
        return f.read(), sig


def upload(host, token, body, sig):
    """POST /api/drivers/washer?probation=0: (seconds from before the
    connection to the whole answer, None or why it failed)."""
    addr, port = host.http.rsplit(":", 1)
    headers = {"Authorization": "Bearer " + token, "Content-Type": "application/octet-stream"}
    if sig:
        headers["Vmac-Signature"] = sig
    t0 = time.perf_counter()
    conn = http.client.HTTPConnection(addr, int(port), timeout=60)
    try:
        conn.request("POST", "/api/drivers/washer?probation=0", body=body, headers=headers)
        r = conn.getresponse()
        answer = r.read()
    finally:
        conn.close()
    seconds = time.perf_counter() - t0
    try:
        a = json.loads(answer)
    except ValueError:
        a = {}
    if r.status != 200 or a.get("unchanged") or [m["ok"] for m in a.get("machines", ())] != [True] \
            or bool(sig) != bool(a.get("signer")):
        return seconds, "%d %.200s" % (r.status, answer)
    return seconds, None


def start(ctx, settings):
    """A vmacd with the washer on washer-1 beside the kitchen's other two
    and OTHERS generic boards, all running."""
    host = ctx.host(settings=settings)
    for plant, name in (("washer", "washer-1"), ("dishwasher", "dish-1"), ("lights", "lights-1")):
        ctx.board(plant, name, wrapper=board_wrapper())
    ctx.board("generic", "g", count=OTHERS, wrapper=board_wrapper())
    host.wait_running(["washer-1", "dish-1", "lights-1"] + ["g-%d" % i for i in range(1, OTHERS + 1)],
                      timeout_s=60)
    return host


def run(ctx, args, uploads, kinds, before_ctx=None):
    """The uploads of every kind, interleaved; before_ctx: a context of the
    --before-bin build, whose host takes the kind "before" beside."""
    work = tempfile.mkdtemp(prefix="vmac-bench-bundle-")  # bundles and the key: removed at the end
    ctx.cleanups.append(lambda: shutil.rmtree(work, ignore_errors=True))
    vmac = os.path.join(args.bin, "vmac")
    settings = dict(SETTINGS)
    key = None
    if "signed" in kinds:
        key, pub = os.path.join(work, "site.key"), os.path.join(work, "site.pub")
        p = subprocess.run(["minisign", "-G", "-W", "-p", pub, "-s", key], capture_output=True, text=True,
                           timeout=60)
        if p.returncode != 0:
            raise AssertionError("minisign -G failed (exit %d): %s" % (p.returncode, p.stderr.strip()[:300]))
        settings.update(deploy_keys=pub, deploy_require_signature="no")
    if before_ctx:
        kinds = kinds + ("before",)
    print("    making %d uploads of each of %s" % (uploads + 1, ", ".join(kinds)), flush=True)
    bodies = {}  # kind -> [(body, signature)], the warm-up's first
    for kind in kinds:
        bodies[kind] = []
        for i in range(uploads + 1):
            version = "1.2.0+%s.%d" % (kind, i)
            if kind == "text":
                bodies[kind].append((inlined_text(version).encode(), None))
            elif kind == "before":
                bodies[kind].append((washer_source(version).encode(), None))
            else:
                bodies[kind].append(make_bundle(vmac, work, version, key if kind == "signed" else None))

    host = start(ctx, settings)
    hosts = {kind: (host, ctx.token) for kind in kinds}
    if before_ctx:
        hosts["before"] = (start(before_ctx, SETTINGS), before_ctx.token)
    seconds = {kind: [] for kind in kinds}
    failed = {kind: [] for kind in kinds}
    uniq = list(dict.fromkeys(h for h, _ in hosts.values()))
    before = [fresh_status(h) for h in uniq]
    t0 = time.monotonic()
    for rnd in range(uploads + 1):  # round 0: the warm-up
        k = rnd % len(kinds)
        for kind in kinds[k:] + kinds[:k]:
            s, why = upload(*hosts[kind], *bodies[kind][rnd])
            if why:
                failed[kind].append(why)
            elif rnd:
                seconds[kind].append(s)
            for pad in range(len(kinds) - 2 if kind == "before" else 0):  # as many kept versions as the other
                s, why = upload(*hosts[kind], washer_source("1.2.0+pad.%d.%d" % (rnd, pad)).encode(), None)
                if why:
                    failed[kind].append("padding: " + why)
        if rnd and rnd % 20 == 0:
            print("    round %d/%d: %s" % (rnd, uploads, ", ".join(
                "%s %.1f ms" % (kind, seconds[kind][-1] * 1e3) for kind in kinds if seconds[kind])), flush=True)
    elapsed = time.monotonic() - t0
    after = [fresh_status(h) for h in uniq]
    count = lambda name: sum(a["counters"][name] - b["counters"][name] for a, b in zip(after, before))  # noqa: E731
    out = {"uploads": uploads, "others": OTHERS, "kinds": list(kinds), "elapsed_s": elapsed,
           "sizes": {kind: len(bodies[kind][0][0]) for kind in kinds},
           "misses": count("misses"), "misses_host": count("misses_host"), "drops": count("drops"),
           "failed": {kind: len(failed[kind]) for kind in kinds},
           "first_failure": {kind: failed[kind][0] for kind in kinds if failed[kind]},
           "running_at_end": sum(1 for a in after for d in a["devices"] if d["state"] == "running"),
           "washer_version_at_end": (host.device("washer-1", host.status()) or {}).get("driver_version")}
    for kind in kinds:
        xs, fifth = sorted(seconds[kind]), max(1, len(seconds[kind]) // 5)
        if xs:
            out[kind] = {"median_ms": statistics.median(xs) * 1e3, "p95_ms": xs[int(0.95 * (len(xs) - 1))] * 1e3,
                         "min_ms": xs[0] * 1e3, "max_ms": xs[-1] * 1e3,
                         "first_fifth_ms": statistics.median(seconds[kind][:fifth]) * 1e3,
                         "last_fifth_ms": statistics.median(seconds[kind][-fifth:]) * 1e3}
    for num, den in RATIOS:
        if num in out and den in out:
            out["%s/%s" % (num, den)] = {q: out[num][q] / out[den][q] for q in FIGURES}
    return out


def bundle(args, uploads=UPLOADS):
    kinds = KINDS if shutil.which("minisign") else KINDS[:2]
    others, load = note_others(), open("/proc/loadavg").read().split()[:3]

    def beside(ctx):
        if not args.before_bin:
            return run(ctx, args, uploads, kinds)
        before_ctx = Context(args.before_bin, tempfile.mkdtemp(prefix="vmac-bench-bundle-before-", dir=args.logs))
        try:
            return run(ctx, args, uploads, kinds, before_ctx)
        finally:
            before_ctx.cleanup()

    out = attempt(lambda: with_ctx(args, "bundle", beside))
    out.update(others_at_start=others, loadavg_at_start=load, loadavg_at_end=open("/proc/loadavg").read().split()[:3])
    if "signed" not in kinds:
        out["signed_skipped"] = "minisign not installed (Debian package minisign): no signed uploads"
    return out


def report_bundle(r):
    print("\nbundles, upload to switched: the washer on one of %s boards (the kitchen and %s generic), %s "
          "uploads of each kind, interleaved:" % (
              (r.get("others") or OTHERS) + 3, r.get("others") or OTHERS, r.get("uploads") or UPLOADS))
    if "error" in r:
        print("  FAILED: %s" % r["error"])
        return
    names = {"text": "washer.lua text, programmes inlined (baseline)", "bundle": "bundle, unsigned",
             "signed": "bundle, signed (minisign ED)", "before": "washer.lua text, --before-bin's vmacd"}
    for kind in r["kinds"]:
        x = r.get(kind)
        if x:
            print("  %-48s %6d bytes  median %6.2f ms  p95 %6.2f ms  (min %.2f, max %.2f; "
                  "1st, 5th fifth %.2f, %.2f)%s" % (
                      names[kind], r["sizes"][kind], x["median_ms"], x["p95_ms"], x["min_ms"], x["max_ms"],
                      x["first_fifth_ms"], x["last_fifth_ms"],
                      "; %d refused" % r["failed"][kind] if r["failed"][kind] else ""))
    for ratio in ("%s/%s" % pair for pair in RATIOS):
        if ratio in r:
            print("  %-48s median %.3f, p95 %.3f; medians of the first fifth %.3f, of the last %.3f" % (
                ratio, *(r[ratio][q] for q in FIGURES)))
    for kind, why in r["first_failure"].items():
        print("  first refusal of %s: %s" % (kind, why))
    if r.get("signed_skipped"):
        print("  %s" % r["signed_skipped"])
    print("  %.0f s of uploads; %d misses (%d the host's), %d drops; %d running at the end, the washer at %s; "
          "load average %s at the start, %s at the end" % (
              r["elapsed_s"], r["misses"], r["misses_host"], r["drops"], r["running_at_end"],
              r["washer_version_at_end"], "/".join(r["loadavg_at_start"]), "/".join(r["loadavg_at_end"])))
