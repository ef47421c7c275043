/* The driver module's insides, shared by its files and by the white-box
 * tests and fuzz harnesses that include it (they do what no driver can:
 * set a cap, build an environment, call a guarded function); the rest of
 * the host sees only driver.h. Who owns what:
 *
 *   protect.c   the protection rule: the counting allocator with its cap,
 *               the budget hook, the one guarded call of driver code, and
 *               drv_protect() around every piece of the host's own work
 *   sandbox.c   the environment a driver gets, built from the one
 *               allow-list
 *   bounded.c   the bounded library functions: each priced before it
 *               runs, refused past its bound
 *   manifest.c  reading and checking the manifest; its JSON description
 *   load.c      a driver file into a new state; dev, its methods, the keys
 *   instance.c  a running machine: boards, level, attach/detach, tick I/O,
 *               operator input, params
 *   takeover.c  hot reload: one instance takes over from another
 *   checkpoint.c  dev.state saved and recovered across a restart
 *   traceback.c the traceback of a driver's error, cleaned for people
 *   luaplant.c  a plant model in Lua (luaplant.h): another kind of file in
 *               the same sandbox, stepped by a simulator
 *
 * Internal names carry the prefix drv_. */
#ifndef VMAC_DRIVER_INTERNAL_H
#define VMAC_DRIVER_INTERNAL_H

#include "../common/file.h"
#include "driver.h"

#include <lauxlib.h>
#include <lua.h>
#include <luajit.h>
#include <lualib.h>
#include <setjmp.h>
#include <stddef.h>
#include <stdint.h>

#define HOOK_EVERY 1000             /* instructions between budget checks */
#define REP_MAX 65536               /* bytes string.rep may build */
#define PATTERN_STEPS_MAX (1 << 24) /* worst-case steps of one pattern call */
#define EVENTS_PER_S 10
#define HOST_RESERVE (64 * 1024)  /* bytes past the cap the host's own work may use */
#define CHARGE_STEPS 65536        /* a library call estimated at this many steps is charged to the budget */
#define STEPS_PER_INSTRUCTION 100 /* ... as one instruction per this many (a call at PATTERN_STEPS_MAX: 168,000) */

#define IO_DI VMAC_IO_DI
#define IO_AI VMAC_IO_AI
#define IO_ENCODER VMAC_IO_ENCODER
#define IO_DO VMAC_IO_DO
#define IO_PWM VMAC_IO_PWM

struct io {
	char name[VMAC_DRIVER_NAME_MAX + 1];
	enum vmac_io_kind kind;
	unsigned channel;
	uint32_t minor; /* board of the machine; has_minor = 0: the primary */
	int has_minor;
	int board; /* index into boards, -1 when that board is not attached */
	double scale, offset;
};

struct var {
	struct vmac_variable pub;
	double every_s; /* timer:N; 0 = auto */
	int group;      /* index of the group's first variable + 1; 0 = none */
	int settable;   /* set = true: an operator may set it */
	int due;
	int warned_cut; /* a cut text value of it was told (once per instance) */
};

struct vmac_driver {
	lua_State *L;
	char stdlib_dir[512];
	const struct vmac_driver_programmes *programmes; /* while loading only: the limits' */
	int loading;                                     /* require() and vmac.cycles() read files only while loading */
	size_t used, cap;                                /* heap accounting of the counting allocator */
	void *(*heap)(void *ctx, void *ptr, size_t osize, size_t nsize); /* NULL: realloc/free */
	void *heap_ctx;
	uint64_t budget_hooks;          /* hook calls allowed per guarded call */
	uint64_t hooks;                 /* hook calls so far in this call */
	uint64_t instructions;          /* counted over every guarded call so far, as the budget counts them */
	uint64_t call_ns;               /* wall-clock time in every guarded call so far */
	uint64_t instruction_budget;    /* per call, as configured (budget_hooks is set from it); fixed at load */
	int64_t budget_ns, deadline_ns; /* wall-clock budget per call; 0 = none */
	int64_t call_budget_ns;         /* this call's: budget_ns times its factor */
	int64_t grace_cpu_ns;           /* the thread's CPU time at the first look past deadline_ns */
	int grace_counting;             /* grace_cpu_ns is set: this call was looked at past its deadline */
	int overrun;                    /* budget exceeded: keep raising until the call unwinds */
	char overrun_msg[96];
	int in_driver;              /* driver code runs now: the cap holds without the host's reserve */
	int mem_refused;            /* an allocation was refused while driver code ran (sticky for the call) */
	int ref_job, ref_traceback; /* drv_protect()'s entry and the traceback handler, made once */
	jmp_buf panic_jmp;          /* where the atpanic handler returns to (panic_armed) */
	int panic_armed;
	int broken; /* an error escaped protection: the state is never touched again */
	char broken_msg[200];
	int failed;                        /* the host's work on it failed where no caller hears (failure says why): */
	char failure[VMAC_DRIVER_ERR_MAX]; /* the next call that reports errors fails with it */
	int ref_tick, ref_attach, ref_input, ref_detach, ref_migrate,
	    ref_recover;      /* registry refs, LUA_NOREF if absent */
	int ref_saved;        /* a checkpoint offered (saved), until recover runs; LUA_NOREF: none */
	int checkpoint_asked; /* dev:checkpoint() was called since the last checkpoint */
	int ref_manifest, ref_dev, ref_inputs, ref_out, ref_vars, ref_params;
	int ref_keys;  /* the names a tick reads and writes, interned once (key_*) */
	char file[64]; /* file name, for messages */
	char name[VMAC_NAME_MAX + 1];
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	unsigned level, max_level;
	struct vmac_timing_want timing; /* the manifest's timing, the host's settings over it */
	uint32_t slot_us, lead_us;      /* the host's slot and lead (limits; 0: not on a host) */
	double out_at_s;                /* dev:output_at of the running tick; -1: none */
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
	double sample_s[VMAC_DRIVER_MAX_BOARDS]; /* the next tick's dev.t per board (vmac_driver_sample_times) */
	int nsample;                             /* how many of them are set: 0, the tick's time for all */
	struct vmac_driver_host host;
	double (*clock)(void *ctx);
	void *clock_ctx;
	double now_s;          /* bus time of the current call */
	double event_window_s; /* dev:event rate limit */
	int64_t tag;           /* the host's (vmac_driver_set_tag) */
	char *describe;        /* the manifest's declarations as JSON (vmac_driver_describe) */
	int events_in_window;
	int loaded;                    /* vmac_driver_load_into ran (once per sandbox) */
	uint64_t vars_version;         /* counts the ticks that published a variable */
	const char *volatile lib_call; /* the bounded library function running now ("string.find"), or NULL */
};

/* The host's work on a driver's state: fn(d, args, err, errlen) returns 0 or
 * -1 with err; it may raise (a raise is a failure of the driver). */
typedef int (*host_work)(struct vmac_driver *d, void *args, char *err, size_t errlen);

/* The keys of a tick, by index into the keys table (load.c, make_keys). */
static inline int key_io(const struct vmac_driver *d, int i)
{
	(void)d;
	return i + 1;
}
static inline int key_var(const struct vmac_driver *d, int i)
{
	return d->nio + i + 1;
}
static inline int key_time(const struct vmac_driver *d)
{
	return d->nio + d->nvars + 1;
}
static inline int key_out(const struct vmac_driver *d)
{
	return d->nio + d->nvars + 2;
}
static inline int key_vars(const struct vmac_driver *d)
{
	return d->nio + d->nvars + 3;
}
static inline int key_state(const struct vmac_driver *d)
{
	return d->nio + d->nvars + 4;
}

/* protect.c */
int64_t drv_mono_ns(void);
struct vmac_driver *drv_of(lua_State *L);
void *drv_alloc(void *ud, void *ptr, size_t osize, size_t nsize);
int drv_on_panic(lua_State *L);
int drv_make_entries(lua_State *L);
int drv_guarded_call(struct vmac_driver *d, int nargs, int nresults, unsigned factor, char *err, size_t errlen);
void drv_charge(lua_State *L, double steps);
int drv_protect_any(struct vmac_driver *d, host_work fn, void *args, char *err, size_t errlen);
int drv_protect(struct vmac_driver *d, host_work fn, void *args, char *err, size_t errlen);
void drv_protect_quiet(struct vmac_driver *d, host_work fn, void *args);
void drv_raw_getfield(lua_State *L, int i, const char *k);

/* traceback.c: text (a message, then luaL_traceback's "stack traceback:"
 * and its frames) into out, at most outlen bytes with the NUL: the message
 * as it is, then each frame once, innermost first from the driver's own
 * line: no frame of the host's C entry named by its address, no error() or
 * assert() frame above the line that called it, no frame listed twice.
 * Without frames left, the message alone. */
void drv_traceback_clean(const char *text, char *out, size_t outlen);
void drv_raw_setfield(lua_State *L, int i, const char *k);

/* bounded.c: put the bounded functions of lib into the table on top: [-0, +0]. */
void drv_wrap_bounded(lua_State *L, const char *lib);

/* sandbox.c */
/* Run a file (or a text in memory) as text in the driver's environment,
 * upvalue 1 of the calling C function, with arg: [-0, +1] what it
 * returned, or raises. */
void drv_run_sandboxed(lua_State *L, const char *path, const char *chunk, const char *arg);
void drv_run_sandboxed_text(lua_State *L, const char *src, size_t len, const char *chunk, const char *arg);
int drv_valid_module_name(const char *name, size_t maxlen);
void drv_make_env(lua_State *L);
int drv_open_lib(lua_State *L, lua_CFunction f, const char *name);

/* load.c: a text compiled as file d->file with the sandbox's environment
 * (text only, no bytecode): [-0, +1] the chunk; or the error message and
 * -1 with err (the syntax error and its line). Protected work only. */
int drv_load_chunk(struct vmac_driver *d, const char *src, size_t len, char *err, size_t errlen);

/* checkpoint.c */
int drv_dev_checkpoint(lua_State *L);

/* manifest.c */
int drv_parse_io(struct vmac_driver *d, int t, const char *what, char *err, size_t errlen);
int drv_parse_manifest(struct vmac_driver *d, const struct vmac_driver_limits *lim, char *err, size_t errlen);
int drv_check_value(lua_State *L, int s, char *why, size_t len);
int drv_describe(struct vmac_driver *d, char *err, size_t errlen);

#endif
