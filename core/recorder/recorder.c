/* The flight recorder's rings: see recorder.h. */
#include "recorder.h"

#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#define MIN_TICKS 64
#define MAX_TICKS (1u << 22) /* 4 Mi ticks (about 160 MiB): a bound on any setting */

/* Zeroed memory aligned to a cache line; NULL when out of memory. */
static void *zalloc_line(size_t size)
{
	void *p;
	size = (size + 63) & ~(size_t)63;
	if (!(p = aligned_alloc(64, size)))
		return NULL;
	return memset(p, 0, size);
}

struct vmac_recorder *vmac_recorder_new(double seconds, double period_s)
{
	struct vmac_recorder *r;
	double want = period_s > 0 ? seconds / period_s : 0;
	uint32_t cap = want >= MAX_TICKS ? MAX_TICKS : want < MIN_TICKS ? MIN_TICKS : (uint32_t)want;
	if (!(seconds > 0))
		return NULL;
	cap = (cap + VMAC_REC_STAGE - 1) / VMAC_REC_STAGE * VMAC_REC_STAGE; /* whole stages */
	r = zalloc_line(sizeof(*r));
	if (!r)
		return NULL;
	r->ticks = zalloc_line((size_t)cap * sizeof(*r->ticks));
	if (!r->ticks) {
		free(r);
		return NULL;
	}
	r->ticks_cap = cap;
	r->attach_ns = -1;
	r->span_ns = (int64_t)((double)cap * period_s * 1e9);
	for (int i = 0; i < VMAC_REC_STATES; i++)
		if (!(r->states[i].data = malloc(VMAC_REC_STATE_MAX))) {
			vmac_recorder_free(r);
			return NULL;
		}
	return r;
}

void vmac_recorder_free(struct vmac_recorder *r)
{
	if (!r)
		return;
	for (int i = 0; i < VMAC_REC_STATES; i++)
		free(r->states[i].data);
	free(r->ticks);
	free(r);
}

/* Two records to a cache line; the ring is 64-byte aligned and holds whole
 * stages. */
_Static_assert(sizeof(struct vmac_rec_tick) == 32, "a tick record is 32 bytes");
_Static_assert(offsetof(struct vmac_rec_tick, at) == 24 && offsetof(struct vmac_rec_tick, out_digital) == 30,
               "a tick record's latch instant and outputs fill the bytes after its inputs");

/* A record goes to the stage, in the recorder, which the bus thread touches
 * every tick anyway; every VMAC_REC_STAGE records the stage goes to the ring
 * in whole cache lines with non-temporal stores. Written one at a time, each
 * record cost the bus thread a cache miss and, on a VM, a page walk: the
 * ring's line was last written recorder_s ago, and every machine's ring is
 * on its own pages (docs/PERFORMANCE.md, "The flight recorder"). */
void vmac_rec_tick(struct vmac_recorder *r, int64_t t_ns, int board, int last, const struct vmac_inputs *in,
                   const struct vmac_outputs *out, int64_t at_ns)
{
	uint32_t slot = r->ticks_next, k = slot % VMAC_REC_STAGE;
	struct vmac_rec_tick *t = &r->stage[k];
	if (++r->ticks_next == r->ticks_cap)
		r->ticks_next = 0;
	t->t_ns = t_ns; /* every byte of the record written: no clearing first */
	t->in = *in;
	t->at = vmac_rec_at_encode(at_ns, t_ns);
	t->out_pwm = out->pwm;
	t->out_digital = out->digital;
	t->board = (uint8_t)board & 0x7f;
	t->last = last != 0;
	r->ticks_written++;
	if (k == VMAC_REC_STAGE - 1) {
		struct vmac_rec_tick *dst = &r->ticks[slot - k];
#if defined(__SSE2__)
		const __m128i *from = (const __m128i *)(const void *)r->stage;
		__m128i *to = (__m128i *)(void *)dst;
		size_t i;
		for (i = 0; i < VMAC_REC_STAGE * sizeof(struct vmac_rec_tick) / 16; i++)
			_mm_stream_si128(to + i, _mm_load_si128(from + i));
#else
		memcpy(dst, r->stage, sizeof(r->stage));
#endif
	}
}

void vmac_rec_state(struct vmac_recorder *r, int64_t t_ns, const uint8_t *data, size_t len)
{
	const struct vmac_rec_state *newest = &r->states[(r->states_next + VMAC_REC_STATES - 1) % VMAC_REC_STATES];
	struct vmac_rec_state *s = &r->states[r->states_next];
	if (len == 0 || len > VMAC_REC_STATE_MAX ||
	    (!r->state_wanted && newest->len && t_ns - newest->t_ns < r->span_ns / 2))
		return;
	r->state_wanted = 0;
	memcpy(s->data, data, len);
	s->len = (uint32_t)len;
	s->t_ns = t_ns;
	s->at = r->ticks_written;
	r->states_next = (r->states_next + 1) % VMAC_REC_STATES;
}

const struct vmac_rec_state *vmac_rec_state_base(const struct vmac_recorder *r)
{
	uint64_t first = r->ticks_written - vmac_rec_nticks(r);
	const struct vmac_rec_state *best = NULL;
	int i;
	for (i = 0; i < VMAC_REC_STATES; i++) {
		const struct vmac_rec_state *s = &r->states[i];
		if (s->len && s->at >= first && s->at < r->ticks_written && (!best || s->at < best->at))
			best = s;
	}
	return best;
}

void vmac_rec_seal(struct vmac_recorder *r)
{
	(void)r;
#if defined(__SSE2__)
	_mm_sfence(); /* the non-temporal stores visible before the recorder is handed over */
#endif
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
	uint64_t n = r->ticks_written - vmac_rec_nticks(r) + i;
	if (n >= r->ticks_written - r->ticks_written % VMAC_REC_STAGE)
		return &r->stage[n % VMAC_REC_STAGE]; /* not in the ring yet */
	return &r->ticks[n % r->ticks_cap];
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
