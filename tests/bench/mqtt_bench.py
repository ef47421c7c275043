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
  misses    counters.misses and misses_host over the window"""

import os
import statistics
import threading
import time

from bench import board_wrapper, cpu_seconds, schedule_for, with_ctx
from fieldbus import MAX_DEVICES_DEFAULT, fresh_status, others_running, run_seconds, wait_attached
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

    def __init__(self, port):
        import test_mqtt  # the tests' way of finding paho (Debian's python3-paho-mqtt)
        mqtt = test_mqtt.paho()
        self.values, self.other = 0, 0
        self.devices, self.window_devices = set(), set()
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
        else:
            self.other += 1

    def close(self):
        self.c.disconnect()
        self.c.loop_stop()


def mqtt_thread_seconds(pid):
    """On-CPU seconds (schedstat) of the MQTT threads: the publisher
    (vmac-mqtt) and the connection's network thread (vmac-mqtt-net)."""
    total = 0
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            with open("/proc/%d/task/%s/comm" % (pid, tid)) as f:
                if f.read().strip() not in ("vmac-mqtt", "vmac-mqtt-net", "vmac-mqtt-spb"):
                    continue
            with open("/proc/%d/task/%s/schedstat" % (pid, tid)) as f:
                total += int(f.read().split()[0])
        except OSError:  # a thread that ended meanwhile
            pass
    return total / 1e9


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


def mqtt(args):
    """MQTT on and off in alternating rounds; {"skipped": why} without a broker or paho."""
    t_start = time.monotonic()
    others = others_running()
    if others:
        print("    note: already running here, sharing the CPUs: %s%s" % (
            ", ".join(others[:8]), " and %d more" % (len(others) - 8) if len(others) > 8 else ""), flush=True)
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
                r = with_ctx(args, "mqtt-%s-%d" % (name, rnd), lambda c: window(c, on, args.seconds))
            except Skip as e:
                print("    mqtt: SKIPPED: %s" % e, flush=True)
                out["skipped"] = str(e)
                return out
            except AssertionError as e:  # boards that did not attach, values that never came
                r = {"error": str(e)[:300]}
            except Exception as e:  # noqa: BLE001 (a program that died, a refused setting)
                r = {"error": "%s: %s" % (type(e).__name__, str(e)[:300])}
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
    out["elapsed_s"] = time.monotonic() - t_start
    out["loadavg_at_end"] = open("/proc/loadavg").read().split()[:3]
    return out


def report_mqtt(r):
    if r.get("skipped"):
        print("mqtt: SKIPPED: %s" % r["skipped"])
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
    print("mqtt: %.0f s in all; load average %s at the start, %s at the end%s" % (
        r["elapsed_s"], "/".join(r["loadavg_at_start"]), "/".join(r["loadavg_at_end"]),
        "; %d programs of ours already running (%s)" % (len(r["others_at_start"]), ", ".join(r["others_at_start"][:4]))
        if r["others_at_start"] else ""))
