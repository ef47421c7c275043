"""The flight recorder keeps each board's latch time (docs/RECORDING.md,
"The file"; docs/TIME.md): a tick line's optional `at` per board is the
instant its inputs were sampled (the driver's dev.boards[i].t), and
`vmac test --replay` gives it back to the driver, so a driver that computes
with dev.t replays as it ran. A recording without `at` (written before
latch times) replays as before: dev.t is the tick's time. vmacd with clock
sync records the instants its timed boards latched at, by the boards' own
--io-log."""

import bisect
import hashlib
import json
import math
import os
import re
import signal
import time

from harness import LOADED, fetch_recording, recording_id
from test_recording import http_post, vmac

# A machine of two boards whose outputs say how long before the tick each
# board's inputs were sampled: pwm the lag in microseconds, do0 the parity
# of the lag in nanoseconds (so a replay that is off by 1 ns differs), do1
# that dev.t is the primary's dev.boards[1].t. A tick before the second
# board has joined sets the first board's outputs only.
LATCHPROBE = """local driver = {
	name = "latchprobe", version = "1",
	io = { lag_a = { "pwm", board = 0 }, odd_a = { "do0", board = 0 }, same = { "do1", board = 0 },
		lag_b = { "pwm", board = 1 }, odd_b = { "do0", board = 1 } },
}
local function lag(time, t)
	local ns = math.floor((time - t) * 1e9 + 0.5)
	return math.max(-1000, math.min(1000, math.floor(ns / 1000 + 0.5))), ns % 2 == 1
end
function driver.tick(dev, inputs)
	dev.out.lag_a, dev.out.odd_a = lag(inputs.time, dev.t)
	if dev.boards[2] then -- the machine begins with its first board alone
		dev.out.lag_b, dev.out.odd_b = lag(inputs.time, dev.boards[2].t)
	end
	dev.out.same = dev.t == dev.boards[1].t
end
return driver
"""

SYNC_SETTINGS = {"clock_sync_ms": 1, "slice_us": 200, "slices_per_slot": 5}
PERIOD_NS = 16000000
# A latch time is the board's clock's reading of its latch: the true
# instant (its counter is CLOCK_MONOTONIC itself) within the clock's error,
# a microsecond or less once locked (TIME.md).
LATCH_SLACK_NS = 5000
LATCH_BEHIND_NS = 1000000000  # the host's bound on a plausible latch (core/host/timed.c)
IO_LATCH = re.compile(r"^\S+ latch (\S+) true=(-?\d+) host=\d+ ")


def outputs(t_ns, at_ns):
    """What LATCHPROBE returns for one board whose inputs were sampled at
    at_ns (None: at the tick's time) in the tick at t_ns: [digital, pwm],
    by the driver's own arithmetic on the doubles replay gives it
    (inputs.time = t_ns / 1e9, dev.t = at_ns / 1e9)."""
    if at_ns is None:
        at_ns = t_ns
    ns = math.floor((t_ns / 1e9 - at_ns / 1e9) * 1e9 + 0.5)
    return [ns % 2, max(-1000, min(1000, math.floor(ns / 1000 + 0.5)))]


def latched_instants(path):
    """The true instants (CLOCK_MONOTONIC ns) a board's --io-log says it
    latched its inputs at, sorted, each with how (docs/BOARD.md: instant,
    at the host's instant by its clock; late, at once, the frame having
    come after it; arrival, without a usable clock; overrun)."""
    with open(path) as f:
        return sorted((int(m.group(2)), m.group(1)) for m in map(IO_LATCH.match, f) if m)


def got_latch(kinds):
    return [k for k in kinds if k not in (None, "received")]


def sealed(lines):
    """Recording lines (header first, JSON objects) as a file's bytes, with
    the end line a writer gives: the count and the BLAKE2b-256 hash."""
    body = b"".join(json.dumps(l, separators=(",", ":")).encode() + b"\n" for l in lines)
    end = {"end": {"lines": len(lines) - 1, "blake2b": hashlib.blake2b(body, digest_size=32).hexdigest()}}
    return body + json.dumps(end, separators=(",", ":")).encode() + b"\n"


def write(t, name, data):
    path = os.path.join(t.logdir, name)
    with open(path, "wb") as f:
        f.write(data)
    return path


def crafted(lags, with_at=True, outputs_at=True, extra=False):
    """A recording of LATCHPROBE: ticks 16 ms apart (7 ns past the ms), board
    i of tick k sampled lags[k][i] ns before it (None: at the tick's time,
    no "at"). with_at: the ticks carry their "at"; outputs_at: the outputs
    recorded are those of the lags (else of dev.t at the tick's time);
    extra: keys no reader knows, in the header, a tick line and a board."""
    header = {"format": "vmac-recording", "version": 1, "machine": "probe-0", "driver": "latchprobe",
              "driver_version": "1", "version_id": 0, "reason": "asked", "captured": 1795000000.0, "level": 4,
              "period_s": PERIOD_NS / 1e9, "attach_t": 1000000, "complete": True,
              "boards": [{"name": "probe-0", "minor": 0}, {"name": "probe-1", "minor": 1}]}
    if extra:
        header["written_by"] = {"vmac": "a later one"}
    lines = [header, {"t": 1000000, "event": "attach", "version": "1"}]
    for k, pair in enumerate(lags):
        t_ns = 3600 * 10 ** 9 + (k + 1) * PERIOD_NS + 7
        tick = []
        for b, lag in enumerate(pair):
            at = None if lag is None else t_ns - lag
            entry = {"b": b, "in": [0, 0, 0, 0, 0, 0], "out": outputs(t_ns, at if outputs_at else None)}
            if b == 0:
                entry["out"][0] |= 2  # dev.t is the primary's dev.boards[1].t
            if with_at and at is not None:
                entry["at"] = at
            if extra:
                entry["how"] = "instant"
            tick.append(entry)
        line = {"t": t_ns, "tick": tick}
        if extra:
            line["clock"] = ["locked", 1.5]
        lines.append(line)
    return sealed(lines)


LAGS = [(None, None), (137001, 52999), (900000, 900000), (1, None), (None, 250000), (15999999, 3), (0, 2)]


def test_a_replay_gives_the_driver_each_boards_latch_time_as_recorded(t):
    """Crafted recordings of LATCHPROBE, run by `vmac test --replay` and by
    the test file `vmac recording to-test` makes (replay() in Lua): with
    `at` the replayed dev.t and dev.boards[i].t are the recorded ones to the
    nanosecond (every output as recorded); without `at`, an old recording,
    they are the tick's time, as before; the same outputs without their
    `at` differ where a board's latch came before its tick; keys a reader
    does not know are skipped."""
    drivers = t.drivers(latchprobe=LATCHPROBE)
    runs = (("latched.rec", crafted(LAGS), 0),
            ("old.rec", crafted(LAGS, with_at=False, outputs_at=False), 0),
            ("unknown-keys.rec", crafted(LAGS, extra=True), 0),
            ("lost-at.rec", crafted(LAGS, with_at=False), 1))
    for name, data, want in runs:
        path = write(t, name, data)
        rc, out, err = vmac(t, "test", "--replay", path, "--drivers", drivers, token="")
        assert rc == want, "%s: vmac test --replay exited %d, not %d:\n%s%s" % (name, rc, want, out, err)
        if want == 0:
            m = re.search(r"(\d+) ticks and 0 operator inputs replayed: every output as recorded", out)
            assert m and int(m.group(1)) == len(LAGS), "%s: not every tick replayed as recorded: %r" % (name, out)
        else:
            # The first tick whose board was sampled before its tick: the second.
            assert re.search(r"DIFFERS at tick 2 \(\S+ s\), board 0:", out), \
                "%s: the replay without at does not differ at tick 2, board 0: %r" % (name, out)
        test_file = os.path.join(t.logdir, name + "_test.lua")
        rc, _, err = vmac(t, "recording", "to-test", path, stdout_file=test_file, token="")
        assert rc == 0, "vmac recording to-test %s failed (exit %d): %s" % (name, rc, err)
        rc, out, err = vmac(t, "test", "--drivers", drivers, test_file, token="")
        assert rc == want, "%s as a test file (replay() in Lua): exit %d, not %d:\n%s%s" % (name, rc, want, out,
                                                                                            err)


def test_vmacd_records_the_instants_its_timed_boards_latched_at(t):
    """vmacd with clock_sync_ms 1 runs LATCHPROBE on two boards acting at
    host instants (phase-aligned pattern, counters CLOCK_MONOTONIC itself);
    `vmac record` captures the machine. Every tick of the last second has an
    `at` per board, the same instant for both or a period apart, before the
    tick by less than two periods, nearly all of them instants the boards
    latched at by their own --io-log (else the reply's receive time); the
    driver's outputs (its dev.t to the nanosecond) replay as recorded, and
    without the `at` they differ."""
    drivers = t.drivers(latchprobe=LATCHPROBE)
    host = t.host(drivers=drivers, settings=SYNC_SETTINGS)
    logs, procs = {}, {}
    for minor in (0, 1):
        name = "probe-%d" % minor
        logs[name] = os.path.join(t.logdir, name + ".io.log")
        procs[name] = t.board("generic", name, driver="latchprobe", major=7, minor=minor,
                              extra=["--io-log", logs[name]])
    host.wait_running(sorted(procs))
    for name, board in procs.items():
        board.wait_line(r"^%s: acting at host instants$" % name, 60, what="%s acting at host instants" % name)
    def at_instants(path):
        with open(path) as f:
            return sum(1 for line in f if " latch instant " in line)

    # A second and a half of latches at the instants, by the boards' own
    # logs, then the recording. A board the loaded machine held off the
    # CPU past its deadline drops the machine, which attaches again with a
    # new recorder: then the wait and the recording are done again.
    for attempt in range(3):
        host.wait_running(sorted(procs))
        started = host.last_event_seq()
        before = {p: at_instants(p) for p in logs.values()}
        deadline = time.monotonic() + 60 * LOADED  # then the recording says what came: until does not fit
        while time.monotonic() < deadline and not all(at_instants(p) >= before[p] + 100 for p in logs.values()):
            time.sleep(0.2)
        since = host.last_event_seq()
        code, body = http_post(host, "/api/devices/probe-0/record", {}, t.token)
        assert code == 200, "POST /api/devices/probe-0/record: %d %s" % (code, body)
        # The machine is named after its primary, the board that answered
        # discovery first: either of the two.
        path = fetch_recording(t, host, recording_id(host.wait_event("recording", after_seq=since)), "probe.rec")
        with open(path, "rb") as f:
            lines = [json.loads(l) for l in f.read().decode().splitlines()]
        header, ticks = lines[0], [l for l in lines[1:-1] if "tick" in l]
        period_ns = round(header["period_s"] * 1e9)
        last = ticks[-int(1e9 // period_ns):]  # the last second
        dropped = host.find_events("dropped", after_seq=started)
        if len(last) >= 30 or not dropped:
            break
    assert len(last) >= 30, "only %d ticks in the recording's last second (drops: %r)" % (
        len(last), [e["text"] for e in dropped])
    for board in procs.values():
        board.signal(signal.SIGTERM)
        assert board.wait_exit(30) == 0, "a board did not exit cleanly"
    latched = {name: latched_instants(p) for name, p in logs.items()}
    # The tick runs on the primary's reply, after its latch; the other
    # board's reply may come after that, and the tick then has its inputs
    # of the period before (DRIVERS.md, dev.boards[i].t). How long after is
    # the machine's load (a bus thread or a worker held off the CPU), so
    # the bound is the host's own: a latch more than LATCH_BEHIND_NS before
    # its reply is not believed (core/host/timed.c).
    for tick in last:
        ats = [b.get("at") for b in tick["tick"]]
        assert len(ats) == 2 and None not in ats, "a tick of the last second without each board's at: %r" % tick
        assert all(0 < tick["t"] - at < LATCH_BEHIND_NS for at in ats), \
            "tick at %d: the boards' inputs were latched %d and %d ns before it" % (tick["t"], tick["t"] - ats[0],
                                                                                  tick["t"] - ats[1])
    # Bus time is CLOCK_MONOTONIC less the host's start: one offset takes
    # the at of nearly every tick to an instant the board's own log says it
    # latched at (its in_at, or later when the frame came late). The host takes
    # the reply's receive time instead when a reply gives it no plausible
    # latch (TIME.md, "dev.t"): then the at is that receive time, after the
    # board's latch (by less than a period on a quiet machine).
    def kind(name, h):
        i = bisect.bisect_right(latched[name], (h + LATCH_SLACK_NS, "~")) - 1
        if i < 0 or h - latched[name][i][0] >= LATCH_BEHIND_NS:
            return None
        return latched[name][i][1] if h - latched[name][i][0] <= LATCH_SLACK_NS else "received"

    names = [b["name"] for b in header["boards"]]  # the primary first, as the tick's entries

    def kinds(off):
        return [kind(name, tick["tick"][b]["at"] + off) for tick in last for b, name in enumerate(names)]
    first = last[0]["tick"][0]["at"]
    best = max((h - first for h, _ in latched[names[0]]), key=lambda off: len(got_latch(kinds(off))))
    got = kinds(best)
    assert None not in got and len(got_latch(got)) >= 0.9 * len(got), (
        "of the last second's %d latch times %d are instants the boards latched at, %d receive times after "
        "one, %d neither" % (len(got), len(got_latch(got)), got.count("received"), got.count(None)))
    for i, tick in enumerate(last):  # both at the host's instant: one instant (of the period, or the one before)
        apart = (tick["tick"][0]["at"] - tick["tick"][1]["at"]) % period_ns
        assert got[2 * i:2 * i + 2] != ["instant", "instant"] or min(apart, period_ns - apart) <= LATCH_SLACK_NS, \
            "the two boards latched %d ns apart, not at one instant of a period, in tick %r" % (apart, tick)
    lags = [tick["t"] - tick["tick"][0]["at"] for tick in last]
    print("latch times: %d ticks, %d of %d board inputs at a latch (%d at the host's instant; the rest: the "
          "reply's receive time); the primary's %.1f .. %.1f us before the tick" % (
              len(last), len(got_latch(got)), len(got), got.count("instant"), min(lags) / 1e3, max(lags) / 1e3))

    rc, out, err = vmac(t, "test", "--replay", path)
    assert rc == 0, "the recording does not replay as recorded (exit %d):\n%s%s" % (rc, out, err)
    m = re.search(r"(\d+) ticks and 0 operator inputs replayed: every output as recorded", out)
    assert m and int(m.group(1)) == len(ticks), "the replay ran %s ticks, the recording has %d: %r" % (
        m and m.group(1), len(ticks), out)
    for line in lines[1:-1]:
        for b in line.get("tick", ()):
            b.pop("at", None)
    rc, out, err = vmac(t, "test", "--replay", write(t, "no-at.rec", sealed(lines[:-1])))
    assert rc == 1 and "DIFFERS at tick" in out, \
        "without its at the recording replays as recorded (exit %d):\n%s%s" % (rc, out, err)
