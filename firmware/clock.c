/* The board's disciplined clock: see clock.h, and docs/TIME.md for the
 * design. Everything in 64-bit integers: times in ns, frequencies Q32
 * (2^-32 ns per ns), products through scale_q32() so that no intermediate
 * overflows for any time difference below 2^63 ns. */
#include "clock.h"

#include <string.h>

#define ONE_Q32 ((int64_t)1 << 32)
#define MAX_Q32 ((int64_t)VMAC_CLOCK_MAX_PPM * ONE_Q32 / 1000000)
#define FREQ_FLOOR_Q32 ((int64_t)VMAC_CLOCK_FREQ_FLOOR_PPB * ONE_Q32 / 1000000000)
#define MIN_INTERVAL_NS 1000000 /* a window shorter than 1 ms is taken as 1 ms in the servo */
#define EWMA 8                  /* every running mean weighs its newest value 1/8 */
#define FAR_NS (UINT64_MAX / 4) /* a bound past any limit, safe to add to */
#define DEV_START_DIV 4         /* the servo starts with a spread of a quarter of the jitter, not 0 */
#define DIFF_MAX_NS ((int64_t)1 << 62)
/* A sample's lateness as the jitter and the window's mean see it: at most
 * +-2^30 ns (1.07 s), so that 16 of them sum and the jitter times 2^32
 * stay in 64 bits. Far beyond the 1 ms of a step: such a sample starts
 * over anyway, by its own (unclamped) times. */
#define LATE_CLAMP_NS ((int64_t)1 << 30)

static uint64_t magnitude(int64_t v)
{
	return v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
}

/* a - b, signed, saturated at +-2^62 (any two times of one run are far
 * closer; a host time from a forged or broken frame may not be), so that a
 * sum or difference of two never overflows. */
static int64_t diff_ns(uint64_t a, uint64_t b)
{
	uint64_t d = a >= b ? a - b : b - a;
	int64_t m = d > (uint64_t)DIFF_MAX_NS ? DIFF_MAX_NS : (int64_t)d;
	return a >= b ? m : -m;
}

/* (dt x f) / 2^32, rounded toward zero, for |f| < 2^31. */
static int64_t scale_q32(int64_t dt, int64_t f)
{
	uint64_t a = magnitude(dt), b = magnitude(f);
	uint64_t r = (a >> 32) * b + (((a & 0xFFFFFFFFu) * b) >> 32);
	return (dt < 0) != (f < 0) ? -(int64_t)r : (int64_t)r;
}

/* now - since, or 0 when now is the earlier (a caller's times out of order). */
static uint64_t elapsed(uint64_t now, uint64_t since)
{
	return now > since ? now - since : 0;
}

static int64_t clamp_late(int64_t lateness)
{
	return lateness > LATE_CLAMP_NS ? LATE_CLAMP_NS : lateness < -LATE_CLAMP_NS ? -LATE_CLAMP_NS : lateness;
}

static int64_t clamp_freq(int64_t f)
{
	return f > MAX_Q32 ? MAX_Q32 : f < -MAX_Q32 ? -MAX_Q32 : f;
}

static uint64_t add_sat(uint64_t a, uint64_t b)
{
	return a > FAR_NS - (b > FAR_NS ? FAR_NS : b) ? FAR_NS : a + b;
}

static void ewma(int64_t *mean, int64_t value)
{
	*mean += (value - *mean) / EWMA;
}

static uint64_t model_host(const struct vmac_clock *c, uint64_t local_ns)
{
	int64_t dl = diff_ns(local_ns, c->local_ref);
	int64_t slewed = dl < c->slew_len_ns ? dl : c->slew_len_ns;
	return c->host_ref + (uint64_t)(dl + scale_q32(dl, c->drift_q32) + scale_q32(slewed, c->slew_q32));
}

/* dl such that dl + dl x f = dh: three rounds of dl = dh - dl x f, each
 * dividing the error by 1/|f| >= 1000. */
static int64_t invert(int64_t dh, int64_t f)
{
	int64_t dl = dh;
	int i;
	for (i = 0; i < 3; i++)
		dl = dh - scale_q32(dl, f);
	return dl;
}

/* Rebase the line at local_ns, where it now reads host_ns (a step when
 * host_ns is not what the line said). */
static void rebase(struct vmac_clock *c, uint64_t local_ns, uint64_t host_ns)
{
	c->local_ref = local_ns;
	c->host_ref = host_ns;
}

static void window_reset(struct vmac_clock *c)
{
	c->window_n = 0;
	c->window_sum_ns = 0;
}

void vmac_clock_init(struct vmac_clock *c)
{
	memset(c, 0, sizeof(*c));
	c->state = VMAC_CLOCK_UNSYNCED;
}

/* Acquisition from this sample on: the line through it, at the frequency
 * learnt before if any (linuxptp's servo keeps its drift across a reset). */
static void start(struct vmac_clock *c, uint64_t host_ns, uint64_t local_ns)
{
	c->state = VMAC_CLOCK_LOCKING;
	c->counters.starts++;
	rebase(c, local_ns, host_ns);
	c->slew_q32 = c->slew_len_ns = 0;
	c->servo = 0;
	c->has_anchor = 0;
	c->offset_mean_ns = c->offset_dev_ns = c->last_offset_ns = 0;
	c->good_windows = c->spike_run = 0;
	c->past_n = 0;
	c->last_update_local = c->last_accept_local = local_ns;
	c->reject_run = 0;
	c->doubted = 0;
	window_reset(c);
}

static void lose(struct vmac_clock *c)
{
	c->state = VMAC_CLOCK_LOST;
	c->doubted = 0;
	c->counters.lost++;
	c->reject_run = 0;
	window_reset(c);
}

/* What the error may have grown by since the last update (servo running):
 * the frequency's uncertainty, then the wander assumed. */
static uint64_t growth_ns(const struct vmac_clock *c, uint64_t since)
{
	uint64_t since_ms = since / 1000000u;
	int64_t freq_unc = c->freq_dev_q32 > FREQ_FLOOR_Q32 ? c->freq_dev_q32 : FREQ_FLOOR_Q32;
	if (since_ms > 1000000u) /* beyond 1000 s nothing is known */
		return FAR_NS;
	return add_sat((uint64_t)scale_q32((int64_t)since, freq_unc),
	               (uint64_t)VMAC_CLOCK_WANDER_PPB_PER_S * since_ms * since_ms / 2000000u);
}

/* The bound right after an update, then growing with the time since:
 * docs/TIME.md, "The error bound". The line's error is what the servo's
 * offsets say on average, within their spread (not each window's, which
 * the servo takes only 1/16 of); a last offset further out than two
 * spreads, or an early spike (or a second late one in a row), is more than
 * noise and counts as it is; then how far the line sits above the lowest
 * offsets seen (the filter's bias: the least path is the truest). */
static uint64_t bound_at(const struct vmac_clock *c, uint64_t local_ns)
{
	uint64_t since = elapsed(local_ns, c->last_update_local);
	uint64_t dev = magnitude(c->offset_dev_ns), last = magnitude(c->last_offset_ns);
	uint64_t phase = magnitude(c->offset_mean_ns) + dev;
	int64_t depth = c->offset_mean_ns - c->floor_ns;
	if (!c->servo) /* acquisition: the phase within a window's jitter, the frequency anything allowed */
		return add_sat(magnitude(c->jitter_ns),
		               (uint64_t)scale_q32((int64_t)(since > FAR_NS ? FAR_NS : since), MAX_Q32));
	if (last > phase + dev)
		phase = last - dev;
	if ((c->spike_ns < 0 ? c->spike_run > 0 : c->spike_run > 1) && magnitude(c->spike_ns) > phase)
		phase = magnitude(c->spike_ns); /* not steered by, but not blind to, a spike */
	phase += VMAC_CLOCK_BOUND_FLOOR_NS + (depth > 0 ? (uint64_t)depth : 0);
	return add_sat(phase, growth_ns(c, since));
}

/* A window whose offset strays from the mean by more than the spread and
 * the bound's growth allow: most likely every frame of it queued (NTP's
 * popcorn spikes), skipped unless VMAC_CLOCK_SPIKE_RUN come in a row. */
static int spike(struct vmac_clock *c, uint64_t now_local)
{
	uint64_t gate = add_sat(VMAC_CLOCK_SPIKE_K * magnitude(c->offset_dev_ns) + VMAC_CLOCK_SPIKE_FLOOR_NS,
	                        growth_ns(c, elapsed(now_local, c->last_update_local)));
	if (magnitude(c->window_min_ns - c->offset_mean_ns) <= gate || c->spike_run >= VMAC_CLOCK_SPIKE_RUN) {
		c->spike_run = 0;
		return 0;
	}
	c->spike_run++;
	c->spike_ns = c->window_min_ns;
	c->counters.spikes++;
	return 1;
}

/* Acquisition, at a window's close: step to its minimum; once two minima
 * lie VMAC_CLOCK_FREQ_EST_NS apart, the frequency between them (linuxptp's
 * first estimate) and the servo from there. */
static void acquire(struct vmac_clock *c)
{
	int64_t dl, dh;
	if (c->has_anchor && elapsed(c->window_min_local, c->anchor_local) >= VMAC_CLOCK_FREQ_EST_NS) {
		dl = diff_ns(c->window_min_local, c->anchor_local);
		dh = diff_ns(c->window_min_host, c->anchor_host);
		if (dl < ((int64_t)1 << 31) && magnitude(dh - dl) < ((uint64_t)1 << 31)) {
			c->drift_q32 = clamp_freq((dh - dl) * ONE_Q32 / dl);
			c->servo = 1;
			c->freq_mean_q32 = c->drift_q32;
			/* its uncertainty: two minima, each within about jitter / WINDOW */
			c->freq_dev_q32 = 2 * (c->jitter_ns / VMAC_CLOCK_WINDOW) * ONE_Q32 / dl;
			c->offset_dev_ns = c->jitter_ns / DEV_START_DIV; /* the spread not yet seen: the jitter's */
			c->floor_ns = 0;
			rebase(c, c->window_min_local, c->window_min_host);
			return;
		}
		c->has_anchor = 0; /* too far apart to divide safely: begin again here */
	}
	if (!c->has_anchor) {
		c->has_anchor = 1;
		c->anchor_local = c->window_min_local;
		c->anchor_host = c->window_min_host;
	}
	rebase(c, c->window_min_local, c->window_min_host);
}

/* The window's offset for the servo: the least of its own minimum's
 * (offset, at now_local) and the last VMAC_CLOCK_PAST_WINDOWS windows'
 * minima as the line now in force sees them, each counted
 * VMAC_CLOCK_PAST_PPM later per ms of its age, so that a drift's trend is
 * not hidden behind an old minimum (NTP's clock filter ages its samples
 * the same way). A window whose every frame queued moves it not at all.
 * Within +-VMAC_CLOCK_STEP_NS when offset is. */
static int64_t past_least(const struct vmac_clock *c, int64_t offset, uint64_t now_local)
{
	uint32_t i;
	for (i = 0; i < c->past_n; i++) {
		int64_t late = diff_ns(model_host(c, c->past_local[i]), c->past_host[i]) +
		               (int64_t)(elapsed(now_local, c->past_local[i]) / 1000000u * VMAC_CLOCK_PAST_PPM);
		if (late < offset && late >= -(int64_t)VMAC_CLOCK_STEP_NS) /* the servo's offsets stay within a step */
			offset = late;
	}
	return offset;
}

/* The window's minimum joins the past ones, the oldest out. */
static void past_push(struct vmac_clock *c)
{
	c->past_local[c->past_next] = c->window_min_local;
	c->past_host[c->past_next] = c->window_min_host;
	c->past_next = (c->past_next + 1) % VMAC_CLOCK_PAST_WINDOWS;
	if (c->past_n < VMAC_CLOCK_PAST_WINDOWS)
		c->past_n++;
}

/* The PI servo, at a window's close: the window's offset (past_least())
 * into the frequency, the line rebased at now so that the
 * correction is a slew, never a step. */
static void servo(struct vmac_clock *c, int64_t offset, uint64_t now_local)
{
	int64_t interval = diff_ns(now_local, c->last_update_local);
	int64_t p_interval;
	uint64_t host_now = model_host(c, now_local);
	past_push(c);
	if (interval < MIN_INTERVAL_NS)
		interval = MIN_INTERVAL_NS;
	p_interval = interval > (int64_t)VMAC_CLOCK_WINDOW_MAX_NS ? (int64_t)VMAC_CLOCK_WINDOW_MAX_NS : interval;
	/* offset / interval in Q32: |offset| <= VMAC_CLOCK_STEP_NS, so no overflow */
	c->drift_q32 = clamp_freq(c->drift_q32 - offset * ONE_Q32 / interval / (1 << VMAC_CLOCK_KI_SHIFT));
	c->slew_q32 =
	    clamp_freq(c->drift_q32 - offset * ONE_Q32 / p_interval / (1 << VMAC_CLOCK_KP_SHIFT)) - c->drift_q32;
	c->slew_len_ns = p_interval;
	rebase(c, now_local, host_now);
	ewma(&c->offset_dev_ns, (int64_t)magnitude(offset - c->offset_mean_ns));
	ewma(&c->offset_mean_ns, offset);
	c->floor_ns += (c->offset_mean_ns - c->floor_ns) / VMAC_CLOCK_FLOOR_AVG;
	if (offset < c->floor_ns)
		c->floor_ns = offset;
	c->freq_mean_q32 += (c->drift_q32 - c->freq_mean_q32) / VMAC_CLOCK_FREQ_AVG;
	ewma(&c->freq_dev_q32, (int64_t)magnitude(c->drift_q32 - c->freq_mean_q32));
	c->last_offset_ns = offset;
}

/* A window is full (or old): the jitter it showed, then acquisition or the
 * servo, then the state by the bound. */
static void close_window(struct vmac_clock *c, uint64_t now_local)
{
	uint64_t bound;
	c->counters.windows++;
	ewma(&c->jitter_ns, c->window_sum_ns / (int64_t)c->window_n - clamp_late(c->window_min_ns));
	if (c->servo && spike(c, now_local)) {
		window_reset(c);
		return;
	}
	if (c->servo && magnitude(c->window_min_ns) > VMAC_CLOCK_STEP_NS) {
		start(c, c->window_min_host, c->window_min_local);
		return;
	}
	if (c->servo)
		servo(c, past_least(c, c->window_min_ns, c->window_min_local), now_local);
	else
		acquire(c);
	c->last_update_local = now_local;
	window_reset(c);
	bound = bound_at(c, now_local);
	if (c->state == VMAC_CLOCK_LOCKING) {
		c->good_windows = c->servo && bound <= VMAC_CLOCK_LOCK_NS ? c->good_windows + 1 : 0;
		if (c->good_windows >= VMAC_CLOCK_LOCK_WINDOWS)
			c->state = VMAC_CLOCK_LOCKED;
	} else {
		c->state = bound <= VMAC_CLOCK_UNLOCK_NS ? VMAC_CLOCK_LOCKED : VMAC_CLOCK_LOCKING;
		c->good_windows = 0;
	}
}

enum vmac_clock_state vmac_clock_tick(struct vmac_clock *c, uint64_t local_ns)
{
	if (c->state == VMAC_CLOCK_UNSYNCED || c->state == VMAC_CLOCK_LOST)
		return c->state;
	if (c->reject_run && elapsed(local_ns, c->reject_since_local) >= VMAC_CLOCK_REJECT_LOST_NS) {
		lose(c);
		return c->state;
	}
	if (elapsed(local_ns, c->last_accept_local) < VMAC_CLOCK_HOLDOVER_NS)
		return c->state;
	if (c->state == VMAC_CLOCK_LOCKED && c->window_n > 0)
		close_window(c, c->last_accept_local); /* what the last samples said, before holding over */
	if (c->state == VMAC_CLOCK_LOCKED) {
		c->state = VMAC_CLOCK_HOLDOVER;
		rebase(c, local_ns, model_host(c, local_ns)); /* continuous: on from here at the mean frequency */
		c->drift_q32 = c->freq_mean_q32;
		c->slew_q32 = c->slew_len_ns = 0;
		c->past_n = 0; /* minima from before the gap: not compared across it */
	}
	if (bound_at(c, local_ns) > VMAC_CLOCK_LOST_NS)
		lose(c);
	return c->state;
}

static int64_t gate_ns(const struct vmac_clock *c)
{
	return VMAC_CLOCK_GATE_K * c->jitter_ns + VMAC_CLOCK_GATE_FLOOR_NS;
}

static int gate_rejects(const struct vmac_clock *c, int64_t lateness)
{
	return (vmac_clock_usable(c) || c->doubted) && lateness - c->offset_mean_ns > gate_ns(c);
}

void vmac_clock_doubt(struct vmac_clock *c)
{
	if (!vmac_clock_usable(c))
		return;
	c->resume = c->state;
	c->doubted = 1;
	c->state = VMAC_CLOCK_LOCKING;
	c->good_windows = 0; /* only the doubt's settling makes it usable again */
}

/* The first sample after vmac_clock_doubt() (vmac_clock_doubt() says
 * what each verdict does); the sample's lateness to go on with. */
static int64_t settle_doubt(struct vmac_clock *c, int64_t lateness, uint64_t host_ns, uint64_t local_ns)
{
	int64_t d = lateness - c->offset_mean_ns;
	uint64_t early = bound_at(c, local_ns) + (uint64_t)gate_ns(c);
	if (d > (int64_t)VMAC_CLOCK_STEP_NS || (d < 0 && magnitude(d) > early)) {
		start(c, host_ns, local_ns); /* another time base: the line through this sample */
		return diff_ns(model_host(c, local_ns), host_ns);
	}
	if (d <= gate_ns(c)) {
		c->state = c->resume;
		c->doubted = 0;
	}
	return lateness;
}

int vmac_clock_feed(struct vmac_clock *c, uint64_t host_ns, uint64_t local_ns)
{
	int64_t lateness;
	vmac_clock_tick(c, local_ns);
	if (c->state == VMAC_CLOCK_UNSYNCED || c->state == VMAC_CLOCK_LOST)
		start(c, host_ns, local_ns);
	else if (c->window_n > 0 && elapsed(local_ns, c->window_start_local) >= VMAC_CLOCK_WINDOW_MAX_NS)
		close_window(c, c->last_accept_local); /* a window never spans a gap: it ends with its last sample */
	lateness = diff_ns(model_host(c, local_ns), host_ns);
	if (c->doubted)
		lateness = settle_doubt(c, lateness, host_ns, local_ns);
	if (gate_rejects(c, lateness)) {
		c->counters.rejected++;
		if (c->reject_run++ == 0)
			c->reject_since_local = local_ns;
		return VMAC_CLOCK_REJECTED;
	}
	c->counters.accepted++;
	c->reject_run = 0;
	c->last_accept_local = local_ns;
	if (c->window_n == 0 || lateness < c->window_min_ns) {
		if (c->window_n == 0)
			c->window_start_local = local_ns;
		c->window_min_ns = lateness;
		c->window_min_local = local_ns;
		c->window_min_host = host_ns;
	}
	c->window_n++;
	c->window_sum_ns += clamp_late(lateness);
	if (c->window_n >= VMAC_CLOCK_WINDOW)
		close_window(c, local_ns);
	return VMAC_CLOCK_ACCEPTED;
}

int vmac_clock_usable(const struct vmac_clock *c)
{
	return c->state == VMAC_CLOCK_LOCKED || c->state == VMAC_CLOCK_HOLDOVER;
}

static int has_line(const struct vmac_clock *c)
{
	return c->state != VMAC_CLOCK_UNSYNCED && c->state != VMAC_CLOCK_LOST;
}

int vmac_clock_to_host(const struct vmac_clock *c, uint64_t local_ns, uint64_t *host_ns)
{
	if (!has_line(c))
		return -1;
	*host_ns = model_host(c, local_ns);
	return 0;
}

/* The inverse of the two pieces: before the slew's end, or after it. */
int vmac_clock_to_local(const struct vmac_clock *c, uint64_t host_ns, uint64_t *local_ns)
{
	int64_t dh, knee, dl;
	if (!has_line(c))
		return -1;
	dh = diff_ns(host_ns, c->host_ref);
	knee = diff_ns(model_host(c, c->local_ref + (uint64_t)c->slew_len_ns), c->host_ref);
	if (dh <= knee)
		dl = invert(dh, c->drift_q32 + c->slew_q32);
	else
		dl = c->slew_len_ns + invert(dh - knee, c->drift_q32);
	if (dl < 0 && (uint64_t)0 - (uint64_t)dl > c->local_ref)
		*local_ns = 0; /* before the counter's start: long past, not its far future */
	else if (dl > 0 && (uint64_t)dl > UINT64_MAX - c->local_ref)
		*local_ns = UINT64_MAX;
	else
		*local_ns = c->local_ref + (uint64_t)dl;
	return 0;
}

uint64_t vmac_clock_bound_ns(const struct vmac_clock *c, uint64_t local_ns)
{
	if (!has_line(c))
		return UINT64_MAX;
	return bound_at(c, local_ns);
}

int vmac_clock_act_at(const struct vmac_clock *c, uint64_t host_ns, uint64_t arrival_local_ns, uint64_t *local_ns)
{
	uint64_t when;
	if (!vmac_clock_usable(c) || vmac_clock_to_local(c, host_ns, &when) != 0) {
		*local_ns = arrival_local_ns;
		return 0;
	}
	*local_ns = when > arrival_local_ns ? when : arrival_local_ns;
	return 1;
}

int32_t vmac_clock_freq_ppb(const struct vmac_clock *c)
{
	return (int32_t)(c->drift_q32 * 1000000000 / ONE_Q32);
}

const char *vmac_clock_state_name(enum vmac_clock_state s)
{
	switch (s) {
	case VMAC_CLOCK_UNSYNCED: return "unsynced";
	case VMAC_CLOCK_LOCKING: return "locking";
	case VMAC_CLOCK_LOCKED: return "locked";
	case VMAC_CLOCK_HOLDOVER: return "holdover";
	case VMAC_CLOCK_LOST: return "lost";
	}
	return "?";
}
