"""The board firmware on a microcontroller: the same firmware/board.c,
core/proto/proto.c and plants, built for the Cortex-M3 of a TI Stellaris
LM3S6965 (make firmware), booted in QEMU's lm3s6965evb machine, speaking raw
Ethernet through QEMU's model of the chip's MAC to a real vmacd
(docs/BOARD.md, "Firmware on a microcontroller").

The link: a Linux bridge of the test's own, one tap device per QEMU board
enslaved to it, vmacd on the bridge (--bus eth:BRIDGE); a POSIX vmac-board
joins through a veth pair whose other end is in a network namespace. Each
board's UART0 is QEMU's stdio: the harness reads its log lines from QEMU's
stdout and writes operator actions ('lights-1 toggle1 1') to its stdin.

Needs root (tap devices, a bridge, CAP_NET_RAW), qemu-system-arm and the
firmware image (build/firmware/, or $VMAC_FIRMWARE); where one is missing
each test is SKIPPED, which CI=true makes a failure."""

import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time

import harness
from harness import LOADED, TIMING, Skip, undisturbed

HERE = os.path.dirname(os.path.abspath(__file__))
CONFIG_SCRIPT = os.path.join(HERE, "..", "..", "scripts", "qemu-board-config.py")
BANNER = r"^vmac-board: 1 \S+ board on bus eth:lm3s6965"
# For the tests that are not about timing: QEMU is an ordinary process,
# which a busy machine holds off the CPU for a period or more now and then
# (seen: over the harness's 80 ms deadline, so a drop at its miss_limit of
# 1). A reply may take the device's whole period (the deadline is never
# longer than that), and a board is dropped after 5 misses in a row: about
# half a second without the CPU for the lights (100 ms), a second for the
# idle washer (200 ms), both inside the boards' 1.5 s watchdog.
RELAXED = {"reply_deadline_us": 250000, "miss_limit": 5}


def image_path(t):
    """The firmware's ELF image, or Skip when it was not built."""
    path = os.environ.get("VMAC_FIRMWARE") or os.path.join(t.bindir, "..", "firmware",
                                                           "vmac-board-lm3s6965.elf")
    path = os.path.abspath(path)
    if not os.path.exists(path):
        raise Skip("no firmware image %s (make firmware; needs gcc-arm-none-eabi and picolibc-arm-none-eabi)"
                   % path)
    return path


def firmware_image(t):
    """The firmware's ELF image, or Skip saying what is missing."""
    if os.geteuid() != 0:
        raise Skip("the QEMU boards need root (tap devices, a bridge, CAP_NET_RAW)")
    if not shutil.which("qemu-system-arm"):
        raise Skip("no qemu-system-arm (make deps installs it)")
    return image_path(t)


class Link:
    """A bridge of this test's own with a tap per QEMU board; removed at
    cleanup, after every process."""

    def __init__(self, t):
        self.t = t
        self.tag = "%05x" % random.SystemRandom().randint(0, 0xFFFFF)
        self.bridge = "vqb" + self.tag
        self.taps = 0
        self.ip("link", "add", self.bridge, "type", "bridge", "stp_state", "0", "forward_delay", "0")
        t.cleanups.append(lambda: self.quiet_ip("link", "del", self.bridge))
        # A fixed address: a bridge takes its lowest port's otherwise, and
        # vmacd sends from the address it read at start.
        self.ip("link", "set", self.bridge, "address", "02:00:00:%s:%s:%s" % (
            self.tag[0:2].rjust(2, "0"), self.tag[2:4], self.tag[4:].rjust(2, "0")))
        self.no_ipv6(self.bridge)
        self.ip("link", "set", self.bridge, "up")

    def ip(self, *argv):
        p = subprocess.run(["ip"] + list(argv), capture_output=True, text=True, timeout=30)
        if p.returncode != 0:
            raise Skip("cannot make the test's bridge and tap devices here (ip %s: %s)" % (
                " ".join(argv), p.stderr.strip()))

    @staticmethod
    def quiet_ip(*argv):
        subprocess.run(["ip"] + list(argv), capture_output=True, timeout=30)

    @staticmethod
    def no_ipv6(ifname):
        """No router solicitations and the like on the board's wire."""
        try:
            with open("/proc/sys/net/ipv6/conf/%s/disable_ipv6" % ifname, "w") as f:
                f.write("1")
        except OSError:
            pass

    def tap(self):
        self.taps += 1
        name = "vqt%s%d" % (self.tag, self.taps)
        self.ip("tuntap", "add", "dev", name, "mode", "tap")
        self.t.cleanups.append(lambda: self.quiet_ip("link", "del", name))
        self.no_ipv6(name)
        self.ip("link", "set", name, "master", self.bridge)
        self.ip("link", "set", name, "up")
        return name

    def namespace_port(self):
        """A veth pair, one end in the bridge, the other in a new network
        namespace: (namespace, interface) for a POSIX vmac-board."""
        ns, near, far = "vqn" + self.tag, "vqh" + self.tag, "vqp" + self.tag
        self.ip("netns", "add", ns)
        self.t.cleanups.append(lambda: self.quiet_ip("netns", "del", ns))
        self.ip("link", "add", near, "type", "veth", "peer", "name", far)
        self.t.cleanups.append(lambda: self.quiet_ip("link", "del", near))
        self.no_ipv6(near)
        self.ip("link", "set", far, "netns", ns)
        self.ip("link", "set", near, "master", self.bridge)
        self.ip("link", "set", near, "up")
        self.ip("netns", "exec", ns, "ip", "link", "set", far, "up")
        return ns, far


def qemu_board(t, image, link, plant, name, config=()):
    """A QEMU LM3S6965 running a copy of image patched to (plant, name) and
    the config script's further options, on a tap of link; returns its
    Proc once the firmware's banner is out. Without a --key-file (or
    --no-key) in config the board gets the key the test enrolls for it
    (t.enroll), as on a host with bus_trust enrolled."""
    if "--key-file" not in config and "--no-key" not in config:
        t.enroll([name])
        config = list(config) + ["--key-file", os.path.join(t.keys, name + ".key")]
    copy = os.path.join(t.logdir, "%s.elf" % name)
    p = subprocess.run([sys.executable, CONFIG_SCRIPT, image, "-o", copy, "--plant", plant, "--name", name]
                       + list(config), capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, "qemu-board-config.py refused %s: %s" % (name, p.stderr.strip())
    mac = [kv.split()[1] for kv in p.stdout.strip().split(", ") if kv.startswith("mac ")][0]
    argv = ["qemu-system-arm", "-M", "lm3s6965evb", "-display", "none", "-monitor", "none", "-serial", "stdio",
            "-nic", "tap,ifname=%s,script=no,downscript=no,model=stellaris,mac=%s" % (link.tap(), mac),
            "-kernel", copy]
    board = harness.Proc(t._name("qemu-" + name), argv, t.logdir, stdin=True)
    t.procs.append(board)
    line = board.wait_line(BANNER, 30, what="the firmware's banner on UART0")
    assert "MAC %s %s" % (name, mac) in line.text, "the board announces another MAC than %s: %r" % (mac, line.text)
    return board


def test_a_qemu_washer_is_discovered_and_served(t):
    image = firmware_image(t)
    link = Link(t)
    board = qemu_board(t, image, link, "washer", "washer-1")
    host = t.host(bus="eth:" + link.bridge, settings=RELAXED)
    s = host.wait_running(["washer-1"], timeout_s=30)
    d = host.device("washer-1", s)
    assert d["driver"] == "washer", "the QEMU washer runs driver %r" % d["driver"]
    assert d["protocol"] == 2 and d["service"] == "cyclic", "served %s with protocol %s, expected cyclic v2" % (
        d["service"], d["protocol"])
    assert d["address"] == board.find_lines(BANNER)[0].text.split()[-1], "the host knows it at another MAC"
    board.wait_line(r"^washer-1: state known device 0x%08x " % d["id"], 30, what="the board's session")
    # 10 s of the host's own clock (uptime_s) at the driver's own period:
    # running throughout, no miss the host caused (undisturbed), a service
    # every period; a late reply of QEMU's is the machine's, not the
    # firmware's, and counts only as a period not served: most are.
    period_us, served, misses, up0 = d["period_us"], d["served"], d["misses"], s["uptime_s"]
    s = host.wait_status(lambda s: s["uptime_s"] - up0 >= 10, 30, "10 s of service", undisturbed(["washer-1"]))
    d = host.device("washer-1", s)
    assert d["period_us"] == period_us, "the period changed from %d to %d us" % (period_us, d["period_us"])
    span_s = s["uptime_s"] - up0
    expected = span_s * 1e6 / period_us
    tried, answered = d["served"] - served + d["misses"] - misses, d["served"] - served
    assert tried >= 0.8 * expected and answered * 2 >= tried, \
        "in %.1f s at a period of %d us (%d periods): served %d, missed %d" % (
            span_s, period_us, expected, answered, tried - answered)
    # The washer's sensors as the plant has them at rest: door closed, tub empty, 20 C.
    assert d["inputs"]["digital"][0] and d["inputs"]["digital"][2], "door closed and tub empty not read: %r" % (
        d["inputs"],)
    assert d["inputs"]["analog"][1] == 800, "water temperature %r counts, expected 800 (20 C)" % (
        d["inputs"]["analog"][1],)


def first_tick(host):
    """The lights driver toggles a light on a switch's change between two of
    its ticks: a switch flipped before its first tick is its starting
    position, no change. Its first tick publishes the lights, off."""
    host.wait_status(lambda s: host.device("lights-1", s)["variables"].get("kitchen") is False, 10,
                     "the lights driver's first tick")


def test_the_wall_switch_of_a_qemu_lights_board_reaches_the_driver(t):
    image = firmware_image(t)
    link = Link(t)
    board = qemu_board(t, image, link, "lights", "lights-1")
    host = t.host(bus="eth:" + link.bridge, settings=RELAXED)
    host.wait_running(["lights-1"], timeout_s=30)
    first_tick(host)
    mark = board.mark()
    board.send("lights-1 toggle1 1")
    board.wait_line(r"^lights-1: toggle1 1$", 30, since=mark, what="the action taken on UART0")
    host.wait_status(lambda s: host.device("lights-1", s)["inputs"]["digital"][0] is True, 10,
                     "the switch's new position in the host's status", undisturbed(["lights-1"]))
    host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is True, 10,
                     "the driver switching the kitchen light on", undisturbed(["lights-1"]))
    board.wait_line(r"^lights-1: outputs digital=0x01 pwm=0$", 30, since=mark, what="the light on, on UART0")
    # Flipped back: the driver toggles again, the light goes off.
    mark = board.mark()
    board.send("lights-1 toggle1 1")
    board.wait_line(r"^lights-1: outputs digital=0x00 pwm=0$", 30, since=mark, what="the light off, on UART0")
    host.wait_status(lambda s: host.device("lights-1", s)["outputs"]["digital"][0] is False, 10,
                     "the host's status with the light off", undisturbed(["lights-1"]))
    # An unknown board name and a refused action change nothing, for as
    # many periods as it takes the driver to see and act on a change.
    board.send("nobody-1 toggle1 1")
    board.send("lights-1 switch1 7")
    board.wait_line(r"^lights-1: refused switch1 7$", 30, since=mark, what="the refusal")
    board.wait_line(r"^vmac-board: no board named nobody-1$", 30, since=mark, what="the unknown name")
    served = host.device("lights-1", host.status())["served"]

    def unchanged(s):
        undisturbed(["lights-1"])(s)
        d = host.device("lights-1", s)
        assert d["inputs"]["digital"][0] is False, "a refused action moved the wall switch"
        assert d["outputs"]["digital"][0] is False, "a refused action switched the light"

    host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 10, 30, "10 more periods", unchanged)
    assert not board.find_lines(r"^lights-1: outputs digital=0x01", since=mark), "the light came on again"


def test_a_stopped_qemu_board_is_dropped_and_comes_back(t):
    image = firmware_image(t)
    link = Link(t)
    ns, port = link.namespace_port()
    board = qemu_board(t, image, link, "lights", "qlights-1")
    host = t.host(bus="eth:" + link.bridge)
    t.board("lights", "plights-1", bus="eth:" + port, wrapper=("ip", "netns", "exec", ns))
    host.wait_running(["qlights-1", "plights-1"], timeout_s=30)
    since = host.last_event_seq()
    board.signal(signal.SIGSTOP)
    try:
        dropped = host.wait_event("dropped", "qlights-1", after_seq=since, invariant=undisturbed(["plights-1"]))
        assert "qlights-1" in dropped["text"] and len(dropped["text"]) > len("qlights-1") + 5, \
            "the drop gives no reason: %r" % dropped["text"]
        served = host.device("plights-1")["served"]
        host.wait_status(lambda s: host.device("plights-1", s)["served"] > served + 25, 30,
                         "the POSIX board served on while the QEMU one is stopped", undisturbed(["plights-1"]))
        assert host.device("plights-1")["misses_host"] == 0, \
            "the host missed the POSIX board's service while its neighbour was stopped"
    finally:
        board.signal(signal.SIGCONT)
    host.wait_event("attached", "qlights-1", after_seq=dropped["seq"], timeout_s=60,
                    invariant=undisturbed(["plights-1"]))
    host.wait_running(["qlights-1", "plights-1"], invariant=undisturbed(["plights-1"]))


def test_the_host_killed_turns_a_qemu_boards_outputs_off(t):
    # What is timed here is the board's watchdog after the kill, which the
    # host's deadline and miss limit do not change; before it, the light
    # switched on is not about timing (a drop then, as in make test's ASan
    # pass beside the package build, restarts the driver and loses the
    # switch's change).
    image = firmware_image(t)
    link = Link(t)
    board = qemu_board(t, image, link, "lights", "lights-1")
    host = t.host(bus="eth:" + link.bridge, settings=RELAXED)
    host.wait_running(["lights-1"], timeout_s=30)
    first_tick(host)
    mark = board.mark()
    board.send("lights-1 toggle1 1")
    board.wait_line(r"^lights-1: outputs digital=0x01 pwm=0$", 30, since=mark, what="the light on")
    mark = board.mark()
    killed = time.monotonic()
    host.signal(signal.SIGKILL)
    limit_s = (TIMING["watchdog_ms"] + 2000) / 1000.0
    trip = board.wait_line(r"^lights-1: watchdog: no frame for %d ms, outputs off$" % TIMING["watchdog_ms"], 30,
                           since=mark, what="the watchdog's trip on UART0")
    off = board.wait_line(r"^lights-1: outputs digital=0x00 pwm=0$", 30, since=mark, what="the light off")
    assert trip.time_s - killed < limit_s, "the watchdog tripped %.2f s after the host died (period %d ms)" % (
        trip.time_s - killed, TIMING["watchdog_ms"])
    assert off.time_s - killed < limit_s, "the light still on %.2f s after the host died" % (off.time_s - killed)
    board.wait_line(r"^lights-1: state unknown device 0x00000000 ", 30, since=mark, what="back to discovery")


KEY_HEX = "00112233445566778899AABBCCDDeeff"
KEYED_LINE = r"^vmac-board: keyed: the board answers only a host that authenticates"


def config(*argv):
    """scripts/qemu-board-config.py argv: (exit code, stdout, stderr)."""
    p = subprocess.run([sys.executable, CONFIG_SCRIPT] + list(argv), capture_output=True, text=True, timeout=30)
    return p.returncode, p.stdout, p.stderr


def key_file(t):
    path = os.path.join(t.logdir, "board.key")
    with open(path, "w") as f:
        f.write(KEY_HEX + "\n")
    os.chmod(path, 0o600)
    return path


def booted(t, image, name):
    """QEMU running image with no network (no root needed) until its
    second start-up line, and a moment for a third; returns its Proc."""
    if not shutil.which("qemu-system-arm"):
        raise Skip("no qemu-system-arm (make deps installs it)")
    board = harness.Proc(t._name(name), ["qemu-system-arm", "-M", "lm3s6965evb", "-display", "none", "-monitor",
                                         "none", "-serial", "stdio", "-nic", "none", "-kernel", image], t.logdir,
                         stdin=True)
    t.procs.append(board)
    board.wait_line(r"^vmac-board: firmware ", 30, what="the firmware's start-up lines on UART0")
    mark = board.mark()
    board.send("status")  # answered after every start-up line
    board.wait_line(r"^\S+: frames ok ", 30, since=mark, what="the counters")
    return board


def test_the_identity_block_carries_a_key_and_never_shows_it(t):
    image = image_path(t)
    key = key_file(t)
    keyed = os.path.join(t.logdir, "keyed.elf")
    rc, out, err = config(image, "-o", keyed, "--name", "k-1", "--key-file", key)
    assert rc == 0 and out.rstrip().endswith(", keyed yes"), "writing a key: exit %d, %r %r" % (rc, out, err)
    assert os.stat(keyed).st_mode & 0o077 == 0, "the copy holding the key is mode %o, expected 0600" % (
        os.stat(keyed).st_mode & 0o777)
    with open(keyed, "rb") as f:
        assert bytes.fromhex(KEY_HEX) in f.read(), "the key is not in the copy's identity block"
    rc, out, _ = config(keyed, "--show")
    assert rc == 0 and "keyed=yes" in out.splitlines(), "--show of a keyed copy: %r" % out
    assert KEY_HEX[:8].lower() not in out.lower(), "--show printed the key"
    # Other changes keep the key; --no-key takes it out of the image.
    again = os.path.join(t.logdir, "again.elf")
    rc, out, _ = config(keyed, "-o", again, "--plant", "lights")
    assert rc == 0 and out.rstrip().endswith(", keyed yes"), "a new plant dropped the key: %r" % out
    plain = os.path.join(t.logdir, "plain.elf")
    rc, out, _ = config(keyed, "-o", plain, "--no-key")
    assert rc == 0 and out.rstrip().endswith(", keyed no"), "--no-key: %r" % out
    with open(plain, "rb") as f:
        assert bytes.fromhex(KEY_HEX) not in f.read(), "--no-key left the key in the image"
    # A block of version 1 (firmware from before keys): the flag and key
    # bytes were reserved. The script shows it unkeyed and refuses a key.
    with open(keyed, "rb") as f:
        data = bytearray(f.read())
    at = data.index(b"VMCF\x02\x00\x80\x00")
    data[at + 4] = 1
    old = os.path.join(t.logdir, "version1.elf")
    with open(old, "wb") as f:
        f.write(data)
    rc, out, _ = config(old, "--show")
    assert rc == 0 and "keyed=no" in out.splitlines(), "--show of a version-1 block: %r" % out
    rc, _, err = config(old, "-o", os.path.join(t.logdir, "refused.elf"), "--key-file", key)
    assert rc == 2 and "version 1" in err, "a key for a version-1 block: exit %d, %r" % (rc, err)
    # The firmware: keyed says so; version 1 with the same bytes runs unkeyed.
    board = booted(t, keyed, "qemu-keyed")
    assert board.find_lines(KEYED_LINE), "the keyed firmware did not say it is keyed: %r" % board.text("stdout")
    assert KEY_HEX[:8].lower() not in board.text("stdout").lower(), "the firmware printed its key"
    board = booted(t, old, "qemu-version1")
    assert not board.find_lines(KEYED_LINE), "a version-1 block ran keyed: %r" % board.text("stdout")
    assert not board.find_lines(r"identity block refused"), "a version-1 block was refused"


def test_a_keyed_qemu_board_never_attaches_to_a_host_without_its_key(t):
    # A key the host does not hold: the board answers the host's DISCOVERs
    # (they carry nonces), sealed with it, and is held back as waiting; it
    # never gets a session.
    image = firmware_image(t)
    link = Link(t)
    board = qemu_board(t, image, link, "lights", "klights-1", config=["--key-file", key_file(t)])
    board.wait_line(KEYED_LINE, 30, what="the keyed line")
    host = t.host(bus="eth:" + link.bridge)
    host.wait_event("waiting", "klights-1", timeout_s=30)
    d = host.device("klights-1", host.wait_status(lambda st: host.device("klights-1", st) is not None, 10,
                                                  "klights-1 in the status"))
    assert "key this host does not hold" in (d.get("note") or ""), "klights-1: %r" % d
    mark = board.mark()
    board.send("status")
    line = board.wait_line(r"^klights-1: frames ok ", 10, since=mark, what="the counters")
    assert line.text.startswith("klights-1: frames ok 0,"), "the keyed board took frames: %r" % line.text
    d = host.device("klights-1", host.status())
    assert d is None or d.get("state") != "running", "a keyed board runs on a host without its key"
    assert not board.find_lines(r"^klights-1: state known"), "the keyed board took a session"


def synced_qemu_board(t):
    """A keyed QEMU lights board, lights-1, running under vmacd with
    clock_sync_ms 1 on raw Ethernet: (board, host)."""
    image = firmware_image(t)
    link = Link(t)
    board = qemu_board(t, image, link, "lights", "lights-1")
    settings = dict(RELAXED, clock_sync_ms=1, slice_us=200, slices_per_slot=5)
    host = t.host(bus="eth:" + link.bridge, settings=settings)
    host.wait_running(["lights-1"], timeout_s=30)
    return board, host


def test_a_qemu_board_feeds_its_clock_from_sync(t):
    """SYNC from vmacd (clock_sync_ms 1, 1 ms slots) reaches the firmware's
    clock, stamped on SysTick's free-running count by the receive interrupt
    (docs/TIME.md, "The wiring"): the board says its clock is locking, its
    status counts SYNC frames accepted (most of them two-step: the host's
    bridge to the taps gives transmit stamps) and nothing malformed, and
    the board is served as ever. That it locks and then acts at the
    instants: the test after this one."""
    board, host = synced_qemu_board(t)
    board.wait_line(r"^lights-1: clock locking, offset [-+][0-9.]+ s, drift ", 30, what="the clock's first SYNC")
    served = host.device("lights-1")["served"]
    host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 20, 30, "20 more periods",
                     undisturbed(["lights-1"]))
    mark = board.mark()
    board.send("status")
    counters = board.wait_line(r"^lights-1: frames ok ", 30, since=mark, what="the counters")
    assert ", malformed 0," in counters.text, "the QEMU board counted frames malformed: %r" % counters.text
    clock = board.wait_line(r"^lights-1: clock \w+.*; sync accepted \d+", 30, since=mark, what="the clock's line")
    accepted = int(re.search(r"sync accepted (\d+)", clock.text).group(1))
    assert accepted > 100, "the QEMU board's clock accepted only %d SYNC frames: %r" % (accepted, clock.text)
    # the two-step (TIME.md, "The two-step SYNC"): the kernel stamps what
    # vmacd sends on the bridge to the taps, and the firmware pairs them
    two_step = int(re.search(r"two-step (\d+)", clock.text).group(1))
    assert two_step > 50, "the QEMU board took %d samples two-step: %r" % (two_step, clock.text)
    assert host.status()["counters"]["sync_stamps"] > 100, "host counters: %r" % host.status()["counters"]


# The clock's line of the board's 'status': its state, and its offset and
# bound unless the clock is lost ("clock lost, acting on arrival; sync ...").
CLOCK_LINE = r"^lights-1: clock (\w+)(?:, offset ([-+][0-9.]+) s, drift [-+][0-9.]+ ppm, bound ([0-9.]+) us)?[^;]*; sync"
# How long the counter's rate is judged, the board's clock line read once
# a second; VMAC_QEMU_CLOCK_S makes it longer for docs/TIME.md's figures.
RATE_SPAN_S = float(os.environ.get("VMAC_QEMU_CLOCK_S", "10"))
RATE_PPM = 50  # allowed: a crystal's error and then some; before the fix QEMU lost 4,000 to 18,000 ppm
# An offset that moved by more than this from one look to the next (a
# second apart) is a step, not a rate: QEMU held off the CPU for longer
# than two of SysTick's turns (671 ms), which the firmware cannot count
# (firmware/mcu/lm3s6965/clock.c, cycles_now); a part's interrupt is never
# held off so long.
STEP_S = 0.1


def clock_status(board):
    """The board's clock line of a fresh 'status': (line, state, offset s,
    bound us), the last two None when the clock is lost."""
    mark = board.mark()
    board.send("status")
    line = board.wait_line(CLOCK_LINE, 30, since=mark, what="the clock's line of a status")
    m = re.search(CLOCK_LINE, line.text)
    return line, m.group(1), m.group(2) and float(m.group(2)), m.group(3) and float(m.group(3))


def counter_rate(board, span_s):
    """The board's clock line once a second for span_s: the counter's rate
    against host time in ppm (the slope of the offsets it prints, by least
    squares over the harness's reading times) and a summary of the rest.
    A look at a lost clock, or at an offset that stepped (STEP_S), starts
    the span again: the rate is that of a counter the board kept. Six
    spans at most (LOADED times)."""
    rows, restarts, row = [], 0, None
    deadline = time.monotonic() + 6 * span_s * LOADED
    while not rows or rows[-1][0].time_s - rows[0][0].time_s < span_s:
        assert time.monotonic() < deadline, "no %.0f s of the QEMU board's clock without a loss or a step in %.0f s " \
            "(%d restarts; the last look: %r)" % (span_s, 6 * span_s * LOADED, restarts, row and row[0].text)
        if rows:
            time.sleep(1.0)
        row = clock_status(board)
        if row[2] is None or (rows and abs(row[2] - rows[-1][2]) > STEP_S):
            restarts += 1
            rows = [] if row[2] is None else [row]
        else:
            rows.append(row)
    n = len(rows)
    xs = [r[0].time_s - rows[0][0].time_s for r in rows]
    ys = [r[2] - rows[0][2] for r in rows]
    mx, my = sum(xs) / n, sum(ys) / n
    ppm = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs) * 1e6
    bounds = sorted(r[3] for r in rows)
    summary = "counter %+.1f ppm over %.0f s, offsets within %.0f us, bound p50 %.1f p90 %.1f us, locked at %d " \
        "of %d looks, the span started again %d times" % (ppm, xs[-1], (max(ys) - min(ys)) * 1e6, bounds[n // 2],
                                                         bounds[n * 9 // 10], sum(1 for r in rows if r[1] == "locked"),
                                                         n, restarts)
    return ppm, summary, rows[-1][0]


def test_a_qemu_boards_clock_locks_and_it_acts_at_the_instants(t):
    """The firmware's clock on QEMU (docs/TIME.md, "The wiring"): with
    vmacd's SYNC (clock_sync_ms 1) the clock locks, the board says it acts
    at host instants (by timer 0A's one-shot), and every TIMED reply the
    host reads while the board says locked has the ARRIVAL bit clear,
    until 20 services at the instants; its counter, SysTick counting its 24
    bits free-running, keeps host time (the offset the board prints moves
    by less than RATE_PPM over a span without a loss or a step: counted by
    SysTick interrupts it lost whole milliseconds whenever QEMU was held
    off the CPU). Locking is asserted
    to happen, not to last: on this shared VM QEMU's path from the tap to
    the firmware moves by several microseconds from one window to the
    next, at times past the clock's 20 us bound for leaving locked."""
    board, host = synced_qemu_board(t)
    board.wait_line(r"^lights-1: clock locked, offset ", 60, what="the clock locked")
    board.wait_line(r"^lights-1: acting at host instants$", 30, what="acting at host instants")
    seen = {"locked": 0, "timed": None}

    def locked_is_at_instants(s):
        c = host.device("lights-1", s)["clock"]
        assert c is not None, "the host has no TIMED reply of the QEMU board: %r" % host.device("lights-1", s)
        if c["state"] == "locked":
            assert c["on_arrival"] is False, "a TIMED reply says locked and acted on arrival: %r" % c
            seen["locked"] += 1

    def enough(s):
        c = host.device("lights-1", s)["clock"]
        if seen["timed"] is None:
            seen["timed"] = c["services_timed"]
        return seen["locked"] >= 3 and c["services_timed"] >= seen["timed"] + 20

    s = host.wait_status(enough, 120, "3 looks at a locked clock and 20 services at the instants",
                         locked_is_at_instants)
    c = host.device("lights-1", s)["clock"]
    ppm, summary, last = counter_rate(board, RATE_SPAN_S)
    timed = board.find_lines(r"^lights-1: timed \d+, on arrival \d+", since=last.index - 3)[-1]
    print("QEMU board: %s; host: services at the instants %d, on arrival %d; board: %s" % (
        summary, c["services_timed"], c["services_on_arrival"], timed.text), file=sys.stderr, flush=True)
    assert abs(ppm) < RATE_PPM, "the QEMU board's counter ran %+.1f ppm off host time: %s" % (ppm, summary)
    assert int(re.search(r"timed (\d+)", timed.text).group(1)) >= 20, "the board's counters: %r" % timed.text


def test_a_qemu_board_serves_a_timed_cyclic_on_arrival_without_a_clock(t):
    """Time-triggered I/O on the firmware (docs/TIME.md, "Time-triggered
    I/O"): the test plays the host on the bridge (AF_PACKET), with no SYNC,
    so the board's clock is unsynced; a TIMED CYCLIC whose instants lie 5 s
    ahead is served on arrival: the TIMED answer (flags REPLY | TIMED, 46
    bytes, ARRIVAL, unsynced, no latch time) comes at once, its applied the
    record's outputs, and the UART says so. With a clock, the timer path
    (timer 0A): test_a_qemu_boards_clock_locks_and_it_acts_at_the_instants."""
    import socket
    import struct

    from frames import (CLOCK_ARRIVAL, CYCLIC_DUE, DEV, DISCOVER, ETH_P_VMAC, OFFSET, REGISTER, REPLY, SHUTDOWN, SYS,
                        TIMED, UPDATE, cyclic, ethernet, frame, latch, parse, register, u16)

    image = firmware_image(t)
    link = Link(t)
    board = qemu_board(t, image, link, "lights", "lights-1", config=["--no-key"])
    s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_VMAC))
    s.bind((link.bridge, ETH_P_VMAC))
    me = s.getsockname()[4]
    broadcast = b"\xff" * 6

    def answer(seq, timeout_s=30):  # blocks in recv, not a poll: LOADED, not until
        deadline = time.monotonic() + timeout_s * LOADED
        while True:
            left = deadline - time.monotonic()
            assert left > 0, "no answer to seq %d from the QEMU board in %d s" % (seq, timeout_s * LOADED)
            s.settimeout(left)
            eth = s.recv(2048)
            got = parse(eth[14:])
            if eth[0:6] == me and got and got[0].flags & REPLY and got[0].seq == seq:
                return eth[6:12], got[0], got[1], eth[14:]

    try:
        s.send(ethernet(broadcast, me, frame(DISCOVER, channel=SYS, seq=7), pad=True))
        mac, h, data, _ = answer(7)
        major, minor = struct.unpack(">II", data[1 + data[0]:1 + data[0] + 8])
        device_id = (3 << 16) | 1
        s.send(ethernet(mac, me, frame(REGISTER, register(major, minor, 60000), device_id=device_id, seq=8, version=2),
                        pad=True))
        assert answer(8)[1].op == REGISTER
        s.send(ethernet(mac, me, frame(OFFSET, u16(1), device_id=device_id, seq=9, version=2), pad=True))
        assert answer(9)[2] == u16(1), "the QEMU board did not take offset 1"
        at = time.monotonic_ns() + 5 * 10**9
        s.send(ethernet(broadcast, me, cyclic([(0, 0, 0, 0), (3, CYCLIC_DUE, 0x05, 0)], seq=10, out_at=at), pad=True))
        _, h, data, payload = answer(10)
        assert time.monotonic_ns() < at, "the answer came after the instant: it waited, with no clock"
        board.wait_line(r"^lights-1: acting on arrival \(clock unsynced\)$", 30, what="'acting on arrival'")
        s.send(ethernet(mac, me, frame(SHUTDOWN, b"\x00", device_id=device_id, seq=11, version=2), pad=True))
        answer(11)
    finally:
        s.close()
    assert h.op == UPDATE and h.channel == DEV and h.flags == REPLY | TIMED and len(payload) >= 46, \
        "the TIMED answer: op 0x%02x flags 0x%02x, %d bytes" % (h.op, h.flags, len(payload))
    a = latch(data)
    assert a.clock == CLOCK_ARRIVAL and a.latched_at == 0 and a.bound_ns == 0xFFFFFFFF, \
        "an unsynced QEMU board's answer: %r" % (a,)
    assert a.applied_digital == 0x05, "applied 0x%02x, want the record's 0x05" % a.applied_digital
