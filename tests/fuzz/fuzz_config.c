/* libFuzzer harness for the host's settings (core/config/config.c): the input
 * is a config file's text for vmac_config_load_text (it runs as Lua with
 * no library, an instruction limit and a memory cap), then the same bytes
 * as command-line settings, one KEY=VALUE a line, for vmac_config_set;
 * vmac_config_check after each. Whatever the bytes, the result is 0 or -1
 * with a message, and every field of the config stays inside its bounds.
 * Seeds: tests/fuzz/corpus-config/; run with make fuzz (docs/TESTING.md). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/config/config.h"
#include "fuzz.h"

static int terminated(const char *s, size_t size)
{
	return memchr(s, 0, size) != NULL;
}

/* What must hold of a config after any sequence of loads and settings,
 * refused or not. all: also that every driver setting is found under its
 * driver's name (quadratic in their number: after the last line, not after
 * each, which cost more than the rest of an input). */
static void check_config(const struct vmac_config *c, int all)
{
	struct vmac_driver_setting out[VMAC_CONFIG_DRIVER_SETTINGS];
	int i, n = 0;
	if (!terminated(c->bus, sizeof(c->bus)) || !terminated(c->iface, sizeof(c->iface)) ||
	    !terminated(c->http, sizeof(c->http)) || !terminated(c->drivers_dir, sizeof(c->drivers_dir)) ||
	    !terminated(c->scripts_dir, sizeof(c->scripts_dir)) || !terminated(c->stdlib_dir, sizeof(c->stdlib_dir)) ||
	    !terminated(c->state_dir, sizeof(c->state_dir)) || !terminated(c->tls_cert, sizeof(c->tls_cert)) ||
	    !terminated(c->tls_key, sizeof(c->tls_key)))
		abort();
	if (c->slice_us < 1 || c->slice_us > 1000000 || c->slices_per_slot < 1 || c->slices_per_slot > 256 ||
	    c->max_level > 12 || c->default_level > 12 || c->reply_deadline_us < 50 || c->watchdog_ms < 1 ||
	    c->watchdog_ms > 60000 || c->miss_limit < 1 || c->max_devices < 1 || c->max_devices > 4096 ||
	    c->driver_memory_kib < 64 || c->driver_instructions < 1000)
		abort(); /* a number outside the range its key allows */
	if ((c->allow_jit | c->realtime | c->cyclic) & ~1)
		abort();
	if (c->ndriver < 0 || c->ndriver > VMAC_CONFIG_DRIVER_SETTINGS)
		abort();
	for (i = 0; i < c->ndriver; i++) {
		const struct vmac_config_driver_setting *x = &c->driver[i];
		if (!terminated(x->driver, sizeof(x->driver)) || !x->driver[0] || strchr(x->driver, '.') ||
		    !terminated(x->s.key, sizeof(x->s.key)) || !x->s.key[0] ||
		    !terminated(x->s.value, sizeof(x->s.value)))
			abort();
	}
	/* Every setting is found under its driver's name, and only there. */
	for (i = 0; all && i < c->ndriver; i++) {
		int j, first = 1;
		for (j = 0; j < i; j++)
			first &= strcmp(c->driver[j].driver, c->driver[i].driver) != 0;
		if (first)
			n += vmac_config_driver_settings(c, c->driver[i].driver, out, VMAC_CONFIG_DRIVER_SETTINGS);
	}
	if (all && n != c->ndriver)
		abort();
}

static void check_result(int rc, const char *err)
{
	if (rc > 0)
		abort(); /* 0, or a negative errno (core/common/errors.h) */
	if (rc != 0 && !err[0])
		abort(); /* refused without saying why */
}

/* The whole input as a config file's text (vmac_config_load reads the
 * file, at most 64 KiB, and hands its bytes to vmac_config_load_text). */
static void fuzz_file(const uint8_t *data, size_t size)
{
	struct vmac_config c;
	char err[512];
	int rc;
	vmac_config_defaults(&c);
	err[0] = 0;
	rc = vmac_config_load_text(&c, "fuzz.lua", (const char *)data, size, err, sizeof(err));
	check_result(rc, err);
	check_config(&c, 1);
	err[0] = 0;
	check_result(vmac_config_check(&c, err, sizeof(err)), err);
}

/* The input as lines KEY=VALUE, as vmacd's flags give them. */
static void fuzz_lines(const uint8_t *data, size_t size)
{
	struct vmac_config c;
	char *text = malloc(size + 1), *line, *save = NULL, err[512];
	if (!text)
		abort();
	memcpy(text, data, size);
	text[size] = 0;
	vmac_config_defaults(&c);
	for (line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
		char *eq = strchr(line, '=');
		if (!eq)
			continue;
		*eq = 0;
		err[0] = 0;
		check_result(vmac_config_set(&c, line, eq + 1, err, sizeof(err)), err);
		check_config(&c, 0);
	}
	check_config(&c, 1);
	err[0] = 0;
	check_result(vmac_config_check(&c, err, sizeof(err)), err);
	free(text);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (size > 65536)
		return 0; /* vmac_config_load refuses a file over 64 KiB */
	fuzz_file(data, size);
	fuzz_lines(data, size);
	return 0;
}
