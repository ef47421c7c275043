/* A plant model in Lua (luaplant.h; docs/BOARD.md, "Plant models in
 * Lua"): the file runs in a driver's sandbox (vmac_driver_new) and is
 * checked once; then each step, action and field read is the host's work
 * on that state (drv_protect), with the plant's own code in the one
 * guarded call. The plant's io is parsed by the manifest's own reader into
 * the sandbox's io[]. A failure of any call fails the plant for good. */
#include "luaplant.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

struct vmac_luaplant {
	struct vmac_driver *d;                               /* the sandbox; d->io[] is the plant's io */
	int ref_step, ref_p, ref_out, ref_actions, ref_keys; /* registry; keys[i + 1] = io[i]'s name */
	char name[VMAC_NAME_MAX + 1], driver[VMAC_NAME_MAX + 1];
	struct vmac_inputs in;
	struct vmac_outputs out;
	double button_left_s[VMAC_DIGITAL_INPUTS]; /* real seconds a button action holds each input on */
	double time_scale;                         /* plant seconds per real second */
	double time_s;                             /* plant time since load; os.clock() reads d->now_s */
	int unsafe;                                /* the last step returned a text */
	uint32_t unsafe_episodes;
	char unsafe_text[VMAC_LUAPLANT_UNSAFE_MAX + 1];
	int failed;
	char failure[VMAC_DRIVER_ERR_MAX];
};

/* A button's hold left shorter than this is over: 0.5 s less five steps of
 * 0.1 s is 3e-17 s in doubles, not 0, and must not hold the input a sixth. */
#define BUTTON_SLACK_S 1e-9

#define BAD(...)                                                                                                       \
	do {                                                                                                           \
		char what_[300];                                                                                       \
		snprintf(what_, sizeof(what_), __VA_ARGS__);                                                           \
		snprintf(err, errlen, "%s: plant: %s", d->file, what_);                                                \
		return -1;                                                                                             \
	} while (0)

static const char *const FIELDS[] = {"name", "driver", "io", "state", "step", "actions", NULL};
#define FIELDS_TEXT "name, driver, io, state, step, actions"

/* A board's driver name: 1..VMAC_NAME_MAX of [A-Za-z0-9_-]. */
static int valid_board_name(const char *s)
{
	size_t n;
	for (n = 0; s[n]; n++)
		if (!((s[n] >= 'a' && s[n] <= 'z') || (s[n] >= 'A' && s[n] <= 'Z') || (s[n] >= '0' && s[n] <= '9') ||
		      s[n] == '-' || s[n] == '_'))
			return 0;
	return n > 0 && n <= VMAC_NAME_MAX;
}

/* Converter counts of an analog value: rounded, clipped to 0..VMAC_ANALOG_MAX, NaN 0. */
static uint16_t to_counts(double counts)
{
	if (!(counts > 0.0))
		return 0;
	if (counts >= VMAC_ANALOG_MAX)
		return VMAC_ANALOG_MAX;
	return (uint16_t)floor(counts + 0.5);
}

/* A number of encoder counts wrapped to a signed 32-bit count. */
static int32_t to_encoder(double v)
{
	double w;
	if (!isfinite(v))
		return 0;
	w = fmod(floor(v), 4294967296.0);
	if (w < 0)
		w += 4294967296.0;
	return (int32_t)(uint32_t)w;
}

/* The inputs from the state's fields named like the io inputs, and the
 * buttons held: [-0, +0]. Allocates nothing. */
static void read_inputs(struct vmac_luaplant *p)
{
	struct vmac_driver *d = p->d;
	lua_State *L = d->L;
	struct vmac_inputs in;
	int s, k, i;
	memset(&in, 0, sizeof(in));
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_p);
	s = lua_gettop(L);
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_keys);
	k = s + 1;
	for (i = 0; i < d->nio; i++) {
		const struct io *io = &d->io[i];
		int type;
		if (io->kind == IO_DO || io->kind == IO_PWM)
			continue;
		lua_rawgeti(L, k, i + 1);
		lua_rawget(L, s);
		type = lua_type(L, -1);
		if (io->kind == IO_DI) {
			int on = type == LUA_TBOOLEAN ? lua_toboolean(L, -1)
			                              : type == LUA_TNUMBER && lua_tonumber(L, -1) != 0;
			if (on)
				in.digital |= (uint8_t)(1u << io->channel);
		} else if (type == LUA_TNUMBER && io->kind == IO_AI) {
			in.analog[io->channel] = to_counts((lua_tonumber(L, -1) - io->offset) / io->scale);
		} else if (type == LUA_TNUMBER) {
			in.encoder = to_encoder(lua_tonumber(L, -1));
		}
		lua_pop(L, 1);
	}
	lua_pop(L, 2);
	for (i = 0; i < VMAC_DIGITAL_INPUTS; i++)
		if (p->button_left_s[i] > 0)
			in.digital |= (uint8_t)(1u << i);
	in.applied = p->out;
	p->in = in;
}

/* The io input named name (a digital one when di), or -1. */
static int find_io(const struct vmac_driver *d, const char *name)
{
	int i;
	for (i = 0; i < d->nio; i++)
		if (strcmp(d->io[i].name, name) == 0)
			return i;
	return -1;
}

/* A name field of the table at t: a string that a board may announce, or
 * absent (dflt). 0, or -1 with err. */
static int name_field(struct vmac_driver *d, int t, const char *field, const char *dflt, char *out, size_t len,
                      char *err, size_t errlen)
{
	lua_State *L = d->L;
	const char *s = dflt;
	drv_raw_getfield(L, t, field);
	if (!lua_isnil(L, -1)) {
		if (lua_type(L, -1) != LUA_TSTRING)
			BAD("%s must be a text", field);
		s = lua_tostring(L, -1);
	}
	if (!s || !valid_board_name(s) || strlen(s) >= len)
		BAD("%s '%s': names are 1..%d of A-Z a-z 0-9 _ -", field, s ? s : "", VMAC_NAME_MAX);
	snprintf(out, len, "%s", s);
	lua_pop(L, 1);
	return 0;
}

/* The checks of the returned table at t beyond its io: [-0, +0]. */
static int check_plant(struct vmac_luaplant *p, int t, const char *default_name, char *err, size_t errlen)
{
	struct vmac_driver *d = p->d;
	lua_State *L = d->L;
	int i;
	lua_pushnil(L);
	while (lua_next(L, t)) {
		const char *k = lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : NULL;
		for (i = 0; k && FIELDS[i] && strcmp(FIELDS[i], k) != 0; i++)
			;
		if (!k || !FIELDS[i])
			BAD("unknown field '%s' (" FIELDS_TEXT ")", k ? k : luaL_typename(L, -2));
		lua_pop(L, 1);
	}
	if (name_field(d, t, "name", default_name, p->name, sizeof(p->name), err, errlen) ||
	    name_field(d, t, "driver", p->name, p->driver, sizeof(p->driver), err, errlen))
		return -1;
	snprintf(d->name, sizeof(d->name), "%s", p->name);
	if (drv_parse_io(d, t, "plant", err, errlen) != 0)
		return -1;
	for (i = 0; i < d->nio; i++) {
		const struct io *io = &d->io[i];
		if (io->has_minor)
			BAD("io.%s: board: a plant is behind one board", io->name);
		if (io->kind == IO_AI && (!isfinite(io->scale) || io->scale == 0 || !isfinite(io->offset)))
			BAD("io.%s: scale must be a number other than 0, offset a number", io->name);
	}
	drv_raw_getfield(L, t, "step");
	if (!lua_isfunction(L, -1))
		BAD("step must be a function (p, dt, out)");
	p->ref_step = luaL_ref(L, LUA_REGISTRYINDEX);
	drv_raw_getfield(L, t, "state");
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		lua_newtable(L);
	} else if (!lua_istable(L, -1)) {
		BAD("state must be a table (the plant's state, p)");
	}
	p->ref_p = luaL_ref(L, LUA_REGISTRYINDEX);
	return 0;
}

/* actions: each a function (p, value) or the name of a digital input in
 * io (a button). Kept as a copy only the host holds (ref_actions: name ->
 * the function, or the button's input channel), so that a plant changing
 * its own actions table later cannot make an action name what was never
 * checked: [-0, +0]. */
static int check_actions(struct vmac_luaplant *p, int t, char *err, size_t errlen)
{
	struct vmac_driver *d = p->d;
	lua_State *L = d->L;
	drv_raw_getfield(L, t, "actions");
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		lua_newtable(L);
	} else if (!lua_istable(L, -1)) {
		BAD("actions must be a table of name = function (p, value) or name = \"input\"");
	}
	lua_newtable(L);
	lua_pushnil(L);
	while (lua_next(L, -3)) {
		const char *k = lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : NULL;
		if (!k || !valid_board_name(k))
			BAD("actions: names are 1..%d of A-Z a-z 0-9 _ -", VMAC_NAME_MAX);
		if (lua_type(L, -1) == LUA_TSTRING) {
			int i = find_io(d, lua_tostring(L, -1));
			if (i < 0 || d->io[i].kind != IO_DI)
				BAD("actions.%s: '%s' is not a digital input of io (a button names one)", k,
				    lua_tostring(L, -1));
			lua_pop(L, 1);
			lua_pushinteger(L, (lua_Integer)d->io[i].channel);
		} else if (!lua_isfunction(L, -1)) {
			BAD("actions.%s: must be a function (p, value) or the name of a digital input", k);
		}
		lua_pushvalue(L, -2);
		lua_insert(L, -2);
		lua_rawset(L, -4);
	}
	p->ref_actions = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_pop(L, 1);
	return 0;
}

struct load_args {
	struct vmac_luaplant *p;
	const char *src;
	size_t len;
	const char *default_name;
	uint64_t seed;
};

static int load_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct load_args *a = args;
	struct vmac_luaplant *p = a->p;
	lua_State *L = d->L;
	int t, i, nout = 0;
	/* math.random's state is the one the sandbox's copy of it uses */
	lua_getglobal(L, "math");
	lua_getfield(L, -1, "randomseed");
	lua_pushnumber(L, (double)(a->seed & ((1ull << 52) - 1)));
	lua_call(L, 1, 0);
	lua_pop(L, 1);
	if (drv_load_chunk(d, a->src, a->len, err, errlen) != 0)
		return -1;
	if (drv_guarded_call(d, 0, 1, VMAC_DRIVER_LOAD_FACTOR, err, errlen) != 0)
		return -1;
	if (!lua_istable(L, -1))
		BAD("the file must return a table (the plant), got %s", luaL_typename(L, -1));
	t = lua_gettop(L);
	if (check_plant(p, t, a->default_name, err, errlen) || check_actions(p, t, err, errlen))
		return -1;
	lua_createtable(L, d->nio, 0);
	for (i = 0; i < d->nio; i++) {
		lua_pushstring(L, d->io[i].name);
		lua_rawseti(L, -2, i + 1);
		nout += d->io[i].kind == IO_DO || d->io[i].kind == IO_PWM;
	}
	p->ref_keys = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_createtable(L, 0, nout);
	p->ref_out = luaL_ref(L, LUA_REGISTRYINDEX);
	read_inputs(p);
	lua_settop(L, 0);
	lua_gc(L, LUA_GCCOLLECT, 0);
	return 0;
}

/* The name a plant's file goes by in its messages: the path as given when
 * Lua's messages show it whole (LUA_IDSIZE - 1 bytes; longer, they cut it
 * at its start, to "...ac-it-x/pla:4:"), else its longest tail that
 * begins after a '/' and fits ("drivers/plants/dryer.lua"), so the
 * messages keep naming the file and its line. */
static const char *shown_name(const char *path)
{
	size_t n = strlen(path);
	const char *slash;
	while (n > LUA_IDSIZE - 1 && (slash = strchr(path, '/')) != NULL) {
		n -= (size_t)(slash + 1 - path);
		path = slash + 1;
	}
	return path;
}

int vmac_luaplant_load(const char *file, const char *src, size_t len, const char *default_name,
                       const struct vmac_luaplant_limits *lim, struct vmac_luaplant **out, char *err, size_t errlen)
{
	struct vmac_driver_limits dl;
	struct vmac_luaplant *p;
	struct load_args args;

	*out = NULL;
	if (len > VMAC_LUAPLANT_FILE_MAX) {
		snprintf(err, errlen, "%s: larger than %u MiB", file, VMAC_LUAPLANT_FILE_MAX >> 20);
		return -1;
	}
	p = calloc(1, sizeof(*p));
	if (!p) {
		snprintf(err, errlen, "out of memory");
		return -1;
	}
	p->ref_step = p->ref_p = p->ref_out = p->ref_actions = p->ref_keys = LUA_NOREF;
	p->time_scale = lim->time_scale > 0 ? lim->time_scale : 1.0;
	memset(&dl, 0, sizeof(dl));
	dl.memory_bytes = lim->memory_bytes ? lim->memory_bytes : VMAC_LUAPLANT_MEMORY;
	dl.instructions = lim->instructions ? lim->instructions : VMAC_LUAPLANT_INSTRUCTIONS;
	dl.budget_us = lim->budget_us;
	if (vmac_driver_new(shown_name(file), &dl, &p->d, err, errlen) != 0) {
		free(p);
		return -1;
	}
	p->d->loaded = 1; /* a plant, never a driver, in this sandbox */
	args.p = p;
	args.src = src;
	args.len = len;
	args.default_name = default_name;
	args.seed = lim->seed;
	if (drv_protect(p->d, load_work, &args, err, errlen) != 0) {
		vmac_luaplant_free(p);
		return -1;
	}
	*out = p;
	return 0;
}

int vmac_luaplant_load_file(const char *path, const struct vmac_luaplant_limits *lim, struct vmac_luaplant **out,
                            char *err, size_t errlen)
{
	const char *base = strrchr(path, '/');
	char name[VMAC_NAME_MAX + 8];
	size_t len = 0, n;
	int code = 0, rc;
	char *src = vmac_read_file(path, VMAC_LUAPLANT_FILE_MAX, &len, err, errlen, &code);
	*out = NULL;
	if (!src)
		return -1;
	snprintf(name, sizeof(name), "%s", base ? base + 1 : path);
	n = strlen(name);
	if (n > 4 && strcmp(name + n - 4, ".lua") == 0)
		name[n - 4] = '\0';
	rc = vmac_luaplant_load(path, src, len, name, lim, out, err, errlen);
	free(src);
	return rc;
}

void vmac_luaplant_free(struct vmac_luaplant *p)
{
	if (!p)
		return;
	vmac_driver_free(p->d);
	free(p);
}

const char *vmac_luaplant_name(const struct vmac_luaplant *p)
{
	return p->name;
}

const char *vmac_luaplant_driver(const struct vmac_luaplant *p)
{
	return p->driver;
}

static void fail(struct vmac_luaplant *p, const char *why)
{
	p->failed = 1;
	snprintf(p->failure, sizeof(p->failure), "%s", why);
}

/* The unsafe text of the step that began an episode, one printable line
 * (control characters, DEL too, made spaces), cut (if it must be) before a
 * UTF-8 character rather than inside one. */
static void keep_unsafe(struct vmac_luaplant *p, const char *text)
{
	size_t n = strlen(text), i;
	if (n > VMAC_LUAPLANT_UNSAFE_MAX) {
		n = VMAC_LUAPLANT_UNSAFE_MAX;
		while (n > 0 && ((unsigned char)text[n] & 0xC0) == 0x80)
			n--;
	}
	for (i = 0; i < n; i++)
		p->unsafe_text[i] = (unsigned char)text[i] < 0x20 || text[i] == 0x7F ? ' ' : text[i];
	p->unsafe_text[n] = '\0';
}

struct step_args {
	struct vmac_luaplant *p;
	double dt_s;
};

static int step_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct step_args *a = args;
	struct vmac_luaplant *p = a->p;
	lua_State *L = d->L;
	int i, o, k;
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_step);
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_p);
	lua_pushnumber(L, a->dt_s);
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_out);
	o = lua_gettop(L);
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_keys);
	k = o + 1;
	for (i = 0; i < d->nio; i++) {
		const struct io *io = &d->io[i];
		if (io->kind != IO_DO && io->kind != IO_PWM)
			continue;
		lua_rawgeti(L, k, i + 1);
		if (io->kind == IO_DO)
			lua_pushboolean(L, (p->out.digital >> io->channel) & 1);
		else
			lua_pushnumber(L, p->out.pwm);
		lua_rawset(L, o);
	}
	lua_pop(L, 1);
	d->now_s = p->time_s + a->dt_s; /* os.clock(): the time the step brings the plant to */
	if (drv_guarded_call(d, 3, 1, 1, err, errlen) != 0)
		return -1;
	if (lua_type(L, -1) == LUA_TSTRING) {
		if (!p->unsafe) {
			p->unsafe_episodes++;
			keep_unsafe(p, lua_tostring(L, -1));
		}
		p->unsafe = 1;
	} else if (lua_isnil(L, -1) || (lua_isboolean(L, -1) && !lua_toboolean(L, -1))) {
		p->unsafe = 0;
	} else {
		BAD("step returned a %s: it returns nothing while the machine is safe, else a text saying what is "
		    "unsafe",
		    luaL_typename(L, -1));
	}
	lua_pop(L, 1);
	p->time_s += a->dt_s;
	for (i = 0; i < VMAC_DIGITAL_INPUTS; i++)
		if (p->button_left_s[i] > 0) {
			p->button_left_s[i] -= a->dt_s / p->time_scale;
			if (p->button_left_s[i] < BUTTON_SLACK_S)
				p->button_left_s[i] = 0;
		}
	read_inputs(p);
	return 0;
}

int vmac_luaplant_step(struct vmac_luaplant *p, double dt_s)
{
	struct step_args args;
	char err[VMAC_DRIVER_ERR_MAX];
	if (p->failed)
		return -1;
	if (!(dt_s > 0))
		return 0;
	args.p = p;
	args.dt_s = dt_s;
	if (drv_protect(p->d, step_work, &args, err, sizeof(err)) != 0) {
		fail(p, err);
		return -1;
	}
	return 0;
}

void vmac_luaplant_sense(const struct vmac_luaplant *p, struct vmac_inputs *in)
{
	*in = p->in;
}

void vmac_luaplant_actuate(struct vmac_luaplant *p, const struct vmac_outputs *out)
{
	p->out = *out;
	p->in.applied = *out;
}

/* The names an action may take, for a refusal: actions, then the state's
 * number and boolean fields, as far as they fit. [-0, +0] */
static void action_names(struct vmac_luaplant *p, char *out, size_t len)
{
	lua_State *L = p->d->L;
	size_t used = 0;
	int pass;
	out[0] = '\0';
	for (pass = 0; pass < 2; pass++) {
		lua_rawgeti(L, LUA_REGISTRYINDEX, pass == 0 ? p->ref_actions : p->ref_p);
		lua_pushnil(L);
		while (lua_next(L, -2)) {
			int t = lua_type(L, -1);
			if (lua_type(L, -2) == LUA_TSTRING && (pass == 0 || t == LUA_TNUMBER || t == LUA_TBOOLEAN) &&
			    used + 2 < len)
				used += (size_t)snprintf(out + used, len - used, "%s%s", used ? ", " : "",
				                         lua_tostring(L, -2));
			lua_pop(L, 1);
		}
		lua_pop(L, 1);
	}
}

struct set_args {
	struct vmac_luaplant *p;
	const char *name;
	double value;
	char *why;
	size_t whylen;
	int refused;
};

/* An action that is a field of the state: a number takes any number, a
 * boolean 0 or 1. [-0, +0] */
static void set_field(struct set_args *a, lua_State *L)
{
	struct vmac_luaplant *p = a->p;
	int type, state;
	char names[200];
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_p);
	state = lua_gettop(L);
	drv_raw_getfield(L, state, a->name);
	type = lua_type(L, -1);
	lua_pop(L, 1);
	if (type == LUA_TNUMBER && !isnan(a->value)) {
		lua_pushnumber(L, a->value);
		drv_raw_setfield(L, state, a->name);
	} else if (type == LUA_TBOOLEAN && (a->value == 0 || a->value == 1)) {
		lua_pushboolean(L, a->value == 1);
		drv_raw_setfield(L, state, a->name);
	} else if (type == LUA_TNUMBER || type == LUA_TBOOLEAN) {
		a->refused = 1;
		snprintf(a->why, a->whylen, "%s takes %s", a->name, type == LUA_TNUMBER ? "a number" : "0 or 1");
	} else {
		a->refused = 1;
		action_names(p, names, sizeof(names));
		snprintf(a->why, a->whylen, "no action or state field '%s' (%s)", a->name, names);
	}
	lua_pop(L, 1);
}

static int set_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct set_args *a = args;
	struct vmac_luaplant *p = a->p;
	lua_State *L = d->L;
	int channel;
	d->now_s = p->time_s;
	lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_actions);
	drv_raw_getfield(L, lua_gettop(L), a->name);
	if (lua_isfunction(L, -1)) {
		lua_rawgeti(L, LUA_REGISTRYINDEX, p->ref_p);
		lua_pushnumber(L, a->value);
		if (drv_guarded_call(d, 2, 2, 1, err, errlen) != 0)
			return -1;
		if (lua_isboolean(L, -2) && !lua_toboolean(L, -2)) {
			a->refused = 1;
			snprintf(a->why, a->whylen, "%s",
			         lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "the plant's action says no");
		}
		lua_pop(L, 2);
	} else if (lua_type(L, -1) == LUA_TNUMBER) {
		channel = (int)lua_tointeger(L, -1); /* a digital input's: checked at load */
		p->button_left_s[channel] = VMAC_LUAPLANT_BUTTON_S;
		lua_pop(L, 1);
	} else {
		lua_pop(L, 1);
		set_field(a, L);
	}
	lua_pop(L, 1);
	read_inputs(p);
	return 0;
}

int vmac_luaplant_set(struct vmac_luaplant *p, const char *name, double value, char *why, size_t whylen)
{
	struct set_args args;
	char err[VMAC_DRIVER_ERR_MAX];
	if (p->failed) {
		snprintf(why, whylen, "the plant has failed: %s", p->failure);
		return -1;
	}
	args.p = p;
	args.name = name;
	args.value = value;
	args.why = why;
	args.whylen = whylen;
	args.refused = 0;
	if (drv_protect(p->d, set_work, &args, err, sizeof(err)) != 0) {
		fail(p, err);
		snprintf(why, whylen, "the plant failed: %s", err);
		return -1;
	}
	return args.refused;
}

struct field_args {
	struct vmac_luaplant *p;
	const char *name;
	struct vmac_value *v;
};

static int field_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct field_args *a = args;
	lua_State *L = d->L;
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, a->p->ref_p);
	drv_raw_getfield(L, lua_gettop(L), a->name);
	memset(a->v, 0, sizeof(*a->v));
	switch (lua_type(L, -1)) {
	case LUA_TNUMBER:
		a->v->type = VMAC_VALUE_NUMBER;
		a->v->number = lua_tonumber(L, -1);
		break;
	case LUA_TBOOLEAN:
		a->v->type = VMAC_VALUE_BOOL;
		a->v->number = lua_toboolean(L, -1);
		break;
	case LUA_TSTRING:
		a->v->type = VMAC_VALUE_STRING;
		snprintf(a->v->str, sizeof(a->v->str), "%s", lua_tostring(L, -1));
		break;
	default: a->v->type = VMAC_VALUE_NONE; break;
	}
	lua_pop(L, 2);
	return 0;
}

int vmac_luaplant_field(struct vmac_luaplant *p, const char *name, struct vmac_value *v)
{
	struct field_args args;
	char err[VMAC_DRIVER_ERR_MAX];
	if (strcmp(name, "unsafe_episodes") == 0) {
		memset(v, 0, sizeof(*v));
		v->type = VMAC_VALUE_NUMBER;
		v->number = p->unsafe_episodes;
		return 0;
	}
	if (p->failed)
		return -1;
	args.p = p;
	args.name = name;
	args.v = v;
	if (drv_protect(p->d, field_work, &args, err, sizeof(err)) != 0) {
		fail(p, err);
		return -1;
	}
	return v->type == VMAC_VALUE_NONE ? -1 : 0;
}

uint32_t vmac_luaplant_unsafe_episodes(const struct vmac_luaplant *p)
{
	return p->unsafe_episodes;
}

const char *vmac_luaplant_unsafe_text(const struct vmac_luaplant *p)
{
	return p->unsafe_text;
}

const char *vmac_luaplant_failure(const struct vmac_luaplant *p)
{
	return p->failed ? p->failure : NULL;
}

uint64_t vmac_luaplant_call_ns(const struct vmac_luaplant *p)
{
	return p->d->call_ns;
}
