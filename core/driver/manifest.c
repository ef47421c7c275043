/* The manifest (docs/DRIVERS.md "The manifest"): every field read and
 * checked, errors naming the field; its declarations as JSON for user
 * interfaces. Runs in the driver's protection at load. */
#include "hints.h"
#include "internal.h"

#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the manifest ---- */

#define BAD(...)                                                                                                       \
	do {                                                                                                           \
		char what_[300];                                                                                       \
		snprintf(what_, sizeof(what_), __VA_ARGS__);                                                           \
		snprintf(err, errlen, "%s: manifest: %s", d->file, what_);                                             \
		return -1;                                                                                             \
	} while (0)

/* s of n bytes: a NUL inside would make "in\0a" and "in\0b" one name
 * "in" on the C side (found by tests/fuzz/fuzz_manifest.c). */
static int valid_name(const char *s, size_t n)
{
	size_t i;
	if (!(s[0] >= 'a' && s[0] <= 'z'))
		return 0;
	for (i = 0; s[i]; i++)
		if (!((s[i] >= 'a' && s[i] <= 'z') || (s[i] >= '0' && s[i] <= '9') || s[i] == '_'))
			return 0;
	return i == n && i <= VMAC_DRIVER_NAME_MAX;
}

/* The key at idx is a string and a valid name. */
static int valid_key(lua_State *L, int idx)
{
	size_t n;
	const char *s;
	if (lua_type(L, idx) != LUA_TSTRING)
		return 0;
	s = lua_tolstring(L, idx, &n);
	return valid_name(s, n);
}

/* s is UTF-8 (what JSON carries): a name or version that is not would
 * make the description, the status and the versions' list leave the whole
 * driver out (found by tests/fuzz/fuzz_manifest.c). */
static int utf8_text(const char *s)
{
	json_t *j = json_string(s);
	json_decref(j);
	return j != NULL;
}

static const char *const CHANNELS_TEXT = "do0..do6, di0..di7, ai0, ai1, pwm, encoder";

static int parse_channel(const char *s, struct io *io)
{
	unsigned n;
	char c;
	if (strcmp(s, "pwm") == 0) {
		io->kind = IO_PWM;
		io->channel = 0;
		return 0;
	}
	if (strcmp(s, "encoder") == 0) {
		io->kind = IO_ENCODER;
		io->channel = 0;
		return 0;
	}
	if (strlen(s) != 3 || sscanf(s + 2, "%1u%c", &n, &c) != 1)
		return -1;
	io->channel = n;
	if (strncmp(s, "di", 2) == 0 && n < VMAC_DIGITAL_INPUTS)
		io->kind = IO_DI;
	else if (strncmp(s, "do", 2) == 0 && n < VMAC_DIGITAL_OUTPUTS)
		io->kind = IO_DO;
	else if (strncmp(s, "ai", 2) == 0 && n < VMAC_ANALOG_INPUTS)
		io->kind = IO_AI;
	else
		return -1;
	return 0;
}

/* Optional field of the table at t: number (or absent: dflt). */
static int opt_number(lua_State *L, int t, const char *field, double dflt, double *out)
{
	int ok;
	lua_getfield(L, t, field);
	ok = lua_isnil(L, -1) || lua_type(L, -1) == LUA_TNUMBER;
	*out = lua_isnil(L, -1) ? dflt : lua_tonumber(L, -1);
	lua_pop(L, 1);
	return ok && *out == *out ? 0 : -1;
}

/* Optional string field copied into out (absent: ""). */
static int opt_string(lua_State *L, int t, const char *field, char *out, size_t len)
{
	size_t n = 0;
	const char *s;
	lua_getfield(L, t, field);
	if (lua_isnil(L, -1)) {
		out[0] = 0;
		lua_pop(L, 1);
		return 0;
	}
	if (lua_type(L, -1) != LUA_TSTRING || (s = lua_tolstring(L, -1, &n), n >= len) || strlen(s) != n) {
		lua_pop(L, 1);
		return -1;
	}
	memcpy(out, s, n + 1);
	lua_pop(L, 1);
	return 0;
}

/* The io field of the table at t into d->io (sorted by name); what names
 * the text in errors ("manifest", "plant"). */
#define BAD_IO(...)                                                                                                    \
	do {                                                                                                           \
		char what_[300];                                                                                       \
		snprintf(what_, sizeof(what_), __VA_ARGS__);                                                           \
		snprintf(err, errlen, "%s: %s: %s", d->file, what, what_);                                             \
		return -1;                                                                                             \
	} while (0)

int drv_parse_io(struct vmac_driver *d, int t, const char *what, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int i, j;
	lua_getfield(L, t, "io");
	if (!lua_istable(L, -1))
		BAD_IO("io must be a table of name = channel (%s)", CHANNELS_TEXT);
	lua_pushnil(L);
	while (lua_next(L, -2)) {
		struct io *io;
		const char *chan;
		int spec = lua_gettop(L);
		if (!valid_key(L, -2))
			BAD_IO("io: names are [a-z][a-z0-9_]* of at most %d characters", VMAC_DRIVER_NAME_MAX);
		if (d->nio == VMAC_DRIVER_MAX_IO)
			BAD_IO("io: more than %d names", VMAC_DRIVER_MAX_IO);
		io = &d->io[d->nio];
		memset(io, 0, sizeof(*io));
		snprintf(io->name, sizeof(io->name), "%s", lua_tostring(L, -2));
		io->scale = 1;
		io->board = 0;
		if (lua_type(L, spec) == LUA_TSTRING) {
			chan = lua_tostring(L, spec);
		} else if (lua_istable(L, spec)) {
			double minor;
			lua_rawgeti(L, spec, 1);
			chan = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : NULL;
			lua_pop(L, 1); /* the string stays alive in the spec table */
			if (!chan)
				BAD_IO("io.%s: the first element must be the channel (%s)", io->name, CHANNELS_TEXT);
			if (opt_number(L, spec, "scale", 1, &io->scale) ||
			    opt_number(L, spec, "offset", 0, &io->offset))
				BAD_IO("io.%s: scale and offset must be numbers", io->name);
			if (opt_number(L, spec, "board", -1, &minor) ||
			    (minor != -1 && (minor < 0 || minor > 4294967295.0 || minor != floor(minor))))
				BAD_IO("io.%s: board must be the minor id of a board of this machine", io->name);
			if (minor >= 0) {
				io->has_minor = 1;
				io->minor = (uint32_t)minor;
				io->board = -1;
			}
		} else {
			BAD_IO("io.%s: must be a channel name or {channel, scale = , offset = , board = }", io->name);
		}
		if (parse_channel(chan, io) != 0)
			BAD_IO("io.%s: unknown channel '%s' (%s)", io->name, chan, CHANNELS_TEXT);
		if ((io->kind == IO_DO || io->kind == IO_PWM) && (io->scale != 1 || io->offset != 0))
			BAD_IO("io.%s: outputs take no scale or offset", io->name);
		for (j = 0; j < d->nio; j++) {
			struct io *o = &d->io[j];
			if ((io->kind == IO_DO || io->kind == IO_PWM) && o->kind == io->kind &&
			    o->channel == io->channel && o->has_minor == io->has_minor && o->minor == io->minor)
				BAD_IO("io.%s: output %s is already io.%s", io->name, chan, o->name);
		}
		d->nio++;
		lua_pop(L, 1);
	}
	lua_pop(L, 1);
	for (i = 0; i < d->nio; i++) /* deterministic order for the tick loops */
		for (j = i; j > 0 && strcmp(d->io[j - 1].name, d->io[j].name) > 0; j--) {
			struct io tmp = d->io[j];
			d->io[j] = d->io[j - 1];
			d->io[j - 1] = tmp;
		}
	return 0;
}
#undef BAD_IO

/* Value of the host's setting driver.NAME.<key>, or NULL. */
static const char *setting(const struct vmac_driver_limits *lim, const char *key)
{
	int i;
	for (i = 0; i < lim->nsettings; i++)
		if (strcmp(lim->settings[i].key, key) == 0)
			return lim->settings[i].value;
	return NULL;
}

/* Check v (on top) against spec (at s: min, max, values); text in why. */
int drv_check_value(lua_State *L, int s, char *why, size_t len)
{
	double lo, hi, x;
	if (opt_number(L, s, "min", -HUGE_VAL, &lo) || opt_number(L, s, "max", HUGE_VAL, &hi)) {
		snprintf(why, len, "min and max must be numbers");
		return -1;
	}
	if (lua_type(L, -1) == LUA_TNUMBER) {
		x = lua_tonumber(L, -1);
		if (!(x >= lo && x <= hi)) {
			snprintf(why, len, "%.14g is out of range %.14g..%.14g", x, lo, hi);
			return -1;
		}
	}
	lua_getfield(L, s, "values");
	if (lua_istable(L, -1)) {
		int i, found = 0;
		for (i = 1;; i++) {
			lua_rawgeti(L, -1, i);
			if (lua_isnil(L, -1)) {
				lua_pop(L, 1);
				break;
			}
			found |= lua_rawequal(L, -1, -3);
			lua_pop(L, 1);
		}
		if (!found) {
			snprintf(why, len, "'%s' is not one of the allowed values",
			         lua_isstring(L, -2)    ? lua_tostring(L, -2)
			         : lua_isboolean(L, -2) ? (lua_toboolean(L, -2) ? "true" : "false")
			                                : luaL_typename(L, -2));
			lua_pop(L, 1);
			return -1;
		}
	} else if (!lua_isnil(L, -1)) {
		snprintf(why, len, "values must be a list");
		lua_pop(L, 1);
		return -1;
	}
	lua_pop(L, 1);
	return 0;
}

/* params -> the dev.params table (on top on success): defaults, then the
 * host's overrides, each checked against its range. */
static int parse_params(struct vmac_driver *d, int t, const struct vmac_driver_limits *lim, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int values, n = 0;
	lua_newtable(L);
	values = lua_gettop(L);
	lua_getfield(L, t, "params");
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		goto overrides;
	}
	if (!lua_istable(L, -1))
		BAD("params must be a table of name = {default = , min = , max = , unit = , persist = }");
	lua_pushnil(L);
	while (lua_next(L, -2)) {
		int s = lua_gettop(L);
		char name[VMAC_DRIVER_NAME_MAX + 1], why[160], key[64];
		const char *over;
		if (!valid_key(L, -2))
			BAD("params: names are [a-z][a-z0-9_]* of at most %d characters", VMAC_DRIVER_NAME_MAX);
		snprintf(name, sizeof(name), "%s", lua_tostring(L, -2));
		if (++n > VMAC_DRIVER_MAX_PARAMS)
			BAD("params: more than %d", VMAC_DRIVER_MAX_PARAMS);
		if (!lua_istable(L, s))
			BAD("params.%s must be a table {default = , ...}", name);
		lua_getfield(L, s, "default");
		if (lua_type(L, -1) != LUA_TNUMBER && lua_type(L, -1) != LUA_TBOOLEAN && lua_type(L, -1) != LUA_TSTRING)
			BAD("params.%s: default (a number, boolean or string) is required", name);
		snprintf(key, sizeof(key), "param.%s", name);
		if ((over = setting(lim, key)) != NULL) {
			int type = lua_type(L, -1);
			char *end;
			double x;
			lua_pop(L, 1);
			if (type == LUA_TNUMBER) {
				x = strtod(over, &end);
				if (end == over || *end || x != x)
					BAD("params.%s: host setting driver.%s.%s = '%s' is not a number", name,
					    d->name, key, over);
				lua_pushnumber(L, x);
			} else if (type == LUA_TBOOLEAN) {
				if (strcmp(over, "true") && strcmp(over, "false"))
					BAD("params.%s: host setting driver.%s.%s = '%s' is not true or false", name,
					    d->name, key, over);
				lua_pushboolean(L, over[0] == 't');
			} else {
				lua_pushstring(L, over);
			}
		}
		if (drv_check_value(L, s, why, sizeof(why)) != 0)
			BAD("params.%s: %s%s", name, why, over ? " (host setting)" : "");
		lua_setfield(L, values, name);
		snprintf(d->params[d->nparams].name, sizeof(d->params[0].name), "%s", name);
		if (opt_string(L, s, "unit", d->params[d->nparams].unit, sizeof(d->params[0].unit)))
			BAD("params.%s: unit must be a string of at most 15 bytes", name);
		lua_getfield(L, s, "persist");
		if (!lua_isnil(L, -1) && !lua_isboolean(L, -1))
			BAD("params.%s: persist must be true or false", name);
		d->params[d->nparams++].persist = lua_toboolean(L, -1);
		lua_pop(L, 2);
	}
	lua_pop(L, 1);
overrides : {
	int i;
	for (i = 0; i < lim->nsettings; i++)
		if (strncmp(lim->settings[i].key, "param.", 6) == 0) {
			lua_getfield(L, values, lim->settings[i].key + 6);
			if (lua_isnil(L, -1))
				BAD("host setting driver.%s.%s: the driver has no param '%s'", d->name,
				    lim->settings[i].key, lim->settings[i].key + 6);
			lua_pop(L, 1);
		}
}
	return 0;
}

static int parse_variables(struct vmac_driver *d, int t, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int i, j;
	lua_getfield(L, t, "variables");
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		return 0;
	}
	if (!lua_istable(L, -1))
		BAD("variables must be a table of name = {unit = , update = , group = , set = }");
	lua_pushnil(L);
	while (lua_next(L, -2)) {
		int s = lua_gettop(L);
		struct var *v;
		char update[32], group[VMAC_DRIVER_NAME_MAX + 1];
		if (!valid_key(L, -2))
			BAD("variables: names are [a-z][a-z0-9_]* of at most %d characters", VMAC_DRIVER_NAME_MAX);
		if (d->nvars == VMAC_DRIVER_MAX_VARS)
			BAD("variables: more than %d", VMAC_DRIVER_MAX_VARS);
		v = &d->vars[d->nvars];
		memset(v, 0, sizeof(*v));
		snprintf(v->pub.name, sizeof(v->pub.name), "%s", lua_tostring(L, -2));
		if (!lua_istable(L, s))
			BAD("variables.%s must be a table (may be empty)", v->pub.name);
		if (opt_string(L, s, "unit", v->pub.unit, sizeof(v->pub.unit)))
			BAD("variables.%s: unit must be a string of at most %d bytes", v->pub.name,
			    (int)sizeof(v->pub.unit) - 1);
		if (opt_string(L, s, "update", update, sizeof(update)))
			BAD("variables.%s: update must be \"auto\" or \"timer:N\" (seconds)", v->pub.name);
		if (update[0] && strcmp(update, "auto") != 0) {
			char *end;
			if (strncmp(update, "timer:", 6) != 0 || (v->every_s = strtod(update + 6, &end), *end) ||
			    !(v->every_s > 0 && v->every_s <= 86400))
				BAD("variables.%s: update must be \"auto\" or \"timer:N\" with 0 < N <= 86400 seconds, "
				    "not '%s'",
				    v->pub.name, update);
		}
		if (opt_string(L, s, "group", group, sizeof(group)) || (group[0] && !valid_name(group, strlen(group))))
			BAD("variables.%s: group must be a name", v->pub.name);
		lua_getfield(L, s, "set");
		v->settable = lua_toboolean(L, -1);
		lua_pop(L, 2);
		d->nvars++;
	}
	lua_pop(L, 1);
	/* Sort by name, then resolve groups: a variable's group is the index+1
	 * of the first variable with the same group name. */
	for (i = 0; i < d->nvars; i++)
		for (j = i; j > 0 && strcmp(d->vars[j - 1].pub.name, d->vars[j].pub.name) > 0; j--) {
			struct var tmp = d->vars[j];
			d->vars[j] = d->vars[j - 1];
			d->vars[j - 1] = tmp;
		}
	lua_getfield(L, t, "variables");
	for (i = 0; i < d->nvars; i++) {
		char gi[VMAC_DRIVER_NAME_MAX + 1], gj[VMAC_DRIVER_NAME_MAX + 1];
		lua_getfield(L, -1, d->vars[i].pub.name);
		opt_string(L, lua_gettop(L), "group", gi, sizeof(gi));
		lua_pop(L, 1);
		if (!gi[0])
			continue;
		for (j = 0; j <= i; j++) {
			lua_getfield(L, -1, d->vars[j].pub.name);
			opt_string(L, lua_gettop(L), "group", gj, sizeof(gj));
			lua_pop(L, 1);
			if (strcmp(gi, gj) == 0) {
				d->vars[i].group = j + 1;
				break;
			}
		}
	}
	lua_pop(L, 1);
	return 0;
}

/* Names shared between params, variables and commands; commands' arg. */
static int check_names(struct vmac_driver *d, int t, int params, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int i;
	for (i = 0; i < d->nvars; i++) {
		lua_getfield(L, params, d->vars[i].pub.name);
		if (!lua_isnil(L, -1))
			BAD("'%s' is both a variable and a param", d->vars[i].pub.name);
		lua_pop(L, 1);
	}
	lua_getfield(L, t, "commands");
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		return 0;
	}
	if (!lua_istable(L, -1))
		BAD("commands must be a table of name = {label = , arg = }");
	lua_pushnil(L);
	while (lua_next(L, -2)) {
		const char *name;
		char arg[VMAC_DRIVER_NAME_MAX + 1];
		if (!valid_key(L, -2))
			BAD("commands: names are [a-z][a-z0-9_]* of at most %d characters", VMAC_DRIVER_NAME_MAX);
		name = lua_tostring(L, -2);
		if (!lua_istable(L, -1))
			BAD("commands.%s must be a table (may be empty)", name);
		lua_getfield(L, params, name);
		if (!lua_isnil(L, -1))
			BAD("'%s' is both a command and a param", name);
		lua_pop(L, 1);
		for (i = 0; i < d->nvars; i++)
			if (strcmp(d->vars[i].pub.name, name) == 0)
				BAD("'%s' is both a command and a variable", name);
		if (opt_string(L, lua_gettop(L), "arg", arg, sizeof(arg)))
			BAD("commands.%s: arg must name a variable or param", name);
		if (arg[0]) {
			int found = 0;
			lua_getfield(L, params, arg);
			found = !lua_isnil(L, -1);
			lua_pop(L, 1);
			for (i = 0; i < d->nvars; i++)
				found |= strcmp(d->vars[i].pub.name, arg) == 0;
			if (!found)
				BAD("commands.%s: arg '%s' is neither a variable nor a param", name, arg);
		}
		lua_pop(L, 1);
	}
	lua_pop(L, 1);
	return 0;
}

static int callback_ref(struct vmac_driver *d, int t, const char *name, int required, char *err, size_t errlen,
                        int *ref)
{
	lua_State *L = d->L;
	lua_getfield(L, t, name);
	if (lua_isnil(L, -1) && !required) {
		lua_pop(L, 1);
		*ref = LUA_NOREF;
		return 0;
	}
	if (!lua_isfunction(L, -1))
		BAD("%s must be a function%s", name, required ? " (it is required)" : "");
	*ref = luaL_ref(L, LUA_REGISTRYINDEX);
	return 0;
}

/* A whole number of microseconds 0..10 s from text (a host setting). */
static int us_of(const char *v, uint32_t *out)
{
	char *end;
	double x = strtod(v, &end);
	if (end == v || *end || x != floor(x) || x < 0 || x > 1e7)
		return -1;
	*out = (uint32_t)x;
	return 0;
}

/* The manifest's timing = {pattern = , input_us = , output_us = } (at t:
 * the manifest), the host's driver.NAME.timing.* over it, checked against
 * the host's lead and the period of the manifest's level. */
static int parse_timing(struct vmac_driver *d, int t, const struct vmac_driver_limits *lim, char *err, size_t errlen)
{
	lua_State *L = d->L;
	char pattern[16] = "", why[300];
	double in = 0, out = 0;
	const char *v;
	int i;
	memset(&d->timing, 0, sizeof(d->timing));
	lua_getfield(L, t, "timing");
	if (!lua_isnil(L, -1)) {
		int tt = lua_gettop(L);
		if (!lua_istable(L, tt))
			BAD("timing must be a table {pattern = , input_us = , output_us = }");
		if (opt_string(L, tt, "pattern", pattern, sizeof(pattern)) || vmac_timing_parse(pattern) < 0)
			BAD("timing.pattern must be \"phase\", \"offsets\" or \"arrival\"");
		if (opt_number(L, tt, "input_us", 0, &in) || opt_number(L, tt, "output_us", 0, &out) ||
		    in != floor(in) || out != floor(out) || in < 0 || out < 0 || in > 1e7 || out > 1e7)
			BAD("timing.input_us and timing.output_us must be whole numbers of microseconds 0..10000000");
		lua_pushnil(L);
		while (lua_next(L, tt)) {
			const char *k = lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : "?";
			if (strcmp(k, "pattern") && strcmp(k, "input_us") && strcmp(k, "output_us"))
				BAD("timing: unknown field '%s' (pattern, input_us, output_us)", k);
			lua_pop(L, 1);
		}
		if (strcmp(pattern, "offsets") != 0 && (in != 0 || out != 0))
			BAD("timing: input_us and output_us are for pattern \"offsets\"");
		d->timing.pattern = vmac_timing_parse(pattern);
		d->timing.input_us = (uint32_t)in;
		d->timing.output_us = (uint32_t)out;
	}
	lua_pop(L, 1);
	for (i = 0; i < lim->nsettings; i++) {
		const char *k = lim->settings[i].key;
		v = lim->settings[i].value;
		if (strncmp(k, "timing.", 7) != 0)
			continue;
		if (strcmp(k, "timing.pattern") == 0     ? (d->timing.pattern = vmac_timing_parse(v)) < 0
		    : strcmp(k, "timing.input_us") == 0  ? us_of(v, &d->timing.input_us)
		    : strcmp(k, "timing.output_us") == 0 ? us_of(v, &d->timing.output_us)
		                                         : -1) {
			snprintf(err, errlen,
			         "host setting driver.%s.%s = '%s': unknown key or bad value (timing.pattern: phase, "
			         "offsets or arrival; timing.input_us, timing.output_us: microseconds)",
			         d->name, k, v);
			return -1;
		}
	}
	if (d->timing.pattern != VMAC_TIMING_OFFSETS)
		d->timing.input_us = d->timing.output_us = 0; /* a setting made it phase or arrival */
	if (d->timing.pattern == VMAC_TIMING_OFFSETS && (!d->timing.input_us || !d->timing.output_us))
		BAD("timing: pattern \"offsets\" needs input_us and output_us");
	d->slot_us = lim->slot_us;
	d->lead_us = lim->timed_lead_us;
	d->out_at_s = -1;
	if (d->timing.pattern == VMAC_TIMING_OFFSETS && lim->slot_us &&
	    vmac_timing_check(&d->timing, lim->timed_lead_us, lim->slot_us << d->level, why, sizeof(why)) != 0)
		BAD("%s (level %u)", why, d->level);
	return 0;
}

int drv_parse_manifest(struct vmac_driver *d, const struct vmac_driver_limits *lim, char *err, size_t errlen)
{
	static const char *const known[] = {"name",      "version",  "level", "description", "io",     "params",
	                                    "variables", "commands", "ui",    "jit",         "timing", NULL};
	lua_State *L = d->L;
	int t = lua_gettop(L), params;
	double level;

	if (opt_string(L, t, "name", d->name, sizeof(d->name)) || !d->name[0] || !utf8_text(d->name))
		BAD("name (the driver's name, a string of UTF-8 text) is required");
	if (lim->expect_name && strcmp(d->name, lim->expect_name) != 0)
		BAD("name is '%s' but the board announced driver '%s'", d->name, lim->expect_name);
	if (opt_string(L, t, "version", d->version, sizeof(d->version)) || !d->version[0] || !utf8_text(d->version))
		BAD("version (a string of UTF-8 text, at most %d bytes) is required", VMAC_DRIVER_VERSION_MAX);
	if (opt_number(L, t, "level", lim->default_level, &level) || level != floor(level) || level < 0 ||
	    level > lim->max_level)
		BAD("level must be a whole number 0..%u (the host's max_level)", lim->max_level);
	d->level = (unsigned)level;
	d->max_level = lim->max_level;
	lua_getfield(L, t, "jit");
	if (!lua_isnil(L, -1) && !lua_isboolean(L, -1))
		BAD("jit must be true or false");
	d->jit = lua_toboolean(L, -1) && lim->allow_jit;
	lua_pop(L, 1);
	lua_getfield(L, t, "ui");
	if (!lua_isnil(L, -1) && !lua_istable(L, -1))
		BAD("ui must be a table");
	lua_pop(L, 1);
	lua_getfield(L, t, "description");
	if (!lua_isnil(L, -1) && !lua_isstring(L, -1))
		BAD("description must be a string");
	lua_pop(L, 1);
	lua_pushnil(L);
	while (lua_next(L, t)) {
		const char *const *k;
		int ok = lua_isfunction(L, -1);
		if (lua_type(L, -2) == LUA_TSTRING)
			for (k = known; *k && !ok; k++)
				ok = strcmp(*k, lua_tostring(L, -2)) == 0;
		if (!ok)
			BAD("unknown field '%s' (manifest fields: name, version, level, description, io, params, "
			    "variables, commands, ui, jit, timing; and functions)",
			    lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : luaL_typename(L, -2));
		lua_pop(L, 1);
	}
	if (parse_timing(d, t, lim, err, errlen) || drv_parse_io(d, t, "manifest", err, errlen) ||
	    parse_variables(d, t, err, errlen) || parse_params(d, t, lim, err, errlen))
		return -1;
	params = lua_gettop(L);
	if (check_names(d, t, params, err, errlen) || callback_ref(d, t, "tick", 1, err, errlen, &d->ref_tick) ||
	    callback_ref(d, t, "attach", 0, err, errlen, &d->ref_attach) ||
	    callback_ref(d, t, "input", 0, err, errlen, &d->ref_input) ||
	    callback_ref(d, t, "detach", 0, err, errlen, &d->ref_detach) ||
	    callback_ref(d, t, "migrate", 0, err, errlen, &d->ref_migrate) ||
	    callback_ref(d, t, "recover", 0, err, errlen, &d->ref_recover))
		return -1;
	return 0; /* leaves the params table on top */
}
#undef BAD

/* ---- the declarations as JSON, for user interfaces ---- */

/* What a description may still hold: values (a null filling a hole of an
 * array is one), and bytes of strings and keys. Without a bound, tables
 * that refer to each other (a cycle, or one table under many keys) make the
 * depth-limited walk exponential: a driver of a few hundred bytes could
 * hold its load for seconds and take gigabytes of the host's heap
 * (docs/RELIABILITY.md). */
struct describe_left {
	long values;
	size_t bytes;
	int over;
};

static int take_bytes(struct describe_left *left, size_t n)
{
	if (n > left->bytes) {
		left->over = 1;
		return -1;
	}
	left->bytes -= n;
	return 0;
}

/* The plain data at index i as JSON (depth-limited; functions and the like
 * are left out: NULL). A table with 1..n and nothing else is an array. */
static json_t *to_json(lua_State *L, int i, int depth, struct describe_left *left)
{
	json_t *o;
	size_t n;
	if (left->over || --left->values < 0) {
		left->over = 1;
		return NULL;
	}
	switch (lua_type(L, i)) {
	case LUA_TBOOLEAN: return json_boolean(lua_toboolean(L, i));
	case LUA_TNUMBER: return json_real(lua_tonumber(L, i));
	case LUA_TSTRING:
		n = lua_objlen(L, i);
		return take_bytes(left, n) == 0 ? json_stringn(lua_tostring(L, i), n) : NULL;
	case LUA_TTABLE: break;
	default: return NULL;
	}
	if (depth > 8)
		return NULL;
	i = i < 0 ? lua_gettop(L) + i + 1 : i;
	n = lua_objlen(L, i);
	o = n > 0 ? json_array() : json_object();
	lua_pushnil(L);
	while (lua_next(L, i)) {
		json_t *v = to_json(L, -1, depth + 1, left);
		if (v && json_is_array(o) && lua_type(L, -2) == LUA_TNUMBER) {
			lua_Number k = lua_tonumber(L, -2);
			if (k >= 1 && k <= (lua_Number)n && k == (lua_Number)(size_t)k) {
				/* the holes before k become nulls, each a value */
				while (json_array_size(o) < (size_t)k - 1 && !left->over)
					if (--left->values < 0)
						left->over = 1;
					else
						json_array_append_new(o, json_null());
				if (!left->over) {
					if (json_array_size(o) < (size_t)k)
						json_array_append_new(o, v);
					else
						json_array_set_new(o, (size_t)k - 1, v);
					v = NULL;
				}
			}
		} else if (v && json_is_object(o) && lua_type(L, -2) == LUA_TSTRING &&
		           take_bytes(left, lua_objlen(L, -2)) == 0) {
			json_object_set_new(o, lua_tostring(L, -2), v);
			v = NULL;
		}
		json_decref(v);
		lua_pop(L, 1);
		if (left->over) {
			lua_pop(L, 1); /* the key: the walk stops here */
			break;
		}
	}
	return o;
}

/* name, version, description, level and the tables io, variables, params,
 * commands and ui of the manifest as JSON text, into d->describe: 0, or -1
 * with err (past VMAC_DRIVER_DESCRIBE_VALUES or _BYTES, or out of memory).
 * Protected work: the fields are fetched first (that may raise), then
 * turned into JSON with calls that neither raise nor allocate on the
 * state, so no JSON leaks. */
int drv_describe(struct vmac_driver *d, char *err, size_t errlen)
{
	static const char *const fields[] = {"description", "io", "variables", "params", "commands", "ui", NULL};
	struct describe_left left = {VMAC_DRIVER_DESCRIBE_VALUES, VMAC_DRIVER_DESCRIBE_BYTES, 0};
	lua_State *L = d->L;
	int first, i;
	json_t *o;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_manifest);
	first = lua_gettop(L) + 1;
	for (i = 0; fields[i]; i++)
		drv_raw_getfield(L, first - 1, fields[i]);
	luaL_checkstack(L, 2 * 10 + 4, "describe"); /* to_json: two slots a level, nine levels */
	o = json_pack("{s:s, s:s, s:i}", "name", d->name, "version", d->version, "level", (int)d->level);
	for (i = 0; fields[i] && o && !left.over; i++) {
		json_t *v = to_json(L, first + i, 0, &left);
		if (v)
			json_object_set_new(o, fields[i], v);
	}
	lua_settop(L, first - 2);
	/* Home Assistant's view: the hints checked, the unit's defaults added. */
	if (o && !left.over && vmac_hints_apply(o, d->file, err, errlen) != 0) {
		json_decref(o);
		return -1;
	}
	d->describe = o && !left.over ? json_dumps(o, JSON_COMPACT) : NULL;
	json_decref(o);
	if (left.over) {
		snprintf(err, errlen,
		         "%s: manifest: too large to describe (description, io, variables, params, commands and ui "
		         "hold more than %d values or %d KiB of text)",
		         d->file, VMAC_DRIVER_DESCRIBE_VALUES, VMAC_DRIVER_DESCRIBE_BYTES / 1024);
		return -1;
	}
	if (!d->describe) {
		snprintf(err, errlen, "%s: out of memory describing the manifest", d->file);
		return -1;
	}
	return 0;
}

const char *vmac_driver_describe(const struct vmac_driver *d)
{
	return d->describe ? d->describe : "{}";
}

/* The load's Lua work, protected: libraries, the environment, the file run
 * under LOAD_FACTOR budgets, the manifest, dev, the description. */
