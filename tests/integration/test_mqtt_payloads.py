"""Payloads and topics as Home Assistant reads them (docs/MQTT.md,
"Conformance: payloads and topics"), against a real broker with a driver of
the test's own: a variable named `error` on its own topic, apart from the
refusals on `_error`; no value (nil, NaN, infinity) published as `None`;
command payloads delivered as the manifest declares them (a select of
strings that look like a number or a boolean, a text, a number, numeric
choices); numeric choices as strings, in the state and in the select's
options. Without mosquitto or python3-paho-mqtt: SKIPPED."""

import json
import time

from harness import LOADED, until
from test_mqtt import HOST_ID, PREFIX, Broker, Hub

PROBE_LUA = """
local driver = {
	name = "probe",
	version = "1.0.0",
	description = "MQTT payloads: names, nothing, choices",
	io = { di0 = "di0" },
	params = {
		mode = { default = "1", values = { "1", "on", "true" }, label = "Mode" },
		gear = { default = 1, values = { 1, 2, 3 }, label = "Gear" },
		note = { default = "x", label = "Note" },
		speed = { default = 5, min = 0, max = 10, label = "Speed" },
	},
	variables = {
		error = { label = "Error" },
		reading = { label = "Reading" },
		ratio = { unit = "%", label = "Ratio" },
		seen = { label = "Seen" },
		temp_c = { unit = "degC", precision = 1, label = "Temperature" },
		raw_c = { label = "Temperature, every digit" }, -- no unit: a unit brings a default precision (DRIVERS.md)
		edge_c = { unit = "degC", precision = 1, label = "Temperature on a rounding boundary" },
	},
}
local ticks = 0

function driver.tick(dev, inputs)
	local p = dev.params
	ticks = ticks + 1
	dev.vars.temp_c = 20 + p.speed + (ticks % 4) * 0.01 -- noise below the declared precision
	dev.vars.raw_c = dev.vars.temp_c
	dev.vars.edge_c = 20 + p.speed + 0.04 + (ticks % 3) * 0.01 -- rounds to x.0 and x.1 by turns
	dev.vars.error = "E42"
	dev.vars.reading = p.speed ~= 3 and p.speed or nil
	dev.vars.ratio = p.speed == 0 and 0 / 0 or p.speed == 10 and math.huge or p.speed * 10
	dev.vars.seen = type(p.mode) .. ":" .. tostring(p.mode) .. " " .. type(p.gear) .. ":" .. tostring(p.gear)
		.. " " .. type(p.note) .. ":" .. tostring(p.note)
end

return driver
"""

DEV = PREFIX + "/probe-1"


def test_mqtt_payloads_names_nothing_and_typed_commands(t):
    broker = Broker(t)
    host = t.host(drivers=t.drivers(probe=PROBE_LUA),
                  settings={"mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_commands": "true"})
    t.board("generic", "probe-1", driver="probe")
    host.wait_running(["probe-1"])
    hub = Hub(broker)
    try:
        def seen(text, since):
            return hub.wait(DEV + "/seen", lambda p: p == text, since=since, what="seen %r" % text)

        def refused(name, payload, code, text):
            mark = hub.mark()
            hub.publish("%s/set/%s" % (DEV, name), payload)
            body = json.loads(hub.wait(DEV + "/_error", since=mark, what="a refusal of %s=%r" % (name, payload)))
            assert body["code"] == code and text in body["error"], "%s=%r: %s" % (name, payload, body)

        # A variable named error is the driver's, on its own topic; refusals have theirs.
        assert hub.wait(DEV + "/error", lambda p: p == "E42", what="the variable error") == "E42"
        refused("speed", "99", "refused", "out of range")
        refused("speed", "on", "malformed", "expected a number")
        assert hub.latest[DEV + "/error"][0] == "E42", "a refusal overwrote the variable error"
        # Commands typed by the declaration: a select's option is a string
        # whatever it looks like; numeric choices are numbers.
        seen("string:1 number:1 string:x", None)
        for payload in ("on", "true", "1"):
            mark = hub.mark()
            hub.publish(DEV + "/set/mode", payload)
            hub.wait(DEV + "/mode", lambda p: p == payload, since=mark, what="mode %r" % payload)
        mark = hub.mark()
        hub.publish(DEV + "/set/gear", "2")
        hub.publish(DEV + "/set/note", "12")
        seen("string:1 number:2 string:12", mark)
        hub.wait(DEV + "/gear", lambda p: p == "2", since=mark, what="gear's state 2 (its option's text, not 2.0)")
        gear = hub.config("select", "probe-1", "gear")
        assert gear["options"] == ["1", "2", "3"], "numeric choices as strings: %s" % gear["options"]
        mode = hub.config("select", "probe-1", "mode")
        assert mode["options"] == ["1", "on", "true"], mode["options"]
        refused("gear", "4", "refused", "not one of the allowed values")
        refused("mode", "off", "refused", "not one of the allowed values")
        # No value: nil, NaN and infinity are HA's None, retained.
        for speed, name, want in (("3", "reading", "None"), ("4", "reading", "4"), ("0", "ratio", "None"),
                                  ("5", "ratio", "50"), ("10", "ratio", "None")):
            mark = hub.mark()
            hub.publish(DEV + "/set/speed", speed)
            hub.wait("%s/%s" % (DEV, name), lambda p: p == want, since=mark, what="%s %r at speed %s" % (
                name, want, speed))
        cfg = hub.config("sensor", "probe-1", "ratio")
        assert cfg["unit_of_measurement"] == "%", cfg
        late = Hub(broker, "late")
        try:
            for name, want in (("ratio", "None"), ("error", "E42")):
                got = late.wait("%s/%s" % (DEV, name))
                assert (got, late.latest["%s/%s" % (DEV, name)][1]) == (want, True), \
                    "a late subscriber gets %s %r retained, got %r" % (name, want, late.latest[DEV + "/" + name])
        finally:
            late.close()
        # A declared precision: the noise below it is not published, nor
        # noise across a rounding boundary (30.04, 30.05, 30.06: 30.0 and
        # 30.1 by turns), which is less than a step from what went out.
        hub.wait(DEV + "/temp_c", lambda p: p == "30.0", what="temp_c 30.0 at speed 10 (one decimal)")
        hub.wait(DEV + "/edge_c", lambda p: p in ("30.0", "30.1"), what="edge_c 30.0 or 30.1 at speed 10")
        hub.wait(DEV + "/raw_c", lambda p: p != "30", what="raw_c with its noise")
        # The window is three publications of raw_c, which changes whenever
        # temp_c's noise does: however slowly a busy machine ticks, temp_c
        # and edge_c had as many chances to go out unrounded.
        mark = hub.mark()
        deadline = time.monotonic() + 30 * LOADED  # a window, then what it held: until does not fit
        with hub.cond:
            while True:
                window = hub.log[mark:]
                raws = [p for tp, p in window if tp == DEV + "/raw_c"]
                if len(raws) >= 3 or time.monotonic() > deadline:
                    break
                hub.cond.wait(0.5)
        temps = [p for tp, p in window if tp == DEV + "/temp_c"]
        edges = [p for tp, p in window if tp == DEV + "/edge_c"]
        assert temps == [] and edges == [] and len(raws) >= 3, \
            "while raw_c (no precision) went out %d times %r: temp_c %r, edge_c %r (precision 1, noise " \
            "across 30.05)" % (len(raws), raws, temps, edges)
        # The host's own site view: error a value, None no value.
        site = {}

        def site_view():
            site["last"] = host.get("/api/site")
            dev = [d for h in site["last"]["hosts"] if h["host"] == HOST_ID
                   for d in h["devices"] if d["device"] == "probe-1"]
            return dev and dev[0]["values"].get("error") == "E42" and "ratio" not in dev[0]["values"]

        until(site_view, 30, lambda: "the site view: error a value, ratio (None) none: %s" % site["last"], poll_s=0.2)
        # A whole step of edge_c is published.
        mark = hub.mark()
        hub.publish(DEV + "/set/speed", "9")
        hub.wait(DEV + "/edge_c", lambda p: p in ("29.0", "29.1"), since=mark, what="edge_c at speed 9, a step down")
    finally:
        hub.close()
