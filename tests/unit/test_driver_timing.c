/* Unit tests for a driver's timing (core/driver/manifest.c, instance.c):
 * the manifest's `timing` table and the host's driver.NAME.timing.* over
 * it, checked against the host's lead and the period of the manifest's
 * level with errors that name the field; and dev.t, dev.boards[i].t, the
 * instants of the inputs a tick is given (docs/DRIVERS.md, "Timing"). */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../core/driver/driver.h"
#include "check_main.h"

static struct vmac_driver_limits limits;
static struct vmac_driver_setting settings[4];

static void setup(void)
{
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = 1 << 20;
	limits.instructions = 200000;
	limits.max_level = 10;
	limits.default_level = 5; /* 32 ms at 1 ms slots */
	limits.slot_us = 1000;
	limits.timed_lead_us = 500;
	limits.settings = settings;
	limits.nsettings = 0;
}

/* Load text as driver "t" (file t.lua). */
static int load(const char *text, struct vmac_driver **d, char *err, size_t errlen)
{
	char dir[] = "/tmp/vmac-test-timing-XXXXXX", path[64];
	FILE *f;
	int rc;
	ck_assert_msg(mkdtemp(dir) != NULL, "mkdtemp failed");
	snprintf(path, sizeof(path), "%s/t.lua", dir);
	f = fopen(path, "w");
	ck_assert_msg(f != NULL, "cannot write %s", path);
	fputs(text, f);
	fclose(f);
	limits.expect_name = "t";
	rc = vmac_driver_load(path, &limits, d, err, errlen);
	unlink(path);
	rmdir(dir);
	return rc;
}

static struct vmac_driver *load_ok(const char *text)
{
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load(text, &d, err, sizeof(err)) == 0, "load failed: %s", err);
	return d;
}

static void load_fails(const char *text, const char *want)
{
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load(text, &d, err, sizeof(err)) != 0, "load succeeded (wanted '%s')", want);
	ck_assert_msg(strstr(err, want) != NULL, "load error '%s' does not say '%s'", err, want);
}

static void set(int i, const char *key, const char *value)
{
	snprintf(settings[i].key, sizeof(settings[i].key), "%s", key);
	snprintf(settings[i].value, sizeof(settings[i].value), "%s", value);
	limits.nsettings = i + 1;
}

#define HEAD "return { name = 't', version = '1', io = { lamp = 'do0' }, "
#define TAIL " tick = function(dev, i) end }\n"

START_TEST(the_manifest_names_a_pattern_or_none)
{
	struct vmac_timing_want w;
	struct vmac_driver *d = load_ok(HEAD TAIL);
	vmac_driver_timing(d, &w);
	ck_assert_int_eq(w.pattern, VMAC_TIMING_DEFAULT);
	vmac_driver_free(d);
	d = load_ok(HEAD "timing = { pattern = 'offsets', input_us = 20000, output_us = 24000 }," TAIL);
	vmac_driver_timing(d, &w);
	ck_assert(w.pattern == VMAC_TIMING_OFFSETS && w.input_us == 20000 && w.output_us == 24000);
	vmac_driver_free(d);
	d = load_ok(HEAD "timing = { pattern = 'arrival' }," TAIL);
	vmac_driver_timing(d, &w);
	ck_assert_int_eq(w.pattern, VMAC_TIMING_ARRIVAL);
	vmac_driver_free(d);
}
END_TEST

START_TEST(a_bad_timing_is_refused_by_name)
{
	load_fails(HEAD "timing = 'phase'," TAIL, "timing must be a table");
	load_fails(HEAD "timing = { pattern = 'now' }," TAIL, "timing.pattern must be \"phase\", \"offsets\"");
	load_fails(HEAD "timing = { pattern = 'phase', input_us = 600 }," TAIL,
	           "input_us and output_us are for pattern \"offsets\"");
	load_fails(HEAD "timing = { pattern = 'offsets', input_us = 600 }," TAIL, "needs input_us and output_us");
	load_fails(HEAD "timing = { pattern = 'offsets', input_us = 0.5, output_us = 600 }," TAIL, "whole numbers");
	load_fails(HEAD "timing = { pattern = 'phase', when = 1 }," TAIL, "timing: unknown field 'when'");
	load_fails(HEAD "timing = { pattern = 'offsets', input_us = 400, output_us = 600 }," TAIL,
	           "timing: input_us = 400 must be at least the host's lead (timed_lead_us: 500 us)");
	load_fails(HEAD "timing = { pattern = 'offsets', input_us = 600, output_us = 32000 }," TAIL,
	           "output_us = 32000 must be at least the host's lead (timed_lead_us: 500 us) and below the period "
	           "(32000 us) (level 5)");
	/* The same offsets fit a level whose period holds them. */
	vmac_driver_free(
	    load_ok(HEAD "level = 6, timing = { pattern = 'offsets', input_us = 600, output_us = 32000 }," TAIL));
}
END_TEST

START_TEST(the_hosts_settings_override_the_manifest)
{
	struct vmac_timing_want w;
	struct vmac_driver *d;
	set(0, "timing.pattern", "offsets");
	set(1, "timing.input_us", "1000");
	set(2, "timing.output_us", "2000");
	d = load_ok(HEAD "timing = { pattern = 'phase' }," TAIL);
	vmac_driver_timing(d, &w);
	ck_assert(w.pattern == VMAC_TIMING_OFFSETS && w.input_us == 1000 && w.output_us == 2000);
	vmac_driver_free(d);
	limits.nsettings = 0;
	set(0, "timing.pattern", "arrival");
	d = load_ok(HEAD "timing = { pattern = 'offsets', input_us = 20000, output_us = 24000 }," TAIL);
	vmac_driver_timing(d, &w);
	ck_assert(w.pattern == VMAC_TIMING_ARRIVAL && w.input_us == 0 && w.output_us == 0);
	vmac_driver_free(d);
	set(0, "timing.pattern", "sometimes");
	load_fails(HEAD TAIL, "host setting driver.t.timing.pattern = 'sometimes': unknown key or bad value");
	set(0, "timing.when", "1");
	load_fails(HEAD TAIL, "driver.t.timing.when");
	set(0, "timing.pattern", "offsets");
	set(1, "timing.input_us", "100");
	set(2, "timing.output_us", "2000");
	load_fails(HEAD TAIL, "input_us = 100 must be at least the host's lead");
}
END_TEST

START_TEST(dev_t_is_each_boards_inputs_instant)
{
	struct vmac_driver *d =
	    load_ok(HEAD "variables = { t = {}, t1 = {}, t2 = {} },\n"
	                 " tick = function(dev, i) dev.vars.t = dev.t; dev.vars.t1 = dev.boards[1].t;"
	                 " dev.vars.t2 = dev.boards[2].t end }\n");
	struct vmac_inputs in0, in1;
	struct vmac_outputs out0, out1;
	const struct vmac_inputs *ins[2] = {&in0, &in1};
	struct vmac_outputs *outs[2] = {&out0, &out1};
	double t[2] = {4.9995, 4.9985};
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int i;
	memset(&in0, 0, sizeof(in0));
	memset(&in1, 0, sizeof(in1));
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "main"), 0);
	ck_assert_int_eq(vmac_driver_add_board(d, 1, "aux"), 0);
	vmac_driver_sample_times(d, t, 2);
	ck_assert_msg(vmac_driver_tick(d, 5.0, ins, outs, err, sizeof(err)) == 0, "tick failed: %s", err);
	for (i = 0; i < 3; i++)
		ck_assert_double_eq(vmac_driver_variable(d, i)->value.number, i == 2 ? 4.9985 : 4.9995);
	/* Given for one tick: the next without them has the tick's own time. */
	ck_assert_msg(vmac_driver_tick(d, 6.0, ins, outs, err, sizeof(err)) == 0, "tick failed: %s", err);
	for (i = 0; i < 3; i++)
		ck_assert_double_eq(vmac_driver_variable(d, i)->value.number, 6.0);
	vmac_driver_free(d);
}
END_TEST

START_TEST(output_at_asks_for_one_tick_within_the_period)
{
	struct vmac_driver *d =
	    load_ok(HEAD "timing = { pattern = 'offsets', input_us = 20000, output_us = 24000 },\n"
	                 " variables = { ok = {}, why = {} },\n"
	                 " tick = function(dev, i) local ok, why = dev:output_at(i.time < 1 and 0.028 or 0.040)\n"
	                 "   dev.vars.ok = ok == true; dev.vars.why = why end }\n");
	struct vmac_inputs in;
	struct vmac_outputs out;
	const struct vmac_inputs *ins[1] = {&in};
	struct vmac_outputs *outs[1] = {&out};
	char err[VMAC_DRIVER_ERR_MAX] = "";
	memset(&in, 0, sizeof(in));
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "main"), 0);
	ck_assert_msg(vmac_driver_tick(d, 0.5, ins, outs, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_double_eq_tol(vmac_driver_output_at(d), 0.028, 1e-12);
	ck_assert(vmac_driver_variable(d, 0)->value.number != 0);
	/* 40 ms is past the 32 ms period of level 5: refused, nothing asked. */
	ck_assert_msg(vmac_driver_tick(d, 1.5, ins, outs, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_double_eq(vmac_driver_output_at(d), -1);
	ck_assert(vmac_driver_variable(d, 0)->value.number == 0);
	ck_assert_msg(strstr(vmac_driver_variable(d, 1)->value.str, "output_at: 0.04") != NULL, "%s",
	              vmac_driver_variable(d, 1)->value.str);
	vmac_driver_free(d);
	d = load_ok(HEAD "variables = { why = {} },\n"
	                 " tick = function(dev, i) local _, why = dev:output_at(0.0004); dev.vars.why = why end }\n");
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "main"), 0);
	ck_assert_msg(vmac_driver_tick(d, 0.5, ins, outs, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_msg(strstr(vmac_driver_variable(d, 0)->value.str, "output_at: 0.0004") != NULL,
	              "phase: below the lead (0.5 ms) is refused: %s", vmac_driver_variable(d, 0)->value.str);
	vmac_driver_free(d);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("driver_timing");
	TCase *tc = tcase_create("timing");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, the_manifest_names_a_pattern_or_none);
	tcase_add_test(tc, a_bad_timing_is_refused_by_name);
	tcase_add_test(tc, the_hosts_settings_override_the_manifest);
	tcase_add_test(tc, dev_t_is_each_boards_inputs_instant);
	tcase_add_test(tc, output_at_asks_for_one_tick_within_the_period);
	suite_add_tcase(s, tc);
	return s;
}
