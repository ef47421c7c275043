/* The board's disciplined clock (docs/TIME.md): host time estimated from
 * the board's own free-running counter and the host's sync samples, each a
 * host send time carried in a frame and the board's receive timestamp of
 * that frame. Offset and frequency are learnt by linuxptp's PI servo (its
 * first-sample step and two-point frequency estimate, then a
 * proportional-integral loop) fed by a minimum filter over windows of
 * samples: a frame can only be late, never early, so the earliest arrival
 * of a window (and of the few windows before, aged) is its truest sample.
 * A gate throws out frames far later than the jitter seen so far, NTP's
 * popcorn spike suppressor a window whose frames all queued, and a bound
 * on the error grows while no sample comes. Portable C99: no heap, no OS header, no floating point (64-bit
 * integers, frequencies in 2^-32 ns per ns), the caller passes every time
 * in; the same code runs on the Cortex-M3 and in vmac-board.
 *
 * The fallback: while the clock is not usable (vmac_clock_usable() 0:
 * unsynced, locking or lost) the board acts on a frame when it arrives,
 * as a board without a clock does, and says so (vmac_clock_act_at()). */
#ifndef VMAC_CLOCK_H
#define VMAC_CLOCK_H

#include <stdint.h>

/* The filter and the servo (docs/TIME.md, "The filter" says why each). */
#define VMAC_CLOCK_WINDOW 16                 /* samples per minimum-filter window */
#define VMAC_CLOCK_WINDOW_MAX_NS 100000000u  /* a window spans at most 100 ms, however few its samples */
#define VMAC_CLOCK_PAST_WINDOWS 3            /* the servo's offset: the least of the window's minimum and 3 before... */
#define VMAC_CLOCK_PAST_PPM 50               /* ...each counted 50 ppm (50 ns per ms) later for its age */
#define VMAC_CLOCK_FREQ_EST_NS 250000000u    /* first frequency: two window minima at least 250 ms apart */
#define VMAC_CLOCK_KP_SHIFT 4                /* P: 1/16 of the offset corrected per window */
#define VMAC_CLOCK_KI_SHIFT 9                /* I: 1/512 of it into the frequency per window */
#define VMAC_CLOCK_FREQ_AVG 32               /* holdover runs on the integral's mean over 32 windows */
#define VMAC_CLOCK_FLOOR_AVG 32              /* the offsets' floor relaxes to their mean over 32 windows */
#define VMAC_CLOCK_SPIKE_K 4                 /* a window offset beyond 4 x the spread... */
#define VMAC_CLOCK_SPIKE_FLOOR_NS 2000       /* ...+ 2 us + the bound's growth is a spike: skipped... */
#define VMAC_CLOCK_SPIKE_RUN 4               /* ...unless 4 come in a row (then it is real) */
#define VMAC_CLOCK_MAX_PPM 1000              /* frequency clamped to +-1000 ppm */
#define VMAC_CLOCK_STEP_NS 1000000           /* a window offset beyond 1 ms: start over (a step) */
#define VMAC_CLOCK_GATE_K 8                  /* reject a sample later than 8 x the jitter... */
#define VMAC_CLOCK_GATE_FLOOR_NS 50000       /* ...plus 50 us */
#define VMAC_CLOCK_REJECT_LOST_NS 250000000u /* every sample rejected for 250 ms: lost */
/* The states and the bound. */
#define VMAC_CLOCK_LOCK_NS 10000         /* locked: bound within 10 us... */
#define VMAC_CLOCK_LOCK_WINDOWS 8        /* ...at 8 windows in a row of the servo */
#define VMAC_CLOCK_UNLOCK_NS 20000       /* locked, a window's bound beyond 20 us: locking again */
#define VMAC_CLOCK_HOLDOVER_NS 50000000u /* locked, no sample accepted for 50 ms: holdover */
#define VMAC_CLOCK_LOST_NS 50000         /* bound beyond 50 us: lost */
#define VMAC_CLOCK_BOUND_FLOOR_NS 1000   /* never a bound below 1 us (a window's drift, the timer's grain) */
#define VMAC_CLOCK_WANDER_PPB_PER_S 100  /* the frequency change assumed in holdover: 0.1 ppm/s */
#define VMAC_CLOCK_FREQ_FLOOR_PPB 50     /* the least frequency uncertainty ever claimed */

enum vmac_clock_state {
	VMAC_CLOCK_UNSYNCED, /* no sample since init: host time unknown; act on arrival */
	VMAC_CLOCK_LOCKING,  /* stepped to the samples, frequency and offset settling; act on arrival */
	VMAC_CLOCK_LOCKED,   /* the bound within VMAC_CLOCK_LOCK_NS: act at host instants */
	VMAC_CLOCK_HOLDOVER, /* locked, but no sample lately: on the learnt mean frequency, the bound growing */
	VMAC_CLOCK_LOST,     /* the bound past VMAC_CLOCK_LOST_NS: act on arrival; the next sample starts over */
};

/* Return of vmac_clock_feed(). */
#define VMAC_CLOCK_ACCEPTED 1
#define VMAC_CLOCK_REJECTED 0

struct vmac_clock_counters {
	uint32_t accepted, rejected; /* samples */
	uint32_t windows;            /* windows closed (each one update, unless a spike) */
	uint32_t spikes;             /* windows skipped as spikes (NTP's popcorn spike suppressor) */
	uint32_t starts;             /* acquisitions begun: the first sample, after lost, an offset beyond 1 ms */
	uint32_t lost;               /* times the clock was lost */
};

/* The clock, from the last update at local_ref, where it read host_ref:
 * host(local) = host_ref + dl x (1 + drift) + min(dl, slew_len) x slew,
 * dl = local - local_ref. The learnt frequency (drift) runs on for good;
 * the servo's proportional correction (slew) only for one window's length,
 * so that holdover carries no correction meant for one window. Continuous
 * from one update to the next except at a step. Times are ns; frequencies
 * Q32 (2^-32 ns/ns, 0.23 ppb). */
struct vmac_clock {
	enum vmac_clock_state state;
	uint64_t local_ref, host_ref;
	int64_t drift_q32; /* the servo's integral: the learnt frequency, - 1 (host ns per local ns) */
	int64_t slew_q32;  /* the servo's proportional term, for slew_len_ns after the update */
	int64_t slew_len_ns;
	int servo; /* 0: the frequency not yet estimated; 1: the PI loop runs */
	/* The window being filled: its sample of least lateness. */
	uint32_t window_n;
	int64_t window_min_ns;
	uint64_t window_min_local, window_min_host, window_start_local;
	int64_t window_sum_ns; /* the window's latenesses summed: its mean, less its minimum, is its jitter */
	/* The last past_n windows' minima (servo only; past_next the slot for
	 * the next): a window's offset is the least of them and its own, as
	 * the line now in force sees them. */
	uint64_t past_local[VMAC_CLOCK_PAST_WINDOWS], past_host[VMAC_CLOCK_PAST_WINDOWS];
	uint32_t past_n, past_next;
	/* The frequency estimate's first point (a window minimum). */
	int has_anchor;
	uint64_t anchor_local, anchor_host;
	/* What the bound is made of (docs/TIME.md, "The error bound"). */
	int64_t offset_mean_ns; /* EWMA of the windows' offsets (the servo's input: past_least() in clock.c) */
	int64_t offset_dev_ns;  /* EWMA of their distance from that mean */
	int64_t last_offset_ns; /* the last window's */
	int64_t floor_ns;       /* the offsets' floor: their least, relaxing to their mean (the bias) */
	int64_t jitter_ns;      /* EWMA of how much later than the window's minimum a sample comes */
	int64_t freq_mean_q32;  /* EWMA of the integral, over about VMAC_CLOCK_FREQ_AVG windows: holdover's frequency */
	int64_t freq_dev_q32;   /* EWMA of the integral's distance from that mean */
	uint64_t last_update_local; /* the last window's close: the bound grows from there */
	uint64_t last_accept_local, reject_since_local;
	uint32_t reject_run;          /* samples rejected in a row */
	uint32_t good_windows;        /* windows of the servo in a row with the bound within VMAC_CLOCK_LOCK_NS */
	uint32_t spike_run;           /* windows skipped in a row as spikes */
	int64_t spike_ns;             /* the last one's offset: the bound counts it while spike_run > 0 */
	int doubted;                  /* a new session: LOCKING until a sample says whose line this is */
	enum vmac_clock_state resume; /* the usable state it was in, back if the sample agrees */
	struct vmac_clock_counters counters;
};

/* UNSYNCED, nothing learnt. */
void vmac_clock_init(struct vmac_clock *c);

/* One sync sample: host_ns, the host's send time of a frame, and
 * local_ns, the board's counter when it arrived. Samples come in order of
 * local_ns. Time passes first (vmac_clock_tick(c, local_ns)), then the
 * sample is filtered. Returns VMAC_CLOCK_ACCEPTED, or VMAC_CLOCK_REJECTED
 * for a frame later than the gate (VMAC_CLOCK_GATE_K x the jitter +
 * VMAC_CLOCK_GATE_FLOOR_NS beyond the clock's offset; only while usable),
 * which changes nothing but the counters and the rejection run. */
int vmac_clock_feed(struct vmac_clock *c, uint64_t host_ns, uint64_t local_ns);

/* Time passes: after VMAC_CLOCK_HOLDOVER_NS without an accepted sample,
 * LOCKED goes to HOLDOVER (its last window closed, then on at the mean
 * frequency) and any state goes to LOST once the bound passes
 * VMAC_CLOCK_LOST_NS; samples rejected without a break for
 * VMAC_CLOCK_REJECT_LOST_NS are LOST too. Returns the state. Call it as
 * often as the state must be current (every loop, before acting);
 * feeding calls it first. docs/TIME.md, "The states". */
enum vmac_clock_state vmac_clock_tick(struct vmac_clock *c, uint64_t local_ns);

/* A new session began: its host may keep another time base (another
 * machine, or one rebooted), so a usable clock is not trusted for it
 * until a sample of its SYNC says which. Until then LOCKING (act on
 * arrival). A sample that agrees with the line (within the gate, early by
 * no more than the bound allows) puts the clock back as it was; one
 * further (earlier than that, or later than a step) starts acquisition
 * over from it; one late within a step is rejected as a queued frame.
 * A clock not usable is left as it is: its windows judge the samples.
 * docs/TIME.md, "A new session". */
void vmac_clock_doubt(struct vmac_clock *c);

/* 1 when the board acts at host instants (LOCKED, HOLDOVER), else 0. */
int vmac_clock_usable(const struct vmac_clock *c);

/* Host time at local counter local_ns, into *host_ns: 0, or -1 (and
 * *host_ns untouched) when unsynced or lost. */
int vmac_clock_to_host(const struct vmac_clock *c, uint64_t local_ns, uint64_t *host_ns);

/* The local counter at host time host_ns, into *local_ns (a timer compare
 * for "act at host instant T"): 0, or -1 when unsynced or lost. The line
 * now in force, extrapolated; an instant before the counter's start gives
 * 0 (long past), never a wrapped far future. */
int vmac_clock_to_local(const struct vmac_clock *c, uint64_t host_ns, uint64_t *local_ns);

/* The estimated bound on |to_host(local_ns) - host time| at local_ns
 * (ns): the offsets' mean and spread at the last update (or the last
 * offset, or a spike, when further out), the filter's bias (the mean above
 * the offsets' floor), then the frequency's uncertainty and the assumed
 * wander times the time since. UINT64_MAX when unsynced or lost. */
uint64_t vmac_clock_bound_ns(const struct vmac_clock *c, uint64_t local_ns);

/* When to act on what a frame asks for at host instant host_ns, the frame
 * having arrived at arrival_local_ns. Usable clock: into *local_ns the local
 * time of host_ns (a timer compare), or arrival_local_ns if that is past,
 * returning 1. Otherwise arrival_local_ns itself (act on arrival: the
 * fallback), returning 0: the caller says so. */
int vmac_clock_act_at(const struct vmac_clock *c, uint64_t host_ns, uint64_t arrival_local_ns, uint64_t *local_ns);

/* The learnt frequency (the servo's integral), ppb: how fast the local
 * counter runs against the host's, negated (a counter 100 ppm fast learns
 * -99,990 ppb: the host's ns per local ns, - 1). */
int32_t vmac_clock_freq_ppb(const struct vmac_clock *c);

const char *vmac_clock_state_name(enum vmac_clock_state s);

#endif
