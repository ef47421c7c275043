"""The sandbox escape corpus (tests/escape/): every attempt to get out of the
driver sandbox, or to stall or crash the host from a driver, fails for its
own reason, its board never switches an output on, the host lives, and a
neighbouring device misses nothing."""

import glob
import os
import re
import shutil
import subprocess

from harness import undisturbed

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "..", "escape")


def corpus(t):
    """Copy the corpus to the test's drivers folder, add the bytecode case;
    returns (folder, {name: expected regex})."""
    path = os.path.join(t.logdir, "drivers")
    os.makedirs(path)
    expected = {}
    for f in sorted(glob.glob(os.path.join(CORPUS, "*.lua"))):
        name = os.path.splitext(os.path.basename(f))[0]
        with open(f) as src:
            text = src.read()
        m = re.search(r"^-- expect: (.+)$", text, re.M)
        assert m, "%s has no '-- expect:' line" % f
        expected[name] = m.group(1).strip()
        shutil.copy(f, path)
    # A driver file that is bytecode: refused before it runs.
    plain = os.path.join(t.logdir, "bytecode_driver.src.lua")
    with open(plain, "w") as f:
        f.write('return { name = "bytecode_driver", version = "1", io = {}, tick = function() end }\n')
    subprocess.run(["luajit", "-b", plain, os.path.join(path, "bytecode_driver.lua")], check=True)
    expected["bytecode_driver"] = r"binary|bytecode|unexpected symbol|attempt to load"
    assert len(expected) >= 25, "the corpus has only %d attempts" % len(expected)
    return path, expected


def failure_events(host, name):
    return [e for e in host.events.values()
            if e["device"] == "esc-" + name and e["kind"] in ("driver_error", "dropped")]


def test_escape_corpus(t):
    drivers, expected = corpus(t)
    host = t.host(drivers=drivers)
    neighbour = t.board("lights", "lights-1")
    host.wait_running(["lights-1"])
    boards = {name: t.board("generic", "esc-" + name, driver=name) for name in expected}

    def all_failed(s):
        return all(any(e["kind"] == "driver_error" for e in failure_events(host, n)) for n in expected)

    host.wait_status(all_failed, 120, "a driver_error from every attempt", undisturbed(["lights-1"]))
    wrong = []
    for name, pattern in sorted(expected.items()):
        texts = [e["text"] for e in failure_events(host, name) if e["kind"] == "driver_error"]
        if not any(re.search(pattern, text) for text in texts):
            wrong.append("%s: expected /%s/, got %r" % (name, pattern, texts[0][:300]))
    assert not wrong, "attempts that failed for the wrong reason:\n  " + "\n  ".join(wrong)
    for name, board in boards.items():
        # The drivers that set an output before failing may show it once the
        # board has applied it; none may be left on.
        lines = board.find_lines(r"outputs digital=")
        assert not lines or "digital=0x00 pwm=0" in lines[-1].text, (
            "esc-%s left an output on: %s" % (name, lines[-1].text))
    assert host.alive(), "vmacd died during the escape corpus"
    assert neighbour.alive(), "the neighbouring board died"
    undisturbed(["lights-1"])(host.status())
