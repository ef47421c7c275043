/* Hot reload (docs/DRIVERS.md "Hot reload"): a new instance takes over the
 * machine an old one runs, with its params, outputs and a plain-data copy
 * of dev.state handed to migrate(). */
#include "internal.h"

#include <stdio.h>
#include <string.h>

/* ---- hot reload: one instance takes over from another ---- */

#define MIGRATE_MAX_ENTRIES 10000
#define MIGRATE_MAX_DEPTH 32

enum { COPY_PARAMS, COPY_STATE };

/* Slots of the old state's stack one copy uses at most: a key and a value a
 * level, reserved beforehand (reserve_work) so that reading it never grows
 * the stack. */
#define COPY_FROM_SLOTS (2 * (MIGRATE_MAX_DEPTH + 2) + 8)

/* A copy of plain data from one driver's state into another's. It runs in
 * the new state's protection (its memory cap stays an error there); the old
 * state is only read, with calls that neither allocate nor raise (raw
 * reads, lua_next over an unchanged table, strings as they are) on stack
 * reserved in its own protection, so that no error of one state can unwind
 * through the other's protected call. */
struct copy {
	struct vmac_driver *from, *to;
	int what; /* COPY_PARAMS, or COPY_STATE: dev.out and dev.state */
	int seen; /* index in to: a table old table -> new table */
	int entries;
	int ref; /* COPY_STATE: the copy of dev.state, in to's registry */
	char why[120];
};

static int copy_value(struct copy *c, int i, int depth);

/* [-0, +1] in to: a copy of the table at index i of from. */
static int copy_table(struct copy *c, int i, int depth)
{
	lua_State *F = c->from->L, *T = c->to->L;
	const void *p = lua_topointer(F, i);
	lua_pushlightuserdata(T, (void *)p);
	lua_rawget(T, c->seen);
	if (!lua_isnil(T, -1))
		return 0; /* shared (or a cycle): one table in the copy too */
	lua_pop(T, 1);
	if (depth > MIGRATE_MAX_DEPTH) {
		snprintf(c->why, sizeof(c->why), "dev.state is nested deeper than %d tables", MIGRATE_MAX_DEPTH);
		return -1;
	}
	luaL_checkstack(T, 6, "dev.state copy"); /* F: COPY_FROM_SLOTS, reserved */
	lua_newtable(T);
	lua_pushlightuserdata(T, (void *)p);
	lua_pushvalue(T, -2);
	lua_rawset(T, c->seen);
	lua_pushnil(F);
	while (lua_next(F, i)) {
		int rk, rv;
		if (++c->entries > MIGRATE_MAX_ENTRIES) {
			snprintf(c->why, sizeof(c->why), "dev.state holds more than %d entries", MIGRATE_MAX_ENTRIES);
			lua_pop(F, 2);
			return -1;
		}
		rk = copy_value(c, lua_gettop(F) - 1, depth + 1);
		if (rk < 0) {
			lua_pop(F, 2);
			return -1;
		}
		if (rk == 0) {
			rv = copy_value(c, lua_gettop(F), depth + 1);
			if (rv < 0) {
				lua_pop(F, 2);
				return -1;
			}
			if (rv == 0)
				lua_rawset(T, -3);
			else
				lua_pop(T, 1); /* the key: its value was not plain data */
		}
		lua_pop(F, 1);
	}
	return 0;
}

/* Push onto to a copy of from's value at absolute index i: 0, 1 when it is
 * not plain data (nothing pushed), -1 when too large (c->why). */
static int copy_value(struct copy *c, int i, int depth)
{
	lua_State *F = c->from->L, *T = c->to->L;
	size_t n;
	const char *s;
	switch (lua_type(F, i)) {
	case LUA_TBOOLEAN: lua_pushboolean(T, lua_toboolean(F, i)); return 0;
	case LUA_TNUMBER: lua_pushnumber(T, lua_tonumber(F, i)); return 0;
	case LUA_TSTRING:
		s = lua_tolstring(F, i, &n);
		lua_pushlstring(T, s, n);
		return 0;
	case LUA_TTABLE: return copy_table(c, i, depth);
	default: return 1;
	}
}

/* Is name one of d's outputs? */
static int is_output(const struct vmac_driver *d, const char *name)
{
	int i;
	for (i = 0; i < d->nio; i++)
		if ((d->io[i].kind == IO_DO || d->io[i].kind == IO_PWM) && strcmp(d->io[i].name, name) == 0)
			return 1;
	return 0;
}

/* to.t[k] = from.t[k] for every string key k whose value has the type it
 * has in to (params: declared there) or that is one of to's outputs. */
static void copy_fields_typed(struct copy *c, int ref_from, int ref_to, int outputs)
{
	lua_State *F = c->from->L, *T = c->to->L;
	int f, t;
	lua_rawgeti(F, LUA_REGISTRYINDEX, ref_from);
	f = lua_gettop(F);
	lua_rawgeti(T, LUA_REGISTRYINDEX, ref_to);
	t = lua_gettop(T);
	lua_pushnil(F);
	while (lua_next(F, f)) {
		int type = lua_type(F, -1);
		if (lua_type(F, -2) == LUA_TSTRING &&
		    (type == LUA_TBOOLEAN || type == LUA_TNUMBER || type == LUA_TSTRING)) {
			const char *k = lua_tostring(F, -2);
			int ok;
			if (outputs) {
				ok = is_output(c->to, k) && type != LUA_TSTRING;
			} else {
				drv_raw_getfield(T, t, k);
				ok = lua_type(T, -1) == type;
				lua_pop(T, 1);
			}
			if (ok) {
				copy_value(c, lua_gettop(F), 0);
				drv_raw_setfield(T, t, k);
			}
		}
		lua_pop(F, 1);
	}
	lua_settop(F, f - 1);
	lua_settop(T, t - 1);
}

/* COPY_PARAMS: dev.params; COPY_STATE: dev.out, then a copy of dev.state
 * into c->ref. Work in to's protection; 0, or -1 with c->why. */
static int copy_into(struct vmac_driver *to, struct copy *c)
{
	lua_State *F = c->from->L, *T = to->L;
	int rc, top = lua_gettop(F);
	if (c->what == COPY_PARAMS) {
		copy_fields_typed(c, c->from->ref_params, to->ref_params, 0);
		return 0;
	}
	copy_fields_typed(c, c->from->ref_out, to->ref_out, 1);
	lua_newtable(T);
	c->seen = lua_gettop(T);
	lua_rawgeti(F, LUA_REGISTRYINDEX, c->from->ref_dev);
	lua_rawgeti(F, LUA_REGISTRYINDEX, c->from->ref_keys);
	lua_rawgeti(F, -1, key_state(c->from));
	lua_rawget(F, -3);
	if (lua_istable(F, -1))
		rc = copy_table(c, lua_gettop(F), 0);
	else {
		lua_newtable(T);
		rc = 0;
	}
	lua_settop(F, top);
	if (rc != 0)
		return -1;
	c->ref = luaL_ref(T, LUA_REGISTRYINDEX);
	return 0;
}

/* Reserve the old state's stack for a copy out of it (its own protection). */
static int reserve_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	(void)args;
	(void)err;
	(void)errlen;
	luaL_checkstack(d->L, COPY_FROM_SLOTS, "copying dev.state");
	return 0;
}

struct take_over_args {
	struct vmac_driver *od;
	double time_s;
};

static int take_over_copy(struct vmac_driver *nd, struct copy *c, int what, char *err, size_t errlen)
{
	c->what = what;
	c->why[0] = 0;
	if (copy_into(nd, c) != 0) {
		snprintf(err, errlen, "copying the old state: %s", c->why);
		return -1;
	}
	return 0;
}

/* In nd's protection: params, attach, dev.out and dev.state, migrate. */
static int take_over_work(struct vmac_driver *nd, void *args, char *err, size_t errlen)
{
	struct take_over_args *a = args;
	struct vmac_driver *od = a->od;
	lua_State *L = nd->L;
	struct copy c;
	int i, j;
	memset(&c, 0, sizeof(c));
	c.from = od;
	c.to = nd;
	c.ref = LUA_NOREF;
	if (take_over_copy(nd, &c, COPY_PARAMS, err, errlen) != 0)
		return -1;
	if (nd->ref_attach != LUA_NOREF) {
		lua_rawgeti(L, LUA_REGISTRYINDEX, nd->ref_attach);
		lua_rawgeti(L, LUA_REGISTRYINDEX, nd->ref_dev);
		if (drv_guarded_call(nd, 1, 0, 1, err, errlen) != 0)
			return -1;
	}
	if (take_over_copy(nd, &c, COPY_STATE, err, errlen) != 0)
		return -1;
	for (i = 0; i < nd->nvars; i++) /* the status keeps its values until the new version publishes */
		for (j = 0; j < od->nvars; j++)
			if (strcmp(nd->vars[i].pub.name, od->vars[j].pub.name) == 0)
				nd->vars[i].pub = od->vars[j].pub;
	if (nd->ref_migrate == LUA_NOREF)
		return 0;
	lua_rawgeti(L, LUA_REGISTRYINDEX, nd->ref_migrate);
	lua_rawgeti(L, LUA_REGISTRYINDEX, nd->ref_dev);
	lua_rawgeti(L, LUA_REGISTRYINDEX, c.ref);
	return drv_guarded_call(nd, 2, 0, 1, err, errlen);
}

int vmac_driver_take_over(struct vmac_driver *nd, struct vmac_driver *od, double time_s, char *err, size_t errlen)
{
	struct take_over_args a = {od, time_s};
	/* od may be one that failed (a rollback takes over from it): only an
	 * error outside protection makes it unreadable. */
	if (drv_protect_any(od, reserve_work, NULL, err, errlen) != 0)
		return -1;
	nd->now_s = time_s;
	return drv_protect(nd, take_over_work, &a, err, errlen);
}
