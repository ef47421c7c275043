/* What the Lua plant's unit tests share (test_luaplant.c,
 * test_luaplant_run.c): loading a plant from text as plants/t.lua with
 * the limits of the test, expecting a load to be refused, stepping, and
 * reading an input or a field of the plant's state. All static inline,
 * each test program using what it needs. */
#ifndef VMAC_TESTS_LUAPLANT_HELPERS_H
#define VMAC_TESTS_LUAPLANT_HELPERS_H

#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/driver/driver.h"
#include "../../core/driver/luaplant.h"

#define PLANT_FILE "plants/t.lua" /* the name messages give the plant's file */

/* The limits of the plant the next plant_of() loads: reset by each test's
 * fixture (luaplant_limits_reset), then changed by the tests that need it. */
static struct vmac_luaplant_limits luaplant_limits;

static inline void luaplant_limits_reset(void)
{
	memset(&luaplant_limits, 0, sizeof(luaplant_limits));
	luaplant_limits.seed = 1;
}

/* A plant loaded from src that must load: the plant, or the test fails
 * with the load's error. The caller frees it. */
static inline struct vmac_luaplant *plant_of(const char *src)
{
	struct vmac_luaplant *p = NULL;
	char err[VMAC_DRIVER_ERR_MAX];
	int rc = vmac_luaplant_load(PLANT_FILE, src, strlen(src), "t", &luaplant_limits, &p, err, sizeof(err));
	ck_assert_msg(rc == 0 && p != NULL, "the plant did not load: %s\n--- source:\n%s", rc ? err : "(no plant)",
	              src);
	return p;
}

/* src must not load, with an error holding each of want1 and want2 (want2
 * may be NULL); what says which refusal this is. */
static inline void expect_refused(const char *what, const char *src, const char *want1, const char *want2)
{
	struct vmac_luaplant *p = (struct vmac_luaplant *)1;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int rc = vmac_luaplant_load(PLANT_FILE, src, strlen(src), "t", &luaplant_limits, &p, err, sizeof(err));
	if (rc == 0)
		vmac_luaplant_free(p);
	ck_assert_msg(rc == -1, "%s: the plant loaded (rc %d), expected a refusal naming '%s'", what, rc, want1);
	ck_assert_msg(p == NULL, "%s: a refused load left *out set", what);
	ck_assert_msg(strstr(err, want1) != NULL, "%s: the error does not say '%s': %s", what, want1, err);
	ck_assert_msg(!want2 || strstr(err, want2) != NULL, "%s: the error does not say '%s': %s", what, want2, err);
}

/* n steps of dt_s seconds, each of which must succeed. */
static inline void steps_ok(struct vmac_luaplant *p, int n, double dt_s)
{
	int i;
	for (i = 0; i < n; i++)
		ck_assert_msg(vmac_luaplant_step(p, dt_s) == 0, "step %d of %d (dt %g s) failed: %s", i + 1, n, dt_s,
		              vmac_luaplant_failure(p) ? vmac_luaplant_failure(p) : "(no failure said)");
}

static inline struct vmac_inputs sensed(const struct vmac_luaplant *p)
{
	struct vmac_inputs in;
	memset(&in, 0xA5, sizeof(in));
	vmac_luaplant_sense(p, &in);
	return in;
}

static inline int digital_in(const struct vmac_luaplant *p, unsigned bit)
{
	return (sensed(p).digital >> bit) & 1;
}

/* The number (or boolean, as 0/1) of state field name; the test fails
 * when there is none. */
static inline double field_number(struct vmac_luaplant *p, const char *name)
{
	struct vmac_value v;
	ck_assert_msg(vmac_luaplant_field(p, name, &v) == 0, "the plant's state has no field '%s'", name);
	ck_assert_msg(v.type == VMAC_VALUE_NUMBER || v.type == VMAC_VALUE_BOOL,
	              "field '%s' is not a number or a boolean (type %d)", name, (int)v.type);
	return v.number;
}

#endif
