/* A driver file into a new sandboxed state: the dev table and its methods,
 * the keys of a tick, the accessors of driver.h, and freeing. */
#include "internal.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- dev methods ---- */

/* dev:set_level(n) -> true | nil, message */
static int dev_set_level(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
	char why[200];
	lua_Number n = luaL_checknumber(L, 2);
	if (n != floor(n) || n < 0 || n > d->max_level)
		return luaL_error(L, "set_level: level must be a whole number 0..%d", (int)d->max_level);
	if (!d->host.set_level) {
		lua_pushnil(L);
		lua_pushliteral(L, "set_level: not attached to a bus");
		return 2;
	}
	if (d->host.set_level(d->host.ctx, (unsigned)n, why, sizeof(why)) != 0) {
		lua_pushnil(L);
		lua_pushstring(L, why);
		return 2;
	}
	lua_pushboolean(L, 1);
	return 1;
}

/* dev:output_at(s) -> true | nil, message: this tick's outputs released s
 * seconds after the planned start of the slot that carries them, at or
 * after the pattern's own instant and within the period. */
static int dev_output_at(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
	lua_Number s = luaL_checknumber(L, 2);
	double from = d->timing.pattern == VMAC_TIMING_OFFSETS ? d->timing.output_us / 1e6 : d->lead_us / 1e6;
	double period = (double)((uint64_t)d->slot_us << d->level) / 1e6;
	if (d->timing.pattern == VMAC_TIMING_ARRIVAL || d->slot_us == 0) {
		lua_pushnil(L);
		lua_pushliteral(L, "output_at: the machine acts on arrival (timing.pattern) or is on no bus");
		return 2;
	}
	if (!(s >= from && s < period)) {
		lua_pushnil(L);
		lua_pushfstring(L,
		                "output_at: %f s is not from the machine's output instant (%f s) to its period (%f s)",
		                (double)s, from, period);
		return 2;
	}
	d->out_at_s = s;
	lua_pushboolean(L, 1);
	return 1;
}

/* dev:event(text): at most EVENTS_PER_S per second of bus time. */
static int dev_event(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
	const char *text = luaL_checkstring(L, 2);
	if (d->now_s - d->event_window_s >= 1) {
		d->event_window_s = d->now_s;
		d->events_in_window = 0;
	}
	if (++d->events_in_window <= EVENTS_PER_S && d->host.event)
		d->host.event(d->host.ctx, "driver", text);
	return 0;
}

/* The keys of a tick as Lua strings, in one array (registry ref_keys): I/O
 * names, then variable names, then "time", "out", "vars", "state". A tick
 * pushes them by index instead of hashing C strings into Lua strings every
 * time, and reading another state's dev.state with them allocates nothing.
 * [-0, +0] */

static void make_keys(struct vmac_driver *d)
{
	lua_State *L = d->L;
	int i;
	lua_createtable(L, key_state(d), 0);
	for (i = 0; i < d->nio; i++) {
		lua_pushstring(L, d->io[i].name);
		lua_rawseti(L, -2, key_io(d, i));
	}
	for (i = 0; i < d->nvars; i++) {
		lua_pushstring(L, d->vars[i].pub.name);
		lua_rawseti(L, -2, key_var(d, i));
	}
	lua_pushliteral(L, "time");
	lua_rawseti(L, -2, key_time(d));
	lua_pushliteral(L, "out");
	lua_rawseti(L, -2, key_out(d));
	lua_pushliteral(L, "vars");
	lua_rawseti(L, -2, key_vars(d));
	lua_pushliteral(L, "state");
	lua_rawseti(L, -2, key_state(d));
	d->ref_keys = luaL_ref(L, LUA_REGISTRYINDEX);
}

/* The dev table, with params (on top) moved into it: [-1, +0]. */
static void make_dev(struct vmac_driver *d)
{
	lua_State *L = d->L;
	int params = lua_gettop(L);
	lua_createtable(L, 0, 12);
	lua_pushstring(L, d->name);
	lua_setfield(L, -2, "name");
	lua_pushstring(L, d->name);
	lua_setfield(L, -2, "driver");
	lua_pushstring(L, d->version);
	lua_setfield(L, -2, "version");
	lua_pushinteger(L, (lua_Integer)d->level);
	lua_setfield(L, -2, "level");
	lua_newtable(L);
	lua_pushvalue(L, -1);
	d->ref_out = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_setfield(L, -2, "out");
	lua_newtable(L);
	lua_pushvalue(L, -1);
	d->ref_vars = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_setfield(L, -2, "vars");
	lua_pushvalue(L, params);
	lua_pushvalue(L, -1);
	d->ref_params = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_setfield(L, -2, "params");
	lua_newtable(L);
	lua_setfield(L, -2, "state");
	lua_newtable(L);
	lua_setfield(L, -2, "boards");
	lua_pushcfunction(L, dev_set_level);
	lua_setfield(L, -2, "set_level");
	lua_pushcfunction(L, dev_output_at);
	lua_setfield(L, -2, "output_at");
	lua_pushcfunction(L, dev_event);
	lua_setfield(L, -2, "event");
	lua_pushcfunction(L, drv_dev_checkpoint);
	lua_setfield(L, -2, "checkpoint");
	d->ref_dev = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_settop(L, params - 1);
	/* The inputs table, reused every tick: every name present from the
	 * start, so a tick allocates nothing for it. */
	lua_createtable(L, 0, d->nio + 1);
	d->ref_inputs = luaL_ref(L, LUA_REGISTRYINDEX);
	make_keys(d);
}

int vmac_driver_load(const char *path, const struct vmac_driver_limits *limits, struct vmac_driver **out, char *err,
                     size_t errlen)
{
	const char *base = strrchr(path, '/');
	size_t len = 0;
	int code = 0;
	char *src = vmac_read_file(path, VMAC_DRIVER_FILE_MAX, &len, err, errlen, &code);
	*out = NULL;
	if (!src)
		return code;
	code = vmac_driver_load_source(base ? base + 1 : path, src, len, limits, out, err, errlen);
	free(src);
	return code;
}

/* The libraries the sandbox copies from (drv_make_env), in a state of
 * nothing else: [-0, +0]. */
static int open_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	lua_State *L = d->L;
	(void)args;
	/* The jit library sets the compiler's parameters (without it jit = true
	 * compiles nothing), then the interpreter only: the count hook that
	 * enforces the budget is not honoured inside JIT-compiled traces. The
	 * sandbox gives drivers no `jit` (drv_make_env). */
	if (drv_open_lib(L, luaopen_jit, LUA_JITLIBNAME)) {
		snprintf(err, errlen, "cannot open the jit library: not enough memory");
		return -1;
	}
	luaJIT_setmode(L, 0, LUAJIT_MODE_ENGINE | LUAJIT_MODE_OFF);
	if (drv_open_lib(L, luaopen_base, "") || drv_open_lib(L, luaopen_string, LUA_STRLIBNAME) ||
	    drv_open_lib(L, luaopen_table, LUA_TABLIBNAME) || drv_open_lib(L, luaopen_math, LUA_MATHLIBNAME) ||
	    drv_open_lib(L, luaopen_bit, LUA_BITLIBNAME)) {
		snprintf(err, errlen, "cannot open libraries: %s",
		         lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "not enough memory");
		return -1;
	}
	lua_getglobal(L, "string");
	lua_pushnil(L);
	lua_setfield(L, -2, "dump");
	lua_pop(L, 1);
	return 0;
}

struct load_args {
	const char *src;
	size_t len;
	const struct vmac_driver_limits *limits;
};

int drv_load_chunk(struct vmac_driver *d, const char *src, size_t len, char *err, size_t errlen)
{
	lua_State *L = d->L;
	char chunkname[80];
	snprintf(chunkname, sizeof(chunkname), "@%s", d->file);
	if (luaL_loadbufferx(L, src, len, chunkname, "t") != 0) {
		snprintf(err, errlen, "%s", lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "not enough memory");
		return -1;
	}
	drv_make_env(L);
	lua_setfenv(L, -2);
	return 0;
}

static int load_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct load_args *a = args;
	lua_State *L = d->L;
	if (drv_load_chunk(d, a->src, a->len, err, errlen) != 0)
		return -1;
	d->loading = 1;
	if (drv_guarded_call(d, 0, 1, VMAC_DRIVER_LOAD_FACTOR, err, errlen) != 0) {
		d->loading = 0;
		d->programmes = NULL;
		return -1;
	}
	d->loading = 0;
	d->programmes = NULL; /* the limits' are the caller's: not kept past the load */
	if (!lua_istable(L, -1)) {
		snprintf(err, errlen, "%s: the file must return a table (the driver), got %s", d->file,
		         luaL_typename(L, -1));
		return -1;
	}
	if (drv_parse_manifest(d, a->limits, err, errlen) != 0)
		return -1;
	make_dev(d);                                      /* consumes params */
	d->ref_manifest = luaL_ref(L, LUA_REGISTRYINDEX); /* the driver table */
	if (drv_describe(d, err, errlen) != 0)
		return -1;
	if (d->jit)
		luaJIT_setmode(L, 0, LUAJIT_MODE_ENGINE | LUAJIT_MODE_ON);
	lua_settop(L, 0);
	lua_gc(L, LUA_GCCOLLECT, 0);
	return 0;
}

int vmac_driver_new(const char *file, const struct vmac_driver_limits *limits, struct vmac_driver **out, char *err,
                    size_t errlen)
{
	struct vmac_driver *d;
	lua_State *L;

	*out = NULL;
	d = calloc(1, sizeof(*d));
	if (!d) {
		snprintf(err, errlen, "out of memory");
		return -ENOMEM;
	}
	d->cap = limits->memory_bytes;
	d->instruction_budget = limits->instructions;
	d->budget_hooks = limits->instructions / HOOK_EVERY + 1;
	d->budget_ns = (int64_t)limits->budget_us * 1000;
	d->clock = limits->clock;
	d->clock_ctx = limits->clock_ctx;
	d->heap = limits->heap;
	d->heap_ctx = limits->heap_ctx;
	d->ref_tick = d->ref_attach = d->ref_input = d->ref_detach = d->ref_migrate = d->ref_recover = LUA_NOREF;
	d->ref_saved = LUA_NOREF;
	snprintf(d->file, sizeof(d->file), "%s", file);
	snprintf(d->name, sizeof(d->name), "?");
	L = d->L = lua_newstate(drv_alloc, d);
	if (!L) {
		free(d);
		snprintf(err, errlen, "cannot create Lua state");
		return -ENOMEM;
	}
	lua_atpanic(L, drv_on_panic);
	if (lua_cpcall(L, drv_make_entries, d) != 0) {
		snprintf(err, errlen, "%s: not enough memory to set up the sandbox", file);
		vmac_driver_free(d);
		return -ENOMEM;
	}
	if (drv_protect(d, open_work, NULL, err, errlen) != 0) {
		vmac_driver_free(d);
		return -ENOMEM;
	}
	*out = d;
	return 0;
}

int vmac_driver_load_into(struct vmac_driver *d, const char *src, size_t len, const struct vmac_driver_limits *limits,
                          char *err, size_t errlen)
{
	struct load_args args;
	int i;

	if (d->loaded) {
		snprintf(err, errlen, "%s: a driver is loaded in this sandbox already", d->file);
		return -EALREADY;
	}
	d->loaded = 1;
	if (len > VMAC_DRIVER_FILE_MAX) {
		snprintf(err, errlen, "%s: larger than %d MiB", d->file, VMAC_DRIVER_FILE_MAX >> 20);
		return -EFBIG;
	}
	snprintf(d->name, sizeof(d->name), "%s", limits->expect_name ? limits->expect_name : "?");
	snprintf(d->stdlib_dir, sizeof(d->stdlib_dir), "%s", limits->stdlib_dir ? limits->stdlib_dir : "");
	d->programmes = limits->programmes;
	for (i = 0; i < limits->nsettings; i++) {
		const char *k = limits->settings[i].key, *v = limits->settings[i].value;
		char *end;
		double x = strtod(v, &end);
		if (strcmp(k, "memory_kib") == 0 && *end == 0 && x >= 64 && x <= 1048576)
			d->cap = (size_t)x * 1024;
		else if (strcmp(k, "instructions") == 0 && *end == 0 && x >= 1000 && x <= 1e9)
			d->instruction_budget = (uint64_t)x, d->budget_hooks = (uint64_t)x / HOOK_EVERY + 1;
		else if (strcmp(k, "budget_us") == 0 && *end == 0 && x >= 0 && x <= 1e7)
			d->budget_ns = (int64_t)x * 1000;
		else if (strncmp(k, "param.", 6) != 0 && strncmp(k, "timing.", 7) != 0) {
			snprintf(
			    err, errlen,
			    "host setting driver.%s.%s = '%s': unknown key or bad value (memory_kib, "
			    "instructions, budget_us, param.NAME, timing.pattern, timing.input_us, timing.output_us)",
			    limits->expect_name ? limits->expect_name : "?", k, v);
			return -EINVAL;
		}
	}
	args.src = src;
	args.len = len;
	args.limits = limits;
	return drv_protect(d, load_work, &args, err, errlen) != 0 ? -EINVAL : 0;
}

int vmac_driver_load_source(const char *file, const char *src, size_t len, const struct vmac_driver_limits *limits,
                            struct vmac_driver **out, char *err, size_t errlen)
{
	struct vmac_driver *d;
	int rc;

	*out = NULL;
	rc = vmac_driver_new(file, limits, &d, err, errlen);
	if (rc != 0)
		return rc;
	rc = vmac_driver_load_into(d, src, len, limits, err, errlen);
	if (rc != 0) {
		vmac_driver_free(d);
		return rc;
	}
	*out = d;
	return 0;
}

const char *vmac_driver_name(const struct vmac_driver *d)
{
	return d->name;
}

const char *vmac_driver_version(const struct vmac_driver *d)
{
	return d->version;
}

unsigned vmac_driver_level(const struct vmac_driver *d)
{
	return d->level;
}

void vmac_driver_timing(const struct vmac_driver *d, struct vmac_timing_want *out)
{
	*out = d->timing;
}

double vmac_driver_output_at(const struct vmac_driver *d)
{
	return d->out_at_s;
}

int vmac_driver_nio(const struct vmac_driver *d)
{
	return d->nio;
}

void vmac_driver_io_info(const struct vmac_driver *d, int i, struct vmac_driver_io *out)
{
	const struct io *io = &d->io[i];
	out->name = io->name;
	out->kind = io->kind;
	out->channel = io->channel;
	out->has_minor = io->has_minor;
	out->minor = io->minor;
	out->scale = io->scale;
	out->offset = io->offset;
}

void vmac_driver_bind(struct vmac_driver *d, const struct vmac_driver_host *host)
{
	d->host = *host;
}

int vmac_driver_boards(const struct vmac_driver *d)
{
	return d->nboards;
}

int vmac_driver_nvars(const struct vmac_driver *d)
{
	return d->nvars;
}

const struct vmac_variable *vmac_driver_variable(const struct vmac_driver *d, int i)
{
	return &d->vars[i].pub;
}

double vmac_driver_variable_every_s(const struct vmac_driver *d, int i)
{
	return d->vars[i].every_s;
}

void vmac_driver_set_tag(struct vmac_driver *d, int64_t tag)
{
	d->tag = tag;
}

int64_t vmac_driver_tag(const struct vmac_driver *d)
{
	return d->tag;
}

size_t vmac_driver_memory(const struct vmac_driver *d)
{
	return d->used;
}

size_t vmac_driver_memory_cap(const struct vmac_driver *d)
{
	return d->cap;
}

uint64_t vmac_driver_instructions(const struct vmac_driver *d)
{
	return d->instructions;
}

uint64_t vmac_driver_call_ns(const struct vmac_driver *d)
{
	return d->call_ns;
}

uint64_t vmac_driver_instruction_budget(const struct vmac_driver *d)
{
	return d->instruction_budget;
}

int64_t vmac_driver_budget_ns(const struct vmac_driver *d)
{
	return d->budget_ns;
}

uint64_t vmac_driver_vars_version(const struct vmac_driver *d)
{
	return d->vars_version;
}

const char *vmac_driver_lib_call(const struct vmac_driver *d)
{
	return d->lib_call;
}

void vmac_driver_free(struct vmac_driver *d)
{
	if (!d)
		return;
	lua_close(d->L);
	free(d->describe);
	free(d);
}
