"""Sparkplug B (docs/MQTT.md, "Sparkplug B") against a real broker: Debian's
mosquitto started by each test (test_mqtt.py's Broker), a paho-mqtt client
as the Sparkplug host application. Payloads are decoded and commands encoded
here by a small protobuf reader and writer that use the specification's
field numbers (Payload: timestamp 1, metrics 2, seq 3; Metric: name 1,
timestamp 3, datatype 4, is_historical 5, is_null 7, int 10, long 11, float
12, double 13, boolean 14, string 15), not vmacd's own .proto: a wrong field number there
fails here. Every payload the node published is decoded again by Eclipse
Tahu's JavaScript codec (npm sparkplug-payload, pinned in
tests/mqtt/tahu/package-lock.json, run through tests/mqtt/tahu/codec.mjs)
and must agree with the test's reader, and one DCMD is encoded by Tahu.
Covered: NBIRTH (bdSeq, Node Control/Rebirth, seq 0), a DBIRTH
per kitchen machine with its metrics and datatypes, DDATA when a light is
switched, seq 0..255 across every message of the node and its wrap from
255 to 0, DCMD switching a
light (and refused, or ignored with commands off), NCMD Rebirth, malformed
DCMDs refused while the host runs on, a dropped board's DDEATH, the NDEATH
the broker publishes for a killed vmacd with the bdSeq of its NBIRTH, and
bdSeq counting on across a restart. SKIPPED without mosquitto or paho."""

import base64
import json
import os
import shutil
import signal
import struct
import subprocess
import threading
import time

from harness import KITCHEN_NAMES, LOADED, Skip, undisturbed, until
from test_mqtt import HOST_ID, PREFIX, Broker, paho

GROUP = "plant"
NODE = "spBv1.0/%s/%%s/%s" % (GROUP, HOST_ID)
BOOLEAN, INT64, UINT64, DOUBLE, STRING = 11, 4, 8, 10, 12


# ---- protobuf, by hand (the wire format: varints and length-delimited fields) ----

def varint(data, i):
    shift = value = 0
    while True:
        if i >= len(data) or shift > 63:
            raise ValueError("truncated varint")
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return value, i


def fields(data):
    """(field number, wire type, value) of a message; bytes for length-delimited."""
    i, out = 0, []
    while i < len(data):
        key, i = varint(data, i)
        num, wt = key >> 3, key & 7
        if wt == 0:
            v, i = varint(data, i)
        elif wt == 1:
            v, i = data[i:i + 8], i + 8
        elif wt == 2:
            n, i = varint(data, i)
            v, i = data[i:i + n], i + n
        elif wt == 5:
            v, i = data[i:i + 4], i + 4
        else:
            raise ValueError("wire type %d" % wt)
        out.append((num, wt, v))
    return out


def decode_metric(data):
    m = {}
    for num, wt, v in fields(data):
        if num == 1:
            m["name"] = v.decode()
        elif num == 3:
            m["timestamp"] = v
        elif num == 4:
            m["datatype"] = v
        elif num == 5:
            m["is_historical"] = bool(v)
        elif num == 7:
            m["is_null"] = bool(v)
        elif num in (10, 11):
            m["value"] = v
        elif num == 12:
            m["value"] = struct.unpack("<f", v)[0]
        elif num == 13:
            m["value"] = struct.unpack("<d", v)[0]
        elif num == 14:
            m["value"] = bool(v)
        elif num == 15:
            m["value"] = v.decode()
    return m


def decode(data):
    p = {"metrics": []}
    for num, wt, v in fields(data):
        if num == 1:
            p["timestamp"] = v
        elif num == 2:
            p["metrics"].append(decode_metric(v))
        elif num == 3:
            p["seq"] = v
    p["by_name"] = {m.get("name"): m for m in p["metrics"]}
    return p


def enc_varint(n):
    out = b""
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out += bytes([b | 0x80])
        else:
            return out + bytes([b])


def enc_field(num, wt, v):
    key = enc_varint(num << 3 | wt)
    if wt == 0:
        return key + enc_varint(v)
    if wt == 1:
        return key + v
    return key + enc_varint(len(v)) + v


def command(metrics):
    """An NCMD/DCMD payload: timestamp and metrics (name, datatype, value)."""
    body = enc_field(1, 0, int(time.time() * 1000))
    for name, datatype, value in metrics:
        m = enc_field(1, 2, name.encode()) if name is not None else b""
        m += enc_field(4, 0, datatype)
        if isinstance(value, bool):
            m += enc_field(14, 0, int(value))
        elif isinstance(value, float):
            m += enc_field(13, 1, struct.pack("<d", value))
        elif isinstance(value, int):
            m += enc_field(11, 0, value)
        elif isinstance(value, str):
            m += enc_field(15, 2, value.encode())
        body += enc_field(2, 2, m)
    return body


# ---- Eclipse Tahu's codec (tests/mqtt/tahu/codec.mjs) ----

TAHU = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "mqtt", "tahu")
TAHU_TYPES = {"Boolean": BOOLEAN, "Int64": INT64, "UInt64": UINT64, "Double": DOUBLE, "String": STRING}


def tahu(requests):
    """Tahu's answers to requests ({"decode": bytes} or {"encode": payload}),
    in order: one node process for all of them."""
    node = shutil.which("node")
    if not node or not os.path.isdir(os.path.join(TAHU, "node_modules", "sparkplug-payload")):
        raise Skip("Eclipse Tahu's codec is not installed (node and npm ci in tests/mqtt/tahu: "
                   "tests/npm_ci.sh tests/mqtt/tahu 12, which make test-integration runs)")
    lines = "".join(json.dumps(dict(r, decode=base64.b64encode(r["decode"]).decode()) if "decode" in r else r) + "\n"
                    for r in requests)
    p = subprocess.run([node, os.path.join(TAHU, "codec.mjs")], input=lines, capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 0, "Tahu's codec failed: %s" % p.stderr[-2000:]
    out = [json.loads(line) for line in p.stdout.splitlines()]
    assert len(out) == len(requests), "Tahu answered %d of %d requests: %s" % (len(out), len(requests), p.stderr)
    return out


def tahu_agrees(raw_messages):
    """Every (topic, payload) decoded by Tahu, field by field as the test's
    reader decoded it: seq, timestamp, and each metric's name, datatype and
    value. Returns how many payloads and metrics were compared."""
    births, requests = {}, []
    for topic, data in raw_messages:  # a host's view: DDATA's datatypes are its device's DBIRTH's
        parts = topic.split("/")
        if parts[2] == "DBIRTH":
            births[parts[4]] = {m["name"]: m["datatype"] for m in decode(data)["metrics"]}
        requests.append({"decode": data, "births": births.get(parts[4], {})} if parts[2] == "DDATA" else
                        {"decode": data})
    answers = tahu(requests)
    metrics = 0
    for (topic, data), a, r in zip(raw_messages, answers, requests):
        assert a["ok"], "Tahu cannot decode the %s payload %s: %s" % (topic, data.hex(), a["error"])
        ours, theirs = decode(data), a["payload"]
        assert ("seq" in ours) == ("seq" in theirs) and int(theirs.get("seq", -1)) == ours.get("seq", -1), \
            "%s: seq %s by Tahu, %s by the test's reader" % (topic, theirs.get("seq"), ours.get("seq"))
        assert int(theirs["timestamp"]) == ours["timestamp"], "%s: timestamps differ: %s" % (topic, theirs)
        assert len(theirs.get("metrics", [])) == len(ours["metrics"]), "%s: metric counts differ" % topic
        for m, t in zip(ours["metrics"], theirs.get("metrics", [])):
            what = "%s metric %s" % (topic, m.get("name"))
            if "datatype" not in m:  # DDATA: the type its birth gave
                m = dict(m, datatype=r.get("births", {}).get(m["name"]))
            assert t["name"] == m["name"] and TAHU_TYPES.get(t["type"]) == m["datatype"], \
                "%s: Tahu reads name %r type %s, the test's reader %r datatype %s" % (
                    what, t["name"], t["type"], m["name"], m["datatype"])
            assert ("timestamp" in t) == ("timestamp" in m) and int(t.get("timestamp", -1)) == m.get("timestamp", -1), \
                "%s: timestamp %s by Tahu, %s" % (what, t.get("timestamp"), m.get("timestamp"))
            if m.get("is_null"):
                assert t["value"] is None, "%s: null for the test's reader, %r for Tahu" % (what, t["value"])
            elif m["datatype"] in (INT64, UINT64):
                assert int(t["value"]) == m["value"], "%s: %s by Tahu, %s" % (what, t["value"], m["value"])
            elif m["datatype"] == DOUBLE:
                assert abs(t["value"] - m["value"]) <= 1e-9 * max(1.0, abs(m["value"])), (what, t, m)
            else:
                assert t["value"] == m["value"], "%s: %r by Tahu, %r by the test's reader" % (what, t["value"], m["value"])
            metrics += 1
    return len(answers), metrics


# ---- a Sparkplug host application ----

class SpHost:
    """Subscribed to spBv1.0/# and PREFIX/#: every message in order, raw."""

    def __init__(self, broker, user=None, password=None):
        mqtt = paho()
        self.cond = threading.Condition()
        self.log = []
        self.c = mqtt.Client(client_id="sphost-%d" % os.getpid())
        if user:
            self.c.username_pw_set(user, password)
        self.c.on_message = self._on_message
        self.c.on_connect = lambda c, u, f, rc: (c.subscribe("spBv1.0/#", qos=1), c.subscribe(PREFIX + "/#", qos=1))
        self.c.connect("127.0.0.1", broker.port, keepalive=30)
        self.c.loop_start()

    def _on_message(self, c, u, m):
        with self.cond:
            self.log.append((m.topic, bytes(m.payload), m.retain, m.qos))
            self.cond.notify_all()

    def publish(self, topic, payload, qos=0, retain=False):
        self.c.publish(topic, payload, qos=qos, retain=retain).wait_for_publish()

    def mark(self):
        with self.cond:
            return len(self.log)

    def wait(self, topic, predicate=lambda p: True, since=0, timeout_s=30, what=None, raw=False):
        """The first message on topic from log index since on whose decoded
        payload satisfies predicate; (payload, index). Waits LOADED times
        timeout_s, as the harness's waits."""
        deadline = time.monotonic() + timeout_s * LOADED
        with self.cond:
            i = since
            while True:
                while i < len(self.log):
                    tp, data, _, _ = self.log[i]
                    i += 1
                    if tp == topic:
                        p = data.decode("utf-8", "replace") if raw else decode(data)
                        if predicate(p):
                            return p, i
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError("no %s on %s within %.0f s (topics seen: %s)" % (
                        what or "matching message", topic, timeout_s * LOADED,
                        sorted({tp for tp, _, _, _ in self.log if tp.startswith("spBv1.0")})))
                self.cond.wait(min(left, 0.5))

    def node_messages(self):
        """(type, device, payload, retain, qos) of every message the node
        published, in order (not the commands sent to it)."""
        out = []
        with self.cond:
            log = list(self.log)
        for tp, data, retain, qos in log:
            parts = tp.split("/")
            if len(parts) >= 4 and parts[:2] == ["spBv1.0", GROUP] and parts[3] == HOST_ID and \
                    parts[2] not in ("NCMD", "DCMD"):
                out.append((parts[2], parts[4] if len(parts) > 4 else None, decode(data), retain, qos))
        return out

    def node_raw(self):
        """(topic, payload bytes) of every message the node published."""
        with self.cond:
            return [(tp, data) for tp, data, _, _ in self.log if tp.startswith("spBv1.0/%s/" % GROUP) and
                    tp.split("/")[3:4] == [HOST_ID] and tp.split("/")[2] not in ("NCMD", "DCMD")]

    def close(self):
        self.c.loop_stop()
        self.c.disconnect()


def spb_host(t, broker, commands=True, extra=None):
    settings = {"mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_keepalive_s": 5, "miss_limit": 3,
                "mqtt_commands": "true" if commands else "false", "mqtt_sparkplug": "true",
                "mqtt_sparkplug_group": GROUP}
    settings.update(extra or {})
    return t.host(settings=settings)


def has_value(metric_name, value):
    return lambda p: p["by_name"].get(metric_name, {}).get("value") == value


def check_seq(messages):
    """seq: NBIRTH 0, then one more per message of the node (mod 256);
    NDEATH without one. Every timestamp, the payload's and each metric's,
    ms since the epoch in UTC: within 5 minutes of this machine's clock (the
    TCK's window for an NBIRTH)."""
    prev = None
    now_ms = time.time() * 1000
    for kind, device, p, retain, qos in messages:
        assert not retain, "%s %s published retained" % (kind, device)
        for ts in [p.get("timestamp")] + [m.get("timestamp") for m in p["metrics"]]:
            assert ts is not None and abs(ts - now_ms) < 300000, \
                "%s %s: a timestamp %s is not UTC ms now (%d)" % (kind, device, ts, now_ms)
        if kind == "NDEATH":
            assert "seq" not in p, "an NDEATH with a seq: %s" % p
            continue
        assert "seq" in p and "timestamp" in p, "%s %s without seq or timestamp: %s" % (kind, device, p)
        if kind == "NBIRTH":
            assert p["seq"] == 0, "NBIRTH seq %d" % p["seq"]
        elif prev is not None:
            assert p["seq"] == (prev + 1) % 256, "%s %s seq %d after %d" % (kind, device, p["seq"], prev)
        prev = p["seq"]


def check_session(messages):
    """check_seq, and what the births promise of every message of the node:
    the NBIRTH's metrics are the node's only ones (bdSeq and Node
    Control/Rebirth) and no NDATA comes (tck-id-topics-nbirth-metric-reqs,
    tck-id-operational-behavior-data-publish-nbirth); an NDEATH holds bdSeq
    alone (tck-id-topics-ndeath-payload); each DDATA metric is one of its
    device's DBIRTH in that session (tck-id-topics-dbirth-metric-reqs,
    tck-id-operational-behavior-data-publish-dbirth); no metric is
    historical, and each metric's timestamps go forward in the order the
    messages came (tck-id-operational-behavior-data-publish-nbirth-order,
    -dbirth-order)."""
    check_seq(messages)
    born, last = {}, {}
    for kind, device, p, retain, qos in messages:
        names = [m.get("name") for m in p["metrics"]]
        assert kind != "NDATA", "an NDATA, but the NBIRTH says the node has no metric of its own to report: %s" % p
        if kind == "NBIRTH":
            assert sorted(names) == ["Node Control/Rebirth", "bdSeq"], "the NBIRTH's metrics: %s" % names
            born = {}  # a new session: every device is born again
        elif kind == "NDEATH":
            assert names == ["bdSeq"], "an NDEATH's metrics: %s (only bdSeq)" % names
        elif kind == "DBIRTH":
            born[device] = set(names)
        elif kind == "DDEATH":
            born.pop(device, None)
        elif kind == "DDATA":
            assert device in born, "a DDATA of %s without its DBIRTH in the session" % device
            assert set(names) <= born[device], "DDATA metrics of %s its DBIRTH did not have: %s" % (
                device, sorted(set(names) - born[device]))
        for m in p["metrics"]:
            assert not m.get("is_historical"), "%s %s: a metric marked historical: %s" % (kind, device, m)
            if kind != "NDEATH":  # the will's time is its CONNECT's
                key = (device, m.get("name"))
                assert m["timestamp"] >= last.get(key, 0), "%s %s: metric %s at %d, after one at %d" % (
                    kind, device, key[1], m["timestamp"], last[key])
                last[key] = m["timestamp"]


def test_sparkplug_births_ddata_dcmd_rebirth_and_ndeath(t):
    broker = Broker(t)
    sp = SpHost(broker)
    host = spb_host(t, broker)
    t.kitchen(host)
    try:
        nbirth, _ = sp.wait(NODE % "NBIRTH", what="NBIRTH")
        assert nbirth["seq"] == 0, nbirth
        bdseq = nbirth["by_name"]["bdSeq"]
        assert bdseq["datatype"] == INT64 and isinstance(bdseq["value"], int), bdseq
        rebirth = nbirth["by_name"]["Node Control/Rebirth"]
        assert rebirth["datatype"] == BOOLEAN and rebirth["value"] is False, rebirth
        # A DBIRTH per machine with every variable and param; the lights'
        # switches are Booleans from their first birth (device_class
        # "switch" says their kind before any value does).
        lights, _ = sp.wait(NODE % "DBIRTH" + "/lights-1", what="lights DBIRTH")
        for name in ("kitchen", "dining", "tv", "disposal", "Commands/all_off"):
            assert lights["by_name"][name]["datatype"] == BOOLEAN, (name, lights["by_name"].get(name))
        kitchen = lights["by_name"]["kitchen"]  # off, or no value yet when born before the first tick
        assert kitchen.get("value") is False or (kitchen.get("is_null") and "value" not in kitchen), kitchen
        assert lights["by_name"]["Properties/Driver"]["value"].startswith("lights "), lights["by_name"]
        washer, _ = sp.wait(NODE % "DBIRTH" + "/washer-1", what="washer DBIRTH")
        w = washer["by_name"]
        assert w["temp_c"]["datatype"] == DOUBLE and w["level_l"]["datatype"] == DOUBLE, (w["temp_c"], w["level_l"])
        assert w["program"]["datatype"] == STRING and w["program"]["value"] == "normal", w["program"]
        assert w["fill_timeout_s"]["datatype"] == INT64, w["fill_timeout_s"]
        assert w["Commands/start"]["datatype"] == BOOLEAN, w.get("Commands/start")
        for m in washer["metrics"]:
            assert "name" in m and "datatype" in m and "timestamp" in m, "a DBIRTH metric lacks name/type/time: %s" % m
        sp.wait(NODE % "DBIRTH" + "/dish-1", what="dishwasher DBIRTH")

        if "value" not in kitchen:  # born before the first tick: its values come first, in a DDATA of their own
            sp.wait(NODE % "DDATA" + "/lights-1", has_value("kitchen", False), what="the lights' first values")

        # DCMD: the kitchen light on, through the bus; DDATA says so.
        mark = sp.mark()
        sp.publish(NODE % "DCMD" + "/lights-1", command([("kitchen", BOOLEAN, True)]))
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is True, 30,
                         "the kitchen light's output on after a DCMD", undisturbed(KITCHEN_NAMES))
        ddata, _ = sp.wait(NODE % "DDATA" + "/lights-1", has_value("kitchen", True), since=mark, what="DDATA kitchen")
        assert "dining" not in ddata["by_name"], "report by exception: %s" % ddata
        for m in ddata["metrics"]:  # the birth said it (tck-id-payloads-metric-datatype-not-req)
            assert "datatype" not in m and "timestamp" in m, "a DDATA metric with a datatype: %s" % m

        # Refused (out of range, read-only) and malformed DCMDs: published back, nothing changes, no crash.
        def refused(payload, code, what):
            m = sp.mark()
            sp.publish(NODE % "DCMD" + "/washer-1", payload)
            body, _ = sp.wait(PREFIX + "/washer-1/_error", since=m, raw=True, what="an error for " + what)
            body = json.loads(body)
            assert body["code"] == code and body["topic"] == NODE % "DCMD" + "/washer-1", "%s: %s" % (what, body)
            # And on record in the host's audit trail (docs/MQTT.md "Audit").
            audit = host.wait_event("audit", text=" -> %s (" % code, after_seq=seen[0], timeout_s=10)
            assert NODE % "DCMD" + "/washer-1" in audit["text"] and "-spb\"" in audit["text"], (
                "%s: the audit event does not say it was a DCMD on the Sparkplug connection: %r" % (
                    what, audit["text"]))
            seen[0] = audit["seq"]

        seen = [host.last_event_seq()]

        before = host.device("washer-1", host.status())["params"]["time_scale"]
        refused(command([("time_scale", DOUBLE, 99.0)]), "refused", "a param out of range")
        refused(command([("level_l", DOUBLE, 3.0)]), "refused", "a read-only variable")
        refused(b"\x12\xff\xff\xff\xff\x0f", "malformed", "a length beyond the payload")
        refused(b"\xff" * 20, "malformed", "garbage")
        refused(command([(None, BOOLEAN, True)]), "malformed", "a metric without a name")
        refused(command([("program", 99, "quick")]), "malformed", "an unknown datatype")
        refused(b"\x12" + enc_varint(1100) + b"\x0a" * 1100, "malformed", "a payload over 1024 bytes")
        refused(command([]), "malformed", "no metrics")
        assert host.device("washer-1", host.status())["params"]["time_scale"] == before, "a refusal changed a param"
        mark = sp.mark()
        sp.publish(NODE % "DCMD" + "/washer-1", command([("program", STRING, "quick")]))
        sp.wait(NODE % "DDATA" + "/washer-1", has_value("program", "quick"), since=mark, what="program set by DCMD")

        # A DCMD encoded by Eclipse Tahu's codec is obeyed like the test's own.
        encoded = tahu([{"encode": {"timestamp": int(time.time() * 1000),
                                    "metrics": [{"name": "dining", "type": "Boolean", "value": True}]}}])[0]
        assert encoded["ok"], "Tahu cannot encode a DCMD: %s" % encoded
        mark = sp.mark()
        sp.publish(NODE % "DCMD" + "/lights-1", base64.b64decode(encoded["b64"]))
        sp.wait(NODE % "DDATA" + "/lights-1", has_value("dining", True), since=mark, what="DDATA dining (Tahu's DCMD)")

        # NCMD Rebirth: NBIRTH (seq 0, the same bdSeq) and every DBIRTH again.
        mark = sp.mark()
        sp.publish(NODE % "NCMD", command([("Node Control/Rebirth", BOOLEAN, True)]))
        again, i = sp.wait(NODE % "NBIRTH", since=mark, what="NBIRTH after Rebirth")
        assert again["seq"] == 0 and again["by_name"]["bdSeq"]["value"] == bdseq["value"], again
        for name in KITCHEN_NAMES:
            sp.wait(NODE % "DBIRTH" + "/" + name, since=i, what="DBIRTH of %s after Rebirth" % name)
        sp.publish(NODE % "NCMD", b"\x0a\x0b garbage")  # malformed NCMD: nothing but an event

        # The TV switched a few times (slower than the status copy is read,
        # so none is conflated away): a DDATA each, seq one more each time.
        since = sp.mark()
        for n in range(6):
            sp.publish(NODE % "DCMD" + "/lights-1", command([("tv", BOOLEAN, n % 2 == 0)]))
            _, since = sp.wait(NODE % "DDATA" + "/lights-1", has_value("tv", n % 2 == 0), since=since,
                               what="DDATA tv %d" % n)
        messages = sp.node_messages()
        check_session(messages)
        tv = [p["seq"] for k, d, p, r, q in messages if k == "DDATA" and "tv" in p["by_name"]]
        assert len(tv) >= 6, "a DDATA per switch of the TV: %s" % tv
        host.status()
        undisturbed(KITCHEN_NAMES)(host.last)

        # Killed: the broker publishes the will, an NDEATH with the NBIRTH's bdSeq.
        mark = sp.mark()
        host.signal(signal.SIGKILL)
        host.wait_exit(10)
        ndeath, _ = sp.wait(NODE % "NDEATH", since=mark, what="the NDEATH will")
        assert ndeath["by_name"]["bdSeq"] == dict(bdseq, timestamp=ndeath["by_name"]["bdSeq"]["timestamp"]), \
            "the NDEATH's bdSeq (name, Int64, value) is not the NBIRTH's: %s, %s" % (ndeath, bdseq)
        assert "seq" not in ndeath, ndeath
        assert [q for k, d, p, r, q in sp.node_messages() if k == "NDEATH"] == [1], "the NDEATH QoS"
        check_session(sp.node_messages())
        # Every payload again through Eclipse Tahu's decoder: it reads what the test's reader read.
        payloads, metrics = tahu_agrees(sp.node_raw())
        assert payloads >= 10 and metrics >= 50, "only %d payloads and %d metrics compared" % (payloads, metrics)
    finally:
        sp.close()


def test_sparkplug_dropped_board_ddeath_commands_off_and_bdseq_across_restarts(t):
    broker = Broker(t)
    sp = SpHost(broker)
    host = spb_host(t, broker, commands=False, extra={"miss_limit": 1})
    boards = t.kitchen(host)
    try:
        first, _ = sp.wait(NODE % "NBIRTH", what="NBIRTH")
        lights, _ = sp.wait(NODE % "DBIRTH" + "/lights-1",
                            lambda p: p["by_name"].get("kitchen", {}).get("datatype") == BOOLEAN, what="lights DBIRTH")
        assert "Commands/all_off" not in lights["by_name"], "command metrics with mqtt_commands off"
        # Commands off: a DCMD changes nothing.
        sp.publish(NODE % "DCMD" + "/lights-1", command([("kitchen", BOOLEAN, True)]))
        host.wait_status(lambda s: host.device("lights-1", s)["served"] > 30, 30, "lights-1 served a while")
        time.sleep(1.0)
        assert host.device("lights-1", host.status())["outputs"]["digital"][0] is False, \
            "a DCMD was obeyed with mqtt_commands off"
        # The washer's board stops answering: dropped, DDEATH; back, DBIRTH.
        mark = sp.mark()
        boards["washer-1"].signal(signal.SIGSTOP)
        try:
            host.wait_status(lambda s: host.device("washer-1", s)["state"] != "running", 30, "washer-1 dropped")
            ddeath, _ = sp.wait(NODE % "DDEATH" + "/washer-1", since=mark, what="DDEATH of washer-1")
            assert ddeath["metrics"] == [] and "seq" in ddeath, ddeath
        finally:
            boards["washer-1"].signal(signal.SIGCONT)
        sp.wait(NODE % "DBIRTH" + "/washer-1", since=mark, timeout_s=60, what="DBIRTH of washer-1 again")
        check_session(sp.node_messages())
        # An orderly stop: DDEATHs and the NDEATH; the next start counts bdSeq on.
        mark = sp.mark()
        host.signal(signal.SIGTERM)
        assert host.wait_exit(20) == 0, "vmacd did not stop cleanly on SIGTERM"
        ndeath, i = sp.wait(NODE % "NDEATH", since=mark, what="NDEATH at an orderly stop")
        assert ndeath["by_name"]["bdSeq"]["value"] == first["by_name"]["bdSeq"]["value"], ndeath
        assert [k for k, d, p, r, q in sp.node_messages()[-4:]].count("DDEATH") == 3, "a DDEATH per machine"
        check_session(sp.node_messages())
        host2 = spb_host(t, broker, commands=False)  # the same state folder: bdSeq counts on
        second, _ = sp.wait(NODE % "NBIRTH", since=i, what="NBIRTH after a restart")
        assert second["by_name"]["bdSeq"]["value"] == (first["by_name"]["bdSeq"]["value"] + 1) % 256, \
            (first["by_name"]["bdSeq"], second["by_name"]["bdSeq"])
        host2.status()
    finally:
        sp.close()


COUNTER_LUA = """
local driver = { name = "counter", version = "1.0.0", io = { do0 = "do0" },
                 variables = { n = { update = "auto" } } }
function driver.tick(dev, inputs)
    dev.state.n = (dev.state.n or 0) + 1
    dev.vars.n = dev.state.n
end
return driver
"""


def test_sparkplug_seq_wraps_from_255_to_0(t):
    """Over 256 messages of one node: seq counts on from 255 to 0 (the NBIRTH
    is the only 0 that is not a wrap), and Tahu reads every payload. Eight
    boards whose driver counts its ticks change a value at every poll of the
    MQTT client, so the node sends some 30 DDATA a second; a Rebirth amid
    them stops the DDATA for the whole birth sequence."""
    broker = Broker(t)
    sp = SpHost(broker)
    settings = {"mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_keepalive_s": 5, "miss_limit": 3,
                "mqtt_sparkplug": "true", "mqtt_sparkplug_group": GROUP}
    host = t.host(drivers=t.drivers(counter=COUNTER_LUA), settings=settings)
    t.board("generic", "count", driver="counter", count=8)
    try:
        _, since = sp.wait(NODE % "NBIRTH", what="NBIRTH")
        sent = [[]]

        def three_hundred():
            sent[0] = sp.node_messages()
            return len(sent[0]) >= 300

        until(three_hundred, 120, lambda: "300 messages of the node (it sent only %d: %s)" % (
            len(sent[0]), sorted({(k, d) for k, d, p, r, q in sent[0]})), poll_s=0.2)
        # A Rebirth while DDATA flows (tck-id-operational-behavior-data-
        # commands-rebirth-action-1 and -2): no DDATA the node made after it
        # took the NCMD comes before its NBIRTH, then the NBIRTH and every
        # DBIRTH with no DDATA among them. Judged by the host's own clock:
        # the payload timestamp of each DDATA (when its status copy was
        # read) against the time of the host's event for the Rebirth. A
        # DDATA seen here after the NCMD may have left the host before the
        # NCMD reached it: the broker hands the two connections their
        # messages in its own order.
        seen = host.last_event_seq()
        mark = sp.mark()
        sp.publish(NODE % "NCMD", command([("Node Control/Rebirth", BOOLEAN, True)]))
        _, i = sp.wait(NODE % "NBIRTH", since=mark, what="NBIRTH after a Rebirth amid DDATA")
        devices = ["count-%d" % n for n in range(1, 9)]
        for name in devices:
            _, end = sp.wait(NODE % "DBIRTH" + "/" + name, since=i, what="DBIRTH of %s after the Rebirth" % name)
            i = max(i, end)
        took_ms = int(host.wait_event("mqtt", text="Rebirth asked for: NBIRTH", after_seq=seen)["time"] * 1000)
        with sp.cond:
            after = [(tp.split("/"), data) for tp, data, _, _ in sp.log[mark:i] if tp.startswith("spBv1.0/")]
        ncmd = next(k for k, (parts, _) in enumerate(after) if parts[2] == "NCMD")
        nbirth = next(k for k, (parts, _) in enumerate(after) if parts[2] == "NBIRTH")
        before_birth = [(parts[2] + "/" + parts[-1], decode(data).get("timestamp")) for parts, data in
                        after[ncmd + 1:nbirth]]
        assert all(k.startswith("DDATA/") for k, _ in before_birth), \
            "after the NCMD and before the NBIRTH, not only DDATA: %s" % before_birth
        late = [(k, ts) for k, ts in before_birth if ts is None or ts > took_ms]
        assert not late, "DDATA made after the host took the Rebirth (its event at %d ms) came before the " \
            "NBIRTH: %s" % (took_ms, late)
        births = [parts[2] for parts, _ in after[nbirth + 1:]]
        assert births == ["DBIRTH"] * len(devices), "between the NBIRTH and the last DBIRTH: %s" % births
        messages = sp.node_messages()
        check_session(messages)
        seqs = [p["seq"] for k, d, p, r, q in messages]
        wraps = [i for i in range(1, len(seqs)) if seqs[i - 1] == 255 and seqs[i] == 0]
        assert wraps and messages[wraps[0]][0] != "NBIRTH", \
            "no wrap from 255 to 0 in %d messages (seqs ...%s)" % (len(seqs), seqs[-20:])
        assert sum(1 for k, d, p, r, q in messages if k == "DBIRTH") >= 8, "a DBIRTH per counting board"
        payloads, metrics = tahu_agrees(sp.node_raw())
        assert payloads >= 300, "Tahu compared only %d payloads" % payloads
        names = [d["name"] for d in host.status()["devices"]]
        undisturbed(names)(host.last)
    finally:
        sp.close()
