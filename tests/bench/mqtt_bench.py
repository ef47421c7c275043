"""make bench, mqtt: what publishing through Mosquitto costs the bus (issue
19, "Numbers"; docs/MQTT.md, "Cost"). 1,000 boards at 10 Hz, each one
machine whose published variable changes at every tick, with MQTT on
(mqtt_url to a Mosquitto started here, native topics and Home Assistant
discovery, a paho subscriber on PREFIX/#) next to the same host with MQTT
off, alternating rounds in one run. Run through bench.py (--only mqtt); the
helpers are bench.py's, fieldbus.py's and test_mqtt.py's. Without mosquitto
or python3-paho-mqtt: SKIPPED, said on stdout and in the results.

Per window (--seconds of steady state, a fresh vmacd each):
  messages  value messages (PREFIX/HOST/DEVICE/NAME) the subscriber got per
            second; the publisher reads the bus's status copy every 250 ms
            (MQTT_POLL_MS), so 1,000 machines changing at 10 Hz are at most
            4,000 a second (conflated: newest wins)
  lateness  tick.lateness_us of GET /api/status; vmacd's histogram covers
            its whole life, so each window is a fresh host measured from
            start: attach (under a second), SETTLE_S and the window
  cpu       vmacd's on-CPU time (schedstat, all threads) and utime+stime as
            a share of a CPU, the MQTT threads' part (publisher and network), Mosquitto's
  misses    counters.misses and misses_host over the window

Then the precision throttle (issue 31): the demo kitchen (washer, dishwasher,
lights on their simulated plants) with a wash running, the washer's temp_c
declared precision = 6 (exact for its 0.025 C steps: every change goes out,
as before the throttle) next to precision = 1 (the shipped washer's: out
when it is a whole 0.1 C from what went out), alternating rounds, a fresh
vmacd each, for two programmes: normal (a warm fill, 37.5 C, the fastest
the water's temperature moves in a shipped programme) and delicate (a cold
fill, 15 C, nearly still). Per window, from the wash step on (the fill
done; the drum turning, so the reading has its noise): temp_c messages and
all the kitchen's value messages per second to the subscriber, tick
lateness, misses, and a check that nothing that matters was lost: the
host's own temp_c (GET /api/status every 100 ms, the copy the publisher
reads; it changes at most once a second, update = "timer:1") put through
the throttle's rule (mqtt_value_moved), which must give the subscriber's
series exactly, in order, while no reading is a whole step from what was
shown."""

import json
import os
import re
import statistics
import threading
import time

from bench import ROOT, board_wrapper, cpu_seconds, schedule_for, thread_seconds, with_ctx
from fieldbus import MAX_DEVICES_DEFAULT, attempt, fresh_status, note_others, others_running, run_seconds, wait_attached
from harness import Skip

# One variable that changes at every tick: a count, published with
# update = "auto" (at the end of every tick in which it changed, the fastest
# a variable is published), so every read of the status copy finds every
# machine changed.
MQTTPROBE_LUA = """local driver = { name = "mqttprobe", version = "1", io = { switch = "di0", lamp = "do0" },
	variables = { count = { update = "auto", label = "Ticks" } } }
function driver.attach(dev) dev.state.count = 0 end
function driver.tick(dev, inputs)
	dev.state.count = dev.state.count + 1
	dev.vars.count = dev.state.count
	dev.out.lamp = inputs.switch
end
return driver
"""

BOARDS, PERIOD_US = 1000, 100000
HOST_ID, PREFIX = "bench", "vmac"
MQTT_POLL_S = 0.25  # core/mqtt/mqtt_internal.h MQTT_POLL_MS: the most often a value goes out
ROUNDS_MIN, ROUNDS_MAX = 2, 4  # 4 rounds of 10 s windows, 2 of 60 s (make bench)
SETTLE_S = 5  # after every board runs, before the window: MQTT's first burst (configs, availability) is out
FIRST_VALUES_TIMEOUT_S = 60  # for a value of every machine to reach the subscriber


class Subscriber:
    """A paho client on PREFIX/# (QoS 0, as values go out) counting the
    value messages PREFIX/HOST/DEVICE/NAME (not status, the host's _NAME
    topics such as _availability and _error, set/ or cmd/) and the machines
    they came from."""

    def __init__(self, port, record=()):
        import test_mqtt  # the tests' way of finding paho (Debian's python3-paho-mqtt)
        mqtt = test_mqtt.paho()
        self.values, self.other = 0, 0
        self.devices, self.window_devices = set(), set()
        self.record = set(record)  # (device, name) whose messages go to log
        self.log = []  # (monotonic time of arrival, device, name, payload text)
        self.c = mqtt.Client(client_id="bench-sub-%d" % os.getpid())
        self.c.on_message = self._on_message
        self.c.on_connect = lambda c, u, f, rc: c.subscribe(PREFIX + "/#", qos=0)
        self.c.connect("127.0.0.1", port, keepalive=30)
        self.c.loop_start()

    def _on_message(self, c, u, m):
        levels = m.topic.split("/")
        if len(levels) == 4 and not levels[3].startswith("_"):  # not _availability, _error
            self.values += 1
            self.devices.add(levels[2])
            self.window_devices.add(levels[2])
            if (levels[2], levels[3]) in self.record:
                self.log.append((time.monotonic(), levels[2], levels[3], m.payload.decode()))
        else:
            self.other += 1

    def close(self):
        self.c.disconnect()
        self.c.loop_stop()


def mqtt_thread_seconds(pid):
    """On-CPU seconds (schedstat) of the MQTT threads: the publisher
    (vmac-mqtt) and the connection's network thread (vmac-mqtt-net)."""
    return thread_seconds(pid, ("vmac-mqtt", "vmac-mqtt-net", "vmac-mqtt-spb"))


def window(ctx, mqtt_on, seconds):
    """A fresh vmacd with BOARDS boards at PERIOD_US running mqttprobe, MQTT
    on (a broker and a subscriber of this context) or off; the figures of
    `seconds` of steady state. Raises Skip without mosquitto or paho."""
    broker = sub = None
    settings = {"reply_deadline_us": PERIOD_US, "realtime": "true",
                "watchdog_ms": max(500, 4 * PERIOD_US // 1000), "discovery_period_ms": 200,
                "max_devices": max(MAX_DEVICES_DEFAULT, BOARDS + 8)}
    settings.update(schedule_for(BOARDS, PERIOD_US))
    if mqtt_on:
        import test_mqtt
        test_mqtt.paho()  # Skip before anything starts
        broker = test_mqtt.Broker(ctx)
        sub = Subscriber(broker.port)
        ctx.cleanups.append(sub.close)
        settings.update({"mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_client_id": "vmac-" + HOST_ID,
                         "mqtt_prefix": PREFIX})
    t_start = time.monotonic()
    host = ctx.host(drivers=ctx.drivers(mqttprobe=MQTTPROBE_LUA), settings=settings)
    ctx.board("generic", "b", count=BOARDS, driver="mqttprobe", wrapper=board_wrapper(),
              extra=("--late-us", str(PERIOD_US)))
    wait_attached(host, BOARDS, timeout_s=30 + BOARDS / 50)
    t_attached = time.monotonic()
    first_values_s = None
    if sub:
        while len(sub.devices) < BOARDS:  # every machine's value came through the broker
            if time.monotonic() - t_attached > FIRST_VALUES_TIMEOUT_S:
                raise AssertionError("values of %d of %d machines reached the subscriber within %d s" % (
                    len(sub.devices), BOARDS, FIRST_VALUES_TIMEOUT_S))
            time.sleep(0.1)  # between two looks at the subscriber's count
        first_values_s = time.monotonic() - t_attached
    time.sleep(max(0.0, t_attached + SETTLE_S - time.monotonic()))  # the same timeline on and off
    before = fresh_status(host)
    values0 = sub.values if sub else 0
    if sub:
        sub.window_devices = set()  # replaced, not cleared: paho's thread adds to whichever it sees
    cpu0, run0, pub0, t0 = cpu_seconds(host.pid), run_seconds(host.pid), mqtt_thread_seconds(host.pid), time.monotonic()
    bcpu0 = cpu_seconds(broker.proc.pid) if broker else 0
    time.sleep(seconds)  # the measurement window itself, not a synchronisation
    after = fresh_status(host)
    cpu1, run1, pub1, t1 = cpu_seconds(host.pid), run_seconds(host.pid), mqtt_thread_seconds(host.pid), time.monotonic()
    bcpu1 = cpu_seconds(broker.proc.pid) if broker else 0
    values1 = sub.values if sub else 0
    ticks = after["tick"]["count"] - before["tick"]["count"]
    elapsed = t1 - t0
    return {
        "mqtt": mqtt_on, "boards": BOARDS, "period_us": PERIOD_US, "seconds": seconds,
        "attach_s": t_attached - t_start, "first_values_s": first_values_s,
        "uptime_s_at_end": after["uptime_s"], "ticks": ticks,
        "misses": after["counters"]["misses"] - before["counters"]["misses"],
        "misses_host": after["counters"].get("misses_host", 0) - before["counters"].get("misses_host", 0),
        "drops": after["counters"]["drops"] - before["counters"]["drops"],
        "running_at_end": sum(1 for d in after["devices"] if d["state"] == "running"),
        "realtime": after["bus"]["realtime"],
        "lateness_us": after["tick"]["lateness_us"],
        "host_cpu_share": (cpu1 - cpu0) / elapsed,
        "host_on_cpu_share": (run1 - run0) / elapsed,
        "run_us_per_device_tick": (run1 - run0) * 1e6 / max(1, ticks * BOARDS),
        "publisher_cpu_share": (pub1 - pub0) / elapsed,
        "broker_cpu_share": (bcpu1 - bcpu0) / elapsed if broker else None,
        "messages_per_s": (values1 - values0) / elapsed if sub else None,
        "machines_heard_in_window": len(sub.window_devices) if sub else None,
        "other_messages": sub.other if sub else None,
    }


# The precision throttle's kitchen (issue 31). The washer plant's water
# temperature is physics read through a 12-bit input of 0.025 C a count,
# with -2..+2 counts of noise while the drum motor runs (docs/BOARD.md,
# "Washer"). It moves with a programme running: the fill sets it, then it
# relaxes toward 20 C with a time constant of 600 s, 0.029 C/s from the
# normal programme's 37.5 C, 0.008 C/s from the delicate one's 15 C. So the
# window is a programme's wash step, after its fill.
KITCHEN_BOARDS = (("washer", "washer-1"), ("dishwasher", "dish-1"), ("lights", "lights-1"))
KITCHEN_PROGRAMS = ("normal", "delicate")  # warm water, cooling fast; cold, nearly still
WASHER, TEMP = "washer-1", "temp_c"
PRECISION_OFF, PRECISION_ON = 6, 1  # 6: every 0.025 C step shows, as undeclared; 1: the shipped washer's
TEMP_DECLARATION = re.compile(r'^\s*temp_c = \{ unit = "degC"[^}]*\}', re.M)  # in variables, not io
STATUS_POLL_S = 0.1  # the host's own temp_c: the status copy is published every 100 ms
WASH_STEP_TIMEOUT_S = 120  # from the start command to the wash step (lock, then a 12 or 15 l fill)
LATE_MESSAGES_S = 1.5  # after the window, for the values of its last status to reach the subscriber
STEP_TOLERANCE = 1e-9  # core/mqtt/mqtt_native.c: texts read back are binary approximations


def washer_source(precision):
    """scripts/drivers/washer.lua with its temp_c variable declared
    precision = `precision` (a precision it declares itself replaced)."""
    with open(os.path.join(ROOT, "scripts", "drivers", "washer.lua")) as f:
        text = f.read()
    found = TEMP_DECLARATION.search(text)
    if not found:
        raise AssertionError("scripts/drivers/washer.lua: no variable temp_c = { unit = \"degC\" ... }: the bench "
                             "needs its declaration to set a precision")
    table, said = re.subn(r"precision = \d+", "precision = %d" % precision, found.group(0))
    if not said:
        table = table.replace("{ ", "{ precision = %d, " % precision, 1)
    return text[:found.start()] + table + text[found.end():]


def text_at(number, precision):
    """A number as core/mqtt/mqtt_native.c mqtt_value_text_at publishes it
    (C's and Python's %.Nf round the same binary value the same way); no
    value (nil in the driver, null in the status) is None."""
    if number is None:
        return "None"
    text = "%.*f" % (precision, number)
    return "%.*f" % (precision, 0.0) if float(text) == 0 else text


def changes(texts):
    """texts without repeats in a row: the changes, in order."""
    out = []
    for t in texts:
        if not out or out[-1] != t:
            out.append(t)
    return out


def moved(number, precision, sent):
    """core/mqtt/mqtt_native.c mqtt_value_moved: whether a reading goes
    out, sent the text that went out last: a number when it is a whole step
    (10^-precision) from the number sent; anything else when its text
    changes."""
    text = text_at(number, precision)
    if text == sent:
        return False
    try:
        shown = float(sent)
    except ValueError:  # None before
        return True
    if number is None:
        return True
    return abs(number - shown) >= 10.0 ** -precision * (1 - STEP_TOLERANCE)


def throttled(readings, precision, sent):
    """The host's readings through the rule, from `sent` (what the broker
    held): the texts published, in order, starting with sent, and the
    largest distance of a reading from what was shown, in steps."""
    out, worst = [sent], 0.0
    for x in readings:
        if moved(x, precision, out[-1]):
            out.append(text_at(x, precision))
        if x is not None and out[-1] != "None":
            worst = max(worst, abs(x - float(out[-1])) / 10.0 ** -precision)
    return out, worst


def kitchen_window(ctx, program, precision, seconds):
    """A fresh vmacd, Mosquitto and subscriber, the kitchen on its plants,
    the washer's temp_c declared with `precision`; `program` started, and
    `seconds` of its wash step measured."""
    import test_mqtt
    from harness import post
    test_mqtt.paho()  # Skip before anything starts
    broker = test_mqtt.Broker(ctx)
    sub = Subscriber(broker.port, record=[(WASHER, TEMP)])
    ctx.cleanups.append(sub.close)
    names = [name for _, name in KITCHEN_BOARDS]
    host = ctx.host(drivers=ctx.drivers(washer=washer_source(precision)), settings={
        "realtime": "true", "mqtt_url": broker.url, "mqtt_host_id": HOST_ID, "mqtt_client_id": "vmac-" + HOST_ID,
        "mqtt_prefix": PREFIX})
    for plant, name in KITCHEN_BOARDS:
        ctx.board(plant, name, wrapper=board_wrapper())
    host.wait_running(names, timeout_s=60)
    t_attached = time.monotonic()

    def washer_vars():
        for d in host.get("/api/status")["devices"]:
            if d["name"] == WASHER:
                return d["variables"]
        raise AssertionError("%s is no longer in the status" % WASHER)

    # Every machine's values through the broker, and the subscriber's temp_c
    # that of the host (the first, None, is followed by 20 C a second later:
    # update = "timer:1").
    while len(sub.devices) < len(names) or not sub.log or sub.log[-1][3] != text_at(washer_vars()[TEMP], precision):
        if time.monotonic() - t_attached > FIRST_VALUES_TIMEOUT_S:
            raise AssertionError("values of %d of %d machines, the washer's %s %s, reached the subscriber within "
                                 "%d s" % (len(sub.devices), len(names), TEMP, sub.log[-1][3] if sub.log else "none",
                                           FIRST_VALUES_TIMEOUT_S))
        time.sleep(0.1)  # between two looks at the subscriber's count
    published_before = len(sub.log)  # the last of these is what the broker holds when the wash starts
    host_temps = []  # (monotonic time, temp_c) of every status read from the start command on
    code, answer = post(host, "/api/devices/%s/cycle" % WASHER, ctx.token,
                        json.dumps({"action": "start", "program": program}).encode())
    if code != 200:
        raise AssertionError("starting the %s programme: %d %s" % (program, code, answer[:200]))
    t_started = time.monotonic()
    while True:
        v = washer_vars()
        host_temps.append((time.monotonic(), v[TEMP]))
        if v.get("step") == "wash":
            break
        if time.monotonic() - t_started > WASH_STEP_TIMEOUT_S:
            raise AssertionError("no wash step within %d s of the start (step %s)" % (WASH_STEP_TIMEOUT_S,
                                                                                      v.get("step")))
        time.sleep(STATUS_POLL_S)
    before = fresh_status(host)
    values0, t0 = sub.values, time.monotonic()
    while time.monotonic() < t0 + seconds:  # the window, the host's temp_c read all along
        host_temps.append((time.monotonic(), washer_vars()[TEMP]))
        time.sleep(STATUS_POLL_S)
    after = fresh_status(host)
    values1, t1 = sub.values, time.monotonic()
    time.sleep(LATE_MESSAGES_S)  # not a measurement: the last status's values on their way
    washer = host.device(WASHER, after)
    log = list(sub.log)
    in_window = [m for m in log if t0 <= m[0] <= t1]
    # Nothing that matters lost: the host's temp_c from the start command
    # to the window's end through the throttle's rule, from what the broker
    # held at the start, against what the subscriber got over the same span;
    # and no reading a whole step from what was shown.
    want, worst_steps = throttled(changes([x for _, x in host_temps]), precision, log[published_before - 1][3])
    got = changes([m[3] for m in log[published_before - 1:] if m[0] <= t1 + LATE_MESSAGES_S])
    lost = [x for x in want if x not in got]
    elapsed = t1 - t0
    return {
        "program": program, "precision": precision, "seconds": seconds,
        "step_at_end": washer["variables"].get("step"),
        "fill_s": t0 - t_started, "uptime_s_at_end": after["uptime_s"],
        "temp_c_start_end_window": [next(x for t, x in host_temps if t >= t0), host_temps[-1][1]],
        "temp_messages_per_s": len(in_window) / elapsed,
        "temp_messages": len(in_window),
        "kitchen_messages_per_s": (values1 - values0) / elapsed,
        "lateness_us": after["tick"]["lateness_us"],
        "misses": after["counters"]["misses"] - before["counters"]["misses"],
        "misses_host": after["counters"].get("misses_host", 0) - before["counters"].get("misses_host", 0),
        "realtime": after["bus"]["realtime"],
        "changes_host": len(want), "changes_subscriber": len(got), "lost": lost,
        "in_order": got[:len(want)] == want, "repeats": len(log) - published_before + 1 - len(got),
        "worst_steps": worst_steps, "rounded_changes": len(changes([text_at(x, precision) for _, x in host_temps])),
        "series_host": want, "series_subscriber": got,
    }



def kitchen_pooled(rows):
    """One programme's windows pooled: off and on, their ratios."""
    out = {"rounds": rows}
    for name in ("off", "on"):
        ok = [rw[name] for rw in rows if "error" not in rw[name]]
        secs = sum(x["seconds"] for x in ok)
        out[name] = {"windows": len(ok), "temp_messages": sum(x["temp_messages"] for x in ok),
                     "temp_messages_per_s": sum(x["temp_messages"] for x in ok) / secs if secs else None,
                     "kitchen_messages_per_s": statistics.mean(x["kitchen_messages_per_s"] for x in ok) if ok
                     else None,
                     "rounded_changes": sum(x["rounded_changes"] for x in ok),
                     "worst_steps": max([x["worst_steps"] for x in ok] or [0]),
                     "lost": sum(len(x["lost"]) for x in ok), "in_order": all(x["in_order"] for x in ok)}
    if out["on"]["windows"] and out["off"]["windows"]:  # None: none with the throttle on (a window too short)
        out["temp_ratio"] = (out["off"]["temp_messages_per_s"] / out["on"]["temp_messages_per_s"]
                             if out["on"]["temp_messages_per_s"] else None)
        out["kitchen_ratio"] = out["off"]["kitchen_messages_per_s"] / max(1e-9, out["on"]["kitchen_messages_per_s"])
    return out


def kitchen_rounds(args, rounds):
    """The precision throttle off (PRECISION_OFF) and on (PRECISION_ON) in
    alternating rounds, each programme of KITCHEN_PROGRAMS in each round;
    the figures of every window, pooled by programme."""
    out = {"programs": {}, "precision_off": PRECISION_OFF, "precision_on": PRECISION_ON, "seconds": args.seconds}
    rows = {program: [] for program in KITCHEN_PROGRAMS}
    for rnd in range(1, rounds + 1):
        for program in KITCHEN_PROGRAMS:
            row = {}
            order = (True, False) if rnd % 2 == 0 else (False, True)  # neither always first
            for on in order:
                name, precision = ("on", PRECISION_ON) if on else ("off", PRECISION_OFF)
                print("mqtt, kitchen round %d/%d: precision throttle %s (the washer's temp_c precision = %d), "
                      "%s wash, %d s of its wash step" % (rnd, rounds, name, precision, program, args.seconds),
                      flush=True)
                r = attempt(lambda: with_ctx(args, "mqtt-kitchen-%s-%s-%d" % (program, name, rnd),
                                             lambda c: kitchen_window(c, program, precision, args.seconds)))
                if "error" in r:
                    print("    FAILED: %s" % r["error"], flush=True)
                else:
                    lat = r["lateness_us"]
                    print("    temp_c %.3f -> %.3f C: %.2f temp_c messages/s (%d), all the kitchen's values %.2f/s; "
                          "%d changes published from the start (%d of the text at precision %d), %s, no reading "
                          "more than %.2f steps from what was shown; tick lateness p99 %d, max %d us; "
                          "%d misses (%d the host's)" % (
                              r["temp_c_start_end_window"][0], r["temp_c_start_end_window"][1],
                              r["temp_messages_per_s"], r["temp_messages"], r["kitchen_messages_per_s"],
                              r["changes_host"] - 1, r["rounded_changes"], precision,
                              "all reached the subscriber in order" if r["in_order"] and not r["lost"] else
                              "LOST %s" % ", ".join(r["lost"][:10]) if r["lost"] else "OUT OF ORDER",
                              r["worst_steps"], lat["p99"], lat["max"], r["misses"], r["misses_host"]), flush=True)
                row[name] = r
            if "error" not in row["on"] and "error" not in row["off"]:
                row["ratio_p99"] = row["on"]["lateness_us"]["p99"] / max(1, row["off"]["lateness_us"]["p99"])
            rows[program].append(row)
    for program in KITCHEN_PROGRAMS:
        out["programs"][program] = kitchen_pooled(rows[program])
    p99 = [rw["ratio_p99"] for program in KITCHEN_PROGRAMS for rw in rows[program] if "ratio_p99" in rw]
    out["ratio_p99_median"] = statistics.median(p99) if p99 else None
    out["ratios_p99"] = p99
    return out


def mqtt(args):
    """MQTT on and off in alternating rounds; {"skipped": why} without a broker or paho."""
    t_start = time.monotonic()
    others = note_others()
    out = {"boards": BOARDS, "period_us": PERIOD_US, "seconds": args.seconds, "settle_s": SETTLE_S,
           "others_at_start": others,
           "loadavg_at_start": open("/proc/loadavg").read().split()[:3], "rounds": []}
    rounds = max(ROUNDS_MIN, min(ROUNDS_MAX, 40 // max(1, args.seconds)))
    for rnd in range(1, rounds + 1):
        row = {}
        order = (True, False) if rnd % 2 else (False, True)  # neither always first
        for on in order:
            name = "on" if on else "off"
            print("mqtt, round %d/%d: MQTT %s, %d boards at %d Hz, %d s" % (
                rnd, rounds, name, BOARDS, 1000000 // PERIOD_US, args.seconds), flush=True)
            try:
                r = attempt(lambda: with_ctx(args, "mqtt-%s-%d" % (name, rnd), lambda c: window(c, on, args.seconds)))
            except Skip as e:
                print("    mqtt: SKIPPED: %s" % e, flush=True)
                out["skipped"] = str(e)
                return out
            if "error" in r:
                print("    FAILED: %s" % r["error"], flush=True)
            else:
                lat = r["lateness_us"]
                print("    tick lateness p50 %d, p99 %d, p99.9 %d, max %d us (over %.0f s of uptime); vmacd %.1f%% "
                      "of a CPU (on-CPU; utime+stime %.1f%%)%s; %d misses (%d the host's), %d drops, %d running%s" % (
                          lat["p50"], lat["p99"], lat["p999"], lat["max"], r["uptime_s_at_end"],
                          100 * r["host_on_cpu_share"], 100 * r["host_cpu_share"],
                          ", MQTT threads %.1f%%, mosquitto %.1f%%" % (
                              100 * r["publisher_cpu_share"], 100 * r["broker_cpu_share"]) if on else "",
                          r["misses"], r["misses_host"], r["drops"], r["running_at_end"],
                          "; %.0f value messages/s to the subscriber (every machine's first within %.1f s)" % (
                              r["messages_per_s"], r["first_values_s"]) if on else ""), flush=True)
            row[name] = r
        if "error" not in row["on"] and "error" not in row["off"]:
            row["ratio_p99"] = row["on"]["lateness_us"]["p99"] / max(1, row["off"]["lateness_us"]["p99"])
            row["ratio_cpu"] = row["on"]["host_on_cpu_share"] / max(1e-9, row["off"]["host_on_cpu_share"])
        out["rounds"].append(row)
    p99 = [rw["ratio_p99"] for rw in out["rounds"] if "ratio_p99" in rw]
    cpu = [rw["ratio_cpu"] for rw in out["rounds"] if "ratio_cpu" in rw]
    rates = [rw["on"]["messages_per_s"] for rw in out["rounds"] if "error" not in rw["on"]]
    out["ratio_p99_median"] = statistics.median(p99) if p99 else None
    out["ratio_cpu_median"] = statistics.median(cpu) if cpu else None
    out["messages_per_s_median"] = statistics.median(rates) if rates else None
    out["kitchen"] = kitchen_rounds(args, rounds)
    out["elapsed_s"] = time.monotonic() - t_start
    out["loadavg_at_end"] = open("/proc/loadavg").read().split()[:3]
    return out


def mqtt_kitchen(args):
    """The precision throttle's rounds alone (--only mqtt-kitchen)."""
    rounds = max(ROUNDS_MIN, min(ROUNDS_MAX, 40 // max(1, args.seconds)))
    t_start = time.monotonic()
    out = {"others_at_start": others_running(), "loadavg_at_start": open("/proc/loadavg").read().split()[:3]}
    try:
        out["kitchen"] = kitchen_rounds(args, rounds)
    except Skip as e:
        print("    mqtt-kitchen: SKIPPED: %s" % e, flush=True)
        out["skipped"] = str(e)
    out["elapsed_s"] = time.monotonic() - t_start
    out["loadavg_at_end"] = open("/proc/loadavg").read().split()[:3]
    return out


def report_mqtt(r):
    if r.get("skipped"):
        print("mqtt: SKIPPED: %s" % r["skipped"])
        return
    if "rounds" not in r:  # --only mqtt-kitchen
        report_kitchen(r["kitchen"])
        print("mqtt-kitchen: %.0f s in all; load average %s at the start, %s at the end" % (
            r["elapsed_s"], "/".join(r["loadavg_at_start"]), "/".join(r["loadavg_at_end"])))
        return
    print("\nMQTT through Mosquitto, %d boards at %d Hz, each machine's variable changing at every tick "
          "(tick lateness over each fresh host's life: attach, %d s settling and the window):" % (
              r["boards"], 1000000 // r["period_us"], r["settle_s"]))
    print("  %-6s %-46s %-46s %-10s %s" % ("round", "MQTT on", "MQTT off", "p99 on/off", "messages/s"))
    for i, rw in enumerate(r["rounds"], 1):
        cells = []
        for name in ("on", "off"):
            x = rw[name]
            cells.append("FAILED" if "error" in x else "p99 %d us, max %d us, CPU %.1f%%, %d/%d misses" % (
                x["lateness_us"]["p99"], x["lateness_us"]["max"], 100 * x["host_on_cpu_share"], x["misses"],
                x["misses_host"]))
        on = rw["on"]
        print("  %-6d %-46s %-46s %-10s %s" % (
            i, cells[0], cells[1], "%.2f" % rw["ratio_p99"] if "ratio_p99" in rw else "-",
            "%.0f" % on["messages_per_s"] if "error" not in on else "-"))
    if r["ratio_p99_median"] is None:
        print("  no ratio (a window failed)")
        return
    ons = [rw["on"] for rw in r["rounds"] if "error" not in rw["on"]]
    offs = [rw["off"] for rw in r["rounds"] if "error" not in rw["off"]]
    med = lambda xs, key: statistics.median(x[key] for x in xs)  # noqa: E731
    print("  tick lateness p99 on/off: %.2f, median of the rounds' %s (goal, issue 19: at most 1.1)" % (
        r["ratio_p99_median"], ", ".join("%.2f" % rw["ratio_p99"] for rw in r["rounds"] if "ratio_p99" in rw)))
    print("  value messages delivered to the subscriber: %.0f/s (median; %d machines, the status copy read every "
          "%d ms: %d/s, in bursts of one per machine, so a window holds %d or %d bursts)" % (
              r["messages_per_s_median"], r["boards"], MQTT_POLL_S * 1000, r["boards"] / MQTT_POLL_S,
              r["seconds"] / MQTT_POLL_S, r["seconds"] / MQTT_POLL_S + 1))
    print("  vmacd's CPU (on-CPU, all threads): on %.1f%% of a CPU, %.2f us per device per tick (MQTT threads "
          "%.1f%%); off %.1f%%, %.2f us; on/off %.2f (median of the rounds); mosquitto %.1f%% of a CPU" % (
              100 * med(ons, "host_on_cpu_share"), med(ons, "run_us_per_device_tick"),
              100 * med(ons, "publisher_cpu_share"), 100 * med(offs, "host_on_cpu_share"),
              med(offs, "run_us_per_device_tick"), r["ratio_cpu_median"], 100 * med(ons, "broker_cpu_share")))
    print("  misses (the host's): on %s, off %s" % (
        ", ".join("%d (%d)" % (x["misses"], x["misses_host"]) for x in ons),
        ", ".join("%d (%d)" % (x["misses"], x["misses_host"]) for x in offs)))
    if r.get("kitchen"):
        report_kitchen(r["kitchen"])
    print("mqtt: %.0f s in all; load average %s at the start, %s at the end%s" % (
        r["elapsed_s"], "/".join(r["loadavg_at_start"]), "/".join(r["loadavg_at_end"]),
        "; %d programs of ours already running (%s)" % (len(r["others_at_start"]), ", ".join(r["others_at_start"][:4]))
        if r["others_at_start"] else ""))


def report_kitchen(k):
    print("\nThe precision throttle: the kitchen, %d s of a wash step per window; the washer's temp_c "
          "(update = \"timer:1\") declared precision = %d (off: every 0.025 C step) or %d (on):" % (
              k["seconds"], k["precision_off"], k["precision_on"]))
    for program, pk in k["programs"].items():
        print("  %s wash:" % program)
        print("  %-6s %-62s %-62s %s" % ("round", "throttle off", "throttle on", "p99 on/off"))
        for i, rw in enumerate(pk["rounds"], 1):
            cells = []
            for name in ("off", "on"):
                x = rw[name]
                if "error" in x:
                    cells.append("FAILED")
                    continue
                first, last = x["temp_c_start_end_window"]
                cells.append("temp_c %.2f/s (%.3f -> %.3f C), all %.2f/s, p99 %d us, %d lost" % (
                    x["temp_messages_per_s"], first, last, x["kitchen_messages_per_s"], x["lateness_us"]["p99"],
                    len(x["lost"])))
            print("  %-6d %-62s %-62s %s" % (i, cells[0], cells[1],
                                             "%.2f" % rw["ratio_p99"] if "ratio_p99" in rw else "-"))
        if "kitchen_ratio" not in pk:
            print("    no ratio (every window of one side failed)")
            continue
        off, on = pk["off"], pk["on"]
        print("    temp_c messages to the subscriber: off %.2f/s, on %.2f/s (all windows pooled: %d and %d messages): "
              "%s (goal, issue 31: at least 5x)" % (
                  off["temp_messages_per_s"], on["temp_messages_per_s"], off["temp_messages"], on["temp_messages"],
                  "%.1fx fewer" % pk["temp_ratio"] if pk["temp_ratio"] else "no ratio: none with the throttle on, "
                  "the windows too short for a step of its precision"))
        print("    with the throttle on, %d changes of the host's temp_c rounded to one decimal; %d published"
              % (on["rounded_changes"], on["temp_messages"]))
        print("    all the kitchen's value messages: off %.2f/s, on %.2f/s: %.2fx fewer" % (
            off["kitchen_messages_per_s"], on["kitchen_messages_per_s"], pk["kitchen_ratio"]))
        print("    the rule's series the subscriber never got: off %d, on %d (in order: off %s, on %s); a reading "
              "at most %.2f steps from what was shown (goal: under 1)" % (
                  off["lost"], on["lost"], "yes" if off["in_order"] else "no", "yes" if on["in_order"] else "no",
                  on["worst_steps"]))
    if k["ratio_p99_median"] is not None:
        print("  tick lateness p99 on/off: %.2f, median of the %d windows' pairs %s (goal: at most 1.1)" % (
            k["ratio_p99_median"], len(k["ratios_p99"]), ", ".join("%.2f" % x for x in k["ratios_p99"])))
