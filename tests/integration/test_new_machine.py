"""docs/NEW_MACHINE.md, followed as a new user follows it, so that the
page cannot rot: from an empty home folder to a dryer tested in virtual
time, run live against its Lua plant, seen through the host's API (what
the web UI's card is built from) and in Home Assistant's discovery
configs, changed and deployed while it runs, and stopped.

How this test reads the page (the page says so at its top too):

- Every fenced block whose info string is `sh` is run, as written and in
  the page's order, in one bash (so `cd`, `export`, background jobs and
  the descriptor a block opens carry over to the next), with the built
  programs first on PATH, HOME a fresh folder, and VMAC_HTTP, VMAC_BUS and
  VMAC_MQTT set to this test's own free port, bus and broker (the page's
  commands take them from the environment, with defaults for a user). A
  command of a block that fails (exit status not 0) fails the test, naming
  the block and the command.
- A line `<!-- file: PATH -->` right before a fenced block: the block is
  the whole of file PATH of the user's folder. It must be the kitchen's
  own, examples/kitchen/PATH, byte for byte, and is written at PATH in the
  shell's working folder when the page reaches it, as the user would.
- A line `<!-- output -->` right before a fenced block: what the `sh`
  block before it prints; each `  ok    NAME` line in it must name a test
  that passed in the real output, and its `N tests, 0 failed` must count
  them.
- Any other block (`console`, `text`, `lua` without a file line) is for
  people and is not run.

Between the blocks the test checks what the page says happens, by the
programs' own words (the host's status and events, the board's lines),
never by waiting a fixed time."""

import json
import os
import re
import socket
import time
import urllib.request

import test_mqtt as mqtt
import test_mqtt_ha as ha
from harness import LOADED, Proc, plain_pass_only, until

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PAGE = os.path.join(ROOT, "docs", "NEW_MACHINE.md")
KITCHEN = os.path.join(ROOT, "examples", "kitchen")
BLOCK_TIMEOUT_S = 240  # the longest block: vmac test of the whole test file, under a sanitizer too
FENCE = re.compile(r"^```(\S*)[^\n]*\n(.*?)^```[ \t]*$", re.M | re.S)


def page_blocks():
    """The page's fenced blocks in order: (kind, text, line, marker), kind
    the info string's first word, marker the `<!-- ... -->` line right
    before the block (or None)."""
    text = open(PAGE).read()
    blocks = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1].strip()
        marker = re.fullmatch(r"<!--\s*(.*?)\s*-->", before)
        blocks.append((m.group(1), m.group(2), text.count("\n", 0, m.start()) + 1,
                       marker.group(1) if marker else None))
    return blocks


class Shell:
    """One bash for the whole page: each block is sourced from a file of
    its own (so a failure names the block's file and line), then a line
    @@done N says it ended; the ERR trap prints @@failed for any command
    that exits non-zero."""

    def __init__(self, t, env):
        self.t = t
        self.proc = Proc(t._name("page-shell"), ["bash", "--norc", "--noprofile"], t.logdir, stdin=True, env=env)
        t.procs.append(self.proc)
        self.count = 0
        self.proc.send("set -E; trap 's=$?; echo \"@@failed ${BASH_SOURCE##*/}:$LINENO: $BASH_COMMAND "
                       "(exit $s)\"' ERR")

    def run(self, text, line, timeout_s=BLOCK_TIMEOUT_S):
        """Run one block; returns the lines it printed on stdout."""
        self.count += 1
        path = os.path.join(self.t.logdir, "page-block-%02d-line-%d.sh" % (self.count, line))
        with open(path, "w") as f:
            f.write(text)
        mark, err_mark = self.proc.mark(), self.proc.mark("stderr")
        self.proc.send("source %s; echo \"@@done %d\"" % (path, self.count))
        done = self.proc.wait_line(r"^@@done %d$" % self.count, timeout_s, since=mark,
                                   what="the end of the page's block at line %d" % line)
        lines = [l.text for l in self.proc.find_lines("", since=mark)[:done.index - mark]]
        failed = [l for l in lines if l.startswith("@@failed")]
        errors = [l.text for l in self.proc.find_lines("", since=err_mark, stream="stderr")]
        assert not failed, "NEW_MACHINE.md line %d: a command of the block failed: %s (stderr: %s)" % (
            line, failed[0][len("@@failed "):], " | ".join(errors[-5:]) or "none")
        return lines

    def cwd(self):
        mark = self.proc.mark()
        self.proc.send('echo "@@cwd $PWD"')
        return self.proc.wait_line(r"^@@cwd ", 30, since=mark, what="the shell's folder").text[len("@@cwd "):]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Live:
    """The live part's view: the host's API with the page's token, and the
    board's log file (the page sends the board's output there)."""

    def __init__(self, folder, http):
        self.folder, self.http = folder, http

    def token(self):
        with open(os.path.join(self.folder, "state", "token")) as f:
            return f.read().strip()

    def get(self, path):
        req = urllib.request.Request("http://%s%s" % (self.http, path))
        req.add_header("Authorization", "Bearer " + self.token())
        with urllib.request.urlopen(req, timeout=10) as r:
            return json.loads(r.read())

    def dryer(self):
        try:
            s = self.get("/api/status")
        except OSError:
            return None
        return next((d for d in s["devices"] if d["name"] == "dryer-1"), None)

    def wait(self, predicate, what, timeout_s=60):
        """The dryer's status once predicate(device) holds."""
        last = [None]

        def look():
            last[0] = self.dryer()
            return last[0] if last[0] is not None and predicate(last[0]) else None

        return until(look, timeout_s, lambda: "%s (the dryer: %s)" % (
            what, json.dumps(last[0])[:600] if last[0] else "not on the host"))

    def board_lines(self):
        try:
            with open(os.path.join(self.folder, "dryer-1.log")) as f:
                return f.read().splitlines()
        except OSError:
            return []

    def wait_board_line(self, pattern, since, what, timeout_s=60):
        """The index of the first line of the board's log at or after since
        that matches pattern."""
        regex = re.compile(pattern)
        lines = [[]]

        def look():
            lines[0] = self.board_lines()
            return next(([i] for i in range(since, len(lines[0])) if regex.search(lines[0][i])), None)

        return until(look, timeout_s, lambda: "dryer-1.log: a line %s (last lines: %s)" % (
            what, " | ".join(lines[0][-6:]) or "none"))[0]


def var(device, name):
    return device.get("variables", {}).get(name)


def check_vmac_test_output(out_block, printed, line):
    """The page's shown output of `vmac test` against what it printed."""
    shown = [re.sub(r"\s+\(.*\)$", "", l.strip()[len("ok"):].strip()) for l in out_block.splitlines()
             if l.startswith("  ok")]
    passed = [re.sub(r"\s+\(.*\)$", "", l.strip()[len("ok"):].strip()) for l in printed if l.startswith("  ok")]
    assert shown, "NEW_MACHINE.md line %d: the output block shows no passing test" % line
    missing = [n for n in shown if n not in passed]
    assert not missing, "NEW_MACHINE.md line %d shows tests that did not pass: %s (passed: %s)" % (
        line, missing, passed)
    summary = re.search(r"^(\d+) tests?, 0 failed", out_block, re.M)
    assert summary, "NEW_MACHINE.md line %d: the output block has no 'N tests, 0 failed' line" % line
    assert int(summary.group(1)) == len(passed), "NEW_MACHINE.md line %d says %s tests, %d passed" % (
        line, summary.group(1), len(passed))


def check_home_assistant(hub):
    """The dryer's discovery configs, as NEW_MACHINE.md lists them, and
    each as Home Assistant reads it (test_mqtt_ha's checkers)."""
    def config(component, obj):
        with hub.cond:
            topics = [tp for tp in hub.latest if re.fullmatch(
                r"homeassistant/%s/[^/]+_dryer-1/%s/config" % (component, obj), tp) and hub.latest[tp][0]]
        return topics

    deadline = time.monotonic() + 60 * LOADED  # a wait on a condition variable: until does not fit
    want = [("sensor", "temp_c"), ("binary_sensor", "heater"), ("binary_sensor", "drum"),
            ("binary_sensor", "door_open"), ("binary_sensor", "running"), ("select", "program"),
            ("button", "start"), ("button", "cancel"), ("sensor", "state"), ("sensor", "target_c")]
    with hub.cond:
        while True:
            found = {w: config(*w) for w in want}
            left = deadline - time.monotonic()
            if all(found.values()) or left <= 0:
                break
            hub.cond.wait(min(left, 0.5))
    missing = ["%s %s" % w for w, topics in found.items() if not topics]
    assert not missing, "Home Assistant: no discovery config for the dryer's %s" % ", ".join(missing)

    def load(w):
        return json.loads(hub.latest[found[w][0]][0])

    temp = load(("sensor", "temp_c"))
    assert temp.get("device_class") == "temperature" and temp.get("unit_of_measurement") == "°C", (
        "the dryer's temperature in HA: %r" % temp)
    for obj, cls in (("heater", "heat"), ("drum", "moving"), ("door_open", "door"), ("running", "running")):
        c = load(("binary_sensor", obj))
        assert c.get("device_class") == cls, "the dryer's %s in HA has device_class %r, the page says %r" % (
            obj, c.get("device_class"), cls)
    programmes = load(("select", "program"))
    assert programmes.get("options") == ["cotton", "delicate"], "the programmes in HA: %r" % programmes
    assert load(("button", "start"))["device"]["name"] == "dryer-1", "the start button's device"
    # Every config, by every rule of MQTT.md's "Conformance: Home Assistant".
    judged = [tp for tp in ha.check_all(hub) if "_dryer-1/" in tp]
    assert len(judged) >= len(want), "only %d of the dryer's configs judged: %s" % (len(judged), judged)


@plain_pass_only("the page's commands under the sanitizers: test-drivers runs its vmac test blocks (the dryer's "
                 "tests), test_kitchen_attaches its Lua plant behind a live board, test_reload a reload")
def test_new_machine_page(t):
    blocks = page_blocks()
    assert any(k == "sh" for k, _, _, _ in blocks), "NEW_MACHINE.md has no sh block"
    home = os.path.join(t.logdir, "home")
    os.makedirs(home)
    broker = mqtt.Broker(t)
    hub = mqtt.Hub(broker, "new-machine")
    t.cleanups.append(hub.close)
    http = "127.0.0.1:%d" % free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("VMAC_")}
    env.update(PATH=os.path.abspath(t.bindir) + os.pathsep + env.get("PATH", ""), HOME=home, VMAC_HTTP=http,
               VMAC_BUS=t.bus, VMAC_MQTT=broker.url)
    shell = Shell(t, env)
    live, last_output, files = None, None, []
    for kind, text, line, marker in blocks:
        if marker and marker.startswith("file:"):
            rel = marker[len("file:"):].strip()
            with open(os.path.join(KITCHEN, rel)) as f:
                assert f.read() == text, ("NEW_MACHINE.md line %d: %s is not examples/kitchen/%s: make the page "
                                          "show the kitchen's file as it is" % (line, rel, rel))
            path = os.path.join(shell.cwd(), rel)
            with open(path, "w") as f:
                f.write(text)
            files.append(rel)
            continue
        if marker == "output":
            assert last_output is not None, "NEW_MACHINE.md line %d: an output block after no sh block" % line
            check_vmac_test_output(text, last_output, line)
            continue
        if kind != "sh":
            continue
        printed = shell.run(text, line)
        last_output = printed
        if "vmac-board --plant-file" in text:
            live = Live(shell.cwd(), http)
            attached(live)
            check_home_assistant(hub)
        elif live is None:
            continue
        elif re.search(r"^vmac status$", text, re.M):
            row = [l for l in printed if l.split()[:1] == ["dryer-1"]]
            assert row and row[0].split()[1:4] == ["dryer", "1.0.0", "running"], (
                "vmac status on the page's host: %s" % (row or printed))
        elif "dryer-1 start 1" in text:
            heats(live)
        elif "dryer-1 door 0" in text:
            door_opened(live)
        elif "dryer-1 door 1" in text:
            live.wait(lambda d: var(d, "state") == "running", "the programme going on with the door closed")
        elif "#token=" in text:
            web_ui(live, printed)
        elif "vmac reload" in text:
            deployed(live, printed)
        elif "kill $(jobs -p)" in text:
            stopped(live)
    assert sorted(files) == sorted(["dryer.lua", "cycles/dryer/cotton.lua", "cycles/dryer/delicate.lua",
                                    "plants/dryer.lua", "tests/dryer_test.lua"]), (
        "NEW_MACHINE.md shows the files %s, not the kitchen's five" % files)
    assert live is not None, "NEW_MACHINE.md never started the board (vmac-board --plant-file)"


def attached(live):
    """The host attaches the dryer board and loads the user's driver."""
    d = live.wait(lambda d: d["state"] == "running" and var(d, "state") == "idle", "dryer-1 running its driver")
    assert d["driver"] == "dryer" and d["driver_version"] == "1.0.0", "dryer-1 runs %s %s" % (
        d["driver"], d["driver_version"])
    live.wait_board_line(r"^dryer-1: state known ", 0, "'state known'")
    assert var(d, "temp_c") is not None and abs(var(d, "temp_c") - 20) < 1, (
        "the plant at rest reads %r C" % var(d, "temp_c"))


def heats(live):
    """The start button starts cotton; the drum turns, the heater comes on
    (the board's outputs) and the air warms (the plant, through its sensor)."""
    live.wait(lambda d: var(d, "state") == "running" and var(d, "cycle") == "cotton", "cotton running")
    start = live.wait(lambda d: var(d, "step") == "warm up", "the warm-up")
    live.wait_board_line(r"^dryer-1: outputs digital=0x03 ", 0, "with the heater and the drum on (0x03)")
    warm = live.wait(lambda d: (var(d, "temp_c") or 0) > 23, "the air warming past 23 C")
    assert var(warm, "temp_c") > var(start, "temp_c"), "the temperature did not rise: %r then %r" % (
        var(start, "temp_c"), var(warm, "temp_c"))


def door_opened(live):
    """The driver turns the heater and the drum off (the board's outputs)
    and the programme pauses, saying why."""
    lines = live.board_lines()
    since = next((i for i in range(len(lines) - 1, -1, -1) if lines[i].startswith("dryer-1: door 0")), None)
    if since is None:
        since = live.wait_board_line(r"^dryer-1: door 0", 0, "'door 0' taken")
    live.wait_board_line(r"^dryer-1: outputs digital=0x00 ", since, "with everything off after the door opened")
    d = live.wait(lambda d: var(d, "paused_by") == "door open", "the programme paused by the door")
    assert var(d, "state") == "paused" and var(d, "door_open") is True, "the dryer with its door open: %r" % (
        d.get("variables"))
    d = live.wait(lambda d: d["outputs"]["digital"][0] == 0 and d["outputs"]["digital"][1] == 0,
                  "the host's status with the heater and drum off")
    assert var(d, "heater") is False, "the heater variable with the door open: %r" % var(d, "heater")


def web_ui(live, printed):
    """The page's address signs in to the web UI, whose card for the dryer
    is built from the driver's manifest (its ui block) and the status."""
    url = next((l for l in printed if l.startswith("http://")), None)
    assert url and url == "http://%s/#token=%s" % (live.http, live.token()), "the printed address: %r" % printed
    with urllib.request.urlopen("http://%s/" % live.http, timeout=10) as r:
        assert r.status == 200 and b"<html" in r.read().lower(), "the web UI's page did not load"
    d = live.dryer()
    manifest = live.get("/api/drivers/dryer/manifest?version=%s" % d["driver_version"])
    ui = manifest.get("ui", {})
    assert ui.get("title") == "Dryer", "the card's title from the manifest: %r" % ui
    assert ["temp_c", "target_c"] in ui.get("plots", []), "the card's plots: %r" % ui.get("plots")


def deployed(live, printed):
    """vmac reload switched the running dryer to 1.0.1, the programme going on."""
    assert any("switched" in l and "dryer-1" in l for l in printed), "vmac reload did not switch dryer-1: %s" % (
        printed)
    d = live.wait(lambda d: d["driver_version"] == "1.0.1", "dryer-1 on 1.0.1")
    assert var(d, "state") in ("running", "paused"), "the programme after the reload: %r" % var(d, "state")
    assert var(d, "cycle") == "cotton", "the programme after the reload: %r" % var(d, "cycle")


def stopped(live):
    """The host told the board to go safe as it stopped; the board ended
    with its outputs off, and its plant never saw an unsafe moment."""
    lines = live.board_lines()
    assert any(l.startswith("dryer-1: state unknown ") for l in lines), "the board never went safe: %s" % (
        lines[-6:])
    outputs = [l for l in lines if l.startswith("dryer-1: outputs ")]
    assert outputs and "digital=0x00 pwm=0" in outputs[-1], "the board ended with %r" % (outputs[-1:])
    unsafe = [l for l in lines if "UNSAFE" in l]
    assert not unsafe, "the dryer's plant saw an unsafe moment live: %s" % unsafe
