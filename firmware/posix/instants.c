/* vmac-board's time-triggered I/O (docs/TIME.md, "Time-triggered I/O"):
 * when the loop must wake for the earliest instant any board waits for
 * (each board's counter mapped to CLOCK_MONOTONIC through its oscillator,
 * as its timer compare would fire), doing what is due and sending the
 * TIMED replies, and --io-log: one line per output change and latch with
 * the true instant it was done at, so a test judges instants by the
 * boards' own log. */
#include <inttypes.h>
#include <stdio.h>
#include <string.h>

#include "boards.h"

#define AHEAD_MAX_NS 1000000000LL /* an instant further ahead: wake then and look again */

static const char *how_name(enum vmac_timed_how how)
{
	switch (how) {
	case VMAC_TIMED_AT_INSTANT: return "instant";
	case VMAC_TIMED_ON_ARRIVAL: return "arrival";
	case VMAC_TIMED_LATE: return "late";
	case VMAC_TIMED_OVERRUN: return "overrun";
	default: return "?";
	}
}

/* Board i's counter value local_ns as CLOCK_MONOTONIC: when its timer
 * reaches it (the oscillator's inverse; without one the counter is
 * CLOCK_MONOTONIC itself). */
static int64_t true_ns(struct board_set *s, int32_t i, uint64_t local_ns)
{
	struct oscillator *o = s->boards[i].osc;
	if (!o)
		return (int64_t)local_ns;
	return s->clock_base_ns + (int64_t)oscillator_true_ns(o, local_ns);
}

/* The board's acted hook: one --io-log line per action. */
static void acted(void *ctx, const struct vmac_board *b, const struct vmac_timed_action *a)
{
	struct board_set *s = ctx;
	int32_t i = (int32_t)((const struct posix_board *)(const void *)b - s->boards);
	int64_t done = vmac_now_ns();
	if (!s->io_log)
		return;
	fprintf(s->io_log,
	        "%s %s %s true=%" PRId64 " host=%" PRIu64 " done=%" PRId64 " digital=0x%02x pwm=%d clock=%s\n",
	        b->id.board, a->kind == VMAC_TIMED_OUT ? "out" : "latch", how_name(a->how),
	        a->local_ns ? true_ns(s, i, a->local_ns) : done, a->host_ns, done, a->outputs.digital, a->outputs.pwm,
	        vmac_clock_state_name(b->clock.state));
}

void boards_timed_init(struct board_set *s)
{
	int32_t i;
	for (i = 0; i < s->count; i++) {
		s->boards[i].board.acted = acted;
		s->boards[i].board.acted_ctx = s;
	}
}

void boards_timed_track(struct board_set *s, int32_t i)
{
	uint64_t local;
	if (s->boards[i].waiting || !vmac_board_next_deadline(&s->boards[i].board, &local))
		return;
	s->boards[i].waiting = 1;
	s->waiting[s->nwaiting++] = i;
}

int64_t boards_next_instant(struct board_set *s, int64_t now_ns)
{
	int64_t next = INT64_MAX;
	int32_t k = 0;
	while (k < s->nwaiting) {
		int32_t i = s->waiting[k];
		uint64_t local, now_local;
		int64_t at;
		if (!vmac_board_next_deadline(&s->boards[i].board, &local)) {
			/* done or cancelled: off the list (the last one takes its place) */
			s->boards[i].waiting = 0;
			s->waiting[k] = s->waiting[--s->nwaiting];
			continue;
		}
		k++;
		now_local = boards_local_ns(s, i, now_ns, 0);
		if (local <= now_local)
			return now_ns;
		/* far ahead (a host's mistake): no walk of the oscillator that far */
		at = local - now_local > (uint64_t)AHEAD_MAX_NS ? now_ns + AHEAD_MAX_NS : true_ns(s, i, local) + 1;
		if (at < next)
			next = at;
	}
	return next;
}

void boards_run_instants(struct board_set *s, int64_t now_ns)
{
	int32_t k;
	for (k = 0; k < s->nwaiting; k++) {
		int32_t i = s->waiting[k];
		struct posix_board *pb = &s->boards[i];
		uint64_t local;
		if (!vmac_board_next_deadline(&pb->board, &local))
			continue;                                    /* dropped by the next boards_next_instant */
		boards_poll_one(s, i, (uint64_t)(now_ns / 1000000)); /* a trip cancels what waits */
		for (;;) {
			struct vmac_packet *out;
			int len;
			uint64_t now_local = boards_local_ns(s, i, now_ns, 0);
			if (!vmac_board_next_deadline(&pb->board, &local) || local > now_local)
				break;
			if (s->nreplies == BOARDS_REPLY_MAX)
				boards_flush(s);
			out = &s->replies[s->nreplies];
			len = vmac_board_run_due(&pb->board, now_local, out->data, sizeof(out->data));
			if (len <= 0)
				continue;
			out->len = (size_t)len;
			out->addr = pb->timed_addr;
			memcpy(out->mac, pb->mac, sizeof(out->mac));
			out->rx_ns = now_ns; /* the late-reply check counts from the latch */
			s->reply_board[s->nreplies++] = i;
		}
	}
	boards_flush(s);
}
