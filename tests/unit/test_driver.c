/* Unit tests of the driver module (core/driver) through its C API: the
 * manifest and its errors, named I/O, machines of several boards, published
 * variables, operator input, the host hooks, the sandbox's bounds, and the
 * sandbox being exactly its allow-list. The escape corpus runs end to end in
 * tests/integration/test_escape.py. */
#include <check.h>
#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <lauxlib.h>
#include <lualib.h>

#include "../../core/driver/driver.h"
#include "check_main.h"

#define STDLIB_DIR "/tmp/vmac-test-driver-stdlib"
#define CYCLES_DIR "/tmp/vmac-test-driver-cycles"

static struct vmac_driver_limits limits;
static struct vmac_driver_programmes programmes;

/* The programmes of folder dir, as the host reads a drivers folder's. */
static void use_folder(const char *dir)
{
	char err[300];
	vmac_driver_programmes_free(&programmes);
	ck_assert_msg(vmac_driver_programmes_read(dir, &programmes, err, sizeof(err)) == 0, "%s", err);
	limits.programmes = &programmes;
}

static void setup(void)
{
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = 1 << 20;
	limits.instructions = 200000;
	limits.max_level = 10;
	limits.default_level = 4;
	limits.stdlib_dir = STDLIB_DIR;
	use_folder(CYCLES_DIR);
}

static void write_file(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	ck_assert_msg(f != NULL, "cannot write %s", path);
	fputs(text, f);
	fclose(f);
}

/* Load text as driver "t" (file t.lua). */
static int load(const char *text, struct vmac_driver **d, char *err, size_t errlen)
{
	char path[] = "/tmp/vmac-test-driver-XXXXXX/t.lua";
	char dir[] = "/tmp/vmac-test-driver-XXXXXX";
	int rc;
	ck_assert_msg(mkdtemp(dir) != NULL, "mkdtemp failed");
	snprintf(path, sizeof(path), "%s/t.lua", dir);
	write_file(path, text);
	limits.expect_name = "t";
	rc = vmac_driver_load(path, &limits, d, err, errlen);
	unlink(path);
	rmdir(dir);
	return rc;
}

static struct vmac_driver *load_ok(const char *text)
{
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load(text, &d, err, sizeof(err)) == 0, "load failed: %s", err);
	return d;
}

static void load_fails(const char *text, const char *want)
{
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load(text, &d, err, sizeof(err)) != 0, "load of a bad driver succeeded (wanted '%s')", want);
	ck_assert_msg(strstr(err, want) != NULL, "load error '%s' does not say '%s'", err, want);
}

/* One board, one tick with the given inputs. */
static int tick1(struct vmac_driver *d, double t, const struct vmac_inputs *in, struct vmac_outputs *out, char *err,
                 size_t errlen)
{
	const struct vmac_inputs *ins[1] = {in};
	struct vmac_outputs *outs[1] = {out};
	return vmac_driver_tick(d, t, ins, outs, err, errlen);
}

static const struct vmac_variable *var(const struct vmac_driver *d, const char *name)
{
	int i;
	for (i = 0; i < vmac_driver_nvars(d); i++)
		if (strcmp(vmac_driver_variable(d, i)->name, name) == 0)
			return vmac_driver_variable(d, i);
	ck_abort_msg("no variable %s", name);
	return NULL;
}

START_TEST(take_over_hands_plain_state_params_and_outputs)
{
	/* The old version: state with shared tables, a cycle, a function, a
	 * coroutine and an object with a metatable; a param set; outputs on. */
	struct vmac_driver *od =
	    load_ok("return { name = 't', version = '1', io = { lamp = 'do0', pump = 'do1', motor = 'pwm' },\n"
	            "  params = { fill_l = { default = 8, min = 1, max = 20 }, mode = { default = 'eco' } },\n"
	            "  attach = function(dev)\n"
	            "    local shared = { n = 1 }\n"
	            "    local s = dev.state\n"
	            "    s.a, s.b, s.count, s.name, s.flag = shared, shared, 41, 'wash', true\n"
	            "    s.self = s\n"
	            "    s.fn = function() end\n"
	            "    s.co = coroutine and coroutine.create(s.fn) or nil\n"
	            "    s.obj = setmetatable({ x = 2 }, { __index = function() return 'm' end })\n"
	            "    s[1], s[2] = 'one', 'two'\n"
	            "    dev.params.fill_l = 12\n"
	            "    dev.params.mode = 'hot'\n"
	            "  end,\n"
	            "  tick = function(dev) dev.out.lamp = true; dev.out.motor = 300 end }\n");
	/* The new version checks what it got. */
	struct vmac_driver *nd = load_ok(
	    "return { name = 't', version = '2', io = { lamp = 'do0', motor = 'pwm', fan = 'do2' },\n"
	    "  params = { fill_l = { default = 8, min = 1, max = 20 } },\n"
	    "  variables = { got = {} },\n"
	    "  attach = function(dev) assert(dev.params.fill_l == 12, 'params copied before attach') end,\n"
	    "  migrate = function(dev, old)\n"
	    "    assert(old.count == 41 and old.name == 'wash' and old.flag == true, 'plain values')\n"
	    "    assert(old.a == old.b and old.a.n == 1, 'a shared table stays one table')\n"
	    "    assert(old.self == old, 'a cycle stays a cycle')\n"
	    "    assert(old.fn == nil and old.co == nil, 'functions and coroutines are dropped')\n"
	    "    assert(old.obj.x == 2 and getmetatable(old.obj) == nil, 'metatables are not copied')\n"
	    "    assert(old[1] == 'one' and old[2] == 'two', 'array part')\n"
	    "    assert(dev.out.lamp == true and dev.out.motor == 300 and dev.out.pump == nil, 'outputs it has')\n"
	    "    dev.state.count = old.count + 1\n"
	    "    dev.vars.got = dev.state.count\n"
	    "  end,\n"
	    "  tick = function(dev) end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	memset(&in, 0, sizeof(in));
	ck_assert_int_eq(vmac_driver_add_board(od, 0, "b0"), 0);
	ck_assert_int_eq(vmac_driver_add_board(nd, 0, "b0"), 0);
	ck_assert_msg(vmac_driver_attach(od, 0, err, sizeof(err)) == 0, "old attach: %s", err);
	ck_assert_msg(tick1(od, 0.1, &in, &out, err, sizeof(err)) == 0, "old tick: %s", err);
	ck_assert_msg(vmac_driver_take_over(nd, od, 0.2, err, sizeof(err)) == 0, "take over failed: %s", err);
	ck_assert_msg(tick1(nd, 0.3, &in, &out, err, sizeof(err)) == 0, "new tick: %s", err);
	ck_assert_msg(out.digital == 0x01 && out.pwm == 300, "the new version's outputs: 0x%02x pwm %d", out.digital,
	              out.pwm);
	ck_assert_msg(var(nd, "got")->value.number == 42, "migrate's result: %g", var(nd, "got")->value.number);
	vmac_driver_free(od);
	vmac_driver_free(nd);
}
END_TEST

START_TEST(take_over_refuses_what_it_cannot_copy)
{
	static const char *const cases[][2] = {
	    {"for i = 1, 20000 do dev.state[i] = i end", "more than 10000 entries"},
	    {"local t = dev.state; for i = 1, 40 do t.next = {}; t = t.next end", "deeper than 32"},
	    {"for i = 1, 8 do dev.state[i] = string.rep(string.char(64 + i), 60000) end", "memory cap"},
	};
	char text[1024], err[VMAC_DRIVER_ERR_MAX];
	size_t i;
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		struct vmac_driver *od, *nd;
		snprintf(text, sizeof(text),
		         "return { name = 't', version = '1', io = { lamp = 'do0' }, attach = function(dev) %s end,\n"
		         "  tick = function() end }",
		         cases[i][0]);
		od = load_ok(text);
		limits.memory_bytes = 300 * 1024; /* the new one cannot hold the big string */
		nd = load_ok("return { name = 't', version = '2', io = { lamp = 'do0' }, tick = function() end,\n"
		             "  migrate = function() error('must not run') end }");
		limits.memory_bytes = 1 << 20;
		ck_assert_msg(vmac_driver_attach(od, 0, err, sizeof(err)) == 0, "old attach (%s): %s", cases[i][0],
		              err);
		err[0] = 0;
		ck_assert_msg(vmac_driver_take_over(nd, od, 0, err, sizeof(err)) != 0, "took over with %s",
		              cases[i][0]);
		ck_assert_msg(strstr(err, cases[i][1]) != NULL, "'%s': error '%s' does not say '%s'", cases[i][0], err,
		              cases[i][1]);
		vmac_driver_free(od);
		vmac_driver_free(nd);
	}
}
END_TEST

START_TEST(manifest_errors_name_the_field)
{
	load_fails("return 42\n", "must return a table");
	load_fails("return { version = '1', io = {}, tick = function() end }\n", "name");
	load_fails("return { name = 'other', version = '1', io = {}, tick = function() end }\n",
	           "board announced driver 't'");
	load_fails("return { name = 't', io = {}, tick = function() end }\n", "version");
	/* Not UTF-8: JSON could not carry it, and the status and the manifest
	 * left the whole driver out (found by tests/fuzz/fuzz_manifest.c). */
	load_fails("return { name = 't', version = '1.\\138', io = {}, tick = function() end }\n",
	           "version (a string of UTF-8 text");
	/* A NUL inside a name made "in\0a" and "in\0b" both "in" on the C side
	 * (found by tests/fuzz/fuzz_manifest.c). */
	load_fails("return { name = 't', version = '1', io = { ['in\\0a'] = 'di0', ['in\\0b'] = 'di1' },\n"
	           "  tick = function() end }\n",
	           "io: names are [a-z][a-z0-9_]*");
	load_fails("return { name = 't', version = '1', io = {}, variables = { ['v\\0'] = {} },\n"
	           "  tick = function() end }\n",
	           "variables");
	load_fails("return { name = 't', version = '1', tick = function() end }\n", "io must be a table");
	load_fails("return { name = 't', version = '1', io = {} }\n", "tick must be a function");
	load_fails("return { name = 't', version = '1', level = 11, io = {}, tick = function() end }\n",
	           "level must be a whole number 0..10");
	load_fails("return { name = 't', version = '1', level = 1.5, io = {}, tick = function() end }\n", "level");
	load_fails("return { name = 't', version = '1', io = { lamp = 'do9' }, tick = function() end }\n",
	           "io.lamp: unknown channel 'do9'");
	load_fails("return { name = 't', version = '1', io = { a = 'do1', b = 'do1' }, tick = function() end }\n",
	           "is already io.");
	load_fails("return { name = 't', version = '1', io = { a = { 'do1', scale = 2 } }, tick = function() end }\n",
	           "outputs take no scale");
	load_fails("return { name = 't', version = '1', io = {}, varaibles = {}, tick = function() end }\n",
	           "unknown field 'varaibles'");
	load_fails("return { name = 't', version = '1', io = {}, params = { p = {} }, tick = function() end }\n",
	           "params.p: default");
	load_fails("return { name = 't', version = '1', io = {}, params = { p = { default = 9, max = 5 } },"
	           " tick = function() end }\n",
	           "params.p: 9 is out of range");
	load_fails("return { name = 't', version = '1', io = {}, params = { x = { default = 1 } },"
	           " variables = { x = {} }, tick = function() end }\n",
	           "'x' is both a variable and a param");
	load_fails("return { name = 't', version = '1', io = {}, commands = { go = { arg = 'nothing' } },"
	           " tick = function() end }\n",
	           "arg 'nothing' is neither");
	load_fails("return { name = 't', version = '1', io = {}, variables = { v = { update = 'timer:0' } },"
	           " tick = function() end }\n",
	           "timer:N");
	load_fails("return { name = 't', version = '1', io = {}, tick = function( end }\n", "t.lua:1:");
}
END_TEST

START_TEST(named_io_in_and_out)
{
	struct vmac_driver *d = load_ok("return { name = 't', version = '2.0', level = 3,\n"
	                                "  io = { door = 'di1', level_l = { 'ai0', scale = 0.01, offset = 1 },\n"
	                                "         drum = 'encoder', valve = 'do2', motor = 'pwm' },\n"
	                                "  tick = function(dev, i)\n"
	                                "    assert(i.door == true and i.level_l == 13.34 and i.drum == -7, 'inputs')\n"
	                                "    assert(i.time == 1.5, 'time')\n"
	                                "    if not dev.out.valve then dev.out.valve = true; dev.out.motor = -250 end\n"
	                                "  end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_str_eq(vmac_driver_version(d), "2.0");
	ck_assert_uint_eq(vmac_driver_level(d), 3);
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "b0"), 0);
	memset(&in, 0, sizeof(in));
	in.digital = 0x02;
	in.analog[0] = 1234;
	in.encoder = -7;
	ck_assert_msg(tick1(d, 1.5, &in, &out, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_msg(out.digital == 0x04 && out.pwm == -250, "outputs 0x%02x pwm %d", out.digital, out.pwm);
	/* Outputs keep their values across ticks. */
	ck_assert_msg(tick1(d, 1.5, &in, &out, err, sizeof(err)) == 0, "second tick failed: %s", err);
	ck_assert_msg(out.digital == 0x04 && out.pwm == -250, "outputs not kept: 0x%02x pwm %d", out.digital, out.pwm);
	vmac_driver_free(d);
}
END_TEST

START_TEST(bad_outputs_fail_and_turn_everything_off)
{
	struct vmac_driver *d = load_ok("return { name = 't', version = '1', io = { a = 'do0', m = 'pwm' },\n"
	                                "  tick = function(dev) dev.out.a = true; dev.out.m = 5000 end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	vmac_driver_add_board(d, 0, "b0");
	memset(&in, 0, sizeof(in));
	ck_assert_int_ne(tick1(d, 0, &in, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "dev.out.m") != NULL, "error does not name the output: %s", err);
	ck_assert_msg(out.digital == 0 && out.pwm == 0, "outputs left on after a bad output");
	vmac_driver_free(d);
}
END_TEST

/* A driver's error comes back with one clean traceback (docs/DRIVERS.md
 * "The sandbox"): the message, then the driver's own frames, each once; the C
 * frames carry no raw address, and none is listed twice. */
START_TEST(a_driver_error_has_one_clean_traceback)
{
	struct vmac_driver *d = load_ok("local function inner() error('boom') end\n"
	                                "local function outer() inner() end\n"
	                                "local lazy = setmetatable({}, { __index = function() outer() end })\n"
	                                "return { name = 't', version = '1', io = {},\n"
	                                "  tick = function(dev) return lazy.x end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	const char *line, *tb;
	vmac_driver_add_board(d, 0, "b0");
	memset(&in, 0, sizeof(in));
	ck_assert_int_ne(tick1(d, 0, &in, &out, err, sizeof(err)), 0);
	tb = strstr(err, "stack traceback:\n");
	ck_assert_msg(tb != NULL, "no traceback in: %s", err);
	ck_assert_msg(strstr(err, "t.lua:1: boom") == err, "the message does not come first: %s", err);
	ck_assert_msg(strstr(err, " at 0x") == NULL, "a raw address in: %s", err);
	ck_assert_msg(strncmp(tb, "stack traceback:\n\tt.lua:1: in function 'inner'\n", 46) == 0,
	              "the driver's line is not the first frame: %s", err);
	ck_assert_msg(strstr(tb, "t.lua:2: in function 'outer'") != NULL, "no frame of outer: %s", err);
	for (line = strchr(tb, '\n'); line && line[1]; line = strchr(line + 1, '\n')) {
		const char *end = strchr(line + 1, '\n');
		size_t len = end ? (size_t)(end - line) : strlen(line);
		char frame[200];
		snprintf(frame, sizeof(frame), "%.*s\n", (int)(len < 190 ? len : 190), line);
		ck_assert_msg(strstr(line + len, frame) == NULL, "frame listed twice (%.*s) in: %s", (int)len, line + 1,
		              err);
	}
	vmac_driver_free(d);
}
END_TEST

/* The tick's tables are looked up by interned keys (load.c, make_keys):
 * a driver that replaces dev.out or dev.vars, or publishes a table, is
 * still caught by name, the stack stays balanced, the outputs stay off. */
START_TEST(replaced_tables_and_bad_variables_fail_by_name)
{
	static const char *const cases[][2] = {
	    {"dev.out = 5", "dev.out must stay a table"},
	    {"dev.vars = 'x'", "dev.vars must stay a table"},
	    {"dev.vars.v = {}", "dev.vars.v must be a number, boolean, string or nil"},
	};
	size_t i;
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		char src[512], err[VMAC_DRIVER_ERR_MAX] = "";
		struct vmac_driver *d;
		struct vmac_inputs in;
		struct vmac_outputs out;
		snprintf(src, sizeof(src),
		         "return { name = 't', version = '1', io = { a = 'do0', s = 'di0' }, variables = { v = {} },\n"
		         "  tick = function(dev, inputs) dev.out.a = inputs.s; dev.vars.v = inputs.time\n"
		         "    if inputs.time >= 1 then %s end end }\n",
		         cases[i][0]);
		d = load_ok(src);
		vmac_driver_add_board(d, 0, "b0");
		memset(&in, 0, sizeof(in));
		in.digital = 1;
		ck_assert_msg(tick1(d, 0.5, &in, &out, err, sizeof(err)) == 0, "%s: a good tick failed: %s",
		              cases[i][0], err);
		ck_assert_msg(out.digital == 1, "%s: output a not driven from input s", cases[i][0]);
		ck_assert_msg(var(d, "v")->value.number == 0.5, "%s: v not published from inputs.time", cases[i][0]);
		ck_assert_int_ne(tick1(d, 1, &in, &out, err, sizeof(err)), 0);
		ck_assert_msg(strstr(err, cases[i][1]) != NULL, "'%s': error '%s' does not say '%s'", cases[i][0], err,
		              cases[i][1]);
		ck_assert_msg(out.digital == 0 && out.pwm == 0, "%s: outputs left on", cases[i][0]);
		vmac_driver_free(d);
	}
}
END_TEST

START_TEST(two_boards_one_machine)
{
	struct vmac_driver *d =
	    load_ok("return { name = 't', version = '1',\n"
	            "  io = { lamp = 'do0', switch = { 'di0', board = 2 }, far = { 'do1', board = 9 } },\n"
	            "  variables = { n = {}, who = {} },\n"
	            "  tick = function(dev, i)\n"
	            "    dev.vars.n = #dev.boards; dev.vars.who = dev.name\n"
	            "    dev.out.lamp = i.switch == true; dev.out.far = true\n"
	            "  end }\n");
	struct vmac_inputs in0, in1;
	struct vmac_outputs out0, out1;
	const struct vmac_inputs *ins[2] = {&in0, &in1};
	struct vmac_outputs *outs[2] = {&out0, &out1};
	char err[VMAC_DRIVER_ERR_MAX] = "";
	memset(&in0, 0, sizeof(in0));
	memset(&in1, 0, sizeof(in1));
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "main"), 0);
	ck_assert_int_eq(vmac_driver_add_board(d, 2, "aux"), 0);
	ck_assert_msg(vmac_driver_add_board(d, 2, "aux-again") != 0, "the same minor added twice");
	in1.digital = 0x01;
	ck_assert_msg(vmac_driver_tick(d, 0, ins, outs, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_msg(out0.digital == 0x01, "the switch on board 2 did not light the lamp on board 0: 0x%02x",
	              out0.digital);
	ck_assert_msg(out1.digital == 0, "output of an absent board landed on board 2: 0x%02x", out1.digital);
	ck_assert_msg(var(d, "n")->value.number == 2, "dev.boards has %g boards", var(d, "n")->value.number);
	ck_assert_str_eq(var(d, "who")->value.str, "main");
	vmac_driver_free(d);
}
END_TEST

START_TEST(variables_publish_by_their_rules)
{
	struct vmac_driver *d = load_ok("return { name = 't', version = '1', io = {},\n"
	                                "  variables = { a = {}, slow = { update = 'timer:1' }, g1 = { group = 'g' },\n"
	                                "                g2 = { group = 'g' }, s = {} },\n"
	                                "  tick = function(dev, i)\n"
	                                "    dev.vars.a = math.floor(i.time); dev.vars.slow = i.time\n"
	                                "    dev.vars.g1 = i.time < 2 and 1 or 2; dev.vars.g2 = i.time\n"
	                                "    dev.vars.s = string.rep('x', 100)\n"
	                                "  end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	double published_a;
	vmac_driver_add_board(d, 0, "b0");
	memset(&in, 0, sizeof(in));
	ck_assert_msg(tick1(d, 0.5, &in, &out, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_msg(var(d, "slow")->value.number == 0.5, "timer variable not published at first");
	published_a = var(d, "a")->published_s;
	ck_assert_int_eq(tick1(d, 0.9, &in, &out, err, sizeof(err)), 0);
	ck_assert_msg(var(d, "a")->published_s == published_a, "an unchanged auto variable was published again");
	ck_assert_msg(var(d, "slow")->value.number == 0.5, "timer:1 published again after 0.4 s");
	ck_assert_msg(var(d, "g1")->published_s == 0.9 && var(d, "g2")->published_s == 0.9,
	              "a group not published whole when one member changed: g1 at %g, g2 at %g",
	              var(d, "g1")->published_s, var(d, "g2")->published_s);
	ck_assert_int_eq(tick1(d, 2.0, &in, &out, err, sizeof(err)), 0);
	ck_assert_msg(var(d, "slow")->value.number == 2.0, "timer:1 not published after 1.5 s");
	ck_assert_msg(var(d, "g1")->value.number == 2 && var(d, "g2")->value.number == 2.0,
	              "group not published whole: g1 %g g2 %g", var(d, "g1")->value.number, var(d, "g2")->value.number);
	ck_assert_msg(strlen(var(d, "s")->value.str) == VMAC_DRIVER_STR_MAX, "string not cut at %d bytes",
	              VMAC_DRIVER_STR_MAX);
	vmac_driver_free(d);
}
END_TEST

static int levels_asked;
static int fake_set_level(void *ctx, unsigned level, char *err, size_t errlen)
{
	(void)ctx;
	levels_asked++;
	if (level > 6) {
		snprintf(err, errlen, "schedule full: test");
		return -1;
	}
	return 0;
}
static int events_seen;
static void fake_event(void *ctx, const char *kind, const char *text)
{
	(void)ctx;
	(void)kind;
	(void)text;
	events_seen++;
}

START_TEST(input_and_host_hooks)
{
	struct vmac_driver *d =
	    load_ok("return { name = 't', version = '1', io = {},\n"
	            "  params = { speed = { default = 10, min = 0, max = 100 } },\n"
	            "  variables = { lamp = { set = true }, ro = {}, answer = {} },\n"
	            "  commands = { go = { arg = 'speed' }, fail = {} },\n"
	            "  tick = function(dev)\n"
	            "    local ok, why = dev:set_level(9); dev.vars.answer = why\n"
	            "    for n = 1, 20 do dev:event('hello ' .. n) end\n"
	            "  end,\n"
	            "  input = function(dev, name, value)\n"
	            "    if name == 'fail' then error('input boom') end\n"
	            "    if name == 'go' and value > dev.params.speed then return nil, 'too fast' end\n"
	            "    dev.vars[name] = value; return true\n"
	            "  end }\n");
	struct vmac_driver_host host = {fake_set_level, fake_event, NULL};
	struct vmac_value v;
	struct vmac_inputs in;
	struct vmac_outputs out;
	char reply[200], err[VMAC_DRIVER_ERR_MAX] = "";
	vmac_driver_bind(d, &host);
	vmac_driver_add_board(d, 0, "b0");
	memset(&v, 0, sizeof(v));
	v.type = VMAC_VALUE_BOOL;
	v.number = 1;
	ck_assert_msg(vmac_driver_input(d, 0, "lamp", &v, reply, sizeof(reply), err, sizeof(err)) == 0,
	              "settable variable refused: %s %s", reply, err);
	ck_assert_int_eq(vmac_driver_input(d, 0, "ro", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_READ_ONLY);
	ck_assert_msg(strstr(reply, "read-only") != NULL, "read-only variable reply: %s", reply);
	ck_assert_int_eq(vmac_driver_input(d, 0, "nosuch", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_NAME);
	v.type = VMAC_VALUE_NUMBER;
	v.number = 500;
	ck_assert_int_eq(vmac_driver_input(d, 0, "speed", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_VALUE);
	ck_assert_msg(strstr(reply, "out of range 0..100") != NULL, "range reply: %s", reply);
	v.number = 50;
	ck_assert_int_eq(vmac_driver_input(d, 0, "speed", &v, reply, sizeof(reply), err, sizeof(err)), 0);
	v.number = 40;
	ck_assert_int_eq(vmac_driver_input(d, 0, "go", &v, reply, sizeof(reply), err, sizeof(err)), 0);
	v.number = 60;
	ck_assert_int_eq(vmac_driver_input(d, 0, "go", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_BY_DRIVER);
	ck_assert_msg(strcmp(reply, "too fast") == 0, "the driver's refusal not passed on: %s", reply);
	ck_assert_int_eq(vmac_driver_input(d, 0, "fail", &v, reply, sizeof(reply), err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "input boom") != NULL && strstr(err, "traceback") != NULL, "input error: %s", err);
	memset(&in, 0, sizeof(in));
	ck_assert_msg(tick1(d, 1, &in, &out, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_int_eq(levels_asked, 1);
	ck_assert_str_eq(var(d, "answer")->value.str, "schedule full: test");
	ck_assert_msg(events_seen == 10, "dev:event let %d of 20 through in one second, expected 10", events_seen);
	vmac_driver_free(d);
}
END_TEST

/* The value of param name now. */
static struct vmac_value param_value(struct vmac_driver *d, const char *name)
{
	struct vmac_variable p[VMAC_DRIVER_MAX_PARAMS];
	int i, n = vmac_driver_params(d, p);
	for (i = 0; i < n; i++)
		if (strcmp(p[i].name, name) == 0)
			return p[i].value;
	ck_abort_msg("no param %s", name);
	return p[0].value;
}

/* Operator input to params: a value of another type than the param's is
 * refused (as restoring a persisted one is), a refusal by the driver leaves
 * the param as it was, and a refusal's message never shows a missing text.
 * All three found by tests/fuzz/fuzz_values.c. */
START_TEST(input_to_params_checks_type_and_refusals_change_nothing)
{
	struct vmac_driver *d =
	    load_ok("return { name = 't', version = '1', io = {},\n"
	            "  params = { speed = { default = 10, min = 0, max = 100 }, mode = { default = 'eco' },\n"
	            "             step = { default = 1, values = { 1, 2 } }, on = { default = false } },\n"
	            "  variables = { pick = { set = true, values = { 'a', 'b' } } },\n"
	            "  tick = function() end,\n"
	            "  input = function(dev, name, value)\n"
	            "    if value == 13 or value == 'never' then return nil, 'not that one' end\n"
	            "    return true\n"
	            "  end }\n");
	struct vmac_value v;
	char reply[200], err[VMAC_DRIVER_ERR_MAX] = "";
	vmac_driver_add_board(d, 0, "b0");
	memset(&v, 0, sizeof(v));
	v.type = VMAC_VALUE_STRING;
	snprintf(v.str, sizeof(v.str), "fast");
	ck_assert_int_eq(vmac_driver_input(d, 0, "speed", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_VALUE);
	ck_assert_msg(strstr(reply, "expected a number, got a string") != NULL, "type refusal: %s", reply);
	v.type = VMAC_VALUE_NONE; /* JSON null: true, no number either */
	ck_assert_int_eq(vmac_driver_input(d, 0, "speed", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_VALUE);
	v.type = VMAC_VALUE_NUMBER;
	v.number = 3;
	ck_assert_int_eq(vmac_driver_input(d, 0, "mode", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_VALUE);
	ck_assert_msg(param_value(d, "speed").number == 10 && param_value(d, "mode").type == VMAC_VALUE_STRING,
	              "a refused value of another type was set");

	v.number = 13; /* in range, refused by the driver */
	ck_assert_int_eq(vmac_driver_input(d, 0, "speed", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_BY_DRIVER);
	ck_assert_msg(param_value(d, "speed").number == 10, "the driver refused 13, yet speed is %g",
	              param_value(d, "speed").number);
	v.number = 42;
	ck_assert_int_eq(vmac_driver_input(d, 0, "speed", &v, reply, sizeof(reply), err, sizeof(err)), 0);
	ck_assert_msg(param_value(d, "speed").number == 42, "speed taken but not set");

	v.type = VMAC_VALUE_BOOL;
	v.number = 1;
	ck_assert_int_eq(vmac_driver_input(d, 0, "on", &v, reply, sizeof(reply), err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_driver_input(d, 0, "step", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_VALUE);
	ck_assert_int_eq(vmac_driver_input(d, 0, "pick", &v, reply, sizeof(reply), err, sizeof(err)),
	                 VMAC_REFUSED_VALUE);
	ck_assert_msg(strstr(reply, "'true' is not one of the allowed values") != NULL,
	              "a boolean refused by a list of values: %s", reply);
	vmac_driver_free(d);
}
END_TEST

START_TEST(sandbox_bounds)
{
	static const char *const refused[] = {"string.format = nil",
	                                      "rawset(string, 'x', 1)",
	                                      "setmetatable(math, {})",
	                                      "('x'):rep(1e9)",
	                                      "string.find(string.rep('a', 5000), '.-.-.-.-b')",
	                                      "getfenv(0)",
	                                      "os.execute('true')",
	                                      "io.open('x')",
	                                      "require('pid')",
	                                      "vmac.cycles()",
	                                      "while true do pcall(function() while true do end end) end",
	                                      "local t = {} for i = 1, 1e7 do t[i] = {} end"};
	static const char *const allowed[] = {
	    "assert(('x 12 y'):match('%d+') == '12')",
	    "assert(('  hi  '):match('^%s*(.-)%s*$') == 'hi')",
	    "assert(string.find(string.rep('a', 60000) .. 'b', 'ab', 1, true) == 60000)",
	    "assert(select(2, string.gsub('abc', '%a', function(c) return c:upper() end)) == 3)",
	    "assert(os.clock() == 7.25)",
	    "assert(string.gsub(string.rep('word ', 500), '[a-z]+', 'w') ~= nil)"};
	size_t i;
	for (i = 0; i < sizeof(refused) / sizeof(refused[0]); i++) {
		char src[400], err[VMAC_DRIVER_ERR_MAX] = "";
		struct vmac_inputs in;
		struct vmac_outputs out;
		struct vmac_driver *d;
		snprintf(src, sizeof(src), "return { name = 't', version = '1', io = {}, tick = function() %s end }\n",
		         refused[i]);
		d = load_ok(src);
		vmac_driver_add_board(d, 0, "b0");
		memset(&in, 0, sizeof(in));
		ck_assert_msg(tick1(d, 7.25, &in, &out, err, sizeof(err)) != 0, "sandbox let this through: %s",
		              refused[i]);
		vmac_driver_free(d);
	}
	for (i = 0; i < sizeof(allowed) / sizeof(allowed[0]); i++) {
		char src[400], err[VMAC_DRIVER_ERR_MAX] = "";
		struct vmac_inputs in;
		struct vmac_outputs out;
		struct vmac_driver *d;
		snprintf(src, sizeof(src), "return { name = 't', version = '1', io = {}, tick = function() %s end }\n",
		         allowed[i]);
		d = load_ok(src);
		vmac_driver_add_board(d, 0, "b0");
		memset(&in, 0, sizeof(in));
		ck_assert_msg(tick1(d, 7.25, &in, &out, err, sizeof(err)) == 0, "sandbox refused '%s': %s", allowed[i],
		              err);
		vmac_driver_free(d);
	}
}
END_TEST

/* Append printf-style to src (size cap), at *n. */
__attribute__((format(printf, 4, 5))) static void add(char *src, size_t cap, size_t *n, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	*n += (size_t)vsnprintf(src + *n, cap - *n, fmt, ap);
	va_end(ap);
	ck_assert_msg(*n < cap, "the checking driver is larger than %zu bytes", cap);
}

/* Whether LuaJIT's own libraries (a plain state) have lib.name (lib NULL:
 * the global name). */
static int luajit_has(lua_State *plain, const char *lib, const char *name)
{
	int has;
	lua_getglobal(plain, lib ? lib : name);
	has = lib ? lua_istable(plain, -1) : !lua_isnil(plain, -1);
	if (has && lib) {
		lua_getfield(plain, -1, name);
		has = !lua_isnil(plain, -1);
		lua_pop(plain, 1);
	}
	lua_pop(plain, 1);
	return has;
}

/* The sandbox is its allow-list (vmac_driver_allowed, which vmac lint gives
 * luacheck): no global outside it, and every name on it there: the host's
 * own always, a copied one whenever this LuaJIT has it (rawlen only with
 * its 5.2 extensions). Checked from inside a driver, as it loads. */
START_TEST(sandbox_is_exactly_the_allow_list)
{
	static char src[32768];
	size_t n = 0;
	const struct vmac_driver_lib *lib;
	const char *const *name;
	lua_State *plain = luaL_newstate();
	int own, checked = 0;
	ck_assert_ptr_nonnull(plain);
	luaL_openlibs(plain);
	add(src, sizeof(src), &n, "local listed = {\n");
	for (lib = vmac_driver_allowed; lib->copied; lib++) {
		if (lib->lib)
			add(src, sizeof(src), &n, "['%s'] = true,\n", lib->lib);
		else
			for (own = 0; own < 2; own++)
				for (name = own ? lib->own : lib->copied; *name; name++)
					add(src, sizeof(src), &n, "['%s'] = true,\n", *name);
	}
	add(src, sizeof(src), &n,
	    "}\nfor k in pairs(_G) do if not listed[k] then\n"
	    "  error('a global not in the allow-list: ' .. tostring(k)) end end\n");
	for (lib = vmac_driver_allowed; lib->copied; lib++)
		for (own = 0; own < 2; own++)
			for (name = own ? lib->own : lib->copied; *name; name++) {
				if (!own && !luajit_has(plain, lib->lib, *name))
					continue;
				checked++;
				add(src, sizeof(src), &n, "if %s['%s'] == nil then error('missing %s%s%s') end\n",
				    lib->lib ? lib->lib : "_G", *name, lib->lib ? lib->lib : "", lib->lib ? "." : "",
				    *name);
			}
	add(src, sizeof(src), &n, "return { name = 't', version = '1', io = {}, tick = function() end }\n");
	lua_close(plain);
	ck_assert_int_gt(checked, 80);
	vmac_driver_free(load_ok(src));
}
END_TEST

/* A heap of the caller's (vmac_driver_limits.heap): the C library's,
 * counting what it holds. */
static size_t heap_live;
static long heap_calls;
static void *counting_heap(void *ctx, void *ptr, size_t osize, size_t nsize)
{
	void *q;
	(void)ctx;
	heap_calls++;
	if (nsize == 0) {
		if (ptr)
			heap_live -= osize;
		free(ptr);
		return NULL;
	}
	q = realloc(ptr, nsize);
	if (q)
		heap_live += nsize - (ptr ? osize : 0);
	return q;
}

START_TEST(two_step_load_on_a_given_heap)
{
	struct vmac_driver *d;
	char err[VMAC_DRIVER_ERR_MAX] = "", big[64];
	const char *src = "local t = require 'twice'\n"
	                  "return { name = 't', version = '1', io = { lamp = 'do0' },\n"
	                  "  tick = function(dev) dev.out.lamp = t.f(1) == 2 end }\n";
	const char *head = "return { name = 't', version = '1', io = {}, tick = function() end }\n";
	struct vmac_driver_setting bad = {"colour", "red"};
	FILE *f;
	int i;
	mkdir(STDLIB_DIR, 0755);
	write_file(STDLIB_DIR "/twice.lua", "return { f = function(x) return 2 * x end }\n");
	heap_live = 0;
	heap_calls = 0;
	limits.heap = counting_heap;
	limits.expect_name = "t";

	/* Every byte of the state comes from the given heap, and the cap's
	 * accounting is what that heap holds. */
	ck_assert_int_eq(vmac_driver_new("t.lua", &limits, &d, err, sizeof(err)), 0);
	ck_assert_msg(heap_calls > 0 && heap_live == vmac_driver_memory(d),
	              "the sandbox did not come from the given heap: %ld calls, %zu bytes held, %zu counted",
	              heap_calls, heap_live, vmac_driver_memory(d));
	ck_assert_int_eq(vmac_driver_load_into(d, src, strlen(src), &limits, err, sizeof(err)), 0);
	ck_assert_str_eq(vmac_driver_name(d), "t");
	ck_assert_msg(heap_live == vmac_driver_memory(d), "%zu bytes held, %zu counted", heap_live,
	              vmac_driver_memory(d));
	/* One driver a sandbox. */
	ck_assert_int_eq(vmac_driver_load_into(d, src, strlen(src), &limits, err, sizeof(err)), -EALREADY);
	ck_assert_msg(strstr(err, "loaded in this sandbox already") != NULL, "%s", err);
	vmac_driver_free(d);
	ck_assert_msg(heap_live == 0, "%zu bytes left in the given heap after free", heap_live);

	/* The stdlib and cycles folders come with the load, not with the
	 * sandbox: one made without them loads a driver that requires. */
	limits.stdlib_dir = NULL;
	limits.programmes = NULL;
	ck_assert_int_eq(vmac_driver_new("t.lua", &limits, &d, err, sizeof(err)), 0);
	limits.stdlib_dir = STDLIB_DIR;
	use_folder(CYCLES_DIR);
	ck_assert_msg(vmac_driver_load_into(d, src, strlen(src), &limits, err, sizeof(err)) == 0,
	              "a sandbox made without a stdlib folder, loaded with one: %s", err);
	vmac_driver_free(d);

	/* A host setting it does not know refuses the load and says which. */
	limits.settings = &bad;
	limits.nsettings = 1;
	ck_assert_int_eq(vmac_driver_new("t.lua", &limits, &d, err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_driver_load_into(d, src, strlen(src), &limits, err, sizeof(err)), -EINVAL);
	ck_assert_msg(strstr(err, "driver.t.colour = 'red': unknown key") != NULL, "%s", err);
	vmac_driver_free(d);
	limits.settings = NULL;
	limits.nsettings = 0;
	limits.heap = NULL;

	/* A file is read whole at its own size, and one over 1 MiB is refused. */
	snprintf(big, sizeof(big), "/tmp/vmac-test-driver-big-%d.lua", (int)getpid());
	f = fopen(big, "w");
	ck_assert_msg(f != NULL, "cannot write %s", big);
	i = fputs(head, f) >= 0 ? (int)strlen(head) : 0;
	fputs("--", f);
	for (i += 3; i < 1 << 20; i++)
		fputc('x', f); /* exactly 1 MiB in all */
	fputc('\n', f);
	fclose(f);
	ck_assert_msg(vmac_driver_load(big, &limits, &d, err, sizeof(err)) == 0, "a 1 MiB driver: %s", err);
	vmac_driver_free(d);
	f = fopen(big, "a");
	fputs("-- and one line too many for 1 MiB\n", f);
	fclose(f);
	ck_assert_int_eq(vmac_driver_load(big, &limits, &d, err, sizeof(err)), -EFBIG);
	ck_assert_msg(strstr(err, "larger than 1 MiB") != NULL, "%s", err);
	unlink(big);
}
END_TEST

/* jit = true: a hot loop is compiled (the count hook, and so the budget,
 * stops there) where the host allows it, and interpreted (the budget
 * stops it) where it does not. */
START_TEST(jit_compiles_a_driver_only_where_allowed)
{
	static const char src[] = "return { name = 't', version = '1', io = {}, jit = true, tick = function()\n"
	                          "  local n = 0 for i = 1, 5000000 do n = n + i % 7 end end }\n";
	struct vmac_driver *d;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_inputs in;
	struct vmac_outputs out;
	int allow;
	memset(&in, 0, sizeof(in));
	for (allow = 0; allow <= 1; allow++) {
		limits.allow_jit = allow;
		d = load_ok(src);
		vmac_driver_add_board(d, 0, "b0");
		if (allow)
			ck_assert_msg(tick1(d, 0, &in, &out, err, sizeof(err)) == 0,
			              "allow_jit: the loop was not compiled (%s)", err);
		else
			ck_assert_msg(tick1(d, 0, &in, &out, err, sizeof(err)) != 0 &&
			                  strstr(err, "time budget exceeded") != NULL,
			              "without allow_jit the budget did not stop the loop (%s)", err);
		vmac_driver_free(d);
	}
}
END_TEST

/* A real-time thread on CPU 0 that, once told hog_at, wakes then and spins
 * there for HOG_NS, holding off every ordinary thread of that CPU. */
#define HOG_NS 60000000
static pthread_mutex_t hog_lock = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t hog_cond = PTHREAD_COND_INITIALIZER;
static int hog_ready, hog_rt;
static int64_t hog_at;
static int64_t mono_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}
static void *hog_main(void *arg)
{
	struct sched_param fifo = {.sched_priority = 1};
	struct timespec at;
	cpu_set_t cpu0;
	(void)arg;
	CPU_ZERO(&cpu0);
	CPU_SET(0, &cpu0);
	pthread_setaffinity_np(pthread_self(), sizeof(cpu0), &cpu0);
	pthread_mutex_lock(&hog_lock);
	hog_rt = pthread_setschedparam(pthread_self(), SCHED_FIFO, &fifo) == 0;
	hog_ready = 1;
	pthread_cond_broadcast(&hog_cond);
	while (hog_at == 0)
		pthread_cond_wait(&hog_cond, &hog_lock);
	at.tv_sec = (time_t)(hog_at / 1000000000);
	at.tv_nsec = (long)(hog_at % 1000000000);
	pthread_mutex_unlock(&hog_lock);
	clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL);
	while (mono_ns() < hog_at + HOG_NS) {
	}
	return NULL;
}

/* One tick of d on CPU 0 with the hog taking the CPU 1 ms into it; *took:
 * the tick's wall time. */
static int tick_held_off(struct vmac_driver *d, int64_t *took, char *err, size_t errlen)
{
	struct vmac_inputs in;
	struct vmac_outputs out;
	pthread_t hog;
	int64_t t0;
	int rc;
	memset(&in, 0, sizeof(in));
	hog_ready = 0;
	hog_at = 0;
	ck_assert_int_eq(pthread_create(&hog, NULL, hog_main, NULL), 0);
	pthread_mutex_lock(&hog_lock);
	while (!hog_ready)
		pthread_cond_wait(&hog_cond, &hog_lock);
	hog_at = mono_ns() + 1000000; /* inside the tick's 5 ms */
	pthread_cond_broadcast(&hog_cond);
	pthread_mutex_unlock(&hog_lock);
	t0 = mono_ns();
	rc = tick1(d, 0, &in, &out, err, errlen);
	*took = mono_ns() - t0;
	pthread_join(hog, NULL);
	ck_assert_msg(hog_rt, "SCHED_FIFO refused: this test needs root (or CAP_SYS_NICE)");
	return rc;
}

/* The wall-clock budget does not count time the machine kept the driver's
 * thread off its CPU: a tick of some 5 ms of work under a 40 ms budget, on
 * CPU 0, where a real-time thread takes the CPU for 60 ms in the middle of
 * it, passes (it took over 40 ms of wall time); a tick that keeps running
 * fails as ever. Needs SCHED_FIFO (root, as make test runs). */
START_TEST(a_thread_held_off_its_cpu_is_not_over_its_budget)
{
	struct vmac_driver *d;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_inputs in;
	struct vmac_outputs out;
	cpu_set_t cpu0;
	int64_t took = 0;
	int rc = -1, tries;
	limits.budget_us = 40000;
	limits.instructions = 100000000;
	d = load_ok("local calls = 0\n"
	            "return { name = 't', version = '1', io = {}, tick = function()\n"
	            "  local n = 0 for i = 1, 800000 do n = n + i end\n"
	            "  calls = calls + 1 if calls > 3 then while true do end end end }\n");
	limits.budget_us = 0;
	limits.instructions = 200000;
	vmac_driver_add_board(d, 0, "b0");
	CPU_ZERO(&cpu0);
	CPU_SET(0, &cpu0);
	ck_assert_int_eq(pthread_setaffinity_np(pthread_self(), sizeof(cpu0), &cpu0), 0);
	/* Up to three tries: a machine busy elsewhere may let the tick end
	 * before the hog wakes, which proves nothing either way. */
	for (tries = 0; tries < 3 && took <= 40000000; tries++) {
		rc = tick_held_off(d, &took, err, sizeof(err));
		ck_assert_msg(rc == 0, "a tick held off its CPU for 60 ms failed after %lld us: %s",
		              (long long)(took / 1000), err);
	}
	ck_assert_msg(took > 40000000,
	              "the tick took %lld us: the other thread did not hold it off (the test proves "
	              "nothing)",
	              (long long)(took / 1000));
	memset(&in, 0, sizeof(in));
	while (tries++ < 3) /* the ticks left before the one that runs on */
		ck_assert_int_eq(tick1(d, 0, &in, &out, err, sizeof(err)), 0);
	ck_assert_int_ne(tick1(d, 1, &in, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "time budget exceeded") != NULL, "a tick that runs on: %s", err);
	vmac_driver_free(d);
}
END_TEST

START_TEST(load_gets_a_larger_budget_and_stdlib)
{
	struct vmac_driver *d;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_inputs in;
	struct vmac_outputs out;
	mkdir(STDLIB_DIR, 0755);
	mkdir(CYCLES_DIR, 0755);
	write_file(STDLIB_DIR "/twice.lua", "return { f = function(x) return 2 * x end }\n");
	write_file(CYCLES_DIR "/b.lua", "return 'second'\n");
	write_file(CYCLES_DIR "/a.lua", "return 'first'\n");
	use_folder(CYCLES_DIR);
	/* About 3 budgets of work at load: allowed (50 budgets); in tick: refused. */
	d = load_ok("local n = 0 for i = 1, 150000 do n = n + i end\n"
	            "local t = require 'twice'\nlocal c = vmac.cycles()\n"
	            "assert(t.f(21) == 42 and c.a == 'first' and c.b == 'second')\n"
	            "for i = 1, 1000 do assert(require 'twice' == t) end\n" /* loaded once, then the same table */
	            "return { name = 't', version = '1', io = {}, tick = function()\n"
	            "  local n = 0 for i = 1, 150000 do n = n + i end end }\n");
	vmac_driver_add_board(d, 0, "b0");
	memset(&in, 0, sizeof(in));
	ck_assert_int_ne(tick1(d, 0, &in, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "time budget exceeded") != NULL, "tick-time overrun: %s", err);
	vmac_driver_free(d);
	write_file(CYCLES_DIR "/c.lua", "return (\n");
	use_folder(CYCLES_DIR);
	load_fails("vmac.cycles()\nreturn { name = 't', version = '1', io = {}, tick = function() end }\n",
	           "cycles/t/c.lua:");
	unlink(CYCLES_DIR "/c.lua");
	load_fails("require 'nosuch'\nreturn {}\n", "no such stdlib module");
}
END_TEST

/* A driver that asks for its programmes and has none fails to load, and
 * the error names the folder the programmes were looked for in. */
START_TEST(no_programmes_name_the_folder)
{
	static const char src[] =
	    "vmac.cycles()\nreturn { name = 't', version = '1', io = {}, tick = function() end }\n";
	const char *folder = "/tmp/vmac-test-driver-no-cycles";
	unlink("/tmp/vmac-test-driver-no-cycles/notes.txt");
	rmdir(folder);
	use_folder(folder); /* no such folder */
	load_fails(src, "t.lua:1: vmac.cycles: no programmes for t in /tmp/vmac-test-driver-no-cycles/");
	mkdir(folder, 0755); /* a folder with no NAME.lua in it */
	write_file("/tmp/vmac-test-driver-no-cycles/notes.txt", "not a programme\n");
	use_folder(folder);
	load_fails(src, "vmac.cycles: no programmes for t in /tmp/vmac-test-driver-no-cycles/");
	unlink("/tmp/vmac-test-driver-no-cycles/notes.txt");
	rmdir(folder);
	limits.programmes = NULL; /* a host that gives none */
	load_fails(src, "vmac.cycles: no programmes for t (the host gave none)");
}
END_TEST

/* A manifest's description is bounded: tables that refer to each other
 * made its walk exponential (fuzz_manifest: 286 bytes held a load for 7 s
 * under ASan and took a gigabyte of C heap), and one string under many keys
 * multiplies its text. */
START_TEST(a_description_past_its_bounds_is_refused)
{
	struct vmac_driver *d;
	char src[600];
	/* Found by the fuzzer: each of 20 variables holds the table of them all. */
	load_fails(
	    "local vars = {}\n"
	    "for i = 1, 20 do vars['v' .. i] = {e = 't', version = '1', variables = vars, tick = function() end} end\n"
	    "return { name = 't', version = '1', io = {}, variables = vars, tick = function() end }\n",
	    "manifest: too large to describe");
	/* One table under four keys a level: 4^9 values in the nine levels walked. */
	load_fails("local t = {} for i = 1, 12 do t = {a = t, b = t, c = t, d = t} end\n"
	           "return { name = 't', version = '1', io = {}, ui = t, tick = function() end }\n",
	           "more than 10000 values or 256 KiB of text");
	/* A list of 32,768 whose only element is its last (its length is
	 * 32,768 in LuaJIT), under 300 keys: 600 values walked, 9.8 million
	 * nulls written out for its holes. */
	load_fails("local t = {} for i = 1, 32768 do t[i] = 0 end for i = 1, 32767 do t[i] = nil end\n"
	           "assert(#t == 32768)\n"
	           "local ui = {} for i = 1, 300 do ui[i] = t end\n"
	           "return { name = 't', version = '1', io = {}, ui = ui, tick = function() end }\n",
	           "too large to describe");
	/* One string of 60 KB five times over. */
	load_fails("local s = string.rep('x', 60000)\n"
	           "return { name = 't', version = '1', io = {}, ui = {s, s, s, s, s}, tick = function() end }\n",
	           "too large to describe");
	/* Within both: 9,000 values, and 180 KB of text. */
	snprintf(src, sizeof(src), "%s",
	         "local ui, s = {}, string.rep('y', 60000) for i = 1, 9000 do ui[i] = i end\n"
	         "return { name = 't', version = '1', io = {}, ui = {ui, s, s, s}, tick = function() end }\n");
	d = load_ok(src);
	ck_assert_msg(strlen(vmac_driver_describe(d)) > 180000, "the description lost its text: %zu bytes",
	              strlen(vmac_driver_describe(d)));
	vmac_driver_free(d);
}
END_TEST

/* The bus thread's rule (docs/HOST.md, "Threads"): once a thread has said
 * it must not run Lua, no call into a driver's state runs there: the call
 * fails with the reason, and the driver is untouched (it ticks on another
 * thread afterwards). Built with VMAC_CHECK_THREADS (the sanitizer build)
 * the process aborts instead, which main() expects there. */
static void *forbidden_tick(void *arg)
{
	static char err[VMAC_DRIVER_ERR_MAX];
	struct vmac_inputs in;
	struct vmac_outputs out;
	memset(&in, 0, sizeof(in));
	vmac_driver_forbid_thread();
	if (tick1(arg, 1.0, &in, &out, err, sizeof(err)) == 0)
		return NULL;
	return err;
}

START_TEST(no_lua_runs_on_a_forbidden_thread)
{
	struct vmac_driver *d = load_ok("return { name = 't', version = '1', io = { lamp = 'do0' },\n"
	                                "  tick = function(dev) dev.out.lamp = true end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX];
	pthread_t th;
	void *why = NULL;
	memset(&in, 0, sizeof(in));
	vmac_driver_add_board(d, 0, "b");
	ck_assert_int_eq(pthread_create(&th, NULL, forbidden_tick, d), 0);
	pthread_join(th, &why);
	ck_assert_msg(why != NULL, "a driver ticked on a thread that must not run Lua");
	ck_assert_msg(strstr(why, "bus thread") != NULL, "the refusal does not say why: %s", (char *)why);
	ck_assert_msg(tick1(d, 2.0, &in, &out, err, sizeof(err)) == 0, "the driver failed after the refusal: %s", err);
	ck_assert_int_eq(out.digital, 1);
	vmac_driver_free(d);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("driver");
	TCase *tc = tcase_create("driver");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_set_timeout(tc, 60);
	tcase_add_test(tc, manifest_errors_name_the_field);
	tcase_add_test(tc, named_io_in_and_out);
	tcase_add_test(tc, bad_outputs_fail_and_turn_everything_off);
	tcase_add_test(tc, a_driver_error_has_one_clean_traceback);
	tcase_add_test(tc, replaced_tables_and_bad_variables_fail_by_name);
	tcase_add_test(tc, two_boards_one_machine);
	tcase_add_test(tc, variables_publish_by_their_rules);
	tcase_add_test(tc, input_and_host_hooks);
	tcase_add_test(tc, input_to_params_checks_type_and_refusals_change_nothing);
	tcase_add_test(tc, sandbox_bounds);
	tcase_add_test(tc, sandbox_is_exactly_the_allow_list);
	tcase_add_test(tc, load_gets_a_larger_budget_and_stdlib);
	tcase_add_test(tc, a_thread_held_off_its_cpu_is_not_over_its_budget);
	tcase_add_test(tc, jit_compiles_a_driver_only_where_allowed);
	tcase_add_test(tc, no_programmes_name_the_folder);
	tcase_add_test(tc, two_step_load_on_a_given_heap);
	tcase_add_test(tc, a_description_past_its_bounds_is_refused);
	tcase_add_test(tc, take_over_hands_plain_state_params_and_outputs);
	tcase_add_test(tc, take_over_refuses_what_it_cannot_copy);
#ifdef VMAC_CHECK_THREADS
	tcase_add_test_raise_signal(tc, no_lua_runs_on_a_forbidden_thread, SIGABRT); /* the checked build aborts */
#else
	tcase_add_test(tc, no_lua_runs_on_a_forbidden_thread);
#endif
	suite_add_tcase(s, tc);
	return s;
}
