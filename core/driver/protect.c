/* The protection rule (docs/DRIVERS.md "Isolation"): the counting
 * allocator with its cap, the budget hook, the one guarded call of driver
 * code, and drv_protect() around every piece of the host's own work.
 *
 * The rule: no lua_* call that can allocate or raise runs on a driver's
 * state outside a protected call. Every entry point of driver.h does its
 * Lua work inside drv_protect(): one lua_pcall
 * of a C function made at load (entering it allocates nothing), with the
 * count hook armed, so that a metamethod the host's access happens to reach
 * is held to the budget as well. An error in the host's own work (a refused
 * allocation, above all) comes back as a failure of that driver, never as a
 * panic. Driver code runs inside that through drv_guarded_call(), with its
 * traceback. The host may go HOST_RESERVE bytes past the cap for its own
 * work (inputs, the traceback, copied state); driver code never may, and an
 * allocation refused while driver code runs fails the call even when the
 * driver catches the error. Outside drv_protect() only calls that neither
 * allocate nor raise are made (lua_rawgeti on the registry, pushes onto the
 * empty top-level stack, reads of plain values). The atpanic handler is the
 * last line: should anything raise outside protection after all, it jumps
 * back into drv_protect(), which marks the driver broken, and every later call
 * fails without touching the state; the host unloads it as any failed
 * driver. */
#include "internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static _Thread_local int forbidden_thread;

void vmac_driver_forbid_thread(void)
{
	forbidden_thread = 1;
}

int64_t drv_mono_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

struct vmac_driver *drv_of(lua_State *L)
{
	struct vmac_driver *d;
	lua_getallocf(L, (void **)&d);
	return d;
}

/* Counting allocator: refuses to grow past the cap, so a greedy driver gets
 * a Lua "not enough memory" error in its own state. The memory itself comes
 * from the C library or from the limits' heap. */
void *drv_alloc(void *ud, void *ptr, size_t osize, size_t nsize)
{
	struct vmac_driver *d = ud;
	void *p;
	if (nsize == 0) {
		if (ptr)
			d->used -= osize;
		if (d->heap)
			d->heap(d->heap_ctx, ptr, osize, 0);
		else
			free(ptr);
		return NULL;
	}
	if (!ptr)
		osize = 0;
	if (nsize > osize && d->used - osize + nsize > d->cap + (d->in_driver ? 0 : HOST_RESERVE)) {
		d->mem_refused |= d->in_driver;
		return NULL;
	}
	p = d->heap ? d->heap(d->heap_ctx, ptr, osize, nsize) : realloc(ptr, nsize);
	if (p)
		d->used = d->used - osize + nsize;
	return p;
}

static int64_t thread_cpu_ns(void)
{
	struct timespec ts;
	if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts) != 0)
		return -1;
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* Past the wall-clock deadline: has the call had its time? A thread that
 * the machine held off its CPUs (a loaded host, other threads before it)
 * has not. From the first look past the deadline the call is given a
 * quarter of its budget more, counted in its thread's CPU time, as the bus
 * counts a job past its limit (jobs.c, overran): a call that runs on is
 * over at 1.25 budgets, and one whose CPU is shared is over once it has
 * had that quarter, however the sharing falls. Each next look is put off
 * until the quarter could have run out at the earliest, so a look costs
 * one system call, and a call within its deadline none. */
static int held_off(struct vmac_driver *d, int64_t now)
{
	int64_t cpu = thread_cpu_ns(), grace = d->call_budget_ns / 4, left;
	if (cpu < 0)
		return 0;
	if (!d->grace_counting) {
		d->grace_counting = 1;
		d->grace_cpu_ns = cpu;
	}
	left = grace - (cpu - d->grace_cpu_ns);
	if (left <= 0)
		return 0;
	d->deadline_ns = now + (left > grace / 8 ? left : grace / 8 + 1);
	return 1;
}

/* Count hook, every HOOK_EVERY instructions: the instruction budget and the
 * wall-clock budget. Once over, it raises on every later hook too, so a
 * driver's pcall cannot swallow the error and carry on. */
/* Whether the call is over its budget (hooks counted so far, or the wall
 * clock): once it is, it stays so, with the message why. */
static int over_budget(struct vmac_driver *d)
{
	int64_t now;
	if (d->overrun)
		return 1;
	if (d->hooks > d->budget_hooks)
		snprintf(d->overrun_msg, sizeof(d->overrun_msg), "time budget exceeded (%llu instructions)",
		         (unsigned long long)(d->budget_hooks * HOOK_EVERY));
	else if (d->deadline_ns && (now = drv_mono_ns()) > d->deadline_ns && !held_off(d, now))
		snprintf(d->overrun_msg, sizeof(d->overrun_msg), "time budget exceeded (%lld us)",
		         (long long)(d->budget_ns / 1000));
	else
		return 0;
	d->overrun = 1;
	return 1;
}

static void budget_hook(lua_State *L, lua_Debug *ar)
{
	struct vmac_driver *d = drv_of(L);
	(void)ar;
	if (!d->overrun)
		d->hooks++;
	if (over_budget(d))
		luaL_error(L, "%s", d->overrun_msg);
}

/* Before a library call the sandbox estimated at `steps`: the hook counts
 * VM instructions, not the work inside C calls, so a costly call counts as
 * one instruction per STEPS_PER_INSTRUCTION of its steps and looks at the
 * wall-clock budget first. A loop of such calls ends at its budget instead
 * of running on between two hooks, in virtual time (no wall clock) too. */
void drv_charge(lua_State *L, double steps)
{
	struct vmac_driver *d = drv_of(L);
	if (steps < CHARGE_STEPS || !d->in_driver)
		return;
	if (!d->overrun)
		d->hooks += (uint64_t)(steps / (STEPS_PER_INSTRUCTION * HOOK_EVERY));
	if (over_budget(d))
		luaL_error(L, "%s", d->overrun_msg);
}

/* The error handler of drv_guarded_call: the host's work, so it may use the
 * reserve (a driver at its cap still gets its traceback). */
static int traceback(lua_State *L)
{
	const char *msg = lua_type(L, 1) == LUA_TSTRING ? lua_tostring(L, 1) : NULL;
	drv_of(L)->in_driver = 0;
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
 * into err. Runs inside drv_protect() only. */
int drv_guarded_call(struct vmac_driver *d, int nargs, int nresults, unsigned factor, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int base = lua_gettop(L) - nargs, rc;
	uint64_t hooks = d->budget_hooks;
	int64_t start_ns = drv_mono_ns();
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_traceback);
	lua_insert(L, base);
	d->hooks = 0;
	d->overrun = 0;
	d->mem_refused = 0;
	d->lib_call = NULL; /* a library call an escaped error left named */
	d->budget_hooks = hooks * factor;
	d->call_budget_ns = d->budget_ns * factor;
	d->deadline_ns = d->budget_ns ? start_ns + d->call_budget_ns : 0;
	d->grace_counting = 0;
	d->in_driver = 1;
	rc = lua_pcall(L, nargs, nresults, base);
	d->in_driver = 0;
	d->budget_hooks = hooks;
	d->instructions += d->hooks * HOOK_EVERY;
	d->call_ns += (uint64_t)(drv_mono_ns() - start_ns);
	if (rc != 0 || d->overrun || d->mem_refused) {
		/* The traceback names the file and line; when the driver swallowed
		 * the error (rc 0) there is none, only what happened. */
		const char *trace =
		    rc != 0 && rc != LUA_ERRMEM && lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : NULL;
		if (rc == LUA_ERRMEM || d->mem_refused) {
			size_t used;
			memory_message(d, err, errlen);
			used = strlen(err);
			if (trace && used + 2 < errlen) {
				snprintf(err + used, errlen - used, ": ");
				drv_traceback_clean(trace, err + used + 2, errlen - used - 2);
			}
		} else if (trace) {
			drv_traceback_clean(trace, err, errlen);
		} else {
			snprintf(err, errlen, "%s", d->overrun ? d->overrun_msg : "unknown error");
		}
		lua_settop(L, base - 1);
		return -1;
	}
	lua_remove(L, base);
	return 0;
}

/* ---- protection of the host's work ---- */

struct job {
	struct vmac_driver *d;
	host_work fn;
	void *args;
	char *err;
	size_t errlen;
	int rc;
};

/* drv_protect()'s entry, made once per state: [-1 (the job), +0]. */
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
int drv_on_panic(lua_State *L)
{
	struct vmac_driver *d = drv_of(L);
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
int drv_protect_any(struct vmac_driver *d, host_work fn, void *args, char *err, size_t errlen)
{
	lua_State *L = d->L;
	struct job job;
	volatile int rc;
	if (d->broken) {
		snprintf(err, errlen, "%s", d->broken_msg);
		return -1;
	}
	if (forbidden_thread) {
#ifdef VMAC_CHECK_THREADS
		fprintf(stderr, "vmac: driver %s called on a thread that must not run Lua (the bus thread)\n", d->name);
		abort();
#endif
		snprintf(err, errlen, "%s: host error: driver called on the bus thread", d->file);
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
	d->call_budget_ns = d->budget_ns;
	d->deadline_ns = d->budget_ns ? drv_mono_ns() + d->budget_ns : 0;
	d->grace_counting = 0;
	/* Restarts the hook's count. The hook stays set after the call: no
	 * bytecode of this state runs outside drv_protect_any, and setting it
	 * again as it is rewrites nothing, where turning it off and on again
	 * would rewrite LuaJIT's dispatch table twice a call. */
	lua_sethook(L, budget_hook, LUA_MASKCOUNT, HOOK_EVERY);
	rc = lua_pcall(L, 1, 0, 0);
	d->in_driver = 0;
	if (rc != 0) {
		if (rc == LUA_ERRMEM)
			snprintf(err, errlen,
			         "%s: memory cap exceeded while the host worked on its state (the cap is %zu "
			         "KiB)",
			         d->file, d->cap / 1024);
		else if (d->overrun)
			snprintf(err, errlen, "%s", d->overrun_msg);
		else
			snprintf(err, errlen, "%s",
			         lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "unknown error");
		job.rc = -1;
	}
	lua_settop(L, 0);
	d->panic_armed = 0;
	return job.rc;
}

/* drv_protect_any for an instance that may run: one whose host work failed
 * unheard (d->failed) fails here with that reason. */
int drv_protect(struct vmac_driver *d, host_work fn, void *args, char *err, size_t errlen)
{
	if (d->failed) {
		snprintf(err, errlen, "%s", d->failure);
		return -1;
	}
	return drv_protect_any(d, fn, args, err, errlen);
}

/* protect for callers that hear no error: a failure is kept for the next
 * call that can report it. */
void drv_protect_quiet(struct vmac_driver *d, host_work fn, void *args)
{
	char err[VMAC_DRIVER_ERR_MAX];
	if (drv_protect(d, fn, args, err, sizeof(err)) != 0 && !d->failed) {
		d->failed = 1;
		snprintf(d->failure, sizeof(d->failure), "%s", err);
	}
}

/* Raw field access by name (no metamethod runs): [-0, +1] and [-1, +0];
 * i is an absolute index. May allocate the key: protected work only. */
void drv_raw_getfield(lua_State *L, int i, const char *k)
{
	lua_pushstring(L, k);
	lua_rawget(L, i);
}

void drv_raw_setfield(lua_State *L, int i, const char *k)
{
	lua_pushstring(L, k);
	lua_insert(L, -2);
	lua_rawset(L, i);
}

/* drv_protect()'s entry and the traceback handler, made once (lua_cpcall'd). */
int drv_make_entries(lua_State *L)
{
	struct vmac_driver *d = lua_touserdata(L, 1);
	lua_pushcfunction(L, run_job);
	d->ref_job = luaL_ref(L, LUA_REGISTRYINDEX);
	lua_pushcfunction(L, traceback);
	d->ref_traceback = luaL_ref(L, LUA_REGISTRYINDEX);
	return 0;
}
