"""Real-time scheduling may be refused (no privilege, a container): the host
must say so once and run on with normal scheduling, serving every device."""

import os
import shutil
import signal

from harness import undisturbed


def test_realtime_refused_falls_back_with_one_warning(t):
    # The host runs with RLIMIT_RTPRIO 0 and, as root, without CAP_SYS_NICE
    # (still root, so it can read the build wherever it is): the kernel
    # refuses SCHED_FIFO, whatever this machine's limits allow.
    prlimit = shutil.which("prlimit")
    assert prlimit, "prlimit (util-linux) is needed to lower RLIMIT_RTPRIO for this test"
    wrapper = (prlimit, "--rtprio=0:0", "--")
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        assert setpriv, "setpriv (util-linux) is needed to drop CAP_SYS_NICE for this test"
        wrapper += (setpriv, "--bounding-set=-sys_nice", "--inh-caps=-sys_nice", "--")
    host = t.host(settings={"realtime": "true"}, wrapper=wrapper)
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
