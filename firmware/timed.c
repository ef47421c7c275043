/* Time-triggered I/O on the board (docs/TIME.md, "Time-triggered I/O";
 * docs/PROTOCOL.md, "Time-triggered I/O"): a TIMED CYCLIC record's or a
 * TIMED UPDATE's outputs and input latch scheduled at the host's instants on the board's own
 * counter through its disciplined clock, done when the caller's timer says
 * (vmac_board_run_due), or on arrival when the clock cannot be trusted, and
 * the TIMED reply that tells the host when the inputs were latched and how
 * good the clock was. At most one output and one latch wait: no queue, no
 * heap, portable C99. */
#include <string.h>

#include "board_internal.h"

static void tell(struct vmac_board *b, enum vmac_timed_kind kind, enum vmac_timed_how how, uint64_t local_ns,
                 uint64_t host_ns)
{
	struct vmac_timed_action a;
	if (!b->acted)
		return;
	memset(&a, 0, sizeof(a));
	a.kind = kind;
	a.how = how;
	a.local_ns = local_ns;
	a.host_ns = host_ns;
	a.outputs = b->outputs;
	b->acted(b->acted_ctx, b, &a);
}

static void do_out(struct vmac_board *b, uint64_t local_ns, enum vmac_timed_how how)
{
	struct vmac_board_timed *t = &b->timed;
	t->out_pending = 0;
	vmac_board_drive(b, &t->out);
	tell(b, VMAC_TIMED_OUT, how, local_ns, t->out_host);
}

/* What the reply says of the clock at the latch, local_ns on the board's
 * counter (stamped 0: the caller gave no time, so the clock cannot say). */
static void latch_clock(const struct vmac_board *b, uint64_t local_ns, int stamped, enum vmac_timed_how how,
                        struct vmac_latch *l)
{
	uint64_t host_ns, bound;
	l->clock = (uint8_t)b->clock.state;
	if (how == VMAC_TIMED_ON_ARRIVAL)
		l->clock |= VMAC_CLOCK_ARRIVAL;
	l->latched_at = 0;
	l->bound_ns = 0xFFFFFFFFu;
	l->offset_ns = 0;
	if (!stamped || vmac_clock_to_host(&b->clock, local_ns, &host_ns) != 0)
		return;
	bound = vmac_clock_bound_ns(&b->clock, local_ns);
	l->latched_at = host_ns;
	l->bound_ns = bound > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)bound;
	l->offset_ns = local_ns >= host_ns ? (int64_t)(local_ns - host_ns) : -(int64_t)(host_ns - local_ns);
}

/* Latch the inputs now (the board counter reading local_ns) and build the
 * TIMED reply: its length, or 0. */
static int do_latch(struct vmac_board *b, uint64_t local_ns, enum vmac_timed_how how, uint8_t *reply, size_t cap)
{
	struct vmac_board_timed *t = &b->timed;
	struct vmac_msg r;
	t->latch_pending = 0;
	memset(&r, 0, sizeof(r));
	r.version = 2;
	r.flags = VMAC_FLAG_REPLY | VMAC_FLAG_TIMED;
	r.seq = t->latch_seq;
	r.device_id = b->device_id;
	r.channel = VMAC_CH_DEVICE;
	r.op = VMAC_OP_UPDATE;
	b->io->read_inputs(b->io_ctx, &r.u.inputs);
	r.u.inputs.applied = b->outputs; /* what it drives at the latch */
	latch_clock(b, local_ns, t->latch_stamped, how, &r.latch);
	tell(b, VMAC_TIMED_LATCH, how, t->latch_stamped ? local_ns : 0, t->latch_host);
	return vmac_board_seal(b, reply, vmac_proto_encode(&r, reply, cap), cap);
}

/* Everything due at now_local_ns, in the order of its instants (an output
 * before a latch of the same instant); a latch only when may_latch. */
static int run(struct vmac_board *b, uint64_t now_local_ns, int may_latch, uint8_t *reply, size_t cap)
{
	struct vmac_board_timed *t = &b->timed;
	int n = 0;
	for (;;) {
		int out_due = t->out_pending && t->out_local <= now_local_ns;
		int latch_due = may_latch && n == 0 && t->latch_pending && t->latch_local <= now_local_ns;
		if (out_due && (!latch_due || t->out_local <= t->latch_local))
			do_out(b, t->out_local, t->out_how);
		else if (latch_due)
			n = do_latch(b, t->latch_local, t->latch_how, reply, cap);
		else
			return n;
	}
}

int vmac_board_run_due(struct vmac_board *b, uint64_t now_local_ns, uint8_t *reply, size_t cap)
{
	return run(b, now_local_ns, 1, reply, cap);
}

int vmac_board_next_deadline(const struct vmac_board *b, uint64_t *local_ns)
{
	const struct vmac_board_timed *t = &b->timed;
	if (!t->out_pending && !t->latch_pending)
		return 0;
	if (t->out_pending && (!t->latch_pending || t->out_local <= t->latch_local))
		*local_ns = t->out_local;
	else
		*local_ns = t->latch_local;
	return 1;
}

void vmac_board_timed_cancel(struct vmac_board *b)
{
	b->timed.out_pending = 0;
	b->timed.latch_pending = 0;
}

void vmac_board_timed_superseded(struct vmac_board *b)
{
	b->timed.out_pending = 0;
}

/* A record came while an earlier one's action still waited: the earlier
 * output is driven now, and, when the new record is due (it needs the one
 * latch), the earlier latch is done now too, in the order of their
 * instants. Returns the forced latch's reply length, or 0. */
static int overrun(struct vmac_board *b, uint64_t now, int due, int stamped, uint8_t *reply, size_t cap)
{
	struct vmac_board_timed *t = &b->timed;
	int force_latch = due && t->latch_pending, n = 0;
	if (!t->out_pending && !force_latch)
		return 0;
	b->counters.timed_overrun++;
	t->latch_stamped = (uint8_t)(t->latch_stamped && stamped); /* done now: at a time the clock may not know */
	if (force_latch && (!t->out_pending || t->latch_local < t->out_local))
		n = do_latch(b, now, VMAC_TIMED_OVERRUN, reply, cap);
	if (t->out_pending)
		do_out(b, now, VMAC_TIMED_OVERRUN);
	if (force_latch && t->latch_pending)
		n = do_latch(b, now, VMAC_TIMED_OVERRUN, reply, cap);
	return n;
}

/* When, on the board's counter, to act at host instant host_ns, the frame
 * having come at now: *local and how (at the instant, or late: at once).
 * Past or future is judged in host time first: an instant far in the past
 * (0, a host's bug) must not wrap the counter into the far future. */
static enum vmac_timed_how when(const struct vmac_board *b, uint64_t host_ns, uint64_t now, uint64_t *local)
{
	uint64_t host_now;
	if (vmac_clock_to_host(&b->clock, now, &host_now) == 0 && host_ns > host_now &&
	    vmac_clock_to_local(&b->clock, host_ns, local) == 0 && *local >= now)
		return VMAC_TIMED_AT_INSTANT;
	*local = now;
	return VMAC_TIMED_LATE;
}

int vmac_board_timed_service(struct vmac_board *b, const struct vmac_board_service *s, uint64_t rx_local_ns,
                             uint8_t *reply, size_t cap)
{
	struct vmac_board_timed *t = &b->timed;
	int stamped = rx_local_ns != VMAC_BOARD_NO_STAMP, due = s->due != 0;
	uint64_t now = stamped ? rx_local_ns : 0; /* unstamped: 0, due at any time the caller names */

	int usable = 0, n;
	if (stamped) {
		vmac_board_clock_poll(b, rx_local_ns); /* holdover, lost: as of the arrival */
		usable = vmac_clock_usable(&b->clock); /* a keyed board's: fed by sealed SYNC only */
	}
	n = overrun(b, now, due, stamped, reply, cap);
	t->mode = usable ? VMAC_TIMED_MODE_INSTANTS : VMAC_TIMED_MODE_ARRIVAL;
	t->out = s->outputs;
	t->out_host = s->out_at;
	t->out_pending = 1;
	if (due) { /* else an earlier latch still waiting keeps its place */
		t->latch_pending = 1;
		t->latch_host = s->in_at;
		t->latch_seq = s->seq;
		t->latch_stamped = (uint8_t)stamped;
	}
	if (!usable) {
		b->counters.timed_arrival++;
		t->out_local = now;
		t->out_how = VMAC_TIMED_ON_ARRIVAL;
		if (due) {
			t->latch_local = now;
			t->latch_how = VMAC_TIMED_ON_ARRIVAL;
		}
	} else {
		b->counters.timed++;
		t->out_how = when(b, t->out_host, now, &t->out_local);
		if (due)
			t->latch_how = when(b, t->latch_host, now, &t->latch_local);
		if (t->out_how == VMAC_TIMED_LATE || (due && t->latch_how == VMAC_TIMED_LATE))
			b->counters.timed_late++;
	}
	/* What is due now (on arrival, late) is done now; a latch only when
	 * no forced one's reply holds the one reply of this call (then the
	 * caller's vmac_board_run_due does it at once). */
	if (n > 0) {
		run(b, now, 0, reply, cap);
		return n;
	}
	return run(b, now, 1, reply, cap);
}
