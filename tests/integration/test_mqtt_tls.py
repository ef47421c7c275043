"""MQTT over TLS to a broker that logs its clients in and holds them to an
ACL: the configuration and the ACL of docs/MQTT.md ("Security") themselves,
read from that file (only the paths and the port are this test's), so the
documentation cannot drift from what works. Certificates from openssl (a
test CA and a server certificate for 127.0.0.1), passwords from
mosquitto_passwd. Checked: vmacd (user vmac-kitchen, mqtts, mqtt_cafile,
mqtt_password_file) publishes its status, discovery configs and Sparkplug
births under the ACL; the hub (user homeassistant) reads them and commands a
light through the native and the Sparkplug command topics; another user with
a valid password can neither read nor command; anonymous clients, a wrong
password and a plain TCP client are refused; a vmacd that does not trust the
broker's certificate never connects, says why, and its bus goes on; the
password is in no log; vmacd killed -> the broker publishes its will.
SKIPPED without mosquitto or paho (a failure with CI=true)."""

import os
import re
import signal
import subprocess
import time

from harness import KITCHEN_NAMES, LOADED, undisturbed
from test_mqtt import Broker, Hub, paho
from test_sparkplug import BOOLEAN, command

DOC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "docs", "MQTT.md")
HOST = "kitchen"  # the docs' example: mqtt_host_id, vmac-kitchen's topics
GROUP = "plant"
PASSWORDS = {"vmac-kitchen": "k1tchen-s3cret-%d" % os.getpid(), "homeassistant": "ha-pass", "mallory": "m-pass"}


def documented_broker():
    """(mosquitto.conf, acl) as docs/MQTT.md's "Security" shows them."""
    with open(DOC) as f:
        text = f.read()
    m = re.search(r"```\n(# /etc/mosquitto/conf\.d/vmac\.conf\n.*?)```", text, re.S)
    assert m, "docs/MQTT.md has no code block starting '# /etc/mosquitto/conf.d/vmac.conf'"
    conf, sep, acl = m.group(1).partition("# /etc/mosquitto/acl\n")
    assert sep and "user vmac-kitchen" in acl and "user homeassistant" in acl, \
        "docs/MQTT.md's ACL block is not as this test expects: %r" % m.group(1)
    return conf, acl


def openssl(t, *args):
    p = subprocess.run(["openssl"] + list(args), capture_output=True, text=True, timeout=60, cwd=t.logdir)
    assert p.returncode == 0, "openssl %s: %s" % (" ".join(args), p.stderr)


def make_ca_and_server(t, name):
    """A CA and a server certificate for 127.0.0.1 it signed (EC keys):
    {"ca": path, "cert": path, "key": path}."""
    d = os.path.join(t.logdir, name)
    os.makedirs(d)
    f = {k: os.path.join(d, k) for k in ("ca.crt", "ca.key", "server.key", "server.csr", "server.crt", "ext")}
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    openssl(t, "req", "-x509", *ec, "-keyout", f["ca.key"], "-out", f["ca.crt"], "-days", "2", "-subj",
            "/CN=vmac test CA %s" % name)
    openssl(t, "req", *ec, "-keyout", f["server.key"], "-out", f["server.csr"], "-subj", "/CN=127.0.0.1")
    with open(f["ext"], "w") as out:
        out.write("subjectAltName=IP:127.0.0.1\n")
    openssl(t, "x509", "-req", "-in", f["server.csr"], "-CA", f["ca.crt"], "-CAkey", f["ca.key"],
            "-CAcreateserial", "-out", f["server.crt"], "-days", "2", "-extfile", f["ext"])
    # mosquitto started as root reads its files as the user mosquitto.
    os.chmod(d, 0o755)
    for path in f.values():
        os.chmod(path, 0o644)
    return {"ca": f["ca.crt"], "cert": f["server.crt"], "key": f["server.key"]}


def tls_broker(t):
    conf, acl = documented_broker()
    pki = make_ca_and_server(t, "pki")
    passwd = os.path.join(t.logdir, "passwd")
    for i, (user, password) in enumerate(PASSWORDS.items()):
        p = subprocess.run(["mosquitto_passwd"] + (["-c"] if i == 0 else []) + ["-b", passwd, user, password],
                           capture_output=True, text=True, timeout=30)
        assert p.returncode == 0, "mosquitto_passwd: %s" % p.stderr
    acl_path = os.path.join(t.logdir, "acl")
    with open(acl_path, "w") as f:
        f.write(acl)
    for path in (passwd, acl_path, t.logdir):
        os.chmod(path, 0o755 if path == t.logdir else 0o644)
    paths = {"/etc/mosquitto/ca.crt": pki["ca"], "/etc/mosquitto/server.crt": pki["cert"],
             "/etc/mosquitto/server.key": pki["key"], "/etc/mosquitto/passwd": passwd,
             "/etc/mosquitto/acl": acl_path}

    def config(port):
        text = conf.replace("listener 8883", "listener %d 127.0.0.1" % port)
        for doc_path, path in paths.items():
            text = text.replace(doc_path, path)
        assert not any("/etc/mosquitto" in ln for ln in text.splitlines() if not ln.startswith("#")), \
            "a path of the docs' config this test does not provide: %s" % text
        return text + "persistence false\n"

    return Broker(t, config=config), pki


def connect_result(broker, cafile=None, user=None, password=None):
    """The CONNACK code a client gets (0 accepted), or the exception text."""
    mqtt = paho()
    c = mqtt.Client(client_id="probe-%d-%s" % (os.getpid(), user))
    if cafile:
        c.tls_set(ca_certs=cafile)
    if user:
        c.username_pw_set(user, password)
    got = []
    c.on_connect = lambda c, u, f, rc: got.append(rc)
    try:
        c.connect("127.0.0.1", broker.port, keepalive=10)
    except Exception as e:  # TLS refused in the handshake
        return "%s: %s" % (type(e).__name__, e)
    deadline = time.monotonic() + 10 * LOADED
    while not got and time.monotonic() < deadline:
        if c.loop(0.2) != 0 and not got:
            break
    c.disconnect()
    return got[0] if got else "no CONNACK"


def test_mqtt_tls_with_the_documented_acl(t):
    broker, pki = tls_broker(t)
    secret = os.path.join(t.logdir, "vmac-kitchen.password")
    with open(secret, "w") as f:
        f.write(PASSWORDS["vmac-kitchen"] + "\n")
    hub = Hub(broker, "ha", cafile=pki["ca"], user="homeassistant", password=PASSWORDS["homeassistant"])
    mallory = Hub(broker, "mallory", cafile=pki["ca"], user="mallory", password=PASSWORDS["mallory"])
    host = t.host(settings={
        "mqtt_url": "mqtts://127.0.0.1:%d" % broker.port, "mqtt_cafile": pki["ca"], "mqtt_user": "vmac-kitchen",
        "mqtt_password_file": secret, "mqtt_host_id": HOST, "mqtt_client_id": "vmac-kitchen",
        "mqtt_commands": "true", "mqtt_sparkplug": "true", "mqtt_sparkplug_group": GROUP, "mqtt_keepalive_s": 5,
        "miss_limit": 3})
    t.kitchen(host)
    try:
        # vmacd publishes under the ACL; the hub reads it all.
        hub.wait("vmac/%s/status" % HOST, lambda p: p == "online", what="the host online (TLS, ACL)")
        hub.wait("vmac/%s/lights-1/_availability" % HOST, lambda p: p == "online", what="lights-1 online")
        hub.wait("homeassistant/switch/%s_lights-1/kitchen/config" % HOST, lambda p: p != "",
                 what="the kitchen light's discovery config")
        hub.wait("spBv1.0/%s/DBIRTH/%s/lights-1" % (GROUP, HOST), what="the lights' Sparkplug DBIRTH")
        assert mallory.subscribed.wait(10), "mallory's subscription was not acknowledged"

        def light(i):
            return host.device("lights-1", host.status())["outputs"]["digital"][i]

        # The hub commands: a native set topic and a Sparkplug DCMD.
        hub.publish("vmac/%s/lights-1/set/kitchen" % HOST, "ON")
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is True, 30,
                         "the kitchen light on from the hub's set topic", undisturbed(KITCHEN_NAMES))
        hub.publish("spBv1.0/%s/DCMD/%s/lights-1" % (GROUP, HOST), command([("dining", BOOLEAN, True)]))
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][1] is True, 30,
                         "the dining light on from the hub's DCMD", undisturbed(KITCHEN_NAMES))

        # mallory logs in but may do nothing: her commands (acknowledged by
        # the broker, then dropped) are not obeyed. The hub's command sent
        # after them is, which shows the host had its chance to see hers.
        mallory.publish("vmac/%s/lights-1/set/tv" % HOST, "ON")
        mallory.publish("spBv1.0/%s/DCMD/%s/lights-1" % (GROUP, HOST), command([("disposal", BOOLEAN, True)]))
        mallory.publish("vmac/%s/status" % HOST, "offline", retain=True)
        hub.publish("vmac/%s/lights-1/set/kitchen" % HOST, "OFF")
        host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is False, 30,
                         "the kitchen light off from the hub's set topic")
        assert light(2) is False and light(3) is False, "a command of a user the ACL does not allow was obeyed"
        hub.wait("vmac/%s/status" % HOST, lambda p: p == "online", what="the host still online")
        with mallory.cond:
            assert mallory.log == [], "mallory, whom the ACL allows nothing, read: %s" % mallory.log[:5]

        # No way in without the right credentials, or without TLS.
        assert connect_result(broker, pki["ca"]) == 5, "an anonymous client was let in"
        assert connect_result(broker, pki["ca"], "homeassistant", "wrong") == 5, "a wrong password was let in"
        plain = connect_result(broker, None, "homeassistant", PASSWORDS["homeassistant"])
        assert plain != 0, "a client without TLS was let in"

        # A vmacd that does not trust the broker's certificate: never
        # connected, says why, runs its bus as before.
        other = make_ca_and_server(t, "other-ca")
        host2 = t.host(settings={
            "mqtt_url": "mqtts://127.0.0.1:%d" % broker.port, "mqtt_cafile": other["ca"],
            "mqtt_user": "vmac-kitchen", "mqtt_password_file": secret, "mqtt_host_id": "untrusting",
            "mqtt_client_id": "vmac-untrusting"})
        host2.wait_line(r"\[mqtt\] cannot connect to the broker .*certificate verify failed", 30,
                               stream="stderr", what="vmacd saying it cannot trust the broker's certificate")
        # It keeps trying (libmosquitto alone would give up after the first
        # refused handshake): the broker sees a second handshake a second or
        # two later, and vmacd said the reason once, not once per attempt.
        broker.proc.wait_line(r"unknown ca", 30, since=0, stream="stderr", what="the first refused handshake")
        first = broker.proc.find_lines(r"unknown ca", stream="stderr")[0]
        broker.proc.wait_line(r"unknown ca", 30, since=first.index + 1, stream="stderr",
                              what="vmacd trying the untrusted broker again")
        said = host2.find_lines(r"\[mqtt\] cannot connect", stream="stderr")
        assert len(said) == 1, "vmacd said the same failure %d times: %s" % (len(said), [x.text for x in said])
        assert host2.status()["uptime_s"] >= 0
        assert "vmac/untrusting/status" not in hub.latest, "a host that trusts another CA connected"

        # Killed: the broker publishes the will.
        mark = hub.mark()
        host.signal(signal.SIGKILL)
        host.wait_exit(10)
        hub.wait("vmac/%s/status" % HOST, lambda p: p == "offline", since=mark, what="the last will offline")
        hub.wait("spBv1.0/%s/NDEATH/%s" % (GROUP, HOST), since=mark, what="the Sparkplug NDEATH will")

        # The password is in no log, neither vmacd's nor the broker's.
        for name in os.listdir(t.logdir):
            path = os.path.join(t.logdir, name)
            if os.path.isfile(path) and (name.endswith(".log") or "stdout" in name or "stderr" in name):
                with open(path, errors="replace") as f:
                    assert PASSWORDS["vmac-kitchen"] not in f.read(), "the broker password is in %s" % name
    finally:
        hub.close()
        mallory.close()
