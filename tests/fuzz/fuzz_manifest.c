/* libFuzzer harness for loading a driver (core/driver/load.c) and checking
 * its manifest (core/driver/manifest.c): the input is a driver's source,
 * loaded into a sandboxed state as the host loads an upload
 * (vmac_driver_load_source: vmac_driver_new, vmac_driver_load_into).
 * Leading lines "--!KEY=VALUE" (Lua comments) become the host's
 * driver.NAME.KEY settings (memory_kib, instructions, budget_us,
 * param.NAME; --!name=X: the board announced driver X, whose programmes
 * vmac.cycles() reads from scripts/cycles/X/). A refused load
 * must say why; an accepted one must have a manifest inside every bound
 * of driver.h and a description that is a JSON object as the API decodes
 * it (http_manifest_json, core/api/api_request.c), and then runs as a
 * machine: its boards added, attach, two ticks, and operator input of each
 * declared name, with outputs only on declared channels.
 * Seeds: tests/fuzz/corpus-manifest/ and the shipped drivers, each
 * announced by its own name (tests/fuzz/run.sh writes them as seeds from
 * scripts/drivers/). */
#include <jansson.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/api/api_request.h"
#include "../../core/driver/driver.h"
#include "fuzz.h"
#include "fuzz_arena.h"

#ifndef FUZZ_STDLIB_DIR
#define FUZZ_STDLIB_DIR "stdlib"
#endif
#ifndef FUZZ_CYCLES_DIR
#define FUZZ_CYCLES_DIR "scripts/cycles"
#endif

#define SETTINGS_MAX 8
/* The instructions a call of the driver may run, and the most a setting
 * line may give it: a twentieth of the host's default driver_instructions
 * (200,000). Every shipped driver runs within the smallest budget the host
 * takes (instructions=1000: about 2,000 a call, 100,000 a load; the budget
 * is counted every 1,000; docs/TESTING.md, "Fuzzing"). An input that loops
 * reaches the budget's overrun, the same code at any budget, after about
 * 500,000 instructions of a load instead of 10 million: at the host's
 * budget a few such inputs would take most of the target's time. */
#define INSTRUCTIONS 10000

/* VMAC_FUZZ_MUST_LOAD=1: the input is one of the shipped drivers, which
 * must load and attach (tests/fuzz/run.sh checks each seed so first): a
 * seed the harness refuses would leave the driver it stands for unfuzzed. */
static int must_load(void)
{
	const char *v = getenv("VMAC_FUZZ_MUST_LOAD");
	return v && strcmp(v, "1") == 0;
}

static int manifest_name_ok(const char *s)
{
	size_t n = strlen(s);
	return n > 0 && n <= VMAC_DRIVER_NAME_MAX && s[0] >= 'a' && s[0] <= 'z' &&
	       strspn(s, "abcdefghijklmnopqrstuvwxyz0123456789_") == n;
}

static int value_ok(const struct vmac_value *v)
{
	return v->type <= VMAC_VALUE_STRING && memchr(v->str, 0, sizeof(v->str)) != NULL &&
	       (v->type != VMAC_VALUE_BOOL || v->number == 0 || v->number == 1);
}

/* What each board may have on: the bits of its declared digital outputs,
 * and whether it has a pwm output. */
struct board_outputs {
	uint32_t minor;
	uint8_t digital;
	int pwm;
};

static void check_loaded(struct vmac_driver *d, struct board_outputs *boards, int *nboards)
{
	json_t *desc = http_manifest_json(vmac_driver_describe(d)); /* as GET /api/drivers/NAME/manifest has it */
	struct vmac_variable p[VMAC_DRIVER_MAX_PARAMS];
	int i, j;
	if (!json_is_object(desc) || !json_is_string(json_object_get(desc, "name")) ||
	    !json_is_string(json_object_get(desc, "version")) || !json_is_integer(json_object_get(desc, "level")))
		abort();
	json_decref(desc);
	if (!vmac_driver_name(d)[0] || strlen(vmac_driver_name(d)) > VMAC_NAME_MAX || !vmac_driver_version(d)[0] ||
	    strlen(vmac_driver_version(d)) > VMAC_DRIVER_VERSION_MAX || vmac_driver_level(d) > 10)
		abort();
	if (vmac_driver_nio(d) < 0 || vmac_driver_nio(d) > VMAC_DRIVER_MAX_IO || vmac_driver_nvars(d) < 0 ||
	    vmac_driver_nvars(d) > VMAC_DRIVER_MAX_VARS || vmac_driver_nparams(d) < 0 ||
	    vmac_driver_nparams(d) > VMAC_DRIVER_MAX_PARAMS)
		abort();
	*nboards = 1;
	boards[0].minor = 0;
	for (i = 0; i < vmac_driver_nio(d); i++) {
		struct vmac_driver_io io;
		struct board_outputs *b = NULL;
		vmac_driver_io_info(d, i, &io);
		if (!manifest_name_ok(io.name) || io.kind > VMAC_IO_PWM)
			abort();
		if ((io.kind == VMAC_IO_DI && io.channel >= VMAC_DIGITAL_INPUTS) ||
		    (io.kind == VMAC_IO_DO && io.channel >= VMAC_DIGITAL_OUTPUTS) ||
		    (io.kind == VMAC_IO_AI && io.channel >= VMAC_ANALOG_INPUTS))
			abort();
		if (i > 0) {
			struct vmac_driver_io prev;
			vmac_driver_io_info(d, i - 1, &prev);
			if (strcmp(prev.name, io.name) >= 0)
				abort(); /* in name order, each name once */
		}
		for (j = 0; j < *nboards; j++)
			if (boards[j].minor == (io.has_minor ? io.minor : 0))
				b = &boards[j];
		if (!b && *nboards < VMAC_DRIVER_MAX_BOARDS) {
			b = &boards[(*nboards)++];
			b->minor = io.minor;
		}
		if (b && io.kind == VMAC_IO_DO)
			b->digital |= (uint8_t)(1u << io.channel);
		if (b && io.kind == VMAC_IO_PWM)
			b->pwm = 1;
	}
	for (i = 0; i < vmac_driver_nvars(d); i++)
		if (!manifest_name_ok(vmac_driver_variable(d, i)->name))
			abort();
	if (vmac_driver_params(d, p) != vmac_driver_nparams(d))
		abort();
	for (i = 0; i < vmac_driver_nparams(d); i++) {
		if (!manifest_name_ok(p[i].name) || !value_ok(&p[i].value) ||
		    !memchr(p[i].unit, 0, sizeof(p[i].unit)) || vmac_driver_param_persists(d, p[i].name) < 0)
			abort();
	}
}

static int tick(struct vmac_driver *d, const struct board_outputs *boards, int nboards, double time_s, uint32_t seed)
{
	struct vmac_inputs in[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs out[VMAC_DRIVER_MAX_BOARDS];
	const struct vmac_inputs *ins[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs *outs[VMAC_DRIVER_MAX_BOARDS];
	char err[VMAC_DRIVER_ERR_MAX];
	int i, rc;
	for (i = 0; i < nboards; i++) {
		memset(&in[i], 0, sizeof(in[i]));
		in[i].digital = (uint8_t)(seed >> i);
		in[i].analog[0] = (uint16_t)(seed % 4096);
		in[i].analog[1] = (uint16_t)(seed / 7 % 4096);
		in[i].encoder = (int32_t)seed;
		ins[i] = &in[i];
		outs[i] = &out[i];
	}
	err[0] = 0;
	rc = vmac_driver_tick(d, time_s, ins, outs, err, sizeof(err));
	for (i = 0; i < nboards; i++) {
		if (out[i].digital & ~boards[i].digital)
			abort(); /* an output the manifest does not declare */
		if (out[i].pwm < -VMAC_PWM_MAX || out[i].pwm > VMAC_PWM_MAX || (!boards[i].pwm && out[i].pwm))
			abort();
		if (rc != 0 && (out[i].digital || out[i].pwm))
			abort(); /* a failed tick drives nothing */
	}
	if (rc != 0 && (rc != -1 || !err[0]))
		abort();
	for (i = 0; rc == 0 && i < vmac_driver_nvars(d); i++)
		if (!value_ok(&vmac_driver_variable(d, i)->value))
			abort();
	return rc;
}

/* Operator input of name with value: 0, a refusal with its reason, or -1
 * (the driver failed: it is not called again). */
static int input(struct vmac_driver *d, const char *name, const struct vmac_value *v)
{
	char reply[640], err[VMAC_DRIVER_ERR_MAX]; /* as the bus thread gives them (VMAC_EVENT_TEXT) */
	int rc;
	err[0] = 0;
	rc = vmac_driver_input(d, 2.0, name, v, reply, sizeof(reply), err, sizeof(err));
	if (rc < -1 || rc > VMAC_REFUSED_NOT_PERSIST || (rc > 0 && !reply[0] && rc != VMAC_REFUSED_BY_DRIVER) ||
	    (rc == -1 && !err[0]) || !memchr(reply, 0, sizeof(reply)))
		abort();
	return rc;
}

/* The machine runs: its boards, attach, a tick, input of every declared
 * name, another tick. Stops at the first failure, as the host does. */
static void run(struct vmac_driver *d, uint32_t seed)
{
	struct board_outputs boards[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_variable p[VMAC_DRIVER_MAX_PARAMS];
	struct vmac_value v;
	json_t *desc, *commands;
	const char *name;
	json_t *decl;
	char err[VMAC_DRIVER_ERR_MAX];
	int i, n, nboards, failed = 0;
	memset(boards, 0, sizeof(boards));
	check_loaded(d, boards, &nboards);
	for (i = 0; i < nboards; i++) {
		char board[16];
		snprintf(board, sizeof(board), "b%d", i);
		if (vmac_driver_add_board(d, boards[i].minor, board) != 0)
			abort();
	}
	if (vmac_driver_add_board(d, boards[0].minor, "again") != -1)
		abort();
	err[0] = 0;
	if (vmac_driver_attach(d, 1.0, err, sizeof(err)) != 0) {
		if (!err[0])
			abort();
		if (must_load()) {
			fprintf(stderr, "fuzz_manifest: a seed that must attach does not: %s\n", err);
			abort();
		}
		return;
	}
	if (tick(d, boards, nboards, 1.0, seed) != 0)
		return;
	memset(&v, 0, sizeof(v));
	for (i = 0; i < vmac_driver_nvars(d) && !failed; i++) {
		v.type = VMAC_VALUE_NUMBER;
		v.number = seed % 100;
		failed = input(d, vmac_driver_variable(d, i)->name, &v) < 0;
	}
	n = vmac_driver_params(d, p);
	for (i = 0; i < n && !failed; i++)
		failed = input(d, p[i].name, &p[i].value) < 0;
	desc = http_manifest_json(vmac_driver_describe(d));
	commands = json_object_get(desc, "commands");
	v.type = VMAC_VALUE_NONE;
	json_object_foreach(commands, name, decl)
	{
		if (!failed)
			failed = input(d, name, &v) < 0;
	}
	json_decref(desc);
	if (!failed && input(d, "no_such_name", &v) != VMAC_REFUSED_NAME)
		abort();
	if (!failed)
		tick(d, boards, nboards, 3.0, seed * 2654435761u);
	vmac_driver_detach(d, "fuzz");
}

/* The input's FNV-1a hash: the seed of the board inputs a tick is given.
 * Not instrumented for coverage: its loop's compare, traced at every byte,
 * took a twentieth of the target's time and tells the fuzzer nothing. */
__attribute__((no_sanitize("coverage"), noinline)) static uint32_t input_hash(const uint8_t *data, size_t size)
{
	uint32_t h = 2166136261u;
	size_t i;
	for (i = 0; i < size; i++)
		h = (h ^ data[i]) * 16777619u;
	return h;
}

/* The programmes of folder dir (vmac.cycles), as the host reads a drivers
 * folder's: read again only when the folder is another than last time. */
static struct vmac_driver_programmes programmes;
static char programmes_dir[VMAC_NAME_MAX + 64];

static void programmes_of(const char *dir)
{
	char err[300];
	if (strcmp(dir, programmes_dir) == 0)
		return;
	vmac_driver_programmes_free(&programmes);
	if (vmac_driver_programmes_read(dir, &programmes, err, sizeof(err)) != 0)
		abort(); /* the shipped programmes must be readable */
	snprintf(programmes_dir, sizeof(programmes_dir), "%s", dir);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct vmac_driver_setting settings[SETTINGS_MAX];
	struct vmac_driver_limits limits;
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX], expect[VMAC_NAME_MAX + 1] = "", cycles[VMAC_NAME_MAX + 64];
	const char *src = (const char *)data, *end = src + size;
	uint32_t seed;
	int nsettings = 0, rc;

	if (size > 65536)
		return 0;
	/* --!KEY=VALUE lines first: the host's settings of this driver. */
	while (end - src > 3 && memcmp(src, "--!", 3) == 0) {
		const char *nl = memchr(src, '\n', (size_t)(end - src)), *eq;
		size_t n = (size_t)((nl ? nl : end) - src - 3);
		char line[128];
		snprintf(line, sizeof(line), "%.*s", (int)(n < sizeof(line) ? n : sizeof(line) - 1), src + 3);
		eq = strchr(line, '=');
		if (eq && strncmp(line, "name=", 5) == 0) {
			snprintf(expect, sizeof(expect), "%s", eq + 1);
		} else if (eq && nsettings < SETTINGS_MAX) {
			struct vmac_driver_setting *s = &settings[nsettings++];
			snprintf(s->key, sizeof(s->key), "%.*s", (int)(eq - line), line);
			snprintf(s->value, sizeof(s->value), "%s", eq + 1);
			/* The harness has no wall-clock budget (it would make runs
			 * differ), and a load gets VMAC_DRIVER_LOAD_FACTOR budgets:
			 * instructions=1e9, which a host allows, would let one input
			 * loop for minutes. Above INSTRUCTIONS the setting is that. */
			if (strcmp(s->key, "instructions") == 0 && strtod(s->value, NULL) > INSTRUCTIONS)
				snprintf(s->value, sizeof(s->value), "%d", INSTRUCTIONS);
		}
		if (!nl)
			break;
		src = nl + 1;
	}
	seed = input_hash(data, size);

	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = 1 << 20;
	limits.instructions = INSTRUCTIONS;
	limits.budget_us = 0; /* instructions bound a run; wall clock would make runs differ */
	limits.max_level = 10;
	limits.default_level = 4;
	limits.stdlib_dir = FUZZ_STDLIB_DIR;
	/* The folder of the announced driver's programmes (vmac.cycles), as the
	 * host has it; a name that is not one has none. */
	snprintf(cycles, sizeof(cycles), "%s/%s", FUZZ_CYCLES_DIR, manifest_name_ok(expect) ? expect : "-");
	programmes_of(cycles);
	limits.programmes = &programmes;
	limits.expect_name = expect[0] ? expect : NULL;
	limits.settings = settings;
	limits.nsettings = nsettings;
	err[0] = 0;
	/* A sandbox as vmac_driver_load_source makes it, restored from the
	 * arena's snapshot (docs/TESTING.md, "Fuzzing"), then the whole input
	 * (settings lines too: they are comments) loaded into it. */
	d = fuzz_arena_kept();
	if (!d) {
		fuzz_arena_prepare(&limits);
		if (vmac_driver_new("fuzz.lua", &limits, &d, err, sizeof(err)) != 0) {
			fprintf(stderr, "fuzz_manifest: no sandbox: %s\n", err);
			abort();
		}
		fuzz_arena_keep(d);
	}
	rc = vmac_driver_load_into(d, (const char *)data, size, &limits, err, sizeof(err));
	if (rc != 0) {
		if (rc > 0 || !err[0] || !memchr(err, 0, sizeof(err)))
			abort(); /* refused without a reason */
		if (must_load()) {
			fprintf(stderr, "fuzz_manifest: a seed that must load does not: %s\n", err);
			abort();
		}
		fuzz_arena_done(d);
		return 0;
	}
	run(d, seed);
	fuzz_arena_done(d);
	return 0;
}
