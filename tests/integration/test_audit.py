"""The audit trail (docs/API.md "Audit trail", docs/MQTT.md "Audit"),
against a real vmacd with simulated boards: every kind of request that
changes something is one audit event, in the documented format, naming the
token's id, name and scope and the client's address: operator input, a
param persisted, cycles, the console's :, > and !, a recording, reload,
rollback, activate, a board enrolled and removed, `vmac token create
--name` and `revoke`, a lock-out, a command refused for its scope; an MQTT
command and a Sparkplug DCMD through a real Mosquitto, each published on
PREFIX/HOST/audit for Home Assistant's event entity. A flood of 2,000
refused requests from 40 addresses makes a bounded number of events, and
the summaries account for every one not said. A full store fails no
request and loses no audit event: each is in the status and the stream at
once, the failure is said once, and the events reach the store when space
is back."""

import http.client
import json
import math
import os
import re
import subprocess
import threading
import time
import urllib.request

import test_mqtt as mq
import test_mqtt_ha as ha
import test_sparkplug as spb
from harness import LOADED, fill_state, small_state, until
from test_reload import counter

# docs/API.md "Audit trail": the format a program reads.
AUDIT = re.compile(r"^(?P<type>[a-z]+) by (?P<who>.+?) from (?P<where>\S+): (?P<what>.*) -> "
                   r"(?P<result>\d{3}|[a-z_]+)(?: \((?P<why>.*)\))?$")
SUMMARY = re.compile(r"^refused: and (\d+) more refused requests")
TYPES = ["input", "param", "cycle", "record", "console", "reload", "activate", "rollback", "board", "token",
         "lockout", "auth", "request", "refused"]


def parse(e):
    m = AUDIT.match(e["text"])
    assert m, "an audit event not in the documented format: %r" % e["text"]
    return dict(m.groupdict(), device=e["device"], seq=e["seq"], text=e["text"])


def named_token(t, scope, name, state=None):
    """A token of scope named name (vmac token create --name): (token, id)."""
    p = subprocess.run([t.path("vmac"), "token", "create", "--state", state or t.logdir, "--scope", scope, "--name",
                        name], capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, "vmac token create --name %s: exit %d %s" % (name, p.returncode, p.stderr)
    token = p.stdout.strip()
    return token, token.split("_")[1]


def call(host, method, path, token=None, body=None, content_type="application/json", source=None):
    """(HTTP status, the answer's text); source: the client's address."""
    conn = http.client.HTTPConnection(*host.http.rsplit(":", 1), timeout=60,
                                      source_address=(source, 0) if source else None)
    headers = {"Content-Type": content_type}
    if token:
        headers["Authorization"] = "Bearer " + token
    if isinstance(body, (dict, list)):
        body = json.dumps(body)
    try:
        conn.request(method, path, body=body, headers=headers)
        r = conn.getresponse()
        return r.status, r.read().decode()
    finally:
        conn.close()


def the_audit(host, after, what, timeout_s=10):
    """The one audit event after seq after whose text holds what (parsed);
    fails when there is none, or more than one."""
    host.wait_event("audit", text=what, after_seq=after, timeout_s=timeout_s)
    host.status()  # one more look: a second event of the same request would be there by now
    found = host.find_events("audit", text=what, after_seq=after)
    assert len(found) == 1, "%d audit events for %r: %s" % (len(found), what, [e["text"] for e in found])
    return parse(found[0])


def audited(host, after, code, what, kind, who, device, token=None, method="POST", path=None, body=None,
            content_type="application/json"):
    """Make the request, check its answer is code and that it made exactly
    one audit event of type kind by who from 127.0.0.1 about device whose
    WHAT holds what; the event (parsed)."""
    got, text = call(host, method, path, token, body, content_type)
    assert got == code, "%s %s: HTTP %d %s (wanted %d)" % (method, path, got, text[:300], code)
    e = the_audit(host, after, what)
    assert (e["type"], e["who"], e["where"], e["result"], e["device"]) == (kind, who, "127.0.0.1", str(code), device), \
        "%s %s was audited as %r" % (method, path, e["text"])
    return e


def test_every_kind_of_request_is_one_audit_event_with_its_token(t):
    # A worker preempted mid-call on a busy machine (no realtime in tests,
    # ASan) must not fail the washer with the 2 ms wall-clock budget: this
    # test is about the audit trail, not the budget.
    host = t.host(drivers=t.drivers(counter=counter("1.0.0")), settings={"driver_budget_us": 20000})
    t.board("washer", "washer-1")
    t.board("lights", "lights-1")
    t.board("lights", "lamp-1", driver="counter")
    host.wait_running(["washer-1", "lights-1", "lamp-1"])
    alice, alice_id = named_token(t, "deploy", "alice")
    who = 'token %s "alice" (deploy)' % alice_id

    def one(code, kind, path, body, what, device, content_type="application/json"):
        return audited(host, host.last_event_seq(), code, what, kind, who, device, alice, path=path, body=body,
                       content_type=content_type)

    one(200, "input", "/api/devices/washer-1/input", {"name": "program", "value": "quick"},
        "POST /api/devices/washer-1/input washer-1.program:quick", "washer-1")
    one(200, "param", "/api/devices/washer-1/input", {"name": "program", "value": "normal", "persist": True},
        "POST /api/devices/washer-1/input washer-1.program>normal", "washer-1")
    one(200, "cycle", "/api/devices/washer-1/cycle", {"action": "start", "program": "quick"},
        "POST /api/devices/washer-1/cycle washer-1.start:quick", "washer-1")
    e = one(409, "cycle", "/api/devices/washer-1/cycle", {"action": "start"},
            "POST /api/devices/washer-1/cycle washer-1.start!", "washer-1")
    assert "already running" in (e["why"] or ""), "a refused cycle does not say why: %r" % e["text"]
    one(200, "cycle", "/api/devices/washer-1/cycle", {"action": "cancel"},
        "POST /api/devices/washer-1/cycle washer-1.cancel!", "washer-1")
    one(200, "console", "/api/console", "washer-1.state? washer-1.program:quick washer-1.program>quick lamp-1.relay:true",
        "POST /api/console washer-1.program:quick washer-1.program>quick lamp-1.relay:true", "washer-1",
        "text/plain")
    one(200, "console", "/api/console", "lights-1.kitchen:true\nlights-1.all_off! washer-1.sauna:1",
        "POST /api/console lights-1.kitchen:true lights-1.all_off! washer-1.sauna#3", "lights-1", "text/plain")
    # A console of reads only changes nothing: no event (the input after it is the next one).
    after = host.last_event_seq()
    assert call(host, "POST", "/api/console", alice, "washer-1.state? washer-1.program?", "text/plain")[0] == 200
    one(200, "input", "/api/devices/lamp-1/input", {"name": "relay", "value": False},
        "POST /api/devices/lamp-1/input lamp-1.relay:false", "lamp-1")
    assert not host.find_events("audit", text="POST /api/console", after_seq=after), "a console of reads was audited"
    one(200, "record", "/api/devices/washer-1/record", "", "POST /api/devices/washer-1/record", "washer-1")

    # Deploys: audited by the dispatcher, the query as it came.
    answer = []
    for version in ("2.0.0", "3.0.0"):
        after = host.last_event_seq()
        code, text = call(host, "POST", "/api/drivers/counter?probation=0", alice, counter(version), "text/x-lua")
        assert code == 200, "uploading %s: %d %s" % (version, code, text)
        answer.append(json.loads(text))
        e = the_audit(host, after, "POST /api/drivers/counter?probation=0")
        assert (e["type"], e["who"], e["result"], e["device"]) == ("reload", who, "200", "counter"), e["text"]
    one(200, "rollback", "/api/drivers/counter/rollback", "", "POST /api/drivers/counter/rollback", "counter")
    one(200, "activate", "/api/drivers/counter/activate?id=%d&probation=0" % answer[1]["id"], "",
        "POST /api/drivers/counter/activate?id=%d&probation=0" % answer[1]["id"], "counter")
    e = one(200, "board", "/api/boards/spare-1", {}, "POST /api/boards/spare-1 enroll spare-1 key ", "spare-1")
    assert re.search(r"key [0-9a-f]{16}", e["what"]), "the enrolled key's fingerprint: %r" % e["text"]
    one(200, "board", "/api/boards/spare-1/remove", "", "POST /api/boards/spare-1/remove remove spare-1", "spare-1")

    # A token of too small a scope: refused (its body unread), audited with its own name and scope.
    rita, rita_id = named_token(t, "read", "rita")
    e = audited(host, host.last_event_seq(), 403, "POST /api/devices/washer-1/input -> 403", "input",
                'token %s "rita" (read)' % rita_id, "washer-1", rita, path="/api/devices/washer-1/input",
                body={"name": "program", "value": "quick"})
    assert "scope operate" in e["why"], "a 403 does not say why: %r" % e["text"]

    # vmac token create --name and revoke, in another process: into the host's log.
    after = host.last_event_seq()
    bob, bob_id = named_token(t, "operate", "bob")
    e = the_audit(host, after, 'vmac token create %s "bob" (operate)' % bob_id)
    assert (e["type"], e["where"], e["result"]) == ("token", "local", "ok") and e["who"].startswith('user "'), \
        e["text"]
    assert re.match(r"at \d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ$", e["why"] or ""), "when it was done: %r" % e["text"]
    for rc_wanted, result in ((0, "ok"), (1, "refused")):
        after = host.last_event_seq()
        p = subprocess.run([t.path("vmac"), "token", "revoke", bob_id, "--state", t.logdir], capture_output=True,
                           text=True, timeout=30)
        assert p.returncode == rc_wanted, "vmac token revoke: exit %d %s" % (p.returncode, p.stderr)
        e = the_audit(host, after, 'vmac token revoke %s "bob"' % bob_id)
        assert (e["type"], e["result"]) == ("token", result), e["text"]
    assert call(host, "GET", "/api/status", bob)[0] == 401, "the revoked token still works"

    # vmac board enroll --local and remove --local, on the store itself: the same way.
    for argv, what in ((["enroll", "--local", "shed", "--out", os.path.join(t.logdir, "shed.key")],
                        "vmac board enroll shed key "), (["remove", "--local", "shed"], "vmac board remove shed")):
        after = host.last_event_seq()
        p = subprocess.run([t.path("vmac"), "board"] + argv + ["--state", t.logdir], capture_output=True, text=True,
                           timeout=30)
        assert p.returncode == 0, "vmac board %s: exit %d %s" % (" ".join(argv), p.returncode, p.stderr)
        e = the_audit(host, after, what)
        assert (e["type"], e["where"], e["result"]) == ("board", "local", "ok") and e["who"].startswith('user "'), \
            e["text"]

    # A lock-out: the tenth wrong secret for one token id, once.
    after = host.last_event_seq()
    guessed = "%016x" % 0xA0D17
    for i in range(11):
        call(host, "GET", "/api/status", "vmac_%s_%064x" % (guessed, i))
    e = the_audit(host, after, "locked out (429)")
    assert (e["type"], e["who"], e["result"]) == ("lockout", "token %s (not valid)" % guessed, "401"), e["text"]
    assert "10 failed attempts with token %s" % guessed in e["why"], e["text"]

    # Every audit event of the run is in the format, and the log has them all.
    audits = [parse(e) for e in host.find_events("audit")]
    assert {a["type"] for a in audits} >= {"input", "param", "cycle", "console", "record", "reload", "rollback",
                                           "activate", "board", "token", "lockout", "auth"}, \
        sorted({a["type"] for a in audits})

    def missing():  # the main loop copies them into the store
        logged = {e["seq"] for e in host.get("/api/events/log?after=0&limit=1000")["events"] if e["kind"] == "audit"}
        return {a["seq"] for a in audits} - logged

    until(lambda: not missing(), 10, lambda: "every audit event in the store's log (missing: %s)" % sorted(missing()),
          poll_s=0.1)


def test_mqtt_commands_are_audited_and_every_audit_event_goes_to_the_broker(t):
    broker = mq.Broker(t)
    host = spb.spb_host(t, broker)
    hub = mq.Hub(broker)  # before the board: it sees the machine's DBIRTH (not retained)
    try:
        hub.subscribed.wait(10)
        t.board("lights", "lights-1")
        host.wait_running(["lights-1"])
        topic = "%s/event/%s/audit/config" % (mq.DISCOVERY, mq.HOST_ID)
        cfg = json.loads(hub.wait(topic, lambda p: p != "", what="the audit entity's config"))
        ha.check_config(topic, cfg)  # every rule of Home Assistant's that applies (test_mqtt_ha.py)
        assert cfg["event_types"] == TYPES and cfg["state_topic"] == mq.PREFIX + "/audit", cfg
        hub.wait(mq.PREFIX + "/lights-1/kitchen", what="the kitchen light's value")
        hub.wait(spb.NODE % "DBIRTH" + "/lights-1", what="the lights' DBIRTH")

        since, after = hub.mark(), host.last_event_seq()
        hub.publish(mq.PREFIX + "/lights-1/set/kitchen", "true")
        e = the_audit(host, after, mq.PREFIX + "/lights-1/set/kitchen lights-1.kitchen:true")
        assert (e["type"], e["where"], e["result"], e["device"]) == ("input", broker.url, "ok", "lights-1"), e["text"]
        assert re.match(r'mqtt client "[^"]+"$', e["who"]), "who, over MQTT: %r" % e["text"]
        got = json.loads(hub.wait(mq.PREFIX + "/audit", lambda p: json.loads(p)["seq"] == e["seq"], since=since,
                                  what="the audit event on MQTT"))
        assert got == {"event_type": "input", "seq": e["seq"], "time": got["time"], "device": "lights-1",
                       "text": e["text"]}, got
        with hub.cond:
            assert not hub.latest[mq.PREFIX + "/audit"][1], "an audit event retained (HA ignores retained events)"

        after = host.last_event_seq()
        hub.publish(mq.PREFIX + "/lights-1/set/sauna", "1")
        e = the_audit(host, after, mq.PREFIX + "/lights-1/set/sauna lights-1.sauna:1")
        assert e["result"] == "refused" and "sauna" in e["why"], e["text"]

        after = host.last_event_seq()
        hub.publish(spb.NODE % "DCMD" + "/lights-1", spb.command([("dining", spb.BOOLEAN, True)]))
        e = the_audit(host, after, spb.NODE % "DCMD" + "/lights-1 lights-1.dining:true")
        assert e["result"] == "ok" and re.match(r'mqtt client "[^"]+-spb"$', e["who"]), e["text"]

        # An HTTP request's audit event goes out too, typed for the entity.
        since = hub.mark()
        code, _ = call(host, "POST", "/api/devices/lights-1/input", t.token, {"name": "tv", "value": True})
        assert code == 200
        got = json.loads(hub.wait(mq.PREFIX + "/audit", lambda p: "lights-1.tv:true" in p, since=since,
                                  what="an HTTP request's audit event on MQTT"))
        assert got["event_type"] == "input" and got["event_type"] in cfg["event_types"], got
    finally:
        hub.close()


def refused_request(host, tokens, source, n):
    """Request n of the flood, from address source: one of four refusals.
    Its HTTP status."""
    read_token, op_token = tokens
    kind = n % 4
    if kind == 0:
        return call(host, "GET", "/api/status", source=source)[0]  # no token: 401, then 429
    if kind == 1:
        return call(host, "GET", "/api/status", "vmac_%016x_%064x" % (n, n), source=source)[0]  # unknown: 401
    if kind == 2:
        return call(host, "POST", "/api/devices/lights-1/input", read_token, {"name": "kitchen", "value": True},
                    source=source)[0]  # too small a scope: 403
    return call(host, "POST", "/api/devices/nowhere/input", op_token, {"name": "kitchen", "value": True},
                source=source)[0]  # no such machine: 404


def flood(host, tokens, n_threads, per_thread, addresses):
    """n_threads x per_thread refused requests from addresses in turn, in
    threads of their own (started here; the caller joins them). The second
    list gets every request that was not refused (none should be)."""
    accepted = []

    def worker(w):
        for i in range(per_thread):
            n = w * per_thread + i
            try:
                code = refused_request(host, tokens, addresses[n % len(addresses)], n)
            except OSError as e:
                code = "no answer: %s" % e
            if not isinstance(code, int) or code < 400:
                accepted.append(code)

    threads = [threading.Thread(target=worker, args=(w,), daemon=True) for w in range(n_threads)]
    for th in threads:
        th.start()
    return threads, accepted


def test_a_flood_of_refused_requests_makes_a_bounded_number_of_events(t):
    """2,000 refused requests (no token, wrong tokens, too small a scope,
    no such device) from 40 addresses, while the operator works: every
    request of the operator is said, the refusals at most 30 (+10
    lock-outs) every 10 s, and the windows' summaries count the rest, so
    that said + summarised = 2,000 exactly."""
    total, n_threads = 2000, 8
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    reader, _ = named_token(t, "read", "reader")
    op, op_id = named_token(t, "operate", "op")
    start_seq = host.last_event_seq()
    addresses = ["127.0.0.%d" % (10 + i) for i in range(40)]
    t0 = time.monotonic()
    threads, accepted = flood(host, (reader, op), n_threads, total // n_threads, addresses)
    for i in range(5):  # the operator's own requests meanwhile
        code, text = call(host, "POST", "/api/devices/lights-1/input", op, {"name": "tv", "value": i % 2 == 0})
        assert code == 200, "the operator's request during the flood: %d %s" % (code, text)
    for th in threads:
        th.join(120)
    elapsed = time.monotonic() - t0
    assert not accepted, "refused requests that were accepted: %s" % accepted[:5]
    # The last window ends 10 s after its first refusal, by the host's
    # clock, and the main loop then says its summary: awaited.
    events, after = [], start_seq
    deadline = time.monotonic() + 60 * LOADED
    while True:
        page = host.get("/api/events/log?after=%d&limit=1000" % after)["events"]
        events += page
        after = page[-1]["seq"] if page else after
        audits = [e for e in events if e["kind"] == "audit"]
        summaries = [e for e in audits if SUMMARY.match(e["text"])]
        said = [parse(e) for e in audits if not SUMMARY.match(e["text"])]
        mine = [e for e in said if e["result"] == "200"]
        refusals = [e for e in said if e["result"] not in ("200", "ok")]  # not the operator's, not vmac token's
        unsaid = sum(int(SUMMARY.match(e["text"]).group(1)) for e in summaries)
        if len(refusals) + unsaid >= total or time.monotonic() > deadline:
            break
        if not page:
            time.sleep(0.5)
    windows = math.ceil(elapsed / 10.0) + 1
    print("  %d refused requests in %.1f s: %d audit events said, %d summaries of the %d not said "
          "(at most %d events in %d windows of 10 s)" % (total, elapsed, len(refusals), len(summaries), unsaid,
                                                        41 * windows, windows))
    assert len(mine) == 5 and all(e["who"] == 'token %s "op" (operate)' % op_id for e in mine), \
        "the operator's requests in the audit trail: %s" % [e["text"] for e in mine]
    assert len(refusals) + unsaid == total, "%d said + %d summarised, not the %d refused" % (
        len(refusals), unsaid, total)
    assert len(refusals) <= 40 * windows and len(summaries) <= windows, \
        "%d refusals and %d summaries said in %.1f s" % (len(refusals), len(summaries), elapsed)
    assert {e["where"] for e in refusals} <= set(addresses), "a refusal from elsewhere"
    assert host.alive(), "vmacd died under the flood"


def test_a_full_store_fails_no_request_and_loses_no_audit_event(t):
    """The state folder on a 1 MiB tmpfs of its own (a mount namespace, as
    tests/integration/test_store.py), filled while the host runs: input is
    answered as ever, each request's audit event is in the status and the
    stream at once, the failure to store events is said once and counted,
    and the events reach the store when space is back."""
    op, op_id = named_token(t, "operate", "panel")  # in the test's state folder: copied below
    state, wrapper = small_state(t)
    host = t.host(wrapper=wrapper, extra=("--state", state), settings={"bus_trust": "open"})
    t.board("lights", "lights-1", keyed=False)
    host.wait_running(["lights-1"])
    fill_state(host, state)
    failed_before = disk_full_failures(host)

    def inputs(n):
        """n inputs, each answered 200 and at once in the status's events."""
        seqs = []
        for i in range(n):
            after = host.last_event_seq()
            code, text = call(host, "POST", "/api/devices/lights-1/input", op, {"name": "tv", "value": i % 2 == 0})
            assert code == 200, "input with the store's disk full: HTTP %d %s" % (code, text)
            e = the_audit(host, after, "lights-1.tv:%s -> 200" % ("true" if i % 2 == 0 else "false"))
            assert e["who"] == 'token %s "panel" (operate)' % op_id, e["text"]
            seqs.append(e["seq"])
        return seqs

    first = host.last_event_seq()
    seqs = []

    def said_full():  # the WAL's room left before the disk fills within a few writes
        if host.find_events("warning", text="events are not being stored", after_seq=first):
            return True
        seqs.extend(inputs(1))
        return False

    until(said_full, 60, "the store saying it could not store events", poll_s=0)
    seqs += inputs(10)  # with the store failing all the while
    warned = host.find_events("warning", text="events are not being stored", after_seq=first)
    assert len(warned) == 1 and "full" in warned[0]["text"], "the failure said %d times: %s" % (
        len(warned), [w["text"] for w in warned])
    assert disk_full_failures(host) > failed_before, "vmac_store_failures_total{reason=\"disk_full\"} did not count"
    streamed = stream_audits(host, first, len(seqs))
    assert set(seqs) <= streamed, "audit events missing from the event stream: %s" % sorted(set(seqs) - streamed)

    subprocess.run(["nsenter", "-t", str(host.popen.pid), "-m", "rm", "-f", os.path.join(state, "fill")],
                   capture_output=True, timeout=30)

    def unstored():
        return set(seqs) - {e["seq"] for e in host.get("/api/events/log?after=%d&limit=1000" % first)["events"]}

    until(lambda: not unstored(), 30, lambda: "every audit event stored once there was space (not: %s)" % sorted(
        unstored()), poll_s=0.2)
    assert host.alive(), "vmacd died on a full disk"


def disk_full_failures(host):
    req = urllib.request.Request("http://%s/metrics" % host.http)
    req.add_header("Authorization", "Bearer " + host.ctx.token)
    with urllib.request.urlopen(req, timeout=10) as r:
        text = r.read().decode()
    m = re.search(r'^vmac_store_failures_total\{reason="disk_full"\} (\d+)', text, re.M)
    assert m, "no vmac_store_failures_total{reason=\"disk_full\"} in GET /metrics"
    return int(m.group(1))


def stream_audits(host, after, want, timeout_s=10):
    """The seqs of the audit events GET /api/events sends after seq after
    (until want of them came, or timeout_s times the harness's LOADED)."""
    req = urllib.request.Request("http://%s/api/events?after=%d" % (host.http, after))
    req.add_header("Authorization", "Bearer " + host.ctx.token)
    seqs = set()
    timeout_s *= LOADED
    deadline = time.monotonic() + timeout_s
    with urllib.request.urlopen(req, timeout=timeout_s) as r:
        while len(seqs) < want and time.monotonic() < deadline:
            line = r.readline().decode()
            if line.startswith("data: "):
                e = json.loads(line[6:])
                if e["kind"] == "audit":
                    seqs.add(e["seq"])
    return seqs
