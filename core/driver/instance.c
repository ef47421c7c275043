/* A running machine (bus thread): its boards and level, attach and detach,
 * one tick (inputs in, dev.out and dev.vars out), operator input, params.
 * Each entry does its Lua work inside drv_protect. */
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* dev.boards[b + 1] = {name = , minor = }; the primary names the machine. */
struct board_args {
	int b;
	uint32_t minor;
	const char *name;
};

static int add_board_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct board_args *a = args;
	lua_State *L = d->L;
	int dev;
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	dev = lua_gettop(L);
	if (a->b == 0) {
		lua_pushstring(L, a->name);
		drv_raw_setfield(L, dev, "name");
	}
	drv_raw_getfield(L, dev, "boards");
	if (lua_istable(L, -1)) {
		lua_createtable(L, 0, 2);
		lua_pushstring(L, a->name);
		drv_raw_setfield(L, lua_gettop(L) - 1, "name");
		lua_pushnumber(L, a->minor);
		drv_raw_setfield(L, lua_gettop(L) - 1, "minor");
		lua_rawseti(L, -2, a->b + 1);
	}
	return 0;
}

int vmac_driver_add_board(struct vmac_driver *d, uint32_t minor, const char *name)
{
	struct board_args a;
	int i;
	for (i = 0; i < d->nboards; i++)
		if (d->board_minor[i] == minor)
			return -1;
	if (d->nboards == VMAC_DRIVER_MAX_BOARDS)
		return -1;
	a.b = d->nboards++;
	a.minor = minor;
	a.name = name;
	d->board_minor[a.b] = minor;
	for (i = 0; i < d->nio; i++)
		if (d->io[i].has_minor && d->io[i].minor == minor)
			d->io[i].board = a.b;
	drv_protect_quiet(d, add_board_work, &a); /* a failure fails the next call */
	return 0;
}

static int set_level_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	lua_State *L = d->L;
	(void)args;
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_pushinteger(L, (lua_Integer)d->level);
	drv_raw_setfield(L, 1, "level");
	return 0;
}

void vmac_driver_set_level_now(struct vmac_driver *d, unsigned level)
{
	d->level = level;
	drv_protect_quiet(d, set_level_work, NULL);
}

/* A callback with dev (and maybe a string) as its arguments. */
struct callback_args {
	int ref;
	const char *arg; /* NULL: none */
};

static int callback_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct callback_args *a = args;
	lua_State *L = d->L;
	lua_rawgeti(L, LUA_REGISTRYINDEX, a->ref);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	if (a->arg)
		lua_pushstring(L, a->arg);
	return drv_guarded_call(d, a->arg ? 2 : 1, 0, 1, err, errlen);
}

int vmac_driver_attach(struct vmac_driver *d, double time_s, char *err, size_t errlen)
{
	struct callback_args a = {d->ref_attach, NULL};
	if (d->ref_attach == LUA_NOREF)
		return d->failed ? drv_protect(d, callback_work, &a, err, errlen) : 0;
	d->now_s = time_s;
	return drv_protect(d, callback_work, &a, err, errlen);
}

void vmac_driver_detach(struct vmac_driver *d, const char *reason)
{
	struct callback_args a = {d->ref_detach, reason};
	char err[VMAC_DRIVER_ERR_MAX];
	if (d->ref_detach == LUA_NOREF)
		return;
	drv_protect(d, callback_work, &a, err, sizeof(err)); /* the machine is going away: errors are ignored */
}

/* ---- the tick ---- */

static void fill_inputs(struct vmac_driver *d, double time_s, const struct vmac_inputs *const in[])
{
	lua_State *L = d->L;
	int i, inputs = lua_gettop(L), keys = inputs + 1;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_keys);
	for (i = 0; i < d->nio; i++) {
		const struct io *io = &d->io[i];
		const struct vmac_inputs *x = io->board >= 0 ? in[io->board] : NULL;
		if (io->kind == IO_DO || io->kind == IO_PWM)
			continue;
		lua_rawgeti(L, keys, key_io(d, i));
		if (!x)
			lua_pushnil(L);
		else if (io->kind == IO_DI)
			lua_pushboolean(L, (x->digital >> io->channel) & 1);
		else if (io->kind == IO_AI)
			lua_pushnumber(L, x->analog[io->channel] * io->scale + io->offset);
		else
			lua_pushinteger(L, x->encoder);
		lua_rawset(L, inputs);
	}
	lua_rawgeti(L, keys, key_time(d));
	lua_pushnumber(L, time_s);
	lua_rawset(L, inputs);
	lua_pop(L, 1);
}

/* dev.out -> out[]: [-0, +0]. */
static int read_outputs(struct vmac_driver *d, struct vmac_outputs *const out[], char *err, size_t errlen)
{
	lua_State *L = d->L;
	int i, rc = 0, keys = lua_gettop(L) + 1, dev = keys + 1, t = keys + 2;
	for (i = 0; i < d->nboards; i++)
		memset(out[i], 0, sizeof(*out[i]));
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_keys);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_rawgeti(L, keys, key_out(d));
	lua_rawget(L, dev);
	if (!lua_istable(L, t)) {
		snprintf(err, errlen, "%s: dev.out must stay a table, got %s", d->file, luaL_typename(L, t));
		lua_pop(L, 3);
		return -1;
	}
	for (i = 0; i < d->nio && rc == 0; i++) {
		const struct io *io = &d->io[i];
		struct vmac_outputs *o = io->board >= 0 && io->board < d->nboards ? out[io->board] : NULL;
		if (io->kind != IO_DO && io->kind != IO_PWM)
			continue;
		lua_rawgeti(L, keys, key_io(d, i));
		lua_rawget(L, t);
		if (io->kind == IO_DO) {
			if (lua_isboolean(L, -1)) {
				if (o && lua_toboolean(L, -1))
					o->digital |= (uint8_t)(1u << io->channel);
			} else if (!lua_isnil(L, -1)) {
				snprintf(err, errlen, "%s: dev.out.%s must be true, false or nil, got %s", d->file,
				         io->name, luaL_typename(L, -1));
				rc = -1;
			}
		} else if (!lua_isnil(L, -1)) {
			double pwm = lua_tonumber(L, -1);
			if (lua_type(L, -1) != LUA_TNUMBER || !(pwm >= -VMAC_PWM_MAX && pwm <= VMAC_PWM_MAX)) {
				snprintf(err, errlen, "%s: dev.out.%s must be a number in -1000..1000, got %s", d->file,
				         io->name,
				         lua_type(L, -1) == LUA_TNUMBER ? lua_tostring(L, -1) : luaL_typename(L, -1));
				rc = -1;
			} else if (o) {
				o->pwm = (int16_t)pwm;
			}
		}
		lua_pop(L, 1);
	}
	lua_pop(L, 3);
	if (rc != 0)
		for (i = 0; i < d->nboards; i++)
			memset(out[i], 0, sizeof(*out[i]));
	return rc;
}

/* s[0..n) into out (room for VMAC_DRIVER_STR_MAX + 1), cut when longer:
 * then it ends with VMAC_DRIVER_CUT_MARK, and the cut falls between two
 * UTF-8 characters (backing off at most 3 continuation bytes), so a valid
 * UTF-8 text stays valid. */
static void copy_text(char *out, const char *s, size_t n)
{
	const size_t mark = sizeof(VMAC_DRIVER_CUT_MARK) - 1;
	size_t keep = VMAC_DRIVER_STR_MAX - mark, back = 0;
	if (n <= VMAC_DRIVER_STR_MAX) {
		memcpy(out, s, n);
		out[n] = 0;
		return;
	}
	while (back < 3 && keep > 0 && ((unsigned char)s[keep] & 0xC0) == 0x80)
		keep--, back++;
	memcpy(out, s, keep);
	memcpy(out + keep, VMAC_DRIVER_CUT_MARK, mark + 1);
}

/* The value on top as a vmac_value; -1 if it has a type a variable cannot.
 * str is "" but for a string: no stack bytes go out with the status (found
 * by tests/fuzz/fuzz_manifest.c). *len: a string's length in Lua (more than
 * VMAC_DRIVER_STR_MAX: it was cut), else 0. */
static int to_value(lua_State *L, struct vmac_value *v, size_t *len)
{
	const char *s;
	*len = 0;
	v->str[0] = 0;
	switch (lua_type(L, -1)) {
	case LUA_TNIL: v->type = VMAC_VALUE_NONE; return 0;
	case LUA_TNUMBER:
		v->type = VMAC_VALUE_NUMBER;
		v->number = lua_tonumber(L, -1);
		return 0;
	case LUA_TBOOLEAN:
		v->type = VMAC_VALUE_BOOL;
		v->number = lua_toboolean(L, -1);
		return 0;
	case LUA_TSTRING:
		s = lua_tolstring(L, -1, len);
		v->type = VMAC_VALUE_STRING;
		copy_text(v->str, s, *len);
		return 0;
	default: return -1;
	}
}

/* The first cut of a variable's text in this instance: one warning event. */
static void warn_cut(struct vmac_driver *d, struct var *v, size_t len)
{
	char text[160];
	if (v->warned_cut || !d->host.event)
		return;
	v->warned_cut = 1;
	snprintf(text, sizeof(text),
	         "dev.vars.%s: a text of %zu bytes was cut to %d (a text value holds at most %d bytes)", v->pub.name,
	         len, VMAC_DRIVER_STR_MAX, VMAC_DRIVER_STR_MAX);
	d->host.event(d->host.ctx, "warning", text);
}

static int value_equal(const struct vmac_value *a, const struct vmac_value *b)
{
	if (a->type != b->type)
		return 0;
	if (a->type == VMAC_VALUE_STRING)
		return strcmp(a->str, b->str) == 0;
	return a->type == VMAC_VALUE_NONE || a->number == b->number ||
	       (a->number != a->number && b->number != b->number);
}

/* dev.vars -> the published values: what is due now, groups whole. */
static int publish_vars(struct vmac_driver *d, double time_s, char *err, size_t errlen)
{
	lua_State *L = d->L;
	struct vmac_value now[VMAC_DRIVER_MAX_VARS];
	int i, j, published = 0, keys = lua_gettop(L) + 1, dev = keys + 1, t = keys + 2;
	size_t len;
	if (d->nvars == 0)
		return 0;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_keys);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_rawgeti(L, keys, key_vars(d));
	lua_rawget(L, dev);
	if (!lua_istable(L, t)) {
		snprintf(err, errlen, "%s: dev.vars must stay a table, got %s", d->file, luaL_typename(L, t));
		lua_pop(L, 3);
		return -1;
	}
	for (i = 0; i < d->nvars; i++) {
		struct var *v = &d->vars[i];
		lua_rawgeti(L, keys, key_var(d, i));
		lua_rawget(L, t);
		if (to_value(L, &now[i], &len) != 0) {
			snprintf(err, errlen, "%s: dev.vars.%s must be a number, boolean, string or nil, got %s",
			         d->file, v->pub.name, luaL_typename(L, -1));
			lua_pop(L, 4);
			return -1;
		}
		lua_pop(L, 1);
		if (len > VMAC_DRIVER_STR_MAX)
			warn_cut(d, v, len);
		v->due = !value_equal(&now[i], &v->pub.value) &&
		         (v->every_s == 0 || time_s - v->pub.published_s >= v->every_s || v->pub.published_s == 0);
	}
	lua_pop(L, 3);
	for (i = 0; i < d->nvars; i++) /* a group is due as a whole */
		if (d->vars[i].due && d->vars[i].group)
			for (j = 0; j < d->nvars; j++)
				if (d->vars[j].group == d->vars[i].group)
					d->vars[j].due = 1;
	for (i = 0; i < d->nvars; i++)
		if (d->vars[i].due) {
			d->vars[i].pub.value = now[i];
			d->vars[i].pub.published_s = time_s;
			published = 1;
		}
	d->vars_version += (uint64_t)published;
	return 0;
}

struct tick_args {
	double time_s;
	const struct vmac_inputs *const *in;
	struct vmac_outputs *const *out;
};

void vmac_driver_sample_times(struct vmac_driver *d, const double *t, int n)
{
	int i;
	d->nsample = n < VMAC_DRIVER_MAX_BOARDS ? n : VMAC_DRIVER_MAX_BOARDS;
	for (i = 0; i < d->nsample; i++)
		d->sample_s[i] = t[i];
}

/* dev.t (the primary's inputs' instant) and dev.boards[i].t (each
 * board's), the tick's time where none was given: [-0, +0]. */
static void fill_sample_times(struct vmac_driver *d, int dev, double time_s)
{
	lua_State *L = d->L;
	int i;
	lua_pushnumber(L, d->nsample > 0 ? d->sample_s[0] : time_s);
	drv_raw_setfield(L, dev, "t");
	drv_raw_getfield(L, dev, "boards");
	if (lua_istable(L, -1))
		for (i = 0; i < d->nboards; i++) {
			lua_rawgeti(L, -1, i + 1);
			if (lua_istable(L, -1)) {
				lua_pushnumber(L, i < d->nsample ? d->sample_s[i] : time_s);
				drv_raw_setfield(L, lua_gettop(L) - 1, "t");
			}
			lua_pop(L, 1);
		}
	lua_pop(L, 1);
	d->nsample = 0; /* given for one tick */
}

static int tick_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct tick_args *a = args;
	lua_State *L = d->L;
	d->out_at_s = -1; /* dev:output_at asks for one tick */
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_tick);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	fill_sample_times(d, lua_gettop(L), a->time_s);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_inputs);
	fill_inputs(d, a->time_s, a->in);
	if (drv_guarded_call(d, 2, 0, 1, err, errlen) != 0 || read_outputs(d, a->out, err, errlen) != 0 ||
	    publish_vars(d, a->time_s, err, errlen) != 0)
		return -1;
	return 0;
}

int vmac_driver_tick(struct vmac_driver *d, double time_s, const struct vmac_inputs *const in[],
                     struct vmac_outputs *const out[], char *err, size_t errlen)
{
	struct tick_args a = {time_s, in, out};
	d->now_s = time_s;
	if (drv_protect(d, tick_work, &a, err, errlen) != 0) {
		int i;
		for (i = 0; i < d->nboards; i++) /* a failed tick drives nothing */
			memset(out[i], 0, sizeof(*out[i]));
		return -1;
	}
	return 0;
}

/* A host value as Lua: [-0, +1]; NONE (a command without argument) is true. */
static void push_value(lua_State *L, const struct vmac_value *v)
{
	if (v->type == VMAC_VALUE_NUMBER)
		lua_pushnumber(L, v->number);
	else if (v->type == VMAC_VALUE_BOOL)
		lua_pushboolean(L, v->number != 0);
	else if (v->type == VMAC_VALUE_STRING)
		lua_pushstring(L, v->str);
	else
		lua_pushboolean(L, 1);
}

struct input_args {
	double time_s;
	const char *name;
	const struct vmac_value *value;
	char *reply;
	size_t replylen;
};

static int input_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct input_args *a = args;
	lua_State *L = d->L;
	const char *name = a->name;
	const struct vmac_value *value = a->value;
	char *reply = a->reply;
	size_t replylen = a->replylen;
	int i, top = lua_gettop(L), kind = 0, old = 0; /* kind: 1 variable, 2 param, 3 command */
	char why[160];

	for (i = 0; i < d->nvars; i++)
		if (strcmp(d->vars[i].pub.name, name) == 0) {
			if (!d->vars[i].settable) {
				snprintf(reply, replylen, "%s is read-only", name);
				return VMAC_REFUSED_READ_ONLY;
			}
			kind = 1;
		}
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_manifest);
	if (!kind) {
		lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
		drv_raw_getfield(L, lua_gettop(L), name);
		kind = lua_isnil(L, -1) ? 0 : 2;
		lua_pop(L, 2);
	}
	if (!kind) {
		lua_getfield(L, -1, "commands");
		if (lua_istable(L, -1)) {
			lua_getfield(L, -1, name);
			kind = lua_istable(L, -1) ? 3 : 0;
			lua_pop(L, 1);
		}
		lua_pop(L, 1);
	}
	if (!kind) {
		snprintf(reply, replylen, "%s: no such variable, param or command", name);
		lua_settop(L, top);
		return VMAC_REFUSED_NAME;
	}
	if (kind == 2) { /* the param's value now, below the manifest: its type, and what a refusal puts back */
		lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
		drv_raw_getfield(L, lua_gettop(L), name);
		lua_remove(L, -2);
		lua_insert(L, -2);
		old = lua_gettop(L) - 1;
	}
	/* Push the value, then check it against the declaration. */
	push_value(L, value);
	if (kind == 2 && lua_type(L, -1) != lua_type(L, old) &&
	    (lua_type(L, old) == LUA_TNUMBER || lua_type(L, old) == LUA_TBOOLEAN || lua_type(L, old) == LUA_TSTRING)) {
		snprintf(reply, replylen, "%s: expected a %s, got a %s", name, luaL_typename(L, old),
		         luaL_typename(L, -1));
		lua_settop(L, top);
		return VMAC_REFUSED_VALUE;
	}
	if (kind != 3) {
		lua_getfield(L, -2, kind == 1 ? "variables" : "params");
		lua_getfield(L, -1, name);
		lua_pushvalue(L, -3);
		if (drv_check_value(L, lua_gettop(L) - 1, why, sizeof(why)) != 0) {
			snprintf(reply, replylen, "%s: %s", name, why);
			lua_settop(L, top);
			return VMAC_REFUSED_VALUE;
		}
		lua_pop(L, 3);
		if (kind == 2) {
			lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
			lua_pushvalue(L, -2);
			drv_raw_setfield(L, lua_gettop(L) - 1, name);
			lua_pop(L, 1);
		}
	}
	if (d->ref_input == LUA_NOREF) {
		lua_settop(L, top);
		if (kind == 2)
			return 0;
		snprintf(reply, replylen, "%s: the driver takes no input", name);
		return VMAC_REFUSED_NO_INPUT;
	}
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_input);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_pushstring(L, name);
	lua_pushvalue(L, -4);
	if (drv_guarded_call(d, 3, 2, 1, err, errlen) != 0) {
		lua_settop(L, top);
		return -1;
	}
	if (lua_toboolean(L, -2)) {
		lua_settop(L, top);
		return 0;
	}
	snprintf(reply, replylen, "%s",
	         lua_type(L, -1) == LUA_TSTRING || lua_type(L, -1) == LUA_TNUMBER ? lua_tostring(L, -1)
	                                                                          : "refused by the driver");
	if (kind == 2) { /* refused: the param is as it was */
		lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
		lua_pushvalue(L, old);
		drv_raw_setfield(L, lua_gettop(L) - 1, name);
	}
	lua_settop(L, top);
	return VMAC_REFUSED_BY_DRIVER;
}

int vmac_driver_input(struct vmac_driver *d, double time_s, const char *name, const struct vmac_value *value,
                      char *reply, size_t replylen, char *err, size_t errlen)
{
	struct input_args a = {time_s, name, value, reply, replylen};
	reply[0] = 0;
	d->now_s = time_s;
	return drv_protect(d, input_work, &a, err, errlen);
}

/* ---- params ---- */

int vmac_driver_nparams(const struct vmac_driver *d)
{
	return d->nparams;
}

static int param_index(const struct vmac_driver *d, const char *name)
{
	int i;
	for (i = 0; i < d->nparams; i++)
		if (strcmp(d->params[i].name, name) == 0)
			return i;
	return -1;
}

int vmac_driver_param_persists(const struct vmac_driver *d, const char *name)
{
	int i = param_index(d, name);
	return i < 0 ? -1 : d->params[i].persist;
}

struct param_args {
	const char *name;
	const struct vmac_value *v;
	char *why;
	size_t whylen;
};

static int params_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct vmac_variable *out = args;
	lua_State *L = d->L;
	int i;
	size_t len;
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
	for (i = 0; i < d->nparams; i++) {
		drv_raw_getfield(L, 1, d->params[i].name);
		to_value(L, &out[i].value, &len);
		lua_settop(L, 1);
	}
	return 0;
}

int vmac_driver_params(const struct vmac_driver *cd, struct vmac_variable *out)
{
	struct vmac_driver *d = (struct vmac_driver *)cd; /* reads only; protection keeps flags in d */
	int i;
	memset(out, 0, (size_t)d->nparams * sizeof(*out));
	for (i = 0; i < d->nparams; i++) {
		memcpy(out[i].name, d->params[i].name, sizeof(out[i].name));
		memcpy(out[i].unit, d->params[i].unit, sizeof(out[i].unit));
	}
	if (d->nparams > 0)
		drv_protect_quiet(d, params_work, out);
	return d->nparams;
}

static int restore_param_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct param_args *a = args;
	lua_State *L = d->L;
	const struct vmac_value *v = a->v;
	const char *name = a->name;
	int type, params;
	char how[160];
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
	params = lua_gettop(L);
	drv_raw_getfield(L, params, name);
	type = lua_type(L, -1);
	lua_pop(L, 1);
	if ((type == LUA_TNUMBER && v->type != VMAC_VALUE_NUMBER) ||
	    (type == LUA_TBOOLEAN && v->type != VMAC_VALUE_BOOL) ||
	    (type == LUA_TSTRING && v->type != VMAC_VALUE_STRING)) {
		snprintf(a->why, a->whylen, "%s: the stored value is not a %s", name, lua_typename(L, type));
		return 1;
	}
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_manifest);
	lua_getfield(L, -1, "params");
	lua_getfield(L, -1, name);
	push_value(L, v);
	if (drv_check_value(L, lua_gettop(L) - 1, how, sizeof(how)) != 0) {
		snprintf(a->why, a->whylen, "%s: %s", name, how);
		return 1;
	}
	drv_raw_setfield(L, params, name); /* dev.params[name] = value */
	return 0;
}

int vmac_driver_restore_param(struct vmac_driver *d, const char *name, const struct vmac_value *v, char *why,
                              size_t whylen)
{
	struct param_args a;
	char err[VMAC_DRIVER_ERR_MAX];
	int i = param_index(d, name), rc;
	if (i < 0 || !d->params[i].persist) {
		snprintf(why, whylen, "%s is %s", name,
		         i < 0 ? "no longer a param of the driver" : "not persist = true");
		return -1;
	}
	memset(&a, 0, sizeof(a));
	a.name = name;
	a.v = v;
	a.why = why;
	a.whylen = whylen;
	rc = drv_protect(d, restore_param_work, &a, err, sizeof(err));
	if (rc < 0)
		snprintf(why, whylen, "%s", err);
	return rc == 0 ? 0 : -1;
}
