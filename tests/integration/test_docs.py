"""The docs against the tree they describe, so that they cannot drift where
it matters: every path and file they name exists, every section another
file points at is there, every function they call by name is in the
source, the counts README states are the code's, the escape corpus's table
lists exactly its files, and every module has its row in README's "What
is here" and its place in ARCHITECTURE.md. A failure says which file and
line to fix.

It reads files and runs no program, so it also runs alone, in well under
a second:

    python3 tests/integration/test_docs.py"""

import glob
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOCS = ["README.md"] + sorted("docs/" + f for f in os.listdir(os.path.join(ROOT, "docs")) if f.endswith(".md"))
NUMBER_WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7, "eight": 8,
                "nine": 9, "ten": 10, "eleven": 11, "twelve": 12}

# Paths the docs name that are not meant to exist: examples of files a
# reader would add.
EXAMPLES = {
    "scripts/cycles/washer/wool.lua": "KITCHEN.md: a programme to add",
    "tests/drivers/washer_drop_test.lua": "RECORDING.md: a test made of a recording",
    "tests/blinker_test.lua": "TESTING.md: a test in a folder of one's own",
    "tests/dryer_test.lua": "NEW_MACHINE.md: the test in a user's own folder (examples/kitchen/tests/)",
}

# Section references known to be wrong, each with the fix it needs
# ((file, doc, title): the reference to write instead); an entry goes when
# its file is fixed.
PENDING = {}

# The numbers README states, each beside the code that makes it true:
# (what it counts, README's words with the number as group 1, the file
# that sets it, the setting with its value as group 1). README is read
# with its line breaks as spaces.
COUNTS = [
    ("random sequences of the scheduler's property test", r"and ([\d,]+) random sequences",
     "tests/unit/test_sched.c", r'env_number\("VMAC_SCHED_PROPERTY_RUNS", (\d+)\)'),
    ("seconds of libFuzzer per parser in make test", r"libFuzzer over every parser, (\d+) s each",
     "tests/fuzz/fuzz.mk", r"^FUZZ_TEST_SECONDS \?= (\d+)"),
    ("malformed datagrams", r"([\d,]+) malformed datagrams",
     "tests/integration/test_malformed.py", r"^TOTAL = (\d+)"),
    ("kills of the store during writes", r"`kill -9` ([\d,]+) times during writes",
     "tests/integration/test_store.py", r"^RUNS = (\d+)"),
    ("host crashes during a wash", r"running wash ([\d,]+) times",
     "tests/integration/test_recovery.py", r"^TRIALS = (\d+)"),
    ("kills of the store under ASan", r"kill test with (\d+) kills",
     "tests/integration/test_store.py", r"^SANITIZED_RUNS = (\d+)"),
    ("kills of the store (the ASan line)", r"kills instead of (\d+)",
     "tests/integration/test_store.py", r"^RUNS = (\d+)"),
    ("host crashes during a wash under ASan", r"host-crash test with (\d+) trials",
     "tests/integration/test_recovery.py", r"^SANITIZED_TRIALS = (\d+)"),
    ("host crashes during a wash (the ASan line)", r"trials instead of (\d+)\)",
     "tests/integration/test_recovery.py", r"^TRIALS = (\d+)"),
    ("integration tests at a time", r"The integration tests run (\w+) at a time",
     "tests/integration/run.py", r'"VMAC_TEST_JOBS", "(\d+)"'),
    ("seconds of a hot reload's probation", r"A version that fails within (\d+) s is rolled back",
     "core/config/config.c", r"reload_probation_s = (\d+);"),
    ("minutes of the soak in make test", r"The (\d+)-minute soak",
     "Makefile", r"soak SOAK_MINUTES=(\d+)"),
]


def read(rel):
    with open(os.path.join(ROOT, rel), errors="replace") as f:
        return f.read()


def line_of(text, pos):
    return text.count("\n", 0, pos) + 1


def tracked_files():
    """Every file of the repository (git's list; else a walk of the tree
    without build/, .git, node_modules and __pycache__)."""
    try:
        out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
        files = [f for f in out.splitlines() if os.path.exists(os.path.join(ROOT, f))]
        if files:
            return files
    except (OSError, subprocess.CalledProcessError):
        pass
    files = []
    for top, dirs, names in os.walk(ROOT):
        dirs[:] = [d for d in dirs if d not in ("build", ".git", "node_modules", "__pycache__")]
        files += [os.path.relpath(os.path.join(top, n), ROOT) for n in names]
    return files


FILES = tracked_files()
BASENAMES = {os.path.basename(f) for f in FILES}
# Text the project wrote: not the fuzzers' corpora and lock files (data),
# nor this file (its patterns and examples name no real thing).
TEXT_FILES = [f for f in FILES if not re.search(r"(^|/)corpus-|package-lock\.json$|\.(png|dict|rec|vrec)$", f)
              and f != "tests/integration/test_docs.py"]
SOURCE_EXT = (".c", ".h", ".lua", ".py", ".sh", ".js", ".mk", ".proto")


def is_placeholder(path):
    """A path with a stand-in for a name: NAME, DRIVER, X, ID... (a run of
    capitals between non-letters). A doc (README.md) is never one."""
    return not path.endswith(".md") and bool(re.search(r"(^|[^A-Za-z])[A-Z]+([^A-Za-z]|$)", path))


def path_exists(path):
    full = os.path.join(ROOT, path)
    if any(c in path for c in "*?["):
        return bool(glob.glob(full))
    return os.path.exists(full)


def failures_message(what, failures):
    return "%s:\n  %s" % (what, "\n  ".join(failures))


def test_every_path_the_docs_and_comments_name_exists(t=None):
    """core/..., firmware/..., tests/..., scripts/..., stdlib/... and
    docs/... wherever the project's own text names them (docs, README,
    source comments, make fragments), and every Markdown link."""
    failures = []
    path_re = re.compile(r"(?<![\w./$%{-])((?:core|firmware|tests|scripts|stdlib|docs)/[\w./*-]*[\w/*])(?![-\w]*[$%{])")
    for rel in TEXT_FILES:
        text = read(rel)
        for m in path_re.finditer(text):
            path = m.group(1)
            if path in EXAMPLES or path_exists(path) or is_placeholder(path):
                continue
            failures.append("%s:%d: `%s` does not exist" % (rel, line_of(text, m.start()), path))
    for rel in DOCS + [f for f in FILES if f.endswith("README.md")]:
        text = read(rel)
        for m in re.finditer(r"\]\(([^)#\s]+)(#[^)]*)?\)", text):
            target = m.group(1)
            if re.match(r"[a-z]+:", target):
                continue
            if not os.path.exists(os.path.join(ROOT, os.path.dirname(rel), target)):
                failures.append("%s:%d: the link to %s leads nowhere" % (rel, line_of(text, m.start()), target))
    assert not failures, failures_message("paths that do not exist", failures)


def test_every_doc_named_exists(t=None):
    """A doc named by its file name (DRIVERS.md, docs/HOST.md) anywhere in
    the project's text is in docs/ (or beside the file naming it)."""
    failures = []
    for rel in TEXT_FILES:
        text = read(rel)
        for m in re.finditer(r"(?<![\w/.-])(?:docs/)?([A-Z][A-Z_]+\.md)\b", text):
            name = m.group(1)
            if not (os.path.exists(os.path.join(ROOT, "docs", name)) or
                    os.path.exists(os.path.join(ROOT, os.path.dirname(rel), name)) or name == "README.md"):
                failures.append("%s:%d: %s is not in docs/" % (rel, line_of(text, m.start()), name))
    assert not failures, failures_message("docs that do not exist", failures)


def norm(text):
    return re.sub(r"\s+", " ", text.replace("`", "")).strip().lower()


def anchors(rel):
    """What a reference "Title" may name in a doc: its headings, its bold
    phrases (a bullet's title) and the first cells of its tables."""
    text = read(rel)
    found = [norm(re.sub(r"^#+\s*", "", line)) for line in text.splitlines() if line.startswith("#")]
    found += [norm(m.group(1)) for m in re.finditer(r"\*\*([^*]+)\*\*", text)]
    found += [norm(m.group(1)) for m in re.finditer(r"^\|\s*([^|]+?)\s*\|", text, re.M)]
    return found


def test_every_section_pointed_at_is_there(t=None):
    """`DOC.md, "Title"` (or `DOC.md "Title"`) names a heading, a bullet's
    bold title or a table row of DOC.md that begins with Title."""
    targets = {os.path.basename(rel): anchors(rel) for rel in DOCS}
    ref_re = re.compile(r"\b([A-Z][A-Z_]+\.md)\)?,?[ \t]*(?:\n[\s*#/-]*)?\(?\"([^\"\n]+)\"")
    failures = []
    for rel in TEXT_FILES:
        text = read(rel)
        for m in ref_re.finditer(text):
            doc, title = m.group(1), m.group(2)
            if doc not in targets or any(a.startswith(norm(title)) for a in targets[doc]):
                continue
            if (rel, doc, title) in PENDING:
                continue
            failures.append('%s:%d: %s has no section "%s"' % (rel, line_of(text, m.start()), doc, title))
    assert not failures, failures_message("references to sections that are not there", failures)


def test_every_file_and_function_the_docs_name_is_in_the_source(t=None):
    """A file the docs name alone in backticks (`bus.c`) is one of the
    repository's; a function they name with its parentheses (`bus_tick()`,
    `vmac.cycles()`) appears in the source. In README's "What is here",
    the files of a folder's row are in that folder."""
    words = set()
    for rel in FILES:
        if rel.endswith(SOURCE_EXT) or os.path.basename(rel) == "Makefile":
            words.update(re.findall(r"\w+", read(rel)))
    failures = []
    for rel in DOCS:
        text = read(rel)
        for m in re.finditer(r"`([^`\n]+)`", text):
            span = m.group(1)
            if re.fullmatch(r"[\w-]+\.(c|h|lua|py|sh|mk|proto)", span) and span not in BASENAMES and not \
                    is_placeholder(span):
                failures.append("%s:%d: no file %s in the repository" % (rel, line_of(text, m.start()), span))
            for call in re.findall(r"([A-Za-z_][\w.:]*)\(", span):
                if re.split(r"[.:]", call)[-1] not in words:
                    failures.append("%s:%d: %s() is nowhere in the source" % (rel, line_of(text, m.start()), call))
    readme = read("README.md")
    table = readme[readme.index("## What is here"):readme.index("## What `make test` runs")]
    for m in re.finditer(r"^\| `((?:core|firmware|scripts|stdlib|tests)/[\w/]*)` \|(.*)$", table, re.M):
        folder, row = m.group(1), m.group(2)
        for span in re.findall(r"`([^`\n]+)`", row):
            if re.fullmatch(r"[\w-]+\.(c|h|lua|proto)", span) and not is_placeholder(span):
                if not glob.glob(os.path.join(ROOT, folder, "**", span), recursive=True):
                    failures.append('README.md "What is here": `%s` is not in %s' % (span, folder))
    assert not failures, failures_message("names the source does not have", failures)


def test_readme_counts_are_the_codes(t=None):
    """Each number README states is the one the code uses."""
    readme = re.sub(r"\s+", " ", read("README.md"))
    failures = []
    for what, said_re, rel, set_re in COUNTS:
        said = re.search(said_re, readme)
        setting = re.search(set_re, read(rel), re.M)
        if not said or not setting:
            failures.append("%s: %s" % (what, ("README no longer says %r" % said_re) if not said else (
                "%s no longer has %r" % (rel, set_re))))
            continue
        value = said.group(1).replace(",", "")
        value = NUMBER_WORDS.get(value.lower(), value)
        if int(value) != int(setting.group(1)):
            failures.append("%s: README says %s, %s has %s" % (what, said.group(1), rel, setting.group(1)))
    attempts = len(glob.glob(os.path.join(ROOT, "tests", "escape", "*.lua")))
    said = re.search(r"the sandbox escape corpus \(`tests/escape/`: its ([\d,]+) attempts", readme)
    if not said:
        failures.append("README no longer says how many attempts the escape corpus has")
    elif int(said.group(1).replace(",", "")) != attempts:
        failures.append("the escape corpus: README says %s attempts, tests/escape/ has %d" % (said.group(1), attempts))
    assert not failures, failures_message("README's counts against the code", failures)


def test_the_escape_corpus_table_lists_its_files(t=None):
    """tests/escape/README.md has one row per attempt: the file's own
    trigger in its "where", and an expected error that is (one of) the
    file's `-- expect:` pattern."""
    text = read("tests/escape/README.md")
    rows = {}
    for m in re.finditer(r"^\| `(\w+\.lua)` \|(.*)\|\s*$", text, re.M):
        cells = [c.strip() for c in m.group(2).split(" | ")]
        rows[m.group(1)] = (cells, line_of(text, m.start()))
    files = {os.path.basename(f) for f in glob.glob(os.path.join(ROOT, "tests", "escape", "*.lua"))}
    failures = ["tests/escape/%s has no row in tests/escape/README.md" % f for f in sorted(files - set(rows))]
    failures += ["tests/escape/README.md:%d: %s is not in tests/escape/" % (rows[f][1], f)
                 for f in sorted(set(rows) - files)]
    for name in sorted(files & set(rows)):
        cells, line = rows[name]
        source = read("tests/escape/" + name)
        expect = re.search(r"^-- expect: (.+)$", source, re.M)
        trigger = re.search(r"^-- trigger: (.+)$", source, re.M)
        where, expected = cells[-2], cells[-1]
        want_where = trigger.group(1).strip() if trigger else None
        if (want_where and where != want_where) or (not want_where and where not in ("load", "attach", "tick")):
            failures.append("tests/escape/README.md:%d: %s runs at '%s', the row says '%s'" % (
                line, name, want_where or "load, attach or tick", where))
        if not expect:
            failures.append("tests/escape/%s has no '-- expect:' line" % name)
            continue
        pattern = expect.group(1).strip()
        shown = re.findall(r"`([^`]+)`", expected)
        if shown:  # the row's first pattern, or some of the file's alternatives
            ok = set(shown[0].split("|")) <= set(pattern.split("|"))
        else:  # said in words ("the host stops cleanly")
            ok = pattern in expected
        if not ok:
            failures.append("tests/escape/README.md:%d: %s expects %r, the row says %r" % (
                line, name, pattern, expected))
    assert not failures, failures_message("the escape corpus's table", failures)


def test_every_module_has_its_place(t=None):
    """Every folder of core/ has a row in README's "What is here" and is
    named in ARCHITECTURE.md, whose MODULES is the Makefile's."""
    readme, arch = read("README.md"), read("docs/ARCHITECTURE.md")
    table = readme[readme.index("## What is here"):readme.index("## What `make test` runs")]
    failures = []
    for name in sorted(os.listdir(os.path.join(ROOT, "core"))):
        if not os.path.isdir(os.path.join(ROOT, "core", name)):
            continue
        if "| `core/%s/` |" % name not in table:
            failures.append('README.md "What is here" has no row for core/%s/' % name)
        if "core/%s/" % name not in arch:
            failures.append("docs/ARCHITECTURE.md does not name core/%s/" % name)
    modules = re.search(r"^MODULES := (.+)$", read("Makefile"), re.M).group(1).split()
    said = re.search(r"`MODULES` is `([^`]+)`", re.sub(r"\s+", " ", arch))
    if not said or said.group(1).split() != modules:
        failures.append("docs/ARCHITECTURE.md says MODULES is %r, the Makefile has %r" % (
            said and said.group(1), " ".join(modules)))
    assert not failures, failures_message("modules and their places in the docs", failures)


def test_no_merge_left_half_done(t=None):
    """No file the project wrote holds a merge's conflict markers (one was
    committed in README.md once, and every other check passed it)."""
    marker = re.compile(r"^(<{7} |={7}$|>{7} )", re.M)
    failures = []
    for rel in TEXT_FILES:
        try:
            text = read(rel)
        except (OSError, UnicodeDecodeError):
            continue
        for m in marker.finditer(text):
            failures.append("%s:%d: %s" % (rel, line_of(text, m.start()), m.group(0).strip()))
    assert not failures, failures_message("conflict markers left by a merge", failures)


def run_standalone(names):
    """Run every test_* function of a module's globals names, without a
    host or run.py (the checks of files: this one, test_types.py); exit 1
    when one failed."""
    failed = 0
    for name, fn in sorted(names.items()):
        if name.startswith("test_") and callable(fn):
            try:
                fn()
                print("PASS", name[len("test_"):])
            except AssertionError as e:
                failed += 1
                print("FAIL", name[len("test_"):] + ":", e)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    run_standalone(globals())
