"""Command lines: bad flags are refused with a clear message and the
documented exit code (never a crash), and every program's --help works."""

import glob
import os
import re
import socket

EXIT_S = 30  # a refused flag should end the program at once; this is the bound
SANITIZER_MARKS = ("AddressSanitizer", "LeakSanitizer", "runtime error:")


class Refusals:
    """Runs command lines that must be refused and collects every way one
    was not, so a single run reports them all."""

    def __init__(self, t):
        self.t = t
        self.problems = []

    def check(self, argv, base, mentions, want_rc=None, shown=None):
        """argv must exit with a positive code (want_rc when given; never a
        signal) and say every text of mentions on stderr. shown: how to name
        the command line in a failure (default: all of it)."""
        rc, out, err = self.t.run(argv, base, EXIT_S)
        shown = shown or "%s %s" % (argv[0].rsplit("/", 1)[-1], " ".join(argv[1:]))
        report = next((l for l in err.splitlines() if any(m in l for m in SANITIZER_MARKS)), None)
        if report:
            self.problems.append("'%s': %s" % (shown, report))
        if rc is None or rc <= 0:
            self.problems.append("'%s' exited %s, expected a refusal (negative: killed by a signal)" % (shown, rc))
        elif want_rc is not None and rc != want_rc:
            self.problems.append("'%s' exited %d, expected %d" % (shown, rc, want_rc))
        for text in mentions:
            if text not in err:
                self.problems.append("'%s': stderr does not mention %r: %r" % (shown, text, err.strip()[:200]))

    def done(self):
        assert not self.problems, "; ".join(self.problems)


    def vmacd(self, flags, base, mentions, want_rc=None):
        """check() vmacd on this test's bus with a free HTTP port, plus flags
        (later flags win, so a bad --bus or --http given here is the one used)."""
        argv = [self.t.path("vmacd"), "--bus", self.t.bus, "--http", "127.0.0.1:0", "--state", self.t.logdir,
                "--set", "realtime=false"]
        self.check(argv + flags, base, mentions, want_rc, shown="vmacd ... " + " ".join(flags))


def test_bad_flags_are_refused(t):
    # docs/HOST.md: "A wrong flag or value stops the host before it starts,
    # with exit code 2 and a message naming the setting."
    r = Refusals(t)
    r.vmacd(["--bus", "nonsense"], "vmacd-bus", ["nonsense"], want_rc=2)
    r.vmacd(["--bus", "10.0.0.1:5870"], "vmacd-bus-unicast", ["10.0.0.1:5870"], want_rc=2)
    r.vmacd(["--set", "slice_us=abc"], "vmacd-slice", ["slice_us", "abc"], want_rc=2)
    r.vmacd(["--set", "unknown_key=1"], "vmacd-unknown-key", ["unknown_key"], want_rc=2)
    r.vmacd(["--set", "slice_us"], "vmacd-set-no-value", ["KEY=VALUE"], want_rc=2)
    r.vmacd(["--set", "realtime=maybe"], "vmacd-realtime", ["realtime", "maybe"], want_rc=2)
    r.vmacd(["--set", "default_level=11", "--set", "max_level=10"], "vmacd-level", ["default_level"], want_rc=2)
    r.vmacd(["--set", "slice_us=100000", "--set", "watchdog_ms=100"], "vmacd-watchdog",
            ["watchdog_ms"], want_rc=2)
    r.vmacd(["--set", "driver.washer=1"], "vmacd-driver-key", ["driver.NAME.KEY"], want_rc=2)
    r.vmacd(["--http", "999.1.1.1:80"], "vmacd-http-addr", ["999.1.1.1"], want_rc=2)
    r.vmacd(["--http", "127.0.0.1:70000"], "vmacd-http-port", ["70000"], want_rc=2)
    r.vmacd(["--no-such-flag"], "vmacd-unknown-flag", ["usage"], want_rc=2)
    r.vmacd(["stray"], "vmacd-stray-arg", ["stray"], want_rc=2)
    busy = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        taken = "127.0.0.1:%d" % busy.getsockname()[1]
        r.vmacd(["--http", taken], "vmacd-http-busy", [taken])  # not a wrong value: any refusal
    finally:
        busy.close()

    board = t.path("vmac-board")
    r.check([board, "--plant", "nosuch", "--bus", t.bus], "board-plant", ["nosuch"], want_rc=2)
    r.check([board, "--bus", "nonsense"], "board-bus", ["nonsense"], want_rc=2)
    r.check([board, "--count", "0", "--bus", t.bus], "board-count", ["--count"], want_rc=2)
    r.check([board, "--name", "a/b", "--bus", t.bus], "board-name", ["a/b"], want_rc=2)
    r.check([board, "--name", "n" * 40, "--bus", t.bus], "board-long-name", ["31"], want_rc=2)

    # docs/CLI.md: 1 host unreachable, 2 wrong usage.
    vmac = t.path("vmac")
    r.check([vmac, "frobnicate"], "vmac-unknown-command", ["frobnicate"], want_rc=2)
    r.check([vmac], "vmac-no-command", ["usage"], want_rc=2)
    r.check([vmac, "status", "--bogus"], "vmac-status-bogus", ["bogus"], want_rc=2)
    closed = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        closed.bind(("127.0.0.1", 0))  # bound, never listening: connections are refused
        r.check([vmac, "status", "--http", "127.0.0.1:%d" % closed.getsockname()[1]], "vmac-no-host",
                ["cannot reach"], want_rc=1)
    finally:
        closed.close()
    r.done()


def test_help_and_version(t):
    for argv in (["vmacd", "--help"], ["vmac-board", "--help"], ["vmac", "--help"], ["vmac", "status", "--help"],
                 ["vmac", "token", "--help"], ["vmac", "console", "--help"], ["vmac", "get", "--help"],
                 ["vmac", "set", "--help"], ["vmac", "events", "--help"], ["vmac", "test", "--help"]):
        rc, out, err = t.run([t.path(argv[0])] + argv[1:], argv[0] + "-help", EXIT_S)
        assert rc == 0, "'%s' exited %d: %s" % (" ".join(argv), rc, err)
        assert out.startswith("usage: "), "'%s' printed no usage on stdout: %r" % (" ".join(argv), out[:200])
    for program in ("vmacd", "vmac"):
        rc, out, err = t.run([t.path(program), "--version"], program + "-version", EXIT_S)
        assert rc == 0 and out.startswith(program + " "), "'%s --version' exited %d, printed %r" % (
            program, rc, out)


def test_lint_knows_the_sandbox(t):
    """vmac lint passes every shipped driver and flags what the sandbox lacks."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    shipped = sorted(glob.glob(os.path.join(root, "scripts", "drivers", "*.lua")))
    assert shipped, "no shipped drivers found under scripts/drivers"
    rc, out, err = t.run([t.path("vmac"), "lint"] + shipped, "lint-shipped")
    assert rc == 0, "vmac lint fails the shipped drivers (exit %d):\n%s%s" % (rc, out, err)

    bad = os.path.join(t.logdir, "escape.lua")
    with open(bad, "w") as f:
        f.write("local d = {}\nfunction d.tick()\n  debug.getinfo(1)\n  return io.open('/etc/passwd')\nend\n"
                "return d\n")
    rc, out, err = t.run([t.path("vmac"), "lint", bad], "lint-bad")
    assert rc == 1, "vmac lint exit %d for a driver using debug and io, expected 1:\n%s%s" % (rc, out, err)
    for name in ("debug", "io"):
        assert re.search(r"escape\.lua:\d+:\d+: accessing undefined variable '?%s'?" % name, out), (
            "vmac lint did not report %s:\n%s" % (name, out))
