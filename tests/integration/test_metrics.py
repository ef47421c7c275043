"""GET /metrics (docs/API.md, "Metrics") scraped by the real Prometheus
server (Debian's prometheus package: /usr/bin/prometheus, with its own
storage in the test's folder, a 1 s scrape interval and a bearer token
from a file), then asked through its query API: the kitchen's series agree
with GET /api/status, a board whose process is killed is dropped and its
series change as Prometheus sees them, a stopped host is up == 0, and every
PromQL expression of the example Grafana dashboard
(docs/grafana/vmac-dashboard.json) parses and runs. Beside it: promtool
check metrics on a scraped body, the boards' clock series there exactly
for the boards whose status has a clock, the token the route needs, the listener
without a token (metrics_http) and the MQTT client's series. Without
prometheus (promtool comes with it) every test here is SKIPPED (a failure
under CI=true)."""

import json
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.parse
import urllib.request

from harness import KITCHEN_NAMES, Skip, until

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DASHBOARD = os.path.join(ROOT, "docs", "grafana", "vmac-dashboard.json")
CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
# The dashboard's panels that have data with the kitchen running (the
# others may be empty: no MQTT, no reload, no failure).
DASHBOARD_WITH_DATA = ("Version", "Up for", "Boards running", "Scrape", "Tick lateness (from the histogram)",
                       "Served frames per second, by machine", "Driver memory", "Driver time (share of a CPU)",
                       "HTTP requests per second, by status", "Store", "variable instance", "variable machine")
POLL_S = 0.2  # between two questions to Prometheus
WAIT_S = 30  # for something Prometheus scrapes every second to show


def tool(name):
    for p in (shutil.which(name), "/usr/bin/" + name):
        if p and os.access(p, os.X_OK):
            return p
    raise Skip("the metrics tests need Prometheus's %s (Debian package prometheus; make deps installs it)" % name)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def scrape(addr, token=None, path="/metrics", method="GET"):
    """(status, Content-Type, body text) of method path on addr, token or none."""
    req = urllib.request.Request("http://%s%s" % (addr, path), method=method)
    if token:
        req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.headers.get("Content-Type"), r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.headers.get("Content-Type"), e.read().decode()


def samples(body):
    """{(name, frozenset of (label, value)): value} of a text exposition."""
    out = {}
    for line in body.splitlines():
        if not line or line.startswith("#"):
            continue
        m = re.match(r'^([a-zA-Z_:][a-zA-Z0-9_:]*)(?:\{(.*)\})? (\S+)$', line)
        assert m, "not a sample line of the text format: %r" % line
        labels = frozenset(re.findall(r'([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\]|\\.)*)"', m.group(2) or ""))
        out[(m.group(1), labels)] = float(m.group(3))
    return out


def promtool_check(body):
    p = subprocess.run([tool("promtool"), "check", "metrics"], input=body, capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0 and not p.stdout.strip() and not p.stderr.strip(), (
        "promtool check metrics is not clean (exit %d): %s %s" % (p.returncode, p.stdout, p.stderr))


class Prometheus:
    """The Prometheus server scraping host's GET /metrics every second with
    token (from a file, as a deployment would keep it), on a free port
    with its storage in the test's folder."""

    def __init__(self, t, host, token):
        exe = tool("prometheus")
        self.port = free_port()
        folder = os.path.join(t.logdir, "prometheus")
        os.makedirs(folder)
        token_file = os.path.join(folder, "token")
        with open(token_file, "w") as f:
            f.write(token + "\n")
        config = os.path.join(folder, "prometheus.yml")
        with open(config, "w") as f:
            f.write("global:\n  scrape_interval: 1s\n  scrape_timeout: 1s\n"
                    "scrape_configs:\n"
                    "  - job_name: vmac\n"
                    "    metrics_path: /metrics\n"
                    "    authorization:\n      type: Bearer\n      credentials_file: %s\n"
                    "    static_configs:\n      - targets: ['%s']\n" % (token_file, host.http))
        self.proc = t.start([exe, "--config.file=" + config, "--storage.tsdb.path=" + os.path.join(folder, "data"),
                             "--web.listen-address=127.0.0.1:%d" % self.port, "--log.level=warn"], "prometheus")

        def ready():
            try:
                with urllib.request.urlopen("http://127.0.0.1:%d/-/ready" % self.port, timeout=5) as r:
                    if r.status == 200:
                        return True
            except (OSError, urllib.error.URLError):
                pass
            if not self.proc.alive():
                raise AssertionError("prometheus exited before it became ready on port %d: %s" % (
                    self.port, self.proc.text()[-500:]))
            return False

        until(ready, 30, lambda: "prometheus ready on port %d (its output: %s)" % (self.port, self.proc.text()[-500:]),
              poll_s=0.05)

    def query(self, expr):
        """The answer of /api/v1/query for expr: (status, result, error)."""
        url = "http://127.0.0.1:%d/api/v1/query?%s" % (self.port, urllib.parse.urlencode({"query": expr}))
        try:
            with urllib.request.urlopen(url, timeout=10) as r:
                a = json.loads(r.read())
        except urllib.error.HTTPError as e:
            a = json.loads(e.read())
        return a["status"], a.get("data", {}).get("result"), a.get("error")

    def vector(self, expr):
        """{frozenset of labels (without __name__): value} of an instant query."""
        status, result, error = self.query(expr)
        assert status == "success", "Prometheus refused %r: %s" % (expr, error)
        return {frozenset((k, v) for k, v in r["metric"].items() if k != "__name__"): float(r["value"][1])
                for r in result}

    def wait(self, expr, predicate, what, timeout_s=WAIT_S):
        """Ask expr until predicate(vector) holds; returns that vector."""
        last = [None]

        def look():
            last[0] = self.vector(expr)
            return [last[0]] if predicate(last[0]) else None  # in a list: an empty vector may be what is awaited

        return until(look, timeout_s, lambda: "Prometheus: %s (%s = %s)" % (what, expr, last[0]), poll_s=POLL_S)[0]

    def fresh(self, expr, after_s, what):
        """expr's vector once every sample in it was scraped after the Unix
        time after_s (and there is one): an instant query's own time is when
        it was asked, timestamp() is the sample's."""
        self.wait("timestamp(%s)" % expr, lambda v: v and all(ts > after_s for ts in v.values()), what)
        return self.vector(expr)


def one(vector, what):
    assert len(vector) == 1, "%s: expected one series, got %s" % (what, vector)
    return next(iter(vector.values()))


def dashboard_exprs(values):
    """Every PromQL expression of the example dashboard (title, expr), with
    Grafana's variables put as a query would get them: values[name], or
    .* (all of them) for a variable not in values."""
    with open(DASHBOARD) as f:
        board = json.load(f)
    exprs = []

    def walk(panels):
        for p in panels:
            walk(p.get("panels", []))
            for target in p.get("targets", []):
                if target.get("expr"):
                    exprs.append((p.get("title", "?"), target["expr"]))

    walk(board["panels"])
    for var in board.get("templating", {}).get("list", []):
        if var.get("type") == "query":
            q = var.get("query")
            q = q.get("query") if isinstance(q, dict) else q
            m = re.match(r"^label_values\((.*),\s*\w+\)$", q or "")
            exprs.append(("variable " + var["name"], m.group(1) if m else q))
    out = []
    for title, e in exprs:
        e = e.replace("$__rate_interval", "1m").replace("$__interval", "15s").replace("$__range", "1h")
        e = re.sub(r"\$\{?(\w+)\}?", lambda m: values.get(m.group(1), ".*"), e)
        out.append((title, e))
    return out


def board_clocks_agree(got, before, after):
    """A board's clock series (vmac_board_clock_*) are there exactly for the
    boards whose status has a clock (one sent a TIMED reply), with its state
    1 and the four others 0; none for a board whose clock is null. A clock
    is never unknown again once known: the status before the scrape says
    who must have one, the status after who cannot."""
    by_board = {}
    for (name, labels), value in got.items():
        if name.startswith("vmac_board_clock_") or name == "vmac_board_services_total":
            by_board.setdefault(dict(labels)["board"], []).append((name, dict(labels), value))
    for d in after["devices"]:
        if d.get("clock") is None:
            assert d["name"] not in by_board, "%s has no clock, but series %s" % (d["name"], by_board[d["name"]])
    for d in before["devices"]:
        if d.get("clock") is None:
            continue
        series = by_board.get(d["name"], [])
        states = {lab["state"]: v for n, lab, v in series if n == "vmac_board_clock_state"}
        assert sorted(states) == sorted(["unsynced", "locking", "locked", "holdover", "lost"]), series
        assert sum(states.values()) == 1, "%s's clock states: %s" % (d["name"], states)
        timing = {lab["timing"] for n, lab, v in series if n == "vmac_board_services_total"}
        assert timing == {"timed", "arrival"}, series


def test_metrics_of_the_kitchen_through_prometheus(t):
    tool("promtool")
    host = t.host()
    boards = t.kitchen(host)
    prom = Prometheus(t, host, t.make_token("read"))
    prom.wait('up{job="vmac"}', lambda v: v and one(v, "up") == 1, "the host scraped (up == 1)")

    # What Prometheus holds agrees with the status: the status before a
    # scrape, the scraped value, the status after (counters only grow).
    before, t0 = host.status(), time.time()
    served = prom.fresh('vmac_device_served_total', t0 + 0.2, "the boards' served frames, scraped after the status")
    ticks = one(prom.vector('vmac_ticks_total'), "vmac_ticks_total")
    # One sample of lateness a tick, both from one scrape.
    lateness = one(prom.vector('vmac_tick_lateness_seconds_count - vmac_ticks_total'), "lateness count - ticks")
    malformed = one(prom.vector('sum(vmac_malformed_frames_total)'), "malformed frames")
    after = host.status()
    assert {dict(k)["board"] for k in served} == set(KITCHEN_NAMES), "served frames of %s" % served
    for labels, value in served.items():
        lab = dict(labels)
        name = lab["board"]
        d0, d1 = host.device(name, before), host.device(name, after)
        assert d0["served"] <= value <= d1["served"], "%s served %d in Prometheus, %d then %d in the status" % (
            name, value, d0["served"], d1["served"])
        assert lab.get("driver") == d1["driver"] and lab.get("machine") == d1["machine"], (
            "%s's labels %s, the status says driver %s machine %s" % (name, lab, d1["driver"], d1["machine"]))
    assert before["tick"]["count"] <= ticks <= after["tick"]["count"], "ticks %d, status %d then %d" % (
        ticks, before["tick"]["count"], after["tick"]["count"])
    running = prom.vector('vmac_devices{state="running"}')
    assert one(running, "running devices") == 3, "vmac_devices{state=running} is %s" % running
    states = prom.vector('vmac_device_state')
    assert {(dict(k)["board"], dict(k)["state"]) for k in states} == {(n, "running") for n in KITCHEN_NAMES}, (
        "device states in Prometheus: %s" % sorted(states))
    versions = prom.vector('vmac_driver_info')
    for name in KITCHEN_NAMES:
        d = host.device(name, after)
        assert (frozenset({("machine", name), ("driver", d["driver"]), ("version", d["driver_version"]),
                           ("job", "vmac"), ("instance", host.http)}) in versions), (
            "no vmac_driver_info for %s %s %s: %s" % (name, d["driver"], d["driver_version"], versions))
    memory = prom.vector('vmac_driver_memory_bytes')
    assert len(memory) == 3 and all(v > 0 for v in memory.values()), "driver memory: %s" % memory
    attached = one(prom.vector('vmac_events_total{kind="attached"}'), "attached events")
    assert attached >= 3, "vmac_events_total{kind=attached} is %d" % attached
    assert before["counters"]["malformed_frames"] <= malformed <= after["counters"]["malformed_frames"]
    assert lateness == 0, "the lateness histogram counts %+d samples beside the ticks" % lateness
    assert prom.vector('vmac_http_requests_total{code="200"}'), "no HTTP 200 answers counted"

    # The example dashboard: every expression parses and runs; those of the
    # kitchen's panels have data.
    exprs = dashboard_exprs({"instance": host.http})
    assert len(exprs) >= 20, "the dashboard holds only %d expressions" % len(exprs)
    for title, e in exprs:
        status, result, error = prom.query(e)
        assert status == "success", "the dashboard's %r: Prometheus refused %r: %s" % (title, e, error)
    for title, e in exprs:
        if title in DASHBOARD_WITH_DATA:
            prom.wait(e, lambda v: v and all(not math.isnan(x) for x in v.values()),
                      "data for the dashboard's %r" % title)
    quantile = prom.vector('histogram_quantile(0.99, sum by (le) (rate(vmac_tick_lateness_seconds_bucket[1m])))')
    assert 0 <= one(quantile, "p99") <= 0.1, "tick lateness p99 from the histogram: %s" % quantile

    # A board whose process dies is dropped: its series change as
    # Prometheus sees them (its machine's are gone, its state is errant,
    # its drops one more in the same series).
    drops = one(prom.vector('vmac_drops_total'), "drops")
    washer_drops = prom.vector('vmac_device_drops_total{board="washer-1"}')
    assert len(washer_drops) == 1, "washer-1's drops: %s" % washer_drops
    boards["washer-1"].kill()
    host.wait_status(lambda s: host.device("washer-1", s)["state"] == "errant", 30, "washer-1 dropped")
    prom.wait('vmac_device_state{board="washer-1"}',
              lambda v: [dict(k)["state"] for k in v] == ["errant"], "washer-1's state errant, and only that")
    prom.wait('vmac_driver_memory_bytes{machine="washer-1"}', lambda v: not v, "washer-1's machine's series gone")
    prom.wait('vmac_drops_total', lambda v: v and one(v, "drops") >= drops + 1, "one more drop")
    prom.wait('vmac_device_drops_total{board="washer-1"}',
              lambda v: v.keys() == washer_drops.keys() and one(v, "drops") == one(washer_drops, "drops") + 1,
              "washer-1's drops one more, in the same series")
    prom.wait('vmac_devices{state="running"}', lambda v: v and one(v, "running") == 2, "two devices running")
    assert host.device("washer-1")["drops"] == one(washer_drops, "drops") + 1, "the status's drops of washer-1"

    # A scraped body passes promtool's own checks (format and naming lint).
    before = host.status()
    code, ctype, body = scrape(host.http, t.token)
    after = host.status()
    assert code == 200 and ctype == CONTENT_TYPE, "GET /metrics: %d %s" % (code, ctype)
    promtool_check(body)
    board_clocks_agree(samples(body), before, after)

    # The host stops: Prometheus says so.
    host.signal(signal.SIGTERM)
    host.wait_exit(30)
    prom.wait('up{job="vmac"}', lambda v: v and one(v, "up") == 0, "up == 0 once the host stopped")


def test_metrics_need_a_read_token_as_the_status_does(t):
    # Every scope includes read: a token without it is one the store does
    # not hold (none, malformed) or no longer honours (revoked).
    host = t.host()
    read = t.make_token("read")
    code, ctype, body = scrape(host.http, read)
    assert code == 200 and ctype == CONTENT_TYPE, "GET /metrics with a read token: %d %s %.200s" % (
        code, ctype, body)
    assert re.search(r"^vmac_build_info\{version=\"\d+\.\d+\.\d+\"\} 1$", body, re.M), "no vmac_build_info"
    revoked = t.make_token("read")
    p = subprocess.run([t.path("vmac"), "token", "revoke", revoked.split("_")[1], "--state", t.logdir],
                       capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, "vmac token revoke: %s" % p.stderr
    for what, token in (("no token", None), ("a malformed token", "vmac_nonsense"), ("a revoked token", revoked)):
        status = scrape(host.http, token, "/api/status")
        metrics = scrape(host.http, token)
        assert metrics[0] == 401 == status[0], "%s: GET /metrics %d, GET /api/status %d" % (
            what, metrics[0], status[0])
        assert "vmac_" not in metrics[2], "%s: GET /metrics answered metrics: %.200s" % (what, metrics[2])
    code, _, _ = scrape(host.http, read, method="POST")
    assert code == 404, "POST /metrics: %d (no such endpoint)" % code
    counts = samples(scrape(host.http, read)[2])
    assert counts.get(("vmac_http_requests_total", frozenset({("code", "401")})), 0) >= 6, (
        "401 answers not counted: %s" % {k: v for k, v in counts.items() if k[0] == "vmac_http_requests_total"})


def test_metrics_listener_without_a_token_and_mqtt_series(t):
    import test_mqtt  # its broker and the way it finds mosquitto (SKIPPED without)
    broker = test_mqtt.Broker(t)
    host = t.host(settings={"metrics_http": "127.0.0.1:0", "mqtt_url": broker.url, "mqtt_host_id": "metrics"})
    line = host.wait_line(r"metrics at http://127\.0\.0\.1:(\d+)/metrics without a token", 30, stream="stderr",
                          what="the metrics_http listener's event")
    addr = "127.0.0.1:%s" % re.search(r":(\d+)/metrics", line.text).group(1)
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    conn = frozenset({("connection", "main")})
    last = {}

    def connected():
        code, ctype, body = scrape(addr)
        assert code == 200 and ctype == CONTENT_TYPE, "GET /metrics on metrics_http: %d %s" % (code, ctype)
        m = last["m"] = samples(body)
        if m.get(("vmac_mqtt_connected", conn)) == 1 and m.get(("vmac_mqtt_messages_published_total", conn), 0) > 0 \
                and m.get(("vmac_device_state", frozenset({("machine", "lights-1"), ("board", "lights-1"),
                                                            ("driver", "lights"), ("state", "running")}))) == 1:
            return body
        return None

    body = until(connected, WAIT_S, lambda: "MQTT connected and publishing, lights-1 running (last seen: %s)" % {
        k: v for k, v in last["m"].items() if k[0].startswith("vmac_mqtt") or k[0] == "vmac_device_state"},
        poll_s=POLL_S)
    promtool_check(body)
    assert scrape(addr, path="/api/status")[0] == 404, "metrics_http serves more than /metrics"
    assert scrape(addr, method="POST")[0] == 405, "metrics_http takes a POST"
    assert scrape(host.http)[0] == 401, "GET /metrics on the API without a token (metrics_http is another address)"
    broker.kill()

    def disconnected():
        last["connected"] = samples(scrape(addr)[2]).get(("vmac_mqtt_connected", conn))
        return last["connected"] == 0

    until(disconnected, WAIT_S, lambda: "vmac_mqtt_connected 0 after the broker was killed (still %s)" % (
        last["connected"]), poll_s=POLL_S)
