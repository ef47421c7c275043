"""The sandbox escape corpus (tests/escape/): every attempt to get out of the
driver sandbox, or to stall or crash the host from a driver, fails for its
own reason, its board never switches an output on, the host lives, and a
neighbouring device misses nothing. Attempts with a '-- trigger:' line run
when the test does what it names: an operator's input, a hot reload of the
running driver, an upload of the file (compiled on an HTTP thread), or the
host stopping (detach)."""

import glob
import json
import os
import re
import shutil
import signal
import subprocess
import urllib.error
import urllib.request

from harness import undisturbed

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "..", "escape")


def corpus(t):
    """Copy the corpus to the test's drivers folder, add the bytecode case;
    returns (folder, {name: expected regex})."""
    path = os.path.join(t.logdir, "drivers")
    os.makedirs(path)
    expected, triggers = {}, {}
    for f in sorted(glob.glob(os.path.join(CORPUS, "*.lua"))):
        name = os.path.splitext(os.path.basename(f))[0]
        with open(f) as src:
            text = src.read()
        m = re.search(r"^-- expect: (.+)$", text, re.M)
        assert m, "%s has no '-- expect:' line" % f
        trigger = re.search(r"^-- trigger: (.+)$", text, re.M)
        if trigger:
            triggers[name] = trigger.group(1).split()
            assert triggers[name][0] in ("input", "reload", "upload", "stop"), "%s: unknown trigger" % f
        expected[name] = m.group(1).strip()
        shutil.copy(f, path)
    # A driver file that is bytecode: refused before it runs.
    plain = os.path.join(t.logdir, "bytecode_driver.src.lua")
    with open(plain, "w") as f:
        f.write('return { name = "bytecode_driver", version = "1", io = {}, tick = function() end }\n')
    subprocess.run(["luajit", "-b", plain, os.path.join(path, "bytecode_driver.lua")], check=True)
    expected["bytecode_driver"] = r"binary|bytecode|unexpected symbol|attempt to load"
    assert len(expected) >= 25, "the corpus has only %d attempts" % len(expected)
    return path, expected, triggers


def call(host, method, path, token, data, content_type):
    """(HTTP status, the answer's text)."""
    req = urllib.request.Request("http://%s%s" % (host.http, path), data=data, method=method)
    req.add_header("Content-Type", content_type)
    req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def failure_events(host, name):
    return [e for e in host.events.values()
            if e["device"] == "esc-" + name and e["kind"] in ("driver_error", "dropped")]


def test_escape_corpus(t):
    drivers, expected, triggers = corpus(t)
    # The drivers that must fail at their memory cap get the smallest cap and
    # time to reach it, so that a loaded machine (a sanitizer build, tests in
    # parallel) does not stop them on their time budget first.
    settings = {}
    for name in expected:
        if "memory" in expected[name] or name.startswith("creep_"):
            settings.update({"driver.%s.memory_kib" % name: "64", "driver.%s.budget_us" % name: "20000",
                             "driver.%s.instructions" % name: "20000000"})
    host = t.host(drivers=drivers, settings=settings)
    neighbour = t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    on_board = [n for n in expected if triggers.get(n, [""])[0] != "upload"]
    t.enroll(["esc-" + name for name in on_board])  # in one run of vmac, not one a board
    boards = {name: t.board("generic", "esc-" + name, driver=name) for name in on_board}
    wrong = []

    # The triggered attempts, each once its board runs.
    for name, trigger in sorted(triggers.items()):
        with open(os.path.join(drivers, name + ".lua"), "rb") as f:
            source = f.read()
        if trigger[0] == "upload":
            code, text = call(host, "POST", "/api/drivers/" + name, t.token, source, "text/x-lua")
        else:
            host.wait_running(["esc-" + name], 30, undisturbed(["lights-1"]))
        if trigger[0] == "input":
            code, text = call(host, "POST", "/api/devices/esc-%s/input" % name, t.token,
                              json.dumps({"name": trigger[1], "value": True}).encode(), "application/json")
        elif trigger[0] == "reload":  # the same version again, in other bytes (the same ones are no change)
            code, text = call(host, "POST", "/api/drivers/%s?force=1" % name, t.token,
                              source + b"\n-- reloaded\n", "text/x-lua")
        if trigger[0] in ("upload", "reload"):
            if code < 400 or not re.search(expected[name], text):
                wrong.append("%s: expected a refusal matching /%s/, got %d %s" % (name, expected[name], code,
                                                                                  text[:300]))
    must_fail = [n for n in on_board if triggers.get(n, [""])[0] not in ("reload", "stop")]

    def all_failed(s):
        return all(any(e["kind"] == "driver_error" for e in failure_events(host, n)) for n in must_fail)

    host.wait_status(all_failed, 120, "a driver_error from every attempt", undisturbed(["lights-1"]))
    for name in sorted(must_fail):
        pattern = expected[name]
        texts = [e["text"] for e in failure_events(host, name) if e["kind"] == "driver_error"]
        if not any(re.search(pattern, text) for text in texts):
            wrong.append("%s: expected /%s/, got %r" % (name, pattern, texts[0][:300]))
    assert not wrong, "attempts that failed for the wrong reason:\n  " + "\n  ".join(wrong)
    for name, board in boards.items():
        # The drivers that set an output before failing may show it once the
        # board has applied it; none may be left on.
        if triggers.get(name, [""])[0] in ("reload", "stop"):
            continue  # still running: checked when the host stops
        lines = board.find_lines(r"outputs digital=")
        assert not lines or "digital=0x00 pwm=0" in lines[-1].text, (
            "esc-%s left an output on: %s" % (name, lines[-1].text))
    assert host.alive(), "vmacd died during the escape corpus"
    assert neighbour.alive(), "the neighbouring board died"
    undisturbed(["lights-1"])(host.status())

    # Stopping the host runs detach on every machine still attached (one
    # creeps there): the host still stops cleanly and every board goes safe.
    host.signal(signal.SIGTERM)
    rc = host.wait_exit(30)
    assert rc == 0, "vmacd exited with %r when stopped after the corpus: %s" % (rc, host.text()[-600:])
    for name in [n for n in on_board if triggers.get(n, [""])[0] in ("reload", "stop")]:
        boards[name].wait_line(r"^esc-%s: state (unknown|sleeping) " % name, 10,
                               what="esc-%s told to go safe" % name)
