"""Command lines: bad flags are refused with a clear message and the
documented exit code (never a crash), and every program's --help works."""

import glob
import os
import re
import socket
import subprocess

from harness import NO_LEAK_SCAN, SANITIZER_MARKS

EXIT_S = 30  # a refused flag should end the program at once; this is the bound


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
    for program in ("vmacd", "vmac", "vmac-board"):
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



def test_lint_gives_one_answer_for_any_path_to_a_file(t):
    """A driver test linted by an absolute path from elsewhere, by a relative
    path, and by one with '..' gets the same warnings: the test API's
    globals are known however the file is named (scripts/luacheckrc)."""
    folder = os.path.join(t.logdir, "mine", "tests")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, "mine_test.lua")
    with open(path, "w") as f:
        f.write('test("one", function()\n  local b = board{ plant = "generic" }\n  run_for(1)\n'
                '  expect(b ~= nil, "a board")\n  local unused = 1\nend)\n')
    elsewhere = os.path.join(t.logdir, "elsewhere")
    os.makedirs(elsewhere, exist_ok=True)
    ways = [(elsewhere, path), (folder, "mine_test.lua"), (t.logdir, "mine/tests/../tests/./mine_test.lua"),
            (elsewhere, "../mine/tests/mine_test.lua"), ("/", "." + path)]
    answers = []
    for cwd, name in ways:
        p = subprocess.run([t.path("vmac"), "lint", name], cwd=cwd, capture_output=True, text=True, timeout=60)
        warnings = sorted(re.sub(r"^.*mine_test\.lua:", "", l.strip()) for l in p.stdout.splitlines()
                          if "mine_test.lua:" in l)
        answers.append((p.returncode, warnings))
    assert answers[0][0] == 1 and len(answers[0][1]) == 1 and "unused" in answers[0][1][0], (
        "vmac lint of the test by its absolute path, from elsewhere: %r (wanted exit 1 and only the unused variable)" % (
            answers[0],))
    for (cwd, name), answer in zip(ways[1:], answers[1:]):
        assert answer == answers[0], "vmac lint %s from %s answered %r, by the absolute path %r" % (
            name, cwd, answer, answers[0])

# Every vmac command and action (docs/CLI.md) with the options it takes
# beside --help, as the documentation names them. A command that loses one
# of them, or its --help, or a command added without an entry here, fails the
# tests below.
API = ["--http", "--host", "--token", "--token-file", "--json"]  # "Reaching a host", "Tokens"
CONSOLE = ["--http", "--host", "--token", "--token-file", "--quiet"]
COMMANDS = {
    "status": API,
    "events": API + ["--after", "--count"],
    "logs": API + ["--follow", "--level"],
    "bundle": ["--json", "--output", "--counter", "--keys"],
    "reload": API + ["--driver", "--probation", "--force", "--sig", "--counter"],
    "rollback": API,
    "activate": API + ["--probation"],
    "drivers": API,
    "recordings": API,
    "recording get": API,
    "recording to-test": [],
    "record": API,
    "schedule": API,
    "console": CONSOLE,
    "get": CONSOLE,
    "set": CONSOLE,
    "token create": ["--state", "--scope", "--note"],
    "token list": ["--state"],
    "token revoke": ["--state"],
    "board enroll": API + ["--state", "--local", "--key-file", "--out", "--key-dir", "--replace", "--note", "--quiet"],
    "board list": API + ["--state", "--local"],
    "board remove": API + ["--state", "--local"],
    "site": ["--mqtt", "--prefix", "--json", "--wait", "--user", "--password-file", "--cafile"],
    "lint": [],
    "bench": ["--seconds", "--only", "--max-boards", "--cpu-awake", "--out"],
    "test": ["--drivers", "--replay", "--filter", "--seed", "--list", "--tap", "--junit", "--trace", "--time-limit",
             "--timeout", "--history"],
}
PARENTS = {"": ["status", "lint", "test", "token", "board", "console", "get", "set", "events", "logs", "site", "bundle",
                "reload", "rollback", "drivers", "activate", "recordings", "recording", "record", "schedule",
                "bench"],
           "token": ["create", "list", "revoke"], "board": ["enroll", "list", "remove"],
           "recording": ["get", "to-test"]}
FLAGS = {"--json", "--quiet", "--list", "--tap", "--local", "--replace", "--force", "--follow"}  # the options that take no value


def names_option(text, option):
    """Whether text names option as a whole word (--token, not --token-file)."""
    return re.search(r"(?<![\w-])%s(?![\w-])" % re.escape(option), text) is not None


# The sweeps below run vmac hundreds of times on the paths each command's
# first run took already: the sanitizer pass's leak scan at exit is left
# to that first run (harness.NO_LEAK_SCAN).


def vmac_run(t, words, env=None, stdin=None, leak_scan=True):
    """vmac WORDS with env as its only VMAC_* variables: (exit code, stdout,
    stderr). leak_scan False: no leak scan at its exit (NO_LEAK_SCAN)."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith("VMAC_")}
    p = subprocess.run([t.path("vmac")] + words, input=stdin, capture_output=True, text=True,
                       env=dict(clean, **(env or {}), **({} if leak_scan else NO_LEAK_SCAN)), timeout=EXIT_S)
    return p.returncode, p.stdout, p.stderr


def test_cli_every_command_has_help_naming_its_options(t):
    """vmac CMD --help exits 0 with a usage on stdout that names every option
    docs/CLI.md gives CMD, and each of them is taken: CMD OPTION [1] --help
    still exits 0 (an option it did not know would stop it with 2 first)."""
    problems = []
    for command, options in sorted(COMMANDS.items()):
        words = command.split()
        rc, out, err = vmac_run(t, words + ["--help"])
        if rc != 0 or not out.startswith("usage: vmac %s" % command):
            problems.append("'vmac %s --help' exited %d, printed %r %r" % (command, rc, out[:80], err[:200]))
            continue
        for option in options + ["--help"]:
            if not names_option(out, option):
                problems.append("'vmac %s --help' does not name %s" % (command, option))
        for option in options:
            given = [option] if option in FLAGS else [option, "1"]
            rc, out, err = vmac_run(t, words + given + ["--help"], leak_scan=False)
            if rc != 0:
                problems.append("'vmac %s %s --help' exited %d: %r" % (command, " ".join(given), rc, err.strip()))
    assert not problems, "\n".join(problems)


def test_cli_help_lists_every_command_and_action(t):
    """vmac --help, vmac token --help and vmac recording --help list exactly
    the commands and actions above (so a new one comes with its entry)."""
    for parent, expected in PARENTS.items():
        words = parent.split()
        rc, out, err = vmac_run(t, words + ["--help"])
        assert rc == 0, "'vmac %s --help' exited %d: %s" % (parent, rc, err)
        listed = re.findall(r"^  ([a-z][a-z-]*) ", out, re.M)
        assert listed == expected, "'vmac %s --help' lists %s, expected %s" % (parent, listed, expected)
        rc, out, err = vmac_run(t, words)
        assert rc == 2 and err.startswith("usage: "), "'vmac %s' alone: exit %d, stderr %r" % (parent, rc, err[:100])
        rc, out, err = vmac_run(t, words + ["nosuch"])
        assert rc == 2 and "'nosuch'" in err, "'vmac %s nosuch': exit %d, stderr %r" % (parent, rc, err)


def test_cli_unknown_options_and_missing_values_are_refused(t):
    """An option a command does not take, and an option without its value,
    stop it with exit code 2 and a message naming the command and the option."""
    problems = []
    for command, options in sorted(COMMANDS.items()):
        words = command.split()
        rc, out, err = vmac_run(t, words + ["--no-such-option"])
        if rc != 2 or "vmac %s" % command not in err or "--no-such-option" not in err:
            problems.append("'vmac %s --no-such-option': exit %d, stderr %r" % (command, rc, err.strip()))
        for option in options:
            if option in FLAGS:
                continue
            rc, out, err = vmac_run(t, words + [option], leak_scan=False)  # the value missing at the end
            if rc != 2 or not names_option(err, option) or "value" not in err:
                problems.append("'vmac %s %s' without a value: exit %d, stderr %r" % (command, option, rc,
                                                                                       err.strip()))
    rc, out, err = vmac_run(t, ["status", "--json=yes"])
    if rc != 2 or "--json" not in err:
        problems.append("'vmac status --json=yes': exit %d, stderr %r" % (rc, err.strip()))
    rc, out, err = vmac_run(t, ["status", "--tok", "x"])  # no abbreviations: --tok is not --token
    if rc != 2 or "--tok" not in err:
        problems.append("'vmac status --tok x': exit %d, stderr %r" % (rc, err.strip()))
    assert not problems, "\n".join(problems)


def test_cli_every_api_command_reaches_the_host_it_is_given(t):
    """Each command on the HTTP API goes to the host of --http, --host,
    --http=ADDR or $VMAC_HTTP (exit 1 and the address said when nothing
    listens there), and reads its token from --token-file or $VMAC_TOKEN_FILE
    (exit 2 naming the file when it cannot be read). docs/CLI.md, "Reaching a
    host", "Tokens"."""
    driver = os.path.join(t.logdir, "counter.lua")
    with open(driver, "w") as f:
        f.write('return { name = "counter", version = "1", io = {}, tick = function() end }\n')
    arguments = {"status": [], "events": [], "logs": [], "reload": [driver], "rollback": ["counter"],
                 "activate": ["counter", "2"], "drivers": [], "recordings": [], "recording get": ["1"],
                 "record": ["washer-1"], "schedule": [], "get": ["lights-1.tv"], "set": ["lights-1.tv:true"], "console": [],
                 "board enroll": ["lamp"], "board list": [], "board remove": ["lamp"]}
    assert sorted(arguments) == sorted(c for c, o in COMMANDS.items() if "--http" in o), (
        "a command that takes --http has no arguments here")
    closed = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    closed.bind(("127.0.0.1", 0))  # bound, never listening: connections are refused
    addr = "127.0.0.1:%d" % closed.getsockname()[1]
    missing = os.path.join(t.logdir, "no-such-token")
    problems = []
    try:
        for command, args in sorted(arguments.items()):
            words = command.split() + args
            for how, extra, env in (("--http", ["--http", addr], None), ("--host", ["--host", addr], None),
                                    ("--http=", ["--http=" + addr], None), ("$VMAC_HTTP", [], {"VMAC_HTTP": addr})):
                rc, out, err = vmac_run(t, words + extra, env, stdin="lights-1.tv?\n", leak_scan=how == "--http")
                if rc != 1 or addr not in err:
                    problems.append("vmac %s with the host in %s: exit %d, stderr %r" % (command, how, rc,
                                                                                          err.strip()[:200]))
            for how, extra, env in (("--token-file", ["--token-file", missing], None),
                                    ("$VMAC_TOKEN_FILE", [], {"VMAC_TOKEN_FILE": missing})):
                rc, out, err = vmac_run(t, words + ["--http", addr] + extra, env, stdin="lights-1.tv?\n",
                                        leak_scan=False)
                if rc != 2 or missing not in err:
                    problems.append("vmac %s with an unreadable %s: exit %d, stderr %r" % (command, how, rc,
                                                                                            err.strip()[:200]))
            rc, out, err = vmac_run(t, words + ["--http", addr, "--token", "x", "--token-file", missing],
                                    stdin="lights-1.tv?\n", leak_scan=False)
            if rc != 1:  # --token wins: the file is never read
                problems.append("vmac %s with --token and a missing --token-file: exit %d, stderr %r" % (
                    command, rc, err.strip()[:200]))
    finally:
        closed.close()
    assert not problems, "\n".join(problems)


def test_cli_token_commands_use_the_state_folder_they_are_given(t):
    """vmac token works on --state DIR, else $VMAC_STATE (docs/CLI.md)."""
    a, b = os.path.join(t.logdir, "state-a"), os.path.join(t.logdir, "state-b")
    rc, token, err = vmac_run(t, ["token", "create", "--scope", "read", "--note", "in-a", "--state", a])
    assert rc == 0 and token.startswith("vmac_"), "token create --state: exit %d, %r" % (rc, err)
    rc, out, err = vmac_run(t, ["token", "create", "--scope", "read", "--note", "in-b"], {"VMAC_STATE": b})
    assert rc == 0, "token create with $VMAC_STATE: exit %d, %r" % (rc, err)
    rc, out, err = vmac_run(t, ["token", "list"], {"VMAC_STATE": a})
    assert rc == 0 and "in-a" in out and "in-b" not in out, "token list with $VMAC_STATE=a: %d %r %r" % (rc, out, err)
    rc, out, err = vmac_run(t, ["token", "list", "--state", b], {"VMAC_STATE": a})
    assert rc == 0 and "in-b" in out and "in-a" not in out, "token list --state b: %d %r %r" % (rc, out, err)
    token_id = token.split("_")[1]
    rc, out, err = vmac_run(t, ["token", "revoke", token_id], {"VMAC_STATE": a})
    assert rc == 0 and "revoked" in err, "token revoke with $VMAC_STATE: exit %d, %r" % (rc, err)
