"""make bench, qemu: the board firmware on a Cortex-M3 (the real image,
build/firmware/vmac-board-lm3s6965.elf, `make firmware`) in QEMU's
lm3s6965evb, served by vmacd on raw Ethernet through a Linux bridge, as
tests/integration/test_qemu.py runs it (its Link and qemu_board), issue 18:

  reply time   a QEMU board and a vmac-board (POSIX, --bus eth: on a veth
               pair into the same bridge) served side by side, each in a slot
               of its own, 100 Hz: the time from the host's request leaving
               it to the board's reply reaching it, p50/p99/p99.9/max,
               measured on the bridge by an AF_PACKET socket with the
               kernel's timestamps (vmacd publishes no per-reply round
               trip): the CYCLIC frame carries a seq and each board's reply
               echoes it
  highest rate one QEMU board alone at periods of 100, 50, 20, 10, 5, 2 and
               1 ms (slots as bench.py's schedule_for, the reply deadline
               one period, zero tolerance), each for --seconds, stopping at
               the first with a miss: the fastest clean one, and each miss
               of the failing one attributed from vmacd's dropped event
               (the host's send time), the same capture (when the request
               and the reply were on the bridge) and the firmware's own
               counters on UART0 (`status`: frames, MAC overruns, watchdog
               trips; its lines carry no times, so they cannot say when)

Both boards run at SCHED_FIFO one below vmacd's bus thread where that is
allowed (bench.py's board_wrapper; QEMU's threads by chrt -a -p after it
started), so that the two are run alike. Without root, qemu-system-arm or
the firmware image: SKIPPED with the reason. Run through bench.py
(--only qemu); the shared helpers are bench.py's and fieldbus.py's."""

import os
import re
import socket
import struct
import subprocess
import threading
import time

from bench import BENCH_LUA, PRIORITY, board_wrapper, schedule_for, with_ctx
from fieldbus import fresh_status
from harness import Skip
from miss_trace import HOST_RE, events
from test_qemu import Link, firmware_image, qemu_board

PERIODS_MS = (100, 50, 20, 10, 5, 2, 1)
REPLY_PERIOD_US = 10000  # the side-by-side run: 100 Hz, each board in its own slot
WARMUP_S = 1.0  # after every board runs: QEMU translates each code path the first time it runs it

# The firmware announces its plant's driver (qemu_board patches --plant,
# which resets --driver): bench.py's probe driver under the generic plant's
# name, for the QEMU board and the vmac-board alike.
PROBE_LUA = BENCH_LUA.replace('name = "benchprobe"', 'name = "generic"')

ETH_P_ALL, ETHERTYPE = 0x0003, 0x88B5
SO_TIMESTAMPNS, SO_RCVBUFFORCE = 35, 33
SOL_PACKET, PACKET_STATISTICS = 263, 6
PACKET_HOST, PACKET_OUTGOING = 0, 4
OP_UPDATE, OP_CYCLIC, CH_DEVICE, CH_SYSTEM, FLAG_REPLY = 0x02, 0x04, 0x00, 0xFF, 0x01
STATUS_RE = re.compile(r"^(\S+): frames ok (\d+), malformed (\d+), ignored (\d+), watchdog trips (\d+)"
                       r"(?:, auth_failed \d+)?; "
                       r"Ethernet received (\d+), sent (\d+), not ours (\d+), oversize (\d+), overruns (\d+)")
STATUS_FIELDS = ("frames_ok", "malformed", "ignored", "watchdog_trips", "eth_received", "eth_sent", "not_ours",
                 "oversize", "overruns")


def mac_text(b):
    return ":".join("%02x" % x for x in b)


def rt_minus_mono():
    """CLOCK_REALTIME - CLOCK_MONOTONIC in ns, from the tightest of 50
    readings (a realtime read between two monotonic ones): a reading
    preempted in the middle would be tens of microseconds off. vmacd reads
    it once at start (vmac_transport_clock_sync), so its stamps and these
    may differ by that much: a few tens of microseconds between the host's
    times and the capture's say nothing."""
    best = None
    for _ in range(50):
        m1 = time.monotonic_ns()
        r = time.clock_gettime_ns(time.CLOCK_REALTIME)
        m2 = time.monotonic_ns()
        if best is None or m2 - m1 < best[0]:
            best = (m2 - m1, r - (m1 + m2) // 2)
    return best[1]


class Capture:
    """Every vmac frame on the bridge, with the kernel's timestamp: the
    host's CYCLIC frames as they leave it (PACKET_OUTGOING on the bridge
    device, where vmacd sends) and the boards' replies as they reach it.
    A thread reads an AF_PACKET socket; the stamps (CLOCK_REALTIME) are
    turned into CLOCK_MONOTONIC as vmacd does (the offset read once at
    start), so that they line up with the host's `sent at` times."""

    def __init__(self, ifname):
        self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, 16 << 20)
        except OSError:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 16 << 20)
        self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        self.sock.bind((ifname, ETH_P_ALL))
        self.sock.settimeout(0.2)
        self.rt_minus_mono = rt_minus_mono()
        self.lock = threading.Lock()
        self.cyclic = []  # (t_ns, seq, [device ids due])
        self.replies = []  # (t_ns, seq, device_id, source MAC)
        self.unstamped = 0
        self.kernel_drops = 0
        self.stop_flag = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        anc = socket.CMSG_SPACE(16)
        while not self.stop_flag.is_set():
            try:
                data, ancdata, _, addr = self.sock.recvmsg(2048, anc)
            except socket.timeout:
                continue
            except OSError:
                return
            if len(data) < 14 + 13 or struct.unpack_from(">H", data, 12)[0] != ETHERTYPE or data[14:16] != b"VM":
                continue
            t = None
            for level, kind, payload in ancdata:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= 16:
                    sec, nsec = struct.unpack_from("qq", payload)
                    t = sec * 1000000000 + nsec - self.rt_minus_mono
            if t is None:
                t = time.monotonic_ns()
                self.unstamped += 1
            v = data[14:]
            flags, seq, dev, channel, op, n = v[3], struct.unpack_from(">H", v, 4)[0], \
                struct.unpack_from(">I", v, 6)[0], v[10], v[11], v[12]
            if addr[2] == PACKET_OUTGOING and not flags & FLAG_REPLY and channel == CH_SYSTEM and op == OP_CYCLIC:
                first = struct.unpack_from(">H", v, 13)[0]
                due = []
                for i in range(n):
                    off = 15 + 6 * i
                    if off + 6 > len(v):
                        break
                    tag, rflags = struct.unpack_from(">HB", v, off)
                    if tag and rflags & 1:
                        due.append((tag << 16) | ((first + i) & 0xFFFF))
                with self.lock:
                    self.cyclic.append((t, seq, due))
            elif addr[2] == PACKET_HOST and flags & FLAG_REPLY and channel == CH_DEVICE and op == OP_UPDATE:
                with self.lock:
                    self.replies.append((t, seq, dev, mac_text(data[6:12])))

    def drops(self):
        """Frames the kernel could not queue to this socket so far (its
        buffer full): a capture with drops has gaps."""
        try:
            self.kernel_drops += struct.unpack("II", self.sock.getsockopt(SOL_PACKET, PACKET_STATISTICS, 8))[1]
        except OSError:
            pass
        return self.kernel_drops

    def stop(self):
        self.stop_flag.set()
        self.thread.join(5)
        self.sock.close()

    def match(self, t0_ns, t1_ns, late_ns=2000000000):
        """Every request (a device due in a CYCLIC frame that left between
        t0 and t1) with its reply on the bridge, if one came within late_ns:
        {device_id: [(t_request, t_reply or None, seq)]}."""
        with self.lock:
            cyclic, replies = list(self.cyclic), list(self.replies)
        by_key = {}
        for t, seq, dev, _mac in replies:
            by_key.setdefault((dev, seq), []).append(t)
        for k in by_key:
            by_key[k].sort()
        out = {}
        for t, seq, due in cyclic:
            if not t0_ns <= t < t1_ns:
                continue
            for dev in due:
                got = None
                for tr in by_key.get((dev, seq), ()):
                    if t <= tr <= t + late_ns:
                        got = tr
                        break
                out.setdefault(dev, []).append((t, got, seq))
        return out

    def request_near(self, seq, t_ns, within_ns=1000000000):
        """The CYCLIC frame of seq that left closest to t_ns (the host's
        `sent at`), or None."""
        with self.lock:
            found = [c for c in self.cyclic if c[1] == seq and abs(c[0] - t_ns) <= within_ns]
        return min(found, key=lambda c: abs(c[0] - t_ns)) if found else None

    def reply_after(self, mac, seq, t_ns, late_ns=2000000000):
        """The first reply from mac echoing seq within late_ns after t_ns
        (by MAC: a board dropped and attached again has a new device id)."""
        with self.lock:
            found = [r[0] for r in self.replies if r[3] == mac and r[1] == seq and t_ns <= r[0] <= t_ns + late_ns]
        return min(found) if found else None


def quantiles(values):
    if not values:
        return None
    v = sorted(values)

    def q(f):
        return v[min(len(v) - 1, int(f * len(v)))]

    return {"p50": q(0.5), "p99": q(0.99), "p999": q(0.999), "max": v[-1], "min": v[0], "n": len(v)}


def reply_stats(pairs, deadline_us, t0_ns):
    """Figures of one device's [(t_request, t_reply, seq)] in microseconds;
    `worst`: the three longest as [seconds into the window, us], so that
    two boards' worst replies can be seen to coincide (the whole machine
    stalled) or not."""
    times = [(tr - t) / 1e3 for t, tr, _ in pairs if tr is not None]
    worst = sorted(((tr - t) / 1e3, (t - t0_ns) / 1e9) for t, tr, _ in pairs if tr is not None)[-3:]
    return {"requests": len(pairs), "replies": len(times), "no_reply": len(pairs) - len(times),
            "over_deadline": sum(1 for x in times if x > deadline_us), "reply_us": quantiles(times),
            "worst": [[round(at, 3), round(took)] for took, at in reversed(worst)]}


def realtime_qemu(board):
    """QEMU's threads at SCHED_FIFO one below vmacd's bus thread, as
    board_wrapper runs vmac-board, when this machine allows it. Returns
    whether it did."""
    if not board_wrapper():
        return False
    p = subprocess.run(["chrt", "-a", "-f", "-p", str(PRIORITY - 1), str(board.pid)], capture_output=True,
                       text=True, timeout=30)
    return p.returncode == 0


def uart_counters(board, name, timeout_s=10):
    """The firmware's own counters ('status' on UART0), or None."""
    mark = board.mark()
    try:
        board.send("status")
        line = board.wait_line(r"^%s: frames ok " % re.escape(name), timeout_s, since=mark, what="the counters")
    except (AssertionError, OSError):
        return None
    m = STATUS_RE.match(line.text)
    return dict(zip(STATUS_FIELDS, (int(x) for x in m.groups()[1:]))) if m else None


def counters_delta(a, b):
    if not a or not b:
        return None
    return {k: b[k] - a[k] for k in STATUS_FIELDS}


def start_link(ctx):
    """The bridge (test_qemu's Link) and the probe driver's folder."""
    return Link(ctx), ctx.drivers(generic=PROBE_LUA)


def window(host, seconds, boards):
    """Warm-up, then `seconds` of steady state: (status before, after,
    t0 ns, t1 ns, first event seq, UART counters before and after)."""
    time.sleep(WARMUP_S)  # see WARMUP_S: the first runs of each code path, not a synchronisation
    first = host.last_event_seq()
    uart0 = {n: uart_counters(b, n) for n, b in boards.items()}
    before = fresh_status(host)
    t0 = time.monotonic_ns()
    time.sleep(seconds)  # the measurement window itself, not a synchronisation
    after = fresh_status(host)
    t1 = time.monotonic_ns()
    uart1 = {n: uart_counters(b, n) for n, b in boards.items()}
    return before, after, t0, t1, first, {n: counters_delta(uart0[n], uart1[n]) for n in boards}


def side_by_side(args, image, seconds):
    """A QEMU board (q-1) and a vmac-board (p-1) on one bridge, 100 Hz,
    each in its own slot: the reply time of each from the bridge capture."""
    period_us = REPLY_PERIOD_US

    def run(ctx):
        link, drivers = start_link(ctx)
        ns, port = link.namespace_port()
        capture = Capture(link.bridge)
        ctx.cleanups.append(capture.stop)
        q = qemu_board(ctx, image, link, "generic", "q-1")
        q_rt = realtime_qemu(q)
        # Two slots of half a period, each board at level 1 in a slot of
        # its own: each board's request is a CYCLIC frame for it alone.
        settings = {"slice_us": period_us // 2, "slices_per_slot": 1, "max_level": 1, "default_level": 1,
                    "reply_deadline_us": period_us, "miss_limit": 1000, "realtime": "true",
                    "watchdog_ms": max(500, 4 * period_us // 1000), "discovery_period_ms": 200}
        host = ctx.host(drivers=drivers, settings=settings, bus="eth:" + link.bridge)
        ctx.board("generic", "p-1", bus="eth:" + port, wrapper=("ip", "netns", "exec", ns) + board_wrapper(),
                  extra=("--late-us", str(period_us)))
        host.wait_running(["q-1", "p-1"], timeout_s=60)
        before, after, t0, t1, _, uart = window(host, seconds, {"q-1": q})
        pairs = capture.match(t0, t1)
        out = {"period_us": period_us, "seconds": seconds, "qemu_realtime": q_rt,
               "board_realtime": bool(board_wrapper()), "host_realtime": after["bus"]["realtime"], "boards": {}}
        for name in ("q-1", "p-1"):
            d = host.device(name, after)
            d0 = host.device(name, before)
            r = reply_stats(pairs.get(d["id"], []), period_us, t0)
            r.update({"kind": "qemu" if name == "q-1" else "vmac-board", "address": d["address"], "slot": d["slot"],
                      "misses": d["misses"] - d0["misses"], "misses_host": d.get("misses_host", 0)
                      - d0.get("misses_host", 0), "served": d["served"] - d0["served"],
                      "state_at_end": d["state"]})
            out["boards"][name] = r
        out["uart"] = uart.get("q-1")
        out["capture_unstamped"], out["capture_drops"] = capture.unstamped, capture.drops()
        out["lateness_us"] = after["tick"]["lateness_us"]
        return out

    return with_ctx(args, "qemu-pair", run)


def attribute(drops, capture, mac, deadline_us, t0_ns, t1_ns):
    """Each miss of a dropped event whose request the host sent between t0
    and t1 (the window), with its cause (docs/PERFORMANCE.md, "The firmware
    in QEMU"): [(seq, cause, detail)]."""
    rows = []
    for e in drops:
        m = HOST_RE.search(e["text"])
        if not m:
            rows.append((None, "other", e["text"][:120]))
            continue
        seq, t_sent, t_recv = int(m.group(1)), int(m.group(2)), m.group(3) and int(m.group(3))
        if not t0_ns <= t_sent < t1_ns:
            continue
        if "the host's fault" in e["text"]:
            rows.append((seq, "host", "the kernel refused the request"))
            continue
        req = capture.request_near(seq, t_sent)
        if req is None:
            rows.append((seq, "not captured", "the request is not in the capture"))
            continue
        t_wire = req[0]
        detail = "on the bridge %+.0f us from the host's send stamp" % ((t_wire - t_sent) / 1e3)
        t_reply = capture.reply_after(mac, seq, t_wire)
        if t_reply is None:
            rows.append((seq, "no reply", detail + "; no reply on the bridge within 2 s"))
            continue
        took = (t_reply - t_wire) / 1e3
        detail += "; reply on the bridge after %.0f us" % took
        if t_recv:
            detail += ", taken by the host %.0f us after that" % ((t_recv - t_reply) / 1e3)
        if took > deadline_us:
            rows.append((seq, "board late", detail))
        else:
            rows.append((seq, "to-host", detail))
    return rows


def rate_probe(args, image, period_us, seconds):
    """One QEMU board alone at period_us for `seconds`, zero tolerance."""

    def run(ctx):
        link, drivers = start_link(ctx)
        capture = Capture(link.bridge)
        ctx.cleanups.append(capture.stop)
        q = qemu_board(ctx, image, link, "generic", "q-1")
        q_rt = realtime_qemu(q)
        settings = {"reply_deadline_us": period_us, "realtime": "true",
                    "watchdog_ms": max(500, 4 * period_us // 1000), "discovery_period_ms": 200}
        settings.update(schedule_for(1, period_us))
        host = ctx.host(drivers=drivers, settings=settings, bus="eth:" + link.bridge)
        host.wait_running(["q-1"], timeout_s=60)
        before, after, t0, t1, first, uart = window(host, seconds, {"q-1": q})
        if after["counters"]["misses"] != before["counters"]["misses"]:
            time.sleep(2)  # a late reply to the window's last requests has 2 s to reach the capture (attribute)
        d, d0 = host.device("q-1", after), host.device("q-1", before)
        drops = [e for e in events(host, ctx.token) if e["seq"] > first and e["kind"] == "dropped"
                 and e["device"] == "q-1"]
        # Every device due is this board (alone on the bus), whatever id
        # each of its sessions had.
        r = reply_stats([p for v in capture.match(t0, t1).values() for p in v], period_us, t0)
        rows = attribute(drops, capture, d0["address"].lower(), period_us, t0, t1)
        causes = {}
        for _, cause, _ in rows:
            causes[cause] = causes.get(cause, 0) + 1
        c0, c1 = before["counters"], after["counters"]
        r.update({"period_us": period_us, "seconds": seconds, "qemu_realtime": q_rt,
                  "misses": c1["misses"] - c0["misses"], "misses_host": c1.get("misses_host", 0)
                  - c0.get("misses_host", 0), "drops": c1["drops"] - c0["drops"],
                  "served": d["served"] - d0["served"] if d["id"] == d0["id"] else None,
                  "state_at_end": d["state"], "late_replies_host": c1["late_replies"] - c0["late_replies"],
                  "causes": causes, "attributed": [list(x) for x in rows[:50]], "uart": uart.get("q-1"),
                  "lateness_us": after["tick"]["lateness_us"], "realtime": after["bus"]["realtime"],
                  "capture_unstamped": capture.unstamped, "capture_drops": capture.drops()})
        return r

    return with_ctx(args, "qemu-%dus" % period_us, run)


def qemu(args):
    """Issue 18's two figures in one run; {"skipped": why} where it cannot."""
    t_start = time.monotonic()
    try:
        image = firmware_image(type("T", (), {"bindir": os.path.abspath(args.bin)})())
    except Skip as e:
        print("    qemu: SKIPPED: %s" % e, flush=True)
        return {"skipped": str(e)}
    out = {"image": image, "loadavg_at_start": open("/proc/loadavg").read().split()[:3]}
    print("qemu reply time: a QEMU board and a vmac-board on one bridge, %d Hz, %d s" % (
        1000000 // REPLY_PERIOD_US, args.seconds), flush=True)
    try:
        out["reply_time"] = side_by_side(args, image, args.seconds)
        for name, b in out["reply_time"]["boards"].items():
            print("    %s" % reply_line(name, b), flush=True)
    except Skip as e:
        print("    qemu: SKIPPED: %s" % e, flush=True)
        return {"skipped": str(e)}
    except Exception as e:  # noqa: BLE001 (a board that did not start or attach: this figure only)
        out["reply_time"] = {"error": "%s: %s" % (type(e).__name__, str(e)[:300])}
        print("    FAILED: %s" % out["reply_time"]["error"], flush=True)

    out["probes"] = []
    for ms in PERIODS_MS:
        print("qemu rate: one QEMU board every %d ms (%d Hz), %d s" % (ms, 1000 // ms, args.seconds), flush=True)
        try:
            r = rate_probe(args, image, ms * 1000, args.seconds)
        except Exception as e:  # noqa: BLE001 (Skip included: the probes end here, the figures so far stand)
            r = {"period_us": ms * 1000, "error": "%s: %s" % (type(e).__name__, str(e)[:300])}
            print("    FAILED: %s" % r["error"], flush=True)
            out["probes"].append(r)
            break
        out["probes"].append(r)
        print("    %s" % probe_line(r), flush=True)
        if r["misses"] or r["drops"] or r["state_at_end"] != "running":
            break
    clean = [p for p in out["probes"] if "error" not in p and not p["misses"] and not p["drops"]
             and p["state_at_end"] == "running"]
    out["fastest_clean_us"] = min((p["period_us"] for p in clean), default=None)
    failing = [p for p in out["probes"] if p not in clean]
    out["first_failing_us"] = failing[0]["period_us"] if failing else None
    out["elapsed_s"] = time.monotonic() - t_start
    out["loadavg_at_end"] = open("/proc/loadavg").read().split()[:3]
    return out


def us(x):
    return "%.0f" % x if x >= 10 else "%.1f" % x


def reply_line(name, b):
    q = b["reply_us"]
    if not q:
        return "%s (%s): no reply captured of %d requests" % (name, b["kind"], b["requests"])
    return ("%s (%s): p50 %s, p99 %s, p99.9 %s, max %s us over %d replies; %d requests without a reply, %d over "
            "the deadline; %d misses (%d the host's); worst at %s" % (
                name, b["kind"], us(q["p50"]), us(q["p99"]), us(q["p999"]), us(q["max"]), q["n"], b["no_reply"],
                b["over_deadline"], b["misses"], b["misses_host"],
                ", ".join("%.2f s (%d us)" % (at, took) for at, took in b["worst"])))


def probe_line(r):
    q = r.get("reply_us")
    rt = "reply p50 %s, p99 %s, max %s us" % (us(q["p50"]), us(q["p99"]), us(q["max"])) if q else "no reply captured"
    u = r.get("uart")
    return "%d misses (%d the host's), %d drops, %s of %d requests; %s%s%s" % (
        r["misses"], r["misses_host"], r["drops"], rt, r["requests"],
        ", ".join("%s %d" % kv for kv in sorted(r["causes"].items())) or "no miss",
        "; UART0: %d frames ok, %d MAC overruns, %d watchdog trips" % (u["frames_ok"], u["overruns"],
                                                                       u["watchdog_trips"]) if u else "",
        "" if r.get("qemu_realtime") else " (QEMU at normal scheduling)")


def report_qemu(r):
    print("\nthe firmware in QEMU (lm3s6965evb, raw Ethernet through a bridge):")
    if "skipped" in r:
        print("  SKIPPED: %s" % r["skipped"])
        return
    rt = r.get("reply_time", {})
    if "error" in rt:
        print("  reply time: FAILED: %s" % rt["error"])
    elif rt:
        print("  reply time, request leaving the host to reply reaching it (bridge capture, kernel stamps), "
              "%d Hz, %d s, each board in its own slot:" % (1000000 // rt["period_us"], rt["seconds"]))
        for name, b in rt["boards"].items():
            print("    %s" % reply_line(name, b))
    for p in r.get("probes", []):
        if "error" in p:
            print("  every %5.0f ms: FAILED: %s" % (p["period_us"] / 1000, p["error"]))
        else:
            print("  every %5.0f ms, %d s: %s" % (p["period_us"] / 1000, p["seconds"], probe_line(p)))
    fc, ff = r.get("fastest_clean_us"), r.get("first_failing_us")
    print("  highest rate with zero misses: %s%s" % (
        "%.0f Hz (every %.0f ms)" % (1e6 / fc, fc / 1000) if fc else "none of the periods tried",
        "; every %.0f ms failed" % (ff / 1000) if ff else "; the fastest tried (1 ms) held"))
    failing = next((p for p in r.get("probes", []) if p["period_us"] == ff), None)
    if failing and failing.get("attributed"):
        print("  its misses (seq: cause, detail; the board's UART0 lines carry no times):")
        for seq, cause, detail in failing["attributed"][:10]:
            print("    seq %s: %s (%s)" % (seq, cause, detail))
    print("  %.0f s in all; load average %s at the start, %s at the end" % (
        r["elapsed_s"], "/".join(r["loadavg_at_start"]), "/".join(r["loadavg_at_end"])))
