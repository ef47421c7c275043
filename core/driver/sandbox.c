/* The sandbox a driver runs in (docs/DRIVERS.md "The sandbox"): its
 * global table built from nothing out of the one allow-list
 * (vmac_driver_allowed) with the bounded library functions of bounded.c
 * in it, pcall and its kin
 * that re-raise a budget or memory overrun, require and vmac.cycles (load
 * time only), os.clock. Stack contracts are stated per function. */
#include "internal.h"

#include <dirent.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* ---- the sandbox ---- */

/* pcall, xpcall and coroutine.resume as drivers see them: the originals
 * (upvalue 1), then, once the budget is spent or an allocation was refused
 * at the cap, that error again.
 * LuaJIT restarts the instruction count after every error, so in
 * `while true do pcall(f) end` the hook would always fire inside f and be
 * caught there; re-raising here makes the overrun reach the host whatever
 * the driver wraps it in. */
static int budget_checked_call(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
	const char *lib_call = d->lib_call;
	int n = lua_gettop(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, n, LUA_MULTRET);
	d->lib_call = lib_call; /* an error it caught may have left a library call's name */
	if (d->overrun)
		return luaL_error(L, "%s", d->overrun_msg);
	if (d->mem_refused) {
		/* The call is failing now: the message and the unwinding (stack for
		 * the handlers, the traceback) come from the host's reserve. */
		d->in_driver = 0;
		lua_pushliteral(L, "not enough memory (the driver's memory cap)");
		return lua_error(L);
	}
	return lua_gettop(L);
}

/* rawset refuses the read-only library tables (their metatable is locked). */
static int safe_rawset(lua_State *L)
{
	luaL_checktype(L, 1, LUA_TTABLE);
	if (lua_getmetatable(L, 1)) {
		lua_getfield(L, -1, "__metatable");
		if (lua_isstring(L, -1))
			return luaL_error(L, "rawset: this table is read-only");
		lua_pop(L, 2);
	}
	luaL_checkany(L, 3);
	lua_settop(L, 3);
	lua_rawset(L, 1);
	return 1;
}

static int read_only(lua_State *L)
{
	return luaL_error(L, "library tables are read-only (tried to set '%s')", lua_tostring(L, 2));
}

/* os.clock(): bus time in seconds (the clock of inputs.time). */
static int bus_clock(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
	lua_pushnumber(L, d->loading ? 0 : d->now_s);
	return 1;
}

/* See internal.h. */
void drv_run_sandboxed_text(lua_State *L, const char *src, size_t len, const char *chunk, const char *arg)
{
	if (luaL_loadbufferx(L, src, len, chunk, "t") != 0)
		lua_error(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_setfenv(L, -2);
	lua_pushstring(L, arg);
	lua_call(L, 1, 1);
}

void drv_run_sandboxed(lua_State *L, const char *path, const char *chunk, const char *arg)
{
	char err[300];
	size_t len = 0;
	int code = 0;
	char *src = vmac_read_file(path, VMAC_DRIVER_FILE_MAX, &len, err, sizeof(err), &code);
	if (!src)
		luaL_error(L, "%s", err);
	if (luaL_loadbufferx(L, src, len, chunk, "t") != 0) {
		free(src);
		lua_error(L);
	}
	free(src);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_setfenv(L, -2);
	lua_pushstring(L, arg);
	lua_call(L, 1, 1);
}

int drv_valid_module_name(const char *name, size_t maxlen)
{
	size_t i;
	for (i = 0; name[i]; i++)
		if (!((name[i] >= 'a' && name[i] <= 'z') || (name[i] >= '0' && name[i] <= '9') || name[i] == '_'))
			return 0;
	return i > 0 && i <= maxlen;
}

/* stdlib/NAME.lua run in the driver's sandbox: [-0, +1] what it returned
 * (true for nothing). Apart from sandbox_require so that requiring a module
 * already loaded, which a loop may do thousands of times, has no buffers on
 * its stack (under ASan every call would poison and clear them). */
static void load_module(lua_State *L, const struct vmac_driver *d, const char *name)
{
	char path[600], chunk[80];
	snprintf(path, sizeof(path), "%s/%s.lua", d->stdlib_dir, name);
	snprintf(chunk, sizeof(chunk), "@stdlib/%s.lua", name);
	if (access(path, R_OK) != 0)
		luaL_error(L, "require '%s': no such stdlib module (stdlib/%s.lua)", name, name);
	drv_run_sandboxed(L, path, chunk, name);
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		lua_pushboolean(L, 1);
	}
}

/* require(name) for drivers: loads stdlib/NAME.lua once, as text, into the
 * driver's own environment (upvalue 1), and keeps what it returned in the
 * table of loaded modules (upvalue 2). Only while the driver
 * file itself is loading (main thread): a callback must never read a file. */
static int sandbox_require(lua_State *L)
{
	struct vmac_driver *d;
	size_t nlen;
	const char *name = luaL_checklstring(L, 1, &nlen);

	/* A loaded module is looked up by the argument itself, a string Lua
	 * has already interned, in the table of loaded modules (upvalue 2):
	 * lua_getfield(name), or a lookup of that table by name, measured and
	 * compared a name again on every call of a loop. */
	lua_pushvalue(L, 1);
	lua_rawget(L, lua_upvalueindex(2));
	if (!lua_isnil(L, -1))
		return 1;
	lua_pop(L, 1);
	if (strlen(name) != nlen || !drv_valid_module_name(name, 40))
		return luaL_error(L, "require: '%s' is not a stdlib module name ([a-z0-9_], at most 40)", name);
	d = drv_of(L);
	if (!d->loading)
		return luaL_error(
		    L, "require '%s': modules can only be required when the driver loads (top of the file)", name);
	if (!d->stdlib_dir[0])
		return luaL_error(L, "require '%s': no standard library configured", name);
	load_module(L, d, name);
	lua_pushvalue(L, 1);
	lua_pushvalue(L, -2);
	lua_rawset(L, lua_upvalueindex(2));
	return 1;
}

int vmac_driver_programmes_read(const char *dir, struct vmac_driver_programmes *out, char *err, size_t errlen)
{
	DIR *d = opendir(dir);
	struct dirent *e;
	int i, j, code = 0;
	memset(out, 0, sizeof(*out));
	snprintf(out->from, sizeof(out->from), "%s", dir);
	out->owned = 1;
	if (!d)
		return 0;
	while ((e = readdir(d)) && out->n < VMAC_DRIVER_PROGRAMMES) {
		struct vmac_driver_programme *p = &out->p[out->n];
		size_t len = strlen(e->d_name);
		char path[900];
		if (len < 5 || len - 4 >= sizeof(p->name) || strcmp(e->d_name + len - 4, ".lua") != 0)
			continue;
		memcpy(p->name, e->d_name, len - 4);
		p->name[len - 4] = 0;
		if (!drv_valid_module_name(p->name, 40))
			continue;
		snprintf(path, sizeof(path), "%s/%s", dir, e->d_name);
		if (!(p->src = vmac_read_file(path, VMAC_DRIVER_FILE_MAX, &p->len, err, errlen, &code))) {
			closedir(d);
			vmac_driver_programmes_free(out);
			return code ? code : -1;
		}
		out->n++;
	}
	closedir(d);
	for (i = 1; i < out->n; i++) /* insertion sort: a handful of names */
		for (j = i; j > 0 && strcmp(out->p[j - 1].name, out->p[j].name) > 0; j--) {
			struct vmac_driver_programme t = out->p[j];
			out->p[j] = out->p[j - 1];
			out->p[j - 1] = t;
		}
	return 0;
}

void vmac_driver_programmes_free(struct vmac_driver_programmes *p)
{
	int i;
	if (p->owned)
		for (i = 0; i < p->n; i++)
			free((char *)p->p[i].src);
	p->n = 0;
}

/* vmac.cycles(): every programme the host gave the driver, run in its
 * sandbox, as a table NAME -> what the file returned, in name order. Load
 * time only. A driver that asks for its programmes needs one at least:
 * with none it raises an error that names where they were looked for, for
 * the person who forgot to put them there. */
static int sandbox_cycles(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
	const struct vmac_driver_programmes *p = d->programmes;
	char chunk[120];
	int i;

	if (!d->loading)
		return luaL_error(L, "vmac.cycles: call it when the driver loads (top of the file)");
	if (!p)
		return luaL_error(L, "vmac.cycles: no programmes for %s (the host gave none)", d->name);
	if (p->n == 0)
		return luaL_error(L, "vmac.cycles: no programmes for %s in %s/", d->name, p->from);
	lua_newtable(L);
	for (i = 0; i < p->n; i++) {
		snprintf(chunk, sizeof(chunk), "@cycles/%s/%s.lua", d->name, p->p[i].name);
		drv_run_sandboxed_text(L, p->p[i].src, p->p[i].len, chunk, p->p[i].name);
		lua_setfield(L, -2, p->p[i].name);
	}
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

/* Replace the table on top with a read-only view of it: [-1, +1]. */
static void make_read_only(lua_State *L)
{
	lua_newtable(L);          /* lib, proxy */
	lua_createtable(L, 0, 3); /* lib, proxy, mt */
	lua_pushvalue(L, -3);
	lua_setfield(L, -2, "__index");
	lua_pushcfunction(L, read_only);
	lua_setfield(L, -2, "__newindex");
	lua_pushliteral(L, "locked");
	lua_setfield(L, -2, "__metatable");
	lua_setmetatable(L, -2);
	lua_remove(L, -2);
}

/* Push a new table with the listed fields of the global library lib:
 * [-0, +1]. */
static void copy_lib(lua_State *L, const char *lib, const char *const *names)
{
	lua_getglobal(L, lib);
	lua_newtable(L);
	copy_fields(L, lua_gettop(L) - 1, names);
	lua_remove(L, -2);
}

/* ---- the allow-list ----
 * Everything a driver's global table holds, by library: the one list
 * (docs/DRIVERS.md "The sandbox"). drv_make_env() copies the `copied` names
 * from LuaJIT's own libraries as they are and puts in the `own` names
 * itself (wrapped, bounded, or the host's); `vmac lint` hands the whole
 * list to luacheck (vmac_driver_allowed). A name LuaJIT lacks (rawlen,
 * without its 5.2 extensions) is copied as nil. Adding a name here is
 * widening the sandbox: the escape corpus (tests/escape) must still fail. */
static const char *const allow_base[] = {"assert",   "error",        "ipairs",       "pairs",  "next",     "select",
                                         "tonumber", "tostring",     "type",         "unpack", "rawequal", "rawget",
                                         "rawlen",   "setmetatable", "getmetatable", NULL};
static const char *const allow_base_own[] = {"pcall", "xpcall", "rawset", "require", "_G", NULL};
static const char *const allow_str[] = {"byte", "char", "format", "len", "lower", "reverse", "sub", "upper", NULL};
static const char *const allow_str_own[] = {"rep", "find", "match", "gmatch", "gsub", NULL}; /* bounded */
static const char *const allow_tab[] = {"concat", "remove", "maxn", NULL};
static const char *const allow_tab_own[] = {"insert", "sort", NULL}; /* bounded */
static const char *const allow_math[] = {"abs",   "ceil", "floor", "max",  "min", "sqrt",   "exp",        "log",
                                         "log10", "pow",  "sin",   "cos",  "tan", "asin",   "acos",       "atan",
                                         "atan2", "fmod", "modf",  "huge", "pi",  "random", "randomseed", "frexp",
                                         "ldexp", "sinh", "cosh",  "tanh", "deg", "rad",    NULL};
static const char *const allow_bit[] = {"tobit",  "tohex",   "bnot", "band", "bor",   "bxor", "lshift",
                                        "rshift", "arshift", "rol",  "ror",  "bswap", NULL};
/* resume is the host's: like pcall it catches errors, so it must re-raise a
 * budget overrun. wrap re-raises every error by itself. */
static const char *const allow_co[] = {"create", "yield", "status", "wrap", "running", NULL};
static const char *const allow_co_own[] = {"resume", NULL};
static const char *const allow_os_own[] = {"clock", NULL}; /* bus time, nothing else of os */
static const char *const allow_vmac_own[] = {"cycles", "version", NULL};
static const char *const allow_none[] = {NULL};

const struct vmac_driver_lib vmac_driver_allowed[] = {
    {NULL, allow_base, allow_base_own}, {"string", allow_str, allow_str_own}, {"table", allow_tab, allow_tab_own},
    {"math", allow_math, allow_none},   {"bit", allow_bit, allow_none},       {"coroutine", allow_co, allow_co_own},
    {"os", allow_none, allow_os_own},   {"vmac", allow_none, allow_vmac_own}, {NULL, NULL, NULL},
};

/* Build the driver's global table from nothing, exactly vmac_driver_allowed:
 * [-0, +1]. */
void drv_make_env(lua_State *L)
{
	int env;

	lua_newtable(L);
	env = lua_gettop(L);
	copy_fields(L, LUA_GLOBALSINDEX, allow_base);
	lua_getglobal(L, "pcall");
	lua_pushcclosure(L, budget_checked_call, 1);
	lua_setfield(L, env, "pcall");
	lua_getglobal(L, "xpcall");
	lua_pushcclosure(L, budget_checked_call, 1);
	lua_setfield(L, env, "xpcall");
	lua_pushcfunction(L, safe_rawset);
	lua_setfield(L, env, "rawset");

	copy_lib(L, "string", allow_str);
	drv_wrap_bounded(L, "string");
	make_read_only(L);
	/* Methods on strings ("x"):rep(n) must reach the bounded functions too,
	 * and getmetatable("") must not hand out anything. */
	lua_pushliteral(L, "");
	lua_getmetatable(L, -1);
	lua_pushvalue(L, -3);
	lua_setfield(L, -2, "__index");
	lua_pushliteral(L, "locked");
	lua_setfield(L, -2, "__metatable");
	lua_pop(L, 2);
	lua_setfield(L, env, "string");

	copy_lib(L, "table", allow_tab);
	drv_wrap_bounded(L, "table");
	make_read_only(L);
	lua_setfield(L, env, "table");
	copy_lib(L, "math", allow_math);
	make_read_only(L);
	lua_setfield(L, env, "math");
	copy_lib(L, "bit", allow_bit);
	make_read_only(L);
	lua_setfield(L, env, "bit");
	copy_lib(L, "coroutine", allow_co);
	lua_getglobal(L, "coroutine");
	lua_getfield(L, -1, "resume");
	lua_pushcclosure(L, budget_checked_call, 1);
	lua_setfield(L, -3, "resume");
	lua_pop(L, 1);
	make_read_only(L);
	lua_setfield(L, env, "coroutine");

	lua_createtable(L, 0, 1);
	lua_pushcfunction(L, bus_clock);
	lua_setfield(L, -2, "clock");
	make_read_only(L);
	lua_setfield(L, env, "os");

	lua_createtable(L, 0, 2);
	lua_pushvalue(L, env);
	lua_pushcclosure(L, sandbox_cycles, 1);
	lua_setfield(L, -2, "cycles");
	lua_pushliteral(L, VMAC_DRIVER_API);
	lua_setfield(L, -2, "version");
	make_read_only(L);
	lua_setfield(L, env, "vmac");

	lua_pushvalue(L, env);
	lua_newtable(L); /* the modules loaded so far: name -> what the module returned */
	lua_pushcclosure(L, sandbox_require, 2);
	lua_setfield(L, env, "require");
	lua_pushvalue(L, env);
	lua_setfield(L, env, "_G");
}

int drv_open_lib(lua_State *L, lua_CFunction f, const char *name)
{
	lua_pushcfunction(L, f);
	lua_pushstring(L, name);
	return lua_pcall(L, 1, 0, 0);
}
