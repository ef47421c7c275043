"""Integration test harness: starts the real vmacd, vmac-board and vmac
programs for one test, watches their output and status, and kills them all
afterwards. Used by run.py and every tests/integration/test_*.py.

Synchronisation is always on an observed event (a line a program printed, a
condition in GET /api/status), never on elapsed time; timeouts only bound how
long an event may take to come, and are generous because the suite also runs
under AddressSanitizer on a small shared machine."""

import http.client
import io
import json
import os
import random
import re
import signal
import socket
import subprocess
import threading
import time
import urllib.error
import urllib.request

# Relaxed timing: a slow machine must never drop a healthy board. Tests check
# behaviour, never speed. Slots of 6.25 ms and drivers at level 4 by default:
# a device is served every 100 ms (the demo drivers ask for their own levels:
# lights 100 ms, washer 200 ms idle and 50 ms running, dishwasher 400 ms
# idle). The deadline allows a board process 80 ms without the CPU (seen:
# >30 ms with two suites and a CPU hog on two cores), and a board is dropped
# after two misses in a row, not one: make test's ASan pass has held a board
# for 100 ms. Tests of what a miss does set miss_limit themselves.
TIMING = {
    "slice_us": 1250,
    "slices_per_slot": 5,
    "default_level": 4,
    "reply_deadline_us": 80000,
    "miss_limit": 2,
    "watchdog_ms": 1500,
    "discovery_period_ms": 300,
}

POLL_S = 0.05  # between two looks at a condition that has not come yet
# Every wait below (wait_line, wait_exit, wait_status, wait_event) gives
# what it waits for LOADED times the timeout its test names: the timeouts
# bound waits for what the programs do, and make test runs both
# integration passes, the package's build and the browser at once on two
# cores. A wait that is met returns at once; only a failure takes longer.
# What a test judges in time it judges by the programs' own timestamps.
LOADED = float(os.environ.get("VMAC_TEST_LOADED", "3"))
SANITIZER_MARKS = ("AddressSanitizer", "LeakSanitizer", "UndefinedBehaviorSanitizer", "runtime error:")


class Skip(Exception):
    """Raised by a test that cannot run on this machine (no root, no mount
    namespace...), with the reason. run.py reports it as SKIP, lists it at
    the end and in $VMAC_SKIP_FILE; with CI=true it is a failure instead: a
    CI run must not pass a test it did not run."""


class Line:
    """One line a program printed: its text, stream, index in that stream
    and when the harness read it (time.monotonic)."""

    def __init__(self, text, stream, index, time_s):
        self.text, self.stream, self.index, self.time_s = text, stream, index, time_s

    def __repr__(self):
        return "%s[%d] %r" % (self.stream, self.index, self.text)


class Proc:
    """A started program in its own process group. Reader threads collect its
    stdout and stderr line by line (also copied to files in the test's log
    directory); wait_line() waits for a line to appear."""

    def __init__(self, name, argv, logdir, stdin=False, env=None):
        self.name = name
        self.argv = argv
        self.lines = {"stdout": [], "stderr": []}
        self.cond = threading.Condition()
        self.logs = {s: open(os.path.join(logdir, "%s.%s" % (name, s)), "w") for s in self.lines}
        self.popen = subprocess.Popen(
            argv,
            stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=True,  # own process group: killpg reaches everything it started
            env=env,
        )
        self.pid = self.popen.pid
        self.readers = [
            threading.Thread(target=self._read, args=(s, getattr(self.popen, s)), daemon=True) for s in self.lines
        ]
        for r in self.readers:
            r.start()

    def _read(self, stream, pipe):
        for raw in iter(pipe.readline, b""):
            text = raw.decode("utf-8", "replace").rstrip("\n")
            with self.cond:
                line = Line(text, stream, len(self.lines[stream]), time.monotonic())
                self.lines[stream].append(line)
                self.logs[stream].write(text + "\n")
                self.logs[stream].flush()
                self.cond.notify_all()
        pipe.close()
        with self.cond:
            self.cond.notify_all()

    def mark(self, stream="stdout"):
        """Index of the next line of stream: wait_line(..., since=mark) sees
        only what is printed from now on."""
        with self.cond:
            return len(self.lines[stream])

    def wait_line(self, pattern, timeout_s, since=0, stream="stdout", what=None):
        """The first line of stream at index >= since that matches the regex
        pattern; AssertionError when none comes within timeout_s."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout_s * LOADED
        with self.cond:
            while True:
                for line in self.lines[stream][since:]:
                    if regex.search(line.text):
                        return line
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self.cond.wait(min(left, 0.5))
            tail = "; ".join(l.text for l in self.lines[stream][since:][-6:])
        raise AssertionError(
            "%s: no %s line %s within %.0f s (last lines: %s)"
            % (self.name, stream, what or repr(pattern), timeout_s * LOADED, tail or "none")
        )

    def find_lines(self, pattern, since=0, stream="stdout"):
        regex = re.compile(pattern)
        with self.cond:
            return [l for l in self.lines[stream][since:] if regex.search(l.text)]

    def text(self, stream="stderr"):
        with self.cond:
            return "\n".join(l.text for l in self.lines[stream])

    def send(self, line):
        """Write one line to the program's stdin (started with stdin=True)."""
        self.popen.stdin.write((line + "\n").encode())
        self.popen.stdin.flush()

    def alive(self):
        return self.popen.poll() is None

    def signal(self, sig):
        os.kill(self.pid, sig)

    def wait_exit(self, timeout_s):
        """The exit code (negative: killed by that signal); AssertionError when
        the program is still running after timeout_s."""
        try:
            rc = self.popen.wait(timeout_s * LOADED)
        except subprocess.TimeoutExpired:
            raise AssertionError("%s did not exit within %.0f s" % (self.name, timeout_s * LOADED))
        for r in self.readers:
            r.join(5)
        return rc

    def kill(self):
        """Kill the whole process group, reap it, close the logs. Idempotent."""
        try:
            os.killpg(self.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            self.popen.wait(10)
        except subprocess.TimeoutExpired:
            pass
        for r in self.readers:
            r.join(5)
        if self.popen.stdin:
            try:
                self.popen.stdin.close()
            except OSError:
                pass
        for f in self.logs.values():
            f.close()

    def sanitizer_report(self):
        """The first sanitizer report line this program printed, or None."""
        for stream in ("stderr", "stdout"):
            for line in self.lines[stream]:
                if any(m in line.text for m in SANITIZER_MARKS):
                    return line.text
        return None


class Host(Proc):
    """vmacd, with its status API at self.http ("127.0.0.1:PORT"). Every
    status fetched is remembered in self.last, and its events are merged into
    self.events (by seq). The status holds the last 20: when more came since
    the last poll (a busy host, a slow poll), the ones between are fetched
    from the event log (GET /api/events/log?after=SEQ), so none is missed."""

    def __init__(self, ctx, name, argv, logdir, env=None):
        super().__init__(name, argv, logdir, env=env)
        self.ctx = ctx
        self.events = {}
        self.complete_to = None  # every event up to this seq is in self.events
        self.last = None
        self.http = None
        self._conns = threading.local()  # each thread's kept-alive connection to the API (_kept_get)

    def ready(self):
        """Wait for the status server to be up; sets self.http (ADDR:PORT) and self.scheme (http or https)."""
        line = self.wait_line(r"status at https?://(\S+)/api/status", 30, stream="stderr", what="'status at ...'")
        m = re.search(r"status at (https?)://(\S+)/api/status", line.text)
        self.scheme, self.http = m.group(1), m.group(2)

    def get(self, path, token=None):
        """GET path with the context's token (or token); the parsed JSON. An
        error status raises urllib.error.HTTPError, as urlopen does."""
        token = self.ctx.token if token is None else token
        headers = {"Authorization": "Bearer " + token} if token else {}
        answer, body = self._kept_get(path, headers)
        if answer.status >= 400:
            raise urllib.error.HTTPError("http://%s%s" % (self.http, path), answer.status, answer.reason,
                                         answer.headers, io.BytesIO(body))
        return json.loads(body)

    def _kept_get(self, path, headers):
        """GET path on this thread's connection to the host, kept alive from
        one poll to the next as a browser's: a new connection per poll cost
        the host a thread and, under ASan, three times the CPU of the answer
        (docs/TESTING.md, "What make test costs"). A connection the host
        closed meanwhile (idle for 30 s) is made again once."""
        addr, port = self.http.rsplit(":", 1)
        conn = getattr(self._conns, "conn", None)
        if conn is None or (conn.host, conn.port) != (addr, int(port)):  # none yet, or a host started again
            conn = self._conns.conn = http.client.HTTPConnection(addr, int(port), timeout=10)
        for again in (False, True):
            try:
                conn.request("GET", path, headers=headers)
                answer = conn.getresponse()
                body = answer.read()
            except (OSError, http.client.HTTPException):
                conn.close()  # the next request connects anew
                if again:
                    raise
                continue
            if answer.will_close:
                conn.close()
            return answer, body

    def status(self):
        s = self.get("/api/status")
        window = s.get("events", [])
        for e in window:
            self.events[e["seq"]] = e
        if window:
            oldest = min(e["seq"] for e in window)
            if self.complete_to is None:
                self.complete_to = oldest - 1  # what came before the first poll is not asked for
            if oldest > self.complete_to + 1:
                self.fill_events(oldest)
            while self.complete_to + 1 in self.events:
                self.complete_to += 1
        self.last = s
        return s

    def fill_events(self, upto):
        """The events after self.complete_to and before upto, from the store's
        log; those not stored yet are asked for again at the next poll."""
        after = self.complete_to
        while after + 1 < upto:
            try:
                page = self.get("/api/events/log?after=%d&limit=1000" % after).get("events", [])
            except (OSError, ValueError):
                return
            for e in page:
                self.events[e["seq"]] = e
            if not page:
                return
            after = max(e["seq"] for e in page)

    def device(self, name, status=None):
        """The device called name in status (the latest by default), or None."""
        s = status or self.last or self.status()
        for d in s["devices"]:
            if d["name"] == name:
                return d
        return None

    def wait_status(self, predicate, timeout_s, what, invariant=None):
        """Poll the status until predicate(status) is true, returning that
        status. invariant(status), when given, is checked on every poll and
        may raise AssertionError: something that must hold all the while."""
        deadline = time.monotonic() + timeout_s * LOADED
        while True:
            if not self.alive():
                raise AssertionError("vmacd exited (code %s) while waiting for %s" % (self.popen.poll(), what))
            s = self.status()
            if invariant:
                invariant(s)
            if predicate(s):
                return s
            if time.monotonic() > deadline:
                raise AssertionError("%s not seen within %.0f s; devices: %s" % (what, timeout_s * LOADED,
                                                                                   describe(s)))
            time.sleep(POLL_S)

    def wait_running(self, names, timeout_s=30, invariant=None):
        """Every device of names running; returns the status."""
        return self.wait_status(
            lambda s: all((self.device(n, s) or {}).get("state") == "running" for n in names),
            timeout_s,
            "%s running" % ", ".join(names),
            invariant,
        )

    def find_events(self, kind, device=None, text=None, after_seq=0):
        """Recorded events of kind (for device, containing text), oldest first."""
        return [
            e
            for seq, e in sorted(self.events.items())
            if seq > after_seq
            and e["kind"] == kind
            and (device is None or e["device"] == device)
            and (text is None or text in e["text"])
        ]

    def wait_event(self, kind, device=None, text=None, after_seq=0, timeout_s=30, invariant=None):
        """The first event of kind (for device, containing text) with seq
        greater than after_seq; waits for it while polling the status."""
        what = "event %s%s%s" % (kind, " for " + device if device else "", " with %r" % text if text else "")
        self.wait_status(lambda s: self.find_events(kind, device, text, after_seq), timeout_s, what, invariant)
        return self.find_events(kind, device, text, after_seq)[0]

    def last_event_seq(self):
        self.status()
        return max(self.events) if self.events else 0


def http_code(host, path, token=None):
    """The HTTP status of GET path on host's API (with token, when given)."""
    req = urllib.request.Request("http://%s%s" % (host.http, path))
    if token:
        req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status
    except urllib.error.HTTPError as e:
        return e.code


def post(host, path, token, data, content_type="application/json"):
    """POST data to host's API with token: (HTTP status, the answer's text),
    an error status included."""
    req = urllib.request.Request("http://%s%s" % (host.http, path), data=data, method="POST")
    req.add_header("Content-Type", content_type)
    req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


RECORDING_EVENT = r"recording (\d+) kept \((\d+) bytes\)"  # the text of a `recording` event (RECORDING.md)


def recording_id(event):
    """The store's id of the recording a 'recording' event announces."""
    m = re.search(RECORDING_EVENT, event["text"])
    assert m, "the recording event does not say which recording it kept: %r" % event["text"]
    return int(m.group(1))


def fetch_recording(t, host, rec_id, name, token=None):
    """`vmac recording get ID > FILE` (FILE in the test's log folder, the
    token the test's deploy token unless given); returns FILE's path."""
    path = os.path.join(t.logdir, name)
    env = dict(os.environ, VMAC_TOKEN=token if token is not None else t.token)
    with open(path, "wb") as f:
        p = subprocess.run([t.path("vmac"), "recording", "get", "--http", host.http, str(rec_id)], stdout=f,
                           stderr=subprocess.PIPE, env=env, timeout=60)
    assert p.returncode == 0, "vmac recording get %d failed (exit %d): %s" % (rec_id, p.returncode,
                                                                             p.stderr.decode("utf-8", "replace"))
    return path


def small_state(t):
    """A state folder for a host on a 1 MiB tmpfs of its own, in a mount
    namespace (needs root, as CI has): (the folder, the wrapper that runs
    the host in that namespace with the test's store copied in). Raises
    Skip where that cannot be had (a failure with CI=true: run.py)."""
    if os.geteuid() != 0:
        raise Skip("needs root for a tmpfs in a mount namespace; run make test as root")
    probe = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c",
                            'mount -t tmpfs -o size=1m tmpfs "$0"', t.logdir], capture_output=True, text=True,
                           timeout=30)
    if probe.returncode != 0:
        raise Skip("cannot mount a tmpfs in a mount namespace here (a container without CAP_SYS_ADMIN?): %s"
                   % probe.stderr.strip())
    state = os.path.join(t.logdir, "small")
    os.makedirs(state)
    wrapper = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
               'mount -t tmpfs -o size=1m tmpfs "$0" && cp "$1"/vmac.db* "$0"/ && shift && exec "$@"',
               state, t.logdir]
    return state, wrapper


def fill_state(host, state):
    """Fill the tmpfs of small_state from inside the host's namespace."""
    fill = subprocess.run(["nsenter", "-t", str(host.popen.pid), "-m", "sh", "-c",
                           'dd if=/dev/zero of="%s/fill" bs=4k 2>/dev/null; df -k "%s" | tail -1' % (state, state)],
                          capture_output=True, text=True, timeout=60)
    assert " 0 " in fill.stdout or "100%" in fill.stdout, "the tmpfs did not fill: %r %r" % (fill.stdout,
                                                                                            fill.stderr)


def describe(status):
    return ", ".join(
        "%s %s misses %d served %d" % (d["name"], d["state"], d["misses"], d["served"]) for d in status["devices"]
    ) or "none"


def until(look, timeout_s, what, poll_s=POLL_S):
    """Call look() every poll_s until it returns something true, and return
    that; after LOADED times timeout_s (as the harness's own waits), an
    AssertionError saying what was awaited: what is a text, or a function
    called then for one (the last state seen, say). For what the Host's
    waits do not ask: the store, a broker, a board's counters, a peer."""
    deadline = time.monotonic() + timeout_s * LOADED
    while True:
        got = look()
        if got:
            return got
        if time.monotonic() > deadline:
            raise AssertionError("%s: not within %.0f s" % (what() if callable(what) else what, timeout_s * LOADED))
        time.sleep(poll_s)


def plain_pass_only(why):
    """Marks a test that judges a whole programme in real time (minutes of
    a plant's physics): make test runs it in the plain pass, and the
    sanitizer pass leaves it out (run.py lists it as PLAIN), because the
    code it runs is run under the sanitizers by the shorter tests and by
    the drivers' tests in virtual time (make test-asan's test-drivers).
    why says which of those cover it."""
    def mark(fn):
        fn.plain_pass_only = why
        return fn
    return mark


def plain_pass_too(why):
    """Marks a test whose run on the plain build judges what the sanitizer
    pass cannot: the memory or the timing of the program as shipped, or
    the full count of trials where the sanitizer pass runs fewer. make
    test runs every other integration test once, under the sanitizers
    (run.py --plain-pass leaves them out of the plain pass); these in both
    passes. why says what the plain run judges."""
    def mark(fn):
        fn.plain_pass_too = why
        return fn
    return mark


def takes_about(seconds):
    """Marks a test that takes about seconds (the plain pass, on the 2-core
    machine make test runs on). run.py starts the longest tests first by
    the times of the last run; for a test it has no time of (a fresh clone,
    as CI's, has none) it goes by this, so a long test is not started last
    with the others done and the pass waiting for it alone."""
    def mark(fn):
        fn.takes_about = float(seconds)
        return fn
    return mark


# Under the ASan build, no leak scan at a program's exit: about half of a
# short run's CPU. AddressSanitizer's checks stay on.
NO_LEAK_SCAN = {"ASAN_OPTIONS": "detect_leaks=0"}


def helper_env():
    """The environment of the harness's own runs of vmac (enrolling keys,
    making tokens) around what a test is about: NO_LEAK_SCAN (the
    commands' own tests scan theirs)."""
    return dict(os.environ, **NO_LEAK_SCAN)


def sanitized(program):
    """Whether program was built with AddressSanitizer (make test's second
    pass): its memory figures then include the sanitizer's own."""
    with open(program, "rb") as f:
        return b"__asan_init" in f.read()


def bus_socket(bus, timeout_s):
    """A UDP socket on the test's bus (GROUP:PORT), a member of its group
    on loopback, as a board's is: it receives DISCOVERs and CYCLIC frames.
    Its sends go out unicast unless told otherwise."""
    group, port = bus.rsplit(":", 1)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("", int(port)))
    s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, socket.inet_aton(group) + socket.inet_aton("127.0.0.1"))
    s.settimeout(timeout_s)
    return s


def sender_socket(bus):
    """A UDP socket that speaks on the test's bus (GROUP:PORT) as a host
    does: bound to an ephemeral port on loopback, its multicast out on
    loopback (its own copies looped back too). Returns it and the group's
    (address, port) to send discovery and CYCLIC frames to."""
    group, port = bus.rsplit(":", 1)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
    return s, (group, int(port))


def misread(counters):
    """The host's malformed-frame counts (status counters) that say a frame
    was read wrong: every reason but stale_seq, a reply to an earlier
    request or session, which is a board process late on a loaded machine
    (its frame well formed). {reason: count} of those above 0."""
    return {k: n for k, n in counters["malformed_by_reason"].items() if n and k != "stale_seq"}


def undisturbed(names):
    """An invariant for wait_status: every device of names is running, and
    none of its misses is the host's own (misses_host: a request the host
    failed to send). A miss the host did not cause (a reply the kernel
    stamped after the deadline, or none, because this shared machine did
    not run the board's process in time) is tolerated while the device runs
    on (miss_limit > 1), and named as the board's when it drops it."""

    def check(s):
        for n in names:
            d = next((d for d in s["devices"] if d["name"] == n), None)
            assert d is not None, "%s vanished from the status" % n
            assert d.get("misses_host", 0) == 0, "%s missed %d replies by the host's own fault" % (
                n, d["misses_host"])
            assert d["state"] == "running", "%s left running: now %s (%s)" % (
                n, d["state"], "after %d misses of its board or the wire, none the host's" % d["misses"]
                if d["misses"] else d.get("note") or "no miss")

    return check


class Trip:
    """A board's watchdog trip as vmac-board printed it: the period the host
    set and the board's own times (CLOCK_MONOTONIC, the clock of
    time.monotonic() on Linux) of its last frame and of its outputs going
    off, in seconds (period_s, ...) and as printed, in whole milliseconds
    (period_ms, ...); line is the Line it came in."""

    def __init__(self, line):
        m = re.search(r": watchdog: no frame for (\d+) ms, outputs off; last frame at (\d+) ms, off at (\d+) ms$",
                      line.text)
        assert m, "a watchdog line without the board's times: %r" % line.text
        self.period_ms, self.last_frame_ms, self.off_ms = (int(g) for g in m.groups())
        self.period_s, self.last_frame_s, self.off_s = (int(g) / 1000.0 for g in m.groups())
        self.line = line


def watchdog_trip(board, name, since, timeout_s=30):
    """The next watchdog trip board prints for its board name at or after
    line since: a Trip. Judge it by trip.off_s, the moment the board turned
    the outputs off, not by when the harness read the line (a busy machine
    delays that by seconds)."""
    line = board.wait_line(r"^%s: watchdog: no frame for \d+ ms, outputs off" % re.escape(name), timeout_s,
                           since=since, what="%s's watchdog trip" % name)
    return Trip(line)


KITCHEN = (("washer", "washer-1"), ("dishwasher", "dish-1"), ("lights", "lights-1"))
KITCHEN_NAMES = [name for _, name in KITCHEN]
# The kitchen's fourth machine, user content: its drivers folder (for
# host(drivers=...)) and its plant in Lua (for board(plant_file=...)).
EXAMPLES_KITCHEN = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                                "examples", "kitchen")
DRYER_PLANT = os.path.join(EXAMPLES_KITCHEN, "plants", "dryer.lua")


class Context:
    """What a test gets: its own bus (random multicast group and port), a log
    directory, and starters for the programs. cleanup() kills everything."""

    def __init__(self, bindir, logdir):
        self.bindir = bindir
        self.logdir = logdir
        rnd = random.SystemRandom()
        self.bus = "239.255.%d.%d:%d" % (rnd.randint(1, 254), rnd.randint(1, 254), rnd.randint(20000, 60000))
        self.procs = []
        self.cleanups = []  # callables run after every process is killed (namespaces, links)
        self.counter = 0
        self.token = None  # made by the first host(): scope deploy, in this test's state folder
        self.enrolled = {}  # state folder: the names enroll() put there

    def path(self, program):
        return os.path.join(self.bindir, program)

    def _name(self, base):
        self.counter += 1
        return "%02d-%s" % (self.counter, base)

    def eth_link(self):
        """A raw-Ethernet bus of this test's own: a veth pair, one end in
        this namespace for vmacd, the other in a new network namespace for
        the boards. Returns (host_iface, namespace, board_iface); both are
        removed at cleanup. Raises Skip where namespaces cannot be made."""
        if os.geteuid() != 0:
            raise Skip("raw Ethernet tests need root (network namespaces, veth, CAP_NET_RAW)")
        tag = "%05x" % random.SystemRandom().randint(0, 0xFFFFF)
        ns, host_if, board_if = "vmac-" + tag, "vmh" + tag, "vmb" + tag

        def ip(*argv):
            p = subprocess.run(["ip"] + list(argv), capture_output=True, text=True, timeout=30)
            if p.returncode != 0:
                raise Skip("cannot make a network namespace and veth pair here (ip %s: %s)" % (
                    " ".join(argv), p.stderr.strip()))

        ip("netns", "add", ns)
        self.cleanups.append(lambda: subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30))
        ip("link", "add", host_if, "type", "veth", "peer", "name", board_if)
        self.cleanups.append(lambda: subprocess.run(["ip", "link", "del", host_if], capture_output=True, timeout=30))
        ip("link", "set", board_if, "netns", ns)
        ip("link", "set", host_if, "up")
        ip("netns", "exec", ns, "ip", "link", "set", board_if, "up")
        ip("netns", "exec", ns, "ip", "link", "set", "lo", "up")
        return host_if, ns, board_if

    def host(self, drivers=None, settings=None, extra=(), wrapper=(), bus=None, env=None):
        """Start vmacd on this test's bus with relaxed timing; returns once its
        status server is up. The HTTP port is chosen by the kernel. wrapper:
        a command vmacd runs under (e.g. setpriv to drop privileges); env:
        its whole environment (default: the test's)."""
        if self.token is None:
            self.token = self.make_token("deploy")
        values = dict(TIMING, realtime="false")
        values.update(settings or {})
        argv = list(wrapper) + [self.path("vmacd"), "--bus", bus or self.bus, "--http", "127.0.0.1:0", "--state",
                                self.logdir]
        if drivers:
            argv += ["--drivers", drivers]
        for k, v in values.items():
            argv += ["--set", "%s=%s" % (k, v)]
        argv += list(extra)
        h = Host(self, self._name("vmacd"), argv, self.logdir, env=env)
        extra = list(extra)
        h.state = extra[extra.index("--state") + 1] if "--state" in extra else self.logdir
        self.procs.append(h)
        h.ready()
        return h

    def board(self, plant, name, driver=None, count=None, commands=False, major=None, minor=None, wrapper=(), bus=None,
              extra=(), keyed=True, plant_file=None):
        """Start vmac-board: count boards NAME-1..NAME-count, else one named
        NAME. keyed: each has its own key, enrolled in this test's state
        folder first (enroll), as a host with bus_trust enrolled wants.
        plant_file: a plant in Lua (--plant-file, BOARD.md "Plant models in
        Lua") instead of the C plant `plant` (then None)."""
        # Late-reply lines only for replies that took a quarter of the tests'
        # reply deadline (TIMING): the ones that matter here.
        argv = list(wrapper) + [self.path("vmac-board")] + (["--plant-file", plant_file] if plant_file else [
            "--plant", plant]) + ["--name", name, "--bus", bus or self.bus,
                                  "--late-us", str(TIMING["reply_deadline_us"] // 4)]
        if keyed:
            self.enroll([name] if not count else ["%s-%d" % (name, i) for i in range(1, count + 1)], again=False)
            argv += ["--key-dir", self.keys]
        argv += list(extra)
        if driver:
            argv += ["--driver", driver]
        if major is not None:
            argv += ["--major", str(major)]
        if minor is not None:
            argv += ["--minor", str(minor)]
        if count:
            argv += ["--count", str(count)]
        if commands:
            argv.append("--commands")
        p = Proc(self._name(name), argv, self.logdir, stdin=commands)
        self.procs.append(p)
        p.wait_line(r"^vmac-board: \d+ \S+ boards? on bus", 30, what="start-up banner")
        return p

    def kitchen(self, host, commands=False):
        """washer-1, dish-1 and lights-1 on this bus, all running; returns
        {name: board}."""
        boards = {name: self.board(plant, name, commands=commands) for plant, name in KITCHEN}
        host.wait_running(KITCHEN_NAMES)
        return boards

    def drivers(self, **files):
        """A --drivers folder in the log directory holding NAME.lua for every
        NAME=source given; returns its path."""
        path = os.path.join(self.logdir, "drivers")
        os.makedirs(path, exist_ok=True)
        for name, source in files.items():
            with open(os.path.join(path, name + ".lua"), "w") as f:
                f.write(source)
        return path

    @property
    def keys(self):
        """This test's board keys: KEYS/NAME.key, made by enroll."""
        return os.path.join(self.logdir, "keys")

    def enroll(self, names, again=True):
        """Enroll boards names in this test's state folder and in that of
        every host of this test started with its own (vmac board enroll
        --local: host running or not), each key in self.keys/NAME.key, made
        the first time; returns once every running host of the test's state
        folder holds them (its status's board_keys). again False: a name
        this context enrolled in a folder already is not enrolled there
        again (board() starting the boards of a test that enrolled them
        all at once)."""
        states = [self.logdir]
        for h in self.procs:
            if isinstance(h, Host) and h.state not in states:
                states.append(h.state)
        for state in states:
            todo = [n for n in names if again or n not in self.enrolled.get(state, ())]
            if not todo:
                continue
            p = subprocess.run([self.path("vmac"), "board", "enroll", "--local", "--state", state, "--key-dir",
                                self.keys, "--replace", "--quiet"] + todo, capture_output=True, text=True,
                               timeout=60, env=helper_env())
            assert p.returncode == 0, "vmac board enroll failed (exit %d): %s" % (p.returncode, p.stderr)
            self.enrolled.setdefault(state, set()).update(todo)
        # A running host has them before the boards announce (one of another
        # state folder takes them within 50 ms: its status needs a token of
        # its own store). Its main thread looks between two loads of drivers
        # (a second or more each under ASan, for the escape corpus's).
        held = len([f for f in os.listdir(self.keys) if f.endswith(".key")])
        for h in self.procs:
            if isinstance(h, Host) and h.http and h.alive() and h.state == self.logdir:
                h.wait_status(lambda st: st.get("board_keys", 0) >= held, 30, "the host holding %d board keys" % held)

    def make_token(self, scope):
        """A new token of scope in this test's state folder (vmac token create)."""
        p = subprocess.run([self.path("vmac"), "token", "create", "--state", self.logdir, "--scope", scope],
                           capture_output=True, text=True, timeout=30, env=helper_env())
        assert p.returncode == 0, "vmac token create failed (exit %d): %s" % (p.returncode, p.stderr)
        return p.stdout.strip()

    def start(self, argv, base):
        """Start any program (for failure-path checks); killed at cleanup.
        It gets the context's token as $VMAC_TOKEN (for vmac's commands)."""
        env = dict(os.environ, VMAC_TOKEN=self.token) if self.token else None
        p = Proc(self._name(base), argv, self.logdir, env=env)
        self.procs.append(p)
        return p

    def run(self, argv, base, timeout_s=60):
        """Run a program to its end: (exit code, stdout, stderr)."""
        p = self.start(argv, base)
        rc = p.wait_exit(timeout_s)
        return rc, p.text("stdout"), p.text("stderr")

    def cleanup(self):
        """Kill every process this test started, even stopped ones; returns
        the first sanitizer report any of them printed, or None."""
        report = None
        for p in reversed(self.procs):
            p.kill()
        for p in self.procs:
            r = p.sanitizer_report()
            if r and not report:
                report = "%s: %s" % (p.name, r)
        for f in reversed(self.cleanups):
            f()
        self.cleanups = []
        return report
