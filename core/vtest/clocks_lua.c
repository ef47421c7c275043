/* The Lua side of the board clocks (clocks.h): `b.clock`, the `clock`
 * table of `board{...}` and `b:clock_step(ppm)` as runner.lua calls them
 * through vtest.c's world methods. */
#include <lauxlib.h>
#include <lua.h>
#include <string.h>

#include "clocks.h"
#include "world.h"

static void set_number(lua_State *L, const char *name, double v)
{
	lua_pushnumber(L, v);
	lua_setfield(L, -2, name);
}

int vt_lua_clock(lua_State *L, struct vt_world *w, struct vt_board *b)
{
	struct vt_clock_view v;
	w->reads_plant = 1; /* the clock ages on the plant grid too (vt_clock_poll) */
	vt_clock_view(w, b, &v);
	lua_createtable(L, 0, 8);
	lua_pushstring(L, v.state);
	lua_setfield(L, -2, "state");
	if (strcmp(v.state, "unsynced") != 0)
		set_number(L, "drift_ppm", v.drift_ppm);
	set_number(L, "true_ppm", v.true_ppm);
	set_number(L, "syncs", v.syncs);
	if (v.has_line) {
		set_number(L, "offset", v.offset_s);
		set_number(L, "bound", v.bound_s);
		set_number(L, "error", v.error_s);
	}
	if (b->acted.count > 0) { /* its last output change of time-triggered I/O */
		static const char *const how[] = {"instant", "arrival", "late", "overrun"};
		lua_createtable(L, 0, 4);
		set_number(L, "time", (double)b->acted.t_ns / 1e9);
		set_number(L, "asked", (double)b->acted.asked_ns / 1e9);
		lua_pushstring(L, b->acted.how >= 0 && b->acted.how < 4 ? how[b->acted.how] : "?");
		lua_setfield(L, -2, "how");
		set_number(L, "count", b->acted.count);
		lua_setfield(L, -2, "output");
	}
	return 1;
}

/* The field name of table t as a number, 0 when absent. */
static double field(lua_State *L, int t, const char *name)
{
	double v = 0;
	lua_getfield(L, t, name);
	if (!lua_isnil(L, -1)) {
		if (lua_type(L, -1) != LUA_TNUMBER)
			luaL_error(L, "%s must be a number", name);
		v = lua_tonumber(L, -1);
	}
	lua_pop(L, 1);
	return v;
}

int vt_lua_set_clock(lua_State *L, int idx, struct vt_world *w, struct vt_board *b)
{
	struct vt_clock_spec spec;
	char err[200];
	luaL_checktype(L, idx, LUA_TTABLE);
	lua_pushnil(L);
	while (lua_next(L, idx)) {
		const char *k = lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : "?";
		if (strcmp(k, "ppm") && strcmp(k, "offset") && strcmp(k, "jitter") && strcmp(k, "wander"))
			return luaL_error(L, "unknown key '%s' (ppm, offset, jitter, wander)", k);
		lua_pop(L, 1);
	}
	spec.ppm = field(L, idx, "ppm");
	spec.offset_s = field(L, idx, "offset");
	spec.jitter_s = field(L, idx, "jitter");
	spec.wander = field(L, idx, "wander");
	if (vt_clock_set(w, b, &spec, err, sizeof(err)) != 0)
		return luaL_error(L, "%s", err);
	return 0;
}

int vt_lua_clock_step(lua_State *L, int idx, struct vt_world *w, struct vt_board *b)
{
	char err[200];
	if (vt_clock_step(w, b, luaL_checknumber(L, idx), err, sizeof(err)) != 0)
		return luaL_error(L, "%s", err);
	return 0;
}
