/* Lua driver instances: sandbox construction, loading and the guarded call.
 * Stack contracts are stated per function; everything a driver can reach is
 * built up from nothing in make_env(). */
#include "driver.h"

#include <errno.h>
#include <lauxlib.h>
#include <lua.h>
#include <lualib.h>
#include <luajit.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define HOOK_EVERY 1000 /* instructions between budget checks */
#define FILE_MAX (1 << 20)

struct vmac_driver {
	lua_State *L;
	char stdlib_dir[512];
	int loading;             /* require() may read files only while loading */
	size_t used, cap;        /* heap accounting of the counting allocator */
	uint64_t budget_hooks;   /* hook calls allowed per guarded call */
	uint64_t hooks;          /* hook calls so far in this call */
	int overrun;             /* budget exceeded: keep raising until the call unwinds */
	int ref_tick;            /* registry refs */
	int ref_inputs, ref_outputs;
	char name[64];
};

/* Counting allocator: refuses to grow past the cap, so a greedy driver gets
 * a Lua "not enough memory" error in its own state. */
static void *counting_alloc(void *ud, void *ptr, size_t osize, size_t nsize)
{
	struct vmac_driver *d = ud;
	void *p;
	if (nsize == 0) {
		if (ptr)
			d->used -= osize;
		free(ptr);
		return NULL;
	}
	if (!ptr)
		osize = 0;
	if (nsize > osize && d->used - osize + nsize > d->cap)
		return NULL;
	p = realloc(ptr, nsize);
	if (p)
		d->used = d->used - osize + nsize;
	return p;
}

/* Count hook. Once over budget it raises on every later hook too, so a
 * driver's pcall cannot swallow the error and carry on. */
static void budget_hook(lua_State *L, lua_Debug *ar)
{
	struct vmac_driver *d;
	(void)ar;
	lua_getallocf(L, (void **)&d);
	if (d->overrun || ++d->hooks > d->budget_hooks) {
		char msg[80]; /* luaL_error knows no %llu */
		d->overrun = 1;
		snprintf(msg, sizeof(msg), "time budget exceeded (%llu instructions)",
		         (unsigned long long)(d->budget_hooks * HOOK_EVERY));
		luaL_error(L, "%s", msg);
	}
}

static int traceback(lua_State *L)
{
	const char *msg = lua_tostring(L, 1);
	luaL_traceback(L, L, msg ? msg : "(error object is not a string)", 1);
	return 1;
}

/* The one guarded call: [-(nargs+1), +nresults]. Calls the function below
 * nargs arguments with a fresh budget; on failure leaves nothing on the
 * stack and writes the message with traceback into err. */
static int guarded_call(struct vmac_driver *d, int nargs, int nresults, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int base = lua_gettop(L) - nargs, rc;
	lua_pushcfunction(L, traceback);
	lua_insert(L, base);
	d->hooks = 0;
	d->overrun = 0;
	lua_sethook(L, budget_hook, LUA_MASKCOUNT, HOOK_EVERY);
	rc = lua_pcall(L, nargs, nresults, base);
	lua_sethook(L, NULL, 0, 0);
	if (rc != 0 || d->overrun) {
		const char *msg = rc != 0 ? lua_tostring(L, -1) : "time budget exceeded";
		if (rc == LUA_ERRMEM)
			msg = "memory cap exceeded";
		snprintf(err, errlen, "%s", msg ? msg : "unknown error");
		lua_settop(L, base - 1);
		return -1;
	}
	lua_remove(L, base);
	return 0;
}

/* string.rep bounded: one C call must not stall the bus. */
static int safe_rep(lua_State *L)
{
	size_t len;
	luaL_checklstring(L, 1, &len);
	lua_Integer n = luaL_checkinteger(L, 2);
	if (n > 0 && (double)len * (double)n > 65536)
		return luaL_error(L, "string.rep result too large (limit 65536 bytes)");
	lua_getfield(L, lua_upvalueindex(1), "rep");
	lua_insert(L, 1);
	lua_call(L, lua_gettop(L) - 1, 1);
	return 1;
}

/* pcall and xpcall as drivers see them: the originals (upvalue 1), then,
 * once the budget is spent, the budget error again. LuaJIT restarts the
 * instruction count after every error, so in `while true do pcall(f) end`
 * the hook would always fire inside f and be caught there; re-raising here
 * makes the overrun reach the host whatever the driver wraps it in. */
static int budget_checked_call(lua_State *L)
{
	struct vmac_driver *d;
	int n = lua_gettop(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, n, LUA_MULTRET);
	lua_getallocf(L, (void **)&d);
	if (d->overrun)
		return luaL_error(L, "time budget exceeded");
	return lua_gettop(L);
}

static char *read_file(const char *path, size_t *len, char *err, size_t errlen, int *code);

/* require(name) for drivers: loads stdlib/NAME.lua once, as text, into the
 * driver's own environment (upvalue 1), and caches it. Only while the driver
 * file itself is loading (main thread): a tick must never read a file. */
static int sandbox_require(lua_State *L)
{
	struct vmac_driver *d;
	const char *name = luaL_checkstring(L, 1);
	char path[600], chunk[80], err[300];
	size_t i, len = 0;
	int code = 0;
	char *src;

	lua_getallocf(L, (void **)&d);
	lua_getfield(L, LUA_REGISTRYINDEX, "vmac.loaded");
	lua_getfield(L, -1, name);
	if (!lua_isnil(L, -1))
		return 1;
	lua_pop(L, 1);
	for (i = 0; name[i]; i++)
		if (!((name[i] >= 'a' && name[i] <= 'z') || (name[i] >= '0' && name[i] <= '9') || name[i] == '_'))
			return luaL_error(L, "require: '%s' is not a stdlib module name ([a-z0-9_])", name);
	if (i == 0 || i > 40)
		return luaL_error(L, "require: bad module name");
	if (!d->loading)
		return luaL_error(L, "require '%s': modules can only be required when the driver loads (top of the file)",
		                  name);
	if (!d->stdlib_dir[0])
		return luaL_error(L, "require '%s': no standard library configured", name);
	snprintf(path, sizeof(path), "%s/%s.lua", d->stdlib_dir, name);
	src = read_file(path, &len, err, sizeof(err), &code);
	if (!src)
		return luaL_error(L, "require '%s': no such stdlib module (%s)", name, err);
	snprintf(chunk, sizeof(chunk), "@stdlib/%s.lua", name);
	code = luaL_loadbufferx(L, src, len, chunk, "t");
	free(src);
	if (code != 0)
		return lua_error(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_setfenv(L, -2);
	lua_pushstring(L, name);
	lua_call(L, 1, 1);
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		lua_pushboolean(L, 1);
	}
	lua_pushvalue(L, -1);
	lua_setfield(L, -3, name);
	return 1;
}

/* Copy the listed fields of the table at src (an absolute or pseudo index)
 * into the table on top of the stack: [-0, +0]. */
static void copy_fields(lua_State *L, int src, const char *const *names)
{
	for (; *names; names++) {
		lua_getfield(L, src, *names);
		lua_setfield(L, -2, *names);
	}
}

/* env.lib = a new table with the listed fields of the global library lib:
 * [-0, +0], env on top. */
static void copy_lib(lua_State *L, const char *lib, const char *const *names)
{
	lua_getglobal(L, lib); /* env, src */
	lua_newtable(L);       /* env, src, dst */
	copy_fields(L, lua_gettop(L) - 1, names);
	lua_setfield(L, -3, lib);
	lua_pop(L, 1);
}

/* Build the driver's global table from nothing: [-0, +1]. */
static void make_env(lua_State *L)
{
	static const char *const base[] = {"assert", "error", "ipairs", "pairs", "next", "select", "tonumber",
	                                   "tostring", "type", "unpack", "pcall", "xpcall", "rawequal", "rawget",
	                                   "rawset", "rawlen", "setmetatable", "getmetatable", NULL};
	static const char *const str[] = {"byte", "char", "find", "format", "gmatch", "gsub", "len", "lower",
	                                  "match", "reverse", "sub", "upper", NULL};
	static const char *const tab[] = {"concat", "insert", "remove", "sort", "maxn", NULL};
	static const char *const math[] = {"abs", "ceil", "floor", "max", "min", "sqrt", "exp", "log", "log10",
	                                   "pow", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "fmod",
	                                   "modf", "huge", "pi", "random", "randomseed", "frexp", "ldexp", "sinh",
	                                   "cosh", "tanh", "deg", "rad", NULL};
	static const char *const bit[] = {"tobit", "tohex", "bnot", "band", "bor", "bxor", "lshift", "rshift",
	                                  "arshift", "rol", "ror", "bswap", NULL};
	/* resume is replaced below: like pcall it catches errors, so it must
	 * re-raise a budget overrun. wrap re-raises on its own. */
	static const char *const co[] = {"create", "yield", "status", "wrap", "running", NULL};

	lua_newtable(L);
	copy_fields(L, LUA_GLOBALSINDEX, base);
	lua_getglobal(L, "pcall");
	lua_pushcclosure(L, budget_checked_call, 1);
	lua_setfield(L, -2, "pcall");
	lua_getglobal(L, "xpcall");
	lua_pushcclosure(L, budget_checked_call, 1);
	lua_setfield(L, -2, "xpcall");
	copy_lib(L, "string", str);
	lua_getfield(L, -1, "string");
	lua_getglobal(L, "string");
	lua_pushcclosure(L, safe_rep, 1);
	lua_setfield(L, -2, "rep");
	lua_pop(L, 1);
	copy_lib(L, "table", tab);
	copy_lib(L, "math", math);
	copy_lib(L, "bit", bit);
	copy_lib(L, "coroutine", co);
	lua_getfield(L, -1, "coroutine");
	lua_getglobal(L, "coroutine");
	lua_getfield(L, -1, "resume");
	lua_pushcclosure(L, budget_checked_call, 1);
	lua_setfield(L, -3, "resume");
	lua_pop(L, 2);
	lua_pushvalue(L, -1);
	lua_pushcclosure(L, sandbox_require, 1);
	lua_setfield(L, -2, "require");
	lua_pushvalue(L, -1);
	lua_setfield(L, -2, "_G");
}

static int open_lib(lua_State *L, lua_CFunction f, const char *name)
{
	lua_pushcfunction(L, f);
	lua_pushstring(L, name);
	return lua_pcall(L, 1, 0, 0);
}

static char *read_file(const char *path, size_t *len, char *err, size_t errlen, int *code)
{
	FILE *f = fopen(path, "rb");
	char *buf;
	if (!f) {
		*code = -errno;
		snprintf(err, errlen, "%s: %s", path, strerror(errno));
		return NULL;
	}
	buf = malloc(FILE_MAX + 1);
	if (!buf) {
		fclose(f);
		*code = -ENOMEM;
		snprintf(err, errlen, "%s: out of memory", path);
		return NULL;
	}
	*len = fread(buf, 1, FILE_MAX + 1, f);
	if (ferror(f) || *len > FILE_MAX) {
		*code = ferror(f) ? -EIO : -EFBIG;
		snprintf(err, errlen, "%s: %s", path, ferror(f) ? "read error" : "larger than 1 MiB");
		fclose(f);
		free(buf);
		return NULL;
	}
	fclose(f);
	return buf;
}

int vmac_driver_load(const char *path, const struct vmac_driver_limits *limits, struct vmac_driver **out,
                     char *err, size_t errlen)
{
	struct vmac_driver *d;
	const char *base = strrchr(path, '/');
	char chunkname[80];
	size_t len = 0;
	int code = 0, rc;
	char *src = read_file(path, &len, err, errlen, &code);
	lua_State *L;

	*out = NULL;
	if (!src)
		return code;
	d = calloc(1, sizeof(*d));
	if (!d) {
		free(src);
		snprintf(err, errlen, "out of memory");
		return -ENOMEM;
	}
	d->cap = limits->memory_bytes;
	if (limits->stdlib_dir)
		snprintf(d->stdlib_dir, sizeof(d->stdlib_dir), "%s", limits->stdlib_dir);
	d->budget_hooks = limits->instructions / HOOK_EVERY + 1;
	snprintf(d->name, sizeof(d->name), "%s", base ? base + 1 : path);
	L = d->L = lua_newstate(counting_alloc, d);
	if (!L) {
		free(src);
		free(d);
		snprintf(err, errlen, "cannot create Lua state");
		return -ENOMEM;
	}
	/* Interpreter only: the count hook that enforces the budget is not
	 * honoured inside JIT-compiled traces. */
	luaJIT_setmode(L, 0, LUAJIT_MODE_ENGINE | LUAJIT_MODE_OFF);
	if (open_lib(L, luaopen_base, "") || open_lib(L, luaopen_string, LUA_STRLIBNAME) ||
	    open_lib(L, luaopen_table, LUA_TABLIBNAME) || open_lib(L, luaopen_math, LUA_MATHLIBNAME) ||
	    open_lib(L, luaopen_bit, LUA_BITLIBNAME)) {
		snprintf(err, errlen, "cannot open libraries: %s", lua_tostring(L, -1));
		goto fail;
	}
	/* ("").dump would reach string.dump through the string metatable. */
	lua_getglobal(L, "string");
	lua_pushnil(L);
	lua_setfield(L, -2, "dump");
	lua_pop(L, 1);
	/* Lock the string metatable: getmetatable("") must not hand out the
	 * unrestricted string library (string.rep without its bound). */
	lua_pushliteral(L, "");
	lua_getmetatable(L, -1);
	lua_pushliteral(L, "locked");
	lua_setfield(L, -2, "__metatable");
	lua_pop(L, 2);

	lua_newtable(L);
	lua_setfield(L, LUA_REGISTRYINDEX, "vmac.loaded");
	snprintf(chunkname, sizeof(chunkname), "@%s", d->name);
	if (luaL_loadbufferx(L, src, len, chunkname, "t") != 0) {
		snprintf(err, errlen, "%s", lua_tostring(L, -1));
		goto fail;
	}
	free(src);
	src = NULL;
	make_env(L);
	lua_setfenv(L, -2);
	d->loading = 1;
	rc = guarded_call(d, 0, 1, err, errlen);
	d->loading = 0;
	if (rc != 0)
		goto fail;
	if (!lua_istable(L, -1)) {
		snprintf(err, errlen, "%s: the file must return a table (the driver), got %s", d->name,
		         luaL_typename(L, -1));
		goto fail;
	}
	lua_getfield(L, -1, "tick");
	if (!lua_isfunction(L, -1)) {
		snprintf(err, errlen, "%s: the driver table has no tick function", d->name);
		goto fail;
	}
	d->ref_tick = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_pop(L, 1);
	/* Reused every tick, so a service allocates nothing for its arguments. */
	lua_createtable(L, 0, 4);
	lua_createtable(L, VMAC_DIGITAL_INPUTS, 0);
	lua_setfield(L, -2, "digital");
	lua_createtable(L, VMAC_ANALOG_INPUTS, 0);
	lua_setfield(L, -2, "analog");
	d->ref_inputs = luaL_ref(L, LUA_REGISTRYINDEX);
	*out = d;
	return 0;
fail:
	free(src);
	lua_close(L);
	free(d);
	return -EINVAL;
}

static int read_outputs(lua_State *L, struct vmac_driver *d, struct vmac_outputs *out, char *err,
                        size_t errlen)
{
	int i;
	memset(out, 0, sizeof(*out));
	if (lua_isnil(L, -1))
		return 0; /* nothing returned: everything off */
	if (!lua_istable(L, -1)) {
		snprintf(err, errlen, "%s: tick must return a table of outputs or nil, got %s", d->name,
		         luaL_typename(L, -1));
		return -1;
	}
	lua_getfield(L, -1, "digital");
	if (lua_istable(L, -1)) {
		for (i = 0; i < VMAC_DIGITAL_OUTPUTS; i++) {
			lua_rawgeti(L, -1, i + 1);
			if (lua_toboolean(L, -1))
				out->digital |= (uint8_t)(1u << i);
			lua_pop(L, 1);
		}
	} else if (!lua_isnil(L, -1)) {
		snprintf(err, errlen, "%s: outputs.digital must be a table of booleans", d->name);
		return -1;
	}
	lua_pop(L, 1);
	lua_getfield(L, -1, "pwm");
	if (!lua_isnil(L, -1)) {
		double pwm = lua_tonumber(L, -1);
		if (!lua_isnumber(L, -1) || pwm != pwm || pwm < -VMAC_PWM_MAX || pwm > VMAC_PWM_MAX) {
			snprintf(err, errlen, "%s: outputs.pwm must be a number in -1000..1000, got %s", d->name,
			         lua_isnumber(L, -1) ? lua_tostring(L, -1) : luaL_typename(L, -1));
			return -1;
		}
		out->pwm = (int16_t)pwm;
	}
	lua_pop(L, 1);
	return 0;
}

/* Push inputs[name], recreating it when the driver replaced it with
 * something else: [-0, +1], inputs table on top on entry. */
static void subtable(lua_State *L, const char *name, int size)
{
	lua_getfield(L, -1, name);
	if (lua_istable(L, -1))
		return;
	lua_pop(L, 1);
	lua_createtable(L, size, 0);
	lua_pushvalue(L, -1);
	lua_setfield(L, -3, name);
}

int vmac_driver_tick(struct vmac_driver *d, double time_s, const struct vmac_inputs *in,
                     struct vmac_outputs *out, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int i, rc;

	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_tick);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_inputs);
	subtable(L, "digital", VMAC_DIGITAL_INPUTS);
	for (i = 0; i < VMAC_DIGITAL_INPUTS; i++) {
		lua_pushboolean(L, (in->digital >> i) & 1);
		lua_rawseti(L, -2, i + 1);
	}
	lua_pop(L, 1);
	subtable(L, "analog", VMAC_ANALOG_INPUTS);
	for (i = 0; i < VMAC_ANALOG_INPUTS; i++) {
		lua_pushinteger(L, in->analog[i]);
		lua_rawseti(L, -2, i + 1);
	}
	lua_pop(L, 1);
	lua_pushinteger(L, in->encoder);
	lua_setfield(L, -2, "encoder");
	lua_pushnumber(L, time_s);
	lua_setfield(L, -2, "time");
	if (guarded_call(d, 1, 1, err, errlen) != 0)
		return -1;
	rc = read_outputs(L, d, out, err, errlen);
	lua_pop(L, 1);
	return rc;
}

size_t vmac_driver_memory(const struct vmac_driver *d)
{
	return d->used;
}

void vmac_driver_free(struct vmac_driver *d)
{
	if (!d)
		return;
	lua_close(d->L);
	free(d);
}
