"""`vmac bundle` and `vmac bundle show` as a user runs them, no host
(docs/CLI.md "vmac bundle", docs/DRIVERS.md "Bundles"): the same driver
bundled twice gives the same bytes, a POSIX tar that `tar tf` lists with
bundle.json first and each file's hash as BLAKE2b-256 of its bytes; the
default file name is NAME-VERSION.vbundle in the working folder; --counter
shows in `vmac bundle show --json`; a damaged bundle and a driver or a
programme that does not compile exit 1 naming the file (and line); wrong
usage exits 2; --help exits 0 naming every option."""
import hashlib
import json
import os
import re
import shutil
import subprocess
import tarfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WASHER = os.path.join(ROOT, "scripts", "drivers", "washer.lua")
WASHER_PROGRAMMES = sorted(f for f in os.listdir(os.path.join(ROOT, "scripts", "cycles", "washer"))
                           if f.endswith(".lua"))

LAMP = """local programmes = vmac.cycles()
local driver = {
	name = "lamp",
	version = "2.1.0",
	level = 3,
	io = { relay = "do0" },
	variables = { mode = {} },
}

function driver.tick(dev, inputs)
	dev.vars.mode = programmes.mode
	dev.out.relay = true
end

return driver
"""


def vmac(t, *argv, cwd=None):
    """build/bin/vmac with argv (in folder cwd): (exit, stdout, stderr)."""
    p = subprocess.run([t.path("vmac")] + list(argv), capture_output=True, text=True, timeout=60, cwd=cwd)
    return p.returncode, p.stdout, p.stderr


def make(t, *argv, cwd=None):
    """vmac bundle argv, which must succeed: its stdout."""
    rc, out, err = vmac(t, "bundle", *argv, cwd=cwd)
    assert rc == 0, "vmac bundle %s exited %d: %s%s" % (" ".join(argv), rc, out, err)
    return out


def read(path):
    with open(path, "rb") as f:
        return f.read()


def lamp_folder(t, programme):
    """A drivers folder holding lamp.lua and its programme cycles/lamp/mode.lua
    of text programme; its path."""
    path = os.path.join(t.logdir, "lamp-drivers")
    shutil.rmtree(path, ignore_errors=True)
    os.makedirs(os.path.join(path, "cycles", "lamp"))
    with open(os.path.join(path, "lamp.lua"), "w") as f:
        f.write(LAMP)
    with open(os.path.join(path, "cycles", "lamp", "mode.lua"), "w") as f:
        f.write(programme)
    return path


def test_bundle_cli_twice_gives_the_same_bytes_and_tar_lists_it(t):
    first, second = os.path.join(t.logdir, "first.vbundle"), os.path.join(t.logdir, "second.vbundle")
    out = make(t, WASHER, "-o", first)
    make(t, WASHER, "-o", second)
    assert read(first) == read(second), "the washer bundled twice gives different bytes"
    m = re.match(r"washer (\S+), counter 0, (\d+) files, (\d+) bytes: (.*)\n", out)
    assert m, "vmac bundle does not say what it made: %r" % out
    assert int(m.group(2)) == 1 + len(WASHER_PROGRAMMES) and int(m.group(3)) == len(read(first)) and \
        m.group(4) == first, "vmac bundle's line disagrees with the file: %r" % out
    sign = 'minisign -S -s KEY -m %s -t "vmac-bundle name=washer version=%s counter=0"' % (first, m.group(1))
    assert sign in out, "vmac bundle does not print the signing command %r: %r" % (sign, out)
    p = subprocess.run(["tar", "tf", first], capture_output=True, text=True, timeout=30)
    assert p.returncode == 0, "tar tf failed on a bundle: %s" % p.stderr
    want = ["bundle.json"] + ["cycles/" + f for f in WASHER_PROGRAMMES] + ["washer.lua"]
    assert p.stdout.split() == want, "tar tf lists %r, not %r" % (p.stdout.split(), want)


def test_bundle_cli_default_name_is_name_version_in_the_working_folder(t):
    work = os.path.join(t.logdir, "work")
    os.makedirs(work)
    out = make(t, WASHER, cwd=work)
    version = re.match(r"washer (\S+),", out).group(1)
    name = "washer-%s.vbundle" % version
    assert os.listdir(work) == [name], "vmac bundle wrote %r in the working folder, not %s" % (os.listdir(work), name)
    assert out.rstrip("\n").split("\n")[0].endswith(": " + name), "vmac bundle names another file: %r" % out
    other = os.path.join(t.logdir, "other.vbundle")
    make(t, WASHER, "-o", other)
    assert read(other) == read(os.path.join(work, name)), "the working folder changes the bundle's bytes"


def test_bundle_cli_counter_shows_in_show_json_with_each_files_hash(t):
    path = os.path.join(t.logdir, "washer.vbundle")
    make(t, WASHER, "--counter", "7", "-o", path)
    rc, out, err = vmac(t, "bundle", "show", path, "--json")
    assert rc == 0, "vmac bundle show --json exited %d: %s" % (rc, err)
    shown = json.loads(out)
    assert shown["counter"] == 7 and shown["name"] == "washer", "show --json: %r" % shown
    assert shown["size"] == len(read(path)), "show --json gives size %r, the file has %d" % (
        shown["size"], len(read(path)))
    assert shown["hash"] == hashlib.blake2b(read(path), digest_size=32).hexdigest(), (
        "the bundle's hash in show --json is not BLAKE2b-256 of its bytes")
    with tarfile.open(path) as tar:
        meta = json.load(tar.extractfile("bundle.json"))
        assert meta["counter"] == 7, "bundle.json says counter %r" % meta["counter"]
        for f in shown["files"]:
            data = tar.extractfile(f["path"]).read()
            assert f["size"] == len(data) and f["hash"] == hashlib.blake2b(data, digest_size=32).hexdigest(), (
                "%s: size or hash in show --json is not its bytes'" % f["path"])
            assert meta["files"][f["path"]] == f["hash"], "%s: bundle.json lists another hash" % f["path"]
    rc, out, err = vmac(t, "bundle", "show", path)
    assert rc == 0 and "washer %s, counter 7" % shown["version"] in out, "vmac bundle show: %s%s" % (out, err)


def test_bundle_cli_show_of_a_damaged_bundle_names_the_file_that_does_not_match(t):
    path = os.path.join(t.logdir, "washer.vbundle")
    make(t, WASHER, "-o", path)
    member = "cycles/" + WASHER_PROGRAMMES[0]
    with tarfile.open(path) as tar:
        at = tar.getmember(member).offset_data
    data = bytearray(read(path))
    data[at] ^= 0x20
    damaged = os.path.join(t.logdir, "damaged.vbundle")
    with open(damaged, "wb") as f:
        f.write(data)
    rc, out, err = vmac(t, "bundle", "show", damaged)
    assert rc == 1, "vmac bundle show of a damaged bundle exited %d: %s%s" % (rc, out, err)
    assert damaged in err and "%s does not match its hash" % member in err, (
        "the refusal does not name the bundle and %s: %r" % (member, err))
    with open(damaged, "ab") as f:
        f.write(b"more")
    rc, out, err = vmac(t, "bundle", "show", damaged)
    assert rc == 1 and "damaged" in err, "a bundle with bytes after its end: %d %s" % (rc, err)


def test_bundle_cli_a_driver_or_programme_that_does_not_compile_is_refused_with_its_line(t):
    out_file = os.path.join(t.logdir, "lamp.vbundle")
    folder = lamp_folder(t, 'return "one"\n')
    assert make(t, folder, "-o", out_file).startswith("lamp 2.1.0, counter 0, 2 files"), "the good lamp"
    os.remove(out_file)
    folder = lamp_folder(t, "return {\n  steps = ,\n}\n")
    rc, out, err = vmac(t, "bundle", folder, "-o", out_file)
    assert rc == 1, "a programme that does not compile was bundled (exit %d): %s" % (rc, out)
    assert "mode.lua:2:" in err, "the refusal does not name mode.lua line 2: %r" % err
    with open(os.path.join(folder, "lamp.lua"), "w") as f:
        f.write(LAMP.replace('version = "2.1.0",', 'version = "2.1.0" +'))
    rc, out, err = vmac(t, "bundle", folder, "-o", out_file)
    assert rc == 1, "a driver that does not compile was bundled (exit %d): %s" % (rc, out)
    assert "lamp.lua:5:" in err, "the refusal does not name lamp.lua line 5: %r" % err
    assert not os.path.exists(out_file), "a refused bundle was written all the same"


def test_bundle_cli_wrong_usage_exits_2(t):
    cases = [
        ([], "expected a folder or driver file"),
        (["show"], "vmac bundle show FILE"),
        ([WASHER, "--counter", "-1"], "--counter must be a whole number"),
        ([WASHER, "--counter", "seven"], "--counter must be a whole number"),
        ([WASHER, "--keys", "deploy_keys"], "--keys is for vmac bundle show"),
        ([WASHER, WASHER], "one folder or driver file"),
        (["show", "a.vbundle", "b.vbundle"], "unexpected argument"),
        ([WASHER, "--colour"], "--colour"),
    ]
    problems = []
    for argv, says in cases:
        rc, out, err = vmac(t, "bundle", *argv, cwd=t.logdir)
        if rc != 2 or says not in err:
            problems.append("vmac bundle %s: exit %d (not 2), stderr %r (not saying %r)" % (
                " ".join(argv), rc, err.strip(), says))
    assert not problems, "; ".join(problems)
    assert not [f for f in os.listdir(t.logdir) if f.endswith(".vbundle")], "wrong usage wrote a bundle"


def test_bundle_cli_help_names_the_options(t):
    rc, out, err = vmac(t, "bundle", "--help")
    assert rc == 0, "vmac bundle --help exited %d: %s" % (rc, err)
    missing = [w for w in ("-o, --output FILE", "--counter N", "--keys FILE", "--json", "show FILE")
               if w not in out]
    assert not missing, "vmac bundle --help does not name %r: %s" % (missing, out)
