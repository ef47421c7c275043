#!/usr/bin/env python3
"""The Debian package under a real systemd (docs/SERVICE.md, "Tested in a
booted Debian"): a Debian 12 root made with mmdebstrap (kept in --root,
made again when the package's dependencies change) is booted with
systemd-nspawn, systemd as its PID 1, on a network of its own. In it:

  dpkg -i the package       the service enabled and started; active means
                            vmacd sent READY=1 (Type=notify)
  systemd-analyze security  the unit's exposure, at most --max-exposure
  a board, enrolled         it attaches and runs (vmac status, as a user would)
  the bus thread stopped    (ptrace, that thread only) systemd's watchdog
                            kills vmacd and starts it again; the board runs
                            again on the new one
  systemctl stop            vmacd stops cleanly, its boards told to go safe
  dpkg --purge              nothing the package put there is left

    tests/package/boot.py --deb build/deb/vmac_VERSION_ARCH.deb --root build/boot-root

With --prepare --bins "BIN ..." instead of --deb it only makes the root,
for the libraries those programs link (dpkg-shlibdeps: the package's own
shlibs:Depends, as the same programs built by make deb link the same
ones), so that make test-package makes it while make deb builds.

Prints one line per step and exits 0, or 1 naming what broke. Without root,
mmdebstrap or systemd-nspawn it says SKIPPED (appended to $VMAC_SKIP_FILE)
and exits 0, or 1 with CI=true."""

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
sys.dont_write_bytecode = True
from park import Parked  # noqa: E402
from threads import thread_of  # noqa: E402

BASE = ["systemd", "systemd-sysv", "dbus"]
MIRROR = "http://deb.debian.org/debian"


class Failed(Exception):
    pass


def step(text):
    print("boot: " + text, flush=True)


def skip(reason):
    print("#" * 72 + "\nboot: SKIPPED: " + reason + "\n" + "#" * 72, flush=True)
    if os.environ.get("VMAC_SKIP_FILE"):
        with open(os.environ["VMAC_SKIP_FILE"], "a") as f:
            f.write("tests/package/boot.py: %s\n" % reason)
    sys.exit(1 if os.environ.get("CI") == "true" else 0)


def names_of(field):
    """Package names of a Depends field (first of alternatives, no versions)."""
    names = set()
    for part in re.split(r"[,\n]", field):
        first = part.split("|")[0].strip()
        name = re.sub(r"\s*\(.*\)", "", first).strip()
        if name:
            names.add(name)
    return names


def depends(deb):
    """The package's dependencies by name (first of alternatives, no versions)."""
    out = subprocess.run(["dpkg-deb", "-f", deb, "Depends", "Pre-Depends"], capture_output=True, text=True,
                         check=True).stdout
    return sorted(names_of(re.sub(r"^(Pre-)?Depends:", "", out, flags=re.M)))


def depends_of_bins(bins):
    """The package names programs bins need, by dpkg-shlibdeps (run where
    debian/control is)."""
    src = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
    p = subprocess.run(["dpkg-shlibdeps", "-O"] + [os.path.abspath(b) for b in bins], cwd=src,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise Failed("dpkg-shlibdeps failed (exit %d): %s" % (p.returncode, p.stderr[-800:]))
    return sorted(names_of(p.stdout.strip().partition("=")[2]))


def make_root(root, packages):
    include = sorted(set(BASE) | set(packages))
    marker = os.path.join(root, ".vmac-boot-root")
    want = "\n".join(include) + "\n"
    if os.path.exists(marker) and open(marker).read() == want:
        step("the Debian root in %s is ready" % root)
        return
    shutil.rmtree(root, ignore_errors=True)
    step("mmdebstrap bookworm into %s with %s (under a minute)" % (root, ", ".join(include)))
    p = subprocess.run(["mmdebstrap", "--variant=minbase", "--include=" + ",".join(include), "bookworm", root,
                        MIRROR], capture_output=True, text=True, timeout=900)
    if p.returncode != 0:
        raise Failed("mmdebstrap failed (exit %d): %s" % (p.returncode, p.stdout[-1500:] + p.stderr[-1500:]))
    with open(marker, "w") as f:
        f.write(want)


class Machine:
    """The root booted by systemd-nspawn; run() runs a command in it."""

    def __init__(self, root, log):
        self.log = open(log, "w")
        self.nspawn = subprocess.Popen(
            ["systemd-nspawn", "-q", "-D", root, "-b", "--private-network", "--console=pipe", "--register=no",
             "--keep-unit"], stdin=subprocess.DEVNULL, stdout=self.log, stderr=subprocess.STDOUT,
            start_new_session=True)
        self.init = None
        end = time.monotonic() + 60
        while time.monotonic() < end and self.nspawn.poll() is None:
            self.init = self.init or child_of(self.nspawn.pid)
            if self.init:
                p = self.run(["systemctl", "is-system-running"], check=False)
                if p.stdout.strip() in ("running", "degraded"):
                    return
            time.sleep(0.2)
        raise Failed("the Debian root did not boot within 60 s (systemd-nspawn %s): see %s" % (
            "exited %s" % self.nspawn.returncode if self.nspawn.poll() is not None else "running", log))

    def run(self, argv, check=True, timeout=120):
        p = subprocess.run(["nsenter", "-t", str(self.init), "-a", "--"] + argv, capture_output=True, text=True,
                           timeout=timeout)
        if check and p.returncode != 0:
            raise Failed("%s failed in the booted root (exit %d): %s" % (" ".join(argv), p.returncode,
                                                                         (p.stdout + p.stderr).strip()[-2000:]))
        return p

    def wait(self, argv, pred, what, timeout_s):
        end = time.monotonic() + timeout_s
        while True:
            p = self.run(argv, check=False)
            if pred(p):
                return p
            if time.monotonic() > end:
                raise Failed("%s not within %d s; last: %s" % (what, timeout_s, (p.stdout + p.stderr).strip()[-1500:]))
            time.sleep(0.2)

    def journal(self, unit):
        return self.run(["journalctl", "-b", "-u", unit, "--no-pager", "-o", "cat"], check=False).stdout

    def host_pid(self, pid):
        """The host's number of the machine's process pid."""
        ns = os.readlink("/proc/%d/ns/pid" % self.init)
        for entry in os.listdir("/proc"):
            if not entry.isdigit():
                continue
            try:
                if os.readlink("/proc/%s/ns/pid" % entry) != ns:
                    continue
                with open("/proc/%s/status" % entry) as f:
                    nspid = [line.split()[1:] for line in f if line.startswith("NSpid:")][0]
            except (OSError, IndexError):
                continue
            if nspid[-1] == str(pid):
                return int(entry)
        raise Failed("no process %d in the booted root" % pid)

    def stop(self):
        if self.init and self.nspawn.poll() is None:
            self.run(["systemctl", "poweroff"], check=False, timeout=30)
            try:
                self.nspawn.wait(60)
            except subprocess.TimeoutExpired:
                pass
        if self.nspawn.poll() is None:
            os.killpg(self.nspawn.pid, signal.SIGKILL)
            self.nspawn.wait(30)
        self.log.close()


def child_of(pid):
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open("/proc/%s/stat" % entry) as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        return int(entry)
            except (OSError, ValueError, IndexError):
                pass
    return None


def seconds(span):
    """systemd's time span ("10s", "1min 30s", "500ms") in seconds."""
    units = {"us": 1e-6, "ms": 1e-3, "s": 1, "min": 60, "h": 3600}
    parts = re.findall(r"([\d.]+)\s*(us|ms|min|s|h)", span)
    if not parts:
        raise Failed("the unit has no watchdog (WatchdogUSec=%r)" % span)
    return sum(float(n) * units[u] for n, u in parts)


def show(m, prop):
    return m.run(["systemctl", "show", "-p", prop, "--value", "vmacd"]).stdout.strip()


def status(m, token):
    p = m.run(["vmac", "status", "--json", "--token", token], check=False)
    try:
        return json.loads(p.stdout) if p.returncode == 0 else None
    except ValueError:
        return None


def board_running(m, token, name):
    def pred(p):
        try:
            s = json.loads(p.stdout)
        except ValueError:
            return False
        return any(d["name"] == name and d["state"] == "running" for d in s["devices"])
    return m.wait(["vmac", "status", "--json", "--token", token], pred, "%s running on vmacd" % name, 30)


def run(args):
    deb = os.path.abspath(args.deb)
    make_root(args.root, depends(deb))
    shutil.copy(deb, os.path.join(args.root, "root", "vmac.deb"))
    m = Machine(args.root, os.path.join(args.logdir, "boot-console.log"))
    try:
        step("booted: systemd runs as PID 1 of the root (host pid %d)" % m.init)
        m.run(["dpkg", "-i", "/root/vmac.deb"])
        files = [f for f in m.run(["dpkg", "-L", "vmac"]).stdout.split("\n") if f and f != "/."]
        enabled = m.run(["systemctl", "is-enabled", "vmacd"], check=False).stdout.strip()
        if enabled != "enabled":
            raise Failed("after dpkg -i the service is %r, not enabled" % enabled)
        m.wait(["systemctl", "is-active", "vmacd"], lambda p: p.stdout.strip() == "active",
               "vmacd active (READY=1 sent)", 30)
        step("dpkg -i: vmacd.service enabled and active (%s)" % show(m, "StatusText"))
        if show(m, "User") != "vmac" or "cap_net_raw" not in show(m, "AmbientCapabilities").lower():
            raise Failed("the unit's user or capabilities are not the package's: %s, %s" % (
                show(m, "User"), show(m, "AmbientCapabilities")))
        pid = m.host_pid(int(show(m, "MainPID")))
        with open("/proc/%d/status" % pid) as f:
            uid = [line.split()[1] for line in f if line.startswith("Uid:")][0]
        if uid == "0":
            raise Failed("vmacd runs as root")

        sec = m.run(["systemd-analyze", "security", "--no-pager", "vmacd.service"], check=False).stdout
        score = re.search(r"Overall exposure level for vmacd.service: ([\d.]+) (\S+)", sec)
        if not score or float(score.group(1)) > args.max_exposure:
            raise Failed("systemd-analyze security: %s (at most %.1f wanted)" % (
                score.group(0) if score else sec[-1000:], args.max_exposure))
        step("systemd-analyze security: exposure %s %s" % (score.group(1), score.group(2)))

        token = m.run(["runuser", "-u", "vmac", "--", "vmac", "token", "create", "--state", "/var/lib/vmac",
                       "--scope", "read"]).stdout.strip()
        m.run(["runuser", "-u", "vmac", "--", "vmac", "board", "enroll", "--local", "--state", "/var/lib/vmac",
               "--key-dir", "/var/lib/vmac/test-keys", "--quiet", "lights-1"])
        m.run(["systemd-run", "--unit", "board-lights", "--", "/usr/bin/vmac-board", "--plant", "lights", "--name",
               "lights-1", "--key-dir", "/var/lib/vmac/test-keys"])
        board_running(m, token, "lights-1")
        step("an enrolled lights board runs on the service")

        restarts = int(show(m, "NRestarts"))
        watchdog_s = seconds(show(m, "WatchdogUSec"))
        try:
            parked = Parked(thread_of(pid, "vmac-bus"))
        except OSError as e:
            raise Failed("cannot stop vmacd's bus thread: %s" % e)
        try:
            # systemd's judgement; a thread held by ptrace cannot die, so
            # it is let go once judged, and vmacd ends on systemd's signal.
            m.wait(["journalctl", "-b", "-u", "vmacd", "--no-pager", "-o", "cat"],
                   lambda p: "Watchdog timeout" in p.stdout,
                   "systemd's watchdog judging vmacd after its bus thread stopped", 3 * watchdog_s + 10)
        finally:
            parked.release()  # let go, or reaped if vmacd was killed meanwhile
        m.wait(["systemctl", "show", "-p", "NRestarts", "--value", "vmacd"],
               lambda p: p.stdout.strip().isdigit() and int(p.stdout) > restarts, "systemd restarting vmacd", 60)
        journal = m.journal("vmacd")
        for said in ("the bus thread has not ticked", "Watchdog timeout"):
            if said not in journal:
                raise Failed("the journal does not say %r:\n%s" % (said, journal[-3000:]))
        m.wait(["systemctl", "is-active", "vmacd"], lambda p: p.stdout.strip() == "active",
               "vmacd active again after the watchdog", 60)
        board_running(m, token, "lights-1")
        step("bus thread stopped: the watchdog restarted vmacd (WatchdogSec %g s) and the board runs again" %
             watchdog_s)

        m.run(["systemctl", "stop", "vmacd"])
        if "every board was told to go safe" not in m.journal("vmacd").rsplit("Watchdog timeout", 1)[-1]:
            raise Failed("systemctl stop: vmacd did not say its boards went safe")
        step("systemctl stop: vmacd told its boards to go safe and stopped")

        m.run(["systemctl", "stop", "board-lights"], check=False)
        m.run(["dpkg", "--purge", "vmac"])
        left = [f for f in files + ["/etc/vmac", "/var/lib/vmac"]
                if os.path.lexists(os.path.join(args.root, f.lstrip("/"))) and not (
                    os.path.isdir(os.path.join(args.root, f.lstrip("/"))) and f not in ("/etc/vmac", "/var/lib/vmac")
                    and os.listdir(os.path.join(args.root, f.lstrip("/"))))]
        ours = [f for f in left if "vmac" in f]
        if ours:
            raise Failed("dpkg --purge left %s" % ", ".join(ours))
        step("dpkg --purge: none of the package's %d files, /etc/vmac or /var/lib/vmac is left" % len(files))
    finally:
        m.stop()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--deb", help="the package to install")
    ap.add_argument("--prepare", action="store_true", help="only make the root, for --bins (no --deb)")
    ap.add_argument("--bins", default="", help="with --prepare: the programs (space-separated) whose libraries it needs")
    ap.add_argument("--root", required=True, help="folder for the Debian root (kept between runs)")
    ap.add_argument("--logdir", default=None, help="where the machine's console log goes (default: --root's parent)")
    ap.add_argument("--max-exposure", type=float, default=4.0, help="systemd-analyze security's highest allowed")
    args = ap.parse_args()
    args.root = os.path.abspath(args.root)
    args.logdir = args.logdir or os.path.dirname(args.root)
    if args.prepare:
        # Ahead of the test: what it cannot do here, the test itself says.
        if os.geteuid() != 0 or not shutil.which("mmdebstrap") or not shutil.which("dpkg-shlibdeps"):
            return
        t0 = time.monotonic()
        try:
            make_root(args.root, depends_of_bins(args.bins.split()))
        except Failed as e:  # the test makes it again, and says so
            print("boot: preparing the root failed: %s" % e, flush=True)
            return
        step("the root prepared in %.0f s" % (time.monotonic() - t0))
        return
    if not args.deb:
        ap.error("--deb is required (or --prepare)")
    if os.geteuid() != 0:
        skip("booting a Debian root needs root (systemd-nspawn)")
    for tool in ("mmdebstrap", "systemd-nspawn", "nsenter", "dpkg-deb"):
        if not shutil.which(tool):
            skip("%s is missing (Debian's mmdebstrap, systemd-container, util-linux, dpkg)" % tool)
    t0 = time.monotonic()
    try:
        run(args)
    except Failed as e:
        print("boot: FAIL: %s" % e, flush=True)
        sys.exit(1)
    step("passed in %.0f s" % (time.monotonic() - t0))


if __name__ == "__main__":
    main()
