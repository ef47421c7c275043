"""Several hosts, one site (docs/MQTT.md, "Several hosts, one site"): two
vmacd hosts (host ids site-a and site-b, each on a bus of its own with a
lights board) on one real mosquitto. `vmac site --mqtt` lists both from the
broker alone; host A's GET /api/site shows host B's devices and their values
read-only, and follows them; B killed with SIGKILL shows offline in both
within the keep-alive window; malformed and foreign messages on the site's
topics, and more hosts, devices and values than the view keeps, change
nothing but its counters. Without mosquitto or python3-paho-mqtt every test
here is SKIPPED (a failure under CI=true), as in test_mqtt.py."""

import json
import os
import random
import signal
import time

from harness import LOADED, until
from test_mqtt import Broker, Hub

KEEPALIVE_S = 5  # mqtt_keepalive_s: the smallest the settings take


def other_bus():
    rnd = random.SystemRandom()
    return "239.255.%d.%d:%d" % (rnd.randint(1, 254), rnd.randint(1, 254), rnd.randint(20000, 60000))


def site_host(t, broker, host_id, bus=None, state=None, commands=False):
    settings = {"mqtt_url": broker.url, "mqtt_host_id": host_id, "mqtt_client_id": "vmac-" + host_id,
                "mqtt_keepalive_s": KEEPALIVE_S, "mqtt_commands": "true" if commands else "false"}
    extra = ("--state", state) if state else ()
    return t.host(settings=settings, bus=bus, extra=extra)


def two_hosts(t, broker):
    """Host A on the test's bus with lights-a, host B on another bus (its own
    state folder) with lights-b, commands on for B; returns (a, b, b_board)."""
    a = site_host(t, broker, "site-a")
    t.board("lights", "lights-a")
    a.wait_running(["lights-a"])
    state_b = os.path.join(t.logdir, "state-b")
    os.makedirs(state_b, exist_ok=True)
    bus_b = other_bus()
    b = site_host(t, broker, "site-b", bus=bus_b, state=state_b, commands=True)
    board_b = t.board("lights", "lights-b", bus=bus_b)
    return a, b, board_b


def vmac_site(t, broker, *args, expect_rc=0):
    """vmac site --mqtt URL ARGS: its stdout (JSON parsed with --json)."""
    # --wait bounds the retained messages' arrival: LOADED seconds, as the
    # harness's waits (a view cut short by a stalled broker is partial).
    rc, out, err = t.run([t.path("vmac"), "site", "--mqtt", broker.url, "--wait", "%g" % LOADED] + list(args),
                         "vmac-site", 30)
    assert rc == expect_rc, "vmac site %s: exit %d, expected %d; stderr: %s; stdout: %s" % (
        " ".join(args), rc, expect_rc, err, out)
    return json.loads(out) if "--json" in args else out


def host_of(site, host_id):
    for h in site["hosts"]:
        if h["host"] == host_id:
            return h
    raise AssertionError("host %s not in the site view: %s" % (host_id, [h["host"] for h in site["hosts"]]))


def device_of(site, host_id, device):
    for d in host_of(site, host_id)["devices"]:
        if d["device"] == device:
            return d
    raise AssertionError("device %s of host %s not in the site view: %s" % (device, host_id, host_of(site, host_id)))


def wait_site(fetch, predicate, timeout_s, what):
    """fetch() until predicate(view) holds (an AssertionError inside counts as
    not yet); the view, or an AssertionError saying what was last seen."""
    seen = {"view": None, "why": None}

    def look():
        try:
            seen["view"] = fetch()
            return seen["view"] if predicate(seen["view"]) else None
        except AssertionError as e:
            seen["why"] = e
            return None

    return until(look, timeout_s, lambda: "%s (%s); last view: %s" % (what, seen["why"], json.dumps(
        seen["view"])[:3000]), poll_s=0.2)


LIGHTS = {"kitchen", "dining", "tv", "disposal"}


def both_online(site, kitchen=False):
    """Both hosts and their lights online with every light's value come (they
    arrive one message each), the kitchen light as said (None: any)."""
    return all(host_of(site, h)["state"] == "online" and device_of(site, h, d)["state"] == "online" and
               LIGHTS <= set(device_of(site, h, d)["values"]) and
               (kitchen is None or device_of(site, h, d)["values"].get("kitchen") is kitchen)
               for h, d in (("site-a", "lights-a"), ("site-b", "lights-b")))


def test_site_two_hosts_listed_followed_and_a_killed_one_offline(t):
    broker = Broker(t)
    a, b, _ = two_hosts(t, broker)
    api = lambda: a.get("/api/site")  # noqa: E731
    view = wait_site(api, both_online, 30, "host A's /api/site showing both hosts and their lights online")
    assert view["enabled"] is True and view["connected"] is True and view["self"] == "site-a", view
    assert host_of(view, "site-a")["self"] is True and host_of(view, "site-b")["self"] is False, view
    values_b = device_of(view, "site-b", "lights-b")["values"]
    assert values_b == {"kitchen": False, "dining": False, "tv": False, "disposal": False}, values_b

    cli = wait_site(lambda: vmac_site(t, broker, "--json"), both_online, 30, "vmac site --json listing both")
    assert cli["self"] is None and [h["host"] for h in cli["hosts"]] == ["site-a", "site-b"], cli
    text = vmac_site(t, broker)
    assert "2 hosts, 2 online" in text, text
    for line in ("site-a", "site-b", "lights-a", "lights-b"):
        assert any(l.split()[:2] == [line, "online"] for l in text.splitlines()), "%r online in:\n%s" % (line, text)
    assert "kitchen=false" in text, text

    # A value that changes on B shows on A's page (B takes MQTT commands).
    hub = Hub(broker)
    try:
        hub.publish("vmac/site-b/lights-b/set/kitchen", "true")
        wait_site(api, lambda s: device_of(s, "site-b", "lights-b")["values"]["kitchen"] is True, 30,
                  "B's kitchen light on, seen in A's /api/site")
    finally:
        hub.close()

    window_s = KEEPALIVE_S * 1.5 + 3  # the broker's keep-alive window, and a margin for the polls
    offline = lambda s: (host_of(s, "site-b")["state"] == "offline" and  # noqa: E731
                         device_of(s, "site-b", "lights-b")["state"] == "offline")
    # B cut off without closing its connection (frozen, as by a power cut
    # behind a switch): the broker gives up on it after 1.5 keep-alives and
    # publishes its last will.
    # When the broker gives up is Mosquitto's doing (1.5 keep-alives after
    # B's last packet, checked on its own timer); on a busy machine that
    # and A's taking the will can come late, so the wait is generous and
    # the time it took is printed, not judged against the window.
    b.signal(signal.SIGSTOP)
    try:
        frozen = time.monotonic()
        wait_site(api, offline, 6 * window_s, "B offline in A's /api/site after SIGSTOP (the broker's keep-alive)")
        print("site: a frozen B offline in A's view %.1f s later (keep-alive %d s)" % (
            time.monotonic() - frozen, KEEPALIVE_S))
    finally:
        b.signal(signal.SIGCONT)
    wait_site(api, lambda s: both_online(s, None), 60, "B online again after SIGCONT (it reconnects with backoff)")

    # B dies: the broker sees its connection close and publishes its last will.
    b.signal(signal.SIGKILL)
    b.wait_exit(10)
    killed = time.monotonic()
    view = wait_site(api, offline, window_s, "B offline in A's /api/site after SIGKILL")
    took_s = time.monotonic() - killed
    assert host_of(view, "site-a")["state"] == "online" and device_of(view, "site-a", "lights-a")["state"] == "online"
    assert "kitchen" in device_of(view, "site-b", "lights-b")["values"], "the last values are kept"
    cli = wait_site(lambda: vmac_site(t, broker, "--json"), offline, window_s, "B offline in vmac site")
    assert host_of(cli, "site-a")["state"] == "online", cli
    text = vmac_site(t, broker)
    assert "2 hosts, 1 online" in text and any(l.split()[:2] == ["site-b", "offline"] for l in text.splitlines()), text
    print("site: B offline in A's view %.1f s after SIGKILL (keep-alive %d s)" % (took_s, KEEPALIVE_S))
    a.status()  # A itself is unharmed


def test_site_malformed_foreign_and_too_many_messages_change_only_counters(t):
    broker = Broker(t)
    a = site_host(t, broker, "site-a")
    t.board("lights", "lights-a")
    a.wait_running(["lights-a"])
    wait_site(lambda: a.get("/api/site"), lambda s: device_of(s, "site-a", "lights-a")["state"] == "online", 30,
              "A's own lights in its site view")
    hub = Hub(broker)
    try:
        bad = [
            ("vmac/bad host!/status", "online"),            # not a host id
            ("vmac/x/status", "maybe"),                     # neither online nor offline
            ("vmac/x/status", b"\xff\xfe"),
            ("vmac/x/dev 1/_availability", "online"),       # not a device name
            ("vmac/x/dev-1/_availability", "up"),
            ("vmac/x/dev-1/Kitchen", "1"),                  # not a variable's name
            ("vmac/x/dev-1/kitchen", "y" * 100),            # longer than any value vmacd publishes
            ("vmac/x/dev-1/kitchen", b"\xc3\x28"),          # not UTF-8
            ("vmac/x/dev-1/kitchen", b"a\x00b"),            # a NUL
            ("vmac/x/dev-1/kitchen", "line\nbreak"),        # control characters
            ("vmac/" + "h" * 200 + "/status", "online"),    # a host id too long
        ]
        # The host's own topics (a refusal, and any other _NAME) are no values.
        foreign = [("vmac/x/dev-1/_error", '{"not": "a value"}'), ("vmac/x/dev-1/_health", "{}"),
                   ("vmac/x/dev-1/set/kitchen", "true"),
                   ("vmac/x/error", "?"), ("other/x/status", "online"), ("vmac/x/y/z/w", "?"), ("vmac", "?")]
        for topic, payload in bad + foreign:
            hub.publish(topic, payload, retain=True)
        # Bounds: 70 hosts (offline: they make room for each other), 300
        # devices on one host, 80 values on one device.
        for i in range(70):
            hub.publish("vmac/ghost-%02d/status" % i, "offline", retain=True)
        for i in range(300):
            hub.publish("vmac/many/dev-%03d/_availability" % i, "online", retain=True)
        for i in range(80):
            hub.publish("vmac/many/dev-000/v%02d" % i, str(i), retain=True)
        hub.publish("vmac/many/status", "online", retain=True)
        hub.publish("vmac/fine/dev-1/note", "café 12", retain=True)  # UTF-8 strings are values too
        hub.publish("vmac/fine/dev-1/ratio", "0.25", retain=True)
        hub.publish("vmac/fine/dev-1/gone", "1", retain=True)
        hub.publish("vmac/fine/dev-1/gone", "", retain=True)  # the retained value cleared
        hub.publish("vmac/fine/dev-1/unset", "7", retain=True)
        hub.publish("vmac/fine/dev-1/unset", "None", retain=True)  # the driver's nil: no value
        hub.publish("vmac/fine/dev-1/error", "E42", retain=True)  # a variable named error is a value

        def settled(s):
            many = host_of(s, "many")
            return (s["malformed"] >= len(bad) and s["dropped"]["hosts"] > 0 and
                    many["devices_dropped"] > 0 and device_of(s, "many", "dev-000")["values_dropped"] > 0 and
                    "error" in device_of(s, "fine", "dev-1")["values"])

        view = wait_site(lambda: a.get("/api/site"), settled, 30, "every bad message counted, the bounds kept")
        assert len(view["hosts"]) <= 64, len(view["hosts"])
        assert len(host_of(view, "many")["devices"]) == 256, len(host_of(view, "many")["devices"])
        assert len(device_of(view, "many", "dev-000")["values"]) == 64
        fine = {"note": "café 12", "ratio": 0.25, "error": "E42"}
        assert device_of(view, "fine", "dev-1")["values"] == fine, view
        assert device_of(view, "fine", "dev-1")["state"] == "unknown", "no status, no availability: unknown"
        assert device_of(view, "site-a", "lights-a")["state"] == "online" and host_of(view, "site-a")["self"]
        for h in view["hosts"]:
            assert h["host"] != "x" or all(d["values"] == {} for d in h["devices"]), h
        # The same messages through vmac site: no crash, the same counters' kind.
        cli = vmac_site(t, broker, "--json")  # it gets the retained ones: the last of each topic
        retained_bad = len(set(topic for topic, _ in bad))
        assert cli["malformed"] == retained_bad and len(cli["hosts"]) <= 64, (cli["malformed"], retained_bad)
        assert cli["dropped"]["hosts"] > 0 and host_of(cli, "many")["devices_dropped"] > 0, cli["dropped"]
        assert device_of(cli, "fine", "dev-1")["values"] == fine, cli
        text = vmac_site(t, broker)
        assert "malformed messages" in text, text
    finally:
        hub.close()
    a.status()
    assert a.alive(), "host A survived it all"


def test_site_without_mqtt_and_vmac_site_usage(t):
    host = t.host()
    assert host.get("/api/site") == {"enabled": False, "why": "MQTT is off (no mqtt_url): no site view"}
    vmac = t.path("vmac")
    rc, out, _ = t.run([vmac, "site", "--help"], "vmac-site-help")
    assert rc == 0 and "--mqtt URL" in out and "Exit codes" in out, out
    for argv, code, text in ((["site"], 2, "--mqtt URL is needed"),
                             (["site", "--mqtt", "http://x"], 2, "mqtt_url"),
                             (["site", "--mqtt", "mqtt://127.0.0.1:1", "--wait", "0"], 2, "--wait"),
                             (["site", "--mqtt", "mqtt://127.0.0.1:1", "extra"], 2, "unexpected argument")):
        rc, _, err = t.run([vmac] + argv, "vmac-site-usage")
        assert rc == code and text in err, "%s: exit %d, stderr %r" % (argv, rc, err)
    with __import__("socket").socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rc, _, err = t.run([vmac, "site", "--mqtt", "mqtt://127.0.0.1:%d" % port, "--wait", "0.5"], "vmac-site-down")
    assert rc == 1 and "cannot reach the broker" in err, (rc, err)
    broker = Broker(t)
    rc, out, err = t.run([vmac, "site", "--mqtt", broker.url, "--wait", "0.5"], "vmac-site-empty")
    assert rc == 3 and "no vmac host" in err and "0 hosts" in out, (rc, out, err)
