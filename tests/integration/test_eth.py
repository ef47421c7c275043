"""vmac on raw Ethernet (EtherType 0x88B5) with the cyclic frame of protocol
version 2 (docs/PROTOCOL.md, "Version 2"): vmacd on one end of a veth pair,
the boards in a network namespace of their own on the other end. Also the
cyclic frame on UDP, and version-1 boards served beside version-2 ones."""

import os
import re
import signal
import subprocess
import sys
import time

from frames import HDR_LEN, UPDATE, ethernet, inputs, reply
from harness import KITCHEN, KITCHEN_NAMES, TIMING, misread, undisturbed, watchdog_trip

PEER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "eth_peer.py")
MAC = re.compile(r"^([0-9a-f]{2}:){5}[0-9a-f]{2}$")


def eth_kitchen(t, commands=False, settings=None):
    """vmacd on eth:HOST_IF, the kitchen's three boards in the namespace."""
    host_if, ns, board_if = t.eth_link()
    host = t.host(bus="eth:" + host_if, settings=settings)
    wrap = ("ip", "netns", "exec", ns)
    boards = {name: t.board(plant, name, bus="eth:" + board_if, wrapper=wrap, commands=commands)
              for plant, name in KITCHEN}
    host.wait_running(KITCHEN_NAMES, timeout_s=30)
    return host, boards, (host_if, ns, board_if)


def check_cyclic(host, names, status=None):
    s = status or host.status()
    offsets = set()
    for n in names:
        d = host.device(n, s)
        assert d["protocol"] == 2 and d["service"] == "cyclic", \
            "%s is served %s with protocol %s, expected the cyclic frame of version 2" % (
                n, d["service"], d["protocol"])
        assert d["offset"] == d["id"] & 0xFFFF, "%s holds offset %r, its slot is %d" % (n, d["offset"],
                                                                                       d["id"] & 0xFFFF)
        offsets.add(d["offset"])
    assert len(offsets) == len(names), "two devices share an offset: %r" % offsets


def counters(host):
    return host.status()["counters"]


def test_the_kitchen_runs_on_raw_ethernet(t):
    host, boards, _ = eth_kitchen(t, commands=True)
    s = host.status()
    check_cyclic(host, KITCHEN_NAMES, s)
    for n in KITCHEN_NAMES:
        addr = host.device(n, s)["address"]
        assert MAC.match(addr) and addr.startswith("02:"), \
            "%s's address %r is not a locally administered MAC" % (n, addr)
    served = {n: host.device(n, s)["served"] for n in KITCHEN_NAMES}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 20 for n in KITCHEN_NAMES), 30,
                     "every device served 20 times more", undisturbed(KITCHEN_NAMES))
    # Operator input on the board reaches the driver, whose output reaches the board.
    lights = boards["lights-1"]
    mark = lights.mark()
    lights.send("lights-1 toggle1 1")
    lights.wait_line(r"^lights-1: outputs digital=0x01 ", 30, since=mark, what="the kitchen light on")
    host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is True, 10,
                     "the host sees the kitchen light on", undisturbed(KITCHEN_NAMES))
    c = counters(host)
    assert not misread(c), "the host counted its own bus's frames as malformed: %r" % (c["malformed_by_reason"],)


def test_a_silent_board_is_dropped_and_comes_back(t):
    host, boards, _ = eth_kitchen(t)
    others = ["dish-1", "lights-1"]
    since = host.last_event_seq()
    boards["washer-1"].signal(signal.SIGSTOP)
    try:
        dropped = host.wait_event("dropped", "washer-1", after_seq=since, invariant=undisturbed(others))
        served = host.device("lights-1")["served"]
        host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 25, 30,
                         "lights-1 served while washer-1 is stopped", undisturbed(others))
    finally:
        boards["washer-1"].signal(signal.SIGCONT)
    host.wait_event("attached", "washer-1", after_seq=dropped["seq"], invariant=undisturbed(others))
    s = host.wait_running(["washer-1"], invariant=undisturbed(others))
    check_cyclic(host, KITCHEN_NAMES, s)


def test_the_host_killed_leaves_every_board_safe(t):
    host, boards, _ = eth_kitchen(t, commands=True)
    host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("kitchen") is False, 30,
                     "the lights driver's first tick (a switch flipped before it is no change)")
    mark = boards["lights-1"].mark()
    boards["lights-1"].send("lights-1 toggle1 1")
    boards["lights-1"].wait_line(r"^lights-1: outputs digital=0x01 ", 30, since=mark, what="the light on")
    marks = {n: b.mark() for n, b in boards.items()}
    killed = time.monotonic()
    host.signal(signal.SIGKILL)
    limit_s = (TIMING["watchdog_ms"] + 2000) / 1000.0
    trips = {}
    for name, board in boards.items():
        trips[name] = trip = watchdog_trip(board, name, marks[name])
        assert trip.off_s - killed < limit_s, "%s tripped its watchdog %.2f s after the host died" % (
            name, trip.off_s - killed)  # the board's own clock, not when the line was read
    # The light goes off in the watchdog's turn: the next outputs line.
    off = boards["lights-1"].wait_line(r"^lights-1: outputs ", 30, since=trips["lights-1"].line.index + 1,
                                       what="the outputs after the watchdog")
    assert off.text.endswith(" digital=0x00 pwm=0"), "lights-1 drives %r after its watchdog" % off.text


def test_version_1_boards_are_served_beside_version_2(t):
    host_if, ns, board_if = t.eth_link()
    host = t.host(bus="eth:" + host_if)
    wrap = ("ip", "netns", "exec", ns)
    t.board("lights", "old-1", driver="lights", bus="eth:" + board_if, wrapper=wrap, extra=("--protocol", "1"))
    t.board("lights", "new-1", driver="lights", bus="eth:" + board_if, wrapper=wrap)
    s = host.wait_running(["old-1", "new-1"])
    old = host.device("old-1", s)
    assert old["protocol"] == 1 and old["service"] == "unicast" and old["offset"] is None, \
        "a version-1 board is served %s with protocol %s" % (old["service"], old["protocol"])
    check_cyclic(host, ["new-1"], s)
    served = {n: host.device(n, s)["served"] for n in ("old-1", "new-1")}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 20 for n in served), 30,
                     "both served", undisturbed(["old-1", "new-1"]))


def test_the_cyclic_frame_on_udp(t):
    """No root needed: the cyclic frame goes to the multicast group, and a
    version-1 board on the same bus is served by unicast."""
    host = t.host()
    t.board("lights", "old-1", driver="lights", extra=("--protocol", "1"))
    t.board("generic", "gen", driver="generic", count=20)
    names = ["gen-%d" % i for i in range(1, 21)]
    s = host.wait_running(names + ["old-1"])
    check_cyclic(host, names, s)
    assert host.device("old-1", s)["service"] == "unicast", "the version-1 board is not served by unicast"
    served = {n: host.device(n, s)["served"] for n in names + ["old-1"]}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 10 for n in served), 30,
                     "every board served", undisturbed(names + ["old-1"]))


def peer(t, ns, board_if, *argv):
    p = t.start(["ip", "netns", "exec", ns, sys.executable, PEER, argv[0], "--iface", board_if] + list(argv[1:]),
                "eth-peer")
    p.wait_line(r"^eth_peer: ", 30, what="eth_peer started")
    return p


def test_a_board_confirming_the_wrong_offset_is_refused(t):
    # The peers are boards of ours without a key: bus_trust open lets them
    # attach, beside the kitchen's keyed boards (sealed and plain CYCLIC
    # frames side by side).
    host, _, (host_if, ns, board_if) = eth_kitchen(t, settings={"bus_trust": "open"})
    since = host.last_event_seq()
    before = counters(host)["malformed_by_reason"]["offset"]
    p = peer(t, ns, board_if, "offset", "--name", "liar-1", "--mac", "02:00:00:00:ee:01")
    p.wait_line(r"^eth_peer: given offset \d+, confirmed \d+", 30, what="the wrong confirmation")
    e = host.wait_event("dropped", "liar-1", after_seq=since, invariant=undisturbed(KITCHEN_NAMES))
    assert "confirmed offset" in e["text"], "the drop does not say why: %r" % e["text"]
    host.wait_status(lambda s: s["counters"]["malformed_by_reason"]["offset"] > before, 10,
                     "the wrong offset counted", undisturbed(KITCHEN_NAMES))
    assert host.device("liar-1")["state"] != "running", "a board with the wrong offset runs"

    since = host.last_event_seq()
    p = peer(t, ns, board_if, "size", "--name", "greedy-1", "--mac", "02:00:00:00:ee:02", "--major", "4343")
    e = host.wait_event("dropped", "greedy-1", after_seq=since, invariant=undisturbed(KITCHEN_NAMES))
    assert "8-byte cyclic records" in e["text"], "the drop does not say why: %r" % e["text"]


def test_short_frames_and_spoofed_replies_are_counted_and_ignored(t):
    host, _, (host_if, ns, board_if) = eth_kitchen(t)
    with open("/sys/class/net/%s/address" % host_if) as f:
        host_mac = bytes(int(x, 16) for x in f.read().strip().split(":"))
    washer = host.device("washer-1")
    spoofer = bytes([0x02, 0, 0, 0, 0xee, 0x03])
    spoofed = inputs(digital=0xFF, analog=(4095, 4095), applied_digital=0x7F, pwm=1000)
    update_reply = reply(UPDATE, spoofed, device_id=washer["id"], seq=1, version=2)
    junk = {
        "short": update_reply[:5],  # shorter than a header (no padding on veth)
        "length": update_reply[:HDR_LEN + 3],  # len says 12, 3 follow
        "unknown_sender": update_reply,  # the washer's session, from another MAC
    }
    on_wire = {reason: ethernet(host_mac, spoofer, payload) for reason, payload in junk.items()}
    before = counters(host)["malformed_by_reason"]
    p = peer(t, ns, board_if, "junk", *sum((["--frame", f.hex()] for f in on_wire.values()), []))
    p.wait_line(r"^eth_peer: sent 3 frames", 30, what="the junk sent")

    def counted(s):
        now = s["counters"]["malformed_by_reason"]
        return all(now[k] > before[k] for k in on_wire)

    s = host.wait_status(counted, 10, "every junk frame counted under its reason", undisturbed(KITCHEN_NAMES))
    assert host.device("washer-1", s)["inputs"]["analog"] != [4095, 4095], \
        "the spoofed reply's inputs reached the washer's driver"
    served = host.device("washer-1", s)["served"]
    host.wait_status(lambda s: host.device("washer-1", s)["served"] > served + 10, 30,
                     "the washer served on after the spoofed reply", undisturbed(KITCHEN_NAMES))


def test_without_cap_net_raw_each_program_says_what_to_do(t):
    if os.geteuid() != 0:
        from harness import Skip
        raise Skip("needs root to drop CAP_NET_RAW from a child")
    state = os.path.join(t.logdir, "nobody-state")
    os.makedirs(state, exist_ok=True)
    os.chmod(state, 0o777)
    drop = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", "--inh-caps=-all",
            "--bounding-set=-all"]
    for argv in ([t.path("vmacd"), "--bus", "eth:lo", "--state", state, "--http", "127.0.0.1:0"],
                 [t.path("vmac-board"), "--bus", "eth:lo", "--plant", "lights"]):
        rc, out, err = t.run(drop + argv, os.path.basename(argv[0]) + "-nocap", timeout_s=30)
        lines = [l for l in err.splitlines() if l.strip()]
        assert rc != 0, "%s ran without CAP_NET_RAW (exit 0)" % argv[0]
        assert any("CAP_NET_RAW" in l and "setcap" in l for l in lines), \
            "%s did not say it needs CAP_NET_RAW: %r" % (os.path.basename(argv[0]), err)


def test_more_boards_than_one_cyclic_frame_holds(t):
    """250 boards: offsets 0-239 in one CYCLIC frame, the rest in a second
    one each slot; every board served, none by another's record."""
    host = t.host(settings={"max_devices": 300, "default_level": 6})  # 250 x 16 of 5 x 1024 slice-slots
    t.board("generic", "many", driver="generic", count=250)
    names = ["many-%d" % i for i in range(1, 251)]
    s = host.wait_running(names, timeout_s=90)
    check_cyclic(host, names, s)
    offsets = sorted(host.device(n, s)["offset"] for n in names)
    assert offsets[-1] >= 240, "every board got an offset below 240 (%d): the second frame is never used" % (
        offsets[-1])
    served = {n: host.device(n, s)["served"] for n in names}
    host.wait_status(lambda s: all(host.device(n, s)["served"] > served[n] + 5 for n in names), 60,
                     "all 250 boards served by both frames", undisturbed(names))
