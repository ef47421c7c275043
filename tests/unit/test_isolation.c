/* Unit tests of the protection rule of core/driver (docs/DRIVERS.md
 * "Isolation"): memory creeping under pcall at every entry point, states at
 * their cap when the host works on them, error objects with metamethods,
 * metamethods the host's reads could reach, and the atpanic handler. A
 * white-box test: through core/driver/internal.h it sets a state's cap to
 * what it holds and raises outside protection, which no driver can do. Any of these
 * used to end the process (LuaJIT's panic) or hang it; here each must come
 * back as an error of that driver. */
#include <check.h>

#include "../../core/driver/internal.h"

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

/* Creeps up to the cap, catching every refused allocation: the pattern of
 * the driver that used to kill vmacd. */
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

int main(void)
{
	Suite *s = suite_create("isolation");
	TCase *tc = tcase_create("isolation");
	SRunner *sr;
	int failed;
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_set_timeout(tc, 60);
	tcase_add_test(tc, creeping_memory_fails_the_call_at_every_entry);
	tcase_add_test(tc, every_way_of_catching_the_refusal_is_refused);
	tcase_add_test(tc, a_state_at_its_cap_fails_as_a_driver_not_the_host);
	tcase_add_test(tc, error_objects_with_metamethods);
	tcase_add_test(tc, a_stack_overflow_says_so);
	tcase_add_test(tc, metamethods_the_host_could_reach);
	tcase_add_test(tc, an_unprotected_error_stops_the_driver_not_the_process);
	suite_add_tcase(s, tc);
	sr = srunner_create(s);
	srunner_run_all(sr, CK_NORMAL);
	failed = srunner_ntests_failed(sr);
	srunner_free(sr);
	return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
