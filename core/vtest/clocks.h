/* The board clocks of `vmac test` (docs/TESTING.md, "Board clocks"): each
 * virtual board's free-running counter, what its disciplined clock
 * (firmware/clock.c, inside firmware/board.c) is fed from and read at.
 *
 * A board without a clock of its own has a perfect counter: world time
 * plus VT_CLOCK_BASE_NS, stamps exact. With one (`board{clock = {...}}`)
 * its counter is firmware/posix/oscillator.c's model (offset, drift,
 * wander, steps of drift, receive jitter), seeded from the run's seed and
 * the board's index: the same seed gives the same counter and the same
 * stamps. Host time is the world's time (the virtual bus stamps SYNC with
 * it), so a board's true error is known here, as on vmac-board's bench. */
#ifndef VMAC_VTEST_CLOCKS_H
#define VMAC_VTEST_CLOCKS_H

#include <stddef.h>
#include <stdint.h>

/* Every board's counter read VT_CLOCK_BASE_NS plus its offset at the
 * world's time 0 (as if powered a while before), so that an offset can be
 * negative; what the test API shows leaves the base out. */
#define VT_CLOCK_BASE_NS 1000000000000LL /* 1000 s */
#define VT_CLOCK_MAX_OFFSET_S 900.0      /* |offset| below the base: the counter never reads below 0 */
#define VT_CLOCK_MAX_PPM 1000.0          /* the clock's own clamp (VMAC_CLOCK_MAX_PPM) */

struct oscillator;
struct vt_world;
struct vt_board;

/* A board's clock as the test asked for it (all 0: the perfect one). */
struct vt_clock_spec {
	double ppm;      /* the counter runs fast by this much (negative: slow) */
	double offset_s; /* counter minus host time at the world's time 0 */
	double jitter_s; /* mean of the exponential receive-stamp delay */
	double wander;   /* the drift's random walk, ppm/sqrt(s) */
};

struct vt_clock {
	struct oscillator *osc; /* NULL: the perfect counter (no model, no cost) */
};

/* What `b.clock` shows: the board's clock read through firmware/board.h
 * and firmware/clock.h at the counter's now, and the truth beside it. */
struct vt_clock_view {
	const char *state; /* unsynced, locking, locked, holdover, lost */
	int has_line;      /* 0 (unsynced, lost): no offset, bound or error */
	double offset_s;   /* the board's estimate of counter - host time, less the base */
	double bound_s;    /* its error bound now */
	double error_s;    /* its reading of host time now less the true one (less the wire's delay) */
	double drift_ppm;  /* the frequency it learnt: how fast it thinks its counter runs */
	double true_ppm;   /* how fast the counter runs now (the model's drift; 0 for the perfect one) */
	uint32_t syncs;    /* SYNC samples fed (accepted and rejected) */
};

/* Give b the modelled counter of spec (replacing any): 0, or -1 with err
 * (a value out of range, no memory). Before b's first frame, normally. */
int vt_clock_set(struct vt_world *w, struct vt_board *b, const struct vt_clock_spec *spec, char *err, size_t errlen);
void vt_clock_free(struct vt_board *b);

/* b's counter at the world's now; rx: as its receive path stamps a frame
 * arriving now (late by the modelled jitter). */
uint64_t vt_clock_local_ns(struct vt_world *w, struct vt_board *b, int rx);

/* The world time (ns) at which b's counter reads local_ns: when a timer
 * of the board set for local_ns fires. No earlier than 4 s before the
 * latest time the counter was read. */
int64_t vt_clock_world_ns(struct vt_board *b, uint64_t local_ns);

/* Age every board's clock at the world's now (holdover, lost): the plant
 * grid calls it. Boards whose clock never had a sample cost one compare. */
void vt_clock_poll(struct vt_world *w);

/* A step of b's drift by ppm from now on (a change of temperature). 0, or
 * -1 with err (the result out of range). Gives a perfect counter a model. */
int vt_clock_step(struct vt_world *w, struct vt_board *b, double ppm, char *err, size_t errlen);

void vt_clock_view(struct vt_world *w, struct vt_board *b, struct vt_clock_view *v);

/* The Lua side (clocks_lua.c), for vtest.c's world methods; each raises
 * on a mistake. Pushes b.clock's table. */
struct lua_State;
int vt_lua_clock(struct lua_State *L, struct vt_world *w, struct vt_board *b);
/* The table at idx ({ppm=, offset=, jitter=, wander=}) as b's clock. */
int vt_lua_set_clock(struct lua_State *L, int idx, struct vt_world *w, struct vt_board *b);
/* The number at idx as a step of b's drift, ppm. */
int vt_lua_clock_step(struct lua_State *L, int idx, struct vt_world *w, struct vt_board *b);

#endif
