/* Lua driver instances: one sandboxed LuaJIT state per machine (one or more
 * boards). Every call from C into driver code goes through protect.c's one
 * guarded call (budget, memory cap, traceback), and every piece of the
 * host's own work on a state runs protected too; a failure marks the
 * driver, never the host: no driver, however written, and no upload can end
 * the process (docs/DRIVERS.md "Isolation"). The driver API is in
 * docs/DRIVERS.md.
 *
 * Threads: vmac_driver_load runs on the main thread (it reads files); once
 * the driver is handed over, every call that runs Lua is made by the one
 * driver worker that runs its machine (core/host/workers.c), one call at a
 * time, and allocates only inside the driver's own capped heap. No Lua runs
 * on the bus thread: a thread that called vmac_driver_forbid_thread gets
 * every such call refused (and, built with VMAC_CHECK_THREADS, aborts). */
#ifndef VMAC_DRIVER_H
#define VMAC_DRIVER_H

#include <stddef.h>
#include <stdint.h>

#include "../common/value.h"
#include "../proto/proto.h"
#include "../sched/timing.h"

#define VMAC_DRIVER_ERR_MAX 512
#define VMAC_DRIVER_MAX_BOARDS 8
#define VMAC_DRIVER_MAX_VARS 24
#define VMAC_DRIVER_MAX_IO 32
#define VMAC_DRIVER_MAX_PARAMS 32
#define VMAC_DRIVER_NAME_MAX 31                /* names of io, params, variables, commands */
#define VMAC_DRIVER_STR_MAX VMAC_VALUE_STR_MAX /* a string variable's value; longer ones are cut */
#define VMAC_DRIVER_CUT_MARK "\xe2\x80\xa6"    /* "…" (UTF-8): a cut text value ends with it */
#define VMAC_DRIVER_VERSION_MAX 31
/* The driver API this host offers (vmac.version; a bundle names the one it
 * needs): MAJOR.MINOR, a bundle of the same major and a minor not above
 * this one runs. */
#define VMAC_DRIVER_API "0.2"
#define VMAC_DRIVER_LOAD_FACTOR 50     /* loading the file gets this many budgets */
#define VMAC_DRIVER_FILE_MAX (1 << 20) /* bytes of a driver's file (and of a stdlib module) */
/* The most a manifest's description (vmac_driver_describe) may hold:
 * values, and bytes of strings and keys; past either, the load is refused. */
#define VMAC_DRIVER_DESCRIBE_VALUES 10000
#define VMAC_DRIVER_DESCRIBE_BYTES (256 * 1024)

/* Per-driver overrides from the host's settings (driver.NAME.KEY). */
struct vmac_driver_setting {
	char key[48]; /* "memory_kib", "instructions", "budget_us", "param.fill_l" */
	char value[64];
};

/* A driver's programmes (docs/DRIVERS.md "Cycles as scripts"), the
 * sources vmac.cycles() runs: from a bundle (core/loader), or read from a
 * folder (vmac_driver_programmes_read). Each name is a module name. */
#define VMAC_DRIVER_PROGRAMMES 64
struct vmac_driver_programme {
	char name[48];
	const char *src;
	size_t len;
};
struct vmac_driver_programmes {
	int n; /* in name order */
	struct vmac_driver_programme p[VMAC_DRIVER_PROGRAMMES];
	char from[600]; /* where they came from, for messages ("/x/cycles/washer", "the bundle") */
	int owned;      /* the sources are malloc'd: vmac_driver_programmes_free frees them */
};

/* Every NAME.lua of folder dir (NAME a module name: others are let be),
 * at most VMAC_DRIVER_PROGRAMMES, read into out (from: dir). A missing
 * folder holds none. 0, or < 0 with err (a file that cannot be read). */
int vmac_driver_programmes_read(const char *dir, struct vmac_driver_programmes *out, char *err, size_t errlen);
void vmac_driver_programmes_free(struct vmac_driver_programmes *p);

struct vmac_driver_limits {
	size_t memory_bytes;    /* cap on the state's heap (default 4 MiB) */
	uint64_t instructions;  /* VM instructions per call (default 200,000) */
	uint32_t budget_us;     /* wall-clock microseconds per call; 0 = no wall-clock limit */
	unsigned default_level; /* level when the manifest names none */
	unsigned max_level;     /* highest level the scheduler has */
	uint32_t slot_us;       /* the host's slot, for checking a manifest's timing; 0: not checked */
	uint32_t timed_lead_us; /* the host's lead (vmac_timing_lead_us) for the same check */
	int allow_jit;          /* honour a manifest's jit = true */
	const char *stdlib_dir; /* where the driver's require() looks; NULL: no require */
	const struct vmac_driver_programmes *programmes; /* what vmac.cycles() runs; NULL: it raises */
	const char *expect_name;                         /* the driver name the board announced; NULL: any */
	const struct vmac_driver_setting *settings;      /* overrides for this driver */
	int nsettings;
	/* Bus time in seconds, for os.clock(); NULL: 0. */
	double (*clock)(void *ctx);
	void *clock_ctx;
	/* Where the state's heap comes from, as a lua_Alloc (free when nsize is
	 * 0; a shrink must not fail); the cap above holds either way. NULL: the
	 * C library's realloc and free. tests/fuzz/ gives an arena it can
	 * snapshot and restore (docs/TESTING.md, "Fuzzing"). */
	void *(*heap)(void *ctx, void *ptr, size_t osize, size_t nsize);
	void *heap_ctx;
};

/* What the host offers a running driver (dev:set_level, dev:event). Set
 * with vmac_driver_bind; the calls come from inside a guarded call, on the
 * thread that runs the driver (its worker): no I/O there. */
struct vmac_driver_host {
	/* Ask for another level; 0, or -1 with err ("schedule full: ..."). */
	int (*set_level)(void *ctx, unsigned level, char *err, size_t errlen);
	/* An event for people: kind "driver" (dev:event's text) or "warning"
	 * (the host's word on what the driver did: a cut text value). */
	void (*event)(void *ctx, const char *kind, const char *text);
	void *ctx;
};

/* A published variable (struct vmac_value: core/common/value.h) as the status shows it. */
struct vmac_variable {
	char name[VMAC_DRIVER_NAME_MAX + 1];
	char unit[16];
	struct vmac_value value;
	double published_s; /* bus time of the last publication */
};

/* The sandbox's allow-list (docs/DRIVERS.md "The sandbox"): every name a
 * driver's global table holds, by library, and nothing else is there.
 * lib NULL is the globals themselves; copied are LuaJIT's own functions as
 * they are, own are the host's (bounded or wrapped versions, os.clock,
 * require, vmac). The one list: the sandbox is built from it, `vmac lint`
 * gives it to luacheck. Ends with lib, copied and own all NULL. */
struct vmac_driver_lib {
	const char *lib;
	const char *const *copied; /* NULL-terminated */
	const char *const *own;    /* NULL-terminated */
};
extern const struct vmac_driver_lib vmac_driver_allowed[];

struct vmac_driver; /* opaque */

/* Load the driver file at path into a fresh sandboxed state, run it, and
 * check its manifest. Slow (reads files, compiles): call off the bus thread.
 * Returns 0 and *out, or a negative errno with err set
 * ("washer.lua:12: unexpected symbol near 'x'",
 *  "washer.lua: manifest: io.lamp: unknown channel 'do9' ..."). */
int vmac_driver_load(const char *path, const struct vmac_driver_limits *limits, struct vmac_driver **out, char *err,
                     size_t errlen);

/* The same from a text in memory (hot reload: a driver uploaded to the
 * host); file names it in messages ("washer.lua"). */
int vmac_driver_load_source(const char *file, const char *src, size_t len, const struct vmac_driver_limits *limits,
                            struct vmac_driver **out, char *err, size_t errlen);

/* The same in two steps: a sandbox with nothing loaded yet (file names it
 * in messages), then the one driver it will hold, from a text in memory
 * (its name, settings, stdlib and cycles folders from limits; -EALREADY the
 * second time). After a
 * failed load_into the sandbox is of no further use: free it.
 * vmac_driver_load_source is these two; tests/fuzz/ snapshots the sandbox
 * between them. */
int vmac_driver_new(const char *file, const struct vmac_driver_limits *limits, struct vmac_driver **out, char *err,
                    size_t errlen);
int vmac_driver_load_into(struct vmac_driver *d, const char *src, size_t len, const struct vmac_driver_limits *limits,
                          char *err, size_t errlen);

/* The manifest's declarations as JSON text, made at load for user
 * interfaces (docs/API.md "GET /api/drivers/NAME/manifest"): name,
 * version, description, level, io, variables, params, commands, ui; plain
 * data only. Valid while the driver is. */
const char *vmac_driver_describe(const struct vmac_driver *d);

/* What the manifest says. */
const char *vmac_driver_name(const struct vmac_driver *d);
const char *vmac_driver_version(const struct vmac_driver *d);
unsigned vmac_driver_level(const struct vmac_driver *d);
/* The manifest's timing (docs/DRIVERS.md, "Timing"), the host's
 * driver.NAME.timing.* applied over it; pattern VMAC_TIMING_DEFAULT when
 * neither names one. Fixed at load: any thread. */
void vmac_driver_timing(const struct vmac_driver *d, struct vmac_timing_want *out);
/* What the last tick asked with dev:output_at: seconds after the planned
 * start of the slot that carries its outputs; -1 when it asked nothing. */
double vmac_driver_output_at(const struct vmac_driver *d);

/* The manifest's board I/O, in name order (for tools that show or test a
 * machine by the driver's names; docs/TESTING.md). */
enum vmac_io_kind { VMAC_IO_DI, VMAC_IO_AI, VMAC_IO_ENCODER, VMAC_IO_DO, VMAC_IO_PWM };
struct vmac_driver_io {
	const char *name; /* valid while the driver is */
	enum vmac_io_kind kind;
	unsigned channel; /* bit of digital in/out, analog input index */
	int has_minor;    /* 0: the primary board; 1: the board with this minor id */
	uint32_t minor;
	double scale, offset; /* analog inputs: counts * scale + offset */
};
int vmac_driver_nio(const struct vmac_driver *d);
void vmac_driver_io_info(const struct vmac_driver *d, int i, struct vmac_driver_io *out);

/* Bus thread from here on. */
void vmac_driver_bind(struct vmac_driver *d, const struct vmac_driver_host *host);

/* Boards of the machine: index 0 is the primary. Adding a board that is
 * already there, or past VMAC_DRIVER_MAX_BOARDS, fails (-1). Should the
 * driver's state have no room for the board's entry in dev.boards, the
 * driver's next call (attach, tick, input) fails with that reason. */
int vmac_driver_add_board(struct vmac_driver *d, uint32_t minor, const char *name);
int vmac_driver_boards(const struct vmac_driver *d);

/* The level the machine runs at now (the bus thread tells the driver); a
 * failure to write dev.level fails the next call, as above. */
void vmac_driver_set_level_now(struct vmac_driver *d, unsigned level);

/* Call attach(dev) if the driver has one. 0, or -1 with err. */
int vmac_driver_attach(struct vmac_driver *d, double time_s, char *err, size_t errlen);

/* One service of the machine: in[i] / out[i] are the inputs and outputs of
 * board i (as added). Runs tick(dev, inputs), then reads dev.out into out[]
 * and publishes due variables. 0, or -1 with err holding the driver's error,
 * file, line and traceback, and every out[] all off; after a failure the
 * driver must not be called again. */
int vmac_driver_tick(struct vmac_driver *d, double time_s, const struct vmac_inputs *const in[],
                     struct vmac_outputs *const out[], char *err, size_t errlen);
/* The instants (bus time, s) of the inputs the next tick gets, board i's
 * at t[i] (docs/DRIVERS.md, dev.t); for that tick only. Without it a
 * tick's dev.t is its own time. */
void vmac_driver_sample_times(struct vmac_driver *d, const double *t, int n);

/* Why operator input was refused: what vmac_driver_input returns (> 0),
 * with the text for people in its reply. */
enum vmac_refusal {
	VMAC_REFUSED_BY_DRIVER = 1, /* input() said no: the driver's message */
	VMAC_REFUSED_NAME,          /* no such variable, param or command */
	VMAC_REFUSED_READ_ONLY,     /* a variable without set = true */
	VMAC_REFUSED_VALUE,         /* outside the declaration's min, max or values */
	VMAC_REFUSED_NO_INPUT,      /* a variable or command, and the driver has no input() */
	VMAC_REFUSED_NOT_PERSIST,   /* persist asked for what is not a persist = true param (the bus's check) */
};

/* Operator input: input(dev, name, value) with value a number, boolean or
 * string as given. Returns 0 (accepted), a vmac_refusal (> 0: reply says
 * why), -1 (driver failure: err). */
int vmac_driver_input(struct vmac_driver *d, double time_s, const char *name, const struct vmac_value *value,
                      char *reply, size_t replylen, char *err, size_t errlen);

/* Hot reload, bus thread: nd (loaded, bound, its boards added) takes over
 * the machine od runs now (docs/DRIVERS.md "Hot reload"). In order: od's
 * dev.params values nd also declares, with the same type, are copied; nd's
 * attach(dev) runs; od's dev.out values of nd's outputs are copied; a copy
 * of od's dev.state, plain data only (tables, strings, numbers, booleans;
 * shared tables stay shared; at most 10,000 entries, 32 deep), goes to nd's
 * migrate(dev, old_state). od is only read (it may be one that failed).
 * 0, or -1 with err: nd must then not run; od is as it was. */
int vmac_driver_take_over(struct vmac_driver *nd, struct vmac_driver *od, double time_s, char *err, size_t errlen);

/* ---- checkpoints and recovery (docs/DRIVERS.md "Recovery after a
 * restart"; checkpoint.c) ---- */
#define VMAC_CHECKPOINT_ENTRIES 10000
#define VMAC_CHECKPOINT_DEPTH 32

/* Whether dev:checkpoint() was called since the last checkpoint. */
int vmac_driver_checkpoint_asked(const struct vmac_driver *d);

/* Bus thread: a plain-data copy of dev.state, encoded into buf (at most cap
 * bytes; *len of them used). Allocates only in the driver's heap. 0, or
 * with err: -E2BIG (too large, too deep, too many entries),
 * -VMAC_EDRIVER (the driver has failed), or the protection's code (its
 * memory cap); the driver runs on either way. Clears the checkpoint_asked
 * flag. */
int vmac_driver_checkpoint(struct vmac_driver *d, uint8_t *buf, size_t cap, size_t *len, char *err, size_t errlen);

/* What the host says of a checkpoint it offers. */
struct vmac_checkpoint_info {
	double time;  /* when it was written (Unix time) */
	double age_s; /* from then to now */
	const char *version;
	int restarted; /* the host has restarted since */
};

/* Main thread, after loading and before the hand over: checkpoint buf
 * (len bytes, as vmac_driver_checkpoint wrote it) decoded into the
 * instance, for its recover(dev, saved). 0, or with err: -EBADMSG
 * ("checkpoint damaged: ..."), -EPROTONOSUPPORT (another format); nothing
 * is offered then. */
int vmac_driver_offer_checkpoint(struct vmac_driver *d, const uint8_t *buf, size_t len,
                                 const struct vmac_checkpoint_info *info, char *err, size_t errlen);

/* After attach: recover(dev, saved) with the checkpoint offered. Returns
 * VMAC_RECOVER_NONE (none offered), VMAC_RECOVER_UNUSED (the driver has no
 * recover; the checkpoint is dropped), VMAC_RECOVER_DONE, or -1 with err (a
 * driver failure). */
enum { VMAC_RECOVER_NONE = 0, VMAC_RECOVER_UNUSED = 1, VMAC_RECOVER_DONE = 2 };
int vmac_driver_recover(struct vmac_driver *d, double time_s, char *err, size_t errlen);

/* A replay resuming mid-life (docs/RECORDING.md, "Replay"), after attach:
 * the dev.state of checkpoint buf handed to migrate(dev, state), as a hot
 * reload hands the old instance's. 0; 1 when the driver has no migrate
 * (nothing done); -1 with err (a damaged checkpoint, or migrate failed). */
int vmac_driver_resume_from(struct vmac_driver *d, const uint8_t *buf, size_t len, double time_s, char *err,
                            size_t errlen);

/* detach(dev, reason) if the driver has one; errors are ignored (the
 * machine is going away). */
void vmac_driver_detach(struct vmac_driver *d, const char *reason);

/* Published variables: how many the driver declares, and the i-th (in name
 * order) with its latest published value. */
int vmac_driver_nvars(const struct vmac_driver *d);
const struct vmac_variable *vmac_driver_variable(const struct vmac_driver *d, int i);
/* How the i-th variable is published: its `update = "timer:N"` period in
 * seconds, 0 when it is published as it changes. For reports (vmac test:
 * a timer-updated value is a copy up to that old); the bus does not ask. */
double vmac_driver_variable_every_s(const struct vmac_driver *d, int i);

/* A number the host attaches to an instance (the store's id of the version
 * it runs; 0 for a driver file). */
void vmac_driver_set_tag(struct vmac_driver *d, int64_t tag);
int64_t vmac_driver_tag(const struct vmac_driver *d);

/* Params (the manifest's `params`, in name order): how many; whether name
 * is one with persist = true (1), one without (0), or none (-1); all of
 * them with their values now into out (room for VMAC_DRIVER_MAX_PARAMS),
 * returning how many (bus thread once bound; raw reads in one protected
 * call, no metamethod runs; a value that cannot be read is NONE). */
int vmac_driver_nparams(const struct vmac_driver *d);
int vmac_driver_param_persists(const struct vmac_driver *d, const char *name);
int vmac_driver_params(const struct vmac_driver *d, struct vmac_variable *out);

/* A persisted value back into dev.params before the driver runs (the host's
 * main thread, right after loading): name must be a persist = true param,
 * v of its type and within its declaration. 0, or -1 with why. */
int vmac_driver_restore_param(struct vmac_driver *d, const char *name, const struct vmac_value *v, char *why,
                              size_t whylen);

/* Bytes the driver's heap holds now, and the most it may (memory_kib, its
 * driver.NAME override; fixed at load, so any thread may read it). */
size_t vmac_driver_memory(const struct vmac_driver *d);
size_t vmac_driver_memory_cap(const struct vmac_driver *d);

/* VM instructions the driver's code has run in all its calls so far, as
 * the budget counts them: in steps of 1,000 (the count hook's period: a
 * call of fewer counts 0), a priced library call as its price. Read it on
 * the thread that runs the driver. And the budget of one call
 * (instructions, its driver.NAME override; fixed at load, so any thread). */
uint64_t vmac_driver_instructions(const struct vmac_driver *d);
/* Wall-clock ns the driver's code has run in all its calls so far (what
 * budget_us judges each call by); read as vmac_driver_instructions. */
uint64_t vmac_driver_call_ns(const struct vmac_driver *d);
uint64_t vmac_driver_instruction_budget(const struct vmac_driver *d);

/* The wall-clock budget of one call (budget_us, its driver.NAME override),
 * in ns; 0: none. */
int64_t vmac_driver_budget_ns(const struct vmac_driver *d);

/* Counts the ticks that published a variable: a caller that copies the
 * variables out needs to copy them only when it has moved. */
uint64_t vmac_driver_vars_version(const struct vmac_driver *d);

/* The library function the driver's code is inside now ("string.find"),
 * or NULL: read from another thread to say what a stalled call was doing
 * (a pointer to a constant string, stored once before and after each
 * bounded library call). */
const char *vmac_driver_lib_call(const struct vmac_driver *d);

/* This thread (the bus thread) must never run a driver's Lua: from now on
 * every call that would is refused with an error saying so. */
void vmac_driver_forbid_thread(void);

void vmac_driver_free(struct vmac_driver *d);

#endif
