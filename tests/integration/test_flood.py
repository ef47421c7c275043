"""A flood of fake boards on the bus (issue #30, "Bounded under flood"): a
process on the segment answers every DISCOVER with hundreds of ANNOUNCEs of
made-up identities of the lights driver. The host lets at most attach_max
of them attach at once and attach_rate a second, says so in a `flood`
warning, and its memory, its real boards and its event log are unaffected.
Having no key (bus_trust enrolled, the default), none attaches: each is
held as waiting for approval, at most attach_max of them listed."""

import random
import socket

from frames import ANNOUNCE, DISCOVER, SYS, announce, parse, reply
from harness import KITCHEN_NAMES, bus_socket, plain_pass_too, sanitized, undisturbed

TOTAL = 10000
OPEN_TOTAL = 3000  # the open bus's flood: enough for the limiter, a third of the time
PER_DISCOVER = 300


def rss_kib(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise AssertionError("no VmRSS for pid %d" % pid)


@plain_pass_too("vmacd's memory under the flood (RSS says nothing under ASan)")
def test_a_flood_of_fake_boards_is_bounded(t):
    flood(t, TOTAL, trust_open=False)


@plain_pass_too("vmacd's memory under the flood (RSS says nothing under ASan)")
def test_a_flood_of_fake_boards_is_bounded_on_an_open_bus(t):
    flood(t, OPEN_TOTAL, trust_open=True)


def flood(t, total, trust_open):
    """total fake announcements; trust_open: bus_trust open, where boards
    without a key attach: the fakes load drivers, at most attach_max at
    once."""
    host = t.host(settings={"bus_trust": "open"} if trust_open else None)
    t.kitchen(host)
    before = host.status()
    rss_before = rss_kib(host.pid)
    target = before["bus"]["host_addr"].rsplit(":", 1)
    target = (target[0], int(target[1]))
    seed = random.SystemRandom().randrange(1 << 32)
    rnd = random.Random(seed)
    sock = bus_socket(t.bus, 5)
    most_attaching = most_waiting = 0
    sent = 0
    try:
        while sent < total:
            got = parse(sock.recvfrom(2048)[0])
            if not got or got[0].channel != SYS or got[0].op != DISCOVER:
                continue
            for _ in range(min(PER_DISCOVER, total - sent)):
                n = rnd.randrange(1 << 31)  # a made-up identity of the lights driver
                sock.sendto(reply(ANNOUNCE, announce(b"lights", b"fake-%d" % n, major=n), channel=SYS,
                                  seq=got[0].seq), target)
                sent += 1
            s = host.status()
            undisturbed(KITCHEN_NAMES)(s)
            attaching = sum(1 for d in s["devices"] if d["state"] == "attaching")
            most_attaching = max(most_attaching, attaching)
            waiting = sum(1 for d in s["devices"] if d["state"] == "waiting")
            most_waiting = max(most_waiting, waiting)
    finally:
        sock.close()

    flood = host.wait_event("flood", timeout_s=30, invariant=undisturbed(KITCHEN_NAMES))
    assert "attach_max" in flood["text"], "the flood warning does not say which setting: %r" % flood["text"]
    after = host.status()
    assert host.alive(), "vmacd died under the flood"
    refused = after["counters"]["attach_refused"] - before["counters"]["attach_refused"]
    assert refused > total // 2, "only %d of %d fake announcements were refused (seed %d)" % (refused, total, seed)
    assert most_attaching <= 32, "%d devices attaching at once, attach_max is 32" % most_attaching
    # Without keys (bus_trust enrolled) the fakes are held as waiting for
    # approval, never attaching: no driver state at all, and at most
    # attach_max listed.
    if not trust_open:
        assert most_attaching == 0, "%d fake boards without a key attached" % most_attaching
        assert most_waiting <= 32, "%d boards listed as waiting at once, attach_max is 32" % most_waiting
    floods = host.find_events("flood")
    assert len(floods) <= 3, "%d flood warnings in one flood: they are said at most every 10 s" % len(floods)
    # The driver states of the few let in are freed when they fail to
    # register; what is left is the device table, allocated at start.
    # (Under AddressSanitizer freed memory sits in its quarantine, 256 MiB
    # by default: RSS says nothing there.)
    grown = rss_kib(host.pid) - rss_before
    assert sanitized(t.path("vmacd")) or grown < 48 * 1024, (
        "vmacd grew by %d KiB under a flood of %d fake boards (seed %d)" % (grown, total, seed))
    # The real boards were served throughout, and still are.
    served = {n: host.device(n, after)["served"] for n in KITCHEN_NAMES}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 5 for n in KITCHEN_NAMES), 30,
                     "every real board served after the flood", undisturbed(KITCHEN_NAMES))
