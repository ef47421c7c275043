"""Home Assistant's MQTT discovery as HA reads it (docs/MQTT.md,
"Conformance: Home Assistant"): every config the demo kitchen publishes,
and every retained value its sensors read, judged by a checker written from
HA's schemas and entity checks, one function per platform, each rule named
as the matrix names it (C1.., S1.., N1..) with the HA source it comes from.
A config that breaks a rule fails with the config's topic and the rule.
Beside them: the health topics the diagnostic sensors read, and the
washer's event entity saying a programme started and that it was dropped.
With mqtt_discovery_mode = device, the same checker reads each device
config as HA's discovery.py does (rules D1..D5), and the move from one
mode to the other follows HA's migration (migrate_discovery, the configs
in the new mode, the old ones cleared) both ways.
Real Mosquitto as in test_mqtt.py; SKIPPED without it or paho-mqtt."""

import json
import math
import os
import re
import signal
import time

import test_mqtt as base
from harness import KITCHEN_NAMES, plain_pass_only, undisturbed, until

DISCOVERY, PREFIX, HOST_ID = base.DISCOVERY, base.PREFIX, base.HOST_ID

# homeassistant/components/sensor/const.py: DEVICE_CLASS_UNITS (None = no
# unit; "any" = no entry, any unit) and DEVICE_CLASS_STATE_CLASSES, the
# units those a number (number/const.py) accepts too (hints.c says why).
M, T, I = "measurement", "total", "total_increasing"
ALL = {M, T, I}
ENERGY = "J kJ MJ GJ mWh Wh kWh MWh GWh TWh cal kcal Mcal Gcal".split()
PRESSURE = "Pa kPa hPa bar cbar mbar mmHg inHg psi".split()
SPEED = "Beaufort ft/s in/s km/h kn m/s mph mm/s".split()
FLUX = "in/d in/h mm/d mm/h".split()
VOLUME = ["L", "mL", "m³", "ft³", "CCF", "gal", "fl. oz."]
UG = ["µg/m³"]
SENSOR = {
    "apparent_power": (["VA"], {M}), "aqi": ([None], {M}),
    "area": ("m² cm² km² mm² in² ft² yd² mi² ac ha".split(), ALL), "atmospheric_pressure": (PRESSURE, {M}),
    "battery": (["%"], {M}), "blood_glucose_concentration": (["mg/dL", "mmol/L"], {M}),
    "carbon_monoxide": (["ppm"], {M}), "carbon_dioxide": (["ppm"], {M}),
    "conductivity": (["S/cm", "mS/cm", "µS/cm"], {M}), "current": (["A", "mA"], {M}),
    "data_rate": ("bit/s kbit/s Mbit/s Gbit/s B/s kB/s MB/s GB/s KiB/s MiB/s GiB/s".split(), {M}),
    "data_size": ("bit kbit Mbit Gbit B kB MB GB TB PB EB ZB YB KiB MiB GiB TiB PiB EiB ZiB YiB".split(), ALL),
    "distance": ("mm cm m km in ft yd mi nmi".split(), ALL), "duration": (["d", "h", "min", "s", "ms"], ALL),
    "energy": (ENERGY, {T, I}), "energy_distance": (["kWh/100km", "mi/kWh", "km/kWh"], {M}),
    "energy_storage": (ENERGY, {M}), "frequency": (["Hz", "kHz", "MHz", "GHz"], {M}),
    "gas": (["m³", "ft³", "CCF"], {T, I}), "humidity": (["%"], {M}), "illuminance": (["lx"], {M}),
    "irradiance": (["W/m²", "BTU/(h⋅ft²)"], {M}), "moisture": (["%"], {M}), "monetary": ("any", {T}),
    "nitrogen_dioxide": (UG, {M}), "nitrogen_monoxide": (UG, {M}), "nitrous_oxide": (UG, {M}), "ozone": (UG, {M}),
    "ph": ([None], {M}), "pm1": (UG, {M}), "pm10": (UG, {M}), "pm25": (UG, {M}), "power_factor": (["%", None], {M}),
    "power": (["W", "kW", "MW", "GW", "TW"], {M}), "precipitation": (["cm", "in", "mm"], ALL),
    "precipitation_intensity": (FLUX, {M}), "pressure": (PRESSURE, {M}), "reactive_power": (["var"], {M}),
    "signal_strength": (["dB", "dBm"], {M}), "sound_pressure": (["dB", "dBA"], {M}), "speed": (SPEED + FLUX, {M}),
    "sulphur_dioxide": (UG, {M}), "temperature": (["°C", "°F", "K"], {M}),
    "temperature_delta": (["°C", "°F", "K"], {M}), "volatile_organic_compounds": (UG, {M}),
    "volatile_organic_compounds_parts": (["ppm", "ppb"], {M}), "voltage": (["V", "mV", "µV", "kV", "MV"], {M}),
    "volume": (VOLUME, {T, I}), "volume_flow_rate": ("m³/h ft³/min L/min gal/min mL/s L/h L/s m³/s".split(), {M}),
    "volume_storage": (VOLUME, {M}), "water": (["m³", "ft³", "CCF", "gal", "L"], {T, I}),
    "weight": ("kg g mg µg oz lb st".split(), ALL), "wind_direction": (["°"], set()), "wind_speed": (SPEED, {M}),
}
SENSOR_TEXT = {"date", "enum", "timestamp"}  # NON_NUMERIC_DEVICE_CLASSES
BINARY = set("battery battery_charging carbon_monoxide cold connectivity door garage_door gas heat light lock "
             "moisture motion moving occupancy opening plug power presence problem running safety smoke sound "
             "tamper update vibration window".split())
SWITCH, BUTTON, EVENT = {"outlet", "switch"}, {"identify", "restart", "update"}, {"doorbell", "button", "motion"}
NUMBER = set(SENSOR) - {"temperature_delta"}  # number/const.py NumberDeviceClass (of the classes above)
DEVICE_KEYS = {"identifiers", "connections", "manufacturer", "model", "model_id", "name", "hw_version",
               "serial_number", "sw_version", "via_device", "suggested_area", "configuration_url"}
ORIGIN_KEYS = {"name", "sw_version", "support_url"}
URL = re.compile(r"^[a-z][a-z0-9+.-]*://\S+$")  # cv.configuration_url: a URL with a scheme (or homeassistant://)

# Keys each platform's DISCOVERY_SCHEMA knows (others are dropped silently:
# extra=vol.REMOVE_EXTRA), the common ones from schemas.py.
COMMON = {"name", "unique_id", "availability", "availability_mode", "availability_topic", "device", "origin",
          "entity_category", "enabled_by_default", "icon", "json_attributes_topic", "json_attributes_template",
          "object_id", "default_entity_id", "qos", "encoding", "payload_available", "payload_not_available"}
KEYS = {
    "sensor": {"state_topic", "value_template", "device_class", "state_class", "unit_of_measurement",
               "suggested_display_precision", "expire_after", "force_update", "options",
               "last_reset_value_template"},
    "binary_sensor": {"state_topic", "value_template", "device_class", "payload_on", "payload_off",
                      "expire_after", "force_update", "off_delay"},
    "switch": {"state_topic", "command_topic", "value_template", "device_class", "payload_on", "payload_off",
               "state_on", "state_off", "optimistic", "retain", "command_template"},
    "number": {"state_topic", "command_topic", "value_template", "command_template", "device_class", "min", "max",
               "step", "mode", "unit_of_measurement", "payload_reset", "optimistic", "retain"},
    "select": {"state_topic", "command_topic", "value_template", "command_template", "options", "optimistic",
               "retain"},
    "text": {"state_topic", "command_topic", "value_template", "command_template", "min", "max", "mode",
             "pattern", "optimistic", "retain"},
    "button": {"command_topic", "command_template", "payload_press", "device_class", "retain"},
    "event": {"state_topic", "value_template", "device_class", "event_types"},
}

TOPIC_MATCHER = re.compile(r"^%s/(\w+)/(?:([a-zA-Z0-9_-]+)/)?([a-zA-Z0-9_-]+)/config$" % DISCOVERY)


def rule(ok, topic, code, text):
    if not ok:
        raise AssertionError("%s: rule %s: %s" % (topic, code, text))


def check_common(topic, component, cfg):
    rule(TOPIC_MATCHER.match(topic) is not None, topic, "C1", "discovery.py TOPIC_MATCHER: bad config topic")
    unknown = set(cfg) - COMMON - KEYS[component]
    rule(not unknown, topic, "C2", "keys %s are not in %s's DISCOVERY_SCHEMA (dropped)" % (sorted(unknown), component))
    rule(isinstance(cfg.get("unique_id"), str), topic, "C3", "unique_id a string")
    dev = cfg.get("device", {})
    # HA takes identifiers and/or connections; vmac always sends identifiers.
    rule(isinstance(dev.get("identifiers"), list) and dev["identifiers"] and
         all(isinstance(i, str) for i in dev["identifiers"]), topic, "C4",
         "schemas.py validate_device_has_at_least_one_identifier")
    rule(set(dev) <= DEVICE_KEYS and all(isinstance(dev[k], str) for k in dev if k not in ("identifiers", "connections")),
         topic, "C4", "schemas.py MQTT_ENTITY_DEVICE_INFO_SCHEMA: device keys %s" % sorted(set(dev) - DEVICE_KEYS))
    rule("configuration_url" not in dev or URL.match(dev["configuration_url"]), topic, "C4",
         "device configuration_url not a URL with a scheme (cv.configuration_url)")
    origin = cfg.get("origin")
    rule(isinstance(origin, dict) and isinstance(origin.get("name"), str) and set(origin) <= ORIGIN_KEYS and
         isinstance(origin.get("sw_version", ""), str) and URL.match(origin.get("support_url", "a://b")), topic, "C5",
         "schemas.py MQTT_ORIGIN_INFO_SCHEMA: origin with a name, sw_version a string, support_url a URL")
    rule(cfg.get("entity_category") in (None, "config", "diagnostic"), topic, "C6", "ENTITY_CATEGORIES_SCHEMA")
    rule(isinstance(cfg.get("enabled_by_default", True), bool), topic, "C7", "enabled_by_default a boolean")
    rule(not ("availability" in cfg and "availability_topic" in cfg), topic, "C8",
         "MQTT_AVAILABILITY_SCHEMA: availability and availability_topic are exclusive")
    for a in cfg.get("availability", []):
        # valid_subscribe_topic allows whole-level wildcards; vmac's topics have none.
        rule(isinstance(a.get("topic"), str) and a["topic"] and "#" not in a["topic"] and "+" not in a["topic"],
             topic, "C8", "MQTT_AVAILABILITY_LIST_SCHEMA: availability topics valid (valid_subscribe_topic)")
    rule(cfg.get("availability_mode", "latest") in ("all", "any", "latest"), topic, "C8", "availability_mode")


def check_sensor(topic, cfg, value):
    dc, sc, unit = cfg.get("device_class"), cfg.get("state_class"), cfg.get("unit_of_measurement")
    rule(dc is None or dc in SENSOR or dc in SENSOR_TEXT, topic, "S1", "device_class %r not a SensorDeviceClass" % dc)
    rule(sc in (None, M, T, I), topic, "S2", "state_class %r not a SensorStateClass" % sc)
    if dc in SENSOR and SENSOR[dc][0] != "any":
        rule(unit in SENSOR[dc][0], topic, "S3", "sensor/__init__.py state: unit %r not valid for %s (%s)"
             % (unit, dc, SENSOR[dc][0]))
    if dc in SENSOR and sc:
        rule(sc in SENSOR[dc][1], topic, "S4", "state_class %r impossible for device class %s" % (sc, dc))
    if dc in SENSOR_TEXT:
        rule(not unit and not sc, topic, "S5", "a non-numeric device class takes no unit nor state class")
    if "options" in cfg:
        rule(dc == "enum" and cfg["options"] and not sc and not unit and
             all(isinstance(o, str) for o in cfg["options"]), topic, "S6",
             "sensor.py validate_sensor_state_and_device_class_config: options only on enum, non-empty")
    rule(cfg.get("entity_category") != "config", topic, "S7",
         "SensorEntity.async_internal_added_to_hass: category config refused")
    p = cfg.get("suggested_display_precision")
    rule(p is None or (isinstance(p, int) and p >= 0), topic, "S8", "suggested_display_precision cv.positive_int")
    # mqtt/sensor.py _update_state: "None" is unknown, "" ignored on a numeric sensor.
    if value not in (None, "", "None") and "value_template" not in cfg:
        numeric = dc not in SENSOR_TEXT and (sc or unit or p is not None or dc is not None)
        if numeric:
            try:
                number = float(value)
            except ValueError:
                number = None
            rule(number is not None and math.isfinite(number), topic, "S9",
                 "a numeric sensor got the non-numeric or non-finite value %r" % value)
        if dc == "enum":
            rule(value in cfg["options"], topic, "S9", "value %r not among the options" % value)
    if dc == "enum":
        rule(all(o != "None" for o in cfg.get("options", [])), topic, "S6", "option \"None\" reads as unknown")


def check_binary_sensor(topic, cfg, value):
    dc = cfg.get("device_class")
    rule(dc is None or dc in BINARY, topic, "B1", "device_class %r not a BinarySensorDeviceClass" % dc)
    rule(isinstance(cfg.get("state_topic"), str), topic, "B2", "state_topic required (MQTT_RO_SCHEMA)")
    if value not in (None, "", "None"):
        rule(value in (cfg.get("payload_on", "ON"), cfg.get("payload_off", "OFF")), topic, "B3",
             "binary_sensor.py: payload %r is neither payload_on nor payload_off" % value)
    rule(cfg.get("entity_category") != "config", topic, "B4",
         "BinarySensorEntity.async_internal_added_to_hass: category config refused")
    e = cfg.get("expire_after")
    rule(e is None or (isinstance(e, int) and e >= 0), topic, "B5", "expire_after cv.positive_int")


def check_switch(topic, cfg, value):
    rule(cfg.get("device_class") in (None,) + tuple(SWITCH), topic, "W1", "device_class not a SwitchDeviceClass")
    rule(isinstance(cfg.get("command_topic"), str), topic, "W2", "command_topic required (MQTT_RW_SCHEMA)")


def check_number(topic, cfg, value):
    lo, hi, step = cfg.get("min", 0), cfg.get("max", 100), cfg.get("step", 1)  # number/const.py defaults
    rule(lo < hi, topic, "N1", "number.py validate_config: max must be > min")
    rule(step >= 1e-3, topic, "N2", "number.py: step vol.Range(min=1e-3)")
    dc = cfg.get("device_class")
    rule(dc is None or dc in NUMBER, topic, "N3", "device_class %r not a NumberDeviceClass" % dc)
    if dc in NUMBER and SENSOR[dc][0] != "any":
        rule(cfg.get("unit_of_measurement") in SENSOR[dc][0], topic, "N3", "unit not valid for %s" % dc)
    rule(cfg.get("mode", "auto") in ("auto", "box", "slider"), topic, "N4", "NumberMode")
    rule(isinstance(cfg.get("command_topic"), str), topic, "N5", "command_topic required")
    if value not in (None, "", cfg.get("payload_reset", "None")):
        rule(lo <= float(value) <= hi, topic, "N6", "value %r out of min..max" % value)


def check_select(topic, cfg, value):
    opts = cfg.get("options")
    # HA asks only for a list (cv.ensure_list); vmac's are non-empty, strings, and none of
    # them one HA could never show ("" is ignored, "none" in any case is unknown).
    rule(isinstance(opts, list) and opts and all(isinstance(o, str) and o.strip() and o.lower() != "none"
                                                  for o in opts), topic, "L1",
         "select.py: options a non-empty list of strings HA can show")
    rule(isinstance(cfg.get("command_topic"), str), topic, "L2", "command_topic required")
    if value not in (None, "") and value.lower() != "none":
        rule(value in opts, topic, "L3", "select.py: value %r not among the options" % value)


def check_text(topic, cfg, value):
    lo, hi = cfg.get("min", 0), cfg.get("max", 255)
    rule(isinstance(lo, int) and isinstance(hi, int) and 0 <= lo <= hi <= 255, topic, "X1",
         "text.py valid_text_size_configuration: 0 <= min <= max <= 255 (MAX_LENGTH_STATE_STATE)")
    rule(isinstance(cfg.get("command_topic"), str), topic, "X2", "command_topic required")
    if "pattern" in cfg:
        try:
            re.compile(cfg["pattern"])
        except re.error:
            rule(False, topic, "X3", "pattern not a regular expression (cv.is_regex)")
    if value is not None:
        rule(len(value) <= 255, topic, "X4", "util.py check_state_too_long: state over 255 characters")


def check_button(topic, cfg, value):
    rule(cfg.get("device_class") in (None,) + tuple(BUTTON), topic, "U1", "device_class not a ButtonDeviceClass")
    rule(isinstance(cfg.get("command_topic"), str), topic, "U2", "command_topic required")


def check_event(topic, cfg, value):
    types = cfg.get("event_types")
    rule(isinstance(types, list) and types and all(isinstance(x, str) for x in types), topic, "E1",
         "event.py: event_types required, a list of strings")
    rule(isinstance(cfg.get("state_topic"), str), topic, "E2", "state_topic required (MQTT_RO_SCHEMA)")
    rule(cfg.get("device_class") in (None,) + tuple(EVENT), topic, "E3", "device_class not an EventDeviceClass")
    rule(cfg.get("device_class") != "doorbell" or "ring" in types, topic, "E4",
         "event/__init__.py: a doorbell without the ring event type is warned about")


# Device-based discovery (mqtt_discovery_mode = device): homeassistant/
# components/mqtt/discovery.py (TOPIC_MATCHER, the subscription to
# DISCOVERY/device/+/config, _parse_device_payload, the loop that makes a
# config of each component) and schemas.py (DEVICE_DISCOVERY_SCHEMA,
# SHARED_OPTIONS, check_unique_id).
DEVICE_TOPIC = re.compile(r"^%s/device/(?:([a-zA-Z0-9_-]+)/)?([a-zA-Z0-9_-]+)/config$" % DISCOVERY)
AVAILABILITY = {"availability", "availability_mode", "availability_template", "availability_topic",
                "payload_available", "payload_not_available"}  # MQTT_AVAILABILITY_SCHEMA
DEVICE_ROOT = {"device", "components", "origin", "state_topic", "command_topic", "qos", "encoding",
               "message_expiry_interval"} | AVAILABILITY
SHARED = AVAILABILITY - {"availability_template"} | {"command_topic", "state_topic"}  # SHARED_OPTIONS
SUPPORTED = {"alarm_control_panel", "binary_sensor", "button", "camera", "climate", "cover", "date", "datetime",
             "device_automation", "device_tracker", "event", "fan", "humidifier", "image", "lawn_mower", "light",
             "lock", "notify", "number", "scene", "select", "sensor", "siren", "switch", "tag", "text", "time",
             "update", "vacuum", "valve", "water_heater"}  # const.py SUPPORTED_COMPONENTS


def expand_device(topic, payload):
    """A device config as discovery.py reads it (rules D1..D4): the config
    HA makes of each component, with the single component topic that has
    the same discovery id (DISCOVERY/PLATFORM/OBJECT/COMPONENT_ID/config)."""
    m = DEVICE_TOPIC.match(topic)
    rule(m is not None, topic, "D1", "discovery.py TOPIC_MATCHER: bad device config topic")
    rule(isinstance(payload, dict) and set(payload) <= DEVICE_ROOT, topic, "D2",
         "schemas.py DEVICE_DISCOVERY_SCHEMA: root keys %s are not allowed (the whole payload is refused)" %
         sorted(set(payload) - DEVICE_ROOT))
    rule(all(k in payload for k in ("device", "components", "origin")), topic, "D2",
         "DEVICE_DISCOVERY_SCHEMA: device, components and origin are required")
    comps = payload["components"]
    rule(isinstance(comps, dict) and comps, topic, "D3", "components: a mapping of component ids")
    out = []
    for cid, comp in sorted(comps.items()):
        rule(isinstance(comp, dict) and comp.get("platform") in SUPPORTED, topic, "D3",
             "component %s: platform required, one of SUPPORTED_COMPONENTS (COMPONENT_CONFIG_SCHEMA)" % cid)
        rule(re.match(r"^[a-zA-Z0-9_-]+$", cid) is not None, topic, "D3", "component id %r" % cid)
        rest = {k: v for k, v in comp.items() if k != "platform"}
        if not rest:
            continue  # the platform alone: the component's removal
        rule(isinstance(rest.get("unique_id"), str), topic, "D4",
             "component %s: an entity component needs a unique_id (schemas.py check_unique_id)" % cid)
        cfg = dict(rest, device=payload["device"], origin=payload["origin"])
        for k in SHARED:  # _merge_common_device_options
            if k in payload and k not in cfg:
                cfg[k] = payload[k]
        out.append(("%s/%s/%s/%s/config" % (DISCOVERY, comp["platform"], m.group(2), cid), cfg))
    return out


CHECKERS = {"sensor": check_sensor, "binary_sensor": check_binary_sensor, "switch": check_switch,
            "number": check_number, "select": check_select, "text": check_text, "button": check_button,
            "event": check_event}


def check_config(topic, cfg, value=None):
    """Every rule of the matrix for one config (and the retained value its
    state topic holds, if any): AssertionError naming topic and rule."""
    m = TOPIC_MATCHER.match(topic)
    component = m.group(1) if m else "?"
    rule(component in CHECKERS, topic, "C0", "vmac publishes no %s" % component)
    check_common(topic, component, cfg)
    CHECKERS[component](topic, cfg, value)


def check_all(hub):
    """Every config the hub holds (single component ones, and those HA makes
    of each device config) by the rules; {topic: config} of them."""
    with hub.cond:
        latest = dict(hub.latest)
    raw = {tp: json.loads(p) for tp, (p, _) in latest.items() if tp.startswith(DISCOVERY + "/") and p and
           tp.endswith("/config")}
    configs = {tp: c for tp, c in raw.items() if not DEVICE_TOPIC.match(tp)}
    for tp, payload in sorted(raw.items()):
        if DEVICE_TOPIC.match(tp):
            for ctp, cfg in expand_device(tp, payload):
                rule(ctp not in configs, tp, "D5", "%s is also discovered on %s: HA takes the first and warns of "
                     "a conflicting discovery message (entity.py)" % (cfg.get("unique_id"), ctp))
                configs[ctp] = cfg
    uids = [c.get("unique_id") for c in configs.values()]
    dup = {u for u in uids if uids.count(u) > 1}
    rule(not dup, "(all configs)", "C3", "unique_id used twice: %s" % sorted(dup))
    for tp, cfg in sorted(configs.items()):
        value, retained = latest.get(cfg.get("state_topic"), (None, False))
        if tp.startswith(DISCOVERY + "/event/"):
            rule(not retained, tp, "E2", "event.py _event_received: a retained event is ignored")
            value = None
        check_config(tp, cfg, value)
    return configs


def test_mqtt_ha_checker_names_the_config_and_the_rule(t):
    """The checker itself: a config HA would warn about fails by rule."""
    good = {"name": "T", "unique_id": "u", "state_topic": "s", "device": {"identifiers": ["d"]},
            "origin": {"name": "vmac"}, "unit_of_measurement": "L", "device_class": "temperature"}
    topic = DISCOVERY + "/sensor/n/o/config"
    for cfg, code in ((good, "S3"), (dict(good, device_class="volume_storage", state_class="total"), "S4"),
                      (dict(good, device_class="enum", options=[1]), "S5"),
                      (dict(good, device_class=None, entity_category="config"), "S7"),
                      (dict(good, device_class=None, origin=None), "C5")):
        try:
            check_config(topic, cfg)
        except AssertionError as e:
            assert topic in str(e) and ("rule %s" % code) in str(e), "wanted rule %s: %s" % (code, e)
        else:
            raise AssertionError("the checker passed a config breaking rule %s: %s" % (code, cfg))
    check_config(topic, dict(good, device_class="volume_storage", state_class="measurement"), "12.5")
    rw = {"name": "T", "unique_id": "u", "state_topic": "s", "command_topic": "c", "device": {"identifiers": ["d"]},
          "origin": {"name": "vmac"}}
    for component, cfg, value, code in (
            ("number", dict(rw, device_class="temperature_delta", unit_of_measurement="K"), None, "N3"),
            ("number", dict(rw, min=5), "3", "N6"),
            ("select", dict(rw, options=["off", "None"]), None, "L1"),
            ("text", dict(rw, min=10, max=5), None, "X1"),
            ("binary_sensor", dict({k: good[k] for k in good if k not in ("unit_of_measurement", "device_class")},
                                   entity_category="config"), None, "B4"),
            ("sensor", dict(good, device_class=None, origin={"name": "vmac", "support_url": "vmac.example"}), None,
             "C5"),
            ("sensor", dict(good, device_class=None, unit_of_measurement="W"), "nan", "S9")):
        topic = "%s/%s/n/o/config" % (DISCOVERY, component)
        try:
            check_config(topic, cfg, value)
        except AssertionError as e:
            assert ("rule %s" % code) in str(e), "wanted rule %s: %s" % (code, e)
        else:
            raise AssertionError("the checker passed a %s config breaking rule %s: %s" % (component, code, cfg))
    check_config(DISCOVERY + "/number/n/o/config", dict(rw, device_class="temperature", unit_of_measurement="K"), "0")
    dev = {"device": {"identifiers": ["d"]}, "origin": {"name": "vmac"},
           "components": {"o": {"platform": "sensor", "unique_id": "u", "state_topic": "s"}, "gone": {"platform": "text"}}}
    topic = DISCOVERY + "/device/n/config"
    made = expand_device(topic, dev)
    assert [tp for tp, _ in made] == [DISCOVERY + "/sensor/n/o/config"] and made[0][1]["device"] == dev["device"], made
    for payload, code in ((dict(dev, name="x"), "D2"), ({k: dev[k] for k in dev if k != "origin"}, "D2"),
                          (dict(dev, components={"o": {"unique_id": "u"}}), "D3"),
                          (dict(dev, components={"o": {"platform": "sensor", "state_topic": "s"}}), "D4")):
        try:
            expand_device(topic, payload)
        except AssertionError as e:
            assert ("rule %s" % code) in str(e), "wanted rule %s: %s" % (code, e)
        else:
            raise AssertionError("the checker passed a device config breaking rule %s: %s" % (code, payload))


def test_mqtt_ha_kitchen_configs_follow_home_assistant(t):
    broker = base.Broker(t)
    host = base.mqtt_host(t, broker)
    t.kitchen(host)
    hub = base.Hub(broker)
    try:
        for name in KITCHEN_NAMES:
            health = json.loads(hub.wait("%s/%s/_health" % (PREFIX, name), what="%s's health" % name))
            # The board's clock as the Clock sensors read it: null until it
            # sends a TIMED reply (a clock known now may be newer than the health).
            clock = host.device(name).get("clock")
            assert {"clock_state", "clock_bound_us", "clock_on_arrival"} <= set(health), health
            assert health["clock_state"] in ((None,) if clock is None else (
                None, "unsynced", "locking", "locked", "holdover", "lost")), (health, clock)
        hub.config("event", "washer-1", "_event")
        state = hub.config("sensor", "washer-1", "_health_clock_state")
        assert (state["device_class"], state["entity_category"], state["value_template"]) == (
            "enum", "diagnostic", "{{ value_json.clock_state }}"), state
        assert state["options"] == ["unsynced", "locking", "locked", "holdover", "lost"], state
        bound = hub.config("sensor", "washer-1", "_health_clock_bound_us")
        assert (bound["unit_of_measurement"], bound["state_class"]) == ("µs", "measurement"), bound
        temp = hub.config("sensor", "washer-1", "temp_c")
        assert (temp["device_class"], temp["state_class"], temp["suggested_display_precision"]) == (
            "temperature", "measurement", 1), temp
        hub.wait(PREFIX + "/washer-1/temp_c", what="a temperature")
        health = json.loads(hub.wait(PREFIX + "/_health", what="the host's health"))
        assert {"misses", "drops", "lateness_p99_ms"} <= set(health), health
        host_cfg = json.loads(hub.wait("%s/binary_sensor/%s/status/config" % (DISCOVERY, HOST_ID)))
        assert host_cfg["entity_category"] == "diagnostic" and host_cfg["origin"]["name"] == "vmac", host_cfg
        # The broker hands a new subscriber its retained messages in the
        # order of its own tables, not by topic: the health topics waited
        # for above may come before some configs.
        until(lambda: len(check_all(hub)) > 40, 10, lambda: "more than 40 configs (%d: %s)" % (
            len(check_all(hub)), sorted(check_all(hub))), poll_s=0.1)
        undisturbed(KITCHEN_NAMES)(host.last)
    finally:
        hub.close()


def test_mqtt_ha_events_say_a_start_and_a_drop(t):
    broker = base.Broker(t)
    host = base.mqtt_host(t, broker, extra={"miss_limit": 1})
    boards = t.kitchen(host)
    hub = base.Hub(broker)
    try:
        events = PREFIX + "/washer-1/_event"
        cfg = hub.config("event", "washer-1", "_event")
        assert "programme_started" in cfg["event_types"] and "dropped" in cfg["event_types"], cfg
        hub.wait(PREFIX + "/washer-1/state", what="the washer's state")
        since = hub.mark()
        hub.publish(PREFIX + "/washer-1/cmd/start", "quick")
        got = json.loads(hub.wait(events, lambda p: "programme_started" in p, since=since, what="a start event"))
        assert got == {"event_type": "programme_started"}, got
        with hub.cond:
            retained = hub.latest[events][1]
        assert not retained, "rule E2: HA ignores a retained event (event.py _event_received)"
        since = hub.mark()
        boards["washer-1"].signal(signal.SIGSTOP)
        try:
            hub.wait(events, lambda p: "dropped" in p, since=since, what="a drop event")
        finally:
            boards["washer-1"].signal(signal.SIGCONT)
    finally:
        hub.close()


def device_topic(node):
    return "%s/device/%s/config" % (DISCOVERY, node)


NODES = [HOST_ID] + ["%s_%s" % (HOST_ID, name) for name in KITCHEN_NAMES]  # the host's HA device, its machines'


def retained_configs(broker, want, what, steady_s=0.0):
    """The discovery configs the broker holds ({topic: payload}), once
    want(configs) holds, as an HA that starts now reads them: a new
    subscriber's retained messages, and what came on those topics since
    (a config published later, or cleared with an empty payload). With
    steady_s, once they have also stayed the same that long: a host
    publishes a machine's configs as one batch, and a look in the middle of
    one sees part of it. what: a text, or what(configs) gives one."""
    late = base.Hub(broker, "late")
    seen = [{}]
    same_since = [None, time.monotonic()]  # the view, and since when it has not changed

    def look():
        with late.cond:
            seen[0] = {tp: p for tp, (p, retained) in late.latest.items()
                       if p and tp.startswith(DISCOVERY + "/") and tp.endswith("/config")}
        if seen[0] != same_since[0]:
            same_since[:] = [seen[0], time.monotonic()]
        return want(seen[0]) and time.monotonic() - same_since[1] >= steady_s

    try:
        until(look, 30, lambda: "%s; retained configs: %s" % (what(seen[0]) if callable(what) else what,
                                                               sorted(seen[0])), poll_s=0.1)
        check_all(late)
        return seen[0]
    finally:
        late.close()


def ours(configs, device_based):
    """The configs of the host's nodes among configs, device ones or single
    component ones."""
    return {tp for tp in configs if (DEVICE_TOPIC.match(tp) is not None) == device_based and
            any("/%s/" % node in tp for node in NODES)}


def test_mqtt_ha_device_discovery_kitchen_and_a_removed_entity(t):
    """mqtt_discovery_mode = device: one config per HA device (the host and
    each machine), read as HA's discovery.py reads it by the same checker;
    a hot reload that drops the TV sends it once with its platform alone
    (HA's removal of a component), then the config without it."""
    broker = base.Broker(t)
    host = base.mqtt_host(t, broker, extra={"mqtt_discovery_mode": "device"})
    t.kitchen(host)
    hub = base.Hub(broker)
    try:
        for node in NODES:
            hub.wait(device_topic(node), lambda p: p != "", what="the device config of " + node)
        washer = json.loads(hub.wait(device_topic(HOST_ID + "_washer-1")))
        temp = washer["components"]["temp_c"]
        assert (temp["platform"], temp["device_class"], temp["unique_id"]) == (
            "sensor", "temperature", "vmac_test_washer-1_temp_c") and "device" not in temp, temp
        assert washer["device"]["identifiers"] == ["vmac_test_washer-1"] and washer["origin"]["name"] == "vmac", \
            washer
        retained = retained_configs(broker, lambda c: len(ours(c, True)) == len(NODES), "every device config")
        assert not ours(retained, False), "single component configs beside the device ones: %s" % ours(retained, False)
        assert len(check_all(hub)) > 40, "the device configs make only %d entities" % len(check_all(hub))

        here = os.path.dirname(os.path.abspath(__file__))
        with open(os.path.join(here, "..", "..", "scripts", "drivers", "lights.lua")) as f:
            src = f.read()
        new = src.replace('version = "1.2.0"', 'version = "1.2.1-ha"').replace(
            '\t\ttv = { set = true, device_class = "switch", label = "TV" },\n', "")
        assert new != src and "1.2.1-ha" in new, "the lights driver changed: this test needs updating"
        path = os.path.join(t.logdir, "lights.lua")
        with open(path, "w") as f:
            f.write(new)
        mark = hub.mark()
        rc, out, err = t.run([t.path("vmac"), "reload", "--http", host.http, "--probation", "0", path], "reload")
        assert rc == 0, "vmac reload failed (exit %d): %s %s" % (rc, out, err)
        lights = device_topic(HOST_ID + "_lights-1")
        hub.wait(lights, lambda p: p and json.loads(p)["components"].get("tv") == {"platform": "switch"}, since=mark,
                 what="the TV with its platform alone (its removal)")
        hub.wait(lights, lambda p: p and "tv" not in json.loads(p)["components"] and
                 json.loads(p)["device"]["model"] == "lights 1.2.1-ha", since=mark,
                 what="the lights' config without the TV, naming the new version")
        retained = retained_configs(broker, lambda c: "tv" not in json.loads(c.get(lights, "{}")).get(
            "components", {"tv": 1}), "the lights' retained config without the TV")
        assert "kitchen" in json.loads(retained[lights])["components"], retained[lights]
    finally:
        hub.close()


def moved(t, broker, hub, mode, old_topics, device_based):
    """vmacd started in mode after a vmacd of the other mode left old_topics
    on the broker: each is told migrate_discovery, the configs of its HA
    device come again in the new mode after that, then it is cleared; every
    node says so in the events. The host."""
    mark = hub.mark()
    host = base.mqtt_host(t, broker, extra={"mqtt_discovery_mode": mode})
    host.wait_running(KITCHEN_NAMES)
    migrate = lambda p: p.startswith("{") and json.loads(p) == {"migrate_discovery": True}  # noqa: E731
    for tp in sorted(old_topics):
        hub.wait(tp, migrate, since=mark, what="migrate_discovery on %s" % tp)
        hub.wait(tp, lambda p: p == "", since=mark, what="%s cleared after the migration" % tp)
        with hub.cond:
            log = [(i, topic, p) for i, (topic, p) in enumerate(hub.log) if i >= mark]
        told = min(i for i, topic, p in log if topic == tp and migrate(p))
        cleared = max(i for i, topic, p in log if topic == tp and p == "")
        node = next(n for n in sorted(NODES, key=len, reverse=True) if "/%s/" % n in tp)
        again = [i for i, topic, p in log if told < i < cleared and p and
                 (topic == device_topic(node) if device_based else "/%s/" % node in topic and topic != tp)]
        assert again, "%s: no config of %s in the new mode between its migrate_discovery and its clearing" % (tp, node)
    for name in [""] + KITCHEN_NAMES:
        host.wait_event("mqtt", device=name or None, text="migrated to %s discovery" % (
            "device-based" if device_based else "single component"))
    return host


@plain_pass_only("device-based discovery under the sanitizers: "
                 "test_mqtt_ha_device_discovery_kitchen_and_a_removed_entity; this one, three hosts one after "
                 "the other, once missed its last 30 s bound under ASan on a loaded VM")
def test_mqtt_ha_discovery_mode_moved_both_ways(t):
    """HA's documented migration between its two discovery modes, done by
    vmacd when it finds the other mode's retained configs of its own HA
    devices: single component to device-based and back; after each, the
    broker holds only the new mode's configs, which the checker passes."""
    broker = base.Broker(t)
    host = base.mqtt_host(t, broker)
    t.kitchen(host)
    hub = base.Hub(broker)
    try:
        # Settled: configs of every node (the host and each machine), the
        # same for a second. (A look in the middle of a machine's batch took
        # part of its configs as the whole, or none: more than 40 were the
        # host's, the washer's and the lights'.)
        singles = ours(retained_configs(
            broker, lambda c: all(ours({tp for tp in c if "/%s/" % node in tp}, False) for node in NODES),
            "the single component configs of every node", steady_s=1.0), False)
        host.signal(signal.SIGTERM)
        assert host.wait_exit(20) == 0, "vmacd did not stop cleanly"
        host = moved(t, broker, hub, "device", singles, True)
        retained = retained_configs(broker, lambda c: not ours(c, False) and len(ours(c, True)) == len(NODES),
                                    "device configs alone")
        host.signal(signal.SIGTERM)
        assert host.wait_exit(20) == 0, "vmacd did not stop cleanly"
        moved(t, broker, hub, "component", ours(retained, True), False)
        retained_configs(broker, lambda c: not ours(c, True) and ours(c, False) == singles,
                         lambda c: "the single component configs alone, as before (device ones: %s; "
                         "missing: %s; new: %s)" % (sorted(ours(c, True)), sorted(singles - ours(c, False)),
                                                     sorted(ours(c, False) - singles)))
    finally:
        hub.close()
