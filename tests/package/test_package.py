#!/usr/bin/env python3
"""make test-package: vmac as the Debian package and make install put it,
checked on this machine with the real tools (docs/SERVICE.md, "Testing the
package"). Not part of the integration suite: that runs twice, once under
AddressSanitizer, and a package is built once.

- the package: make deb; dpkg -i; the man page, the user, the state folder,
  the conffile and the enabled unit; systemd-analyze verify on the installed
  unit and on the source's, and its security score as SERVICE.md states it;
  vmacd started as the unit's ExecStart says, as its User with its
  capabilities (setpriv), on a bus and port of the test's own; the kitchen's
  boards (the installed vmac-board) running in /api/status; SIGTERM, exit 0;
  dpkg -i over itself and dpkg -r keeping a changed settings file and the
  store; dpkg --purge: every file the package had gone, /etc/vmac and /var/lib/vmac
  too, the user kept.
- make install DESTDIR=... PREFIX=/usr: exactly the files expected; from
  another folder, the installed vmac test, vmac lint and vmacd finding their
  files under the prefix, a board attaching with its shipped driver; a
  second prefix in the unit and the settings file.

The package part needs root (dpkg, setpriv): without it, it is SKIPPED (a
failure under CI=true, as in tests/integration/run.py). A vmac package
installed before is purged first: run this only where that is fine.

    python3 tests/package/test_package.py --build build [--filter NAME]"""

import argparse
import glob
import grp
import os
import pwd
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import traceback

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "tests", "integration"))
sys.dont_write_bytecode = True

import harness  # noqa: E402

# Each part's bound, not a measure: make deb takes about 30 s of it on two
# idle cores, and 6 to 7 minutes in make test on a slow day of the shared VM
# (353 and 412 s on 2026-11-27, the whole test 479.5 s), built beside the
# ASan build: a bound against a hang, with room for that.
TIME_LIMIT_S = 900
SCORE_MAX = 4.0  # systemd-analyze security's exposure: "OK" or better
PACKAGE_DIRS = ("/usr/share/vmac", "/usr/share/doc/vmac", "/etc/vmac")  # the package's own folders
STATE_DIR = "/var/lib/vmac"
WANTS_LINK = "/etc/systemd/system/multi-user.target.wants/vmacd.service"


def sh(argv, what, timeout_s=300, **kw):
    """Run argv to its end; its stdout. AssertionError with what and the
    tail of its output when it fails."""
    p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL, **kw)
    if p.returncode != 0:
        tail = "\n".join((p.stdout + p.stderr).strip().splitlines()[-15:])
        raise AssertionError("%s failed (%s exited %d):\n%s" % (what, " ".join(argv[:3]), p.returncode, tail))
    return p.stdout


def installed():
    """Whether dpkg knows a vmac package: installed, or removed with its
    settings left (config-files)."""
    p = subprocess.run(["dpkg-query", "-W", "-f=${Status}", "vmac"], capture_output=True, text=True)
    return p.returncode == 0 and not p.stdout.strip().endswith("not-installed")


def unit_settings(path):
    """The unit file's [Service] settings: {key: [values in order]}."""
    settings, section = {}, None
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line.startswith("["):
                section = line
            elif section == "[Service]" and "=" in line and not line.startswith("#"):
                key, value = line.split("=", 1)
                settings.setdefault(key, []).append(value)
    return settings


def capability_names(hex_mask):
    """Capability numbers set in a /proc/PID/status mask, as names."""
    names = {12: "net_admin", 13: "net_raw", 14: "ipc_lock", 21: "sys_admin", 23: "sys_nice", 24: "sys_resource"}
    mask = int(hex_mask, 16)
    return sorted(names.get(i, "cap%d" % i) for i in range(64) if mask >> i & 1)


def proc_status(pid):
    with open("/proc/%d/status" % pid) as f:
        return dict(line.rstrip("\n").split(":\t", 1) for line in f if ":\t" in line)


def fifo_threads(pid):
    """Names of pid's threads scheduled SCHED_FIFO (policy 1 in stat)."""
    found = []
    for task in glob.glob("/proc/%d/task/*" % pid):
        try:
            with open(task + "/stat") as f:
                stat = f.read()
            with open(task + "/comm") as f:
                comm = f.read().strip()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if fields[38] == "1":  # field 41 of stat, counted from 3 after the name
            found.append(comm)
    return found


def security_score(unit):
    out = sh(["systemd-analyze", "security", "--offline=true", "--no-pager", unit], "systemd-analyze security")
    m = re.search(r"Overall exposure level for \S+: ([\d.]+) (\w+)", out)
    assert m, "systemd-analyze security printed no overall exposure:\n%s" % out[-500:]
    return float(m.group(1)), m.group(2)


def verify_unit(unit, what):
    p = subprocess.run(["systemd-analyze", "verify", unit], capture_output=True, text=True, timeout=60)
    said = (p.stdout + p.stderr).strip()
    assert p.returncode == 0 and not said, "systemd-analyze verify of %s (%s): exit %d: %s" % (
        what, unit, p.returncode, said)


def purge(why):
    print("test_package: dpkg --purge vmac (%s)" % why, flush=True)
    sh(["dpkg", "--purge", "vmac"], "dpkg --purge vmac")


def need_tools(*tools):
    missing = [tool for tool in tools if not shutil.which(tool)]
    if missing:
        raise harness.Skip("%s not installed here (make deps installs them)" % ", ".join(missing))


# ---- the Debian package ----

def test_the_debian_package(t, build):
    if os.geteuid() != 0:
        raise harness.Skip("installing and purging a .deb needs root (dpkg -i, setpriv to the user vmac)")
    need_tools("dpkg-buildpackage", "dh", "lintian", "help2man", "setpriv", "runuser", "prlimit", "systemd-analyze",
               "man")
    if installed():
        purge("installed before this test")
    t0 = time.monotonic()
    sh(["make", "--no-print-directory", "-C", ROOT, "deb", "BUILD=" + build], "make deb", timeout_s=TIME_LIMIT_S - 60)
    debs = glob.glob(os.path.join(build, "deb", "vmac_*.deb"))
    assert len(debs) == 1, "make deb made %s, not one vmac_VERSION_ARCH.deb in %s/deb" % (debs, build)
    print("test_package: make deb took %.0f s: %s" % (time.monotonic() - t0, debs[0]), flush=True)
    sh(["dpkg", "-i", debs[0]], "dpkg -i " + debs[0])
    try:
        files = sh(["dpkg", "-L", "vmac"], "dpkg -L vmac").split()
        check_installed(files)
        run_as_the_unit_does(t)
        check_upgrade_and_remove(debs[0])
        purge("the end of the test")
    except BaseException:
        subprocess.run(["dpkg", "--purge", "vmac"], capture_output=True, timeout=120)  # leave the machine clean
        raise
    check_purged(files)


def check_installed(files):
    for path in ("/usr/bin/vmacd", "/usr/bin/vmac", "/usr/bin/vmac-board", "/lib/systemd/system/vmacd.service",
                 "/usr/share/vmac/scripts/drivers/washer.lua", "/usr/share/vmac/stdlib/cycle.lua",
                 "/usr/share/man/man1/vmacd.1.gz", "/etc/vmac/vmacd.conf", "/usr/share/doc/vmac/SERVICE.md"):
        assert path in files, "the package has no %s (dpkg -L vmac)" % path
    where = sh(["man", "-w", "vmacd"], "man -w vmacd").strip()
    assert where == "/usr/share/man/man1/vmacd.1.gz", "man -w vmacd finds %r, not the package's page" % where
    page = sh(["man", "-P", "cat", "vmacd"], "man vmacd", env=dict(os.environ, MANWIDTH="100", LC_ALL="C.UTF-8"))
    assert "SYNOPSIS" in page and "--config" in page and "/etc/vmac/vmacd.conf" in page, \
        "man vmacd has no synopsis, --config or the settings file:\n%s" % page[:600]
    user = pwd.getpwnam("vmac")
    assert user.pw_dir == STATE_DIR and user.pw_shell.endswith("nologin"), \
        "the user vmac has home %s and shell %s" % (user.pw_dir, user.pw_shell)
    st = os.stat(STATE_DIR)
    assert st.st_uid == user.pw_uid and st.st_mode & 0o777 == 0o700, \
        "%s is owned by uid %d with mode %o, not vmac's with 0700" % (STATE_DIR, st.st_uid, st.st_mode & 0o777)
    conffiles = sh(["dpkg-query", "-W", "-f=${Conffiles}", "vmac"], "dpkg-query Conffiles")
    assert "/etc/vmac/vmacd.conf" in conffiles, "/etc/vmac/vmacd.conf is not a conffile: %r" % conffiles
    assert os.path.islink(WANTS_LINK) and os.readlink(WANTS_LINK) == "/lib/systemd/system/vmacd.service", \
        "the service is not enabled: %s does not lead to the unit" % WANTS_LINK
    verify_unit("/lib/systemd/system/vmacd.service", "the installed unit")
    verify_unit(os.path.join(ROOT, "packaging", "vmacd.service"), "the source's unit")
    score, word = security_score("/lib/systemd/system/vmacd.service")
    assert score <= SCORE_MAX, "systemd-analyze security: exposure %.1f %s, more than %.1f" % (score, word, SCORE_MAX)
    with open(os.path.join(ROOT, "docs", "SERVICE.md")) as f:
        said = re.search(r"exposure level for vmacd\.service: ([\d.]+) (\w+)", f.read())
    assert said and (float(said.group(1)), said.group(2)) == (score, word), \
        "docs/SERVICE.md says the exposure is %s, systemd-analyze says %.1f %s" % (
            said and said.group(0), score, word)
    print("test_package: installed; the unit verified, exposure %.1f %s" % (score, word), flush=True)


def limits_wrapper(settings):
    """prlimit's options for the unit's LimitRTPRIO and LimitMEMLOCK, those
    this machine lets root raise (a container without CAP_SYS_RESOURCE
    cannot: said, and the capabilities carry real-time there)."""
    options = []
    for key, option in (("LimitRTPRIO", "--rtprio"), ("LimitMEMLOCK", "--memlock")):
        value = settings.get(key, [None])[-1]
        if value is None:
            continue
        value = "unlimited" if value == "infinity" else value
        arg = "%s=%s:%s" % (option, value, value)
        if subprocess.run(["prlimit", arg, "true"], capture_output=True).returncode == 0:
            options.append(arg)
        else:
            print("test_package: this machine cannot raise %s to %s (no CAP_SYS_RESOURCE); started without it"
                  % (key, value), flush=True)
    return ["prlimit"] + options + ["--"] if options else []


# Runs argv[1:] under the kernel's W^X (prctl PR_SET_MDWE, Linux 6.3 and
# later), kept across exec: what MemoryDenyWriteExecute=yes asks of systemd.
MDWE = ("import ctypes, os, sys\n"
        "if ctypes.CDLL(None, use_errno=True).prctl(65, 1, 0, 0, 0) != 0:\n"
        "    sys.exit('PR_SET_MDWE: ' + os.strerror(ctypes.get_errno()))\n"
        "os.execvp(sys.argv[1], sys.argv[1:])\n")


def mdwe_wrapper(settings):
    """A command that runs the next one with writable code refused, when the
    unit says MemoryDenyWriteExecute=yes and this kernel can (else said)."""
    if settings.get("MemoryDenyWriteExecute", ["no"])[-1] != "yes":
        return []
    wrapper = [sys.executable, "-c", MDWE]
    p = subprocess.run(wrapper + ["true"], capture_output=True, text=True)
    if p.returncode != 0:
        print("test_package: this kernel cannot refuse writable code (%s); started without it" % p.stderr.strip(),
              flush=True)
        return []
    return wrapper


def setpriv_wrapper(settings):
    """setpriv's options for the unit's User, Group, capabilities and
    NoNewPrivileges."""
    user = settings["User"][-1]
    group = settings.get("Group", [user])[-1]
    ambient = [c.lower().replace("cap_", "") for c in " ".join(settings.get("AmbientCapabilities", [])).split()]
    bounding = [c.lower().replace("cap_", "") for c in " ".join(settings.get("CapabilityBoundingSet", [])).split()]
    caps = lambda names: ",".join(["-all"] + ["+" + n for n in names])  # noqa: E731
    argv = ["setpriv", "--reuid=" + user, "--regid=" + group, "--init-groups", "--inh-caps=" + caps(ambient),
            "--ambient-caps=" + caps(ambient), "--bounding-set=" + caps(bounding)]
    if settings.get("NoNewPrivileges", ["no"])[-1] == "yes":
        argv.append("--no-new-privs")
    return argv, sorted(ambient)


def run_as_the_unit_does(t):
    settings = unit_settings("/lib/systemd/system/vmacd.service")
    exec_start = shlex.split(settings["ExecStart"][-1])
    assert exec_start[0] == "/usr/bin/vmacd" and "--state" in exec_start, "ExecStart is %r" % exec_start
    state = exec_start[exec_start.index("--state") + 1]
    assert state == STATE_DIR and settings.get("StateDirectory") == ["vmac"], \
        "the unit keeps its state in %s (StateDirectory %s), not %s" % (state, settings.get("StateDirectory"),
                                                                         STATE_DIR)
    user = settings["User"][-1]
    uid, gid = pwd.getpwnam(user).pw_uid, grp.getgrnam(settings.get("Group", [user])[-1]).gr_gid
    as_user = ["runuser", "-u", user, "--", "/usr/bin/vmac"]

    # The boards' keys and a token, made as the service's user (the store stays theirs).
    keys = os.path.join(t.logdir, "keys")
    os.makedirs(keys)
    os.chown(keys, uid, gid)
    os.chmod(t.logdir, 0o755)
    sh(as_user + ["board", "enroll", "--local", "--state", state, "--key-dir", keys, "--quiet"] +
       harness.KITCHEN_NAMES, "vmac board enroll as " + user)
    t.token = sh(as_user + ["token", "create", "--state", state, "--scope", "read"], "vmac token create").strip()

    t.bindir = "/usr/bin"  # the boards too are the package's
    setpriv, caps = setpriv_wrapper(settings)
    umask = settings.get("UMask", ["0022"])[-1]
    # As systemd starts it: working folder /, the unit's umask, limits, W^X, user and capabilities.
    wrapper = ["env", "-C", "/", "sh", "-c", 'umask %s && exec "$@"' % umask, "sh"] + limits_wrapper(settings) + \
        mdwe_wrapper(settings) + setpriv
    argv = wrapper + exec_start + ["--bus", t.bus, "--http", "127.0.0.1:0"] + \
        ["--set=%s=%s" % kv for kv in harness.TIMING.items()]
    host = harness.Host(t, t._name("vmacd"), argv, t.logdir)
    host.state = state
    t.procs.append(host)
    host.ready()

    status = proc_status(host.pid)
    assert status["Uid"].split()[0] == str(uid), "vmacd runs as uid %s, not %s's %d" % (status["Uid"], user, uid)
    held = capability_names(status["CapEff"])
    assert held == caps, "vmacd holds the capabilities %s, not the unit's %s" % (held, caps)
    assert status["NoNewPrivs"].strip() == "1", "vmacd runs without no_new_privs"

    for plant, name in harness.KITCHEN:
        t.board(plant, name, keyed=False, extra=["--key-dir", keys])
    host.wait_running(harness.KITCHEN_NAMES, timeout_s=60)
    refused = host.find_events("warning", text="real-time setup refused")
    assert not refused, "with the unit's capabilities and limits real-time was refused: %s" % refused[0]["text"]
    fifo = fifo_threads(host.pid)
    assert fifo, "no thread of vmacd runs SCHED_FIFO (realtime = true, the unit's capabilities)"
    for path in glob.glob(state + "/*"):
        assert os.stat(path).st_uid == uid, "%s is not the user %s's" % (path, user)
    print("test_package: vmacd as %s with %s: the kitchen runs, SCHED_FIFO threads %s" % (
        user, ",".join(caps), ",".join(sorted(set(fifo)))), flush=True)

    host.signal(signal.SIGTERM)
    rc = host.wait_exit(30)
    assert rc == 0, "vmacd exited %d after SIGTERM, not 0: %s" % (rc, host.text()[-500:])


def check_upgrade_and_remove(deb):
    """Installing over it (the upgrade path) keeps a settings file changed
    by hand and the state; dpkg -r keeps both too."""
    conf = "/etc/vmac/vmacd.conf"
    with open(conf, "a") as f:
        f.write("-- changed by test_package.py\n")
    store = os.path.join(STATE_DIR, "vmac.db")
    assert os.path.exists(store), "vmacd left no store in %s" % STATE_DIR
    sh(["dpkg", "-i", deb], "dpkg -i over the installed package")
    with open(conf) as f:
        assert "changed by test_package.py" in f.read(), "installing over the package lost the changed %s" % conf
    assert os.path.exists(store), "installing over the package lost the store %s" % store
    sh(["dpkg", "-r", "vmac"], "dpkg -r vmac")
    assert not os.path.exists("/usr/bin/vmacd"), "dpkg -r left /usr/bin/vmacd"
    assert os.path.exists(conf) and os.path.exists(store), "dpkg -r removed %s" % (
        conf if not os.path.exists(conf) else store)
    print("test_package: over itself and removed: the changed settings and the store kept", flush=True)


def check_purged(files):
    assert not installed(), "vmac is still known to dpkg after dpkg --purge"
    left = [f for f in files if (os.path.lexists(f) and not os.path.isdir(f))
            or (os.path.isdir(f) and f.startswith(PACKAGE_DIRS))]
    left += [p for p in (STATE_DIR, "/etc/vmac", WANTS_LINK,
                         "/var/lib/systemd/deb-systemd-helper-enabled/vmacd.service.dsh-also") if os.path.lexists(p)]
    assert not left, "dpkg --purge left %s" % ", ".join(sorted(set(left)))
    pwd.getpwnam("vmac")  # kept on purge (docs/SERVICE.md): KeyError here if not


# ---- make install ----

def expected_install(prefix):
    """Every file make install should put under DESTDIR for PREFIX /usr."""
    data = ["scripts/luacheckrc"]
    for pattern in ("core/vtest/*.lua", "stdlib/*.lua", "scripts/drivers/*.lua", "scripts/cycles/*/*.lua", "tests/drivers/*_test.lua"):
        data += [os.path.relpath(p, ROOT) for p in glob.glob(os.path.join(ROOT, pattern))]
    docs = [os.path.basename(p) for p in glob.glob(os.path.join(ROOT, "docs", "*.md"))] + ["README.md"]
    files = ["bin/vmacd", "bin/vmac", "bin/vmac-board", "lib/systemd/system/vmacd.service", "lib/sysusers.d/vmac.conf",
             "lib/tmpfiles.d/vmac.conf"] + ["share/man/man1/%s.1" % p for p in ("vmacd", "vmac", "vmac-board")]
    files += ["share/vmac/" + f for f in data] + ["share/doc/vmac/" + f for f in docs]
    files += ["share/vmac/types/" + os.path.relpath(p, os.path.join(ROOT, "scripts", "types"))
              for p in glob.glob(os.path.join(ROOT, "scripts", "types", "**", "*.lua"), recursive=True)]
    files += ["share/doc/vmac/grafana/vmac-dashboard.json"]
    return sorted([prefix.lstrip("/") + "/" + f for f in files] + ["etc/vmac/vmacd.conf"])


def installed_files(dest):
    found = []
    for top, _, names in os.walk(dest):
        found += [os.path.relpath(os.path.join(top, n), dest) for n in names]
    return sorted(found)


def test_make_install(t, build):
    need_tools("help2man", "man", "luacheck")
    dest = os.path.join(t.logdir, "dest")
    sh(["make", "--no-print-directory", "-C", ROOT, "install", "BUILD=" + build, "DESTDIR=" + dest, "PREFIX=/usr"],
       "make install DESTDIR=... PREFIX=/usr")
    want, got = expected_install("/usr"), installed_files(dest)
    assert got == want, "make install put these where not expected: %s; and these are missing: %s" % (
        sorted(set(got) - set(want)) or "none", sorted(set(want) - set(got)) or "none")
    assert os.access(os.path.join(dest, "usr/bin/vmacd"), os.X_OK), "the installed vmacd is not executable"
    with open(os.path.join(dest, "usr/lib/systemd/system/vmacd.service")) as f:
        unit = f.read()
    assert "ExecStart=/usr/bin/vmacd --config /etc/vmac/vmacd.conf --state /var/lib/vmac\n" in unit, \
        "the installed unit's ExecStart is not /usr's: %s" % re.findall(r"ExecStart=.*", unit)
    where = sh(["man", "-M", os.path.join(dest, "usr/share/man"), "-w", "vmacd"], "man -w vmacd (installed)").strip()
    assert where.startswith(dest), "man -M finds %r, not the installed page" % where

    # From another working folder: each program finds its files under the prefix, not in this tree.
    share = os.path.join(dest, "usr/share/vmac")
    bindir = os.path.join(dest, "usr/bin")
    rc, out, err = t.run(["env", "-C", t.logdir, os.path.join(bindir, "vmac"), "test"], "vmac-test", 120)
    assert rc == 0, "the installed vmac test failed (exit %d):\n%s%s" % (rc, out[-800:], err[-400:])
    assert os.path.join(share, "tests/drivers/washer_test.lua") in out, \
        "the installed vmac test did not run the installed driver tests:\n%s" % out[:400]
    rc, out, err = t.run(["env", "-C", "/", os.path.join(bindir, "vmac"), "lint",
                          os.path.join(share, "scripts/drivers/lights.lua")], "vmac-lint")
    assert rc == 0, "the installed vmac lint fails the installed lights driver (exit %d): %s%s" % (rc, out, err)

    t.bindir = bindir
    host = t.host(wrapper=["env", "-C", "/"])
    host.wait_line(r"^vmacd: drivers from %s$" % re.escape(os.path.join(share, "scripts/drivers")), 10,
                   stream="stderr", what="drivers from the installed share folder")
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])

    # Another prefix: the unit and the settings file name its paths.
    other = os.path.join(t.logdir, "other")
    sh(["make", "--no-print-directory", "-C", ROOT, "install", "BUILD=" + build, "DESTDIR=" + other,
        "PREFIX=/opt/vmac"], "make install PREFIX=/opt/vmac")
    unit = unit_settings(os.path.join(other, "opt/vmac/lib/systemd/system/vmacd.service"))
    assert unit["ExecStart"] == ["/opt/vmac/bin/vmacd --config /opt/vmac/etc/vmac/vmacd.conf --state /var/lib/vmac"], \
        "PREFIX=/opt/vmac: ExecStart is %s" % unit["ExecStart"]
    with open(os.path.join(other, "opt/vmac/etc/vmac/vmacd.conf")) as f:
        conf = f.read()
    assert "/opt/vmac/share/vmac/scripts/drivers" in conf and "/usr/share" not in conf, \
        "PREFIX=/opt/vmac: the settings file still names /usr's paths"


# ---- the runner ----

TESTS = [("the_debian_package", test_the_debian_package), ("make_install", test_make_install)]


def on_alarm(signum, frame):
    raise AssertionError("the test did not finish within %d s" % TIME_LIMIT_S)


def main():
    ap = argparse.ArgumentParser(description="Test vmac's Debian package and make install on this machine.")
    ap.add_argument("--build", default="build", help="the build folder (make's BUILD)")
    ap.add_argument("--filter", default="", help="run only parts whose name contains this text")
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    ci = os.environ.get("CI") == "true"
    signal.signal(signal.SIGALRM, on_alarm)
    failed = 0
    for name, fn in TESTS:
        if args.filter not in name:
            continue
        logdir = tempfile.mkdtemp(prefix="vmac-pkg-%s-" % name)
        t = harness.Context(os.path.join(build, "bin"), logdir)
        outcome, reason, t0 = "pass", "", time.monotonic()
        signal.alarm(TIME_LIMIT_S)
        try:
            fn(t, build)
        except harness.Skip as e:
            outcome, reason = ("fail", "could not run, and CI=true makes that a failure: %s" % e) if ci else (
                "skip", str(e))
        except Exception as e:  # noqa: BLE001: every failure is reported
            outcome = "fail"
            reason = str(e) if isinstance(e, AssertionError) else "".join(
                traceback.format_exception_only(type(e), e)).strip()
        finally:
            signal.alarm(0)
            t.cleanup()
        took = time.monotonic() - t0
        if outcome == "pass":
            shutil.rmtree(logdir, ignore_errors=True)
            print("PASS package %s (%.1f s)" % (name, took), flush=True)
        elif outcome == "skip":
            shutil.rmtree(logdir, ignore_errors=True)
            print("#" * 80 + "\nSKIP package %s: %s\n" % (name, reason) + "#" * 80, flush=True)
            if os.environ.get("VMAC_SKIP_FILE"):
                with open(os.environ["VMAC_SKIP_FILE"], "a") as f:
                    f.write("package test %s: %s\n" % (name, reason))
        else:
            failed += 1
            print("FAIL package %s (%.1f s): %s [logs: %s]" % (name, took, reason, logdir), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
