/* Unit and property tests of the communication scheduler (core/sched):
 * admission, the even table of thesis Appendix I, and the switch from one
 * table to the next that never postpones a running device.
 *
 * VMAC_SCHED_PROPERTY_RUNS sets how many random sequences the property test
 * runs (default 100000); VMAC_SCHED_PROPERTY_SEED its first seed (default 1).
 * A failure names the seed, the step and the slot; rerun just that sequence
 * with VMAC_SCHED_PROPERTY_SEED=<seed> VMAC_SCHED_PROPERTY_RUNS=1. */
#include <check.h>
#include <errno.h>
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/sched/sched.h"
#include "check_main.h"

#define MAX_S 16

/* ck_assert_msg records a check point on every call (a write to the parent
 * process in fork mode); the property test makes millions of checks, so it
 * only calls into Check when one fails. */
#define CHECK(cond, ...)                                                                                               \
	do {                                                                                                           \
		if (!(cond))                                                                                           \
			ck_abort_msg(__VA_ARGS__);                                                                     \
	} while (0)

/* ---- helpers ---- */

static uint64_t rng_next(uint64_t *state)
{
	uint64_t z = (*state += 0x9E3779B97F4A7C15ULL);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
	return z ^ (z >> 31);
}

static unsigned rng_below(uint64_t *state, unsigned n)
{
	return (unsigned)(rng_next(state) % n);
}

static struct vmac_sched *new_sched(unsigned S, unsigned K, unsigned max_devices)
{
	struct vmac_sched *s = vmac_sched_new(S, K, max_devices);
	ck_assert_msg(s != NULL, "vmac_sched_new(%u, %u, %u) returned NULL", S, K, max_devices);
	return s;
}

static void add_ok(struct vmac_sched *s, uint32_t id, unsigned level)
{
	char err[200] = "";
	int rc = vmac_sched_add(s, id, level, err, sizeof(err));
	ck_assert_msg(rc == 0, "add device %u at level %u: rc %d (%s)", (unsigned)id, level, rc, err);
}

/* Run one slot, return the number of entries (checked for sanity). */
static int run_slot(struct vmac_sched *s, uint64_t slot, struct vmac_sched_entry *e)
{
	int n = vmac_sched_slot(s, slot, e, VMAC_SCHED_MAX_SLICES);
	ck_assert_msg(n >= 0, "vmac_sched_slot(%" PRIu64 ") returned %d", slot, n);
	return n;
}

/* Run slots until nothing is pending; returns the slot after the last run. */
static uint64_t settle(struct vmac_sched *s, uint64_t slot, unsigned max_slots)
{
	struct vmac_sched_entry e[VMAC_SCHED_MAX_SLICES];
	unsigned i;
	for (i = 0; i < max_slots; i++) {
		run_slot(s, slot++, e);
		if (vmac_sched_pending(s, NULL) == 0)
			return slot;
	}
	ck_abort_msg("changes still pending after %u slots", max_slots);
	return slot;
}

/* Loads of the table in force: max - min over all rows. */
static unsigned spread(const struct vmac_sched *s, unsigned *lo_out, unsigned *hi_out)
{
	unsigned N = 1u << vmac_sched_max_level(s), row, lo = ~0u, hi = 0;
	for (row = 0; row < N; row++) {
		unsigned l = vmac_sched_load(s, row);
		lo = l < lo ? l : lo;
		hi = l > hi ? l : hi;
	}
	if (lo_out)
		*lo_out = lo;
	if (hi_out)
		*hi_out = hi;
	return hi - lo;
}

/* ---- admission ---- */

START_TEST(admission_fills_exactly_and_refuses_one_more)
{
	struct vmac_sched *s = new_sched(2, 3, 64); /* 2 slices x 8 slots = 16 slice-slots */
	char err[200] = "";
	unsigned used, total;
	int rc;
	add_ok(s, 100, 1); /* 4 slice-slots each */
	add_ok(s, 101, 1);
	add_ok(s, 102, 2); /* 2 */
	add_ok(s, 103, 2);
	add_ok(s, 104, 3); /* 1 */
	add_ok(s, 105, 3);
	vmac_sched_capacity(s, &used, &total);
	ck_assert_msg(used == 14 && total == 16, "capacity after 14 slice-slots: used %u total %u", used, total);
	rc = vmac_sched_add(s, 106, 2, err, sizeof(err)); /* needs 2, 2 free: fits exactly */
	ck_assert_msg(rc == 0, "a device that fits exactly was refused: %d (%s)", rc, err);
	rc = vmac_sched_add(s, 107, 3, err, sizeof(err));
	ck_assert_msg(rc == -ENOSPC, "a device on a full schedule got rc %d, want -ENOSPC", rc);
	ck_assert_str_eq(err, "schedule full: need level 3 (1 slice every 8 slots, 1 slice-slots per block), "
	                      "free capacity 0 of 16 slice-slots per block");
	settle(s, 0, 64);
	ck_assert_msg(spread(s, NULL, NULL) == 0, "a full table must load every slot alike, spread %u",
	              spread(s, NULL, NULL));
	vmac_sched_free(s);
}
END_TEST

START_TEST(admission_message_names_need_and_free_capacity)
{
	struct vmac_sched *s = new_sched(10, 3, 64); /* 80 slice-slots */
	char err[200] = "";
	unsigned i;
	int rc;
	for (i = 0; i < 9; i++)
		add_ok(s, i, 0); /* 8 each: 72 */
	for (i = 0; i < 6; i++)
		add_ok(s, 50 + i, 3); /* 1 each: 78 */
	rc = vmac_sched_add(s, 99, 1, err, sizeof(err));
	ck_assert_int_eq(rc, -ENOSPC);
	ck_assert_str_eq(err, "schedule full: need level 1 (1 slice every 2 slots, 4 slice-slots per block), "
	                      "free capacity 2 of 80 slice-slots per block");
	rc = vmac_sched_add(s, 99, 2, err, sizeof(err)); /* 2 of 2 free: admitted */
	ck_assert_msg(rc == 0, "level 2 needs exactly the 2 free slice-slots but got %d (%s)", rc, err);
	vmac_sched_free(s);
}
END_TEST

START_TEST(admission_errors)
{
	struct vmac_sched *s = new_sched(4, 2, 3);
	char err[200] = "";
	int rc;
	ck_assert_int_eq(vmac_sched_add(s, 1, 3, err, sizeof(err)), -EINVAL);
	ck_assert_str_eq(err, "level 3 out of range 0..2");
	add_ok(s, 1, 2);
	ck_assert_int_eq(vmac_sched_add(s, 1, 2, err, sizeof(err)), -EEXIST);
	ck_assert_str_eq(err, "device 1 is already scheduled");
	add_ok(s, 2, 2);
	add_ok(s, 3, 2);
	rc = vmac_sched_add(s, 4, 2, err, sizeof(err));
	ck_assert_msg(rc == -ENOSPC, "max_devices 3 but a 4th device got rc %d", rc);
	ck_assert_str_eq(err, "schedule full: 3 devices already (max_devices)");
	ck_assert_int_eq(vmac_sched_remove(s, 77), -ENOENT);
	ck_assert_int_eq(vmac_sched_set_level(s, 77, 1, err, sizeof(err)), -ENOENT);
	ck_assert_str_eq(err, "device 77 is not scheduled");
	ck_assert_int_eq(vmac_sched_set_level(s, 1, 9, err, sizeof(err)), -EINVAL);
	ck_assert_msg(vmac_sched_new(0, 3, 10) == NULL, "0 slices per slot accepted");
	ck_assert_msg(vmac_sched_new(4, VMAC_SCHED_MAX_LEVEL + 1, 10) == NULL, "too many levels accepted");
	ck_assert_msg(vmac_sched_new(4, 3, 0) == NULL, "max_devices 0 accepted");
	vmac_sched_free(s);
	vmac_sched_free(NULL);
}
END_TEST

START_TEST(slot_numbers_must_increase_and_out_must_fit)
{
	struct vmac_sched *s = new_sched(3, 1, 8);
	struct vmac_sched_entry e[3];
	add_ok(s, 7, 0);
	add_ok(s, 8, 0);
	ck_assert_int_eq(vmac_sched_slot(s, 10, e, 3), 2);
	ck_assert_int_eq(vmac_sched_slot(s, 10, e, 3), -EINVAL);
	ck_assert_int_eq(vmac_sched_slot(s, 9, e, 3), -EINVAL);
	ck_assert_int_eq(vmac_sched_slot(s, 11, e, 1), -ENOBUFS);
	ck_assert_int_eq(vmac_sched_slot(s, 20, e, 3), 2); /* skipping slots is allowed */
	vmac_sched_free(s);
}
END_TEST

/* Thesis Figure 16: device 1 at n = 0, device 2 at n = 1, a block of two
 * slots: device 1 in every slot, device 2 in every other one. */
START_TEST(thesis_figure_16)
{
	struct vmac_sched *s = new_sched(2, 1, 8);
	struct vmac_sched_entry e[2];
	uint64_t slot;
	int seen2 = 0;
	add_ok(s, 1, 0);
	add_ok(s, 2, 1);
	for (slot = 0; slot < 8; slot++) {
		int n = run_slot(s, slot, e), i, has1 = 0, has2 = 0;
		for (i = 0; i < n; i++) {
			has1 |= e[i].device == 1;
			has2 |= e[i].device == 2;
		}
		ck_assert_msg(has1, "device 1 (n = 0) missing in slot %" PRIu64, slot);
		if (slot > 0)
			ck_assert_msg(has2 != seen2, "device 2 (n = 1) must alternate; slot %" PRIu64 " has it: %d",
			              slot, has2);
		seen2 = has2;
	}
	vmac_sched_free(s);
}
END_TEST

/* Table 3 of the thesis: ten 100 us slices per 1 ms slot. With K = 7 (a
 * block of 128 ms) the schedule holds 10 devices at 1 kHz (n = 0), 80 at
 * 125 Hz (n = 3), 160 at 62.5 Hz (n = 4) or 1280 at 7.8 Hz (n = 7); one more
 * is refused, and every slot is exactly full. */
static void fill_level(unsigned level, unsigned expect)
{
	struct vmac_sched *s = new_sched(10, 7, 2000);
	struct vmac_sched_entry e[10];
	static unsigned served[1280];
	char err[200];
	unsigned i, slot;
	uint64_t t;
	for (i = 0; i < expect; i++)
		add_ok(s, 1000 + i, level);
	ck_assert_msg(vmac_sched_add(s, 5000, 7, err, sizeof(err)) == -ENOSPC,
	              "level %u: device %u (even at level 7) admitted past %u", level, expect + 1, expect);
	t = settle(s, 0, 4);
	memset(served, 0, sizeof(served));
	for (slot = 0; slot < 256; slot++) {
		int n = run_slot(s, t + slot, e), k;
		ck_assert_msg(n == 10, "level %u x %u: slot %u holds %d devices, want 10", level, expect, slot, n);
		for (k = 0; k < n; k++) {
			ck_assert_msg(e[k].slice == (unsigned)k, "slot %u: entry %d has slice %u", slot, k, e[k].slice);
			served[e[k].device - 1000]++;
		}
	}
	for (i = 0; i < expect; i++)
		ck_assert_msg(served[i] == 256u >> level, "level %u: device %u served %u times in 256 slots, want %u",
		              level, i, served[i], 256u >> level);
	vmac_sched_free(s);
}

START_TEST(table3_capacity)
{
	fill_level(0, 10);
	fill_level(3, 80);
	fill_level(4, 160);
	fill_level(7, 1280);
}
END_TEST

START_TEST(refused_level_change_keeps_device_running)
{
	struct vmac_sched *s = new_sched(1, 2, 8); /* 4 slice-slots */
	struct vmac_sched_device d;
	char err[200] = "";
	uint64_t t;
	add_ok(s, 1, 1); /* 2 */
	add_ok(s, 2, 2); /* 1 */
	t = settle(s, 0, 8);
	ck_assert_int_eq(vmac_sched_set_level(s, 2, 0, err, sizeof(err)), -ENOSPC);
	ck_assert_str_eq(err, "schedule full: need level 0 (1 slice every 1 slots, 4 slice-slots per block), "
	                      "free capacity 2 of 4 slice-slots per block");
	ck_assert_int_eq(vmac_sched_pending(s, NULL), 0);
	ck_assert_int_eq(vmac_sched_device(s, 2, &d), 0);
	ck_assert_msg(d.state == VMAC_SCHED_RUNNING && d.level == 2 && d.want_level == 2,
	              "after a refused change device 2 is state %d level %u want %u", d.state, d.level, d.want_level);
	ck_assert_msg(vmac_sched_set_level(s, 2, 1, err, sizeof(err)) == 0, "level 1 fits exactly: %s", err);
	t = settle(s, t, 8);
	ck_assert_int_eq(vmac_sched_device(s, 2, &d), 0);
	ck_assert_msg(d.level == 1, "device 2 level %u after the change, want 1", d.level);
	vmac_sched_free(s);
}
END_TEST

START_TEST(removed_device_is_not_served_and_id_can_return)
{
	struct vmac_sched *s = new_sched(2, 2, 8);
	struct vmac_sched_entry e[2];
	struct vmac_sched_device d;
	uint64_t t;
	int n, i;
	add_ok(s, 42, 0);
	add_ok(s, 43, 2);
	ck_assert_int_eq(vmac_sched_device(s, 42, &d), 0);
	ck_assert_msg(d.state == VMAC_SCHED_WAITING, "before any slot device 42 is state %d, want WAITING", d.state);
	t = settle(s, 0, 4);
	ck_assert_int_eq(vmac_sched_remove(s, 42), 0);
	ck_assert_int_eq(vmac_sched_device(s, 42, &d), -ENOENT);
	n = run_slot(s, t++, e);
	for (i = 0; i < n; i++)
		ck_assert_msg(e[i].device != 42, "device 42 served after its removal");
	add_ok(s, 42, 1);
	t = settle(s, t, 8);
	ck_assert_int_eq(vmac_sched_device(s, 42, &d), 0);
	ck_assert_msg(d.state == VMAC_SCHED_RUNNING && d.level == 1, "device 42 back: state %d level %u", d.state,
	              d.level);
	ck_assert_msg(spread(s, NULL, NULL) <= 1, "spread %u after remove + add", spread(s, NULL, NULL));
	vmac_sched_free(s);
}
END_TEST

/* The worked example of docs/SCHEDULER.md: one slice per slot, a block of
 * four slots. a and b (level 2) run at offsets 0 and 1; c asks for level 1.
 * Each class of level 1, {0, 2} and {1, 3}, holds one of a and b, so one of
 * them has to move. Asked just before slot 4 (offset 0: a is due now, b
 * next), every even table would postpone a or b, so the switch waits; at
 * slot 5 a has just been served and can move from 0 to 3: its next service
 * comes 3 slots after the last one instead of 4. */
START_TEST(worked_example_switch_waits_and_moves_earlier)
{
	struct vmac_sched *s = new_sched(1, 2, 8);
	struct vmac_sched_entry e[1];
	struct vmac_sched_device a, b, c;
	uint64_t waited = 0;
	int n;
	add_ok(s, 'a', 2);
	n = run_slot(s, 0, e); /* a switched in at slot 0, first service at once: offset 0 */
	ck_assert_msg(n == 1 && e[0].device == 'a', "slot 0 serves the new device a (n %d)", n);
	add_ok(s, 'b', 2);
	n = run_slot(s, 1, e); /* b switched in at slot 1: offset 1 */
	ck_assert_msg(n == 1 && e[0].device == 'b', "slot 1 serves the new device b (n %d)", n);
	ck_assert_int_eq(run_slot(s, 2, e), 0);
	ck_assert_int_eq(run_slot(s, 3, e), 0);
	ck_assert_int_eq(vmac_sched_device(s, 'a', &a), 0);
	ck_assert_int_eq(vmac_sched_device(s, 'b', &b), 0);
	ck_assert_msg(a.offset == 0 && b.offset == 1, "start: a at %u, b at %u; want 0 and 1", a.offset, b.offset);
	add_ok(s, 'c', 1);
	n = run_slot(s, 4, e);
	ck_assert_msg(n == 1 && e[0].device == 'a', "slot 4 must still serve a from the old table (n %d)", n);
	ck_assert_msg(vmac_sched_pending(s, &waited) == 1 && waited == 1,
	              "at slot 4 no even table keeps a and b on time: c must wait (pending %u, waited %" PRIu64 ")",
	              vmac_sched_pending(s, NULL), waited);
	n = run_slot(s, 5, e);
	ck_assert_msg(n == 1 && e[0].device == 'b', "slot 5 serves b (n %d, device %u)", n, n ? e[0].device : 0);
	ck_assert_int_eq(vmac_sched_pending(s, NULL), 0);
	ck_assert_int_eq(vmac_sched_device(s, 'a', &a), 0);
	ck_assert_int_eq(vmac_sched_device(s, 'b', &b), 0);
	ck_assert_int_eq(vmac_sched_device(s, 'c', &c), 0);
	ck_assert_msg(a.offset == 3 && b.offset == 1 && c.level == 1 && c.offset == 0,
	              "after the switch: a at %u (want 3), b at %u (want 1), c level %u at %u (want 1 at 0)", a.offset,
	              b.offset, c.level, c.offset);
	n = run_slot(s, 6, e);
	ck_assert_msg(n == 1 && e[0].device == 'c', "slot 6 serves c");
	n = run_slot(s, 7, e);
	ck_assert_msg(n == 1 && e[0].device == 'a', "slot 7 serves a, 3 slots after slot 4");
	vmac_sched_free(s);
}
END_TEST

/* ---- negative control: greedy placement without moving anybody ----
 *
 * Place each arriving device in the emptiest class of its level (the
 * thesis's rule) but never move a device already placed. Appendix I's bound
 * needs the rebuild in ascending n: in arrival order the spread grows. */

struct greedy {
	unsigned N, load[256];
	unsigned level[64], offset[64];
	int live[64];
};

static unsigned greedy_spread(const struct greedy *g)
{
	unsigned lo = ~0u, hi = 0, r;
	for (r = 0; r < g->N; r++) {
		lo = g->load[r] < lo ? g->load[r] : lo;
		hi = g->load[r] > hi ? g->load[r] : hi;
	}
	return hi - lo;
}

static void greedy_place(struct greedy *g, unsigned i, unsigned level)
{
	unsigned p = 1u << level, o, r, best = 0, best_max = ~0u;
	for (o = 0; o < p; o++) {
		unsigned m = 0;
		for (r = o; r < g->N; r += p)
			m = g->load[r] > m ? g->load[r] : m;
		if (m < best_max) {
			best_max = m;
			best = o;
		}
	}
	for (r = best; r < g->N; r += p)
		g->load[r]++;
	g->level[i] = level;
	g->offset[i] = best;
	g->live[i] = 1;
}

static void greedy_remove(struct greedy *g, unsigned i)
{
	unsigned r;
	for (r = g->offset[i]; r < g->N; r += 1u << g->level[i])
		g->load[r]--;
	g->live[i] = 0;
}

START_TEST(negative_control_greedy_without_moves_breaks_the_bound)
{
	const unsigned K = 6, N = 1u << K; /* 7 levels, 0..6 */
	unsigned worst_arrivals = 0, worst_departures = 0, seed;
	uint64_t worst_seed = 0;
	for (seed = 1; seed <= 2000; seed++) {
		struct greedy g;
		uint64_t rng = seed;
		unsigned i, sp;
		memset(&g, 0, sizeof(g));
		g.N = N;
		for (i = 0; i < 40; i++) {
			greedy_place(&g, i, rng_below(&rng, K + 1));
			sp = greedy_spread(&g);
			if (sp > worst_arrivals) {
				worst_arrivals = sp;
				worst_seed = seed;
			}
		}
		for (i = 0; i < 400; i++) { /* churn: one leaves, one arrives */
			unsigned victim = rng_below(&rng, 40);
			greedy_remove(&g, victim);
			greedy_place(&g, victim, rng_below(&rng, K + 1));
			sp = greedy_spread(&g);
			worst_departures = sp > worst_departures ? sp : worst_departures;
		}
	}
	printf("negative control: greedy without moves, 7 levels: spread %u from arrivals alone (seed %" PRIu64
	       "), %u with departures\n",
	       worst_arrivals, worst_seed, worst_departures);
	ck_assert_msg(worst_arrivals >= 2, "greedy without moves kept spread %u <= 1: the control shows nothing",
	              worst_arrivals);
	ck_assert_msg(worst_departures >= 3, "greedy with departures only reached spread %u", worst_departures);

	/* the same arrivals through the scheduler stay within 1 */
	{
		struct vmac_sched *s = new_sched(MAX_S, K, 64);
		uint64_t rng = worst_seed, t = 0;
		unsigned i;
		for (i = 0; i < 40; i++) {
			char err[200];
			if (vmac_sched_add(s, i, rng_below(&rng, K + 1), err, sizeof(err)) != 0)
				break;
			t = settle(s, t, 8 * N);
			ck_assert_msg(spread(s, NULL, NULL) <= 1,
			              "scheduler spread %u after arrival %u of seed %" PRIu64, spread(s, NULL, NULL), i,
			              worst_seed);
		}
		vmac_sched_free(s);
	}
}
END_TEST

/* ---- property test: random sequences of attach, detach, level change ----
 *
 * After every burst of changes the slots run until the scheduler has put
 * them all in force, then one more block; every slot is checked as it runs:
 *   (a) whenever nothing is pending, the fullest slot holds at most one
 *       device more than the emptiest;
 *   (b) no two services in a slot share a slice, no device twice in a slot,
 *       and the table in force, rebuilt from every device's level, offset and
 *       slice, has no two devices in one slice and matches the loads;
 *   (c) a device never waits longer between two services than the period it
 *       had at the first of them (across any number of switches), removed
 *       devices are never served, and every device is served each block;
 *   (d) add and set_level succeed exactly when the sum of 2^(K - n) over the
 *       admitted devices stays within S * 2^K;
 *   (e) every burst of c changes is in force within (c + 1) blocks. */

#define PMAX 512

struct pdev {
	unsigned want;
	int live;
	int has_last;
	uint64_t last;
	unsigned last_level;
};

struct prop {
	uint64_t seed, rng;
	unsigned S, K, N, total, used;
	struct vmac_sched *s;
	struct pdev dev[PMAX];
	unsigned ndev, nlive;
	uint32_t salt, inverse;
	uint64_t slot;
	unsigned step;
	uint64_t max_wait_slots; /* longest time a burst took to come in force */
	unsigned max_wait_blocks_x100;
};

static uint64_t prop_worst_wait_x100; /* over all runs, in hundredths of a block per change */
static uint64_t prop_switch_checks;

static uint32_t id_of(const struct prop *p, unsigned idx)
{
	return (uint32_t)idx * 0x9E3779B1u + p->salt;
}

static unsigned idx_of(const struct prop *p, uint32_t id)
{
	return (unsigned)((id - p->salt) * p->inverse);
}

static void prop_slot(struct prop *p)
{
	struct vmac_sched_entry e[MAX_S + 1];
	int n = vmac_sched_slot(p->s, p->slot, e, (int)p->S), k;
	CHECK(n >= 0 && n <= (int)p->S, "seed %" PRIu64 " step %u slot %" PRIu64 ": vmac_sched_slot returned %d (S %u)",
	      p->seed, p->step, p->slot, n, p->S);
	for (k = 0; k < n; k++) {
		unsigned i = idx_of(p, e[k].device);
		struct pdev *d;
		CHECK(i < p->ndev, "seed %" PRIu64 " step %u slot %" PRIu64 ": unknown device %u served", p->seed,
		      p->step, p->slot, (unsigned)e[k].device);
		d = &p->dev[i];
		CHECK(e[k].slice < p->S && (k == 0 || e[k].slice > e[k - 1].slice),
		      "seed %" PRIu64 " step %u slot %" PRIu64 ": slice %u of entry %d (previous %d, S %u)", p->seed,
		      p->step, p->slot, e[k].slice, k, k ? e[k - 1].slice : -1, p->S);
		CHECK(d->live, "seed %" PRIu64 " step %u slot %" PRIu64 ": device %u served after its removal", p->seed,
		      p->step, p->slot, i);
		CHECK(!d->has_last || d->last != p->slot,
		      "seed %" PRIu64 " step %u slot %" PRIu64 ": device %u served twice in one slot", p->seed, p->step,
		      p->slot, i);
		CHECK(!d->has_last || p->slot - d->last <= (1u << d->last_level),
		      "seed %" PRIu64 " step %u: device %u waited %" PRIu64 " slots (served at %" PRIu64
		      " at level %u, period %u, next at %" PRIu64 " at level %u)",
		      p->seed, p->step, i, p->slot - d->last, d->last, d->last_level, 1u << d->last_level, p->slot,
		      e[k].level);
		d->has_last = 1;
		d->last = p->slot;
		d->last_level = e[k].level;
	}
	p->slot++;
}

static void prop_add(struct prop *p, unsigned level)
{
	char err[200] = "";
	unsigned w = 1u << (p->K - level);
	int rc, fits = p->used + w <= p->total;
	if (p->ndev >= PMAX)
		return;
	rc = vmac_sched_add(p->s, id_of(p, p->ndev), level, err, sizeof(err));
	CHECK(fits ? rc == 0 : rc == -ENOSPC,
	      "seed %" PRIu64 " step %u: add at level %u (needs %u, used %u of %u) returned %d (%s)", p->seed, p->step,
	      level, w, p->used, p->total, rc, err);
	if (rc == 0) {
		struct pdev *d = &p->dev[p->ndev];
		memset(d, 0, sizeof(*d));
		d->want = level;
		d->live = 1;
		p->used += w;
		p->nlive++;
		p->ndev++;
	} else {
		CHECK(strncmp(err, "schedule full: need level", 25) == 0, "seed %" PRIu64 " step %u: refusal text '%s'",
		      p->seed, p->step, err);
		p->ndev++; /* the id is spent either way */
		p->dev[p->ndev - 1].live = 0;
		p->dev[p->ndev - 1].has_last = 0;
	}
}

static int prop_pick_live(struct prop *p, unsigned *out)
{
	unsigned tries;
	if (p->nlive == 0)
		return 0;
	for (tries = 0; tries < 4 * PMAX; tries++) {
		unsigned i = rng_below(&p->rng, p->ndev);
		if (p->dev[i].live) {
			*out = i;
			return 1;
		}
	}
	return 0;
}

static void prop_remove(struct prop *p)
{
	unsigned i;
	int rc;
	if (!prop_pick_live(p, &i))
		return;
	rc = vmac_sched_remove(p->s, id_of(p, i));
	CHECK(rc == 0, "seed %" PRIu64 " step %u: remove of live device %u returned %d", p->seed, p->step, i, rc);
	p->dev[i].live = 0;
	p->used -= 1u << (p->K - p->dev[i].want);
	p->nlive--;
}

static void prop_set_level(struct prop *p, unsigned level)
{
	char err[200] = "";
	unsigned i, w_old, w_new;
	int rc, fits;
	if (!prop_pick_live(p, &i))
		return;
	w_old = 1u << (p->K - p->dev[i].want);
	w_new = 1u << (p->K - level);
	fits = p->used - w_old + w_new <= p->total;
	rc = vmac_sched_set_level(p->s, id_of(p, i), level, err, sizeof(err));
	CHECK(fits ? rc == 0 : rc == -ENOSPC,
	      "seed %" PRIu64 " step %u: device %u level %u -> %u (used %u of %u) returned %d (%s)", p->seed, p->step,
	      i, p->dev[i].want, level, p->used, p->total, rc, err);
	if (rc == 0) {
		p->used = p->used - w_old + w_new;
		p->dev[i].want = level;
	}
}

/* Everything in force: check the table itself. */
static void prop_check_table(struct prop *p)
{
	static int32_t owner[(MAX_S) << 8];
	static struct vmac_sched_device list[PMAX];
	unsigned used, total, lo, hi, row, k, nlive = 0;
	uint64_t load_sum = 0, weight_sum = 0;
	int n;
	vmac_sched_capacity(p->s, &used, &total);
	CHECK(used == p->used && total == p->total,
	      "seed %" PRIu64 " step %u: capacity used %u of %u, model says %u of %u", p->seed, p->step, used, total,
	      p->used, p->total);
	CHECK(spread(p->s, &lo, &hi) <= 1,
	      "seed %" PRIu64 " step %u: fullest slot holds %u devices, emptiest %u (S %u, K %u)", p->seed, p->step, hi,
	      lo, p->S, p->K);
	for (k = 0; k < p->N * p->S; k++)
		owner[k] = -1;
	n = vmac_sched_devices(p->s, list, PMAX);
	for (k = 0; k < (unsigned)n; k++) {
		const struct vmac_sched_device *d = &list[k];
		unsigned i = idx_of(p, d->device);
		CHECK(i < p->ndev && p->dev[i].live, "seed %" PRIu64 " step %u: listed device %u is not live", p->seed,
		      p->step, i);
		CHECK(d->state == VMAC_SCHED_RUNNING && d->level == p->dev[i].want && d->want_level == d->level,
		      "seed %" PRIu64 " step %u: device %u state %d level %u want %u, asked for %u", p->seed, p->step,
		      i, d->state, d->level, d->want_level, p->dev[i].want);
		CHECK(d->slice < p->S && d->offset < (1u << d->level),
		      "seed %" PRIu64 " step %u: device %u slice %u offset %u level %u", p->seed, p->step, i, d->slice,
		      d->offset, d->level);
		for (row = d->offset; row < p->N; row += 1u << d->level) {
			int32_t *o = &owner[row * p->S + d->slice];
			CHECK(*o < 0, "seed %" PRIu64 " step %u: devices %d and %u share slice %u of row %u", p->seed,
			      p->step, *o, i, d->slice, row);
			*o = (int32_t)i;
		}
		CHECK(p->dev[i].has_last && p->dev[i].last + p->N >= p->slot,
		      "seed %" PRIu64 " step %u: device %u not served during the last block (slot %" PRIu64 ")",
		      p->seed, p->step, i, p->slot);
		weight_sum += p->N >> d->level;
		nlive++;
	}
	CHECK(nlive == p->nlive, "seed %" PRIu64 " step %u: %u devices listed, %u live", p->seed, p->step, nlive,
	      p->nlive);
	for (row = 0; row < p->N; row++) {
		unsigned cnt = 0;
		for (k = 0; k < p->S; k++)
			cnt += owner[row * p->S + k] >= 0;
		CHECK(cnt == vmac_sched_load(p->s, row),
		      "seed %" PRIu64 " step %u: row %u load %u but %u devices placed there", p->seed, p->step, row,
		      vmac_sched_load(p->s, row), cnt);
		load_sum += cnt;
	}
	CHECK(load_sum == weight_sum, "seed %" PRIu64 " step %u: loads sum %" PRIu64 ", devices need %" PRIu64, p->seed,
	      p->step, load_sum, weight_sum);
}

static void prop_run(uint64_t seed)
{
	static struct prop p;
	unsigned steps, k, target;
	memset(&p, 0, sizeof(p));
	p.seed = seed;
	p.rng = seed ^ 0x6A09E667F3BCC909ULL;
	p.S = 1 + rng_below(&p.rng, MAX_S);
	p.K = rng_below(&p.rng, 9);
	p.N = 1u << p.K;
	p.total = p.S * p.N;
	p.salt = (uint32_t)rng_next(&p.rng);
	p.inverse = 0x9E3779B1u;
	for (k = 0; k < 5; k++) /* Newton: inverse of the odd multiplier mod 2^32 */
		p.inverse *= 2u - 0x9E3779B1u * p.inverse;
	p.slot = rng_next(&p.rng) >> 40; /* the caller's slot counter need not start at 0 */
	p.s = new_sched(p.S, p.K, PMAX);

	/* half the runs start from a table filled to a random fraction */
	if (rng_below(&p.rng, 2)) {
		target = rng_below(&p.rng, p.total + 1);
		while (p.used < target && p.ndev < PMAX / 2)
			prop_add(&p, rng_below(&p.rng, p.K + 1));
	}
	steps = 1 + rng_below(&p.rng, 10);
	for (p.step = 0; p.step <= steps; p.step++) {
		unsigned burst = p.step == 0 ? 0 : rng_below(&p.rng, 10) < 7 ? 1 : 2 + rng_below(&p.rng, 3), b;
		uint64_t start, waited;
		for (b = 0; b < burst; b++) {
			unsigned op = rng_below(&p.rng, 100), level = rng_below(&p.rng, p.K + 1);
			if (op < 50)
				prop_add(&p, level);
			else if (op < 72)
				prop_remove(&p);
			else
				prop_set_level(&p, level);
		}
		start = p.slot;
		while (vmac_sched_pending(p.s, &waited) > 0) {
			CHECK(p.slot - start <= (uint64_t)(burst + 1) * p.N + 1,
			      "seed %" PRIu64 " step %u: %u changes still pending after %" PRIu64
			      " slots (S %u, K %u, oldest waited %" PRIu64 ")",
			      p.seed, p.step, vmac_sched_pending(p.s, NULL), p.slot - start, p.S, p.K, waited);
			prop_slot(&p);
		}
		if (p.slot - start > p.max_wait_slots)
			p.max_wait_slots = p.slot - start;
		if (burst && (p.slot - start) * 100 / (burst * p.N) > prop_worst_wait_x100)
			prop_worst_wait_x100 = (p.slot - start) * 100 / (burst * p.N);
		CHECK(spread(p.s, NULL, NULL) <= 1, "seed %" PRIu64 " step %u: spread %u right after the switch",
		      p.seed, p.step, spread(p.s, NULL, NULL));
		for (k = 0; k < p.N; k++)
			prop_slot(&p);
		prop_check_table(&p);
		prop_switch_checks++;
	}
	vmac_sched_free(p.s);
}

static unsigned long env_number(const char *name, unsigned long fallback)
{
	const char *v = getenv(name);
	char *end;
	unsigned long n;
	if (!v || !*v)
		return fallback;
	n = strtoul(v, &end, 10);
	return *end ? fallback : n;
}

START_TEST(property_random_sequences)
{
	unsigned long runs = env_number("VMAC_SCHED_PROPERTY_RUNS", 100000);
	unsigned long first = env_number("VMAC_SCHED_PROPERTY_SEED", 1), i;
	for (i = 0; i < runs; i++)
		prop_run(first + i);
	printf(
	    "property: %lu random sequences (seeds %lu..%lu), %" PRIu64
	    " settled tables checked; slowest burst came in force after %" PRIu64 ".%02" PRIu64 " blocks per change\n",
	    runs, first, first + runs - 1, prop_switch_checks, prop_worst_wait_x100 / 100, prop_worst_wait_x100 % 100);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("sched");
	TCase *unit = tcase_create("unit");
	TCase *prop = tcase_create("property");
	tcase_set_timeout(unit, 60);
	tcase_add_test(unit, admission_fills_exactly_and_refuses_one_more);
	tcase_add_test(unit, admission_message_names_need_and_free_capacity);
	tcase_add_test(unit, admission_errors);
	tcase_add_test(unit, slot_numbers_must_increase_and_out_must_fit);
	tcase_add_test(unit, thesis_figure_16);
	tcase_add_test(unit, table3_capacity);
	tcase_add_test(unit, refused_level_change_keeps_device_running);
	tcase_add_test(unit, removed_device_is_not_served_and_id_can_return);
	tcase_add_test(unit, worked_example_switch_waits_and_moves_earlier);
	tcase_add_test(unit, negative_control_greedy_without_moves_breaks_the_bound);
	suite_add_tcase(s, unit);
	tcase_set_timeout(prop, 900);
	tcase_add_test(prop, property_random_sequences);
	suite_add_tcase(s, prop);
	return s;
}
