"""Real-time scheduling may be refused (no privilege, a container): the host
must say so once and run on with normal scheduling, serving every device.
The simulated boards ask for it too (docs/BOARD.md, "Real-time
scheduling"), below the host's threads, and say so once when refused."""

import os
import re
import shutil
import signal

from harness import undisturbed

REFUSED = r"^vmac-board: real-time setup refused \("
BOARD_PRIORITY = 30


def no_realtime_wrapper():
    """A command prefix under which the kernel refuses SCHED_FIFO, whatever
    this machine's limits allow: RLIMIT_RTPRIO 0 and, as root, no
    CAP_SYS_NICE (still root, so the program can read the build wherever it
    is)."""
    prlimit = shutil.which("prlimit")
    assert prlimit, "prlimit (util-linux) is needed to lower RLIMIT_RTPRIO for this test"
    wrapper = (prlimit, "--rtprio=0:0", "--")
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        assert setpriv, "setpriv (util-linux) is needed to drop CAP_SYS_NICE for this test"
        wrapper += (setpriv, "--bounding-set=-sys_nice", "--inh-caps=-sys_nice", "--")
    return wrapper


def policy(pid):
    """(scheduling policy without SCHED_RESET_ON_FORK, priority) of pid."""
    return os.sched_getscheduler(pid) & ~os.SCHED_RESET_ON_FORK, os.sched_getparam(pid).sched_priority


def stopped_stderr(t, board):
    """Every line board printed on stderr, read to the end: stopped first."""
    board.signal(signal.SIGTERM)
    assert board.wait_exit(20) == 0, "vmac-board did not stop cleanly"
    return board.find_lines(r".", stream="stderr")


def test_realtime_refused_falls_back_with_one_warning(t):
    host = t.host(settings={"realtime": "true"}, wrapper=no_realtime_wrapper())
    t.board("lights", "lights-1")
    status = host.wait_running(["lights-1"])
    warnings = host.find_events("warning", text="real-time setup refused")
    assert not status["bus"]["realtime"], "real-time was granted with RLIMIT_RTPRIO 0 and no CAP_SYS_NICE"
    assert len(warnings) == 1, "expected one 'real-time setup refused' warning, got %d: %r" % (
        len(warnings), [e["text"] for e in host.find_events("warning")])
    served = host.device("lights-1", status)["served"]
    host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 10, 30,
                     "lights-1 served with normal scheduling", undisturbed(["lights-1"]))


def held_open(pid, path):
    """Whether process pid holds path open."""
    for fd in os.listdir("/proc/%d/fd" % pid):
        try:
            if os.readlink("/proc/%d/fd/%s" % (pid, fd)) == path:
                return True
        except OSError:  # closed meanwhile
            pass
    return False


def test_cpu_awake_holds_the_pm_qos_request_only_when_asked(t):
    """cpu_awake = true: vmacd holds /dev/cpu_dma_latency open (the kernel's
    PM QoS request of 0 us lasts as long as that) while serving; by default
    it does not. Where the device cannot be opened (not root, no such
    device), one warning and the host runs on."""
    dev = "/dev/cpu_dma_latency"
    host = t.host(settings={"cpu_awake": "true"})
    t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    if os.geteuid() == 0 and os.path.exists(dev):
        assert held_open(host.pid, dev), "vmacd with cpu_awake does not hold %s open" % dev
        assert not host.find_events("warning", text="cpu_awake refused"), "cpu_awake refused as root"
    else:
        assert len(host.find_events("warning", text="cpu_awake refused")) == 1, \
            "cpu_awake could not be had here, and vmacd did not say so once"
    host.signal(signal.SIGTERM)
    assert host.wait_exit(20) == 0, "vmacd did not stop cleanly"
    other = t.host()
    assert not held_open(other.pid, dev), "vmacd holds %s open without cpu_awake" % dev


def test_a_board_runs_real_time_below_the_host(t):
    """As root vmac-board gets SCHED_FIFO below vmacd's bus thread and
    driver workers, and says nothing about it; elsewhere it gets it if this
    machine's RLIMIT_RTPRIO allows, or says once that it did not."""
    host = t.host(settings={"realtime": "true"})
    board = t.board("lights", "lights-1")
    s = host.wait_running(["lights-1"])
    got = policy(board.pid)
    assert got[0] in (os.SCHED_FIFO, os.SCHED_OTHER), "vmac-board runs with policy %d" % got[0]
    if os.geteuid() == 0:
        assert got == (os.SCHED_FIFO, BOARD_PRIORITY), "as root vmac-board runs with (policy, priority) %r, " \
            "not SCHED_FIFO %d" % (got, BOARD_PRIORITY)
    if got[0] == os.SCHED_FIFO and s["bus"]["realtime"]:
        host_rt = {tid: policy(tid)[1] for tid in map(int, os.listdir("/proc/%d/task" % host.pid))
                   if policy(tid)[0] == os.SCHED_FIFO}
        assert host_rt, "vmacd says it runs real-time, yet none of its threads is SCHED_FIFO"
        assert got[1] < min(host_rt.values()), "vmac-board's SCHED_FIFO %d is not below every real-time " \
            "thread of vmacd's (%r)" % (got[1], host_rt)
    refused = [l.text for l in stopped_stderr(t, board) if re.search(REFUSED, l.text)]
    assert len(refused) == (got[0] != os.SCHED_FIFO), "vmac-board got %s and printed %d refusal lines: %r" % (
        "SCHED_FIFO" if got[0] == os.SCHED_FIFO else "normal scheduling", len(refused), refused)


def test_a_board_refused_real_time_says_so_once_and_is_served(t):
    host = t.host()
    board = t.board("lights", "lights-1", wrapper=no_realtime_wrapper())
    line = board.wait_line(REFUSED, 30, stream="stderr", what="the refusal")
    assert "SCHED_FIFO" in line.text and "RLIMIT_RTPRIO" in line.text, "the refusal does not say what and why: " \
        "%r" % line.text
    assert policy(board.pid)[0] == os.SCHED_OTHER, "vmac-board runs real-time although it was refused"
    s = host.wait_running(["lights-1"])
    served = host.device("lights-1", s)["served"]
    host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 10, 30,
                     "lights-1 served with normal scheduling", undisturbed(["lights-1"]))
    # --no-realtime: not asked, so nothing to say.
    quiet = t.board("lights", "lights-2", extra=("--no-realtime",))
    host.wait_running(["lights-1", "lights-2"])
    assert policy(quiet.pid)[0] == os.SCHED_OTHER, "vmac-board --no-realtime runs real-time"
    lines = [l.text for l in stopped_stderr(t, quiet)]
    assert not lines, "vmac-board --no-realtime printed on stderr: %r" % lines
    refused = [l.text for l in stopped_stderr(t, board) if re.search(REFUSED, l.text)]
    assert len(refused) == 1, "expected one refusal line, got %d: %r" % (len(refused), refused)
