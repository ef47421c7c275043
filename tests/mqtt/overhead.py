#!/usr/bin/env python3
"""What the MQTT client costs the host (docs/MQTT.md, "Cost"): the same
host and boards run twice in one go, MQTT off then on (a local mosquitto, a
subscriber to every topic), each for --seconds; printed: the host's CPU
time per device per tick (utime + stime of the whole vmacd process over the
device-ticks served), the MQTT threads' share, the tick lateness p99, and
the ratios on/off.

    python3 tests/mqtt/overhead.py --bin build/bin [--boards 60] [--seconds 20]
"""

import argparse
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "integration"))
sys.dont_write_bytecode = True

import harness  # noqa: E402
import test_mqtt  # noqa: E402

TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid, tid=None):
    path = "/proc/%d/task/%d/stat" % (pid, tid) if tid else "/proc/%d/stat" % pid
    with open(path) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def mqtt_threads(pid):
    """The publisher thread (vmac-mqtt) and the connections' network threads
    (vmac-mqtt-net, and vmac-mqtt-spb for Sparkplug)."""
    tids = []
    for tid in os.listdir("/proc/%d/task" % pid):
        with open("/proc/%d/task/%s/comm" % (pid, tid)) as f:
            if f.read().strip() in ("vmac-mqtt", "vmac-mqtt-net", "vmac-mqtt-spb"):
                tids.append(int(tid))
    return tids


def run(bindir, boards, seconds, mqtt):
    logdir = tempfile.mkdtemp(prefix="vmac-mqtt-overhead-")
    t = harness.Context(os.path.abspath(bindir), logdir)
    try:
        settings = {"miss_limit": 3}
        hub = broker = None
        if mqtt:
            broker = test_mqtt.Broker(t)
            settings.update({"mqtt_url": broker.url, "mqtt_host_id": "bench", "mqtt_commands": "true"})
        host = t.host(settings=settings)
        t.kitchen(host)
        t.board("generic", "gen", count=boards)
        names = harness.KITCHEN_NAMES + ["gen-%d" % i for i in range(1, boards + 1)]
        host.wait_running(names, timeout_s=60)
        if mqtt:
            hub = test_mqtt.Hub(broker)
        time.sleep(2)  # settled: every machine attached and (with MQTT) announced
        s0 = host.status()
        c0 = cpu_s(host.pid)
        m0 = sum(cpu_s(host.pid, tid) for tid in mqtt_threads(host.pid))
        time.sleep(seconds)
        s1 = host.status()
        c1 = cpu_s(host.pid)
        m1 = sum(cpu_s(host.pid, tid) for tid in mqtt_threads(host.pid))
        served = sum(host.device(n, s1)["served"] - host.device(n, s0)["served"] for n in names)
        harness.undisturbed(names)(s1)
        messages = len(hub.log) if hub else 0
        if hub:
            hub.close()
        return {"cpu_us_per_device_tick": (c1 - c0) / served * 1e6, "mqtt_threads_us_per_device_tick":
                (m1 - m0) / served * 1e6, "served": served, "lateness_p99_us": s1["tick"]["lateness_us"]["p99"],
                "messages": messages}
    finally:
        t.cleanup()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default="build/bin")
    ap.add_argument("--boards", type=int, default=60)
    ap.add_argument("--seconds", type=float, default=20)
    a = ap.parse_args()
    off = run(a.bin, a.boards, a.seconds, False)
    on = run(a.bin, a.boards, a.seconds, True)
    for name, r in (("off", off), ("on", on)):
        print("MQTT %-3s: %.2f us CPU per device per tick (MQTT threads %.2f), %d device-ticks, tick lateness "
              "p99 %d us, %d messages to the subscriber" % (name, r["cpu_us_per_device_tick"],
                                                            r["mqtt_threads_us_per_device_tick"], r["served"],
                                                            r["lateness_p99_us"], r["messages"]))
    print("ratio on/off: CPU per device per tick %.2f; without the MQTT threads %.2f; lateness p99 %.2f" % (
        on["cpu_us_per_device_tick"] / off["cpu_us_per_device_tick"],
        (on["cpu_us_per_device_tick"] - on["mqtt_threads_us_per_device_tick"]) / off["cpu_us_per_device_tick"],
        on["lateness_p99_us"] / max(off["lateness_p99_us"], 1)))


if __name__ == "__main__":
    main()
