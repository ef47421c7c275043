/* Unit tests for the seed's patterns on the 2^n schedule (core/sched/timing.c):
 * the names, the checks a manifest's timing must pass (offsets at least the
 * lead, below the period), the resolution (arrival without clock sync,
 * phase by default) and the instants of a service. docs/TIME.md, "The
 * patterns", is the contract checked; the host's frames are in
 * tests/integration/test_timed.py. */
#include <check.h>
#include <string.h>

#include "../../core/sched/timing.h"
#include "check_main.h"

START_TEST(names_parse_back)
{
	int p;
	for (p = VMAC_TIMING_PHASE; p <= VMAC_TIMING_ARRIVAL; p++)
		ck_assert_int_eq(vmac_timing_parse(vmac_timing_name(p)), p);
	ck_assert_int_eq(vmac_timing_parse("default"), -1);
	ck_assert_int_eq(vmac_timing_parse("Phase"), -1);
	ck_assert_int_eq(vmac_timing_parse(""), -1);
}
END_TEST

START_TEST(the_lead_is_half_a_slot_unless_set)
{
	ck_assert_uint_eq(vmac_timing_lead_us(0, 1000), 500);
	ck_assert_uint_eq(vmac_timing_lead_us(0, 6250), 3125);
	ck_assert_uint_eq(vmac_timing_lead_us(200, 1000), 200);
}
END_TEST

START_TEST(phase_by_default_at_the_lead_with_clock_sync)
{
	struct vmac_timing_want w = {VMAC_TIMING_DEFAULT, 0, 0};
	struct vmac_timing t;
	char err[200];
	uint64_t out_at, in_at;
	ck_assert_int_eq(vmac_timing_resolve(&w, 1, 500, 32000, &t, err, sizeof(err)), 0);
	ck_assert_int_eq(t.pattern, VMAC_TIMING_PHASE);
	vmac_timing_instants(&t, 7000000000LL, &out_at, &in_at);
	ck_assert_uint_eq(out_at, 7000500000ULL);
	ck_assert_uint_eq(in_at, 7000500000ULL); /* one instant: inputs latched, outputs released */
}
END_TEST

START_TEST(arrival_without_clock_sync_whatever_is_asked)
{
	struct vmac_timing_want w[] = {{VMAC_TIMING_DEFAULT, 0, 0},
	                               {VMAC_TIMING_PHASE, 0, 0},
	                               {VMAC_TIMING_OFFSETS, 600, 900},
	                               {VMAC_TIMING_ARRIVAL, 0, 0}};
	struct vmac_timing t;
	char err[200];
	uint64_t out_at = 1, in_at = 1;
	unsigned i;
	for (i = 0; i < sizeof(w) / sizeof(w[0]); i++) {
		ck_assert_int_eq(vmac_timing_resolve(&w[i], 0, 500, 1000, &t, err, sizeof(err)), 0);
		ck_assert_int_eq(t.pattern, VMAC_TIMING_ARRIVAL);
	}
	ck_assert_int_eq(vmac_timing_resolve(&w[3], 1, 500, 1000, &t, err, sizeof(err)), 0);
	ck_assert_int_eq(t.pattern, VMAC_TIMING_ARRIVAL);
	vmac_timing_instants(&t, 7000000000LL, &out_at, &in_at);
	ck_assert(out_at == 0 && in_at == 0);
}
END_TEST

START_TEST(offsets_are_their_own_instants)
{
	struct vmac_timing_want w = {VMAC_TIMING_OFFSETS, 20000, 24000};
	struct vmac_timing t;
	char err[200];
	uint64_t out_at, in_at;
	ck_assert_int_eq(vmac_timing_resolve(&w, 1, 500, 32000, &t, err, sizeof(err)), 0);
	ck_assert_int_eq(t.pattern, VMAC_TIMING_OFFSETS);
	vmac_timing_instants(&t, 1000000LL, &out_at, &in_at);
	ck_assert_uint_eq(in_at, 21000000ULL);
	ck_assert_uint_eq(out_at, 25000000ULL);
	/* Outputs before inputs are allowed: the seed's fixed offsets name both. */
	w.input_us = 900, w.output_us = 600;
	ck_assert_int_eq(vmac_timing_resolve(&w, 1, 500, 1000, &t, err, sizeof(err)), 0);
}
END_TEST

START_TEST(offsets_below_the_lead_or_past_the_period_are_refused_with_a_reason)
{
	struct vmac_timing_want w = {VMAC_TIMING_OFFSETS, 400, 600};
	struct vmac_timing t;
	char err[200];
	ck_assert_int_eq(vmac_timing_resolve(&w, 1, 500, 1000, &t, err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "input_us = 400") && strstr(err, "timed_lead_us: 500 us") &&
	                  strstr(err, "period (1000 us)"),
	              "%s", err);
	ck_assert_int_eq(t.pattern, VMAC_TIMING_ARRIVAL); /* refused: what it runs is arrival */
	w.input_us = 500, w.output_us = 1000;             /* the lead itself is fine; the period is not */
	ck_assert_int_eq(vmac_timing_check(&w, 500, 1000, err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "output_us = 1000"), "%s", err);
	w.output_us = 999;
	ck_assert_int_eq(vmac_timing_check(&w, 500, 1000, err, sizeof(err)), 0);
	/* The same offsets at a shorter period (a lower level) do not fit. */
	ck_assert_int_eq(vmac_timing_check(&w, 500, 500, err, sizeof(err)), -1);
}
END_TEST

START_TEST(instants_are_for_offsets_only)
{
	struct vmac_timing_want w = {VMAC_TIMING_PHASE, 600, 0};
	char err[200];
	ck_assert_int_eq(vmac_timing_check(&w, 500, 1000, err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "for pattern offsets, not phase"), "%s", err);
	w.pattern = VMAC_TIMING_ARRIVAL;
	ck_assert_int_eq(vmac_timing_check(&w, 500, 1000, err, sizeof(err)), -1);
	w.pattern = 9;
	ck_assert_int_eq(vmac_timing_check(&w, 500, 1000, err, sizeof(err)), -1);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("timing");
	TCase *tc = tcase_create("patterns");
	tcase_add_test(tc, names_parse_back);
	tcase_add_test(tc, the_lead_is_half_a_slot_unless_set);
	tcase_add_test(tc, phase_by_default_at_the_lead_with_clock_sync);
	tcase_add_test(tc, arrival_without_clock_sync_whatever_is_asked);
	tcase_add_test(tc, offsets_are_their_own_instants);
	tcase_add_test(tc, offsets_below_the_lead_or_past_the_period_are_refused_with_a_reason);
	tcase_add_test(tc, instants_are_for_offsets_only);
	suite_add_tcase(s, tc);
	return s;
}
