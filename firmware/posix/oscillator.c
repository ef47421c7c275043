/* A board's oscillator, simulated: see oscillator.h. The counter is a sum
 * over a grid of 1 ms steps of true time, each at the drift of its knot;
 * between knots it is linear. The wander's increments and the receive
 * delays come from two splitmix64 streams of the seed. */
#include "oscillator.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static uint64_t splitmix64(uint64_t *state)
{
	uint64_t z = (*state += 0x9E3779B97F4A7C15ULL);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
	return z ^ (z >> 31);
}

/* Uniform in (0, 1): never 0, so that its log is finite. */
static double unit_open(uint64_t *state)
{
	return ((double)(splitmix64(state) >> 11) + 0.5) / 9007199254740992.0;
}

static double normal(uint64_t *state)
{
	double u1 = unit_open(state), u2 = unit_open(state);
	return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}

static int slot(int64_t knot)
{
	return (int)(knot % OSCILLATOR_HISTORY);
}

static void step_drift_in(struct oscillator *o, int64_t knot)
{
	if (o->step_done || o->cfg.step_at_s < 0 || (double)knot * OSCILLATOR_STEP_NS < o->cfg.step_at_s * 1e9)
		return;
	o->drift_ppm[slot(knot)] += o->cfg.step_ppm;
	o->step_done = 1;
}

void oscillator_init(struct oscillator *o, const struct oscillator_config *cfg)
{
	memset(o, 0, sizeof(*o));
	o->cfg = *cfg;
	o->wander_rng = cfg->seed ^ 0x5DEECE66DULL;
	o->jitter_rng = cfg->seed * 0x2545F4914F6CDD1DULL + 0x632BE59BD9B4E019ULL;
	o->local_ns[0] = cfg->offset_s * 1e9;
	o->drift_ppm[0] = cfg->drift_ppm;
	step_drift_in(o, 0);
}

/* One more knot: the counter at its end, and the drift of its segment. */
static void advance(struct oscillator *o)
{
	int64_t k = o->newest;
	double step_s = OSCILLATOR_STEP_NS / 1e9;
	double local = o->local_ns[slot(k)] + OSCILLATOR_STEP_NS * (1.0 + o->drift_ppm[slot(k)] * 1e-6);
	double drift = o->drift_ppm[slot(k)];
	if (o->cfg.wander_ppm > 0)
		drift += o->cfg.wander_ppm * sqrt(step_s) * normal(&o->wander_rng);
	o->newest = k + 1;
	o->local_ns[slot(k + 1)] = local;
	o->drift_ppm[slot(k + 1)] = drift;
	step_drift_in(o, k + 1);
}

static void check_kept(const struct oscillator *o, int64_t knot, const char *what)
{
	if (knot < 0 || knot <= o->newest - OSCILLATOR_HISTORY) {
		fprintf(stderr, "oscillator: %s is %lld steps behind the newest, more than the %d kept\n", what,
		        (long long)(o->newest - knot), OSCILLATOR_HISTORY);
		abort();
	}
}

static double local_at(struct oscillator *o, uint64_t true_ns)
{
	int64_t k = (int64_t)(true_ns / OSCILLATOR_STEP_NS);
	while (o->newest < k)
		advance(o);
	check_kept(o, k, "a true time asked for");
	return o->local_ns[slot(k)] +
	       (double)(true_ns - (uint64_t)k * OSCILLATOR_STEP_NS) * (1.0 + o->drift_ppm[slot(k)] * 1e-6);
}

uint64_t oscillator_local_ns(struct oscillator *o, uint64_t true_ns)
{
	double local = local_at(o, true_ns);
	return local <= 0 ? 0 : (uint64_t)local;
}

uint64_t oscillator_true_ns(struct oscillator *o, uint64_t local_ns)
{
	double target = (double)local_ns;
	int64_t lo, hi;
	while (o->local_ns[slot(o->newest)] <= target)
		advance(o);
	lo = o->newest - OSCILLATOR_HISTORY + 1 > 0 ? o->newest - OSCILLATOR_HISTORY + 1 : 0;
	hi = o->newest; /* local_ns[hi] > target */
	if (o->local_ns[slot(lo)] > target)
		check_kept(o, lo - 1, "a local time asked for");
	while (hi - lo > 1) { /* the last knot at or before target: local_ns[lo] <= target < local_ns[hi] */
		int64_t mid = lo + (hi - lo) / 2;
		if (o->local_ns[slot(mid)] <= target)
			lo = mid;
		else
			hi = mid;
	}
	return (uint64_t)llround((double)lo * OSCILLATOR_STEP_NS +
	                         (target - o->local_ns[slot(lo)]) / (1.0 + o->drift_ppm[slot(lo)] * 1e-6));
}

double oscillator_drift_ppm(struct oscillator *o, uint64_t true_ns)
{
	int64_t k = (int64_t)(true_ns / OSCILLATOR_STEP_NS);
	(void)local_at(o, true_ns);
	return o->drift_ppm[slot(k)];
}

uint64_t oscillator_rx_delay_ns(struct oscillator *o)
{
	if (o->cfg.jitter_us <= 0)
		return 0;
	return (uint64_t)(-log(unit_open(&o->jitter_rng)) * o->cfg.jitter_us * 1e3);
}
