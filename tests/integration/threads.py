"""A running program's threads by name, from /proc/PID/task: the tests
that pin, park or judge one of vmacd's threads (vmac-bus, vmac-worker-N)
find it here."""

import os


def threads(pid, prefix):
    """The ids of process pid's threads whose name (comm) begins with prefix."""
    found = []
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            with open("/proc/%d/task/%s/comm" % (pid, tid)) as f:
                if f.read().strip().startswith(prefix):
                    found.append(int(tid))
        except OSError:  # a thread that ended meanwhile
            pass
    return found


def thread_of(pid, name):
    """The id of process pid's thread called name."""
    for tid in threads(pid, name):
        with open("/proc/%d/task/%d/comm" % (pid, tid)) as f:
            if f.read().strip() == name:
                return tid
    raise AssertionError("process %d has no thread named %s" % (pid, name))


def schedstat(pid, tid):
    """What the kernel says of thread tid (/proc/PID/task/TID/schedstat):
    (ns it ran, ns it waited, runnable, for a CPU, times it was on one)."""
    with open("/proc/%d/task/%d/schedstat" % (pid, tid)) as f:
        ran_ns, waited_ns, slices = (int(x) for x in f.read().split())
    return ran_ns, waited_ns, slices
