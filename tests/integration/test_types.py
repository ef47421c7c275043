"""The LuaLS annotation files (scripts/types/) against the docs of the API
they describe: every function and method that DRIVERS.md, STDLIB.md and
TESTING.md name has its annotation, and every annotated function is named
in one of them; the plant API's fields against BOARD.md's table; and
against the code: the stdlib's modules and the test runner's globals. A failure names the missing ones and where to add them.

It reads files and runs no program, so it also runs alone:

    python3 tests/integration/test_types.py

How the docs name the API (all three docs, code spans and ```lua blocks):
- `RECEIVER:method` (with or without its arguments), RECEIVER one of
  METHOD_RECEIVERS: `c:wait(s)`, `dev:checkpoint()`, `b:try_set`,
  `interlock:update/apply` (each name of a slash list);
- `MODULE.function(` or `MODULE.function{`, MODULE one of MODULES:
  `cycle.new(body, options)`, `ramp.profile{...}`, `vmac.cycles()`;
- bare names, only as the first cell of the tables in BARE_TABLES (the
  driver's callbacks, the test API's globals) and `test(` in TESTING.md.

How the annotations name it: `function X.name(` (X a module or global
table), `function X:name(` (X the local of a `---@class`, named by that
class), `function name(` (a global), and the `fun(...)` fields of
vmac.Driver (the callbacks, named driver.NAME)."""

import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TYPES = "scripts/types"
DOCS = ["docs/" + name for name in "DRIVERS.md STDLIB.md TESTING.md".split()]

# The names the docs give objects, and the class of each in scripts/types/.
METHOD_RECEIVERS = {
    "dev": "vmac.Dev",
    "t": "vmac.Timer", "u": "vmac.Timer", "timer": "vmac.Timer",
    "loop": "vmac.Pid", "pid": "vmac.Pid",
    "r": "vmac.Ramp", "ramp": "vmac.Ramp",
    "c": "vmac.Cycle", "cycle": "vmac.Cycle",
    "il": "vmac.Interlock", "interlock": "vmac.Interlock",
    "control": "vmac.Appliance", "appliance": "vmac.Appliance",
    "b": "vmac.test.Board",
    "handle": "vmac.test.Every",
}
# Tables of functions: the sandbox's globals and the stdlib's modules.
MODULES = ["vmac", "os", "timer", "pid", "ramp", "cycle", "interlock", "appliance"]
# (the header row of the tables starts with, the prefix their names get, doc).
BARE_TABLES = [
    ("| callback |", "driver.", "docs/DRIVERS.md"),
    ("| call | does |", "", "docs/TESTING.md"),
    ("| call | fails unless |", "", "docs/TESTING.md"),
]
# The callbacks: the fun() fields of this class are driver.NAME.
CALLBACK_CLASS = "vmac.Driver"


def read(rel):
    with open(os.path.join(ROOT, rel)) as f:
        return f.read()


def line_of(text, pos):
    return text.count("\n", 0, pos) + 1


def code_of(text):
    """(position, code) of every code span and ```lua block of a Markdown
    text, the blocks without their comments."""
    found = []
    for m in re.finditer(r"^```lua\n(.*?)^```", text, re.S | re.M):
        found.append((m.start(1), re.sub(r"--[^\n]*", "", m.group(1))))
    prose = re.sub(r"^```.*?^```", lambda m: " " * len(m.group(0)), text, flags=re.S | re.M)
    for m in re.finditer(r"`([^`\n]+)`", prose):
        found.append((m.start(1), m.group(1)))
    return found


def documented():
    """{api name: "doc:line" of its first mention} from the docs."""
    names = {}
    receivers = "|".join(sorted(METHOD_RECEIVERS, key=len, reverse=True))
    method_re = re.compile(r"(?<![\w.:])(%s):([a-z_]\w*(?:/[a-z_]\w*)*)" % receivers)
    function_re = re.compile(r"(?<![\w.:])(%s)\.(\w+)\s*[({]" % "|".join(MODULES))
    for doc in DOCS:
        text = read(doc)
        for pos, code in code_of(text):
            where = "%s:%d" % (doc, line_of(text, pos))
            for m in method_re.finditer(code):
                for method in m.group(2).split("/"):
                    names.setdefault("%s:%s" % (METHOD_RECEIVERS[m.group(1)], method), where)
            for m in function_re.finditer(code):
                names.setdefault("%s.%s" % (m.group(1), m.group(2)), where)
    for header, prefix, doc in BARE_TABLES:
        text = read(doc)
        starts = [m.start() + 1 for m in re.finditer(re.escape("\n" + header), text)]
        assert starts, "%s has no table whose header starts %r (tests/integration/test_types.py, BARE_TABLES)" % (
            doc, header)
        for start in starts:
            end = text.find("\n\n", start)
            for m in re.finditer(r"^\| `(\w+)\s*[({]", text[start:end], re.M):
                names.setdefault(prefix + m.group(1), "%s:%d" % (doc, line_of(text, start + m.start())))
    testing = read("docs/TESTING.md")
    m = re.search(r"`test\(", testing)
    if m:
        names.setdefault("test", "docs/TESTING.md:%d" % line_of(testing, m.start()))
    return names


def type_files():
    files = []
    for top, _, found in os.walk(os.path.join(ROOT, TYPES)):
        files += [os.path.relpath(os.path.join(top, f), ROOT) for f in found if f.endswith(".lua")]
    return sorted(files)


def annotated():
    """{api name: "file:line"} from scripts/types/."""
    names = {}
    for rel in type_files():
        text = read(rel)
        classes = {}  # local table -> the class annotated above it
        for m in re.finditer(r"^---@class\s+([\w.]+)[^\n]*\n(?:---[^\n]*\n)*(?:local\s+)?(\w+)\s*=\s*\{\}", text, re.M):
            classes[m.group(2)] = m.group(1)
        for m in re.finditer(r"^function\s+(?:(\w+)([.:]))?(\w+)\s*\(", text, re.M):
            table, sep, name = m.groups()
            if not table:
                key = name
            elif sep == ":":
                key = "%s:%s" % (classes.get(table, table), name)
            else:
                key = "%s.%s" % (table, name)
            names[key] = "%s:%d" % (rel, line_of(text, m.start()))
        block = re.search(r"^---@class\s+%s\b[^\n]*\n((?:---[^\n]*\n)*)" % re.escape(CALLBACK_CLASS), text, re.M)
        if block:
            for m in re.finditer(r"^---@field\s+(\w+)\??\s+fun\(", block.group(1), re.M):
                names["driver." + m.group(1)] = "%s:%d" % (rel, line_of(text, block.start(1) + m.start()))
    return names


def test_every_documented_function_has_its_annotation(t=None):
    """What DRIVERS.md, STDLIB.md and TESTING.md name is annotated in
    scripts/types/."""
    docs, types = documented(), annotated()
    missing = ["%s (named at %s)" % (name, docs[name]) for name in sorted(set(docs) - set(types))]
    assert not missing, "documented but not annotated in %s/:\n  %s" % (TYPES, "\n  ".join(missing))


def test_every_annotated_function_is_documented(t=None):
    """Every function scripts/types/ annotates is named in DRIVERS.md,
    STDLIB.md or TESTING.md."""
    docs, types = documented(), annotated()
    missing = ["%s (annotated at %s)" % (name, types[name]) for name in sorted(set(types) - set(docs))]
    assert not missing, "annotated but in none of %s:\n  %s" % (", ".join(DOCS), "\n  ".join(missing))


def test_the_annotation_files_are_luals_meta_files(t=None):
    """Each file starts with ---@meta, and a stdlib module's file is
    required by the module's name (---@meta NAME, NAME.lua in stdlib/)."""
    failures = []
    for rel in type_files():
        first = read(rel).split("\n", 1)[0]
        meta = re.fullmatch(r"---@meta(?: (\w+))?", first)
        if not meta:
            failures.append("%s:1: starts with %r, not ---@meta" % (rel, first))
        elif rel.startswith(TYPES + "/stdlib/"):
            module = os.path.splitext(os.path.basename(rel))[0]
            if meta.group(1) != module or not os.path.exists(os.path.join(ROOT, "stdlib", module + ".lua")):
                failures.append("%s:1: should be ---@meta %s, for stdlib/%s.lua" % (rel, module, module))
    stdlib = {os.path.splitext(f)[0] for f in os.listdir(os.path.join(ROOT, "stdlib")) if f.endswith(".lua")}
    typed = {os.path.splitext(os.path.basename(f))[0] for f in type_files() if f.startswith(TYPES + "/stdlib/")}
    failures += ["stdlib/%s.lua has no %s/stdlib/%s.lua" % (m, TYPES, m) for m in sorted(stdlib - typed)]
    assert not failures, "the annotation files:\n  " + "\n  ".join(failures)


def test_the_test_api_annotated_is_the_runners(t=None):
    """The globals core/vtest/runner.lua hands a test file (its env table
    and test) are the global functions of scripts/types/test.lua."""
    runner = read("core/vtest/runner.lua")
    table = re.search(r"for k, v in pairs \{(.*?)\} do", runner, re.S)
    assert table, "core/vtest/runner.lua: no `for k, v in pairs { ... } do` giving the test API (test_types.py)"
    given = set(re.findall(r"(\w+)\s*=", table.group(1))) | {"test"}
    text = read(TYPES + "/test.lua")
    typed = set(re.findall(r"^function\s+(\w+)\s*\(", text, re.M))
    failures = ["%s: given by the runner, not annotated in %s/test.lua" % (n, TYPES) for n in sorted(given - typed)]
    failures += ["%s: annotated in %s/test.lua, not given by the runner" % (n, TYPES) for n in sorted(typed - given)]
    assert not failures, "the test API:\n  " + "\n  ".join(failures)


def test_each_stdlib_module_annotated_is_the_code(t=None):
    """stdlib/NAME.lua and scripts/types/stdlib/NAME.lua define the same
    module functions and methods (`function M.f` and `function C:m`)."""
    failures = []
    for rel in type_files():
        if not rel.startswith(TYPES + "/stdlib/"):
            continue
        code = "stdlib/" + os.path.basename(rel)
        if not os.path.exists(os.path.join(ROOT, code)):
            continue  # said by test_the_annotation_files_are_luals_meta_files
        defined = {}
        for path in (code, rel):
            defined[path] = set(re.findall(r"^function\s+\w+([.:]\w+)\s*\(", read(path), re.M))
        failures += ["%s defines %s, %s does not annotate it" % (code, n, rel)
                     for n in sorted(defined[code] - defined[rel])]
        failures += ["%s annotates %s, %s does not define it" % (rel, n, code)
                     for n in sorted(defined[rel] - defined[code])]
    assert not failures, "the stdlib against its annotations:\n  " + "\n  ".join(failures)


def test_the_plant_api_annotated_is_board_md(t=None):
    """The fields of vmac.Plant (scripts/types/plant.lua) are the rows of
    BOARD.md's table of what a plant file returns, and the reverse."""
    board = read("docs/BOARD.md")
    table = re.search(r"^\| field \| required \| meaning \|\n(.*?)\n\n", board, re.S | re.M)
    assert table, "docs/BOARD.md: no table headed | field | required | meaning | (Plant models in Lua)"
    documented_fields = set()
    for row in re.findall(r"^\| ([^|]+) \|", table.group(1), re.M):
        documented_fields |= set(re.findall(r"`(\w+)", row))
    text = read(TYPES + "/plant.lua")
    block = re.search(r"^---@class\s+vmac\.Plant\b[^\n]*\n((?:---[^\n]*\n)*)", text, re.M)
    assert block, "%s/plant.lua has no ---@class vmac.Plant" % TYPES
    typed = set(re.findall(r"^---@field\s+(\w+)", block.group(1), re.M))
    failures = ["%s: in BOARD.md's table, not a field of vmac.Plant" % n for n in sorted(documented_fields - typed)]
    failures += ["%s: a field of vmac.Plant, not in BOARD.md's table" % n for n in sorted(typed - documented_fields)]
    assert not failures, "the plant API:\n  " + "\n  ".join(failures)


if __name__ == "__main__":
    from test_docs import run_standalone
    run_standalone(globals())
