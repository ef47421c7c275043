/* The flight recorder's rings: see recorder.h. */
#include "recorder.h"

#include <stdlib.h>
#include <string.h>

#define MIN_TICKS 64
#define MAX_TICKS (1u << 22) /* 4 Mi ticks (about 160 MiB): a bound on any setting */

struct vmac_recorder *vmac_recorder_new(double seconds, double period_s)
{
	struct vmac_recorder *r;
	double want = period_s > 0 ? seconds / period_s : 0;
	uint32_t cap = want >= MAX_TICKS ? MAX_TICKS : want < MIN_TICKS ? MIN_TICKS : (uint32_t)want;
	if (!(seconds > 0))
		return NULL;
	r = calloc(1, sizeof(*r));
	if (!r)
		return NULL;
	r->ticks = calloc(cap, sizeof(*r->ticks));
	if (!r->ticks) {
		free(r);
		return NULL;
	}
	r->ticks_cap = cap;
	r->attach_ns = -1;
	return r;
}

void vmac_recorder_free(struct vmac_recorder *r)
{
	if (!r)
		return;
	free(r->ticks);
	free(r);
}

void vmac_rec_tick(struct vmac_recorder *r, int64_t t_ns, int board, int last, const struct vmac_inputs *in,
                   const struct vmac_outputs *out)
{
	struct vmac_rec_tick *t = &r->ticks[r->ticks_next];
	if (++r->ticks_next == r->ticks_cap)
		r->ticks_next = 0;
	t->t_ns = t_ns;
	t->board = (uint8_t)board;
	t->last = (uint8_t)last;
	t->in = *in;
	t->out = *out;
	r->ticks_written++;
}

struct vmac_rec_event *vmac_rec_event(struct vmac_recorder *r, int64_t t_ns, enum vmac_rec_kind kind)
{
	struct vmac_rec_event *e = &r->events[r->events_written % VMAC_REC_EVENTS];
	memset(e, 0, sizeof(*e));
	e->t_ns = t_ns;
	e->kind = (uint8_t)kind;
	r->events_written++;
	return e;
}

uint32_t vmac_rec_nticks(const struct vmac_recorder *r)
{
	return r->ticks_written < r->ticks_cap ? (uint32_t)r->ticks_written : r->ticks_cap;
}

const struct vmac_rec_tick *vmac_rec_tick_at(const struct vmac_recorder *r, uint32_t i)
{
	uint64_t first = r->ticks_written - vmac_rec_nticks(r);
	return &r->ticks[(first + i) % r->ticks_cap];
}

uint32_t vmac_rec_nevents(const struct vmac_recorder *r)
{
	return r->events_written < VMAC_REC_EVENTS ? (uint32_t)r->events_written : VMAC_REC_EVENTS;
}

const struct vmac_rec_event *vmac_rec_event_at(const struct vmac_recorder *r, uint32_t i)
{
	uint64_t first = r->events_written - vmac_rec_nevents(r);
	return &r->events[(first + i) % VMAC_REC_EVENTS];
}
