/* The Lua tests of stdlib/ (tests/lua/test_*.lua), run in the driver
 * sandbox itself, not in an emulation of it. From the repository root:
 *
 *   build/tests/lua_tests [test_NAME.lua ...]
 *
 * One line per test case, then "N passed, N failed"; exit 1 if any failed.
 *
 * Every case gets a fresh driver state, made the way the host makes one
 * (vmac_driver_load_source of a minimal driver: the same libraries, the
 * JIT off, the memory cap of a driver, the count hook), and the test file
 * runs there in a global table built by the sandbox's own drv_make_env(), as
 * a driver file does at load: exactly vmac_driver_allowed, nothing more
 * (no print, io, debug or load). tests/lua/run.lua, the runner's Lua half,
 * is that state's chunk: it requires the test file (which registers its
 * cases with testing.test) and runs the one case asked for. Results come
 * back as return values and errors, so the test needs no extra global.
 *
 * The one difference from a driver: require. The driver's own require
 * still loads stdlib/ modules (as in a driver, once per state); a name
 * that is no stdlib module is looked up next in tests/lua/ (testing,
 * host_copy, washer_plant and the test files themselves), loaded as text
 * into the same sandboxed globals; "washer_example" is the lua block of
 * docs/STDLIB.md after its example marker, at its own line numbers; and
 * "driver_NAME" runs scripts/drivers/NAME.lua, with vmac.cycles() reading
 * scripts/cycles/NAME/, anew at every require: each is a new instance of
 * the shipped driver (its manifest and callbacks), as after a restart. As
 * the whole case runs as a driver file's load, require works all through it
 * (and os.clock() is 0, as while a driver loads).
 *
 * What the real sandbox cannot give a test, the tests do not do: one
 * state cannot load a module twice, so the reload tests of appliance and
 * cycle_restore build the new instance from the same modules (the copy the
 * new version gets is host_copy's plain data either way); and a test reads
 * no file itself.
 *
 * Budget: the driver's count hook, CASE_BUDGETS times a driver's default
 * instructions per case; no wall-clock limit, so a result does not depend
 * on the machine. White-box: it reaches core/driver/internal.h, as
 * tests/unit/test_isolation.c does, to build the global table with
 * drv_make_env() and run the case with drv_guarded_call(). */
#include "../../core/driver/internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <glob.h>

#define CASE_MEMORY_BYTES (4096 * 1024) /* a driver's default cap (driver_memory_kib) */
#define DRIVER_INSTRUCTIONS 200000      /* a driver's default budget per call (driver_instructions) */
#define CASE_BUDGETS 500                /* per case: 100 million instructions (the whole wash takes 37) */

#define TESTS_DIR "tests/lua"
#define DRIVERS_DIR "scripts/drivers"
#define CYCLES_DIR "scripts/cycles"
#define DRIVER_PREFIX "driver_"
#define EXAMPLE_DOC "docs/STDLIB.md"
#define EXAMPLE_MARKER "<!-- test_washer_example.lua loads the next lua block -->"

/* What the state is made from: a driver with nothing in it. */
static const char STATE_SOURCE[] = "return { name = 'lua_tests', version = '1', io = {}, tick = function() end }\n";

/* The lua block of docs/STDLIB.md after the example marker, preceded by as
 * many newlines as lines come before it, so that messages name the
 * document's own lines: [-0, +1] the chunk, or raises. */
static void load_example(lua_State *L)
{
	char err[300];
	size_t len = 0, i, lines = 0, code_len;
	int code = 0;
	char *doc = vmac_read_file(EXAMPLE_DOC, VMAC_DRIVER_FILE_MAX, &len, err, sizeof(err), &code), *at, *start, *end,
	     *text;
	if (!doc)
		luaL_error(L, "%s", err);
	doc[len] = 0;
	at = strstr(doc, EXAMPLE_MARKER);
	start = at ? strstr(at, "```lua\n") : NULL;
	end = start ? strstr(start + 7, "\n```") : NULL;
	if (!end) {
		free(doc);
		luaL_error(L, "%s: no lua block after the marker '%s'", EXAMPLE_DOC, EXAMPLE_MARKER);
	}
	start += 7;
	for (i = 0; doc + i < start; i++)
		lines += doc[i] == '\n';
	code_len = (size_t)(end - start) + 1;
	text = malloc(lines + code_len);
	if (!text) {
		free(doc);
		luaL_error(L, "not enough memory for %s", EXAMPLE_DOC);
	}
	memset(text, '\n', lines);
	memcpy(text + lines, start, code_len);
	code = luaL_loadbufferx(L, text, lines + code_len, "@" EXAMPLE_DOC, "t");
	free(text);
	free(doc);
	if (code != 0)
		lua_error(L);
}

/* "driver_NAME": a new instance of scripts/drivers/NAME.lua, its
 * programmes from scripts/cycles/NAME/: [-0, +1] what the file returned,
 * or raises. Not cached: every require is another instance. */
static struct vmac_driver_programmes programmes; /* the last driver's: a case requires one at a time */

static int require_driver(lua_State *L, const char *path, const char *driver)
{
	struct vmac_driver *d = drv_of(L);
	char chunk[600], dir[300], err[300];
	snprintf(dir, sizeof(dir), CYCLES_DIR "/%s", driver);
	vmac_driver_programmes_free(&programmes);
	if (vmac_driver_programmes_read(dir, &programmes, err, sizeof(err)) != 0)
		luaL_error(L, "%s", err);
	d->programmes = &programmes;
	snprintf(chunk, sizeof(chunk), "@%s", path);
	drv_run_sandboxed(L, path, chunk, driver);
	return 1;
}

/* require for the tests: upvalue 1 the sandboxed globals, upvalue 2 the
 * driver's own require (which keeps the stdlib modules), upvalue 3 the
 * test helpers loaded so far. */
static int test_require(lua_State *L)
{
	const char *name = luaL_checkstring(L, 1);
	char path[600], chunk[600];
	int helper, example;
	snprintf(path, sizeof(path), "%s/%s.lua", drv_of(L)->stdlib_dir, name);
	if (!drv_valid_module_name(name, 40) || access(path, R_OK) == 0)
		goto driver_require;
	if (strncmp(name, DRIVER_PREFIX, strlen(DRIVER_PREFIX)) == 0) {
		snprintf(path, sizeof(path), DRIVERS_DIR "/%s.lua", name + strlen(DRIVER_PREFIX));
		if (access(path, R_OK) == 0)
			return require_driver(L, path, name + strlen(DRIVER_PREFIX));
	}
	snprintf(path, sizeof(path), TESTS_DIR "/%s.lua", name);
	helper = access(path, R_OK) == 0;
	example = strcmp(name, "washer_example") == 0;
	if (!helper && !example)
		goto driver_require;
	lua_getfield(L, lua_upvalueindex(3), name);
	if (!lua_isnil(L, -1))
		return 1;
	lua_pop(L, 1);
	if (helper) {
		snprintf(chunk, sizeof(chunk), "@%s", path);
		drv_run_sandboxed(L, path, chunk, name);
	} else {
		load_example(L);
		lua_pushvalue(L, lua_upvalueindex(1));
		lua_setfenv(L, -2);
		lua_pushstring(L, name);
		lua_call(L, 1, 1);
	}
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		lua_pushboolean(L, 1);
	}
	lua_pushvalue(L, -1);
	lua_setfield(L, lua_upvalueindex(3), name);
	return 1;
driver_require:
	lua_pushvalue(L, lua_upvalueindex(2));
	lua_insert(L, 1);
	lua_call(L, lua_gettop(L) - 1, 1);
	return 1;
}

struct case_args {
	const char *suite; /* "test_pid" */
	const char *file;  /* "tests/lua/test_pid.lua": the state's file name, in messages */
	int index;         /* 0: the names of the cases; 1..n: run case n */
	char *names;       /* index 0: the names, one a line (malloc'd) */
	long assertions;   /* index 1..n: the assertions the case made */
};

/* Protected work on a fresh state: tests/lua/run.lua in make_env's global
 * table (require as above), called with the suite and the case's index
 * under CASE_BUDGETS budgets, loading (so require works) throughout. */
static int case_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct case_args *a = args;
	lua_State *L = d->L;
	size_t len = 0;
	int code = 0;
	char *src = vmac_read_file(TESTS_DIR "/run.lua", VMAC_DRIVER_FILE_MAX, &len, err, errlen, &code);
	if (!src)
		return -1;
	code = luaL_loadbufferx(L, src, len, "@" TESTS_DIR "/run.lua", "t");
	free(src);
	if (code != 0) {
		snprintf(err, errlen, "%s", lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "not enough memory");
		return -1;
	}
	drv_make_env(L);                /* chunk, env */
	lua_pushvalue(L, -1);           /* chunk, env, env */
	lua_getfield(L, -1, "require"); /* chunk, env, env, the driver's require */
	lua_newtable(L);                /* chunk, env, env, require, the helpers loaded */
	lua_pushcclosure(L, test_require, 3);
	lua_setfield(L, -2, "require"); /* chunk, env */
	lua_setfenv(L, -2);
	lua_pushstring(L, a->suite);
	lua_pushinteger(L, a->index);
	d->loading = 1;
	code = drv_guarded_call(d, 2, 1, CASE_BUDGETS, err, errlen);
	d->loading = 0;
	if (code != 0)
		return -1;
	if (a->index == 0) {
		const char *names = lua_tolstring(L, -1, &len);
		if (!names || !(a->names = malloc(len + 1))) {
			snprintf(err, errlen, "%s/run.lua: expected the names of the cases", TESTS_DIR);
			return -1;
		}
		memcpy(a->names, names, len + 1);
	} else {
		a->assertions = (long)lua_tointeger(L, -1);
	}
	return 0;
}

/* One run of tests/lua/run.lua in a fresh state. 0, or -1 with err. */
static int run_case(struct case_args *a, char *err, size_t errlen)
{
	struct vmac_driver_limits limits;
	struct vmac_driver *d;
	int rc;
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = CASE_MEMORY_BYTES;
	limits.instructions = DRIVER_INSTRUCTIONS;
	limits.max_level = 1;
	limits.stdlib_dir = "stdlib";
	if (vmac_driver_load_source(a->file, STATE_SOURCE, sizeof(STATE_SOURCE) - 1, &limits, &d, err, errlen) != 0)
		return -1;
	rc = drv_protect(d, case_work, a, err, errlen);
	vmac_driver_free(d);
	return rc;
}

static int passed, failed;

static void report_failure(const char *suite, const char *name, const char *message)
{
	const char *line = message, *nl;
	failed++;
	printf("FAIL %s: %s\n", suite, name);
	while (*line) {
		nl = strchr(line, '\n');
		printf("     %.*s\n", nl ? (int)(nl - line) : (int)strlen(line), line);
		line = nl ? nl + 1 : line + strlen(line);
	}
}

static void run_file(const char *path)
{
	char suite[64], file[100], label[300], err[VMAC_DRIVER_ERR_MAX * 4];
	const char *base = strrchr(path, '/') ? strrchr(path, '/') + 1 : path;
	struct case_args a;
	char *name, *next;
	int index = 0;
	size_t n = strlen(base);
	if (n < 10 || n - 4 >= sizeof(suite) || strncmp(base, "test_", 5) != 0 || strcmp(base + n - 4, ".lua") != 0) {
		report_failure(path, "(load)", "not a test file name (test_NAME.lua in " TESTS_DIR "/)");
		return;
	}
	memcpy(suite, base, n - 4);
	suite[n - 4] = 0;
	snprintf(file, sizeof(file), TESTS_DIR "/%s.lua", suite);
	memset(&a, 0, sizeof(a));
	a.suite = suite;
	a.file = file;
	if (run_case(&a, err, sizeof(err)) != 0) {
		report_failure(suite + 5, "(load)", err);
		return;
	}
	if (!a.names[0])
		report_failure(suite + 5, "(load)", "the file registered no tests");
	for (name = a.names; *name; name = next) {
		next = strchr(name, '\n');
		if (next)
			*next++ = 0;
		else
			next = name + strlen(name);
		snprintf(label, sizeof(label), "%s", name);
		a.index = ++index;
		a.assertions = 0;
		if (run_case(&a, err, sizeof(err)) != 0)
			report_failure(suite + 5, label, err);
		else if (a.assertions == 0)
			report_failure(suite + 5, label, "the test asserted nothing");
		else {
			passed++;
			printf("ok   %s: %s\n", suite + 5, label);
		}
	}
	free(a.names);
}

int main(int argc, char **argv)
{
	glob_t files;
	size_t i;
	int k;
	setvbuf(stdout, NULL, _IOLBF, 0);
	if (argc > 1) {
		for (k = 1; k < argc; k++) /* test_NAME.lua, or a path to it: the one in tests/lua/ runs */
			run_file(argv[k]);
	} else {
		if (glob(TESTS_DIR "/test_*.lua", 0, NULL, &files) != 0) {
			printf("no tests found in %s/: run from the repository root\n", TESTS_DIR);
			return 1;
		}
		for (i = 0; i < files.gl_pathc; i++)
			run_file(files.gl_pathv[i]);
		globfree(&files);
	}
	printf("%d passed, %d failed\n", passed, failed);
	return failed == 0 ? 0 : 1;
}
