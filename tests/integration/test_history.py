"""The plots' history (docs/API.md, "GET /api/devices/NAME/history"): a
running machine has the recent values of the variables its manifest plots,
one list per variable as long as the list of times and never longer than
samples_max; a machine whose board is gone has none; the route needs a
token."""

import time

from harness import http_code, until

SAMPLES_MAX = 240  # docs/API.md: 120 s at one sample every 0.5 s


def history(host, name, token=None):
    return host.get("/api/devices/%s/history" % name, token=token)


def wait_samples(host, name, count, timeout_s=20):
    def look():
        if http_code(host, "/api/devices/%s/history" % name, host.ctx.token) == 200:
            h = history(host, name)
            if len(h["t"]) >= count:
                return h
        return None

    return until(look, timeout_s, "%s's history at %d samples" % (name, count), poll_s=0.25)


def test_a_running_machine_has_the_history_of_its_plots(t):
    host = t.host()
    t.kitchen(host)
    h = wait_samples(host, "washer-1", 4)
    assert h["machine"] == "washer-1" and h["driver_version"], "the answer names its machine: %r" % h
    assert h["samples_max"] == SAMPLES_MAX and h["period_s"] == 0.5, "the documented bounds: %r" % h
    # Exactly the washer's ui.plots = {{"drum_rpm", "drum_setpoint_rpm"}, {"level_l"}}.
    assert sorted(h["series"]) == ["drum_rpm", "drum_setpoint_rpm", "level_l"], (
        "the washer's series are its plotted variables: %r" % sorted(h["series"]))
    n = len(h["t"])
    assert 4 <= n <= SAMPLES_MAX, "%d samples" % n
    for name, values in h["series"].items():
        assert len(values) == n, "%s has %d values for %d times" % (name, len(values), n)
        assert all(v is None or isinstance(v, (int, float)) for v in values), "%s: %r" % (name, values)
        assert any(v is not None for v in values), "%s was a number in no sample: %r" % (name, values)
    assert h["t"] == sorted(h["t"]), "times oldest first: %r" % h["t"]
    gaps = [b - a for a, b in zip(h["t"], h["t"][1:])]
    assert all(0.2 < g < 2.0 for g in gaps), "samples about period_s apart: %r" % gaps
    assert abs(h["now"] - time.time()) < 5 and h["now"] >= h["t"][-1], "now is the host's clock: %r" % h["now"]
    # The lights may have attached after the washer's fourth sample, and
    # a sample taken before their driver first published is None: wait for
    # one that is not.
    seen = [None]

    def kitchen_sampled():
        seen[0] = wait_samples(host, "lights-1", 1)
        return any(v is not None for v in seen[0]["series"].get("kitchen", []))

    until(kitchen_sampled, 20, lambda: "a sample of the lights' kitchen: %r" % seen[0]["series"],
          poll_s=0.25)  # a sample every 0.5 s
    lights = seen[0]
    assert sorted(lights["series"]) == ["dining", "disposal", "kitchen", "tv"], (
        "booleans are kept as 0 and 1: %r" % lights["series"])
    assert all(v is None or v in (0, 1) for v in lights["series"]["kitchen"]), lights["series"]["kitchen"]


def test_a_machine_gone_has_no_history(t):
    host = t.host()
    board = t.board("dishwasher", "dish-1")
    host.wait_running(["dish-1"])
    wait_samples(host, "dish-1", 2)
    board.kill()
    host.wait_status(lambda s: host.device("dish-1", s) is None or host.device("dish-1", s)["state"] != "running",
                     30, "dish-1 dropped")
    until(lambda: http_code(host, "/api/devices/dish-1/history", t.token) == 404, 5,
          lambda: "dish-1's history gone (still there: %r)" % history(host, "dish-1"), poll_s=0.2)
    assert http_code(host, "/api/devices/nothing-here/history", t.token) == 404


def test_the_history_needs_a_token(t):
    host = t.host()
    t.board("dishwasher", "dish-1")
    host.wait_running(["dish-1"])
    wait_samples(host, "dish-1", 1)
    path = "/api/devices/dish-1/history"
    assert http_code(host, path) == 401, "no token: HTTP %d" % http_code(host, path)
    assert http_code(host, path, "vmac_bad") == 401, "a malformed token: HTTP %d" % http_code(host, path, "vmac_bad")
    read = t.make_token("read")
    assert http_code(host, path, read) == 200, "a read token: HTTP %d" % http_code(host, path, read)
