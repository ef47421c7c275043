"""One thread of a running vmacd stopped and let go again, for the
watchdog tests (test_service.py, tests/package/boot.py): PTRACE_SEIZE and
PTRACE_INTERRUPT stop only that thread, where SIGSTOP would stop them all,
so the main thread goes on while the bus thread is held."""

import ctypes
import os

PTRACE_DETACH, PTRACE_SEIZE, PTRACE_INTERRUPT = 17, 0x4206, 0x4207
WALL = 0x40000000


class Parked:
    """Thread tid stopped until release(); OSError when ptrace refuses."""

    def __init__(self, tid):
        self.libc = ctypes.CDLL(None, use_errno=True)
        self.libc.ptrace.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p]
        self.tid = tid
        for request in (PTRACE_SEIZE, PTRACE_INTERRUPT):
            if self.libc.ptrace(request, tid, None, None) != 0:
                err = ctypes.get_errno()
                raise OSError(err, "ptrace of thread %d: %s" % (tid, os.strerror(err)))
        os.waitpid(tid, WALL)

    def release(self):
        """Let it go; once its process was killed meanwhile, it is ours to
        reap before the process can end (True: it was let go alive)."""
        alive = self.libc.ptrace(PTRACE_DETACH, self.tid, None, None) == 0
        try:
            os.waitpid(self.tid, WALL | os.WNOHANG)
        except ChildProcessError:
            pass
        return alive
