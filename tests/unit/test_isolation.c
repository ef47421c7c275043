/* Unit tests of the protection rule of core/driver (docs/DRIVERS.md
 * "Isolation"): memory creeping under pcall at every entry point, states at
 * their cap when the host works on them, error objects with metamethods,
 * metamethods the host's reads could reach, and the atpanic handler. A
 * white-box test: through core/driver/internal.h it sets a state's cap to
 * what it holds and raises outside protection, which no driver can do.
 * Unprotected, any of these ends the process (LuaJIT's panic) or hangs it;
 * here each must come back as an error of that driver. At the end, the cost model of the
 * bounded library functions (core/driver/bounded.c): calls that would stall
 * the bus are refused, ordinary ones run, and d->lib_call names the call. */
#include <check.h>

#include "../../core/driver/internal.h"
#include "check_main.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static struct vmac_driver_limits limits;

static void setup(void)
{
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = 512 * 1024;
	limits.instructions = 2000000;
	limits.max_level = 10;
	limits.default_level = 4;
	limits.expect_name = "t";
}

/* Creeps up to the cap, catching every refused allocation: the driver
 * that ends a host in which pcall can swallow the cap. */
#define CREEP                                                                                                          \
	"local function creep() G = G or {} for i = 1, 1e7 do "                                                        \
	"if not pcall(function() G[#G + 1] = { i, i, i } end) then break end end end\n"

static int load_text(const char *text, struct vmac_driver **d, char *err, size_t errlen)
{
	return vmac_driver_load_source("t.lua", text, strlen(text), &limits, d, err, errlen);
}

static struct vmac_driver *load_ok(const char *text)
{
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load_text(text, &d, err, sizeof(err)) == 0, "load failed: %s", err);
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "b0"), 0);
	return d;
}

static int tick1(struct vmac_driver *d, double t, struct vmac_outputs *out, char *err, size_t errlen)
{
	struct vmac_inputs in;
	const struct vmac_inputs *ins[1] = {&in};
	struct vmac_outputs *outs[1] = {out};
	memset(&in, 0, sizeof(in));
	return vmac_driver_tick(d, t, ins, outs, err, errlen);
}

static void says(const char *err, const char *want, const char *where)
{
	ck_assert_msg(strstr(err, want) != NULL, "%s: error '%s' does not say '%s'", where, err, want);
}

START_TEST(creeping_memory_fails_the_call_at_every_entry)
{
	struct vmac_driver *d = NULL, *od;
	struct vmac_outputs out;
	struct vmac_value v = {VMAC_VALUE_BOOL, 1, ""};
	char err[VMAC_DRIVER_ERR_MAX] = "", reply[200];

	/* At load (the HTTP thread for an upload). */
	ck_assert_msg(load_text(CREEP "creep()\nreturn { name = 't', version = '1', io = {}, tick = function() end }",
	                        &d, err, sizeof(err)) != 0,
	              "a driver that creeps at load loaded");
	says(err, "memory cap exceeded", "load");

	/* In attach. */
	d = load_ok(CREEP "return { name = 't', version = '1', io = {}, attach = creep, tick = function() end }");
	ck_assert_msg(vmac_driver_attach(d, 0, err, sizeof(err)) != 0, "attach that creeps succeeded");
	says(err, "memory cap exceeded", "attach");
	vmac_driver_free(d);

	/* In tick, with an output on: every output off, and the next tick too. */
	d = load_ok(CREEP "return { name = 't', version = '1', io = { lamp = 'do0' },\n"
	                  "  tick = function(dev) dev.out.lamp = true creep() end }");
	out.digital = 0xff;
	ck_assert_msg(tick1(d, 0, &out, err, sizeof(err)) != 0, "tick that creeps succeeded");
	says(err, "memory cap exceeded", "tick");
	says(err, "t.lua", "tick (the file)");
	ck_assert_msg(out.digital == 0 && out.pwm == 0, "a failed tick left outputs 0x%02x", out.digital);
	tick1(d, 0.01, &out, err, sizeof(err)); /* the host must not, but it must survive it */
	ck_assert_msg(out.digital == 0, "a second tick after the failure drove 0x%02x", out.digital);
	vmac_driver_free(d);

	/* In input. */
	d = load_ok(CREEP "return { name = 't', version = '1', io = {}, commands = { go = {} },\n"
	                  "  input = function() creep() return true end, tick = function() end }");
	ck_assert_msg(vmac_driver_input(d, 0, "go", &v, reply, sizeof(reply), err, sizeof(err)) < 0,
	              "input that creeps was not a failure (reply '%s')", reply);
	says(err, "memory cap exceeded", "input");
	vmac_driver_free(d);

	/* In migrate (hot reload). */
	od = load_ok("return { name = 't', version = '1', io = {}, attach = function(dev) dev.state.n = 1 end,\n"
	             "  tick = function() end }");
	ck_assert_int_eq(vmac_driver_attach(od, 0, err, sizeof(err)), 0);
	d = load_ok(CREEP "return { name = 't', version = '2', io = {}, migrate = creep, tick = function() end }");
	ck_assert_msg(vmac_driver_take_over(d, od, 0, err, sizeof(err)) != 0, "migrate that creeps succeeded");
	says(err, "memory cap exceeded", "migrate");
	vmac_driver_free(d);
	vmac_driver_free(od);

	/* In detach: errors are ignored, the process lives. */
	d = load_ok(CREEP "return { name = 't', version = '1', io = {}, detach = creep, tick = function() end }");
	vmac_driver_detach(d, "test");
	vmac_driver_free(d);
}
END_TEST

START_TEST(every_way_of_catching_the_refusal_is_refused)
{
	static const char *const catchers[] = {
	    "pcall(function() local t = {} for i = 1, 1e7 do t[i] = {} end end)",
	    "xpcall(function() local t = {} for i = 1, 1e7 do t[i] = {} end end, function(e) return e end)",
	    "coroutine.resume(coroutine.create(function() local t = {} for i = 1, 1e7 do t[i] = {} end end))",
	    "pcall(coroutine.wrap(function() local t = {} for i = 1, 1e7 do t[i] = {} end end))",
	    "pcall(function() pcall(function() local t = {} for i = 1, 1e7 do t[i] = {} end end) end)",
	    "pcall(string.rep, 'x', 60000) local s = {} for i = 1, 1e6 do "
	    "if not pcall(function() s[i] = string.rep('y', 60000) .. i end) then break end end"};
	size_t i;
	for (i = 0; i < sizeof(catchers) / sizeof(catchers[0]); i++) {
		char src[600], err[VMAC_DRIVER_ERR_MAX] = "";
		struct vmac_outputs out;
		struct vmac_driver *d;
		snprintf(src, sizeof(src), "return { name = 't', version = '1', io = {}, tick = function() %s end }",
		         catchers[i]);
		d = load_ok(src);
		ck_assert_msg(tick1(d, 0, &out, err, sizeof(err)) != 0, "the driver caught the refusal: %s",
		              catchers[i]);
		says(err, "memory cap exceeded", catchers[i]);
		says(err, "t.lua:1:", catchers[i]); /* the refusal re-raised where it was caught: a traceback */
		vmac_driver_free(d);
	}
}
END_TEST

/* The host's work on a state at its cap: inputs, params, level, boards,
 * copied state. With the reserve it goes through and the driver's next
 * allocation fails; past the reserve, the host's work itself fails, as an
 * error of that driver. */
START_TEST(a_state_at_its_cap_fails_as_a_driver_not_the_host)
{
	static const char *const text =
	    "local ballast = {} for i = 1, 4000 do ballast[i] = { i } end\n" /* more than the reserve */
	    "return { name = 't', version = '1', io = { a = 'ai0', b = 'di1', lamp = 'do0' },\n"
	    "  params = { p = { default = 1, persist = true } },\n"
	    "  input = function() return true end,\n"
	    "  tick = function(dev, inputs) dev.state.x = { inputs.a, #ballast } end }";
	struct vmac_variable p[VMAC_DRIVER_MAX_PARAMS];
	struct vmac_value v = {VMAC_VALUE_NUMBER, 2, ""};
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "", why[200] = "", reply[200];
	struct vmac_driver *d, *od;
	int k;

	/* At the cap, within the reserve: the host's part works, the driver's
	 * allocation is refused. */
	d = load_ok(text);
	d->cap = d->used;
	vmac_driver_set_level_now(d, 3);
	ck_assert_int_eq(vmac_driver_params(d, p), 1);
	ck_assert_msg(tick1(d, 0, &out, err, sizeof(err)) != 0, "a tick that allocates at the cap succeeded");
	says(err, "memory cap exceeded", "tick at the cap");
	vmac_driver_free(d);

	/* Past the reserve too: every entry point fails, none crashes. */
	for (k = 0; k < 6; k++) {
		d = load_ok(text);
		ck_assert_msg(d->used > HOST_RESERVE, "the state holds less than the reserve");
		d->cap = d->used - HOST_RESERVE;
		err[0] = 0;
		switch (k) {
		case 0:
			vmac_driver_set_level_now(d, 3); /* no error to return: the next call fails */
			ck_assert_int_ne(tick1(d, 0, &out, err, sizeof(err)), 0);
			break;
		case 1:
			vmac_driver_add_board(d, 7, "b7");
			ck_assert_int_ne(vmac_driver_attach(d, 0, err, sizeof(err)), 0);
			break;
		case 2: ck_assert_int_ne(tick1(d, 0, &out, err, sizeof(err)), 0); break;
		case 3:
			ck_assert_int_ne(vmac_driver_input(d, 0, "p", &v, reply, sizeof(reply), err, sizeof(err)), 0);
			ck_assert_msg(err[0] || reply[0], "input at the cap said nothing");
			break;
		case 4:
			vmac_driver_restore_param(d, "p", &v, why, sizeof(why));
			vmac_driver_params(d, p);
			ck_assert_int_ne(tick1(d, 0, &out, err, sizeof(err)), 0);
			break;
		case 5: /* a migrated dev.state into a state at its cap */
			od = load_ok("return { name = 't', version = '1', io = {},\n"
			             "  attach = function(dev) for i = 1, 2000 do dev.state[i] = { i } end end,\n"
			             "  tick = function() end }");
			ck_assert_int_eq(vmac_driver_attach(od, 0, err, sizeof(err)), 0);
			ck_assert_int_ne(vmac_driver_take_over(d, od, 0, err, sizeof(err)), 0);
			vmac_driver_free(od);
			break;
		}
		if (k != 3)
			says(err, "memory cap exceeded", "past the reserve");
		vmac_driver_free(d);
	}
}
END_TEST

START_TEST(error_objects_with_metamethods)
{
	static const char *const objects[] = {
	    "setmetatable({}, { __tostring = function() while true do end end })",
	    "setmetatable({}, { __tostring = function() error('inner') end, __index = function() error('x') end })",
	    "setmetatable({}, { __concat = function() while true do end end, __eq = function() return true end })",
	    "coroutine.create(function() end)",
	    "function() end",
	    "nil",
	    "42",
	    "true"};
	size_t i;
	for (i = 0; i < sizeof(objects) / sizeof(objects[0]); i++) {
		char src[400], err[VMAC_DRIVER_ERR_MAX] = "";
		struct vmac_outputs out;
		struct vmac_driver *d;
		snprintf(src, sizeof(src),
		         "return { name = 't', version = '1', io = {}, tick = function() error(%s) end }", objects[i]);
		d = load_ok(src);
		ck_assert_msg(tick1(d, 0, &out, err, sizeof(err)) != 0, "error(%s) did not fail the tick", objects[i]);
		ck_assert_msg(err[0] != 0, "error(%s) gave no message", objects[i]);
		vmac_driver_free(d);
	}
}
END_TEST

/* An error in the error handler (a stack overflow leaves it no room) still
 * comes back with what LuaJIT said. */
START_TEST(a_stack_overflow_says_so)
{
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_outputs out;
	struct vmac_driver *d;
	limits.memory_bytes = 4 << 20; /* the default cap: the stack overflows before the heap is full */
	d = load_ok("return { name = 't', version = '1', io = {},\n"
	            "  tick = function() local function f() return 1 + f() end f() end }");
	ck_assert_int_ne(tick1(d, 0, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "stack overflow") || strstr(err, "error in error handling"),
	              "a stack overflow said '%s'", err);
	vmac_driver_free(d);
}
END_TEST

/* Metamethods on what the host reads or writes never run unbounded: the
 * host's accesses are raw, and the hook is armed for all its work. */
START_TEST(metamethods_the_host_could_reach)
{
	struct vmac_outputs out;
	struct vmac_variable p[VMAC_DRIVER_MAX_PARAMS];
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_driver *d;
	/* A manifest whose absent fields loop when read. */
	ck_assert_int_ne(
	    load_text("return setmetatable({ name = 't', version = '1', io = {}, tick = function() end },\n"
	              "  { __index = function() while true do end end })",
	              &d, err, sizeof(err)),
	    0);
	d = load_ok("local loop = { __index = function() while true do end end,\n"
	            "  __newindex = function() while true do end end }\n"
	            "return { name = 't', version = '1', io = { lamp = 'do0', a = 'ai0' }, variables = { v = {} },\n"
	            "  params = { p = { default = 1 } },\n"
	            "  tick = function(dev, inputs)\n"
	            "    if getmetatable(dev) then return end\n"
	            "    dev.params.p = nil setmetatable(dev.params, loop)\n"
	            "    inputs.a = nil setmetatable(inputs, loop)\n"
	            "    setmetatable(dev.out, loop) setmetatable(dev.vars, loop) setmetatable(dev, loop)\n"
	            "  end }");
	ck_assert_msg(tick1(d, 0, &out, err, sizeof(err)) == 0, "first tick: %s", err);
	ck_assert_int_eq(vmac_driver_params(d, p), 1);
	ck_assert_msg(p[0].value.type == VMAC_VALUE_NONE, "the removed param reads as something");
	vmac_driver_set_level_now(d, 2);
	ck_assert_msg(tick1(d, 0.1, &out, err, sizeof(err)) == 0, "second tick: %s", err);
	ck_assert_msg(out.digital == 0, "an output the driver never set is on");
	vmac_driver_free(d);
}
END_TEST

/* The last line: an error raised outside every protected call is reported
 * with the driver's name, and the driver is never touched again. */
START_TEST(an_unprotected_error_stops_the_driver_not_the_process)
{
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_driver *d = load_ok("return { name = 't', version = '1', io = {}, tick = function() end }");
	if (setjmp(d->panic_jmp) == 0) {
		d->panic_armed = 1;
		lua_pushliteral(d->L, "boom outside");
		lua_error(d->L); /* no protected call: LuaJIT's panic */
		ck_abort_msg("lua_error returned");
	}
	d->panic_armed = 0;
	d->broken = 1; /* as protect() does when it lands here */
	says(d->broken_msg, "boom outside", "the panic message");
	ck_assert_int_ne(tick1(d, 0, &out, err, sizeof(err)), 0);
	says(err, "error outside a protected call", "a tick after the panic");
	vmac_driver_free(d);
}
END_TEST

/* The bounded library functions (core/driver/bounded.c): a call whose
 * worst case is over PATTERN_STEPS_MAX steps is refused before it runs,
 * naming the function, each for the work the old cost model priced at
 * nothing; the ordinary calls next to them still run. S is 64 KiB, the
 * cap a driver's default. */
START_TEST(costly_library_calls_are_refused_and_ordinary_ones_run)
{
	static const struct {
		const char *code, *refusal; /* NULL: it must run */
	} cases[] = {
	    {"S:find('[' .. string.rep('b', 300) .. ']')", "string.find: pattern too costly"},
	    {"S:find(string.rep('a', 300) .. '.b')", "string.find: pattern too costly"},
	    {"(S .. S):find(string.rep('a', 60000) .. 'b', 1, true)", "string.find: plain search too costly"},
	    {"(S .. S):find(string.rep('a', 60000) .. 'b')", "string.find: plain search too costly"},
	    {"S:match('^.-' .. string.rep('a', 300) .. 'b')", "string.match: pattern too costly"},
	    {"string.rep('(', 65536):find('%b()')", "string.find: pattern too costly"},
	    {"S:find('%f[' .. string.rep('b', 300) .. ']')", "string.find: pattern too costly"},
	    {"S:find('a*a*b')", "string.find: pattern too costly"},
	    {"S:find('a*a*b', 2 ^ 32 + 1)", "string.find: pattern too costly"}, /* LuaJIT: the whole subject */
	    {"string.gmatch(string.rep('^', 2000), '^.-.-b')", "string.gmatch: pattern too costly"},
	    {"S:gsub('(x?)', string.rep('%1', 100))", "string.gsub: pattern too costly"},
	    {"S:gsub('a', string.rep('y', 1000))", "string.gsub: pattern too costly"},
	    {"(S .. S .. S .. S):gsub('', function() end)", "string.gsub: pattern too costly"},
	    {"local a, b, t = S .. 'a', S .. 'b', {} for i = 1, 2000 do t[i] = i % 2 == 0 and a or b end "
	     "table.sort(t)",
	     "table.sort: too costly"},
	    {"table.insert({}, -2 ^ 31 + 1, true)", "table.insert: too costly"},
	    {"table.insert({}, 1e10, true)", "table.insert: too costly"},
	    {"table.insert({}, '-100000000', true)", "table.insert: too costly"},
	    {"assert(S:find('a*a*b', -40) == nil)", NULL},
	    {"assert(select(2, S:gsub('a', string.rep('y', 1000), 1)) == 1)", NULL},
	    {"assert((string.rep(' ', 500) .. 'x y' .. string.rep(' ', 500)):match('^%s*(.-)%s*$') == 'x y')", NULL},
	    {"assert(select(2, (string.rep('word ', 13000) .. string.rep('word ', 13000)):gsub('%a+', 'w')) == 26000)",
	     NULL},
	    {"local n = 0 for k, v in string.rep('key=value,', 20):gmatch('(%w+)=(%w+)') do n = n + 1 end "
	     "assert(n == 20)",
	     NULL},
	    {"assert(S:find(string.rep('a', 1000), 1, true) == 1 and S:find('[^a]') == nil)", NULL},
	    {"assert(('f(a(b)c) g(d)'):gsub('%b()', '') == 'f g')", NULL},
	    {"local t = {} for i = 1, 5000 do t[i] = i * 7919 % 5003 end table.sort(t) "
	     "table.sort(t, function(x, y) return x > y end) for i = 2, 5000 do assert(t[i - 1] > t[i]) end",
	     NULL},
	    {"local t = {} for i = 1, 10000 do t[i] = i end table.insert(t, 1, 0) assert(t[1] == 0 and t[10001] == "
	     "10000)",
	     NULL},
	};
	size_t i;
	limits.memory_bytes = 4096 * 1024; /* a driver's default cap */
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		char src[600], err[VMAC_DRIVER_ERR_MAX] = "";
		struct vmac_outputs out;
		struct vmac_driver *d;
		int rc;
		snprintf(src, sizeof(src),
		         "local S = string.rep('a', 65536)\n"
		         "return { name = 't', version = '1', io = {}, tick = function() %s end }\n",
		         cases[i].code);
		d = load_ok(src);
		rc = tick1(d, 0, &out, err, sizeof(err));
		if (cases[i].refusal) {
			ck_assert_msg(rc != 0, "ran, though too costly: %s", cases[i].code);
			says(err, cases[i].refusal, cases[i].code);
		} else {
			ck_assert_msg(rc == 0, "refused an ordinary call: %s: %s", cases[i].code, err);
		}
		ck_assert_msg(d->lib_call == NULL, "lib_call left at '%s' after %s", d->lib_call, cases[i].code);
		vmac_driver_free(d);
	}
}
END_TEST

/* What the heap saw of d->lib_call: the names in the order they changed. */
struct lib_call_watch {
	struct vmac_driver *d;
	char seen[8][24];
	int n;
};

static void *watching_heap(void *ctx, void *ptr, size_t osize, size_t nsize)
{
	struct lib_call_watch *w = ctx;
	const char *now = w->d ? w->d->lib_call : NULL;
	(void)osize;
	if (now && (w->n == 0 || strcmp(w->seen[w->n - 1], now) != 0) && w->n < 8)
		snprintf(w->seen[w->n++], sizeof(w->seen[0]), "%s", now);
	if (nsize == 0) {
		free(ptr);
		return NULL;
	}
	return realloc(ptr, nsize);
}

/* d->lib_call names the bounded function running (an inner one while it
 * runs, then the outer one again), and nothing once it returns, even when
 * an error inside it was caught. */
START_TEST(lib_call_names_the_library_function_running)
{
	struct lib_call_watch w;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_driver *d;
	memset(&w, 0, sizeof(w));
	limits.heap = watching_heap;
	limits.heap_ctx = &w;
	d = load_ok("return { name = 't', version = '1', io = {}, tick = function()\n"
	            "  pcall(string.gsub, 'abc', '%a', function() error('caught') end)\n"
	            "  string.gsub('abc', '%a', function(c) return string.rep(c, 40) end) end }");
	w.d = d;
	ck_assert_msg(tick1(d, 0, &out, err, sizeof(err)) == 0, "tick: %s", err);
	ck_assert_msg(d->lib_call == NULL, "lib_call left at '%s' after the tick", d->lib_call);
	ck_assert_msg(w.n >= 3 && strcmp(w.seen[w.n - 3], "string.gsub") == 0 &&
	                  strcmp(w.seen[w.n - 2], "string.rep") == 0 && strcmp(w.seen[w.n - 1], "string.gsub") == 0,
	              "allocations saw lib_call as %d names, the last '%s'", w.n, w.n ? w.seen[w.n - 1] : "");
	w.d = NULL;
	vmac_driver_free(d);
}
END_TEST

/* The traceback's text cleaned (core/driver/traceback.c): each frame once,
 * no address of the host's C entry, the driver's line first. */
START_TEST(a_traceback_lists_each_frame_once_without_addresses)
{
	static const char doubled[] = "washer.lua:12: boom\nstack traceback:\n"
	                              "\t[C]: in function 'error'\n"
	                              "\twasher.lua:12: in function 'fill'\n"
	                              "\twasher.lua:12: in function 'fill'\n"
	                              "\t[C]: at 0x562db6e8f180\n"
	                              "\twasher.lua:40: in function <washer.lua:38>\n"
	                              "\twasher.lua:40: in function <washer.lua:38>\n"
	                              "\t[C]: at 0x562db6e8f180";
	char out[400], small[24];
	drv_traceback_clean(doubled, out, sizeof(out));
	ck_assert_str_eq(out, "washer.lua:12: boom\nstack traceback:\n"
	                      "\twasher.lua:12: in function 'fill'\n"
	                      "\twasher.lua:40: in function <washer.lua:38>");
	drv_traceback_clean("t.lua:1: boom\nstack traceback:\n\t[C]: in function 'error'\n\t[C]: at 0x1", out,
	                    sizeof(out));
	ck_assert_str_eq(out, "t.lua:1: boom");
	drv_traceback_clean("no traceback at all", out, sizeof(out));
	ck_assert_str_eq(out, "no traceback at all");
	drv_traceback_clean(doubled, small, sizeof(small));
	ck_assert_msg(strlen(small) == sizeof(small) - 1 && strncmp(small, doubled, sizeof(small) - 1) == 0,
	              "a short buffer does not hold the start of the text: '%s'", small);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("isolation");
	TCase *tc = tcase_create("isolation");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_set_timeout(tc, 60);
	tcase_add_test(tc, creeping_memory_fails_the_call_at_every_entry);
	tcase_add_test(tc, every_way_of_catching_the_refusal_is_refused);
	tcase_add_test(tc, a_state_at_its_cap_fails_as_a_driver_not_the_host);
	tcase_add_test(tc, error_objects_with_metamethods);
	tcase_add_test(tc, a_stack_overflow_says_so);
	tcase_add_test(tc, metamethods_the_host_could_reach);
	tcase_add_test(tc, an_unprotected_error_stops_the_driver_not_the_process);
	tcase_add_test(tc, costly_library_calls_are_refused_and_ordinary_ones_run);
	tcase_add_test(tc, lib_call_names_the_library_function_running);
	tcase_add_test(tc, a_traceback_lists_each_frame_once_without_addresses);
	suite_add_tcase(s, tc);
	return s;
}
