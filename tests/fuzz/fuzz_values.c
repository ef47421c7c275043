/* libFuzzer harness for the conversion of values between the host and a
 * driver (core/driver/instance.c): dev.out into board outputs, dev.vars
 * into published variables, operator input (vmac_driver_input, checked
 * against the declarations) and params both ways (vmac_driver_params,
 * vmac_driver_restore_param). One fixed driver (below) runs a program of
 * operations the input spells (see struct op); between them the harness
 * writes any Lua value (nil, booleans, numbers of every kind, strings of
 * any bytes and length, tables, functions) into dev.out, dev.vars,
 * dev.params, dev.state or dev itself, as a driver could. White-box: it
 * reaches the state through core/driver/internal.h, as
 * tests/unit/test_isolation.c does. Seeds: tests/fuzz/corpus-values/. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/driver/internal.h"
#include "fuzz.h"
#include "fuzz_arena.h"

/* Every kind of I/O, on three boards (the primary, minor 7, minor
 * 0xFFFFFFFF); variables of every update rule, a group; params of every
 * type with ranges and value lists; commands. input() and tick() do what
 * dev.state tells them, so a program can make them refuse, fail or raise
 * any value. */
static const char DRIVER[] =
    "local driver = {\n"
    "  name = 'fuzz', version = '1.0',\n"
    "  io = {\n"
    "    lamp = 'do0', pump = 'do6', motor = 'pwm', door = 'di0', level = 'di7', count = 'encoder',\n"
    "    temp = { 'ai0', scale = 0.1, offset = -5 }, flow = 'ai1',\n"
    "    aux = { 'do1', board = 7 }, probe = { 'ai1', board = 7, scale = -1e300 },\n"
    "    far = { 'do2', board = 4294967295 }, far_in = { 'di3', board = 4294967295 },\n"
    "  },\n"
    "  variables = {\n"
    "    speed = { unit = 'rpm', set = true, min = 0, max = 1200 },\n"
    "    label = { set = true, values = { 'a', 'b' } },\n"
    "    ok = {},\n"
    "    t1 = { update = 'timer:0.5', group = 'g' }, t2 = { group = 'g' },\n"
    "    t3 = { update = 'auto', set = true },\n"
    "  },\n"
    "  params = {\n"
    "    fill_l = { default = 5, min = 0, max = 10, persist = true, unit = 'l' },\n"
    "    mode = { default = 'eco', values = { 'eco', 'quick', '' }, persist = true },\n"
    "    on = { default = false, persist = true },\n"
    "    gain = { default = 1.5 },\n"
    "    step = { default = 1, values = { 1, 2, 3 } },\n"
    "  },\n"
    "  commands = { start = { arg = 'mode' }, stop = {} },\n"
    "}\n"
    "function driver.tick(dev, inputs)\n"
    "  local s = dev.state\n"
    "  if s.tick_raise ~= nil then error(s.tick_raise, 0) end\n"
    "  s.last = inputs.time\n"
    "end\n"
    "function driver.input(dev, name, value)\n"
    "  local s = dev.state\n"
    "  if s.input_raise ~= nil then error(s.input_raise, 0) end\n"
    "  s.got = value\n"
    "  return s.ok, s.why\n"
    "end\n"
    "return driver\n";

static const char *const NAMES[] = {
    /* I/O */
    "lamp", "pump", "motor", "door", "level", "count", "temp", "flow", "aux", "probe", "far", "far_in",
    /* variables, params, commands */
    "speed", "label", "ok", "t1", "t2", "t3", "fill_l", "mode", "on", "gain", "step", "start", "stop",
    /* dev's own and dev.state's */
    "out", "vars", "params", "state", "boards", "tick_raise", "input_raise", "why", "got", "time", "", "name"};
#define NNAMES (sizeof(NAMES) / sizeof(NAMES[0]))

/* The input, read from the front; past its end every read is 0. */
struct reader {
	const uint8_t *p, *end;
};

static uint8_t byte(struct reader *r)
{
	return r->p < r->end ? *r->p++ : 0;
}

static double number(struct reader *r)
{
	static const double special[] = {0.0,          -0.0,         1,
	                                 -1,           1000,         -1000,
	                                 1000.5,       -1000.000001, 1e300,
	                                 -1e300,       5e-324,       9007199254740993.0,
	                                 4294967296.0, 2147483648.0, -2147483649.0,
	                                 10,           0.1};
	uint8_t k = byte(r);
	double x;
	size_t i;
	if (k < 64)
		return special[k % (sizeof(special) / sizeof(special[0]))];
	if (k < 80)
		return k & 1 ? INFINITY : -INFINITY;
	if (k < 88)
		return NAN;
	if (k < 160)
		return (double)(int8_t)byte(r);
	for (i = 0, x = 0; i < sizeof(x); i++)
		((uint8_t *)&x)[i] = byte(r);
	return x;
}

/* A name: one of NAMES, or raw bytes (NUL-terminated in buf). */
static const char *name(struct reader *r, char *buf, size_t len)
{
	uint8_t k = byte(r);
	size_t n, i;
	if (k < 2 * NNAMES)
		return NAMES[k % NNAMES];
	n = byte(r) % len;
	for (i = 0; i < n; i++)
		buf[i] = (char)byte(r);
	buf[n] = 0;
	return buf;
}

/* A host value as the API makes them (a string at most 63 bytes). */
static void host_value(struct reader *r, struct vmac_value *v)
{
	size_t n, i;
	memset(v, 0, sizeof(*v));
	v->type = (enum vmac_value_type)(byte(r) % 4);
	if (v->type == VMAC_VALUE_BOOL)
		v->number = byte(r) & 1;
	else if (v->type == VMAC_VALUE_NUMBER)
		v->number = number(r);
	else if (v->type == VMAC_VALUE_STRING) {
		uint8_t k = byte(r);
		if (k < 40) {
			snprintf(v->str, sizeof(v->str), "%s", NAMES[k % NNAMES]);
		} else {
			n = byte(r) % (VMAC_VALUE_STR_MAX + 1);
			for (i = 0; i < n; i++)
				v->str[i] = (char)byte(r);
		}
	}
}

static int c_function(lua_State *L)
{
	return lua_gettop(L);
}

/* Any Lua value a driver could make: [-0, +1]. */
static void push_lua_value(lua_State *L, struct reader *r)
{
	uint8_t k = byte(r);
	size_t n, i;
	char buf[300];
	switch (k % 10) {
	case 0: lua_pushnil(L); break;
	case 1: lua_pushboolean(L, 1); break;
	case 2: lua_pushboolean(L, 0); break;
	case 3:
	case 4: lua_pushnumber(L, number(r)); break;
	case 5:
		n = byte(r); /* up to 255 bytes: a string variable keeps 63 */
		for (i = 0; i < n; i++)
			buf[i] = (char)byte(r);
		lua_pushlstring(L, buf, n);
		break;
	case 6: lua_pushstring(L, NAMES[byte(r) % NNAMES]); break;
	case 7: lua_newtable(L); break;
	case 8:
		lua_createtable(L, 2, 0);
		lua_pushnumber(L, number(r));
		lua_rawseti(L, -2, 1);
		break;
	default: lua_pushcfunction(L, c_function); break;
	}
}

/* Write a value into dev.out, dev.vars, dev.params or dev.state, or into
 * dev itself (which may replace those tables): protected host work. */
static int set_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	static const char *const tables[] = {"out", "vars", "params", "state", NULL};
	struct reader *r = args;
	lua_State *L = d->L;
	const char *table = tables[byte(r) % 5];
	char buf[40];
	const char *key = name(r, buf, sizeof(buf));
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	if (table) {
		drv_raw_getfield(L, 1, table);
		if (!lua_istable(L, -1))
			return 0;
	}
	push_lua_value(L, r);
	drv_raw_setfield(L, lua_gettop(L) - 1, key);
	return 0;
}

/* The boards, in the order added; what each may have on. */
static uint32_t minors[VMAC_DRIVER_MAX_BOARDS];
static int nboards;
static int trace = -1; /* VMAC_FUZZ_TRACE set: each operation printed */

static uint8_t allowed_digital(int b)
{
	uint8_t bits = b == 0 ? 0x41 : 0; /* lamp do0, pump do6 on the primary */
	if (minors[b] == 7)
		bits |= 0x02; /* aux */
	if (minors[b] == 0xFFFFFFFFu)
		bits |= 0x04; /* far */
	return bits;
}

static int value_ok(const struct vmac_value *v)
{
	return v->type <= VMAC_VALUE_STRING && memchr(v->str, 0, sizeof(v->str)) != NULL &&
	       (v->type != VMAC_VALUE_BOOL || v->number == 0 || v->number == 1);
}

static int tick(struct vmac_driver *d, struct reader *r, double time_s)
{
	struct vmac_inputs in[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs out[VMAC_DRIVER_MAX_BOARDS];
	const struct vmac_inputs *ins[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs *outs[VMAC_DRIVER_MAX_BOARDS];
	char err[VMAC_DRIVER_ERR_MAX];
	int i, rc;
	for (i = 0; i < nboards; i++) {
		in[i].digital = byte(r);
		in[i].analog[0] = (uint16_t)(byte(r) << 4);
		in[i].analog[1] = (uint16_t)(byte(r) << 4);
		in[i].encoder = (int32_t)((uint32_t)byte(r) << 24 | byte(r));
		memset(&out[i], 0xAA, sizeof(out[i])); /* the driver's tick must write every one */
		ins[i] = &in[i];
		outs[i] = &out[i];
	}
	err[0] = 0;
	rc = vmac_driver_tick(d, time_s, ins, outs, err, sizeof(err));
	if (trace)
		fprintf(stderr, "fuzz_values: tick %d %s, board 0 digital 0x%02x pwm %d\n", rc, err, out[0].digital,
		        out[0].pwm);
	if (rc != 0 && (rc != -1 || !err[0]))
		abort();
	for (i = 0; i < nboards; i++) {
		if (out[i].digital & ~allowed_digital(i))
			abort(); /* on a channel no output of that board is declared on */
		if (out[i].pwm < -VMAC_PWM_MAX || out[i].pwm > VMAC_PWM_MAX || (i != 0 && out[i].pwm != 0))
			abort();
		if (rc != 0 && (out[i].digital || out[i].pwm))
			abort(); /* a failed tick drives nothing */
	}
	for (i = 0; i < vmac_driver_nvars(d); i++) {
		const struct vmac_variable *v = vmac_driver_variable(d, i);
		if (!value_ok(&v->value) || !memchr(v->name, 0, sizeof(v->name)))
			abort();
	}
	return rc;
}

/* The params as the status shows them: each a value of a type a param can
 * have, its string terminated. */
static void check_params(const struct vmac_driver *d)
{
	struct vmac_variable p[VMAC_DRIVER_MAX_PARAMS];
	int i, n = vmac_driver_params(d, p);
	if (n != vmac_driver_nparams(d))
		abort();
	for (i = 0; i < n; i++)
		if (!value_ok(&p[i].value) || !memchr(p[i].name, 0, sizeof(p[i].name)))
			abort();
}

static int same_value(const struct vmac_value *a, const struct vmac_value *b)
{
	if (a->type != b->type)
		return 0;
	if (a->type == VMAC_VALUE_STRING)
		return strcmp(a->str, b->str) == 0;
	return a->number == b->number || (a->number != a->number && b->number != b->number);
}

/* A refusal's message about a value that is no string (nor names one)
 * has no "(null)" in it: that was a NULL where the value's text should be. */
static void check_text(const char *text, const char *name, const struct vmac_value *v)
{
	if (v->type != VMAC_VALUE_STRING && !strstr(name, "(null)") && strstr(text, "(null)"))
		abort();
}

/* Operator input. Refused, it changes no param; taken, a param keeps the
 * type it had (what restoring a persisted value also insists on). */
static int input(struct vmac_driver *d, struct reader *r, double time_s)
{
	struct vmac_variable before[VMAC_DRIVER_MAX_PARAMS], after[VMAC_DRIVER_MAX_PARAMS];
	struct vmac_value v;
	char buf[40], reply[640], err[VMAC_DRIVER_ERR_MAX];
	const char *n = name(r, buf, sizeof(buf));
	int rc, i;
	host_value(r, &v);
	vmac_driver_params(d, before);
	err[0] = 0;
	memset(reply, 'x', sizeof(reply));
	rc = vmac_driver_input(d, time_s, n, &v, reply, sizeof(reply), err, sizeof(err));
	if (trace)
		fprintf(stderr, "fuzz_values: input %s (type %d) -> %d '%s' %s\n", n, (int)v.type, rc, reply,
		        rc < 0 ? err : "");
	if (rc < -1 || rc > VMAC_REFUSED_NOT_PERSIST || !memchr(reply, 0, sizeof(reply)) || (rc == -1 && !err[0]))
		abort();
	if (rc > 0 && rc != VMAC_REFUSED_BY_DRIVER && !reply[0])
		abort();                  /* refused without saying why */
	if (rc != VMAC_REFUSED_BY_DRIVER) /* the driver's own message may say anything */
		check_text(reply, n, &v);
	if (rc < 0)
		return rc;
	vmac_driver_params(d, after);
	for (i = 0; i < vmac_driver_nparams(d); i++) {
		if (rc > 0 && !same_value(&before[i].value, &after[i].value))
			abort(); /* a refused input changed a param */
		if (rc == 0 && strcmp(before[i].name, n) != 0 && !same_value(&before[i].value, &after[i].value))
			abort(); /* an input changed another param */
		if (rc == 0 && before[i].value.type != VMAC_VALUE_NONE && before[i].value.type != after[i].value.type)
			abort(); /* a param of one type took a value of another (NONE: the driver wrote a table there)
			          */
	}
	return rc;
}

static void restore(struct vmac_driver *d, struct reader *r)
{
	struct vmac_value v;
	char buf[40], why[200];
	const char *n = name(r, buf, sizeof(buf));
	int rc;
	host_value(r, &v);
	why[0] = 0;
	rc = vmac_driver_restore_param(d, n, &v, why, sizeof(why));
	if ((rc != 0 && rc != -1) || (rc != 0 && !why[0]))
		abort();
	check_text(why, n, &v);
}

/* An input is a program: [minor of the primary board] then operations,
 * each a byte (its low bits, see below) and its arguments. */
enum op { OP_SET, OP_TICK, OP_INPUT, OP_PARAMS, OP_RESTORE, OP_ADD_BOARD, OP_LEVEL, OP_PERSISTS, OP_COUNT };

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	static const uint32_t board_minors[] = {0, 7, 0xFFFFFFFFu, 1};
	struct vmac_driver *d = NULL;
	struct reader r = {data, data + size};
	char err[VMAC_DRIVER_ERR_MAX];
	double time_s = 1;
	int steps, alive = 1;

	if (size > 4096)
		return 0;
	if (trace < 0)
		trace = getenv("VMAC_FUZZ_TRACE") != NULL;
	d = fuzz_arena_fixed_driver("fuzz_values", DRIVER, sizeof(DRIVER) - 1, 1 << 20, 100000);
	nboards = 0;
	minors[nboards++] = board_minors[byte(&r) % 4];
	if (vmac_driver_add_board(d, minors[0], "primary") != 0)
		abort();
	for (steps = 0; alive && r.p < r.end && steps < 200; steps++) {
		char buf[40];
		uint32_t minor;
		enum op op = (enum op)(byte(&r) % OP_COUNT);
		if (trace)
			fprintf(stderr, "fuzz_values: op %d at byte %d\n", (int)op, (int)(r.p - data - 1));
		switch (op) {
		case OP_SET:
			if (drv_protect(d, set_work, &r, err, sizeof(err)) != 0)
				alive = 0; /* only out of memory, at the cap */
			break;
		case OP_TICK:
			time_s += byte(&r) / 16.0;
			alive = tick(d, &r, time_s) == 0;
			break;
		case OP_INPUT: alive = input(d, &r, time_s) >= 0; break;
		case OP_PARAMS: check_params(d); break;
		case OP_RESTORE: restore(d, &r); break;
		case OP_ADD_BOARD:
			minor = board_minors[byte(&r) % 4];
			if (vmac_driver_add_board(d, minor, "board") == 0) {
				if (nboards == VMAC_DRIVER_MAX_BOARDS)
					abort();
				minors[nboards++] = minor;
			}
			break;
		case OP_LEVEL: vmac_driver_set_level_now(d, byte(&r) % 11); break;
		case OP_PERSISTS:
			if (vmac_driver_param_persists(d, name(&r, buf, sizeof(buf))) < -1)
				abort();
			break;
		default: abort();
		}
	}
	if (trace)
		fprintf(stderr, "fuzz_values: %d operations, %s\n", steps,
		        alive ? "the driver runs" : "the driver failed");
	check_params(d);
	fuzz_arena_done(d);
	return 0;
}
