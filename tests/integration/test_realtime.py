"""Real-time scheduling may be refused (no privilege, a container): the host
must say so once and run on with normal scheduling, serving every device."""

import os
import shutil

from harness import undisturbed


def test_realtime_refused_falls_back_with_one_warning(t):
    wrapper = ()
    if os.geteuid() == 0:
        # As root SCHED_FIFO would be granted: run the host without
        # CAP_SYS_NICE (still root, so it can read the build wherever it
        # is), which with RLIMIT_RTPRIO 0 makes the kernel refuse it.
        setpriv = shutil.which("setpriv")
        assert setpriv, "setpriv (util-linux) is needed to drop CAP_SYS_NICE for this test"
        wrapper = (setpriv, "--bounding-set=-sys_nice", "--inh-caps=-sys_nice", "--")
    host = t.host(settings={"realtime": "true"}, wrapper=wrapper)
    t.board("lights", "lights-1")
    status = host.wait_running(["lights-1"])
    warnings = host.find_events("warning", text="real-time setup refused")
    if status["bus"]["realtime"]:
        # Not root, but allowed real-time by its limits: nothing to warn about.
        assert not warnings, "real-time granted, yet warned: %r" % warnings
        return
    assert len(warnings) == 1, "expected one 'real-time setup refused' warning, got %d: %r" % (
        len(warnings), [e["text"] for e in host.find_events("warning")])
    served = host.device("lights-1", status)["served"]
    host.wait_status(lambda s: host.device("lights-1", s)["served"] > served + 10, 30,
                     "lights-1 served with normal scheduling", undisturbed(["lights-1"]))
