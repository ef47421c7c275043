"""Sparkplug B's session rules (docs/MQTT.md, "Sparkplug B" and its
conformance table) against a real Mosquitto, with a paho client as the
host application (test_sparkplug.py's SpHost and payload reader) and, where
a test must see what the broker saw, tests/integration/mqtt_proxy.py
between vmacd and the broker reading every CONNECT packet as the
Sparkplug TCK's monitor does:
- bdSeq counts every CONNECT, those the broker refused (a wrong password)
  too, and the NBIRTH and the will of the accepted one carry the same;
- the Sparkplug session lives on while the main connection is down, and the
  main one's return re-births nothing;
- a Primary Host Application (mqtt_sparkplug_primary_host): no NBIRTH before
  its STATE says online, NDEATH and a new connection when it says offline, a
  stale or malformed STATE ignored;
- a hot reload: the device's DDEATH before its new DBIRTH;
- ids that clash: another node with this one's descriptor, an edge id or
  machine names that differ only in case, said in the host's events.
SKIPPED without mosquitto, paho or Tahu, as test_sparkplug.py."""

import json
import os
import random
import re
import shutil
import signal
import subprocess
import time

from harness import KITCHEN_NAMES, Skip
from mqtt_proxy import MqttProxy, client_ids
from test_mqtt import HOST_ID, PREFIX, Broker
from test_sparkplug import BOOLEAN, DOUBLE, GROUP, INT64, NODE, STRING, SpHost, check_session, command, decode, \
    has_value, spb_host, tahu_agrees

MAIN_ID = "vmac-spbtest"


def will_bdseq(payload):
    """The bdSeq metric of an NDEATH will, its only one (tck-id-topics-
    ndeath-payload): (datatype, value)."""
    p = decode(payload)
    assert [m.get("name") for m in p["metrics"]] == ["bdSeq"], "a will's metrics: %s (only bdSeq)" % p["metrics"]
    m = p["by_name"]["bdSeq"]
    return m["datatype"], m["value"]


def passwd(path, user, password):
    tool = shutil.which("mosquitto_passwd")
    if not tool:
        raise Skip("mosquitto_passwd (Debian package mosquitto) is not installed")
    subprocess.run([tool, "-b", path, user, password], check=True, capture_output=True)
    os.chmod(path, 0o644)  # mosquitto reads it as its own user


def test_sparkplug_bdseq_counts_every_connect_refused_ones_too(t):
    """tck-id-topics-nbirth-bdseq-increment: each CONNECT's will has a
    bdSeq one more than the CONNECT before it, whether or not the broker
    accepted that one; the NBIRTH says the accepted CONNECT's."""
    pw = os.path.join(t.logdir, "passwd")
    open(pw, "w").close()
    os.chmod(t.logdir, 0o755)
    passwd(pw, "hub", "hub-pw")  # vmacd's user is not there yet: refused
    broker = Broker(t, config=lambda port: "listener %d 127.0.0.1\nallow_anonymous false\npassword_file %s\n"
                                           "persistence false\n" % (port, pw))
    proxy = MqttProxy(broker.port)
    secret = os.path.join(t.logdir, "vmac-pw")
    with open(secret, "w") as f:
        f.write("vmac-pw\n")
    sp = SpHost(broker, user="hub", password="hub-pw")
    host = spb_host(t, broker, extra={"mqtt_url": proxy.url, "mqtt_client_id": MAIN_ID, "mqtt_user": "vmac",
                                      "mqtt_password_file": secret})
    t.kitchen(host)
    try:
        proxy.wait_connects(lambda c: len(client_ids(c, "-spb")) >= 2, 30, "two Sparkplug CONNECTs refused")
        host.wait_event("mqtt", text="not authorised", timeout_s=10)
        assert not any(tp == NODE % "NBIRTH" for tp, _, _, _ in sp.log), "an NBIRTH while the broker refused vmacd"
        passwd(pw, "vmac", "vmac-pw")
        broker.proc.signal(signal.SIGHUP)  # mosquitto reads its password file again
        nbirth, _ = sp.wait(NODE % "NBIRTH", timeout_s=60, what="NBIRTH once the password is right")
        wills = [will_bdseq(p) for cid, topic, p in client_ids(proxy.connects, "-spb")]
        topics = {topic for cid, topic, p in client_ids(proxy.connects, "-spb")}
        assert topics == {NODE % "NDEATH"}, "the Sparkplug CONNECTs' will topics: %s" % topics
        assert len(wills) >= 3, "CONNECTs seen: %s" % wills
        for (dt, value), (_, nxt) in zip(wills, wills[1:]):
            assert dt == INT64, "a will's bdSeq is not Int64: %s" % wills
            assert nxt == (value + 1) % 256, "bdSeq did not count every CONNECT: %s" % wills
        born = nbirth["by_name"]["bdSeq"]
        assert (born["datatype"], born["value"]) == wills[-1], \
            "the NBIRTH's bdSeq %s is not the accepted CONNECT's will %s" % (born, wills[-1])
        mark = sp.mark()
        host.signal(signal.SIGKILL)
        host.wait_exit(10)
        ndeath, _ = sp.wait(NODE % "NDEATH", since=mark, what="the will after SIGKILL")
        assert ndeath["by_name"]["bdSeq"]["value"] == born["value"], (ndeath, born)
    finally:
        proxy.close()
        sp.close()


def test_sparkplug_lives_on_while_the_main_connection_is_down(t):
    """The main connection (native topics, Home Assistant) cut and kept out;
    the Sparkplug session goes on: a DCMD is obeyed and its DDATA comes, a
    dropped machine's DDEATH and its DBIRTH when it is back. The main
    connection's return re-births nothing on Sparkplug."""
    broker = Broker(t)
    proxy = MqttProxy(broker.port)
    sp = SpHost(broker)
    host = spb_host(t, broker, extra={"mqtt_url": proxy.url, "mqtt_client_id": MAIN_ID})
    boards = t.kitchen(host)
    try:
        sp.wait(NODE % "DBIRTH" + "/lights-1", lambda p: p["by_name"].get("kitchen", {}).get("datatype") == BOOLEAN,
                what="lights DBIRTH")
        for name in KITCHEN_NAMES:
            sp.wait(NODE % "DBIRTH" + "/" + name, what="DBIRTH of " + name)
        mark = sp.mark()
        proxy.block(MAIN_ID)
        sp.wait(PREFIX + "/status", lambda p: p == "offline", since=mark, raw=True,
                what="the main connection's will (it was cut)")
        host.wait_event("mqtt", text="lost the broker", timeout_s=20)

        sp.publish(NODE % "DCMD" + "/lights-1", command([("kitchen", BOOLEAN, True)]))
        sp.wait(NODE % "DDATA" + "/lights-1", has_value("kitchen", True), since=mark,
                what="DDATA of a DCMD while the main connection is down")
        boards["washer-1"].signal(signal.SIGSTOP)
        try:
            host.wait_status(lambda s: host.device("washer-1", s)["state"] != "running", 30, "washer-1 dropped")
            sp.wait(NODE % "DDEATH" + "/washer-1", since=mark, what="DDEATH while the main connection is down")
        finally:
            boards["washer-1"].signal(signal.SIGCONT)
        _, back = sp.wait(NODE % "DBIRTH" + "/washer-1", since=mark, timeout_s=60,
                          what="DBIRTH of washer-1 back, the main connection still down")
        assert not any(tp == PREFIX + "/status" and p == b"online" for tp, p, _, _ in sp.log[mark:]), \
            "the main connection was not kept out"

        proxy.unblock(MAIN_ID)
        sp.wait(PREFIX + "/status", lambda p: p == "online", since=back, raw=True, timeout_s=60,
                what="the main connection back")
        sp.wait(PREFIX + "/washer-1/_availability", lambda p: p == "online", since=back, raw=True,
                what="the main connection's devices said again")
        # A DCMD after that: on the Sparkplug connection, anything the main
        # connection's return made it say comes before its DDATA.
        sp.publish(NODE % "DCMD" + "/lights-1", command([("tv", BOOLEAN, True)]))
        _, end = sp.wait(NODE % "DDATA" + "/lights-1", has_value("tv", True), since=back, what="DDATA tv")
        said = [(k, d) for k, d, p, r, q in sp.node_messages()]
        kinds = [tp.split("/")[2] for tp, _, _, _ in sp.log[back:end] if tp.startswith("spBv1.0/" + GROUP + "/")]
        assert not {"NBIRTH", "DBIRTH", "DDEATH", "NDEATH"} & set(kinds), \
            "the main connection's return re-birthed on Sparkplug: %s" % kinds
        assert said.count(("NBIRTH", None)) == 1, "one NBIRTH in the whole test: %s" % said
        check_session(sp.node_messages())
        tahu_agrees(sp.node_raw())
        host.signal(signal.SIGTERM)  # an orderly stop: DDEATHs and the NDEATH, through the relay
        assert host.wait_exit(20) == 0, "vmacd did not stop cleanly"
        wire_ok(proxy, {"NBIRTH", "DBIRTH", "DDATA", "DDEATH", "NDEATH"})
    finally:
        proxy.close()
        sp.close()


def test_sparkplug_connection_lost_and_back_counts_bdseq_and_births_once(t):
    """The broker gone (every connection cut, TCP connects refused) and
    back: the CONNECT after it carries the bdSeq after the last CONNECT's
    (the refused TCP connects sent none), then one NBIRTH and exactly one
    DBIRTH per machine, no DDEATH between them."""
    broker = Broker(t)
    proxy = MqttProxy(broker.port)
    sp = SpHost(broker)
    host = spb_host(t, broker, extra={"mqtt_url": proxy.url, "mqtt_client_id": MAIN_ID})
    t.kitchen(host)
    try:
        for name in KITCHEN_NAMES:
            sp.wait(NODE % "DBIRTH" + "/" + name, what="DBIRTH of " + name)
        seq = host.last_event_seq()
        before = len(client_ids(proxy.connects, "-spb"))
        mark = sp.mark()
        proxy.pause()
        host.wait_event("mqtt", text="(Sparkplug) (Connection refused", after_seq=seq, timeout_s=30)
        proxy.resume()
        nbirth, i = sp.wait(NODE % "NBIRTH", since=mark, timeout_s=60, what="NBIRTH after the outage")
        wills = [will_bdseq(p)[1] for _, _, p in client_ids(proxy.connects, "-spb")]
        assert len(wills) == before + 1, "one CONNECT after the outage, none while TCP was refused: %s" % wills
        assert wills[-1] == (wills[-2] + 1) % 256 == nbirth["by_name"]["bdSeq"]["value"], \
            "bdSeq after an outage whose connects sent no CONNECT: %s, NBIRTH %s" % (wills, nbirth["by_name"])
        for name in KITCHEN_NAMES:
            sp.wait(NODE % "DBIRTH" + "/" + name, since=i, what="DBIRTH of %s after the outage" % name)
        sp.publish(NODE % "DCMD" + "/lights-1", command([("tv", BOOLEAN, True)]))
        _, end = sp.wait(NODE % "DDATA" + "/lights-1", has_value("tv", True), since=i, what="DDATA tv")
        said = [tp.split("/")[2] + "/" + tp.split("/")[-1] for tp, _, _, _ in sp.log[i:end]
                if tp.startswith("spBv1.0/" + GROUP + "/") and "/DCMD/" not in tp]
        for name in KITCHEN_NAMES:
            assert said.count("DBIRTH/" + name) == 1, "DBIRTHs of %s after the NBIRTH: %s" % (name, said)
        assert not [k for k in said if k.startswith(("DDEATH", "NBIRTH"))], "a death or second NBIRTH: %s" % said
        check_session(sp.node_messages())
        wire_ok(proxy, {"NBIRTH", "DBIRTH", "DDATA"})
    finally:
        proxy.close()
        sp.close()


def wire_ok(proxy, kinds):
    """As the TCK's monitor reads the packets: every Sparkplug CONNECT a
    clean session with a QoS 1, not retained, will; every message of the
    node QoS 0 and not retained but the NDEATH (QoS 1); on each connection
    the NBIRTH first, and no DDATA or DDEATH of a device before its DBIRTH
    in that session; kinds all seen. (A broker clears the retain flag for a
    subscriber already there, so only the wire shows it.)"""
    for (cid, _, _), f in zip(proxy.connects, proxy.flags):
        if cid.endswith("-spb"):
            assert f == {"clean": True, "will_qos": 1, "will_retain": False}, "CONNECT of %s: %s" % (cid, f)
    sent = [(tp, q, r, conn) for cid, tp, q, r, conn in proxy.publishes if cid.endswith("-spb")]
    seen = {tp.split("/")[2] for tp, q, r, conn in sent}
    assert kinds <= seen, "the relay saw %s of the node, not all of %s" % (seen, kinds)
    wrong = [(tp, q, r) for tp, q, r, conn in sent if r or q != (1 if "/NDEATH/" in tp else 0)]
    assert not wrong, "node messages with another QoS, or retained: %s" % wrong[:5]
    born, first = set(), {}
    for tp, q, r, conn in sent:
        kind, device = tp.split("/")[2], "/".join(tp.split("/")[4:])
        if conn not in first:
            first[conn] = kind
            assert kind in ("NBIRTH", "NDEATH"), "connection %d's first message is a %s" % (conn, tp)
        if kind == "NBIRTH":
            born = {(conn, "")}
        elif kind == "DBIRTH":
            born.add((conn, device))
        elif kind == "DDEATH":
            assert (conn, device) in born, "a DDEATH of %s not born in this session" % device
            born.discard((conn, device))
        elif kind == "DDATA":
            assert (conn, "") in born and (conn, device) in born, "a DDATA of %s before its DBIRTH" % device


def state(online, ts):
    return json.dumps({"online": online, "timestamp": ts})


def test_sparkplug_primary_host_state(t):
    """mqtt_sparkplug_primary_host: births only once the host application's
    STATE says online, on its own id's topic (another id's online, one in
    another case, changes nothing); its offline ends the session (NDEATH
    with the session's bdSeq, a new CONNECT, never while the old one is
    open) and the next online brings an NBIRTH with the next bdSeq. An
    older STATE and a malformed one change nothing."""
    broker = Broker(t)
    proxy = MqttProxy(broker.port)
    sp = SpHost(broker)
    topic = "spBv1.0/STATE/scada"
    t0 = int(time.time() * 1000)
    sp.publish(topic, state(False, t0), qos=1, retain=True)
    host = spb_host(t, broker, extra={"mqtt_sparkplug_primary_host": "scada", "mqtt_url": proxy.url,
                                      "mqtt_client_id": MAIN_ID})
    t.kitchen(host)
    try:
        host.wait_event("mqtt", text="waiting for the primary host scada", timeout_s=30)
        host.wait_running(KITCHEN_NAMES)
        seq = host.last_event_seq()
        # Online, but for other ids (tck-id-message-flow-edge-node-birth-
        # publish-phid-wait-id): no births; the malformed STATE after them,
        # said in the events, shows they were past.
        for other in ("spBv1.0/STATE/scada2", "spBv1.0/STATE/SCADA", "spBv1.0/STATE/scad"):
            sp.publish(other, state(True, t0 + 1), qos=1)
        sp.publish(topic, "not json", qos=1)
        host.wait_event("mqtt", text="STATE of the primary host scada ignored", after_seq=seq)
        assert not [k for k, d, p, r, q in sp.node_messages() if k in ("NBIRTH", "DBIRTH")], \
            "births before the primary host was online: %s" % sp.node_messages()

        mark = sp.mark()
        sp.publish(topic, state(True, t0 + 1), qos=1, retain=True)
        nbirth, i = sp.wait(NODE % "NBIRTH", since=mark, what="NBIRTH once the primary host is online")
        for name in KITCHEN_NAMES:
            sp.wait(NODE % "DBIRTH" + "/" + name, since=i, what="DBIRTH of %s after the NBIRTH" % name)
        bdseq = nbirth["by_name"]["bdSeq"]["value"]

        # An offline older than the online it follows: ignored (a Rebirth
        # after it is answered, with no NDEATH between).
        mark = sp.mark()
        sp.publish(topic, state(False, t0), qos=1)
        sp.publish(NODE % "NCMD", command([("Node Control/Rebirth", BOOLEAN, True)]))
        sp.wait(NODE % "NBIRTH", since=mark, what="NBIRTH for a Rebirth after a stale offline")
        assert NODE % "NDEATH" not in [tp for tp, _, _, _ in sp.log[mark:]], "a stale offline ended the session"

        mark = sp.mark()
        sp.publish(topic, state(False, t0 + 2), qos=1, retain=True)
        ndeath, _ = sp.wait(NODE % "NDEATH", since=mark, what="NDEATH when the primary host went offline")
        assert ndeath["by_name"]["bdSeq"]["value"] == bdseq, (ndeath, bdseq)
        host.wait_event("mqtt", text="primary host scada is offline")
        host.wait_event("mqtt", text="waiting for the primary host scada", after_seq=seq)
        # An online older than that offline (after the reconnect: the node
        # remembers the last STATE's timestamp) is ignored.
        mark = sp.mark()
        sp.publish(topic, state(True, t0 + 1), qos=1)
        seq2 = host.last_event_seq()
        sp.publish(topic, "[]", qos=1)
        host.wait_event("mqtt", text="STATE of the primary host scada ignored", after_seq=seq2)
        assert NODE % "NBIRTH" not in [tp for tp, _, _, _ in sp.log[mark:]], "an older online brought an NBIRTH"
        mark = sp.mark()
        sp.publish(topic, json.dumps({"online": True, "timestamp": float(t0 + 3)}), qos=1, retain=True)
        again, _ = sp.wait(NODE % "NBIRTH", since=mark, what="NBIRTH when the primary host is back (a real timestamp)")
        assert again["by_name"]["bdSeq"]["value"] == (bdseq + 1) % 256, \
            "the new session's bdSeq: %s after %s" % (again["by_name"]["bdSeq"], bdseq)
        check_session(sp.node_messages())
        # One server, one Sparkplug connection at a time (tck-id-operational-
        # behavior-primary-application-state-with-multiple-servers-single-
        # server): the redial's CONNECT came after the old connection closed.
        spb = client_ids(proxy.connects, "-spb")
        assert len(spb) >= 2, "no second Sparkplug CONNECT after the offline STATE: %s" % [c for c, _, _ in spb]
        assert proxy.overlaps("-spb") == [], "two Sparkplug connections open at once: %s" % proxy.overlaps("-spb")
    finally:
        proxy.close()
        sp.close()


def test_sparkplug_hot_reload_ddeath_before_the_new_dbirth(t):
    broker = Broker(t)
    sp = SpHost(broker)
    host = spb_host(t, broker)
    t.kitchen(host)
    try:
        sp.wait(NODE % "DBIRTH" + "/lights-1", lambda p: p["by_name"].get("kitchen", {}).get("datatype") == BOOLEAN,
                what="lights DBIRTH")
        here = os.path.dirname(os.path.abspath(__file__))
        with open(os.path.join(here, "..", "..", "scripts", "drivers", "lights.lua")) as f:
            src = f.read()
        version = src.split('version = "', 1)[1].split('"', 1)[0]
        new = src.replace('version = "%s"' % version, 'version = "%s-spb"' % version, 1)
        path = os.path.join(t.logdir, "lights.lua")
        with open(path, "w") as f:
            f.write(new)
        mark = sp.mark()
        rc, out, err = t.run([t.path("vmac"), "reload", "--http", host.http, "--probation", "0", path], "reload")
        assert rc == 0, "vmac reload failed (exit %d): %s %s" % (rc, out, err)
        born, i = sp.wait(NODE % "DBIRTH" + "/lights-1",
                          lambda p: p["by_name"]["Properties/Driver"]["value"] == "lights %s-spb" % version,
                          since=mark, what="the new version's DBIRTH")
        kinds = [tp.split("/")[2] for tp, _, _, _ in sp.log[mark:i] if tp.endswith("/lights-1")]
        assert kinds and kinds[-1] == "DBIRTH" and "DDEATH" in kinds and kinds.index("DDEATH") < len(kinds) - 1, \
            "no DDEATH of lights-1 before its new DBIRTH: %s" % kinds
        check_session(sp.node_messages())
    finally:
        sp.close()


CHOICES_LUA = """
local driver = { name = "choices", version = "1.0.0", io = { do0 = "do0" },
                 params = { speed = { default = 2, values = { 1, 2, 3 } },
                            ratio = { default = 0.5, values = { 0.5, 1.5 } },
                            mode = { default = "eco", values = { "eco", "1", "on" } } },
                 variables = { word = { default = "none yet" }, level = { unit = "l" } } }
function driver.tick(dev, inputs)
    dev.vars.word = 5        -- declared a string, its value a number
    dev.vars.level = "full"  -- declared a number, its value a string
end
return driver
"""


def test_sparkplug_datatypes_of_value_lists(t):
    """A list of whole numbers is an Int64, of other numbers a Double, of
    strings a String (one that looks like a number or a boolean stays a
    string); a DCMD of each is taken as declared."""
    broker = Broker(t)
    sp = SpHost(broker)
    host = t.host(drivers=t.drivers(choices=CHOICES_LUA), settings={
        "mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_commands": "true", "mqtt_sparkplug": "true",
        "mqtt_sparkplug_group": GROUP})
    t.board("generic", "ch", driver="choices")
    try:
        born, _ = sp.wait(NODE % "DBIRTH" + "/ch", what="the DBIRTH of a driver with value lists")
        b = born["by_name"]
        assert (b["speed"]["datatype"], b["speed"]["value"]) == (INT64, 2), b["speed"]
        assert (b["ratio"]["datatype"], b["ratio"]["value"]) == (DOUBLE, 0.5), b["ratio"]
        assert (b["mode"]["datatype"], b["mode"]["value"]) == (STRING, "eco"), b["mode"]
        # A value of another kind than declared: the String takes its text,
        # the Double (a unit) is null rather than a value it cannot say.
        assert b["word"]["datatype"] == STRING and b["level"]["datatype"] == DOUBLE, (b["word"], b["level"])
        assert "value" not in b["level"] and b["level"].get("is_null"), b["level"]
        word_said = lambda p: p["by_name"].get("word", {}).get("value") == "5"  # noqa: E731
        if not word_said(born):  # born before the first tick: its value comes in a DDATA
            sp.wait(NODE % "DDATA" + "/ch", word_said, what="the word's value as text")
        # The native topics say the same: the text, and None (HA's unknown)
        # where an entity of the declared kind could not read the value.
        sp.wait(PREFIX + "/ch/word", lambda p: p == "5", raw=True, what="the word's native value")
        sp.wait(PREFIX + "/ch/level", lambda p: p == "None", raw=True, what="a string in a number as None")
        mark = sp.mark()
        sp.publish(NODE % "DCMD" + "/ch", command([("speed", INT64, 3), ("mode", STRING, "1"), ("ratio", DOUBLE, 1.5)]))
        sp.wait(NODE % "DDATA" + "/ch", lambda p: has_value("speed", 3)(p) or "speed" not in p["by_name"],
                since=mark, what="DDATA after the DCMD")
        host.wait_status(lambda s: host.device("ch", s)["params"] == {"speed": 3, "mode": "1", "ratio": 1.5}, 30,
                         "the params set by the DCMD as declared")
        payloads, _ = tahu_agrees(sp.node_raw())
        assert payloads >= 3, payloads
    finally:
        sp.close()


def other_node(t, broker, host_id, client_id, folder):
    """Another vmacd as a Sparkplug Edge Node of GROUP on the same broker:
    a bus and a state folder of its own (no board: an NBIRTH is all it
    says), its bdSeq from 100 (two fresh nodes both start at 0, and two
    NBIRTHs of one Rebirth may share a millisecond: then a twin's reads as
    the node's own)."""
    state = os.path.join(t.logdir, folder)
    os.makedirs(state, exist_ok=True)
    with open(os.path.join(state, "sparkplug-bdseq"), "w") as f:
        f.write("100\n")
    rnd = random.SystemRandom()
    bus = "239.255.%d.%d:%d" % (rnd.randint(1, 254), rnd.randint(1, 254), rnd.randint(20000, 60000))
    return t.host(bus=bus, extra=("--state", state), settings={
        "mqtt_url": broker.url, "mqtt_host_id": host_id, "mqtt_client_id": client_id, "mqtt_sparkplug": "true",
        "mqtt_sparkplug_group": GROUP, "mqtt_keepalive_s": 5})


def test_sparkplug_ids_that_clash_are_told(t):
    """An Edge Node Descriptor MUST be unique (tck-id-intro-edge-node-id-
    uniqueness, tck-id-topic-structure-namespace-unique-edge-node-
    descriptor, tck-id-payloads-nbirth-edge-node-descriptor): no node can
    enforce it, but vmacd sees the group's NBIRTHs and says in its events
    when another node publishes as its GROUP/EDGE, or as an edge id that
    differs from its own only in case; two of its machines whose names
    differ only in case are said too (tck-id-case-sensitivity-sparkplug-ids,
    a SHOULD NOT). Its own NBIRTH, which the broker brings back to it, is not
    taken for another's."""
    broker = Broker(t)
    sp = SpHost(broker)
    a = spb_host(t, broker)
    try:
        t.board("lights", "lamp-a")
        a.wait_running(["lamp-a"])
        t.board("lights", "LAMP-A")
        a.wait_running(["lamp-a", "LAMP-A"])
        said = a.wait_event("mqtt", text="differ only in case", timeout_s=30)
        assert "lamp-a" in said["text"] and "LAMP-A" in said["text"] and "SHOULD NOT" in said["text"], said["text"]
        for name in ("lamp-a", "LAMP-A"):
            sp.wait(NODE % "DBIRTH" + "/" + name, what="DBIRTH of " + name)
        # Its own NBIRTH back (a Rebirth): nothing said. The node that comes
        # next, its edge id in another case, shows that it was handled.
        seq = a.last_event_seq()
        mark = sp.mark()
        sp.publish(NODE % "NCMD", command([("Node Control/Rebirth", BOOLEAN, True)]))
        sp.wait(NODE % "NBIRTH", since=mark, what="NBIRTH after a Rebirth")
        other_node(t, broker, HOST_ID.upper(), "vmac-upper", "state-upper")
        told = a.wait_event("mqtt", text="has an id that differs from this one", after_seq=seq, timeout_s=30)
        assert "another Edge Node of group %s, %s," % (GROUP, HOST_ID.upper()) in told["text"], told["text"]
        assert not a.find_events("mqtt", text="another Edge Node publishes as", after_seq=seq), \
            "its own NBIRTH was taken for another node's: %s" % [e["text"] for e in a.find_events("mqtt",
                                                                                              after_seq=seq)]
        # A second node with the same descriptor: said by the first when its
        # NBIRTH comes, and by the second when both obey one Rebirth.
        seq = a.last_event_seq()
        twin = other_node(t, broker, HOST_ID, "vmac-twin", "state-twin")
        twice = "another Edge Node publishes as %s/%s" % (GROUP, HOST_ID)
        told = a.wait_event("mqtt", text=twice, after_seq=seq, timeout_s=30)
        assert "MUST be unique" in told["text"] and "mqtt_host_id" in told["text"], told["text"]
        # (The second's API takes no token of this test's: its stderr shows
        # its events.)
        sp.publish(NODE % "NCMD", command([("Node Control/Rebirth", BOOLEAN, True)]))
        twin.wait_line(re.escape(twice), 30, stream="stderr", what="the second node telling of the first")
    finally:
        sp.close()
