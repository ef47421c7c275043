"""The MQTT client (docs/MQTT.md) against a real broker: Debian's mosquitto,
started by each test on a free port with no persistence, and a paho-mqtt
client as the hub. Home Assistant discovery configs from the kitchen's
manifests, commands from MQTT through the same checks as the HTTP API,
refusals and malformed messages published back without harm, the broker
killed and restarted (vmacd reconnects and says everything again while the
bus misses nothing), a dropped machine and a killed host said offline, HA's
birth message answered, a hot reload removing an entity, and bad settings
stopping the host at start. Without mosquitto or python3-paho-mqtt every
test here is SKIPPED (a failure under CI=true)."""

import json
import os
import shutil
import signal
import socket
import sys
import threading
import time

from harness import KITCHEN_NAMES, LOADED, Skip, undisturbed, until

HOST_ID = "test"
PREFIX = "vmac/" + HOST_ID
DISCOVERY = "homeassistant"


def paho():
    """paho.mqtt.client: the python3 running the tests, else Debian's copy
    (python3-paho-mqtt, pure Python) for a python3 of another origin."""
    try:
        import paho.mqtt.client as client
        return client
    except ImportError:
        pass
    for path in ("/usr/lib/python3/dist-packages",):
        if os.path.isdir(os.path.join(path, "paho")) and path not in sys.path:
            sys.path.append(path)
    try:
        import paho.mqtt.client as client
        return client
    except ImportError:
        raise Skip("MQTT tests need python3-paho-mqtt (make deps installs it)")


def mosquitto_path():
    for p in (shutil.which("mosquitto"), "/usr/sbin/mosquitto"):
        if p and os.access(p, os.X_OK):
            return p
    raise Skip("MQTT tests need the mosquitto broker (Debian package mosquitto; make deps installs it)")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Broker:
    """mosquitto on 127.0.0.1:port with a generated config, no persistence:
    a restarted broker has forgotten every retained message. config: the
    configuration's text instead of an open listener, a function of the port
    (test_mqtt_tls.py)."""

    def __init__(self, t, config=None):
        self.t, self.port, self.proc = t, free_port(), None
        self.conf = os.path.join(t.logdir, "mosquitto.conf")
        with open(self.conf, "w") as f:
            f.write(config(self.port) if config else
                    "listener %d 127.0.0.1\nallow_anonymous true\npersistence false\n" % self.port)
        self.start()

    def start(self):
        self.proc = self.t.start([mosquitto_path(), "-c", self.conf], "mosquitto")

        def listening():
            try:
                socket.create_connection(("127.0.0.1", self.port), 1).close()
                return True
            except OSError:
                if not self.proc.alive():
                    raise AssertionError("mosquitto exited before it listened on port %d: %s" % (
                        self.port, self.proc.text()))
                return False

        until(listening, 20, lambda: "mosquitto listening on port %d (its output: %s)" % (self.port, self.proc.text()),
              poll_s=0.05)

    def kill(self):
        self.proc.kill()

    @property
    def url(self):
        return "mqtt://127.0.0.1:%d" % self.port


class Hub:
    """A client subscribed to everything: the latest payload of each topic
    (and whether it came retained), and every message in order. With cafile
    it connects over TLS, with user and password it logs in."""

    def __init__(self, broker, name="hub", cafile=None, user=None, password=None):
        mqtt = paho()
        self.cond = threading.Condition()
        self.latest, self.log = {}, []
        self.subscribed = threading.Event()
        self.c = mqtt.Client(client_id="%s-%d" % (name, os.getpid()))
        if cafile:
            self.c.tls_set(ca_certs=cafile)
        if user:
            self.c.username_pw_set(user, password)
        self.c.on_message = self._on_message
        self.c.on_connect = lambda c, u, f, rc: c.subscribe("#", qos=1)
        self.c.on_subscribe = lambda c, u, mid, granted: self.subscribed.set()
        self.c.connect("127.0.0.1", broker.port, keepalive=30)
        self.c.loop_start()

    def _on_message(self, c, u, m):
        with self.cond:
            self.latest[m.topic] = (m.payload.decode("utf-8", "replace"), m.retain)
            self.log.append((m.topic, m.payload.decode("utf-8", "replace")))
            self.cond.notify_all()

    def publish(self, topic, payload, retain=False):
        self.c.publish(topic, payload, qos=1, retain=retain).wait_for_publish()

    def mark(self):
        with self.cond:
            return len(self.log)

    def wait(self, topic, predicate=lambda p: True, timeout_s=30, what=None, since=None):
        """The latest payload of topic once predicate(payload) holds (with
        since: only messages from log index since on). Waits LOADED times
        timeout_s, as the harness's waits."""
        deadline = time.monotonic() + timeout_s * LOADED
        with self.cond:
            while True:
                if since is None:
                    got = self.latest.get(topic)
                    if got is not None and predicate(got[0]):
                        return got[0]
                else:
                    for tp, p in self.log[since:]:
                        if tp == topic and predicate(p):
                            return p
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError("no %s on %s within %.0f s (latest: %r)" % (
                        what or "matching message", topic, timeout_s * LOADED, self.latest.get(topic)))
                self.cond.wait(min(left, 0.5))

    def config(self, component, device, obj, timeout_s=30):
        topic = "%s/%s/%s_%s/%s/config" % (DISCOVERY, component, HOST_ID, device, obj)
        try:
            return json.loads(self.wait(topic, lambda p: p != "", timeout_s, "discovery config"))
        except AssertionError as e:
            with self.cond:  # the same entity as another component says why
                others = sorted(tp for tp in self.latest
                                if tp.endswith("/%s_%s/%s/config" % (HOST_ID, device, obj)) and tp != topic)
            raise AssertionError("%s; configs of %s %s as another component: %s" % (e, device, obj, others or "none"))

    def close(self):
        self.c.loop_stop()
        self.c.disconnect()


def mqtt_host(t, broker, commands=True, extra=None):
    settings = {"mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_keepalive_s": 5,
                "mqtt_commands": "true" if commands else "false", "miss_limit": 3}
    settings.update(extra or {})
    return t.host(settings=settings)


def test_mqtt_discovery_configs_for_the_kitchen(t):
    broker = Broker(t)
    host = mqtt_host(t, broker)
    t.kitchen(host)
    hub = Hub(broker)
    try:
        level = hub.config("sensor", "washer-1", "level_l")
        assert level["unit_of_measurement"] == "L" and level["state_topic"] == PREFIX + "/washer-1/level_l", level
        temp = hub.config("sensor", "washer-1", "temp_c")
        assert temp["unit_of_measurement"] == "°C" and temp.get("device_class") == "temperature", temp
        light = hub.config("switch", "lights-1", "kitchen")
        assert light["command_topic"] == PREFIX + "/lights-1/set/kitchen", light
        assert light["state_topic"] == PREFIX + "/lights-1/kitchen" and light["payload_on"] == "true", light
        fill = hub.config("number", "washer-1", "fill_timeout_s")
        assert (fill["min"], fill["max"], fill["step"]) == (10, 3600, 1), "number from the param's range: %s" % fill
        assert fill["command_topic"] == PREFIX + "/washer-1/set/fill_timeout_s", fill
        program = hub.config("select", "washer-1", "program")
        assert program["options"] == ["delicate", "normal", "quick"], program
        for button in ("start", "pause", "resume", "cancel"):
            b = hub.config("button", "washer-1", button)
            assert b["command_topic"] == "%s/washer-1/cmd/%s" % (PREFIX, button), b
        hub.config("select", "dish-1", "program")
        hub.config("button", "lights-1", "all_off")
        for cfg in (level, light, fill, program):
            dev = cfg["device"]
            assert dev["via_device"] == "vmac_" + HOST_ID, "via_device is %r" % dev.get("via_device")
            assert dev["manufacturer"] == "vmac" and dev["model"].startswith(dev["name"].split("-")[0]), dev
            assert [a["topic"] for a in cfg["availability"]] == [
                PREFIX + "/status", "%s/%s/_availability" % (PREFIX, dev["name"])], cfg["availability"]
            assert cfg["availability_mode"] == "all", cfg
        host_cfg = json.loads(hub.wait("%s/binary_sensor/%s/status/config" % (DISCOVERY, HOST_ID)))
        assert host_cfg["device"]["identifiers"] == ["vmac_" + HOST_ID], host_cfg
        for name in KITCHEN_NAMES:
            hub.wait("%s/%s/_availability" % (PREFIX, name), lambda p: p == "online", what="online")
        assert hub.wait(PREFIX + "/status") == "online"
        assert hub.wait(PREFIX + "/washer-1/program") == "normal"
        # The lamp's first value published (before it, its retained state is
        # the cleared one a driver still loading leaves), then a newcomer.
        hub.wait(PREFIX + "/lights-1/kitchen", lambda p: p == "false", what="the kitchen lamp's first value")
        late = Hub(broker, "late")
        try:
            got, retained = late.wait(PREFIX + "/lights-1/kitchen"), late.latest[PREFIX + "/lights-1/kitchen"][1]
            assert got == "false" and retained, "a late subscriber gets the retained state (%r, %r)" % (got, retained)
        finally:
            late.close()
        host.status()
        undisturbed(KITCHEN_NAMES)(host.last)
    finally:
        hub.close()


def test_mqtt_commands_refusals_and_malformed_messages(t):
    broker = Broker(t)
    host = mqtt_host(t, broker)
    t.kitchen(host)
    hub = Hub(broker)
    try:
        hub.config("switch", "lights-1", "kitchen")
        hub.publish(PREFIX + "/lights-1/set/kitchen", "true")
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is True, 30,
                         "the kitchen light's output on after an MQTT switch command", undisturbed(KITCHEN_NAMES))
        hub.wait(PREFIX + "/lights-1/kitchen", lambda p: p == "true", what="the new state published")
        hub.publish(PREFIX + "/lights-1/set/kitchen", "OFF")
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is False, 30,
                         "the kitchen light off again (payload OFF)")
        hub.publish(PREFIX + "/washer-1/set/program", "quick")
        hub.wait(PREFIX + "/washer-1/program", lambda p: p == "quick", what="the programme set from a select")

        def refused(topic, payload, code, text=None):
            device = topic.split("/")[2]
            mark = hub.mark()
            hub.publish(topic, payload)
            body = json.loads(hub.wait("%s/%s/_error" % (PREFIX, device), since=mark, what="an error for %s" % topic))
            assert body["code"] == code and body["topic"] == topic, "%s %r: %s" % (topic, payload, body)
            if text:
                assert text in body["error"], "%s %r: %s" % (topic, payload, body)
            return body

        before = host.device("washer-1", host.status())["params"]["time_scale"]
        refused(PREFIX + "/washer-1/set/time_scale", "99", "refused")
        refused(PREFIX + "/washer-1/set/level_l", "3", "refused")            # a read-only variable
        refused(PREFIX + "/washer-1/set/program", "boil", "refused")         # not one of its values
        refused(PREFIX + "/washer-1/cmd/explode", "", "refused")             # no such command
        refused(PREFIX + "/nosuch-9/set/kitchen", "true", "not_running")
        refused(PREFIX + "/lights-1/set/kitchen", "x" * 300, "malformed", "256 bytes")
        refused(PREFIX + "/lights-1/set/kitchen", '{"value": true}', "malformed")
        refused(PREFIX + "/lights-1/set/kitchen", "", "malformed", "needs a value")
        refused(PREFIX + "/lights-1/set/Kitchen", "true", "malformed")
        refused(PREFIX + "/lights-1/set/kitchen", b"tr\x00ue", "malformed", "NUL")
        assert host.device("washer-1", host.status())["params"]["time_scale"] == before, "a refusal changed a param"
        # Topics nobody expects, and garbage on HA's status topic: no harm.
        for topic, payload in ((PREFIX + "/lights-1/set", "true"), (PREFIX + "/x/y/z/w", "?"),
                               (DISCOVERY + "/status", b"\xff\xfe garbage"), (PREFIX + "/lights-1/cmd/all_off/x", ""),
                               ("vmac/other-host/lights-1/set/kitchen", "true"), (PREFIX + "/bad name!/set/x", "1")):
            hub.publish(topic, payload)
        mark = hub.mark()
        hub.publish(PREFIX + "/lights-1/cmd/all_off", "PRESS")
        hub.publish(PREFIX + "/lights-1/set/dining", "1")  # a number for a boolean: the driver decides
        hub.publish(PREFIX + "/lights-1/set/tv", "true")
        hub.wait(PREFIX + "/lights-1/tv", lambda p: p == "true", since=mark, what="the TV on after all that")
        # The variable goes out from the tick that set it; the board says its
        # relay is on in a later reply.
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][2] is True, 30,
                         "the TV relay on", undisturbed(KITCHEN_NAMES))
    finally:
        hub.close()


def test_mqtt_broker_killed_and_restarted(t):
    broker = Broker(t)
    host = mqtt_host(t, broker)
    t.kitchen(host)
    hub = Hub(broker)
    hub.config("switch", "lights-1", "kitchen")
    hub.close()
    broker.kill()
    served = {n: host.device(n, host.status())["served"] for n in KITCHEN_NAMES}
    # The bus goes on with no broker at all.
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 20 for n in KITCHEN_NAMES), 60,
                     "every machine served on while the broker is down", undisturbed(KITCHEN_NAMES))
    host.wait_event("mqtt", text="lost the broker", invariant=undisturbed(KITCHEN_NAMES))
    broker.start()  # the same port, nothing retained any more
    hub = Hub(broker)
    try:
        # Back within the backoff (at most 30 s), with everything retained again.
        cfg = hub.config("switch", "lights-1", "kitchen", timeout_s=60)
        assert cfg["device"]["via_device"] == "vmac_" + HOST_ID
        hub.config("sensor", "washer-1", "level_l", timeout_s=30)
        assert hub.wait(PREFIX + "/status", timeout_s=30) == "online"
        for name in KITCHEN_NAMES:
            hub.wait("%s/%s/_availability" % (PREFIX, name), lambda p: p == "online", what="online again")
        hub.wait(PREFIX + "/lights-1/kitchen", what="the values again")
        hub.publish(PREFIX + "/lights-1/set/kitchen", "true")
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is True, 30,
                         "a command after the reconnect", undisturbed(KITCHEN_NAMES))
    finally:
        hub.close()
    host.status()
    undisturbed(KITCHEN_NAMES)(host.last)


def test_mqtt_dropped_machine_and_killed_host_go_offline(t):
    broker = Broker(t)
    host = mqtt_host(t, broker, extra={"miss_limit": 1})
    boards = t.kitchen(host)
    hub = Hub(broker)
    try:
        topic = PREFIX + "/washer-1/_availability"
        hub.wait(topic, lambda p: p == "online", what="washer-1 online")
        boards["washer-1"].signal(signal.SIGSTOP)
        try:
            host.wait_status(lambda s: host.device("washer-1", s)["state"] != "running", 30, "washer-1 dropped")
            hub.wait(topic, lambda p: p == "offline", what="washer-1 offline after its drop")
        finally:
            boards["washer-1"].signal(signal.SIGCONT)
        hub.wait(topic, lambda p: p == "online", timeout_s=60, what="washer-1 online again after it re-attached")
        hub.wait(PREFIX + "/status", lambda p: p == "online")
        host.signal(signal.SIGKILL)
        host.wait_exit(10)
        # The broker sees the connection close and publishes the last will.
        hub.wait(PREFIX + "/status", lambda p: p == "offline", timeout_s=30, what="the last will 'offline'")
    finally:
        hub.close()


def test_mqtt_home_assistant_birth_republishes_configs(t):
    broker = Broker(t)
    host = mqtt_host(t, broker)
    t.kitchen(host)
    hub = Hub(broker)
    try:
        topic = "%s/switch/%s_lights-1/kitchen/config" % (DISCOVERY, HOST_ID)
        hub.config("switch", "lights-1", "kitchen")
        hub.publish(topic, "", retain=True)  # as if the broker had lost it
        hub.wait(topic, lambda p: p == "", what="the config cleared")
        mark = hub.mark()
        hub.publish(DISCOVERY + "/status", "online")
        cfg = json.loads(hub.wait(topic, lambda p: p != "", since=mark, what="the config after HA's birth"))
        assert cfg["command_topic"] == PREFIX + "/lights-1/set/kitchen"
        host.wait_event("mqtt", text="Home Assistant is online")
    finally:
        hub.close()


def test_mqtt_hot_reload_removes_entities_the_new_version_lacks(t):
    broker = Broker(t)
    host = mqtt_host(t, broker)
    t.kitchen(host)
    hub = Hub(broker)
    try:
        tv = "%s/switch/%s_lights-1/tv/config" % (DISCOVERY, HOST_ID)
        hub.config("switch", "lights-1", "tv")
        here = os.path.dirname(os.path.abspath(__file__))
        with open(os.path.join(here, "..", "..", "scripts", "drivers", "lights.lua")) as f:
            src = f.read()
        new = src.replace('version = "1.2.0"', 'version = "1.2.1-mqtt"').replace(
            '\t\ttv = { set = true, device_class = "switch", label = "TV" },\n', "")
        assert new != src and "1.2.1-mqtt" in new, "the lights driver changed: this test needs updating"
        path = os.path.join(t.logdir, "lights.lua")
        with open(path, "w") as f:
            f.write(new)
        rc, out, err = t.run([t.path("vmac"), "reload", "--http", host.http, "--probation", "0", path], "reload")
        assert rc == 0, "vmac reload failed (exit %d): %s %s" % (rc, out, err)
        hub.wait(tv, lambda p: p == "", what="the TV's config removed (empty retained payload)")
        kitchen = "%s/switch/%s_lights-1/kitchen/config" % (DISCOVERY, HOST_ID)
        hub.wait(kitchen, lambda p: p and json.loads(p)["device"]["model"] == "lights 1.2.1-mqtt",
                 what="the kitchen light's config naming the new version")
    finally:
        hub.close()


def test_mqtt_entity_configured_again_when_its_value_tells_its_kind(t):
    """A variable with no default and no unit is a switch, a number or a
    text only by its value. Until the driver publishes one (a machine shows
    running before its first tick) it is configured as a text; its value
    then brings the right config and removes the guess."""
    broker = Broker(t)
    host = mqtt_host(t, broker)
    t.kitchen(host)
    hub = Hub(broker)
    try:
        hub.config("switch", "lights-1", "kitchen")
        here = os.path.dirname(os.path.abspath(__file__))
        with open(os.path.join(here, "..", "..", "scripts", "drivers", "lights.lua")) as f:
            src = f.read()
        disposal = '\t\tdisposal = { set = true, device_class = "switch", label = "Garbage disposal" },\n'
        new = src
        for old, by in (('version = "1.2.0"', 'version = "1.2.2-mqtt"'),
                        (disposal, disposal + '\t\tspare = { set = true, label = "Spare" },\n'),
                        ("function driver.input(dev, name, value)\n",
                         'function driver.input(dev, name, value)\n\tif name == "spare" then\n'
                         "\t\tdev.vars.spare = value == true\n\t\treturn true\n\tend\n")):
            assert old in new, "the lights driver changed (no %r): this test needs updating" % old
            new = new.replace(old, by)
        path = os.path.join(t.logdir, "lights.lua")
        with open(path, "w") as f:
            f.write(new)
        rc, out, err = t.run([t.path("vmac"), "reload", "--http", host.http, "--probation", "0", path], "reload")
        assert rc == 0, "vmac reload failed (exit %d): %s %s" % (rc, out, err)
        text = "%s/text/%s_lights-1/spare/config" % (DISCOVERY, HOST_ID)
        hub.config("text", "lights-1", "spare")  # no value yet (the driver leaves it nil): a text
        mark = hub.mark()
        hub.publish(PREFIX + "/lights-1/set/spare", "true")
        hub.wait(PREFIX + "/lights-1/spare", lambda p: p == "true", since=mark, what="the spare's value")
        switch = hub.config("switch", "lights-1", "spare")
        assert switch["command_topic"] == PREFIX + "/lights-1/set/spare", switch
        assert switch["device"]["model"] == "lights 1.2.2-mqtt", switch
        hub.wait(text, lambda p: p == "", since=mark, what="the text config of the spare removed (empty retained)")
        assert "%s/switch/%s_lights-1/kitchen/config" % (DISCOVERY, HOST_ID) in hub.latest
    finally:
        hub.close()


def test_mqtt_commands_are_off_by_default(t):
    broker = Broker(t)
    host = t.host(settings={"mqtt_url": broker.url, "mqtt_host_id": HOST_ID})
    t.kitchen(host)
    hub = Hub(broker)
    try:
        cfg = hub.config("binary_sensor", "lights-1", "kitchen")
        assert "command_topic" not in cfg, cfg
        assert "%s/button/%s_washer-1/start/config" % (DISCOVERY, HOST_ID) not in hub.latest
        hub.publish(PREFIX + "/lights-1/set/kitchen", "true")
        hub.publish(PREFIX + "/lights-1/set/tv", "true")
        hub.wait(PREFIX + "/lights-1/kitchen", lambda p: p == "false")
        host.wait_status(lambda s: host.device("lights-1", s)["served"] > 30, 30, "lights-1 served a while")
        assert host.device("lights-1", host.status())["outputs"]["digital"][0] is False, \
            "a command from MQTT was obeyed with mqtt_commands off"
    finally:
        hub.close()


def test_mqtt_bad_settings_stop_the_host(t):
    vmacd = t.path("vmacd")
    cases = [
        ({"mqtt_url": "http://127.0.0.1:1883"}, "mqtt_url"),
        ({"mqtt_url": "mqtt://:1883"}, "mqtt_url"),
        ({"mqtt_url": "mqtt://127.0.0.1:99999"}, "port"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_password_file": os.path.join(t.logdir, "none")},
         "mqtt_password_file"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_cafile": __file__}, "mqtts://"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_prefix": "a/#"}, "mqtt_prefix"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_host_id": "a/b"}, "mqtt_host_id"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_password": "secret-pw"}, "mqtt_user"),
        ({"mqtt_url": "mqtts://127.0.0.1:8883", "mqtt_certfile": __file__}, "mqtt_keyfile"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "ui_url": "ftp://x/"}, "ui_url"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "ui_url": "http://a b/"}, "ui_url"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_sparkplug_primary_host": "a/b"},
         "mqtt_sparkplug_primary_host"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_sparkplug_group": "plant+1"}, "mqtt_sparkplug_group"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_sparkplug_group": "pl\u00e4nt"}, "mqtt_sparkplug_group"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_host_id": "kitchen#2"}, "mqtt_host_id"),
        ({"mqtt_url": "mqtt://127.0.0.1:1883", "mqtt_discovery_mode": "entity"}, "mqtt_discovery_mode"),
    ]
    for settings, want in cases:
        argv = [vmacd, "--http", "127.0.0.1:0", "--state", t.logdir, "--set", "realtime=false"]
        for k, v in settings.items():
            argv += ["--set", "%s=%s" % (k, v)]
        rc, out, err = t.run(argv, "vmacd-bad-mqtt")
        assert rc == 2, "vmacd with %s exited %d, expected 2: %s" % (settings, rc, err)
        assert want in err, "vmacd with %s did not name %r: %r" % (settings, want, err)
        assert "secret-pw" not in err, "the password was printed: %r" % err


def test_mqtt_configuration_url_and_health_on_every_status_copy(t):
    """The web UI's address in every HA device (ui_url, else from http); the
    health sensors expire; a machine's _health comes out again with no
    value of its changing (the lights, left alone), looked at on every
    status copy, not only when a value changed."""
    broker = Broker(t)
    host = mqtt_host(t, broker, extra={"ui_url": "https://kitchen.example:8443/vmac/"})
    t.kitchen(host)
    hub = Hub(broker)
    try:
        kitchen = hub.config("switch", "lights-1", "kitchen")
        assert kitchen["device"]["configuration_url"] == "https://kitchen.example:8443/vmac/#devices", kitchen
        conn = json.loads(hub.wait("%s/binary_sensor/%s/status/config" % (DISCOVERY, HOST_ID), lambda p: p != "",
                                   what="the host's connectivity config"))
        assert conn["device"]["configuration_url"] == "https://kitchen.example:8443/vmac/", conn
        misses = hub.config("sensor", "lights-1", "_health_misses")
        assert misses["expire_after"] == 150 and misses["entity_category"] == "diagnostic", misses
        topic = PREFIX + "/lights-1/_health"
        for relay in ("kitchen", "dining", "tv", "disposal"):  # their first values (the first tick)
            hub.wait(PREFIX + "/lights-1/" + relay, lambda p: p == "false", what="the lights' first values")
        first = json.loads(hub.wait(topic, what="the lights' health"))
        mark = hub.mark()
        second = json.loads(hub.wait(topic, lambda p: json.loads(p)["served"] > first["served"], since=mark,
                                     timeout_s=40, what="the lights' health again, their values unchanged"))
        assert second["served"] > first["served"], (first, second)
        with hub.cond:
            lights = [tp for tp, _ in hub.log[mark:] if tp.startswith(PREFIX + "/lights-1/") and
                      not tp.split("/")[-1].startswith("_")]
        assert not lights, "a lights value changed, so this proves nothing: %s" % lights
    finally:
        hub.close()
    # Without ui_url, from the http setting: none for port 0 (the kernel's
    # choice, which the harness uses), else that address.
    broker2 = Broker(t)
    host2 = mqtt_host(t, broker2)
    t.kitchen(host2)
    hub2 = Hub(broker2)
    try:
        kitchen = hub2.config("switch", "lights-1", "kitchen")
        assert "configuration_url" not in kitchen["device"], kitchen["device"]
    finally:
        hub2.close()
