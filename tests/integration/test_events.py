"""The event stream (docs/API.md, "GET /api/events"; docs/CLI.md, "vmac
events"): events arrive as they happen, a client resumes after the last one
it saw, the stream needs a token, and a host that stops ends its streams
instead of waiting for them."""

import json
import signal
import urllib.error
import urllib.request


def events_cmd(t, host, base, *args):
    return t.start([t.path("vmac"), "events", "--http", host.http] + list(args), base)


def json_lines(proc):
    return [json.loads(l.text) for l in proc.lines["stdout"]]


def test_events_arrive_as_they_happen_and_resume(t):
    host = t.host()
    # The log begins with the audit events of the test's token and of the
    # board's key (docs/API.md "Audit trail"); the board's come after them.
    host.wait_event("audit", text="vmac token create")
    t.enroll(["lights-1"])
    made = host.wait_event("audit", text="vmac board enroll lights-1")["seq"]
    follow = events_cmd(t, host, "events-follow", "--json", "--count", "2", "--after", str(made))
    # Whether the stream opens before or after the board attaches, it starts
    # with the events the log keeps (after the key's), so nothing is missed.
    board = t.board("lights", "lights-1", keyed=False, extra=("--key-dir", t.keys))
    host.wait_running(["lights-1"])
    board.signal(signal.SIGSTOP)
    rc = follow.wait_exit(30)
    board.signal(signal.SIGCONT)
    events = json_lines(follow)
    assert rc == 0, "vmac events --count 2 exited %d: %s" % (rc, follow.text("stderr"))
    assert [(e["kind"], e["device"]) for e in events] == [("attached", "lights-1"), ("dropped", "lights-1")], (
        "the stream's events: %r" % events)
    assert events[0]["seq"] < events[1]["seq"], "events out of order: %r" % events

    # Resume after the first: the second comes at once, from the log.
    again = events_cmd(t, host, "events-resume", "--json", "--count", "1", "--after", str(events[0]["seq"]))
    assert again.wait_exit(30) == 0, "resuming failed: %s" % again.text("stderr")
    assert [e["seq"] for e in json_lines(again)] == [events[1]["seq"]], "resumed at the wrong event: %r" % (
        json_lines(again))

    # People's format: seq, time, kind, text.
    people = events_cmd(t, host, "events-people", "--count", "1", "--after", str(made))
    assert people.wait_exit(30) == 0
    line = people.lines["stdout"][0].text
    assert line.startswith("%d " % events[0]["seq"]) and "attached" in line and "lights-1 attached" in line, (
        "vmac events' line: %r" % line)


def test_the_stream_needs_a_token_and_a_valid_resume_point(t):
    host = t.host()
    req = urllib.request.Request("http://%s/api/events" % host.http)
    try:
        urllib.request.urlopen(req, timeout=10)
        raise AssertionError("GET /api/events without a token was answered")
    except urllib.error.HTTPError as e:
        assert e.code == 401, "GET /api/events without a token: HTTP %d" % e.code
    req = urllib.request.Request("http://%s/api/events?after=abc" % host.http)
    req.add_header("Authorization", "Bearer " + t.token)
    try:
        urllib.request.urlopen(req, timeout=10)
        raise AssertionError("GET /api/events?after=abc was answered")
    except urllib.error.HTTPError as e:
        assert e.code == 400, "GET /api/events?after=abc: HTTP %d" % e.code
    p = t.start([t.path("vmac"), "events", "--http", host.http, "--token", "vmac_bad"], "events-bad-token")
    rc = p.wait_exit(30)
    assert rc == 1 and "401" in p.text("stderr"), "vmac events with a bad token: exit %d, %r" % (
        rc, p.text("stderr"))


def test_a_stopping_host_ends_its_streams(t):
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    follow = events_cmd(t, host, "events-open")
    follow.wait_line(r"lights-1 attached", 30, what="the replayed attach event: the stream is open")
    streams = [urllib.request.urlopen(urllib.request.Request(
        "http://%s/api/events" % host.http, headers={"Authorization": "Bearer " + t.token}), timeout=30)
        for _ in range(3)]
    host.signal(signal.SIGTERM)
    assert host.wait_exit(10) == 0, "vmacd did not stop within 10 s with event streams open"
    rc = follow.wait_exit(10)
    assert rc == 0 and "the host ended the stream" in follow.text("stderr"), (
        "vmac events when the host stopped: exit %d, %r" % (rc, follow.text("stderr")))
    for s in streams:
        s.close()


def test_the_event_log_is_kept_in_the_store(t):
    """Events go to the store (docs/API.md "GET /api/events/log"): they are
    there after the host stops and starts again, and numbering goes on."""
    host = t.host()
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    host.wait_status(lambda s: any(e["kind"] == "attached" for e in host.get("/api/events/log")["events"]), 10,
                     "the attach event in the stored log")
    before = host.get("/api/events/log")["events"]
    attached = [e for e in before if e["kind"] == "attached" and e["device"] == "lights-1"]
    assert attached, "no attached event for lights-1 in the stored log: %r" % before
    host.signal(signal.SIGTERM)
    assert host.wait_exit(30) == 0, "vmacd did not stop cleanly"

    host = t.host()
    host.wait_running(["lights-1"], timeout_s=60)
    host.wait_status(lambda s: len([e for e in host.get("/api/events/log?limit=1000")["events"]
                                    if e["kind"] == "attached"]) >= 2, 10, "the second attach stored")
    after = host.get("/api/events/log?limit=1000")["events"]
    seqs = [e["seq"] for e in after]
    assert seqs == sorted(set(seqs)), "the stored seqs are not unique and in order: %r" % seqs
    assert after[0] == before[0], "the first run's events are gone: %r vs %r" % (after[0], before[0])
    assert host.status()["events"][-1]["seq"] > before[-1]["seq"], "numbering started over after the restart"
    assert host.get("/api/events/log?after=%d&limit=1" % after[0]["seq"])["events"][0]["seq"] == after[1]["seq"], \
        "after= does not page"
    for bad in ("after=-1", "limit=0", "limit=5000", "after=x"):
        try:
            host.get("/api/events/log?" + bad)
            raise AssertionError("GET /api/events/log?%s answered 200" % bad)
        except urllib.error.HTTPError as e:
            assert e.code == 400, "GET /api/events/log?%s: %d" % (bad, e.code)
