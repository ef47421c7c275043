/* Lua driver instances: sandbox construction, loading, the manifest, and
 * the guarded call. Stack contracts are stated per function; everything a
 * driver can reach is built up from nothing in make_env(). The driver API
 * is docs/DRIVERS.md.
 *
 * The protection rule (docs/DRIVERS.md "Isolation"): no lua_* call that can
 * allocate or raise runs on a driver's state outside a protected call.
 * Every entry point below does its Lua work inside protect(): one lua_pcall
 * of a C function made at load (entering it allocates nothing), with the
 * count hook armed, so that a metamethod the host's access happens to reach
 * is held to the budget as well. An error in the host's own work (a refused
 * allocation, above all) comes back as a failure of that driver, never as a
 * panic. Driver code runs inside that through guarded_call(), with its
 * traceback. The host may go HOST_RESERVE bytes past the cap for its own
 * work (inputs, the traceback, copied state); driver code never may, and an
 * allocation refused while driver code runs fails the call even when the
 * driver catches the error. Outside protect() only calls that neither
 * allocate nor raise are made (lua_rawgeti on the registry, pushes onto the
 * empty top-level stack, reads of plain values). The atpanic handler is the
 * last line: should anything raise outside protection after all, it jumps
 * back into protect(), which marks the driver broken, and every later call
 * fails without touching the state; the host unloads it as any failed
 * driver. */
#include "driver.h"

#include <dirent.h>
#include <errno.h>
#include <lauxlib.h>
#include <lua.h>
#include <lualib.h>
#include <jansson.h>
#include <luajit.h>
#include <math.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define HOOK_EVERY 1000 /* instructions between budget checks */
#define FILE_MAX (1 << 20)
#define REP_MAX 65536              /* bytes string.rep may build */
#define PATTERN_STEPS_MAX (1 << 24) /* worst-case steps of one pattern call */
#define EVENTS_PER_S 10
#define HOST_RESERVE (64 * 1024) /* bytes past the cap the host's own work may use */

#define IO_DI VMAC_IO_DI
#define IO_AI VMAC_IO_AI
#define IO_ENCODER VMAC_IO_ENCODER
#define IO_DO VMAC_IO_DO
#define IO_PWM VMAC_IO_PWM

struct io {
	char name[VMAC_DRIVER_NAME_MAX + 1];
	enum vmac_io_kind kind;
	unsigned channel;
	uint32_t minor;  /* board of the machine; has_minor = 0: the primary */
	int has_minor;
	int board;       /* index into boards, -1 when that board is not attached */
	double scale, offset;
};

struct var {
	struct vmac_variable pub;
	double every_s;  /* timer:N; 0 = auto */
	int group;       /* index of the group's first variable + 1; 0 = none */
	int settable;    /* set = true: an operator may set it */
	int due;
};

struct vmac_driver {
	lua_State *L;
	char stdlib_dir[512], cycles_dir[600];
	int loading;             /* require() and vmac.cycles() read files only while loading */
	size_t used, cap;        /* heap accounting of the counting allocator */
	uint64_t budget_hooks;   /* hook calls allowed per guarded call */
	uint64_t hooks;          /* hook calls so far in this call */
	int64_t budget_ns, deadline_ns; /* wall-clock budget per call; 0 = none */
	int overrun;             /* budget exceeded: keep raising until the call unwinds */
	char overrun_msg[96];
	int in_driver;           /* driver code runs now: the cap holds without the host's reserve */
	int mem_refused;         /* an allocation was refused while driver code ran (sticky for the call) */
	int ref_job, ref_traceback; /* protect()'s entry and the traceback handler, made once */
	jmp_buf panic_jmp;       /* where the atpanic handler returns to (panic_armed) */
	int panic_armed;
	int broken;              /* an error escaped protection: the state is never touched again */
	char broken_msg[200];
	int failed;              /* the host's work on it failed where no caller hears (failure says why): */
	char failure[VMAC_DRIVER_ERR_MAX]; /* the next call that reports errors fails with it */
	int ref_tick, ref_attach, ref_input, ref_detach, ref_migrate; /* registry refs, LUA_NOREF if absent */
	int ref_manifest, ref_dev, ref_inputs, ref_out, ref_vars, ref_params;
	int ref_keys; /* the names a tick reads and writes, interned once (key_*) */
	char file[64];           /* file name, for messages */
	char name[VMAC_NAME_MAX + 1];
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	unsigned level, max_level;
	int jit;
	struct io io[VMAC_DRIVER_MAX_IO];
	int nio;
	struct var vars[VMAC_DRIVER_MAX_VARS];
	int nvars;
	struct param {
		char name[VMAC_DRIVER_NAME_MAX + 1];
		char unit[16];
		int persist; /* persist = true: an operator may set it with persistence */
	} params[VMAC_DRIVER_MAX_PARAMS];
	int nparams;
	uint32_t board_minor[VMAC_DRIVER_MAX_BOARDS];
	int nboards;
	struct vmac_driver_host host;
	double (*clock)(void *ctx);
	void *clock_ctx;
	double now_s;            /* bus time of the current call */
	double event_window_s;   /* dev:event rate limit */
	int64_t tag;             /* the host's (vmac_driver_set_tag) */
	char *describe;          /* the manifest's declarations as JSON (vmac_driver_describe) */
	int events_in_window;
};

static int64_t mono_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static struct vmac_driver *driver_of(lua_State *L)
{
	struct vmac_driver *d;
	lua_getallocf(L, (void **)&d);
	return d;
}

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
	if (nsize > osize && d->used - osize + nsize > d->cap + (d->in_driver ? 0 : HOST_RESERVE)) {
		d->mem_refused |= d->in_driver;
		return NULL;
	}
	p = realloc(ptr, nsize);
	if (p)
		d->used = d->used - osize + nsize;
	return p;
}

/* Count hook, every HOOK_EVERY instructions: the instruction budget and the
 * wall-clock budget. Once over, it raises on every later hook too, so a
 * driver's pcall cannot swallow the error and carry on. */
static void budget_hook(lua_State *L, lua_Debug *ar)
{
	struct vmac_driver *d = driver_of(L);
	(void)ar;
	if (!d->overrun) {
		if (++d->hooks > d->budget_hooks) {
			snprintf(d->overrun_msg, sizeof(d->overrun_msg), "time budget exceeded (%llu instructions)",
			         (unsigned long long)(d->budget_hooks * HOOK_EVERY));
			d->overrun = 1;
		} else if (d->deadline_ns && mono_ns() > d->deadline_ns) {
			snprintf(d->overrun_msg, sizeof(d->overrun_msg), "time budget exceeded (%lld us)",
			         (long long)(d->budget_ns / 1000));
			d->overrun = 1;
		}
	}
	if (d->overrun)
		luaL_error(L, "%s", d->overrun_msg);
}

/* The error handler of guarded_call: the host's work, so it may use the
 * reserve (a driver at its cap still gets its traceback). */
static int traceback(lua_State *L)
{
	const char *msg = lua_type(L, 1) == LUA_TSTRING ? lua_tostring(L, 1) : NULL;
	driver_of(L)->in_driver = 0;
	luaL_traceback(L, L, msg ? msg : "(error object is not a string)", 1);
	return 1;
}

static void memory_message(const struct vmac_driver *d, char *err, size_t errlen)
{
	snprintf(err, errlen, "%s: memory cap exceeded (not enough memory; the cap is %zu KiB)", d->file,
	         d->cap / 1024);
}

/* The one guarded call of driver code: [-(nargs+1), +nresults]. Calls the
 * function below nargs arguments with a fresh budget (times factor); on
 * failure leaves nothing on the stack and writes the message with traceback
 * into err. Runs inside protect() only. */
static int guarded_call(struct vmac_driver *d, int nargs, int nresults, unsigned factor, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int base = lua_gettop(L) - nargs, rc;
	uint64_t hooks = d->budget_hooks;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_traceback);
	lua_insert(L, base);
	d->hooks = 0;
	d->overrun = 0;
	d->mem_refused = 0;
	d->budget_hooks = hooks * factor;
	d->deadline_ns = d->budget_ns ? mono_ns() + d->budget_ns * factor : 0;
	d->in_driver = 1;
	rc = lua_pcall(L, nargs, nresults, base);
	d->in_driver = 0;
	d->budget_hooks = hooks;
	if (rc != 0 || d->overrun || d->mem_refused) {
		/* The traceback names the file and line; when the driver swallowed
		 * the error (rc 0) there is none, only what happened. */
		const char *trace = rc != 0 && rc != LUA_ERRMEM && lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : NULL;
		if (rc == LUA_ERRMEM || d->mem_refused) {
			char what[160];
			memory_message(d, what, sizeof(what));
			snprintf(err, errlen, "%s%s%s", what, trace ? ": " : "", trace ? trace : "");
		} else {
			snprintf(err, errlen, "%s", trace ? trace : d->overrun ? d->overrun_msg : "unknown error");
		}
		lua_settop(L, base - 1);
		return -1;
	}
	lua_remove(L, base);
	return 0;
}

/* ---- protection of the host's work ---- */

/* The host's work on a driver's state: fn(d, args, err, errlen) returns 0 or
 * -1 with err; it may raise (a raise is a failure of the driver). */
typedef int (*host_work)(struct vmac_driver *d, void *args, char *err, size_t errlen);

struct job {
	struct vmac_driver *d;
	host_work fn;
	void *args;
	char *err;
	size_t errlen;
	int rc;
};

/* protect()'s entry, made once per state: [-1 (the job), +0]. */
static int run_job(lua_State *L)
{
	struct job *j = lua_touserdata(L, 1);
	lua_pop(L, 1);
	j->rc = j->fn(j->d, j->args, j->err, j->errlen);
	return 0;
}

/* The last line: an error raised outside any protected call. LuaJIT would
 * exit the process after this returns, so it never returns while an entry
 * point is armed; it says which driver and why on stderr either way. */
static int on_panic(lua_State *L)
{
	struct vmac_driver *d = driver_of(L);
	const char *msg = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "(error object is not a string)";
	snprintf(d->broken_msg, sizeof(d->broken_msg), "%s: error outside a protected call: %s", d->file, msg);
	fprintf(stderr, "vmac: driver %s: %s%s\n", d->name, d->broken_msg,
	        d->panic_armed ? "; the driver is stopped" : "; cannot recover, the process ends");
	if (d->panic_armed)
		longjmp(d->panic_jmp, 1);
	return 0;
}

/* Run fn inside one protected call with the budget's hook armed (factor
 * budgets for the host's own work). 0, or -1 with err. Entering allocates
 * nothing: the entry function is in the registry, the job is light
 * userdata, and the top-level stack is empty between calls. */
static int protect_any(struct vmac_driver *d, host_work fn, void *args, char *err, size_t errlen)
{
	lua_State *L = d->L;
	struct job job;
	volatile int rc;
	if (d->broken) {
		snprintf(err, errlen, "%s", d->broken_msg);
		return -1;
	}
	job.d = d;
	job.fn = fn;
	job.args = args;
	job.err = err;
	job.errlen = errlen;
	job.rc = -1;
	if (setjmp(d->panic_jmp) != 0) {
		d->panic_armed = 0;
		d->broken = 1;
		d->in_driver = 0;
		lua_sethook(L, NULL, 0, 0);
		snprintf(err, errlen, "%s", d->broken_msg);
		return -1;
	}
	d->panic_armed = 1;
	lua_settop(L, 0);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_job);
	lua_pushlightuserdata(L, &job);
	d->hooks = 0;
	d->overrun = 0;
	d->deadline_ns = d->budget_ns ? mono_ns() + d->budget_ns : 0;
	lua_sethook(L, budget_hook, LUA_MASKCOUNT, HOOK_EVERY);
	rc = lua_pcall(L, 1, 0, 0);
	lua_sethook(L, NULL, 0, 0);
	d->in_driver = 0;
	if (rc != 0) {
		if (rc == LUA_ERRMEM)
			snprintf(err, errlen, "%s: memory cap exceeded while the host worked on its state (the cap is %zu "
			         "KiB)", d->file, d->cap / 1024);
		else if (d->overrun)
			snprintf(err, errlen, "%s", d->overrun_msg);
		else
			snprintf(err, errlen, "%s", lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "unknown error");
		job.rc = -1;
	}
	lua_settop(L, 0);
	d->panic_armed = 0;
	return job.rc;
}

/* protect_any for an instance that may run: one whose host work failed
 * unheard (d->failed) fails here with that reason. */
static int protect(struct vmac_driver *d, host_work fn, void *args, char *err, size_t errlen)
{
	if (d->failed) {
		snprintf(err, errlen, "%s", d->failure);
		return -1;
	}
	return protect_any(d, fn, args, err, errlen);
}

/* protect for callers that hear no error: a failure is kept for the next
 * call that can report it. */
static void protect_quiet(struct vmac_driver *d, host_work fn, void *args)
{
	char err[VMAC_DRIVER_ERR_MAX];
	if (protect(d, fn, args, err, sizeof(err)) != 0 && !d->failed) {
		d->failed = 1;
		snprintf(d->failure, sizeof(d->failure), "%s", err);
	}
}

/* Raw field access by name (no metamethod runs): [-0, +1] and [-1, +0];
 * i is an absolute index. May allocate the key: protected work only. */
static void raw_getfield(lua_State *L, int i, const char *k)
{
	lua_pushstring(L, k);
	lua_rawget(L, i);
}

static void raw_setfield(lua_State *L, int i, const char *k)
{
	lua_pushstring(L, k);
	lua_insert(L, -2);
	lua_rawset(L, i);
}

/* ---- the sandbox ---- */

/* string.rep bounded: one C call must not stall the bus. */
static int safe_rep(lua_State *L)
{
	size_t len, seplen = 0;
	lua_Integer n;
	luaL_checklstring(L, 1, &len);
	n = luaL_checkinteger(L, 2);
	luaL_optlstring(L, 3, "", &seplen);
	if (n > 0 && ((double)(len + seplen) * (double)n > REP_MAX || n > REP_MAX))
		return luaL_error(L, "string.rep result too large (limit %d bytes)", REP_MAX);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, lua_gettop(L) - 1, 1);
	return 1;
}

/* Worst-case steps of matching pattern p against a subject of n bytes: Lua
 * patterns backtrack, so each unbounded quantifier (*, +, -) can multiply
 * the work by n, each ? by 2, and an unanchored search tries n starts. One
 * pass over the items of the pattern: %x, %bxy, %f[set], [set], or one
 * character, each maybe followed by a quantifier. */
static double pattern_cost(const char *p, size_t plen, size_t n)
{
	double cost = 1, nn = (double)n + 1;
	size_t i = 0;
	if (plen > 0 && p[0] == '^')
		i = 1;
	else
		cost = nn;
	while (i < plen) {
		char c = p[i];
		if (c == '(' || c == ')') { /* captures: no item of their own */
			i++;
			continue;
		}
		if (c == '%' && i + 1 < plen && p[i + 1] == 'b') {
			i += 4; /* %bxy: balanced match, linear */
			continue;
		}
		if (c == '%' && i + 1 < plen && p[i + 1] == 'f') {
			i += 2; /* %f[set]: a frontier, zero width */
			if (i < plen && p[i] == '[') {
				i++;
				if (i < plen && p[i] == '^')
					i++;
				if (i < plen && p[i] == ']')
					i++;
				while (i < plen && p[i] != ']')
					i += p[i] == '%' ? 2 : 1;
				i++;
			}
			continue;
		}
		if (c == '%') {
			i += 2;
		} else if (c == '[') {
			i++;
			if (i < plen && p[i] == '^')
				i++;
			if (i < plen && p[i] == ']')
				i++;
			while (i < plen && p[i] != ']')
				i += p[i] == '%' ? 2 : 1;
			i++;
		} else {
			i++;
		}
		if (i < plen && (p[i] == '*' || p[i] == '+' || p[i] == '-')) {
			cost *= nn;
			i++;
		} else if (i < plen && p[i] == '?') {
			cost *= 2;
			i++;
		}
	}
	return cost;
}

/* string.find/match/gmatch/gsub bounded (upvalue 1: the original). */
static int safe_pattern(lua_State *L)
{
	size_t n, plen;
	const char *p;
	luaL_checklstring(L, 1, &n);
	p = luaL_checklstring(L, 2, &plen);
	if (!(lua_gettop(L) >= 4 && lua_toboolean(L, 4) && lua_tocfunction(L, lua_upvalueindex(2)) != NULL) &&
	    pattern_cost(p, plen, n) > PATTERN_STEPS_MAX)
		return luaL_error(L, "pattern too costly for a %d-byte subject (worst case over %d steps): "
		                     "use fewer '*', '+', '-' or a shorter string",
		                  (int)n, PATTERN_STEPS_MAX);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, lua_gettop(L) - 1, LUA_MULTRET);
	return lua_gettop(L);
}

/* pcall, xpcall and coroutine.resume as drivers see them: the originals
 * (upvalue 1), then, once the budget is spent or an allocation was refused
 * at the cap, that error again.
 * LuaJIT restarts the instruction count after every error, so in
 * `while true do pcall(f) end` the hook would always fire inside f and be
 * caught there; re-raising here makes the overrun reach the host whatever
 * the driver wraps it in. */
static int budget_checked_call(lua_State *L)
{
	struct vmac_driver *d = driver_of(L);
	int n = lua_gettop(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, n, LUA_MULTRET);
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
	struct vmac_driver *d = driver_of(L);
	lua_pushnumber(L, d->loading ? 0 : d->now_s);
	return 1;
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

/* Load a file as text into the driver's environment (upvalue 1 of the
 * calling C closure) and call it with arg: [-0, +1] the result, or raises. */
static void run_sandboxed(lua_State *L, const char *path, const char *chunk, const char *arg)
{
	char err[300];
	size_t len = 0;
	int code = 0;
	char *src = read_file(path, &len, err, sizeof(err), &code);
	if (!src)
		luaL_error(L, "%s", err);
	code = luaL_loadbufferx(L, src, len, chunk, "t");
	free(src);
	if (code != 0)
		lua_error(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_setfenv(L, -2);
	lua_pushstring(L, arg);
	lua_call(L, 1, 1);
}

static int valid_module_name(const char *name, size_t maxlen)
{
	size_t i;
	for (i = 0; name[i]; i++)
		if (!((name[i] >= 'a' && name[i] <= 'z') || (name[i] >= '0' && name[i] <= '9') || name[i] == '_'))
			return 0;
	return i > 0 && i <= maxlen;
}

/* require(name) for drivers: loads stdlib/NAME.lua once, as text, into the
 * driver's own environment (upvalue 1), and caches it. Only while the driver
 * file itself is loading (main thread): a callback must never read a file. */
static int sandbox_require(lua_State *L)
{
	struct vmac_driver *d = driver_of(L);
	size_t nlen;
	const char *name = luaL_checklstring(L, 1, &nlen);
	char path[600], chunk[80];

	lua_getfield(L, LUA_REGISTRYINDEX, "vmac.loaded");
	lua_getfield(L, -1, name);
	if (!lua_isnil(L, -1))
		return 1;
	lua_pop(L, 1);
	if (strlen(name) != nlen || !valid_module_name(name, 40))
		return luaL_error(L, "require: '%s' is not a stdlib module name ([a-z0-9_], at most 40)", name);
	if (!d->loading)
		return luaL_error(L, "require '%s': modules can only be required when the driver loads (top of the file)",
		                  name);
	if (!d->stdlib_dir[0])
		return luaL_error(L, "require '%s': no standard library configured", name);
	snprintf(path, sizeof(path), "%s/%s.lua", d->stdlib_dir, name);
	snprintf(chunk, sizeof(chunk), "@stdlib/%s.lua", name);
	if (access(path, R_OK) != 0)
		return luaL_error(L, "require '%s': no such stdlib module (stdlib/%s.lua)", name, name);
	run_sandboxed(L, path, chunk, name);
	if (lua_isnil(L, -1)) {
		lua_pop(L, 1);
		lua_pushboolean(L, 1);
	}
	lua_pushvalue(L, -1);
	lua_setfield(L, -3, name);
	return 1;
}

/* vmac.cycles(): every CYCLES_DIR/NAME.lua, run in the driver's sandbox, as
 * a table NAME -> what the file returned, in name order. Load time only.
 * The names live on the C stack, so a file that raises leaks nothing. */
static int sandbox_cycles(lua_State *L)
{
	struct vmac_driver *d = driver_of(L);
	char names[64][48], path[900], chunk[120];
	int n = 0, i, j;
	DIR *dir;
	struct dirent *e;

	if (!d->loading)
		return luaL_error(L, "vmac.cycles: call it when the driver loads (top of the file)");
	lua_newtable(L);
	if (!d->cycles_dir[0] || !(dir = opendir(d->cycles_dir)))
		return 1;
	while ((e = readdir(dir)) && n < 64) {
		size_t len = strlen(e->d_name);
		if (len < 5 || len - 4 >= sizeof(names[0]) || strcmp(e->d_name + len - 4, ".lua") != 0)
			continue;
		memcpy(names[n], e->d_name, len - 4);
		names[n][len - 4] = 0;
		if (valid_module_name(names[n], 40))
			n++;
	}
	closedir(dir);
	for (i = 1; i < n; i++) /* insertion sort: a handful of names */
		for (j = i; j > 0 && strcmp(names[j - 1], names[j]) > 0; j--) {
			char t[48];
			memcpy(t, names[j], sizeof(t));
			memcpy(names[j], names[j - 1], sizeof(t));
			memcpy(names[j - 1], t, sizeof(t));
		}
	for (i = 0; i < n; i++) {
		snprintf(path, sizeof(path), "%s/%s.lua", d->cycles_dir, names[i]);
		snprintf(chunk, sizeof(chunk), "@cycles/%s/%s.lua", d->name, names[i]);
		run_sandboxed(L, path, chunk, names[i]);
		lua_setfield(L, -2, names[i]);
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
	lua_newtable(L);                 /* lib, proxy */
	lua_createtable(L, 0, 3);        /* lib, proxy, mt */
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

/* t[name] = closure(t_orig[name] [, marker]) on the table on top: [-0, +0]. */
static void wrap_field(lua_State *L, const char *lib, const char *name, lua_CFunction f, int marker)
{
	lua_getglobal(L, lib);
	lua_getfield(L, -1, name);
	lua_remove(L, -2);
	if (marker)
		lua_pushcfunction(L, read_only);
	else
		lua_pushnil(L);
	lua_pushcclosure(L, f, 2);
	lua_setfield(L, -2, name);
}

/* ---- the allow-list ----
 * Everything a driver's global table holds, by library: the one list
 * (docs/DRIVERS.md "The sandbox"). make_env() copies the `copied` names
 * from LuaJIT's own libraries as they are and puts in the `own` names
 * itself (wrapped, bounded, or the host's); `vmac lint` hands the whole
 * list to luacheck (vmac_driver_allowed). A name LuaJIT lacks (rawlen,
 * without its 5.2 extensions) is copied as nil. Adding a name here is
 * widening the sandbox: the escape corpus (tests/escape) must still fail. */
static const char *const allow_base[] = {"assert", "error", "ipairs", "pairs", "next", "select", "tonumber",
                                         "tostring", "type", "unpack", "rawequal", "rawget", "rawlen",
                                         "setmetatable", "getmetatable", NULL};
static const char *const allow_base_own[] = {"pcall", "xpcall", "rawset", "require", "_G", NULL};
static const char *const allow_str[] = {"byte", "char", "format", "len", "lower", "reverse", "sub", "upper", NULL};
static const char *const allow_str_own[] = {"rep", "find", "match", "gmatch", "gsub", NULL}; /* bounded */
static const char *const allow_tab[] = {"concat", "insert", "remove", "sort", "maxn", NULL};
static const char *const allow_math[] = {"abs", "ceil", "floor", "max", "min", "sqrt", "exp", "log", "log10",
                                         "pow", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "fmod",
                                         "modf", "huge", "pi", "random", "randomseed", "frexp", "ldexp", "sinh",
                                         "cosh", "tanh", "deg", "rad", NULL};
static const char *const allow_bit[] = {"tobit", "tohex", "bnot", "band", "bor", "bxor", "lshift", "rshift",
                                        "arshift", "rol", "ror", "bswap", NULL};
/* resume is the host's: like pcall it catches errors, so it must re-raise a
 * budget overrun. wrap re-raises every error by itself. */
static const char *const allow_co[] = {"create", "yield", "status", "wrap", "running", NULL};
static const char *const allow_co_own[] = {"resume", NULL};
static const char *const allow_os_own[] = {"clock", NULL}; /* bus time, nothing else of os */
static const char *const allow_vmac_own[] = {"cycles", "version", NULL};
static const char *const allow_none[] = {NULL};

const struct vmac_driver_lib vmac_driver_allowed[] = {
    {NULL, allow_base, allow_base_own},
    {"string", allow_str, allow_str_own},
    {"table", allow_tab, allow_none},
    {"math", allow_math, allow_none},
    {"bit", allow_bit, allow_none},
    {"coroutine", allow_co, allow_co_own},
    {"os", allow_none, allow_os_own},
    {"vmac", allow_none, allow_vmac_own},
    {NULL, NULL, NULL},
};

/* Build the driver's global table from nothing, exactly vmac_driver_allowed:
 * [-0, +1]. */
static void make_env(lua_State *L)
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
	wrap_field(L, "string", "rep", safe_rep, 0);
	wrap_field(L, "string", "find", safe_pattern, 1);
	wrap_field(L, "string", "match", safe_pattern, 0);
	wrap_field(L, "string", "gmatch", safe_pattern, 0);
	wrap_field(L, "string", "gsub", safe_pattern, 0);
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
	lua_pushliteral(L, "0.2");
	lua_setfield(L, -2, "version");
	make_read_only(L);
	lua_setfield(L, env, "vmac");

	lua_pushvalue(L, env);
	lua_pushcclosure(L, sandbox_require, 1);
	lua_setfield(L, env, "require");
	lua_pushvalue(L, env);
	lua_setfield(L, env, "_G");
}

static int open_lib(lua_State *L, lua_CFunction f, const char *name)
{
	lua_pushcfunction(L, f);
	lua_pushstring(L, name);
	return lua_pcall(L, 1, 0, 0);
}

/* ---- the manifest ---- */

#define BAD(...)                                                                                                       \
	do {                                                                                                           \
		char what_[300];                                                                                       \
		snprintf(what_, sizeof(what_), __VA_ARGS__);                                                           \
		snprintf(err, errlen, "%s: manifest: %s", d->file, what_);                                             \
		return -1;                                                                                             \
	} while (0)

static int valid_name(const char *s)
{
	size_t i;
	if (!(s[0] >= 'a' && s[0] <= 'z'))
		return 0;
	for (i = 0; s[i]; i++)
		if (!((s[i] >= 'a' && s[i] <= 'z') || (s[i] >= '0' && s[i] <= '9') || s[i] == '_'))
			return 0;
	return i <= VMAC_DRIVER_NAME_MAX;
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

static int parse_io(struct vmac_driver *d, int t, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int i, j;
	lua_getfield(L, t, "io");
	if (!lua_istable(L, -1))
		BAD("io must be a table of name = channel (%s)", CHANNELS_TEXT);
	lua_pushnil(L);
	while (lua_next(L, -2)) {
		struct io *io;
		const char *chan;
		int spec = lua_gettop(L);
		if (lua_type(L, -2) != LUA_TSTRING || !valid_name(lua_tostring(L, -2)))
			BAD("io: names are [a-z][a-z0-9_]* of at most %d characters", VMAC_DRIVER_NAME_MAX);
		if (d->nio == VMAC_DRIVER_MAX_IO)
			BAD("io: more than %d names", VMAC_DRIVER_MAX_IO);
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
				BAD("io.%s: the first element must be the channel (%s)", io->name, CHANNELS_TEXT);
			if (opt_number(L, spec, "scale", 1, &io->scale) || opt_number(L, spec, "offset", 0, &io->offset))
				BAD("io.%s: scale and offset must be numbers", io->name);
			if (opt_number(L, spec, "board", -1, &minor) || (minor != -1 && (minor < 0 || minor > 4294967295.0 ||
			                                                                  minor != floor(minor))))
				BAD("io.%s: board must be the minor id of a board of this machine", io->name);
			if (minor >= 0) {
				io->has_minor = 1;
				io->minor = (uint32_t)minor;
				io->board = -1;
			}
		} else {
			BAD("io.%s: must be a channel name or {channel, scale = , offset = , board = }", io->name);
		}
		if (parse_channel(chan, io) != 0)
			BAD("io.%s: unknown channel '%s' (%s)", io->name, chan, CHANNELS_TEXT);
		if ((io->kind == IO_DO || io->kind == IO_PWM) && (io->scale != 1 || io->offset != 0))
			BAD("io.%s: outputs take no scale or offset", io->name);
		for (j = 0; j < d->nio; j++) {
			struct io *o = &d->io[j];
			if ((io->kind == IO_DO || io->kind == IO_PWM) && o->kind == io->kind && o->channel == io->channel &&
			    o->has_minor == io->has_minor && o->minor == io->minor)
				BAD("io.%s: output %s is already io.%s", io->name, chan, o->name);
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
static int check_value(lua_State *L, int s, char *why, size_t len)
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
			snprintf(why, len, "'%s' is not one of the allowed values", lua_tostring(L, -2));
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
static int parse_params(struct vmac_driver *d, int t, const struct vmac_driver_limits *lim, char *err,
                        size_t errlen)
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
		if (lua_type(L, -2) != LUA_TSTRING || !valid_name(lua_tostring(L, -2)))
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
					BAD("params.%s: host setting driver.%s.%s = '%s' is not a number", name, d->name, key, over);
				lua_pushnumber(L, x);
			} else if (type == LUA_TBOOLEAN) {
				if (strcmp(over, "true") && strcmp(over, "false"))
					BAD("params.%s: host setting driver.%s.%s = '%s' is not true or false", name, d->name, key,
					    over);
				lua_pushboolean(L, over[0] == 't');
			} else {
				lua_pushstring(L, over);
			}
		}
		if (check_value(L, s, why, sizeof(why)) != 0)
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
overrides:
	{
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
		if (lua_type(L, -2) != LUA_TSTRING || !valid_name(lua_tostring(L, -2)))
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
				BAD("variables.%s: update must be \"auto\" or \"timer:N\" with 0 < N <= 86400 seconds, not '%s'",
				    v->pub.name, update);
		}
		if (opt_string(L, s, "group", group, sizeof(group)) || (group[0] && !valid_name(group)))
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
		if (lua_type(L, -2) != LUA_TSTRING || !valid_name(lua_tostring(L, -2)))
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

static int parse_manifest(struct vmac_driver *d, const struct vmac_driver_limits *lim, char *err, size_t errlen)
{
	static const char *const known[] = {"name", "version", "level", "description", "io", "params", "variables",
	                                    "commands", "ui", "jit", NULL};
	lua_State *L = d->L;
	int t = lua_gettop(L), params;
	double level;

	if (opt_string(L, t, "name", d->name, sizeof(d->name)) || !d->name[0])
		BAD("name (the driver's name, a string) is required");
	if (lim->expect_name && strcmp(d->name, lim->expect_name) != 0)
		BAD("name is '%s' but the board announced driver '%s'", d->name, lim->expect_name);
	if (opt_string(L, t, "version", d->version, sizeof(d->version)) || !d->version[0])
		BAD("version (a string of at most %d bytes) is required", VMAC_DRIVER_VERSION_MAX);
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
			BAD("unknown field '%s' (manifest fields: name, version, level, description, io, params, variables, "
			    "commands, ui, jit; and functions)",
			    lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : luaL_typename(L, -2));
		lua_pop(L, 1);
	}
	if (parse_io(d, t, err, errlen) || parse_variables(d, t, err, errlen) ||
	    parse_params(d, t, lim, err, errlen))
		return -1;
	params = lua_gettop(L);
	if (check_names(d, t, params, err, errlen) || callback_ref(d, t, "tick", 1, err, errlen, &d->ref_tick) ||
	    callback_ref(d, t, "attach", 0, err, errlen, &d->ref_attach) ||
	    callback_ref(d, t, "input", 0, err, errlen, &d->ref_input) ||
	    callback_ref(d, t, "detach", 0, err, errlen, &d->ref_detach) ||
	    callback_ref(d, t, "migrate", 0, err, errlen, &d->ref_migrate))
		return -1;
	return 0; /* leaves the params table on top */
}
#undef BAD

/* ---- dev methods ---- */

/* dev:set_level(n) -> true | nil, message */
static int dev_set_level(lua_State *L)
{
	struct vmac_driver *d = driver_of(L);
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

/* dev:event(text): at most EVENTS_PER_S per second of bus time. */
static int dev_event(lua_State *L)
{
	struct vmac_driver *d = driver_of(L);
	const char *text = luaL_checkstring(L, 2);
	if (d->now_s - d->event_window_s >= 1) {
		d->event_window_s = d->now_s;
		d->events_in_window = 0;
	}
	if (++d->events_in_window <= EVENTS_PER_S && d->host.event)
		d->host.event(d->host.ctx, text);
	return 0;
}

/* The keys of a tick as Lua strings, in one array (registry ref_keys): I/O
 * names, then variable names, then "time", "out", "vars", "state". A tick
 * pushes them by index instead of hashing C strings into Lua strings every
 * time, and reading another state's dev.state with them allocates nothing.
 * [-0, +0] */
static int key_io(const struct vmac_driver *d, int i) { (void)d; return i + 1; }
static int key_var(const struct vmac_driver *d, int i) { return d->nio + i + 1; }
static int key_time(const struct vmac_driver *d) { return d->nio + d->nvars + 1; }
static int key_out(const struct vmac_driver *d) { return d->nio + d->nvars + 2; }
static int key_vars(const struct vmac_driver *d) { return d->nio + d->nvars + 3; }
static int key_state(const struct vmac_driver *d) { return d->nio + d->nvars + 4; }

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
	lua_pushcfunction(L, dev_event);
	lua_setfield(L, -2, "event");
	d->ref_dev = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_settop(L, params - 1);
	/* The inputs table, reused every tick: every name present from the
	 * start, so a tick allocates nothing for it. */
	lua_createtable(L, 0, d->nio + 1);
	d->ref_inputs = luaL_ref(L, LUA_REGISTRYINDEX);
	make_keys(d);
}

int vmac_driver_load(const char *path, const struct vmac_driver_limits *limits, struct vmac_driver **out,
                     char *err, size_t errlen)
{
	const char *base = strrchr(path, '/');
	size_t len = 0;
	int code = 0;
	char *src = read_file(path, &len, err, errlen, &code);
	*out = NULL;
	if (!src)
		return code;
	code = vmac_driver_load_source(base ? base + 1 : path, src, len, limits, out, err, errlen);
	free(src);
	return code;
}

/* ---- the declarations as JSON, for user interfaces ---- */

/* The plain data at index i as JSON (depth-limited; functions and the like
 * are left out: NULL). A table with 1..n and nothing else is an array. */
static json_t *to_json(lua_State *L, int i, int depth)
{
	json_t *o;
	size_t n;
	switch (lua_type(L, i)) {
	case LUA_TBOOLEAN: return json_boolean(lua_toboolean(L, i));
	case LUA_TNUMBER: return json_real(lua_tonumber(L, i));
	case LUA_TSTRING: return json_stringn(lua_tostring(L, i), lua_objlen(L, i));
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
		json_t *v = to_json(L, -1, depth + 1);
		if (v && json_is_array(o) && lua_type(L, -2) == LUA_TNUMBER) {
			lua_Number k = lua_tonumber(L, -2);
			if (k >= 1 && k <= (lua_Number)n && k == (lua_Number)(size_t)k) {
				while (json_array_size(o) < (size_t)k)
					json_array_append_new(o, json_null());
				json_array_set_new(o, (size_t)k - 1, v);
				v = NULL;
			}
		} else if (v && json_is_object(o) && lua_type(L, -2) == LUA_TSTRING) {
			json_object_set_new(o, lua_tostring(L, -2), v);
			v = NULL;
		}
		json_decref(v);
		lua_pop(L, 1);
	}
	return o;
}

/* name, version, description, level and the tables io, variables, params,
 * commands and ui of the manifest as JSON text. Protected work: the fields
 * are fetched first (that may raise), then turned into JSON with calls that
 * neither raise nor allocate on the state, so no JSON leaks. */
static char *describe(struct vmac_driver *d)
{
	static const char *const fields[] = {"description", "io", "variables", "params", "commands", "ui", NULL};
	lua_State *L = d->L;
	int first, i;
	json_t *o;
	char *text;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_manifest);
	first = lua_gettop(L) + 1;
	for (i = 0; fields[i]; i++)
		raw_getfield(L, first - 1, fields[i]);
	luaL_checkstack(L, 2 * 10 + 4, "describe"); /* to_json: two slots a level, nine levels */
	o = json_pack("{s:s, s:s, s:i}", "name", d->name, "version", d->version, "level", (int)d->level);
	for (i = 0; fields[i] && o; i++) {
		json_t *v = to_json(L, first + i, 0);
		if (v)
			json_object_set_new(o, fields[i], v);
	}
	lua_settop(L, first - 2);
	text = o ? json_dumps(o, JSON_COMPACT) : NULL;
	json_decref(o);
	return text;
}

const char *vmac_driver_describe(const struct vmac_driver *d)
{
	return d->describe ? d->describe : "{}";
}

/* The load's Lua work, protected: libraries, the environment, the file run
 * under LOAD_FACTOR budgets, the manifest, dev, the description. */
struct load_args {
	const char *src;
	size_t len;
	const struct vmac_driver_limits *limits;
};

static int load_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct load_args *a = args;
	lua_State *L = d->L;
	char chunkname[80];
	/* Interpreter only: the count hook that enforces the budget is not
	 * honoured inside JIT-compiled traces. */
	luaJIT_setmode(L, 0, LUAJIT_MODE_ENGINE | LUAJIT_MODE_OFF);
	if (open_lib(L, luaopen_base, "") || open_lib(L, luaopen_string, LUA_STRLIBNAME) ||
	    open_lib(L, luaopen_table, LUA_TABLIBNAME) || open_lib(L, luaopen_math, LUA_MATHLIBNAME) ||
	    open_lib(L, luaopen_bit, LUA_BITLIBNAME)) {
		snprintf(err, errlen, "cannot open libraries: %s",
		         lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "not enough memory");
		return -1;
	}
	lua_getglobal(L, "string");
	lua_pushnil(L);
	lua_setfield(L, -2, "dump");
	lua_pop(L, 1);
	lua_newtable(L);
	lua_setfield(L, LUA_REGISTRYINDEX, "vmac.loaded");
	snprintf(chunkname, sizeof(chunkname), "@%s", d->file);
	if (luaL_loadbufferx(L, a->src, a->len, chunkname, "t") != 0) {
		snprintf(err, errlen, "%s", lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "not enough memory");
		return -1;
	}
	make_env(L);
	lua_setfenv(L, -2);
	d->loading = 1;
	if (guarded_call(d, 0, 1, VMAC_DRIVER_LOAD_FACTOR, err, errlen) != 0) {
		d->loading = 0;
		return -1;
	}
	d->loading = 0;
	if (!lua_istable(L, -1)) {
		snprintf(err, errlen, "%s: the file must return a table (the driver), got %s", d->file,
		         luaL_typename(L, -1));
		return -1;
	}
	if (parse_manifest(d, a->limits, err, errlen) != 0)
		return -1;
	make_dev(d);                                     /* consumes params */
	d->ref_manifest = luaL_ref(L, LUA_REGISTRYINDEX); /* the driver table */
	d->describe = describe(d);
	if (d->jit)
		luaJIT_setmode(L, 0, LUAJIT_MODE_ENGINE | LUAJIT_MODE_ON);
	lua_settop(L, 0);
	lua_gc(L, LUA_GCCOLLECT, 0);
	return 0;
}

/* protect()'s entry and the traceback handler, made once (lua_cpcall'd). */
static int make_entries(lua_State *L)
{
	struct vmac_driver *d = lua_touserdata(L, 1);
	lua_pushcfunction(L, run_job);
	d->ref_job = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_pushcfunction(L, traceback);
	d->ref_traceback = luaL_ref(L, LUA_REGISTRYINDEX);
	return 0;
}

int vmac_driver_load_source(const char *file, const char *src, size_t len, const struct vmac_driver_limits *limits,
                            struct vmac_driver **out, char *err, size_t errlen)
{
	struct vmac_driver *d;
	struct load_args args;
	int i;
	lua_State *L;

	*out = NULL;
	if (len > FILE_MAX) {
		snprintf(err, errlen, "%s: larger than 1 MiB", file);
		return -EFBIG;
	}
	d = calloc(1, sizeof(*d));
	if (!d) {
		snprintf(err, errlen, "out of memory");
		return -ENOMEM;
	}
	d->cap = limits->memory_bytes;
	d->budget_hooks = limits->instructions / HOOK_EVERY + 1;
	d->budget_ns = (int64_t)limits->budget_us * 1000;
	d->clock = limits->clock;
	d->clock_ctx = limits->clock_ctx;
	d->ref_tick = d->ref_attach = d->ref_input = d->ref_detach = d->ref_migrate = LUA_NOREF;
	for (i = 0; i < limits->nsettings; i++) {
		const char *k = limits->settings[i].key, *v = limits->settings[i].value;
		char *end;
		double x = strtod(v, &end);
		if (strcmp(k, "memory_kib") == 0 && *end == 0 && x >= 64 && x <= 1048576)
			d->cap = (size_t)x * 1024;
		else if (strcmp(k, "instructions") == 0 && *end == 0 && x >= 1000 && x <= 1e9)
			d->budget_hooks = (uint64_t)x / HOOK_EVERY + 1;
		else if (strcmp(k, "budget_us") == 0 && *end == 0 && x >= 0 && x <= 1e7)
			d->budget_ns = (int64_t)x * 1000;
		else if (strncmp(k, "param.", 6) != 0) {
			snprintf(err, errlen, "host setting driver.%s.%s = '%s': unknown key or bad value (memory_kib, "
			         "instructions, budget_us, param.NAME)", limits->expect_name ? limits->expect_name : "?", k, v);
			free(d);
			return -EINVAL;
		}
	}
	if (limits->stdlib_dir)
		snprintf(d->stdlib_dir, sizeof(d->stdlib_dir), "%s", limits->stdlib_dir);
	if (limits->cycles_dir)
		snprintf(d->cycles_dir, sizeof(d->cycles_dir), "%s", limits->cycles_dir);
	snprintf(d->file, sizeof(d->file), "%s", file);
	snprintf(d->name, sizeof(d->name), "%s", limits->expect_name ? limits->expect_name : "?");
	L = d->L = lua_newstate(counting_alloc, d);
	if (!L) {
		free(d);
		snprintf(err, errlen, "cannot create Lua state");
		return -ENOMEM;
	}
	lua_atpanic(L, on_panic);
	if (lua_cpcall(L, make_entries, d) != 0) {
		snprintf(err, errlen, "%s: not enough memory to set up the sandbox", file);
		goto fail;
	}
	args.src = src;
	args.len = len;
	args.limits = limits;
	if (protect(d, load_work, &args, err, errlen) != 0)
		goto fail;
	*out = d;
	return 0;
fail:
	lua_close(L);
	free(d->describe);
	free(d);
	return -EINVAL;
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
		raw_setfield(L, dev, "name");
	}
	raw_getfield(L, dev, "boards");
	if (lua_istable(L, -1)) {
		lua_createtable(L, 0, 2);
		lua_pushstring(L, a->name);
		raw_setfield(L, lua_gettop(L) - 1, "name");
		lua_pushnumber(L, a->minor);
		raw_setfield(L, lua_gettop(L) - 1, "minor");
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
	protect_quiet(d, add_board_work, &a); /* a failure fails the next call */
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
	raw_setfield(L, 1, "level");
	return 0;
}

void vmac_driver_set_level_now(struct vmac_driver *d, unsigned level)
{
	d->level = level;
	protect_quiet(d, set_level_work, NULL);
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
	return guarded_call(d, a->arg ? 2 : 1, 0, 1, err, errlen);
}

int vmac_driver_attach(struct vmac_driver *d, double time_s, char *err, size_t errlen)
{
	struct callback_args a = {d->ref_attach, NULL};
	if (d->ref_attach == LUA_NOREF)
		return d->failed ? protect(d, callback_work, &a, err, errlen) : 0;
	d->now_s = time_s;
	return protect(d, callback_work, &a, err, errlen);
}

void vmac_driver_detach(struct vmac_driver *d, const char *reason)
{
	struct callback_args a = {d->ref_detach, reason};
	char err[VMAC_DRIVER_ERR_MAX];
	if (d->ref_detach == LUA_NOREF)
		return;
	protect(d, callback_work, &a, err, sizeof(err)); /* the machine is going away: errors are ignored */
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
				snprintf(err, errlen, "%s: dev.out.%s must be true, false or nil, got %s", d->file, io->name,
				         luaL_typename(L, -1));
				rc = -1;
			}
		} else if (!lua_isnil(L, -1)) {
			double pwm = lua_tonumber(L, -1);
			if (lua_type(L, -1) != LUA_TNUMBER || !(pwm >= -VMAC_PWM_MAX && pwm <= VMAC_PWM_MAX)) {
				snprintf(err, errlen, "%s: dev.out.%s must be a number in -1000..1000, got %s", d->file,
				         io->name, lua_type(L, -1) == LUA_TNUMBER ? lua_tostring(L, -1) : luaL_typename(L, -1));
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

/* The value on top as a vmac_value; -1 if it has a type a variable cannot. */
static int to_value(lua_State *L, struct vmac_value *v)
{
	size_t n;
	const char *s;
	switch (lua_type(L, -1)) {
	case LUA_TNIL:
		v->type = VMAC_VALUE_NONE;
		return 0;
	case LUA_TNUMBER:
		v->type = VMAC_VALUE_NUMBER;
		v->number = lua_tonumber(L, -1);
		return 0;
	case LUA_TBOOLEAN:
		v->type = VMAC_VALUE_BOOL;
		v->number = lua_toboolean(L, -1);
		return 0;
	case LUA_TSTRING:
		s = lua_tolstring(L, -1, &n);
		if (n > VMAC_DRIVER_STR_MAX)
			n = VMAC_DRIVER_STR_MAX;
		v->type = VMAC_VALUE_STRING;
		memcpy(v->str, s, n);
		v->str[n] = 0;
		return 0;
	default:
		return -1;
	}
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
	int i, j, keys = lua_gettop(L) + 1, dev = keys + 1, t = keys + 2;
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
		if (to_value(L, &now[i]) != 0) {
			snprintf(err, errlen, "%s: dev.vars.%s must be a number, boolean, string or nil, got %s", d->file,
			         v->pub.name, luaL_typename(L, -1));
			lua_pop(L, 4);
			return -1;
		}
		lua_pop(L, 1);
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
		}
	return 0;
}

struct tick_args {
	double time_s;
	const struct vmac_inputs *const *in;
	struct vmac_outputs *const *out;
};

static int tick_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct tick_args *a = args;
	lua_State *L = d->L;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_tick);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_inputs);
	fill_inputs(d, a->time_s, a->in);
	if (guarded_call(d, 2, 0, 1, err, errlen) != 0 || read_outputs(d, a->out, err, errlen) != 0 ||
	    publish_vars(d, a->time_s, err, errlen) != 0)
		return -1;
	return 0;
}

int vmac_driver_tick(struct vmac_driver *d, double time_s, const struct vmac_inputs *const in[],
                     struct vmac_outputs *const out[], char *err, size_t errlen)
{
	struct tick_args a = {time_s, in, out};
	d->now_s = time_s;
	if (protect(d, tick_work, &a, err, errlen) != 0) {
		int i;
		for (i = 0; i < d->nboards; i++) /* a failed tick drives nothing */
			memset(out[i], 0, sizeof(*out[i]));
		return -1;
	}
	return 0;
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
	int i, top = lua_gettop(L), kind = 0; /* 1 variable, 2 param, 3 command */
	char why[160];

	for (i = 0; i < d->nvars; i++)
		if (strcmp(d->vars[i].pub.name, name) == 0) {
			if (!d->vars[i].settable) {
				snprintf(reply, replylen, "%s is read-only", name);
				return 1;
			}
			kind = 1;
		}
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_manifest);
	if (!kind) {
		lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
		raw_getfield(L, lua_gettop(L), name);
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
		return 1;
	}
	/* Push the value, then check it against the declaration. */
	if (value->type == VMAC_VALUE_NUMBER)
		lua_pushnumber(L, value->number);
	else if (value->type == VMAC_VALUE_BOOL)
		lua_pushboolean(L, value->number != 0);
	else if (value->type == VMAC_VALUE_STRING)
		lua_pushstring(L, value->str);
	else
		lua_pushboolean(L, 1);
	if (kind != 3) {
		lua_getfield(L, -2, kind == 1 ? "variables" : "params");
		lua_getfield(L, -1, name);
		lua_pushvalue(L, -3);
		if (check_value(L, lua_gettop(L) - 1, why, sizeof(why)) != 0) {
			snprintf(reply, replylen, "%s: %s", name, why);
			lua_settop(L, top);
			return 1;
		}
		lua_pop(L, 3);
		if (kind == 2) {
			lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
			lua_pushvalue(L, -2);
			raw_setfield(L, lua_gettop(L) - 1, name);
			lua_pop(L, 1);
		}
	}
	if (d->ref_input == LUA_NOREF) {
		lua_settop(L, top);
		if (kind == 2)
			return 0;
		snprintf(reply, replylen, "%s: the driver takes no input", name);
		return 1;
	}
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_input);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_pushstring(L, name);
	lua_pushvalue(L, -4);
	if (guarded_call(d, 3, 2, 1, err, errlen) != 0) {
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
	lua_settop(L, top);
	return 1;
}

int vmac_driver_input(struct vmac_driver *d, double time_s, const char *name, const struct vmac_value *value,
                      char *reply, size_t replylen, char *err, size_t errlen)
{
	struct input_args a = {time_s, name, value, reply, replylen};
	reply[0] = 0;
	d->now_s = time_s;
	return protect(d, input_work, &a, err, errlen);
}

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
	int what;     /* COPY_PARAMS, or COPY_STATE: dev.out and dev.state */
	int seen;     /* index in to: a table old table -> new table */
	int entries;
	int ref;      /* COPY_STATE: the copy of dev.state, in to's registry */
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
	case LUA_TBOOLEAN:
		lua_pushboolean(T, lua_toboolean(F, i));
		return 0;
	case LUA_TNUMBER:
		lua_pushnumber(T, lua_tonumber(F, i));
		return 0;
	case LUA_TSTRING:
		s = lua_tolstring(F, i, &n);
		lua_pushlstring(T, s, n);
		return 0;
	case LUA_TTABLE:
		return copy_table(c, i, depth);
	default:
		return 1;
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
		if (lua_type(F, -2) == LUA_TSTRING && (type == LUA_TBOOLEAN || type == LUA_TNUMBER || type == LUA_TSTRING)) {
			const char *k = lua_tostring(F, -2);
			int ok;
			if (outputs) {
				ok = is_output(c->to, k) && type != LUA_TSTRING;
			} else {
				raw_getfield(T, t, k);
				ok = lua_type(T, -1) == type;
				lua_pop(T, 1);
			}
			if (ok) {
				copy_value(c, lua_gettop(F), 0);
				raw_setfield(T, t, k);
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
		if (guarded_call(nd, 1, 0, 1, err, errlen) != 0)
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
	return guarded_call(nd, 2, 0, 1, err, errlen);
}

int vmac_driver_take_over(struct vmac_driver *nd, struct vmac_driver *od, double time_s, char *err, size_t errlen)
{
	struct take_over_args a = {od, time_s};
	/* od may be one that failed (a rollback takes over from it): only an
	 * error outside protection makes it unreadable. */
	if (protect_any(od, reserve_work, NULL, err, errlen) != 0)
		return -1;
	nd->now_s = time_s;
	return protect(nd, take_over_work, &a, err, errlen);
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
	int i;
	struct vmac_variable *out;
	const char *name;
	const struct vmac_value *v;
	char *why;
	size_t whylen;
};

static int param_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct param_args *a = args;
	lua_State *L = d->L;
	(void)err;
	(void)errlen;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_params);
	raw_getfield(L, 1, d->params[a->i].name);
	to_value(L, &a->out->value);
	return 0;
}

int vmac_driver_param(const struct vmac_driver *cd, int i, struct vmac_variable *out)
{
	struct vmac_driver *d = (struct vmac_driver *)cd; /* reads only; protection keeps flags in d */
	struct param_args a;
	memset(out, 0, sizeof(*out));
	if (i < 0 || i >= d->nparams)
		return -1;
	memcpy(out->name, d->params[i].name, sizeof(out->name));
	memcpy(out->unit, d->params[i].unit, sizeof(out->unit));
	a.i = i;
	a.out = out;
	protect_quiet(d, param_work, &a);
	return 0;
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
	raw_getfield(L, params, name);
	type = lua_type(L, -1);
	lua_pop(L, 1);
	if ((type == LUA_TNUMBER && v->type != VMAC_VALUE_NUMBER) || (type == LUA_TBOOLEAN && v->type != VMAC_VALUE_BOOL) ||
	    (type == LUA_TSTRING && v->type != VMAC_VALUE_STRING)) {
		snprintf(a->why, a->whylen, "%s: the stored value is not a %s", name, lua_typename(L, type));
		return 1;
	}
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_manifest);
	lua_getfield(L, -1, "params");
	lua_getfield(L, -1, name);
	if (v->type == VMAC_VALUE_NUMBER)
		lua_pushnumber(L, v->number);
	else if (v->type == VMAC_VALUE_BOOL)
		lua_pushboolean(L, v->number != 0);
	else
		lua_pushstring(L, v->str);
	if (check_value(L, lua_gettop(L) - 1, how, sizeof(how)) != 0) {
		snprintf(a->why, a->whylen, "%s: %s", name, how);
		return 1;
	}
	raw_setfield(L, params, name); /* dev.params[name] = value */
	return 0;
}

int vmac_driver_restore_param(struct vmac_driver *d, const char *name, const struct vmac_value *v, char *why,
                              size_t whylen)
{
	struct param_args a;
	char err[VMAC_DRIVER_ERR_MAX];
	int i = param_index(d, name), rc;
	if (i < 0 || !d->params[i].persist) {
		snprintf(why, whylen, "%s is %s", name, i < 0 ? "no longer a param of the driver" : "not persist = true");
		return -1;
	}
	memset(&a, 0, sizeof(a));
	a.name = name;
	a.v = v;
	a.why = why;
	a.whylen = whylen;
	rc = protect(d, restore_param_work, &a, err, sizeof(err));
	if (rc < 0)
		snprintf(why, whylen, "%s", err);
	return rc == 0 ? 0 : -1;
}

int vmac_driver_nvars(const struct vmac_driver *d)
{
	return d->nvars;
}

const struct vmac_variable *vmac_driver_variable(const struct vmac_driver *d, int i)
{
	return &d->vars[i].pub;
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

void vmac_driver_free(struct vmac_driver *d)
{
	if (!d)
		return;
	lua_close(d->L);
	free(d->describe);
	free(d);
}
