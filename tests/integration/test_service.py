"""vmacd as a systemd service (docs/SERVICE.md): the notifications it sends
on $NOTIFY_SOCKET (READY=1 once the bus ticks and the API listens,
WATCHDOG=1 from the main thread only while the bus thread ticks, STOPPING=1
on the way down), read off a datagram socket the test holds as systemd
would; and its log in the journal, read by journalctl from a real
systemd-journald the test starts in a mount namespace of its own."""

import json
import os
import signal
import socket
import subprocess
import time
import urllib.request

from harness import KITCHEN, Proc, Skip
from park import Parked
from threads import thread_of

WATCHDOG_USEC = 600000  # vmacd pings every 300 ms



def notify_socket(t):
    path = os.path.join(t.logdir, "notify.sock")
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    return s, path


def receive(s, want, timeout_s):
    """The datagrams up to and including the first holding want (e.g.
    "READY=1"), each as a dict; AssertionError after timeout_s without it."""
    got, end = [], time.monotonic() + timeout_s
    while True:
        left = end - time.monotonic()
        assert left > 0, "no %s from vmacd within %.0f s; it sent %s" % (want, timeout_s, got)
        s.settimeout(left)
        try:
            data = s.recv(4096).decode()
        except socket.timeout:
            continue
        msg = dict(line.split("=", 1) for line in data.split("\n") if "=" in line)
        got.append(msg)
        if want in data.split("\n"):
            return got


def drain(s):
    """Every datagram waiting now."""
    got = []
    s.setblocking(False)
    try:
        while True:
            got.append(s.recv(4096).decode())
    except BlockingIOError:
        pass
    s.setblocking(True)
    return got


def test_notify_ready_watchdog_stopping(t):
    s, path = notify_socket(t)
    env = dict(os.environ, NOTIFY_SOCKET=path, WATCHDOG_USEC=str(WATCHDOG_USEC))
    env.pop("WATCHDOG_PID", None)
    h = t.host(env=env)
    first = receive(s, "READY=1", 30)
    assert all("WATCHDOG" not in m for m in first), "WATCHDOG=1 before READY=1: %s" % first
    ready = first[-1]
    assert "bus " in ready.get("STATUS", ""), "READY=1 without a STATUS naming the bus: %s" % ready
    # Ready means the API answers (and the bus has ticked: its heartbeat,
    # which the status copy shows up to 100 ms later).
    with urllib.request.urlopen("http://%s/api/health" % h.http, timeout=10) as r:
        assert r.status == 200, "READY=1 but GET /api/health answered %d" % r.status
    h.wait_status(lambda st: st["tick"]["count"] > 0, 5, "the bus ticking")
    t.kitchen(h)
    pings = [m for m in receive(s, "WATCHDOG=1", 5) if "WATCHDOG" in m]
    pings += [m for m in receive(s, "WATCHDOG=1", 5) if "WATCHDOG" in m]
    assert len(pings) >= 2, "fewer than two WATCHDOG=1 in 10 s of a ticking bus"

    # The bus thread stopped (the main thread runs on): no more WATCHDOG.
    mark = h.mark("stderr")
    try:
        parked = Parked(thread_of(h.pid, "vmac-bus"))
    except OSError as e:
        raise Skip("cannot stop one thread here (%s): the watchdog test needs ptrace" % e)
    try:
        h.wait_line(r"watchdog: the bus thread has not ticked for \d+ ms", 10, since=mark, stream="stderr",
                    what="the main thread saying it stopped feeding the watchdog")
        drain(s)  # a look that saw the last ticks may have pinged before the line
        window = 5 * WATCHDOG_USEC / 1e6
        s.settimeout(window)
        try:
            late = s.recv(4096).decode()
        except socket.timeout:
            late = None
        assert late is None, "vmacd sent %r while its bus thread was stopped" % late
    finally:
        assert parked.release(), "the bus thread could not be let go"
    h.wait_line(r"watchdog: the bus thread ticks again", 10, since=mark, stream="stderr",
                what="the watchdog fed again once the bus thread ticks")
    receive(s, "WATCHDOG=1", 5)

    h.signal(signal.SIGTERM)
    receive(s, "STOPPING=1", 10)
    assert h.wait_exit(30) == 0, "vmacd did not exit 0 after SIGTERM"


def test_no_notify_socket_no_notifications(t):
    """Outside systemd (no NOTIFY_SOCKET) vmacd runs as always and its log
    lines keep their 'vmacd: ' form, events included."""
    env = {k: v for k, v in os.environ.items() if k not in ("NOTIFY_SOCKET", "WATCHDOG_USEC", "JOURNAL_STREAM")}
    h = t.host(env=env)
    t.board("lights", "lights-1")
    h.wait_running(["lights-1"])
    h.wait_line(r"^vmacd: \[attached\] lights-1", 10, stream="stderr", what="the attached event on stderr")


JOURNAL_WRAPPER = r"""
set -e
mkdir -p /run/systemd /run/log
mount -t tmpfs tmpfs /run/systemd
mount --bind "$JOURNAL_DIR" /run/log
mkdir -p /run/systemd/journal
/lib/systemd/systemd-journald &
i=0; while [ ! -S /run/systemd/journal/stdout ] && [ $i -lt 200 ]; do sleep 0.05; i=$((i+1)); done
exec systemd-cat -t vmacd sh -c 'JOURNAL_STREAM=$(stat -L -c %d:%i /proc/self/fd/2); export JOURNAL_STREAM; exec "$@"' vmacd "$@"
"""


def journal(dirpath):
    p = subprocess.run(["journalctl", "-D", os.path.join(dirpath, "journal"), "-o", "json", "--no-pager", "SYSLOG_IDENTIFIER=vmacd"],
                       capture_output=True, text=True, timeout=30)
    return [json.loads(line) for line in p.stdout.splitlines() if line.strip()]


def wait_entry(dirpath, pred, what, timeout_s=30):
    end = time.monotonic() + timeout_s
    while True:
        entries = journal(dirpath)
        found = [e for e in entries if pred(e)]
        if found:
            return found[0]
        assert time.monotonic() < end, "no journal entry %s within %d s; vmacd's entries: %s" % (
            what, timeout_s, [(e.get("PRIORITY"), e.get("MESSAGE")) for e in entries][-20:])
        time.sleep(0.1)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_journal_priorities_and_fields(t):
    """Under the journal (JOURNAL_STREAM names stderr) every line carries
    its syslog priority and every event is an entry with fields
    VMAC_EVENT, VMAC_DEVICE and VMAC_SEQ, as journalctl reads them."""
    if os.geteuid() != 0:
        raise Skip("the journal test needs root (a mount namespace for its own systemd-journald)")
    for need in ("/lib/systemd/systemd-journald", "/usr/bin/journalctl", "/usr/bin/systemd-cat", "/usr/bin/unshare"):
        if not os.path.exists(need):
            raise Skip("%s is missing (Debian's systemd and util-linux)" % need)
    jdir = os.path.join(t.logdir, "journal")
    os.makedirs(jdir)
    if t.token is None:
        t.token = t.make_token("deploy")
    port = free_port()
    argv = ["unshare", "-m", "--propagation", "private", "sh", "-c", JOURNAL_WRAPPER, "journal",
            t.path("vmacd"), "--bus", t.bus, "--http", "127.0.0.1:%d" % port, "--state", t.logdir,
            "--set", "realtime=false", "--set", "reply_deadline_us=20000"]
    proc = Proc(t._name("journal"), argv, t.logdir, env=dict(os.environ, JOURNAL_DIR=jdir))
    t.procs.append(proc)
    start = wait_entry(jdir, lambda e: "status at http://" in e.get("MESSAGE", ""), "'status at ...'")
    assert start["PRIORITY"] == "5", "the start-up line has priority %s, not 5 (notice)" % start["PRIORITY"]
    assert not start["MESSAGE"].startswith(("<", "vmacd:")), \
        "the line's prefix was not read as a priority: %r" % start["MESSAGE"]
    req = urllib.request.Request("http://127.0.0.1:%d/api/health" % port)
    with urllib.request.urlopen(req, timeout=10) as r:
        assert r.status == 200
    plant, name = KITCHEN[2]
    board = t.board(plant, name)
    attached = wait_entry(jdir, lambda e: e.get("VMAC_EVENT") == "attached", "for the attached event")
    assert attached.get("VMAC_DEVICE") == name and attached["PRIORITY"] == "5" and int(attached["VMAC_SEQ"]) > 0, \
        "the attached event's fields: %s" % {k: v for k, v in attached.items() if not k.startswith("_")}
    assert attached["MESSAGE"].startswith("[attached] %s" % name), attached["MESSAGE"]
    board.kill()
    dropped = wait_entry(jdir, lambda e: e.get("VMAC_EVENT") == "dropped", "for the dropped board")
    assert dropped.get("VMAC_DEVICE") == name and dropped["PRIORITY"] == "4", \
        "a dropped board is a warning (4) naming it: %s" % {k: v for k, v in dropped.items() if not k.startswith("_")}
