#!/usr/bin/env python3
"""make soak / make test-soak: one vmacd under every fault at once for
SOAK_MINUTES, its resources sampled every 10 s (docs/RELIABILITY.md, "Soak").

What runs against one host (its own bus group and port, HTTP on a free port,
a fresh state folder):

  healthy   lights-1, washer-1 (a quick programme started again whenever
            one ends) and two generic boards, never disturbed: their
            host-caused misses (misses_host) must stay 0 and the host must
            never drop them by its own fault
  victims   one vmac-board --count 5 (driver `victim`), killed with SIGKILL
            and started again every 2 to 4 s
  reloads   POST /api/drivers/victim (a new version each time) every 10 s
  UI        20 web UI clients: streaming GET /api/live each, reconnecting
            after a random 5..60 s, and GET /api/status 10 times a second
            between them
  junk      1,000 malformed datagrams a second to the host's bus address
  tokens    5 requests a second with no token, a wrong one or a revoked one:
            every one must be refused, 401, or 429 once its key is locked
            out (docs/API.md, "Abuse": 10 failures a minute of one token id,
            or of one address without a token of the right shape; each
            request comes from its own loopback address 127.0.1.x), while
            the web UI clients' valid token is never refused
  store     the state folder on a tmpfs of its own (a mount namespace) with a
            filler file leaving --store-free-kib; when the store is full (a
            reload answered 507) and has been for 30 s, 1 MiB of the filler
            is given back, as an operator clearing space would

Every 10 s: the host's RSS, open descriptors, threads, and the size of
vmac.db and vmac.db-wal, one line each. At the end: start (after a warm-up
of the first 20% of the run) against end, the healthy boards' misses, and
what every fault source did; exit 1 with what broke.

usage: soak.py --bin build/bin [--minutes M] [--out build/soak]"""

import argparse
import http.client
import json
import multiprocessing
import os
import random
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
from frames import UPDATE, inputs, patch, reply  # noqa: E402  (the tests' vmac frames)
from harness import Context, TIMING  # noqa: E402  (the integration tests' process handling)

SAMPLE_S = 10
WARMUP_FRACTION = 0.2
RELOAD_S = 10
UI_CLIENTS = 20
JUNK_PER_S = 1000
BAD_TOKENS_PER_S = 5
HEALTHY = ["lights-1", "washer-1", "steady-1", "steady-2"]
VICTIMS = 5
FREE_STEP_BYTES = 1 << 20
TMPFS_SIZE = "64m"

# The victims' driver; every reload uploads it with a new version number.
VICTIM_LUA = """-- soak victim, upload %(n)d
local driver = { name = "victim", version = "1.0.%(n)d", io = { switch = "di0", lamp = "do0", level = "ai0" },
	variables = { lamp = {}, ticks = {} } }
function driver.tick(dev, inputs)
	dev.state.ticks = (dev.state.ticks or 0) + 1
	dev.out.lamp = inputs.switch
	dev.vars.lamp = inputs.switch
	dev.vars.ticks = dev.state.ticks
end
function driver.migrate(dev, old)
	dev.state.ticks = old.ticks or 0
end
return driver
"""


def log(msg):
    print(msg, flush=True)


class Api:
    """Requests to the host's HTTP API; (status code, body) or (None, error)."""

    def __init__(self, http_addr):
        host, port = http_addr.rsplit(":", 1)
        self.host, self.port = host, int(port)

    def request(self, method, path, token=None, body=None, source=None, timeout_s=10):
        conn = http.client.HTTPConnection(self.host, self.port, timeout=timeout_s,
                                          source_address=(source, 0) if source else None)
        try:
            headers = {"Authorization": "Bearer " + token} if token is not None else {}
            if body is not None:
                headers["Content-Type"] = "text/plain"
            conn.request(method, path, body=body, headers=headers)
            r = conn.getresponse()
            # A 401 to a stream is a whole answer; a 200 to one is never read here.
            data = r.read() if not r.getheader("Content-Type", "").startswith("text/event-stream") else b""
            return r.status, data.decode("utf-8", "replace")
        except (OSError, http.client.HTTPException) as e:
            return None, "%s: %s" % (type(e).__name__, e)
        finally:
            conn.close()

    def json(self, path, token):
        code, body = self.request("GET", path, token)
        if code != 200:
            raise RuntimeError("GET %s: %s %s" % (path, code, body[:200]))
        return json.loads(body)


# ---- child processes: the junk sender and the UI clients (own GILs) ----

def junk_datagrams(rnd, count):
    """Datagrams the host must drop as malformed: random bytes, truncated
    vmac headers, a wrong magic or version, replies of unknown devices."""
    out = []
    for _ in range(count):
        dev = rnd.randint(0x40000000, 0xFFFFFFFF)  # never an id this host gave out
        update = reply(UPDATE, inputs(), seq=rnd.randint(0, 65535), device_id=dev)
        kind = rnd.randint(0, 4)
        if kind == 0:
            data = bytearray(rnd.getrandbits(8) for _ in range(rnd.randint(0, 120)))
            if data and data[0] == ord("V"):
                data[0] = 0
            out.append(bytes(data))
        elif kind == 1:
            out.append(update[:rnd.randint(0, len(update) - 1)])
        elif kind == 2:
            out.append(patch(update, "magic", rnd.choice([b"MV", b"vm", b"\0\0"])))
        elif kind == 3:
            out.append(patch(update, "version", rnd.choice([0, 3, 0xFF])))
        else:
            out.append(update)
    return out


def junk_main(target, seed, stop, sent):
    """1,000 malformed datagrams a second, 10 every 10 ms."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops us
    pool = junk_datagrams(random.Random(seed), 4096)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    per_tick = JUNK_PER_S // 100
    i, due = 0, time.monotonic()
    while not stop.is_set():
        for _ in range(per_tick):
            try:
                sock.sendto(pool[i % len(pool)], target)
            except OSError:
                pass  # a full socket buffer: the datagram is not counted as sent
            else:
                with sent.get_lock():
                    sent.value += 1
            i += 1
        due += 0.01
        late = due - time.monotonic()
        if late > 0:
            time.sleep(late)
        elif late < -1:
            due = time.monotonic()  # more than a second behind: do not burst to catch up


def ui_main(http_addr, token, seed, stop, counters, errors):
    """UI_CLIENTS streaming GET /api/live clients, each reconnecting after a
    random lifetime, and a poller of GET /api/status between them."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    host, port = http_addr.rsplit(":", 1)
    rnd = random.Random(seed)

    def count(name, n=1):
        with counters[name].get_lock():
            counters[name].value += n

    def error(text):
        count("errors")
        try:
            errors.put_nowait(text)
        except Exception:
            pass

    def live_client(lifetime_rnd):
        while not stop.is_set():
            end = time.monotonic() + lifetime_rnd.uniform(5, 60)
            conn = http.client.HTTPConnection(host, int(port), timeout=20)
            try:
                conn.request("GET", "/api/live", headers={"Authorization": "Bearer " + token})
                r = conn.getresponse()
                if r.status != 200:
                    error("GET /api/live: %d %s" % (r.status, r.read()[:200]))
                    time.sleep(1)
                    continue
                count("live_connects")
                while not stop.is_set() and time.monotonic() < end:
                    line = r.fp.readline()
                    if not line:
                        if not stop.is_set():
                            error("GET /api/live: the host closed the stream")
                        break
                    if line.startswith(b"data: "):
                        count("live_messages")
            except (OSError, http.client.HTTPException) as e:
                if not stop.is_set():
                    error("GET /api/live: %s: %s" % (type(e).__name__, e))
                    time.sleep(1)
            finally:
                conn.close()

    threads = [threading.Thread(target=live_client, args=(random.Random(rnd.random()),), daemon=True)
               for _ in range(UI_CLIENTS)]
    for t in threads:
        t.start()
    api = Api(http_addr)
    while not stop.is_set():
        code, body = api.request("GET", "/api/status", token)
        if code == 200:
            count("status_ok")
        else:
            error("GET /api/status: %s %s" % (code, body[:200]))
        stop.wait(0.1)
    for t in threads:
        t.join(25)


# ---- the soak ----

class Soak:
    def __init__(self, args):
        self.args = args
        self.seconds = args.minutes * 60
        self.rnd = random.Random(args.seed)
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.failures = []
        self.notes = []
        self.samples = []
        self.victim_proc = None
        self.victim_log = None
        self.mp = multiprocessing.get_context("spawn")  # no fork of a process with threads
        self.mp_stop = self.mp.Event()
        self.children = []
        self.counts = {"restarts": 0, "reloads_ok": 0, "reload_machines": 0, "reloads_full": 0,
                       "space_freed": 0, "bad_requests": 0, "bad_401": 0, "washer_starts": 0,
                       "status_polls": 0}
        self.reload_answers = {}
        self.bad_other = {}
        self.event_kinds = {}
        self.warnings = {}
        self.healthy_drops = []
        self.healthy_bad = []
        self.last_status = None
        self.store_on_tmpfs = False
        self.last_free = 0.0
        self.smaps_warm = None
        self.smaps_last = None

    def fail(self, msg):
        with self.lock:
            if msg not in self.failures:
                self.failures.append(msg)
        log("soak: FAILURE: " + msg)

    # -- set-up --

    def start(self):
        a = self.args
        shutil.rmtree(a.out, ignore_errors=True)
        os.makedirs(a.out)
        self.ctx = ctx = Context(a.bin, a.out)
        # Tokens in the staging store (the context's folder), then copied
        # into the small state folder with the database.
        self.deploy = ctx.token = ctx.make_token("deploy")
        self.token = ctx.make_token("read")
        self.operate = ctx.make_token("operate")
        revoked = ctx.make_token("read")
        rc = subprocess.run([ctx.path("vmac"), "token", "revoke", revoked.split("_")[1], "--state", a.out],
                            capture_output=True, text=True, timeout=30)
        if rc.returncode != 0:
            raise RuntimeError("vmac token revoke failed: %s" % rc.stderr)
        self.bad_tokens = [None, "vmac_%016x_%064x" % (self.rnd.getrandbits(64), self.rnd.getrandbits(256)),
                           revoked, "not-a-token", "vmac_" + revoked.split("_")[1] + "_" + "0" * 64]
        self.state = os.path.join(a.out, "state")
        os.makedirs(self.state)
        # Every board enrolled before the host starts: its store is the copy
        # the wrapper makes into its own mount namespace, so enrolling later
        # from here would not reach it.
        ctx.enroll(["washer-1", "lights-1", "steady-1", "steady-2"] +
                   ["victim-%d" % i for i in range(1, VICTIMS + 1)])
        wrapper = self.store_wrapper()
        settings = {"miss_limit": 3, "driver.washer.param.time_scale": "0.002",
                    "driver.washer.param.program": "quick"}
        drivers = ctx.drivers(victim=VICTIM_LUA % {"n": 0})
        self.host = ctx.host(drivers=drivers, settings=settings, wrapper=wrapper, extra=("--state", self.state))
        self.pid = self.host.pid
        with open("/proc/%d/comm" % self.pid) as f:
            comm = f.read().strip()
        if comm != "vmacd":
            raise RuntimeError("process %d is %s, not vmacd" % (self.pid, comm))
        self.api = Api(self.host.http)
        keys = ("--key-dir", ctx.keys)
        self.boards = {"washer-1": ctx.board("washer", "washer-1", commands=True, keyed=False, extra=keys),
                       "lights-1": ctx.board("lights", "lights-1", keyed=False, extra=keys),
                       "steady": ctx.board("generic", "steady", count=2, keyed=False, extra=keys)}
        self.boards["washer-1"].send("washer-1 fill_rate_lps 5")
        self.host.wait_running(HEALTHY, timeout_s=60)
        self.start_victims()
        self.host.wait_running(["victim-%d" % i for i in range(1, VICTIMS + 1)], timeout_s=60)
        status = self.api.json("/api/status", self.token)
        ip, port = status["bus"]["host_addr"].rsplit(":", 1)
        self.bus_addr = (ip, int(port))
        log("soak: vmacd pid %d, HTTP %s, bus %s (host %s:%d), state %s%s" % (
            self.pid, self.host.http, ctx.bus, ip, int(port), self.state,
            " on a tmpfs of %s with %d KiB left" % (TMPFS_SIZE, a.store_free_kib) if self.store_on_tmpfs else ""))

    def store_wrapper(self):
        """vmacd's wrapper: a mount namespace with a tmpfs on the state folder,
        the staging database copied in and a filler leaving store_free_kib.
        None possible: SKIPPED loudly, a failure with CI=true."""
        reason = None
        if os.geteuid() != 0:
            reason = "needs root for a tmpfs in a mount namespace"
        else:
            probe = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c",
                                    'mount -t tmpfs -o size=1m tmpfs "$0"', self.state],
                                   capture_output=True, text=True, timeout=30)
            if probe.returncode != 0:
                reason = "cannot mount a tmpfs in a mount namespace here: %s" % probe.stderr.strip()
        if reason:
            text = "soak: the store near full: %s" % reason
            log("#" * 80)
            log("SKIPPED: " + text + "; the store runs on the ordinary disk")
            log("#" * 80)
            if os.environ.get("VMAC_SKIP_FILE"):
                with open(os.environ["VMAC_SKIP_FILE"], "a") as f:
                    f.write(text + "\n")
            if os.environ.get("CI") == "true":
                self.fail("could not run the store-near-full part, and CI=true makes that a failure: " + reason)
            shutil.copy(os.path.join(self.args.out, "vmac.db"), self.state)
            for ext in ("-wal", "-shm"):
                if os.path.exists(os.path.join(self.args.out, "vmac.db" + ext)):
                    shutil.copy(os.path.join(self.args.out, "vmac.db" + ext), self.state)
            return ()
        self.store_on_tmpfs = True
        script = ('mount -t tmpfs -o size=%s tmpfs "$0" && cp "$1"/vmac.db* "$0"/ && '
                  'avail=$(df -k --output=avail "$0" | tail -1) && '
                  'fallocate -l $(( (avail - %d) * 1024 )) "$0"/filler && shift && exec "$@"'
                  % (TMPFS_SIZE, self.args.store_free_kib))
        return ("unshare", "--mount", "--propagation", "private", "sh", "-c", script, self.state, self.args.out)

    def in_host_ns(self, path):
        """path as the host sees it, through its mount namespace."""
        return "/proc/%d/root%s" % (self.pid, os.path.abspath(path))

    # -- the fault sources, each on its own thread --

    def start_victims(self):
        if self.victim_log is None:
            self.victim_log = open(os.path.join(self.args.out, "victims.log"), "a")
        self.victim_proc = subprocess.Popen(
            [self.ctx.path("vmac-board"), "--plant", "generic", "--name", "victim", "--driver", "victim",
             "--count", str(VICTIMS), "--bus", self.ctx.bus, "--key-dir", self.ctx.keys, "--quiet", "--late-us", "0"],
            stdin=subprocess.DEVNULL, stdout=self.victim_log, stderr=subprocess.STDOUT, start_new_session=True)

    def kill_victims(self):
        p, self.victim_proc = self.victim_proc, None
        if p:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait(10)

    def victims_loop(self):
        while not self.stop.wait(self.rnd.uniform(2, 4)):
            self.kill_victims()
            if self.stop.wait(0.3):
                break
            self.start_victims()
            self.counts["restarts"] += 1

    def reload_loop(self):
        n = 0
        while not self.stop.wait(RELOAD_S):
            n += 1
            code, body = self.api.request("POST", "/api/drivers/victim", self.deploy,
                                          (VICTIM_LUA % {"n": n}).encode(), timeout_s=30)
            key = str(code) if code else body.split(":")[0]
            self.reload_answers[key] = self.reload_answers.get(key, 0) + 1
            if code == 200:
                self.counts["reloads_ok"] += 1
                self.counts["reload_machines"] += sum(1 for m in json.loads(body).get("machines", []) if m["ok"])
            elif code == 507:
                self.counts["reloads_full"] += 1
                self.free_space()
            elif code == 409:
                # A machine refused the version: it names why; victims are
                # killed at any moment, so one may vanish mid-switch.
                self.notes.append("reload %d refused (409): %s" % (n, body[:300]))
            else:
                self.fail("reload %d answered %s: %s" % (n, code, body[:300]))

    def free_space(self):
        """The store is full: after 30 s of it, give back 1 MiB of the filler."""
        if not self.store_on_tmpfs or time.monotonic() - self.last_free < 30:
            return
        filler = self.in_host_ns(os.path.join(self.state, "filler"))
        try:
            size = os.stat(filler).st_size
            if size >= FREE_STEP_BYTES:
                os.truncate(filler, size - FREE_STEP_BYTES)
                self.counts["space_freed"] += 1
                self.last_free = time.monotonic()
        except OSError as e:
            self.notes.append("could not shrink the filler: %s" % e)

    def bad_token_loop(self):
        requests = [("GET", "/api/status"), ("GET", "/api/live"), ("GET", "/api/events"),
                    ("GET", "/api/whoami"), ("POST", "/api/drivers/victim"), ("POST", "/api/devices/washer-1/cycle"),
                    ("POST", "/api/console"), ("GET", "/api/events/log")]
        i = 0
        while not self.stop.wait(1.0 / BAD_TOKENS_PER_S):
            i += 1
            method, path = requests[i % len(requests)]
            token = self.bad_tokens[i % len(self.bad_tokens)]
            source = "127.0.1.%d" % (1 + i % 250)
            body = b'{"action": "start"}' if method == "POST" else None
            code, text = self.api.request(method, path, token, body, source=source)
            self.counts["bad_requests"] += 1
            if code in (401, 429):
                self.counts["bad_401"] += 1
            else:
                key = "%s %s with token %r: %s" % (method, path, token and token[:12], code or text)
                self.bad_other[key] = self.bad_other.get(key, 0) + 1

    def washer_loop(self):
        while not self.stop.wait(2):
            s = self.last_status
            d = next((d for d in s["devices"] if d["name"] == "washer-1"), None) if s else None
            if d and d["state"] == "running" and d["variables"].get("state") not in ("running", "paused"):
                code, body = self.api.request("POST", "/api/devices/washer-1/cycle", self.operate,
                                              b'{"action": "start", "program": "quick"}')
                if code == 200:
                    self.counts["washer_starts"] += 1
                elif code != 409:
                    self.notes.append("washer start answered %s: %s" % (code, body[:200]))

    def events_loop(self):
        """Every event from the stream: kinds counted, warnings by text,
        drops of healthy boards recorded."""
        after = 0
        self.events_log = open(os.path.join(self.args.out, "events.jsonl"), "w")
        while not self.stop.is_set():
            conn = http.client.HTTPConnection(self.api.host, self.api.port, timeout=20)
            try:
                conn.request("GET", "/api/events?after=%d" % after, headers={"Authorization": "Bearer " + self.token})
                r = conn.getresponse()
                while not self.stop.is_set():
                    line = r.fp.readline()
                    if not line:
                        break
                    if not line.startswith(b"data: "):
                        continue
                    e = json.loads(line[6:])
                    after = max(after, e["seq"])
                    self.event_kinds[e["kind"]] = self.event_kinds.get(e["kind"], 0) + 1
                    self.events_log.write(line[6:].decode("utf-8", "replace"))
                    if e["kind"] == "warning":
                        # One count per kind of warning: names and numbers left out.
                        text = re.sub(r"\b[a-z]+-\d+\b", "NAME", e["text"])
                        text = re.sub(r"\d+", "N", text)[:100]
                        self.warnings[text] = self.warnings.get(text, 0) + 1
                    if e["kind"] == "dropped" and e["device"] in HEALTHY:
                        self.healthy_drops.append(e["text"])
            except (OSError, http.client.HTTPException, ValueError):
                pass
            finally:
                conn.close()
            self.stop.wait(0.5)
        self.events_log.close()

    # -- watching the host --

    def poll_status(self):
        """Healthy boards: running, no host-caused miss. Called every second."""
        code, body = self.api.request("GET", "/api/status", self.token)
        if code != 200:
            self.notes.append("GET /api/status answered %s: %s" % (code, body[:200]))
            return
        s = json.loads(body)
        self.last_status = s
        self.counts["status_polls"] += 1
        for name in HEALTHY:
            d = next((d for d in s["devices"] if d["name"] == name), None)
            if d is None:
                bad = "%s is not in the status" % name
            elif d.get("misses_host", 0):
                bad = "%s: %d misses by the host's own fault (state %s)" % (name, d["misses_host"], d["state"])
            elif d["state"] != "running":
                bad = "%s %s after %d misses of its board or the wire (none the host's)" % (name, d["state"],
                                                                                            d["misses"])
            else:
                continue
            if bad not in self.healthy_bad:
                self.healthy_bad.append(bad)
                log("soak: " + bad)

    def read_smaps(self):
        """{mapping name: Rss KiB} of the host, anonymous mappings summed
        under [anon] (malloc arenas and LuaJIT's chunks are not told apart)."""
        out = {}
        name = None
        try:
            with open("/proc/%d/smaps" % self.pid) as f:
                for line in f:
                    fields = line.split()
                    if "-" in fields[0] and len(fields) >= 5 and not fields[0].endswith(":"):
                        name = fields[5] if len(fields) > 5 else "[anon]"
                        if name.startswith("/"):
                            name = os.path.basename(name)
                    elif fields[0] == "Rss:":
                        out[name] = out.get(name, 0) + int(fields[1])
        except OSError:
            pass
        return out

    def sample(self, elapsed_s):
        def status_field(name):
            with open("/proc/%d/status" % self.pid) as f:
                for line in f:
                    if line.startswith(name + ":"):
                        return int(line.split()[1])
            return 0

        def size(name):
            try:
                return os.stat(self.in_host_ns(os.path.join(self.state, name))).st_size
            except OSError:
                return 0

        s = {"t": elapsed_s, "rss_kib": status_field("VmRSS"), "anon_kib": status_field("RssAnon"),
             "file_kib": status_field("RssFile"), "fds": len(os.listdir("/proc/%d/fd" % self.pid)),
             "threads": status_field("Threads"), "db": size("vmac.db"), "wal": size("vmac.db-wal")}
        # Where the memory is, mapping by mapping, once after the warm-up and
        # at the end (the report names the mappings that grew).
        if not self.smaps_warm and elapsed_s >= WARMUP_FRACTION * self.seconds:
            self.smaps_warm = self.read_smaps()
        self.smaps_last = self.read_smaps()
        if self.store_on_tmpfs:
            st = os.statvfs(self.in_host_ns(self.state))
            s["free_kib"] = st.f_bavail * st.f_frsize // 1024
        st = self.last_status or {}
        s["malformed"] = st.get("counters", {}).get("malformed_frames", 0)
        self.samples.append(s)
        log("  %6.0f s  rss %7d KiB (anon %d)  fds %4d  threads %3d  db %6d KiB  wal %6d KiB%s  malformed %8d  "
            "restarts %4d  reloads %3d/%-3d  401s %5d" % (
                elapsed_s, s["rss_kib"], s["anon_kib"], s["fds"], s["threads"], s["db"] // 1024, s["wal"] // 1024,
                "  free %5d KiB" % s["free_kib"] if "free_kib" in s else "", s["malformed"],
                self.counts["restarts"], self.counts["reloads_ok"],
                self.counts["reloads_ok"] + self.counts["reloads_full"], self.counts["bad_401"]))

    # -- the run --

    def run(self):
        self.start()
        host0 = self.api.json("/api/status", self.token)
        self.malformed0 = host0["counters"]["malformed_frames"]
        self.junk_sent = self.mp.Value("q", 0)
        self.ui_counters = {k: self.mp.Value("q", 0) for k in
                            ("live_connects", "live_messages", "status_ok", "errors")}
        self.ui_errors = self.mp.Queue(1000)
        self.children = [
            self.mp.Process(target=junk_main, args=(self.bus_addr, self.args.seed, self.mp_stop,
                                                            self.junk_sent), daemon=True),
            self.mp.Process(target=ui_main, args=(self.host.http, self.token, self.args.seed, self.mp_stop,
                                                          self.ui_counters, self.ui_errors), daemon=True)]
        for c in self.children:
            c.start()
        threads = [threading.Thread(target=f, daemon=True) for f in
                   (self.victims_loop, self.reload_loop, self.bad_token_loop, self.washer_loop, self.events_loop)]
        for t in threads:
            t.start()
        log("soak: %g minutes; one line every %d s (warm-up: the first %d%%)" % (
            self.args.minutes, SAMPLE_S, WARMUP_FRACTION * 100))
        started = time.monotonic()
        next_sample = started + SAMPLE_S
        while True:
            now = time.monotonic()
            if not self.host.alive():
                self.fail("vmacd exited (code %s) %.0f s into the soak; its stderr ends: %s" % (
                    self.host.popen.poll(), now - started, self.host.text("stderr")[-600:]))
                break
            self.poll_status()
            if now >= next_sample:
                self.sample(now - started)
                next_sample += SAMPLE_S
            if now - started >= self.seconds:
                break
            time.sleep(min(1.0, max(0.0, next_sample - time.monotonic())))
        self.stop.set()
        self.mp_stop.set()
        for t in threads:
            t.join(40)
        for c in self.children:
            c.join(30)
        self.kill_victims()
        self.report(time.monotonic() - started)

    def report(self, elapsed_s):
        final = None
        if self.host.alive():
            code, body = self.api.request("GET", "/api/status", self.token)
            if code == 200:
                final = json.loads(body)
            else:
                self.fail("the host no longer answers GET /api/status: %s %s" % (code, body[:200]))
        elif not self.failures:
            self.fail("vmacd exited (code %s)" % self.host.popen.poll())

        log("")
        log("== soak report (%.1f minutes)" % (elapsed_s / 60))
        after = [s for s in self.samples if s["t"] >= WARMUP_FRACTION * self.seconds] or self.samples[-1:]
        window = max(1, len(after) // 10)
        growth = {}
        if after:
            log("  %-12s %10s %12s %8s   (median of the first and of the last %d samples after the warm-up)" % (
                "", "start", "end", "change", window))
            for key, label, div in (("rss_kib", "RSS KiB", 1), ("fds", "descriptors", 1), ("threads", "threads", 1),
                                    ("db", "vmac.db KiB", 1024), ("wal", "-wal KiB", 1024)):
                a = statistics.median(s[key] for s in after[:window]) / div
                b = statistics.median(s[key] for s in after[-window:]) / div
                pct = (b - a) * 100.0 / a if a else 0.0
                growth[key] = (a, b, pct)
                log("  %-12s %10.0f %12.0f %+7.1f%%" % (label, a, b, pct))
            if self.smaps_warm and self.smaps_last:
                grew = sorted(((self.smaps_last.get(k, 0) - self.smaps_warm.get(k, 0), k)
                               for k in set(self.smaps_warm) | set(self.smaps_last)), reverse=True)
                log("  RSS by mapping, warm-up -> end: " + ", ".join(
                    "%s %+d KiB" % (k, d) for d, k in grew if abs(d) >= 64) or "no mapping changed by 64 KiB")
            peak = max(self.samples, key=lambda s: s["rss_kib"])
            log("  peak rss %d KiB at %.0f s; fds %d..%d, threads %d..%d over the whole run" % (
                peak["rss_kib"], peak["t"], min(s["fds"] for s in self.samples), max(s["fds"] for s in self.samples),
                min(s["threads"] for s in self.samples), max(s["threads"] for s in self.samples)))
        if final:
            log("  host uptime %.0f s; tick lateness p50 %s p99 %s max %s us, skipped %s" % (
                final["uptime_s"], final["tick"]["lateness_us"]["p50"], final["tick"]["lateness_us"]["p99"],
                final["tick"]["lateness_us"]["max"], final["tick"]["skipped"]))
            for name in HEALTHY:
                d = next((d for d in final["devices"] if d["name"] == name), {})
                log("  %-9s %-8s served %8d  misses %3d  misses_host %d" % (
                    name, d.get("state"), d.get("served", 0), d.get("misses", 0), d.get("misses_host", 0)))
                if d.get("misses_host", 0):
                    self.fail("%s: %d misses by the host's own fault" % (name, d["misses_host"]))
            c = final["counters"]
            log("  malformed datagrams: %d sent, the host counted %d (%s)" % (
                self.junk_sent.value, c["malformed_frames"] - self.malformed0,
                ", ".join("%s %d" % kv for kv in sorted(c["malformed_by_reason"].items()) if kv[1])))
            log("  host counters: misses %d (misses_host %d), late replies %d, drops %d, events lost %d" % (
                c["misses"], c.get("misses_host", 0), c["late_replies"], c["drops"], c["events_lost"]))
        n = self.counts
        log("  victims: %d board restarts (SIGKILL, %d boards each)" % (n["restarts"], VICTIMS))
        log("  reloads: %d switched (%d machine switches), %d refused 507 (store full), answers %s" % (
            n["reloads_ok"], n["reload_machines"], n["reloads_full"], json.dumps(self.reload_answers)))
        log("  bad tokens: %d requests, %d refused (401 or 429)%s" % (
            n["bad_requests"], n["bad_401"], "; others: " + json.dumps(self.bad_other) if self.bad_other else ""))
        u = {k: v.value for k, v in self.ui_counters.items()}
        log("  UI clients: %d /api/live connections, %d messages, %d GET /api/status, %d errors" % (
            u["live_connects"], u["live_messages"], u["status_ok"], u["errors"]))
        ui_errors = []
        while True:
            try:
                ui_errors.append(self.ui_errors.get_nowait())
            except Exception:
                break
        for e in ui_errors[:5]:
            log("    " + e)
        log("  washer: %d programmes started" % n["washer_starts"])
        log("  events: %s" % json.dumps(dict(sorted(self.event_kinds.items()))))
        for text, count in sorted(self.warnings.items(), key=lambda kv: -kv[1]):
            log("  warning x%d: %s" % (count, text))
        if self.store_on_tmpfs:
            log("  store: tmpfs %s, %d KiB left at the start, 1 MiB given back %d times when full" % (
                TMPFS_SIZE, self.args.store_free_kib, n["space_freed"]))
        for note in self.notes[:10]:
            log("  note: " + note)
        if len(self.notes) > 10:
            log("  note: ... and %d more" % (len(self.notes) - 10))

        # Pass or fail.
        if n["bad_requests"] == 0 or n["bad_401"] != n["bad_requests"]:
            self.fail("%d of %d bad-token requests were not refused (401 or 429): %s" % (
                n["bad_requests"] - n["bad_401"], n["bad_requests"], json.dumps(self.bad_other)[:500]))
        for bad in self.healthy_bad:
            if "host's own fault" in bad or "not in the status" in bad:
                self.fail("healthy board: " + bad)
        for text in self.healthy_drops:
            log("  a healthy board was dropped (its board's or the wire's miss, not the host's): " + text)
        if u["errors"] > 0:
            self.fail("the UI clients met %d errors (first: %s)" % (u["errors"], ui_errors[:1]))
        unsafe = self.boards["washer-1"].find_lines(r"UNSAFE")
        if unsafe:
            self.fail("the washer's plant saw an unsafe door: %s" % unsafe[0].text)
        if n["reloads_ok"] == 0:
            self.fail("no reload of the victims' driver succeeded")
        if self.junk_sent.value < 0.5 * JUNK_PER_S * elapsed_s:
            self.fail("only %d malformed datagrams went out in %.0f s" % (self.junk_sent.value, elapsed_s))
        if growth:
            strict = self.args.minutes >= 30
            rss_a, rss_b, rss_pct = growth["rss_kib"]
            fd_a, fd_b, fd_pct = growth["fds"]
            if strict:
                if rss_pct > 5:
                    self.fail("RSS grew %.1f%% after the warm-up (%.0f -> %.0f KiB; goal: within 5%%)" % (
                        rss_pct, rss_a, rss_b))
                if fd_pct > 5:
                    self.fail("open descriptors grew %.1f%% after the warm-up (%.0f -> %.0f; goal: within 5%%)" % (
                        fd_pct, fd_a, fd_b))
            else:
                log("  (a run under 30 minutes is too short to judge 5%: it fails only on RSS +50% or "
                    "descriptors +50)")
                if rss_pct > 50:
                    self.fail("RSS grew %.1f%% after the warm-up (%.0f -> %.0f KiB)" % (rss_pct, rss_a, rss_b))
                if fd_b - fd_a > 50:
                    self.fail("open descriptors grew by %.0f after the warm-up (%.0f -> %.0f)" % (
                        fd_b - fd_a, fd_a, fd_b))

    def cleanup(self):
        self.stop.set()
        self.mp_stop.set()
        for c in self.children:
            c.join(5)
            if c.is_alive():
                c.terminate()
                c.join(5)
        self.kill_victims()
        if self.victim_log:
            self.victim_log.close()
        if hasattr(self, "ctx"):
            # vmacd's mount namespace, and its tmpfs, go with it.
            self.ctx.cleanup()


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bin", default="build/bin")
    p.add_argument("--minutes", type=float, default=float(os.environ.get("SOAK_MINUTES", 60)))
    p.add_argument("--out", default="build/soak", help="logs and the staging state folder (emptied first)")
    p.add_argument("--store-free-kib", type=int, default=1024, help="space left on the store's tmpfs at the start")
    p.add_argument("--seed", type=int, default=random.SystemRandom().randrange(1 << 31))
    args = p.parse_args()
    args.bin = os.path.abspath(args.bin)
    args.out = os.path.abspath(args.out)
    log("soak: seed %d, logs in %s" % (args.seed, args.out))
    soak = Soak(args)

    def on_term(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    signal.signal(signal.SIGINT, signal.default_int_handler)  # also when started with SIGINT ignored
    try:
        soak.run()
    except KeyboardInterrupt:
        log("soak: interrupted; stopping everything")
        return 130
    except Exception as e:
        soak.fail("the soak itself broke: %s: %s" % (type(e).__name__, e))
    finally:
        soak.cleanup()
    if soak.failures:
        log("soak FAILED:")
        for f in soak.failures:
            log("  - " + f)
        return 1
    log("soak passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
