"""The store loses nothing committed (docs/HOST.md "The store"): a process
writing to it is killed with SIGKILL at random points, 200 times; each time
the database opens, passes SQLite's integrity check and holds every write
that was acknowledged. And a full disk is an error on the request, not a
crash: the host keeps running and nothing changes. A store removed under
a running host is said, once, and written no more."""

import glob
import os
import random
import re
import shutil
import subprocess
import time

from harness import KITCHEN_NAMES, fill_state, plain_pass_too, post, sanitized, small_state, undisturbed

RUNS = 200
# Under the sanitizers (make test-asan) the writer and the check run the
# same store code on every kill: 20 kills look for memory errors on it,
# and the plain build's 200 judge what survives a kill.
SANITIZED_RUNS = 20


def store_crash(t):
    return os.path.normpath(os.path.join(t.bindir, "..", "tests", "store_crash"))


@plain_pass_too("all RUNS kills (the sanitizer pass kills SANITIZED_RUNS times)")
def test_kill_9_during_writes_loses_nothing_acknowledged(t):
    exe = store_crash(t)
    assert os.access(exe, os.X_OK), "%s is missing (make %s)" % (exe, exe)
    runs = SANITIZED_RUNS if sanitized(exe) else RUNS
    seed = random.SystemRandom().randrange(1 << 30)
    rnd = random.Random(seed)
    acked_total = 0
    for run in range(runs):
        state = os.path.join(t.logdir, "kill-%03d" % run)
        p = subprocess.Popen([exe, "write", state], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        first = p.stdout.readline()  # the store is open and one write is acknowledged
        assert first.strip() == b"1", "run %d: the writer did not start: %r %r" % (run, first, p.stderr.read())
        time.sleep(rnd.uniform(0, 0.05))  # the random point of the kill, not a synchronisation
        p.kill()
        rest = p.stdout.read()
        p.wait()
        lines = (first + rest).split(b"\n")
        acked = int(lines[-2])  # the last complete line: its write had returned
        acked_total += acked
        c = subprocess.run([exe, "check", state, str(acked)], capture_output=True, text=True, timeout=60)
        assert c.returncode == 0, "run %d of %d (seed %d), killed after %d acknowledged writes: %s" % (
            run + 1, runs, seed, acked, c.stderr.strip())
        shutil.rmtree(state)
    assert acked_total > runs, "the writer hardly wrote anything (%d writes in %d runs)" % (acked_total, runs)


def test_a_full_disk_is_an_error_not_a_crash(t):
    """The state folder on a small tmpfs of its own (a mount namespace:
    needs root, as CI has), filled up while the host runs. Skipped where
    that cannot be had (a failure with CI=true: run.py)."""
    token = t.make_token("deploy")  # in the test's own state folder: copied below
    state, wrapper = small_state(t)
    t.enroll(["washer-1"])  # into the store the host's copies
    host = t.host(wrapper=wrapper, extra=("--state", state))
    t.board("washer", "washer-1", keyed=False, extra=("--key-dir", t.keys))
    version = host.device("washer-1", host.wait_running(["washer-1"]))["driver_version"]
    fill_state(host, state)  # from inside the host's mount namespace
    # A bundle of the washer and its programmes, its driver padded to 700 KiB.
    scripts = os.path.join(os.path.dirname(__file__), "..", "..", "scripts")
    mine = os.path.join(t.logdir, "big")
    shutil.copytree(os.path.join(scripts, "cycles", "washer"), os.path.join(mine, "cycles", "washer"))
    with open(os.path.join(scripts, "drivers", "washer.lua")) as f:
        src = re.sub(r'version = "[^"]+"', 'version = "9.0.0"', f.read(), count=1)
    with open(os.path.join(mine, "washer.lua"), "w") as f:
        f.write(("-- " + "x" * 76 + "\n") * 9000 + src)
    made = subprocess.run([t.path("vmac"), "bundle", os.path.join(mine, "washer.lua"), "-o",
                           os.path.join(t.logdir, "big.vbundle")], capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, "vmac bundle of the big washer: %s%s" % (made.stdout, made.stderr)
    with open(os.path.join(t.logdir, "big.vbundle"), "rb") as f:
        big = f.read()
    code, body = post(host, "/api/drivers/washer?probation=0", token, big, "application/octet-stream")
    assert code == 507 and "store" in body and "full" in body, \
        "uploading to a full disk: HTTP %d %s" % (code, body[:300])
    code, body = post(host, "/api/devices/washer-1/input", token, b'{"name": "program", "value": "quick", '
                      b'"persist": true}')
    # 200 when the write fits in space the database's files already hold.
    assert code in (200, 507), "persisting to a full disk: HTTP %d %s" % (code, body)
    s = host.status()
    d = host.device("washer-1", s)
    assert d["state"] == "running" and d["driver_version"] == version, \
        "the full disk changed the running machine: %s %s" % (d["state"], d["driver_version"])
    assert host.alive(), "vmacd died on a full disk"


def test_a_store_removed_under_the_host_is_said_not_lost_silently(t):
    """The database deleted (or replaced) under a running host: its writes
    would go to a file no one can open again. The host notices on its next
    write, says so once, and writes no more; the machines run on."""
    host = t.host()
    t.kitchen(host)
    db = os.path.join(t.logdir, "vmac.db")
    assert os.path.exists(db), "no store at %s" % db
    t.enroll(["lights-2"])  # while the store is there: the host has the key
    for f in glob.glob(db + "*"):
        os.unlink(f)
    # Something to store: a board attaching is an event.
    t.board("lights", "lights-2", keyed=False, extra=("--key-dir", t.keys))
    # Events and checkpoints each say it, in whichever order they next write.
    warning = host.wait_event("warning", text="events are not being stored", timeout_s=30,
                              invariant=undisturbed(KITCHEN_NAMES))
    assert "removed or replaced" in warning["text"] and db in warning["text"], (
        "the warning does not say why writes stopped and which file: %r" % warning["text"])
    host.wait_running(["lights-2"])
    assert not os.path.exists(db), "the host made a new, empty store at %s" % db
    # Each kind of write (events, checkpoints) says it once, not at every try.
    for what in ("events are not being stored", "checkpoints are not being saved"):
        said = [e for e in host.find_events("warning", text="removed or replaced") if e["text"].startswith(what)]
        assert len(said) <= 1, "'%s' was said %d times" % (what, len(said))
