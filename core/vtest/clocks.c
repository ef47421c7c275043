/* The board clocks of `vmac test`: see clocks.h. */
#include "clocks.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../firmware/posix/oscillator.h"
#include "world.h"

static int board_index(const struct vt_world *w, const struct vt_board *b)
{
	int i;
	for (i = 0; i < w->nboards && w->boards[i] != b; i++)
		;
	return i;
}

static int in_range(double v, double lo, double hi)
{
	return v >= lo && v <= hi; /* false for NaN */
}

int vt_clock_set(struct vt_world *w, struct vt_board *b, const struct vt_clock_spec *spec, char *err, size_t errlen)
{
	struct oscillator_config oc;
	struct oscillator *o;
	if (!in_range(spec->ppm, -VT_CLOCK_MAX_PPM, VT_CLOCK_MAX_PPM)) {
		snprintf(err, errlen, "ppm must be in -%g..%g, got %g", VT_CLOCK_MAX_PPM, VT_CLOCK_MAX_PPM, spec->ppm);
		return -1;
	}
	if (!in_range(spec->offset_s, -VT_CLOCK_MAX_OFFSET_S, VT_CLOCK_MAX_OFFSET_S)) {
		snprintf(err, errlen, "offset must be seconds in -%g..%g, got %g", VT_CLOCK_MAX_OFFSET_S,
		         VT_CLOCK_MAX_OFFSET_S, spec->offset_s);
		return -1;
	}
	if (!in_range(spec->jitter_s, 0, 0.01)) {
		snprintf(err, errlen, "jitter must be seconds in 0..0.01 (20e-6: 20 us), got %g", spec->jitter_s);
		return -1;
	}
	if (!in_range(spec->wander, 0, 10)) {
		snprintf(err, errlen, "wander must be ppm/sqrt(s) in 0..10, got %g", spec->wander);
		return -1;
	}
	o = b->clock.osc ? b->clock.osc : malloc(sizeof(*o));
	if (!o) {
		snprintf(err, errlen, "out of memory for a board clock");
		return -1;
	}
	memset(&oc, 0, sizeof(oc));
	oc.offset_s = (double)VT_CLOCK_BASE_NS / 1e9 + spec->offset_s;
	oc.drift_ppm = spec->ppm;
	oc.wander_ppm = spec->wander;
	oc.step_at_s = -1;
	oc.jitter_us = spec->jitter_s * 1e6;
	/* The run's seed and the board's place in the scene: boards differ,
	 * runs under one seed do not. */
	oc.seed = w->seed * 0x9E3779B97F4A7C15ULL + 0xC10CULL + (uint64_t)board_index(w, b);
	oscillator_init(o, &oc);
	b->clock.osc = o;
	return 0;
}

void vt_clock_free(struct vt_board *b)
{
	free(b->clock.osc);
	b->clock.osc = NULL;
}

uint64_t vt_clock_local_ns(struct vt_world *w, struct vt_board *b, int rx)
{
	uint64_t t = (uint64_t)w->now_ns;
	if (!b->clock.osc)
		return t + (uint64_t)VT_CLOCK_BASE_NS;
	if (rx)
		t += oscillator_rx_delay_ns(b->clock.osc);
	return oscillator_local_ns(b->clock.osc, t);
}

int64_t vt_clock_world_ns(struct vt_board *b, uint64_t local_ns)
{
	if (!b->clock.osc)
		return (int64_t)local_ns - VT_CLOCK_BASE_NS;
	return (int64_t)oscillator_true_ns(b->clock.osc, local_ns);
}

void vt_clock_poll(struct vt_world *w)
{
	int i;
	for (i = 0; i < w->nboards; i++) {
		struct vt_board *b = w->boards[i];
		if (b->powered && b->fw.clock.state != VMAC_CLOCK_UNSYNCED)
			vmac_board_clock_poll(&b->fw, vt_clock_local_ns(w, b, 0));
	}
}

int vt_clock_step(struct vt_world *w, struct vt_board *b, double ppm, char *err, size_t errlen)
{
	struct oscillator *o;
	double now_ppm;
	if (!b->clock.osc) { /* the perfect counter, as a model: the same readings from here on */
		struct vt_clock_spec perfect;
		memset(&perfect, 0, sizeof(perfect));
		if (vt_clock_set(w, b, &perfect, err, errlen) != 0)
			return -1;
	}
	o = b->clock.osc;
	now_ppm = oscillator_drift_ppm(o, (uint64_t)w->now_ns); /* walks the model up to now */
	if (!in_range(now_ppm + ppm, -VT_CLOCK_MAX_PPM, VT_CLOCK_MAX_PPM)) {
		snprintf(err, errlen, "a step of %g ppm takes the drift from %g to %g ppm, beyond +-%g", ppm, now_ppm,
		         now_ppm + ppm, VT_CLOCK_MAX_PPM);
		return -1;
	}
	if (!o->step_done && o->cfg.step_at_s >= 0) {
		o->cfg.step_ppm += ppm; /* one not yet in the knots: they add up */
		return 0;
	}
	/* From the model's next knot on (1 ms grid): just before it, so that
	 * the comparison in the model cannot round it a knot later. */
	o->cfg.step_at_s = ((double)(o->newest + 1) * OSCILLATOR_STEP_NS - 1000.0) / 1e9;
	o->cfg.step_ppm = ppm;
	o->step_done = 0;
	return 0;
}

void vt_clock_view(struct vt_world *w, struct vt_board *b, struct vt_clock_view *v)
{
	const struct vmac_clock *c = &b->fw.clock;
	uint64_t local = vt_clock_local_ns(w, b, 0), host, bound;
	int64_t offset;
	memset(v, 0, sizeof(*v));
	v->state = vmac_clock_state_name(c->state);
	v->drift_ppm = -(double)vmac_clock_freq_ppb(c) / 1000.0;
	v->true_ppm = b->clock.osc ? oscillator_drift_ppm(b->clock.osc, (uint64_t)w->now_ns) : 0;
	v->syncs = c->counters.accepted + c->counters.rejected;
	if (vmac_board_clock_offset(&b->fw, local, &offset, &bound) != 0 || vmac_clock_to_host(c, local, &host) != 0)
		return;
	v->has_line = 1;
	v->offset_s = (double)(offset - VT_CLOCK_BASE_NS) / 1e9;
	v->bound_s = (double)bound / 1e9;
	/* A one-way clock cannot see the path's least delay (docs/TIME.md):
	 * here the wire's, which every frame takes. */
	v->error_s = (double)((int64_t)host - (w->now_ns - VT_WIRE_NS)) / 1e9;
}
