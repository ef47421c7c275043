/* `vmac test`: a LuaJIT state running core/vtest/runner.lua (the test API,
 * discovery of test files, reports) over the module "vmac.world" defined
 * here, a thin binding of world.h. Options and the API: docs/TESTING.md.
 *
 * Protection: every use of the runner's state happens inside the one
 * lua_pcall that runs runner.lua (the world's C functions here are called
 * from it), so no error on it can reach LuaJIT's panic; the drivers under
 * test run in states of their own, protected by core/driver/ as in vmacd. */
#include "vtest.h"

#include <lauxlib.h>
#include <lua.h>
#include <lualib.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/paths.h"
#include "replay.h"
#include "world.h"

#define WORLD_MT "vmac.world"

struct lworld {
	struct vt_world *w;
	lua_State *L;
	int check_ref;    /* the Lua function vt_run calls after each delivery */
	int check_failed; /* it raised: its error is on the stack */
};

/* The world's metatable, by reference: checks run at every tick, and
 * luaL_checkudata would look the metatable up by name each time. */
static int world_mt_ref = LUA_NOREF;

static struct lworld *check_world(lua_State *L)
{
	struct lworld *lw = lua_touserdata(L, 1);
	int ok;
	if (!lw || !lua_getmetatable(L, 1))
		luaL_typerror(L, 1, WORLD_MT);
	lua_rawgeti(L, LUA_REGISTRYINDEX, world_mt_ref);
	ok = lua_rawequal(L, -1, -2);
	lua_pop(L, 2);
	if (!ok)
		luaL_typerror(L, 1, WORLD_MT);
	if (!lw->w)
		luaL_error(L, "the world of this test is gone");
	return lw;
}

static struct vt_board *check_board(lua_State *L, struct lworld *lw, int i)
{
	const char *name = luaL_checkstring(L, i);
	struct vt_board *b = vt_board_find(lw->w, name);
	if (!b)
		luaL_error(L, "no board named '%s' in this test", name);
	return b;
}

/* The host's settings for a test: the defaults of vmac test with the
 * list of {key, value} at index idx over them. Raises on a bad one. */
static void test_config(lua_State *L, int idx, struct vmac_config *cfg)
{
	char err[512];
	int i, n;
	luaL_checktype(L, idx, LUA_TTABLE);
	vmac_config_defaults(cfg);
	vmac_config_shipped_dirs(cfg);
	cfg->realtime = 0;
	cfg->max_devices = 64;     /* a scene, not a plant floor: keeps each tick short */
	cfg->driver_budget_us = 0; /* the instruction budget only: deterministic */
	n = (int)lua_objlen(L, idx);
	for (i = 1; i <= n; i++) {
		const char *k, *v;
		lua_rawgeti(L, idx, i);
		lua_rawgeti(L, -1, 1);
		lua_rawgeti(L, -2, 2);
		k = lua_tostring(L, -2);
		v = lua_tostring(L, -1);
		if (!k || !v)
			luaL_error(L, "config: setting %d is not a key and a value", i);
		if (strcmp(k, "drivers") == 0)
			snprintf(cfg->drivers_dir, sizeof(cfg->drivers_dir), "%s", v);
		else if (vmac_config_set(cfg, k, v, err, sizeof(err)) != 0)
			luaL_error(L, "config: %s", err);
		lua_pop(L, 3);
	}
	if (vmac_config_check(cfg, err, sizeof(err)) != 0)
		luaL_error(L, "config: %s", err);
}

/* world.new(settings, seed): settings is a list of {key, value} strings
 * applied over the test defaults with the host's own config keys. */
static int l_new(lua_State *L)
{
	struct vmac_config cfg;
	char err[512];
	uint64_t seed = (uint64_t)luaL_checknumber(L, 2);
	struct lworld *lw;
	test_config(L, 1, &cfg);
	lw = lua_newuserdata(L, sizeof(*lw));
	memset(lw, 0, sizeof(*lw));
	lw->L = L;
	lw->check_ref = LUA_NOREF;
	luaL_getmetatable(L, WORLD_MT);
	lua_setmetatable(L, -2);
	lw->w = vt_world_new(&cfg, seed, err, sizeof(err));
	if (!lw->w)
		return luaL_error(L, "cannot build the world: %s", err);
	return 1;
}

/* world.replay(text, settings, use_recorded) -> rc, report: a flight
 * recording replayed against a driver (replay.c): rc 0 as recorded, 1
 * differs or fails, -1 cannot run. */
static int l_replay(lua_State *L)
{
	struct vmac_config cfg;
	size_t len;
	const char *text = luaL_checklstring(L, 1, &len);
	char *report = malloc(16384);
	int rc;
	test_config(L, 2, &cfg);
	if (!report)
		return luaL_error(L, "out of memory");
	rc = vt_replay(text, len, &cfg, lua_toboolean(L, 3), report, 16384);
	lua_pushinteger(L, rc);
	lua_pushstring(L, report);
	free(report);
	return 2;
}

static int l_gc(lua_State *L)
{
	struct lworld *lw = luaL_checkudata(L, 1, WORLD_MT);
	if (lw->w) {
		if (lw->w->trace)
			fflush(lw->w->trace);
		vt_world_free(lw->w);
		lw->w = NULL;
	}
	return 0;
}

/* w:board(name, plant, driver|nil, major|nil, minor|nil) -> io_note, driver */
static int l_board(lua_State *L)
{
	struct lworld *lw = check_world(L);
	const char *name = luaL_checkstring(L, 2), *plant = luaL_checkstring(L, 3);
	const char *driver = luaL_optstring(L, 4, NULL);
	char err[VMAC_DRIVER_ERR_MAX + 200];
	uint32_t major = lua_isnoneornil(L, 5) ? vmac_proto_default_major(name) : (uint32_t)luaL_checknumber(L, 5);
	uint32_t minor = (uint32_t)luaL_optnumber(L, 6, 0);
	struct vt_board *b;
	b = vt_board_add(lw->w, name, plant, driver, major, minor, err, sizeof(err));
	if (!b)
		return luaL_error(L, "%s", err);
	lua_pushstring(L, b->io_note);
	lua_pushstring(L, b->fw.id.driver);
	return 2;
}

/* The check after each delivery: calls the registered Lua function; a true
 * result stops the run; an error is kept on the stack for l_run to raise. */
static int run_check(void *ctx)
{
	struct lworld *lw = ctx;
	lua_State *L = lw->L;
	int stop;
	lua_rawgeti(L, LUA_REGISTRYINDEX, lw->check_ref);
	if (lua_pcall(L, 0, 1, 0) != 0) {
		lw->check_failed = 1;
		return 2;
	}
	stop = lua_toboolean(L, -1);
	lua_pop(L, 1);
	return stop;
}

/* w:run(until_s, check|nil) -> true when check stopped it; false and why
 * when a Lua plant failed (the test fails with it). */
static int l_run(lua_State *L)
{
	struct lworld *lw = check_world(L);
	double until = luaL_checknumber(L, 2);
	int rc, prev = lw->check_ref;
	if (!lua_isnoneornil(L, 3)) {
		luaL_checktype(L, 3, LUA_TFUNCTION);
		lua_pushvalue(L, 3);
		lw->check_ref = luaL_ref(L, LUA_REGISTRYINDEX);
	} else {
		lw->check_ref = LUA_NOREF;
	}
	lw->check_failed = 0;
	/* The test may have acted since the last run: check at the first tick. */
	lw->w->moved = 1;
	lw->w->check_reads_plant = 1;
	rc = vt_run(lw->w, (int64_t)(until * 1e9 + 0.5), lw->check_ref == LUA_NOREF ? NULL : run_check, lw);
	if (lw->check_ref != LUA_NOREF)
		luaL_unref(L, LUA_REGISTRYINDEX, lw->check_ref);
	lw->check_ref = prev;
	if (lw->check_failed)
		return lua_error(L); /* the check's error, as it was raised */
	if (rc == VT_PLANT_FAILED) {
		lua_pushboolean(L, 0);
		lua_pushstring(L, lw->w->plant_failure);
		return 2;
	}
	lua_pushboolean(L, rc != 0);
	return 1;
}

static int l_now(lua_State *L)
{
	struct lworld *lw = check_world(L);
	lw->w->reads_plant = 1; /* time moves on at every tick */
	lua_pushnumber(L, (double)lw->w->now_ns / 1e9);
	return 1;
}

/* w:io(board, name) -> value, or nil and why */
static int l_io(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	double v;
	int is_bool;
	if (vt_io_value(lw->w, b, luaL_checkstring(L, 3), &v, &is_bool) != 0) {
		lua_pushnil(L);
		lua_pushstring(L, b->io_note);
		return 2;
	}
	if (is_bool)
		lua_pushboolean(L, v != 0);
	else
		lua_pushnumber(L, v);
	return 1;
}

static int l_io_names(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	int i;
	lua_createtable(L, b->nio, 0);
	for (i = 0; i < b->nio; i++) {
		lua_pushstring(L, b->io[i].name);
		lua_rawseti(L, -2, i + 1);
	}
	return 1;
}

static void push_value(lua_State *L, const struct vmac_value *v)
{
	switch (v->type) {
	case VMAC_VALUE_NUMBER: lua_pushnumber(L, v->number); break;
	case VMAC_VALUE_BOOL: lua_pushboolean(L, v->number != 0); break;
	case VMAC_VALUE_STRING: lua_pushstring(L, v->str); break;
	default: lua_pushnil(L); break;
	}
}

/* w:state(device) -> "running", ..., or "absent" */
static int l_state(lua_State *L)
{
	struct lworld *lw = check_world(L);
	const char *name = luaL_checkstring(L, 2);
	lua_pushstring(L, lw->w->bus ? vmac_bus_device_state(lw->w->bus, name) : "absent");
	return 1;
}

/* w:var(device, name) -> value (nil when not published or no device) */
static int l_var(lua_State *L)
{
	struct lworld *lw = check_world(L);
	const char *device = luaL_checkstring(L, 2), *name = luaL_checkstring(L, 3);
	const struct vmac_variable *v = lw->w->bus ? vmac_bus_device_var(lw->w->bus, device, name) : NULL;
	if (v)
		push_value(L, &v->value);
	else
		lua_pushnil(L);
	return 1;
}

/* w:device(name) -> table of the host's view, or nil */
static int l_device(lua_State *L)
{
	struct lworld *lw = check_world(L);
	const struct vmac_device_status *d = vt_device(lw->w, luaL_checkstring(L, 2));
	int i;
	if (!d) {
		lua_pushnil(L);
		return 1;
	}
	lua_createtable(L, 0, 14);
	lua_pushstring(L, d->state);
	lua_setfield(L, -2, "state");
	lua_pushstring(L, d->driver);
	lua_setfield(L, -2, "driver");
	lua_pushstring(L, d->driver_version);
	lua_setfield(L, -2, "driver_version");
	lua_pushstring(L, d->machine);
	lua_setfield(L, -2, "machine");
	lua_pushstring(L, d->note);
	lua_setfield(L, -2, "note");
	lua_pushnumber(L, d->level);
	lua_setfield(L, -2, "level");
	lua_pushnumber(L, d->period_us);
	lua_setfield(L, -2, "period_us");
	lua_pushnumber(L, (double)d->misses);
	lua_setfield(L, -2, "misses");
	lua_pushnumber(L, (double)d->misses_host);
	lua_setfield(L, -2, "misses_host");
	lua_pushnumber(L, (double)d->driver_late);
	lua_setfield(L, -2, "driver_late");
	lua_pushnumber(L, (double)d->served);
	lua_setfield(L, -2, "served");
	lua_pushnumber(L, (double)d->driver_memory);
	lua_setfield(L, -2, "driver_memory");
	lua_createtable(L, 0, d->nvars);
	for (i = 0; i < d->nvars; i++) {
		push_value(L, &d->vars[i].value);
		lua_setfield(L, -2, d->vars[i].name);
	}
	lua_setfield(L, -2, "vars");
	return 1;
}

/* w:timers(board) -> { NAME = { every_s =, published_s = } }: the driver's
 * variables declared `update = "timer:N"`, each with its period and the
 * virtual time it was last published (nil before the first, or no host). */
static int l_timers(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	const struct vmac_device_status *d = vt_device(lw->w, b->fw.id.board);
	int i, j;
	lua_createtable(L, 0, b->ntimers);
	for (i = 0; i < b->ntimers; i++) {
		lua_createtable(L, 0, 2);
		lua_pushnumber(L, b->timers[i].every_s);
		lua_setfield(L, -2, "every_s");
		for (j = 0; d && j < d->nvars && strcmp(d->vars[j].name, b->timers[i].name) != 0; j++)
			;
		if (d && j < d->nvars && d->vars[j].published_s > 0) {
			lua_pushnumber(L, (double)lw->w->host_start_ns / 1e9 + d->vars[j].published_s);
			lua_setfield(L, -2, "published_s");
		}
		lua_setfield(L, -2, b->timers[i].name);
	}
	return 1;
}

/* w:input(device, name, value) -> rc (0 accepted, > 0 refused: a vmac_refusal, < 0 failed), reply */
static int l_input(lua_State *L)
{
	struct lworld *lw = check_world(L);
	const char *device = luaL_checkstring(L, 2), *name = luaL_checkstring(L, 3);
	struct vmac_value v;
	char reply[256] = "";
	int rc;
	memset(&v, 0, sizeof(v));
	switch (lua_type(L, 4)) {
	case LUA_TNONE:
	case LUA_TNIL: v.type = VMAC_VALUE_NONE; break;
	case LUA_TBOOLEAN:
		v.type = VMAC_VALUE_BOOL;
		v.number = lua_toboolean(L, 4);
		break;
	case LUA_TNUMBER:
		v.type = VMAC_VALUE_NUMBER;
		v.number = lua_tonumber(L, 4);
		break;
	case LUA_TSTRING:
		v.type = VMAC_VALUE_STRING;
		snprintf(v.str, sizeof(v.str), "%s", lua_tostring(L, 4));
		break;
	default: return luaL_error(L, "input: the value must be nil, a boolean, a number or a string");
	}
	rc = vt_input(lw->w, device, name, &v, reply, sizeof(reply));
	lua_pushnumber(L, rc);
	lua_pushstring(L, reply);
	return 2;
}

/* w:set(board, name, value): an operator action on the plant. */
static int l_set(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	const char *name = luaL_checkstring(L, 3);
	double v = lua_isboolean(L, 4) ? lua_toboolean(L, 4) : luaL_optnumber(L, 4, 1);
	char why[VMAC_DRIVER_ERR_MAX + 64];
	if (vmac_sim_set(&b->sim, name, v, why, sizeof(why)) != 0)
		return luaL_error(L, "%s: %s", b->fw.id.board, why);
	return 0;
}

/* w:plant(board, field): the plant's state, for checks a sensor cannot make. */
static int l_plant(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	const char *f = luaL_checkstring(L, 3);
	struct vmac_value v;
	lw->w->reads_plant = 1;
	if (vmac_sim_field(&b->sim, f, &v) != 0) {
		if (vmac_sim_failure(&b->sim))
			return luaL_error(L, "%s: the %s plant has failed: %s", b->fw.id.board, vmac_sim_name(&b->sim),
			                  vmac_sim_failure(&b->sim));
		return luaL_error(L, "%s: the %s plant has no field '%s' (%s; docs/TESTING.md)", b->fw.id.board,
		                  vmac_sim_name(&b->sim), f, vmac_sim_fields_text(&b->sim));
	}
	if (v.type == VMAC_VALUE_NUMBER)
		lua_pushnumber(L, v.number);
	else if (v.type == VMAC_VALUE_BOOL)
		lua_pushboolean(L, v.number != 0);
	else
		lua_pushstring(L, v.str);
	return 1;
}

/* w:connect(board, plugged, powered) */
static int l_connect(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	b->plugged = lua_toboolean(L, 3);
	if (lua_toboolean(L, 4) != b->powered)
		vt_board_power(lw->w, b, lua_toboolean(L, 4));
	return 0;
}

static double opt_field(lua_State *L, int t, const char *name, double lo, double hi)
{
	double v;
	lua_getfield(L, t, name);
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		return 0;
	}
	v = lua_tonumber(L, -1);
	if (lua_type(L, -1) != LUA_TNUMBER || !(v >= lo && v <= hi))
		luaL_error(L, "faults: %s must be a number in %g..%g", name, lo, hi);
	lua_pop(L, 1);
	return v;
}

/* w:faults(board, {drop=, corrupt=, delay=, delay_fraction=, late=}) */
static int l_faults(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	struct vt_faults f;
	luaL_checktype(L, 3, LUA_TTABLE);
	lua_pushnil(L);
	while (lua_next(L, 3)) {
		const char *k = lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : "?";
		if (strcmp(k, "drop") && strcmp(k, "corrupt") && strcmp(k, "delay") && strcmp(k, "delay_fraction") &&
		    strcmp(k, "late"))
			return luaL_error(L, "faults: unknown key '%s' (drop, corrupt, delay, delay_fraction, late)",
			                  k);
		lua_pop(L, 1);
	}
	f.drop = opt_field(L, 3, "drop", 0, 1);
	f.corrupt = opt_field(L, 3, "corrupt", 0, 1);
	f.delay_ns = (int64_t)(opt_field(L, 3, "delay", 0, 60) * 1e9);
	f.late_ns = (int64_t)(opt_field(L, 3, "late", 0, 60) * 1e9);
	lua_getfield(L, 3, "delay_fraction");
	f.delay_fraction = lua_isnil(L, -1) ? (f.delay_ns ? 1 : 0) : opt_field(L, 3, "delay_fraction", 0, 1);
	lua_pop(L, 1);
	b->faults = f;
	return 0;
}

/* w:events(from) -> list of {time=, kind=, device=, text=} from index from (1-based) */
static int l_events(lua_State *L)
{
	struct lworld *lw = check_world(L);
	size_t from = (size_t)luaL_optnumber(L, 2, 1), i;
	lua_createtable(L, 0, 0);
	for (i = from > 0 ? from - 1 : 0; i < lw->w->nevents; i++) {
		const struct vt_event *e = &lw->w->events[i];
		lua_createtable(L, 0, 4);
		lua_pushnumber(L, (double)e->t_ns / 1e9);
		lua_setfield(L, -2, "time");
		lua_pushstring(L, e->kind);
		lua_setfield(L, -2, "kind");
		lua_pushstring(L, e->device);
		lua_setfield(L, -2, "device");
		lua_pushstring(L, e->text);
		lua_setfield(L, -2, "text");
		lua_rawseti(L, -2, (int)(i + 2 - from));
	}
	return 1;
}

/* w:history(board) -> list of {time=, io = {name = value}} oldest first */
static int l_history(lua_State *L)
{
	struct lworld *lw = check_world(L);
	struct vt_board *b = check_board(L, lw, 2);
	lw->w->reads_plant = 1;
	unsigned n = b->nhist < VT_HISTORY ? b->nhist : VT_HISTORY, k;
	lua_createtable(L, (int)n, 0);
	for (k = 0; k < n; k++) {
		const struct vt_service *s = &b->hist[(b->nhist - n + k) % VT_HISTORY];
		int i;
		lua_createtable(L, 0, 3);
		lua_pushnumber(L, (double)s->t_ns / 1e9);
		lua_setfield(L, -2, "time");
		lua_createtable(L, 0, b->nio);
		for (i = 0; i < b->nio; i++) {
			const struct vt_io *io = &b->io[i];
			switch (io->kind) {
			case VMAC_IO_DO: lua_pushboolean(L, (s->out.digital >> io->channel) & 1); break;
			case VMAC_IO_PWM: lua_pushnumber(L, s->out.pwm); break;
			case VMAC_IO_DI: lua_pushboolean(L, (s->in.digital >> io->channel) & 1); break;
			case VMAC_IO_AI: lua_pushnumber(L, s->in.analog[io->channel] * io->scale + io->offset); break;
			default: lua_pushnumber(L, s->in.encoder); break;
			}
			lua_setfield(L, -2, io->name);
		}
		lua_setfield(L, -2, "io");
		lua_rawseti(L, -2, (int)k + 1);
	}
	return 1;
}

/* w:trace(file_handle|nil, test_name): CSV rows for every service. The
 * name is stored quoted for CSV ("" for a quote), cut to fit. */
static int l_trace(lua_State *L)
{
	struct lworld *lw = check_world(L);
	FILE **fp = lua_isnoneornil(L, 2) ? NULL : luaL_checkudata(L, 2, LUA_FILEHANDLE);
	const char *name = luaL_optstring(L, 3, "");
	char *q = lw->w->trace_test, *end = q + sizeof(lw->w->trace_test) - 2;
	lw->w->trace = fp ? *fp : NULL;
	*q++ = '"';
	for (; *name && q < end - 1; name++) {
		if (*name == '"')
			*q++ = '"';
		*q++ = *name;
	}
	*q++ = '"';
	*q = 0;
	return 0;
}

/* w:config(key, value): a host setting for drivers loaded from now on
 * (driver.NAME.param.KEY and the like). */
static int l_config(lua_State *L)
{
	struct lworld *lw = check_world(L);
	char err[256];
	if (vmac_config_set(&lw->w->cfg, luaL_checkstring(L, 2), luaL_checkstring(L, 3), err, sizeof(err)) != 0)
		return luaL_error(L, "config: %s", err);
	return 0;
}

/* w:driver_cost(driver, seconds) */
static int l_driver_cost(lua_State *L)
{
	struct lworld *lw = check_world(L);
	const char *driver = luaL_checkstring(L, 2);
	double s = luaL_checknumber(L, 3);
	char err[128];
	if (!(s >= 0 && s <= 60))
		return luaL_error(L, "driver_cost: seconds must be in 0..60, got %f", s);
	if (vt_driver_cost(lw->w, driver, (int64_t)(s * 1e9), err, sizeof(err)) != 0)
		return luaL_error(L, "%s", err);
	return 0;
}

/* w:clock(board) -> b.clock; w:set_clock(board, spec); w:clock_step(board, ppm) (clocks_lua.c) */
static int l_clock(lua_State *L)
{
	struct lworld *lw = check_world(L);
	return vt_lua_clock(L, lw->w, check_board(L, lw, 2));
}

static int l_set_clock(lua_State *L)
{
	struct lworld *lw = check_world(L);
	return vt_lua_set_clock(L, 3, lw->w, check_board(L, lw, 2));
}

static int l_clock_step(lua_State *L)
{
	struct lworld *lw = check_world(L);
	return vt_lua_clock_step(L, 3, lw->w, check_board(L, lw, 2));
}

static int l_slot(lua_State *L)
{
	lua_pushnumber(L, vmac_config_slot_us(&check_world(L)->w->cfg) / 1e6);
	return 1;
}

static int l_stop_host(lua_State *L)
{
	vt_stop_host(check_world(L)->w);
	return 0;
}

static int l_crash_host(lua_State *L)
{
	vt_crash_host(check_world(L)->w);
	return 0;
}

static int l_start_host(lua_State *L)
{
	char err[256];
	if (vt_start_host(check_world(L)->w, err, sizeof(err)) != 0)
		return luaL_error(L, "start_host: %s", err);
	return 0;
}

static int l_frames(lua_State *L)
{
	lua_pushnumber(L, (double)check_world(L)->w->frames);
	return 1;
}

/* world.wall(): a monotonic wall clock in seconds, for the runaway guard
 * and the speed figure. */
static int l_wall(lua_State *L)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	lua_pushnumber(L, (double)ts.tv_sec + (double)ts.tv_nsec / 1e9);
	return 1;
}

static int open_world(lua_State *L)
{
	static const luaL_Reg methods[] = {{"board", l_board},
	                                   {"run", l_run},
	                                   {"now", l_now},
	                                   {"io", l_io},
	                                   {"io_names", l_io_names},
	                                   {"state", l_state},
	                                   {"var", l_var},
	                                   {"device", l_device},
	                                   {"timers", l_timers},
	                                   {"input", l_input},
	                                   {"set", l_set},
	                                   {"plant", l_plant},
	                                   {"connect", l_connect},
	                                   {"faults", l_faults},
	                                   {"events", l_events},
	                                   {"history", l_history},
	                                   {"trace", l_trace},
	                                   {"stop_host", l_stop_host},
	                                   {"crash_host", l_crash_host},
	                                   {"start_host", l_start_host},
	                                   {"frames", l_frames},
	                                   {"free", l_gc},
	                                   {"config", l_config},
	                                   {"slot", l_slot},
	                                   {"driver_cost", l_driver_cost},
	                                   {"clock", l_clock},
	                                   {"set_clock", l_set_clock},
	                                   {"clock_step", l_clock_step},
	                                   {NULL, NULL}};
	static const luaL_Reg funcs[] = {{"new", l_new}, {"wall", l_wall}, {"replay", l_replay}, {NULL, NULL}};
	luaL_newmetatable(L, WORLD_MT);
	lua_pushvalue(L, -1);
	world_mt_ref = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_pushcfunction(L, l_gc);
	lua_setfield(L, -2, "__gc");
	lua_newtable(L);
	luaL_register(L, NULL, methods);
	lua_setfield(L, -2, "__index");
	lua_pop(L, 1);
	lua_newtable(L);
	luaL_register(L, NULL, funcs);
	return 1;
}

/* o as the runner's OPTS table (core/vtest/runner.lua). */
static void push_options(lua_State *L, const struct vmac_test_options *o)
{
	int i;
	lua_createtable(L, 0, 12);
	lua_createtable(L, o->npaths, 0);
	for (i = 0; i < o->npaths; i++) {
		lua_pushstring(L, o->paths[i]);
		lua_rawseti(L, -2, i + 1);
	}
	lua_setfield(L, -2, "paths");
#define OPT_STRING(name)                                                                                               \
	if (o->name) {                                                                                                 \
		lua_pushstring(L, o->name);                                                                            \
		lua_setfield(L, -2, #name);                                                                            \
	}
	OPT_STRING(drivers)
	OPT_STRING(replay)
	OPT_STRING(filter)
	OPT_STRING(junit)
	OPT_STRING(trace)
#undef OPT_STRING
	lua_pushnumber(L, (lua_Number)o->seed);
	lua_setfield(L, -2, "seed");
	lua_pushnumber(L, (lua_Number)o->history);
	lua_setfield(L, -2, "history");
	lua_pushnumber(L, o->time_limit_s);
	lua_setfield(L, -2, "time_limit");
	lua_pushnumber(L, o->timeout_s);
	lua_setfield(L, -2, "timeout");
	lua_pushboolean(L, o->list);
	lua_setfield(L, -2, "list");
	lua_pushboolean(L, o->tap);
	lua_setfield(L, -2, "tap");
}

int vmac_test_run(const struct vmac_test_options *o)
{
	char root[VMAC_PATH_MAX], runner[VMAC_PATH_MAX + 32];
	lua_State *L = luaL_newstate();
	int rc;
	if (!L) {
		fprintf(stderr, "vmac test: cannot create a Lua state\n");
		return 2;
	}
	luaL_openlibs(L);
	lua_getglobal(L, "package");
	lua_getfield(L, -1, "preload");
	lua_pushcfunction(L, open_world);
	lua_setfield(L, -2, "vmac.world");
	lua_pop(L, 2);
	vmac_root_dir(root, sizeof(root));
	snprintf(runner, sizeof(runner), "%s/core/vtest/runner.lua", root);
	lua_pushstring(L, root);
	lua_setglobal(L, "VMAC_ROOT");
	push_options(L, o);
	lua_setglobal(L, "OPTS");
	if (luaL_loadfile(L, runner) != 0 || lua_pcall(L, 0, 1, 0) != 0) {
		fprintf(stderr, "vmac test: %s\n", lua_tostring(L, -1));
		lua_close(L);
		return 2;
	}
	rc = (int)lua_tonumber(L, -1);
	lua_close(L);
	return rc;
}
