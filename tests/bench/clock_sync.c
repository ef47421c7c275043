/* Ten boards acting on one host instant by their disciplined clocks
 * (firmware/clock.c over firmware/posix/oscillator.c), next to the same
 * boards acting when the frame arrives (what every board does today), in
 * one simulated run (docs/TIME.md, "The numbers"):
 *
 *   - 10 boards, drifts spread over -100..+100 ppm, offsets of seconds,
 *     wander 0.02 ppm/sqrt(s), receive jitter exponential with mean 20 us;
 *   - the host ticks at 1 kHz and its frame leaves late by the host's own
 *     send lateness: log-normal, median 47 us, p99 134 us (eth-cyclic's
 *     figures in docs/PERFORMANCE.md, "The fieldbus"), the frame carrying
 *     its true send time (taken as late as possible);
 *   - timed: each tick asks every board to act at host instant T = the
 *     tick + one period (phase-aligned, one period delay); a board's timer
 *     fires at to_local(T) on its own counter, and the true instant of
 *     that is what counts; on arrival: the true instant the frame arrives.
 *
 * Reported: the spread of the ten true instants of one tick (max - min),
 * p50, p99 and max over every tick; how far from its intended instant
 * each board acts (T for timed, the tick for on arrival), p99 and max;
 * the ratio of the spreads' p99; the convergence time of each board; the
 * error after 1 s without sync frames; and the clock's own cost, ns per
 * sample on this machine. Deterministic under --seed. --json prints one
 * JSON object:
 *
 *   make build/bench/clock_sync && build/bench/clock_sync [--seconds S] [--seed N] [--json] */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../firmware/clock.h"
#include "../../firmware/posix/oscillator.h"

#define BOARDS 10
#define PERIOD_NS 1000000ull
#define T0_NS 100000000000ull /* true time of the first tick: beyond every offset */
#define WARMUP_S 2            /* every board locked before measuring */
#define LATENESS_MEDIAN_US 47.0
#define LATENESS_SIGMA 0.45 /* ln(134 / 47) / 2.326: p99 134 us; p99.9 is then 189 us (200 measured) */

struct board {
	struct oscillator osc;
	struct vmac_clock clock;
	uint64_t locked_at; /* true time first LOCKED, 0 until then */
};

static struct board boards[BOARDS];
static uint64_t host_rng;

static double unit_open(void)
{
	uint64_t z = (host_rng += 0x9E3779B97F4A7C15ULL);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
	return ((double)((z ^ (z >> 31)) >> 11) + 0.5) / 9007199254740992.0;
}

/* The host's send lateness, ns: log-normal (Box-Muller). */
static uint64_t host_lateness_ns(void)
{
	double normal = sqrt(-2.0 * log(unit_open())) * cos(6.283185307179586 * unit_open());
	return (uint64_t)(LATENESS_MEDIAN_US * 1e3 * exp(LATENESS_SIGMA * normal));
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

static double quantile(double *v, size_t n, double q)
{
	size_t i = (size_t)(q * (double)(n - 1) + 0.5);
	return n ? v[i < n ? i : n - 1] : 0;
}

struct figures {
	double spread_p50, spread_p99, spread_max; /* ns, max - min of the ten instants of a tick */
	double off_p99, off_max;                   /* ns, |instant - intended| of any board */
};

static void summarise(double *spread, double *off, size_t ticks, struct figures *f)
{
	qsort(spread, ticks, sizeof(double), cmp_double);
	qsort(off, ticks * BOARDS, sizeof(double), cmp_double);
	f->spread_p50 = quantile(spread, ticks, 0.50);
	f->spread_p99 = quantile(spread, ticks, 0.99);
	f->spread_max = spread[ticks - 1];
	f->off_p99 = quantile(off, ticks * BOARDS, 0.99);
	f->off_max = off[ticks * BOARDS - 1];
}

/* One tick: the frame leaves at send_ns (true = host time), reaches each
 * board after its receive delay; each feeds its clock. instants_timed and
 * instants_arrival (BOARDS each, may be NULL) get the true instants at
 * which each would act on host instant act_ns. Returns the boards that
 * fell back to acting on arrival. */
static int tick(uint64_t send_ns, uint64_t act_ns, double *instants_timed, double *instants_arrival)
{
	int i, fallbacks = 0;
	for (i = 0; i < BOARDS; i++) {
		struct board *b = &boards[i];
		uint64_t arrival = send_ns + oscillator_rx_delay_ns(&b->osc), local, when;
		local = oscillator_local_ns(&b->osc, arrival);
		vmac_clock_feed(&b->clock, send_ns, local);
		if (b->clock.state == VMAC_CLOCK_LOCKED && !b->locked_at)
			b->locked_at = arrival;
		if (!instants_timed)
			continue;
		if (vmac_clock_act_at(&b->clock, act_ns, local, &when) == 0)
			fallbacks++;
		instants_timed[i] = (double)oscillator_true_ns(&b->osc, when);
		instants_arrival[i] = (double)arrival;
	}
	return fallbacks;
}

static double spread_of(const double *v)
{
	double lo = v[0], hi = v[0];
	int i;
	for (i = 1; i < BOARDS; i++) {
		lo = v[i] < lo ? v[i] : lo;
		hi = v[i] > hi ? v[i] : hi;
	}
	return hi - lo;
}

/* After the run: every board 1 s without a frame, then its error and bound. */
static void holdover(uint64_t from_ns, double *worst_error, double *worst_bound)
{
	int i;
	*worst_error = *worst_bound = 0;
	for (i = 0; i < BOARDS; i++) {
		uint64_t t = from_ns, host, local = 0;
		for (; t <= from_ns + 1000000000ull; t += PERIOD_NS) { /* time passes, the clock asked each ms */
			local = oscillator_local_ns(&boards[i].osc, t);
			vmac_clock_tick(&boards[i].clock, local);
		}
		t -= PERIOD_NS;
		if (vmac_clock_to_host(&boards[i].clock, local, &host) != 0) {
			*worst_error = INFINITY;
			continue;
		}
		if (fabs((double)(int64_t)(host - t)) > *worst_error)
			*worst_error = fabs((double)(int64_t)(host - t));
		if ((double)vmac_clock_bound_ns(&boards[i].clock, local) > *worst_bound)
			*worst_bound = (double)vmac_clock_bound_ns(&boards[i].clock, local);
	}
}

/* ns per vmac_clock_feed on this machine: a locked clock fed 1,000,000 exact samples. */
static double feed_cost_ns(void)
{
	struct vmac_clock c;
	struct timespec a, b;
	uint64_t k, n = 1000000;
	vmac_clock_init(&c);
	clock_gettime(CLOCK_MONOTONIC, &a);
	for (k = 0; k < n; k++)
		vmac_clock_feed(&c, T0_NS + k * PERIOD_NS, 5000000000ull + k * (PERIOD_NS + 100));
	clock_gettime(CLOCK_MONOTONIC, &b);
	return ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / n;
}

static void print_json(const struct figures *timed, const struct figures *arrival, double lock_max_s, double hold_error,
                       double hold_bound, long fallbacks, double feed_ns, int seconds, uint64_t seed)
{
	printf("{\"boards\": %d, \"seconds\": %d, \"seed\": %llu, \"rate_hz\": 1000, \"jitter_us\": 20, "
	       "\"timed\": {\"spread_p50_ns\": %.0f, \"spread_p99_ns\": %.0f, \"spread_max_ns\": %.0f, "
	       "\"off_p99_ns\": %.0f, \"off_max_ns\": %.0f, \"fallbacks\": %ld}, "
	       "\"arrival\": {\"spread_p50_ns\": %.0f, \"spread_p99_ns\": %.0f, \"spread_max_ns\": %.0f, "
	       "\"off_p99_ns\": %.0f, \"off_max_ns\": %.0f}, \"spread_p99_ratio\": %.1f, "
	       "\"lock_max_s\": %.3f, \"holdover_1s_error_ns\": %.0f, \"holdover_1s_bound_ns\": %.0f, "
	       "\"feed_ns\": %.1f}\n",
	       BOARDS, seconds, (unsigned long long)seed, timed->spread_p50, timed->spread_p99, timed->spread_max,
	       timed->off_p99, timed->off_max, fallbacks, arrival->spread_p50, arrival->spread_p99, arrival->spread_max,
	       arrival->off_p99, arrival->off_max, arrival->spread_p99 / timed->spread_p99, lock_max_s, hold_error,
	       hold_bound, feed_ns);
}

static void print_text(const struct figures *timed, const struct figures *arrival, double lock_max_s, double hold_error,
                       double hold_bound, long fallbacks, double feed_ns, int seconds)
{
	printf("clock sync: %d boards (-100..+100 ppm, 20 us receive jitter), sync at 1 kHz, host send lateness "
	       "p50 47 / p99 134 us, %d s\n",
	       BOARDS, seconds);
	printf("                         spread of one tick's instants (us)   off its intended instant (us)\n");
	printf("                         p50       p99       max              p99       max\n");
	printf("  timed (host instant)   %-9.2f %-9.2f %-16.2f %-9.2f %.2f   (%ld fell back to arrival)\n",
	       timed->spread_p50 / 1e3, timed->spread_p99 / 1e3, timed->spread_max / 1e3, timed->off_p99 / 1e3,
	       timed->off_max / 1e3, fallbacks);
	printf("  on arrival (today)     %-9.2f %-9.2f %-16.2f %-9.2f %.2f\n", arrival->spread_p50 / 1e3,
	       arrival->spread_p99 / 1e3, arrival->spread_max / 1e3, arrival->off_p99 / 1e3, arrival->off_max / 1e3);
	printf("  spread p99, on arrival / timed: %.1f (goal: timed p99 <= 10 us)\n",
	       arrival->spread_p99 / timed->spread_p99);
	printf("convergence: every board locked (within 10 us) %.3f s after its first frame at the latest\n",
	       lock_max_s);
	printf("holdover: 1 s without frames, worst error %.2f us, its bound %.2f us\n", hold_error / 1e3,
	       hold_bound / 1e3);
	printf("cost: %.1f ns per sample fed (this machine)\n", feed_ns);
}

int main(int argc, char **argv)
{
	int seconds = 20, json = 0, i;
	uint64_t seed = 1, t, ticks, k;
	double *spread_t, *spread_a, *off_t, *off_a, timed[BOARDS], arrival[BOARDS], lock_max_s = 0;
	double hold_error, hold_bound;
	long fallbacks = 0;
	struct figures ft, fa;
	for (i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--json"))
			json = 1;
		else if (!strcmp(argv[i], "--seconds") && i + 1 < argc)
			seconds = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--seed") && i + 1 < argc)
			seed = strtoull(argv[++i], NULL, 10);
		else {
			fprintf(stderr, "usage: clock_sync [--seconds S] [--seed N] [--json]\n");
			return 2;
		}
	}
	if (seconds < 1)
		seconds = 1;
	host_rng = seed * 0x2545F4914F6CDD1DULL;
	for (i = 0; i < BOARDS; i++) {
		struct oscillator_config cfg = {((double)((seed + (uint64_t)i) * 7919 % 19) - 9.0) * 1.03,
		                                -100.0 + 200.0 * i / (BOARDS - 1),
		                                0.02,
		                                -1,
		                                0,
		                                20.0,
		                                seed * 1000 + (uint64_t)i};
		oscillator_init(&boards[i].osc, &cfg);
		vmac_clock_init(&boards[i].clock);
	}
	ticks = (uint64_t)seconds * 1000;
	spread_t = malloc(ticks * sizeof(double));
	spread_a = malloc(ticks * sizeof(double));
	off_t = malloc(ticks * BOARDS * sizeof(double));
	off_a = malloc(ticks * BOARDS * sizeof(double));
	if (!spread_t || !spread_a || !off_t || !off_a)
		return 1;
	for (t = T0_NS; t < T0_NS + WARMUP_S * 1000000000ull; t += PERIOD_NS)
		tick(t + host_lateness_ns(), 0, NULL, NULL);
	for (i = 0; i < BOARDS; i++) {
		if (!boards[i].locked_at) {
			fprintf(stderr, "clock_sync: board %d not locked after %d s\n", i, WARMUP_S);
			return 1;
		}
		if ((boards[i].locked_at - T0_NS) / 1e9 > lock_max_s)
			lock_max_s = (boards[i].locked_at - T0_NS) / 1e9;
	}
	for (k = 0; k < ticks; k++, t += PERIOD_NS) {
		uint64_t act = t + PERIOD_NS; /* phase-aligned, one period delay */
		fallbacks += tick(t + host_lateness_ns(), act, timed, arrival);
		spread_t[k] = spread_of(timed);
		spread_a[k] = spread_of(arrival);
		for (i = 0; i < BOARDS; i++) {
			off_t[k * BOARDS + i] = fabs(timed[i] - (double)act);
			off_a[k * BOARDS + i] = fabs(arrival[i] - (double)t);
		}
	}
	summarise(spread_t, off_t, ticks, &ft);
	summarise(spread_a, off_a, ticks, &fa);
	holdover(t, &hold_error, &hold_bound);
	if (json)
		print_json(&ft, &fa, lock_max_s, hold_error, hold_bound, fallbacks, feed_cost_ns(), seconds, seed);
	else
		print_text(&ft, &fa, lock_max_s, hold_error, hold_bound, fallbacks, feed_cost_ns(), seconds);
	free(spread_t);
	free(spread_a);
	free(off_t);
	free(off_a);
	return 0;
}
