/* A board's oscillator, simulated (docs/TIME.md, "The oscillator model"):
 * the local free-running counter a real board reads, made from the true
 * time of the simulation with an offset, a drift, a drift that wanders (a
 * random walk) and steps (a change of temperature), and the one-sided
 * jitter of a receive timestamp (a frame is only ever late). What
 * firmware/clock.c disciplines in the tests and the bench; later what
 * `vmac-board --clock-ppm/--clock-offset/--clock-jitter-us` will run on.
 * Deterministic under its seed. POSIX only: double and libm. */
#ifndef VMAC_POSIX_OSCILLATOR_H
#define VMAC_POSIX_OSCILLATOR_H

#include <stdint.h>

/* The model walks a grid of OSCILLATOR_STEP_NS of true time (the drift is
 * constant within a step, the wander's increment drawn at each knot) and
 * remembers the last OSCILLATOR_HISTORY knots, so that what a board reads
 * does not depend on when or how often it is asked. */
#define OSCILLATOR_STEP_NS 1000000u /* 1 ms */
#define OSCILLATOR_HISTORY 4096     /* knots: 4.096 s of true time behind the newest */

struct oscillator_config {
	double offset_s;   /* local - true at true time 0 (may be negative: see oscillator_local_ns) */
	double drift_ppm;  /* the counter runs fast by this much (negative: slow) */
	double wander_ppm; /* the drift's random walk: standard deviation after 1 s, ppm/sqrt(s) */
	double step_at_s;  /* true time of a step change of drift; < 0: none */
	double step_ppm;   /* that change */
	double jitter_us;  /* mean of the exponential receive delay; 0: timestamps exact */
	uint64_t seed;     /* the wander's and the jitter's random streams (two, independent) */
};

struct oscillator {
	struct oscillator_config cfg;
	int64_t newest;                       /* index of the newest knot (true time newest x step) */
	double local_ns[OSCILLATOR_HISTORY];  /* the counter at each knot, by index mod HISTORY */
	double drift_ppm[OSCILLATOR_HISTORY]; /* the drift from that knot to the next */
	int step_done;                        /* the step change is in the knots already */
	uint64_t wander_rng, jitter_rng;
};

/* Start at true time 0 with cfg. */
void oscillator_init(struct oscillator *o, const struct oscillator_config *cfg);

/* The local counter at true time true_ns (ns), rounded down. true_ns may
 * be any time from OSCILLATOR_HISTORY steps before the newest asked for on;
 * earlier times abort (a test's mistake). A counter below 0 (a negative
 * offset at an early true time) reads 0: start the simulation later than
 * the offset. */
uint64_t oscillator_local_ns(struct oscillator *o, uint64_t true_ns);

/* The true time (ns, rounded to the nearest) at which the counter reads
 * local_ns: when a timer compare at local_ns fires. Same window as
 * oscillator_local_ns; a local time in the future walks the model on. */
uint64_t oscillator_true_ns(struct oscillator *o, uint64_t local_ns);

/* The drift now in force at true time true_ns, ppm (what a perfect
 * frequency estimate would be). */
double oscillator_drift_ppm(struct oscillator *o, uint64_t true_ns);

/* One receive delay, ns: exponential with mean cfg.jitter_us, never
 * negative. Its own random stream: how many are drawn changes nothing else. */
uint64_t oscillator_rx_delay_ns(struct oscillator *o);

#endif
