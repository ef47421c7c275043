/* Generic peripheral board logic: the state machine of docs/PROTOCOL.md
 * ("Board behaviour"), independent of transport and clock. */
#include <string.h>

#include "board_internal.h"

void vmac_board_drive(struct vmac_board *b, const struct vmac_outputs *out)
{
	b->outputs = *out;
	b->io->write_outputs(b->io_ctx, out);
}

static void drive(struct vmac_board *b, const struct vmac_outputs *out)
{
	vmac_board_drive(b, out);
}

void vmac_board_safe(struct vmac_board *b)
{
	static const struct vmac_outputs off = {0, 0};
	vmac_board_timed_cancel(b); /* the safe state never waits for an instant */
	drive(b, &off);
	b->state = VMAC_BOARD_UNKNOWN;
	b->device_id = 0;
	b->offset = VMAC_OFFSET_NONE;
	memset(b->to_board, 0, sizeof(b->to_board)); /* the session's keys go with it */
	memset(b->to_host, 0, sizeof(b->to_host));
}

int vmac_board_seal(struct vmac_board *b, uint8_t *reply, int n, size_t cap)
{
	if (n <= 0)
		return 0;
	if (!b->id.keyed)
		return n;
	n = vmac_proto_seal(reply, (size_t)n, cap, ++b->tx_counter, b->to_host, NULL, 0);
	return n > 0 ? n : 0;
}

/* Keyed: whether the host's frame of the current session opens under its
 * key with a counter above the last one (a replay does not). */
static int opens(struct vmac_board *b, const uint8_t *frame, size_t len, const struct vmac_msg *req)
{
	if (!(req->flags & VMAC_FLAG_AUTH) || req->counter <= b->rx_counter ||
	    vmac_proto_open(frame, len, b->to_board, NULL, 0) != 0) {
		b->counters.auth_failed++;
		return 0;
	}
	b->rx_counter = req->counter;
	return 1;
}

void vmac_board_init(struct vmac_board *b, const struct vmac_board_identity *id, const struct vmac_board_io *io,
                     void *io_ctx, uint64_t now_ms)
{
	memset(b, 0, sizeof(*b));
	vmac_clock_init(&b->clock);
	b->id = *id;
	if (b->id.protocol == 0 || b->id.protocol > VMAC_PROTO_VERSION)
		b->id.protocol = VMAC_PROTO_VERSION;
	b->io = io;
	b->io_ctx = io_ctx;
	b->watchdog_ms = VMAC_BOARD_DEFAULT_WATCHDOG_MS;
	b->last_valid_ms = now_ms;
	vmac_board_safe(b);
}

int vmac_board_poll(struct vmac_board *b, uint64_t now_ms)
{
	if (b->state == VMAC_BOARD_KNOWN && now_ms - b->last_valid_ms >= b->watchdog_ms) {
		vmac_board_safe(b);
		b->counters.watchdog_trips++;
		return 1;
	}
	if (b->state == VMAC_BOARD_SLEEPING && now_ms >= b->sleep_until_ms)
		b->state = VMAC_BOARD_UNKNOWN;
	return 0;
}

static int answer(struct vmac_board *b, struct vmac_msg *r, const struct vmac_msg *req, uint8_t *reply, size_t cap)
{
	r->version = req->version; /* a reply speaks the request's version */
	r->flags = VMAC_FLAG_REPLY;
	r->seq = req->seq;
	r->channel = req->channel;
	return vmac_board_seal(b, reply, vmac_proto_encode(r, reply, cap), cap);
}

static int answer_error(struct vmac_board *b, const struct vmac_msg *req, uint32_t device_id, uint8_t code,
                        uint8_t *reply, size_t cap)
{
	struct vmac_msg r;
	memset(&r, 0, sizeof(r));
	r.device_id = device_id ? device_id : req->device_id;
	r.op = VMAC_OP_ERROR;
	r.u.error.code = code;
	r.u.error.op = req->op;
	return answer(b, &r, req, reply, cap);
}

static int answer_inputs(struct vmac_board *b, const struct vmac_msg *req, uint8_t *reply, size_t cap)
{
	struct vmac_msg r;
	memset(&r, 0, sizeof(r));
	r.device_id = b->device_id;
	r.op = req->op;
	b->io->read_inputs(b->io_ctx, &r.u.inputs);
	r.u.inputs.applied = b->outputs;
	return answer(b, &r, req, reply, cap);
}

static int answer_ack(struct vmac_board *b, const struct vmac_msg *req, uint32_t device_id, uint8_t *reply, size_t cap)
{
	struct vmac_msg r;
	memset(&r, 0, sizeof(r));
	r.device_id = device_id;
	r.op = req->op;
	return answer(b, &r, req, reply, cap);
}

static int on_discover(struct vmac_board *b, const struct vmac_msg *req, uint8_t *reply, size_t cap)
{
	struct vmac_msg r;
	int n;
	if (b->state != VMAC_BOARD_UNKNOWN)
		return 0; /* only unknown boards answer (thesis, device discovery) */
	if (b->id.keyed && !req->u.discover.has_nonce)
		return 0; /* a host that cannot authenticate us: we have nothing to say to it */
	memset(&r, 0, sizeof(r));
	r.op = VMAC_SYS_ANNOUNCE;
	memcpy(r.u.announce.driver, b->id.driver, sizeof(r.u.announce.driver));
	memcpy(r.u.announce.board, b->id.board, sizeof(r.u.announce.board));
	r.u.announce.major = b->id.major;
	r.u.announce.minor = b->id.minor;
	r.u.announce.firmware_major = VMAC_FIRMWARE_MAJOR;
	r.u.announce.firmware_minor = VMAC_FIRMWARE_MINOR;
	r.u.announce.caps = b->id.caps;
	/* The announce says which version the board speaks at most, whatever
	 * the DISCOVER's (sent as 1, so boards of every version answer it). */
	r.version = b->id.protocol;
	r.flags = VMAC_FLAG_REPLY;
	r.seq = req->seq;
	r.channel = VMAC_CH_SYSTEM;
	n = vmac_proto_encode(&r, reply, cap);
	if (n <= 0 || !b->id.keyed)
		return n > 0 ? n : 0;
	/* Sealed with the board's own key over this discovery's nonce: an old
	 * ANNOUNCE replayed answers another nonce. The nonce is kept: the
	 * REGISTER that follows is sealed with keys made from it. */
	b->has_nonce = 1;
	memcpy(b->nonce, req->u.discover.nonce, VMAC_NONCE_LEN);
	n = vmac_proto_seal(reply, (size_t)n, cap, 0, b->id.key, b->nonce, VMAC_NONCE_LEN);
	return n > 0 ? n : 0;
}

/* v2: the record at our offset, if it is our session's. Due: answer with
 * the inputs, as to an UPDATE (its seq, our session). TIMED: timed.c
 * schedules it once it is checked and has fed the watchdog. */
static int on_cyclic(struct vmac_board *b, const struct vmac_msg *req, uint64_t now_ms, uint64_t rx_local_ns,
                     uint8_t *reply, size_t cap)
{
	struct vmac_cyclic_record rec;
	struct vmac_msg r;
	int rc;
	if (b->state != VMAC_BOARD_KNOWN || b->offset == VMAC_OFFSET_NONE)
		return 0;
	rc = vmac_proto_cyclic_record(req, b->offset, &rec);
	/* rec is filled even when rc says its values are bad: the tag decides
	 * whose it is. Tag 0 is an empty record, never a session's. */
	if (rc == 1 || rec.tag == 0 || rec.tag != (uint16_t)(b->device_id >> 16)) {
		b->counters.frames_ignored++; /* not ours: no outputs, no watchdog */
		return 0;
	}
	if (b->id.keyed) {
		/* Ours by its tag: it must open under our session's key, in a
		 * frame newer than the last we obeyed. */
		if (!(req->flags & VMAC_FLAG_AUTH) || req->counter <= b->rx_cyclic_counter ||
		    vmac_proto_cyclic_open_record(req, b->offset, b->to_board) != 0) {
			b->counters.auth_failed++;
			return 0;
		}
		b->rx_cyclic_counter = req->counter;
	}
	if (rc != 0) {
		b->counters.frames_malformed++; /* our record, but out of range: never driven */
		return 0;
	}
	b->last_valid_ms = now_ms;
	b->counters.frames_ok++;
	if (req->flags & VMAC_FLAG_TIMED) {
		struct vmac_board_service s;
		s.outputs = rec.outputs;
		s.out_at = req->u.cyclic.out_at;
		s.in_at = req->u.cyclic.in_at;
		s.seq = req->seq;
		s.due = (rec.flags & VMAC_CYCLIC_DUE) != 0;
		return vmac_board_timed_service(b, &s, rx_local_ns, reply, cap);
	}
	vmac_board_timed_superseded(b);
	drive(b, &rec.outputs);
	if (!(rec.flags & VMAC_CYCLIC_DUE))
		return 0;
	memset(&r, 0, sizeof(r));
	r.version = req->version;
	r.flags = VMAC_FLAG_REPLY;
	r.seq = req->seq;
	r.device_id = b->device_id;
	r.channel = VMAC_CH_DEVICE;
	r.op = VMAC_OP_UPDATE;
	b->io->read_inputs(b->io_ctx, &r.u.inputs);
	r.u.inputs.applied = b->outputs;
	return vmac_board_seal(b, reply, vmac_proto_encode(&r, reply, cap), cap);
}

/* v2, unicast: a TIMED UPDATE of our session, checked (and, keyed,
 * opened) and its watchdog fed; served as a DUE record of a TIMED CYCLIC
 * is (timed.c): every UPDATE is answered, with the TIMED reply. */
static int on_timed_update(struct vmac_board *b, const struct vmac_msg *req, uint64_t rx_local_ns, uint8_t *reply,
                           size_t cap)
{
	struct vmac_board_service s;
	s.outputs = req->u.outputs;
	s.out_at = req->out_at;
	s.in_at = req->in_at;
	s.seq = req->seq;
	s.due = 1;
	return vmac_board_timed_service(b, &s, rx_local_ns, reply, cap);
}

/* Keyed: a REGISTER opens under the keys of the session it starts (made
 * from our key, the nonce we announced to and its device id); a replay of
 * the current session's is refused by its counter. Then those keys are
 * the session's. 1, or 0 (ignored, counted). */
static int register_opens(struct vmac_board *b, const uint8_t *frame, size_t len, const struct vmac_msg *req)
{
	uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
	int replay = b->state == VMAC_BOARD_KNOWN && req->device_id == b->device_id && req->counter <= b->rx_counter;
	if (!b->has_nonce || !(req->flags & VMAC_FLAG_AUTH) || replay) {
		b->counters.auth_failed++;
		return 0;
	}
	vmac_proto_session_keys(b->id.key, b->nonce, req->device_id, to_board, to_host);
	if (vmac_proto_open(frame, len, to_board, NULL, 0) != 0) {
		b->counters.auth_failed++;
		return 0;
	}
	memcpy(b->to_board, to_board, VMAC_KEY_LEN);
	memcpy(b->to_host, to_host, VMAC_KEY_LEN);
	b->rx_counter = req->counter;
	b->rx_cyclic_counter = 0;
	b->rx_sync_counter = 0;
	b->tx_counter = 0;
	return 1;
}

static int on_register(struct vmac_board *b, const struct vmac_msg *req, uint64_t now_ms, uint8_t *reply, size_t cap)
{
	static const struct vmac_outputs off = {0, 0};
	if (req->u.reg.major != b->id.major || req->u.reg.minor != b->id.minor)
		return answer_error(b, req, 0, VMAC_BERR_IDENTITY, reply, cap);
	/* A new session (or the host restarted): outputs stay off until the host
	 * sends fresh values in an UPDATE; nothing of the old one waits. */
	vmac_board_timed_cancel(b);
	drive(b, &off);
	vmac_clock_doubt(&b->clock); /* its host may keep another time base */
	b->state = VMAC_BOARD_KNOWN;
	b->device_id = req->device_id;
	b->watchdog_ms = req->u.reg.watchdog_ms;
	b->offset = VMAC_OFFSET_NONE; /* a v2 host tells it again */
	b->last_valid_ms = now_ms;
	b->counters.frames_ok++;
	return answer_ack(b, req, b->device_id, reply, cap);
}

/* Whether a keyed board may feed its clock from this SYNC: a sealed one
 * whose MAC at our offset opens under our session's key, with a counter
 * above the last SYNC we took in this session. Without a session and an
 * offset we have no key to check it with. 1, or 0 (counted). */
static int sync_opens(struct vmac_board *b, const struct vmac_msg *req)
{
	int rc;
	if (!(req->flags & VMAC_FLAG_AUTH) || b->state != VMAC_BOARD_KNOWN || b->offset == VMAC_OFFSET_NONE) {
		b->counters.sync_ignored++; /* unsealed, or nothing to check it with yet */
		return 0;
	}
	rc = vmac_proto_sync_open(req, b->offset, b->to_board);
	if (rc == 1) {
		b->counters.sync_ignored++; /* no MAC for our offset: another chunk's frame */
		return 0;
	}
	if (rc != 0 || req->counter <= b->rx_sync_counter) {
		b->counters.auth_failed++; /* forged, another board's, or replayed */
		return 0;
	}
	b->rx_sync_counter = req->counter;
	return 1;
}

/* The two-step SYNC's prev_tx_ns names the transmit time of last, the
 * SYNC before req of the same stream: req follows it at once and the time
 * is plausible (not before last's host_ns, not long after). */
static int names_last(const struct vmac_board_sync_last *last, const struct vmac_msg *req, uint16_t stream)
{
	uint64_t tx = req->u.sync.prev_tx_ns;
	return last->valid && last->stream == stream && (uint16_t)(last->seq + 1) == req->seq && tx != 0 &&
	       tx >= last->host_ns && tx - last->host_ns <= VMAC_BOARD_TWO_STEP_SPAN_NS;
}

/* A SYNC taken (docs/TIME.md, "The two-step SYNC"): the sample held back
 * from the last one goes to the clock first, with the transmit time this
 * one names for it (two-step); not named (a lost stamp, a lost frame,
 * another stream), it is dropped while the host names times (its own
 * host_ns is early by the host's send path, tens of microseconds: mixed in,
 * such samples move the clock by that much), else fed with its own host_ns
 * (one-step). This one's own sample is held back in turn while the host
 * names times and SYNC frames come often enough
 * (VMAC_BOARD_TWO_STEP_GAP_NS); else it goes now, one-step. Samples reach
 * the clock in the order of their receive times. */
static void sync_feed(struct vmac_board *b, const struct vmac_msg *req, uint64_t rx_local_ns)
{
	struct vmac_board_sync_last *last = &b->sync_last;
	uint16_t stream = (req->flags & VMAC_FLAG_AUTH) ? req->u.sync.first : VMAC_OFFSET_NONE;
	uint64_t gap = last->valid && rx_local_ns >= last->rx_local_ns ? rx_local_ns - last->rx_local_ns : UINT64_MAX;
	int named = names_last(last, req, stream);
	if (last->valid && last->deferred) {
		if (named) {
			b->counters.sync_two_step++;
			vmac_clock_feed(&b->clock, req->u.sync.prev_tx_ns, last->rx_local_ns);
		} else if (!last->two_step) {
			vmac_clock_feed(&b->clock, last->host_ns, last->rx_local_ns);
		}
	}
	if (req->u.sync.prev_tx_ns != 0)
		last->two_step = 1;
	if (named || req->u.sync.prev_tx_ns != 0)
		last->unnamed = 0;
	else if (++last->unnamed >= VMAC_BOARD_UNNAMED_MAX)
		last->two_step = 0; /* the host stopped stamping: one-step from here */
	last->valid = 1;
	last->deferred = last->two_step && gap <= VMAC_BOARD_TWO_STEP_GAP_NS;
	last->seq = req->seq;
	last->stream = stream;
	last->host_ns = req->u.sync.host_ns;
	last->rx_local_ns = rx_local_ns;
	if (!last->deferred)
		vmac_clock_feed(&b->clock, req->u.sync.host_ns, rx_local_ns);
}

/* SYNC: the host's send time and our receive time, one sample for the
 * clock (sync_feed: now, or with the next SYNC, two-step). Nothing else
 * changes: no answer, no outputs, no watchdog. A keyed board takes only a
 * sealed SYNC that carries its MAC (sync_opens), an unkeyed one only the
 * plain SYNC, in any state (docs/TIME.md, "Trust"). */
static int on_sync(struct vmac_board *b, const struct vmac_msg *req, uint64_t rx_local_ns)
{
	if (b->id.protocol < 2 || rx_local_ns == VMAC_BOARD_NO_STAMP ||
	    (!b->id.keyed && (req->flags & VMAC_FLAG_AUTH))) {
		b->counters.sync_ignored++;
		return 0;
	}
	if (b->id.keyed && !sync_opens(b, req))
		return 0;
	if (b->clock_local_ns < rx_local_ns)
		b->clock_local_ns = rx_local_ns;
	sync_feed(b, req, rx_local_ns);
	return 0;
}

enum vmac_clock_state vmac_board_clock_poll(struct vmac_board *b, uint64_t local_ns)
{
	if (b->clock_local_ns < local_ns)
		b->clock_local_ns = local_ns;
	return vmac_clock_tick(&b->clock, local_ns);
}

int vmac_board_clock_offset(const struct vmac_board *b, uint64_t local_ns, int64_t *offset_ns, uint64_t *bound_ns)
{
	uint64_t host_ns;
	if (vmac_clock_to_host(&b->clock, local_ns, &host_ns) != 0)
		return -1;
	*offset_ns = local_ns >= host_ns ? (int64_t)(local_ns - host_ns) : -(int64_t)(host_ns - local_ns);
	*bound_ns = vmac_clock_bound_ns(&b->clock, local_ns);
	return 0;
}

/* A host frame of the system channel, whole and well made but for an op
 * this code does not know: one a later protocol added (as SYNC was), which
 * goes to every board on the bus. Ignored, not counted malformed, so that
 * the next such op reaches boards of today harmlessly. */
static int later_system_op(const uint8_t *frame, size_t len)
{
	uint8_t op = len >= VMAC_HDR_LEN ? frame[11] : 0;
	if (op == VMAC_SYS_DISCOVER || op == VMAC_SYS_CYCLIC || op == VMAC_SYS_SYNC || op == VMAC_SYS_ANNOUNCE)
		return 0; /* known, so malformed as it came */
	return len >= VMAC_HDR_LEN && frame[10] == VMAC_CH_SYSTEM &&
	       (frame[3] & ~VMAC_FLAG_AUTH) == 0 && /* a request; no reserved flag */
	       (frame[6] | frame[7] | frame[8] | frame[9]) == 0 && vmac_proto_frame_length(frame, len) == (int)len;
}

int vmac_board_receive(struct vmac_board *b, const uint8_t *frame, size_t len, uint64_t now_ms, uint8_t *reply,
                       size_t cap)
{
	return vmac_board_receive_at(b, frame, len, now_ms, VMAC_BOARD_NO_STAMP, reply, cap);
}

int vmac_board_receive_at(struct vmac_board *b, const uint8_t *frame, size_t len, uint64_t now_ms, uint64_t rx_local_ns,
                          uint8_t *reply, size_t cap)
{
	struct vmac_msg req;
	uint32_t id;
	int rc;

	vmac_board_poll(b, now_ms);
	rc = vmac_proto_decode(frame, len, &req);
	if (rc == VMAC_EPROTO_OP && later_system_op(frame, len)) {
		b->counters.frames_ignored++; /* a system op of a later protocol: not for us to judge */
		return 0;
	}
	if (rc != 0) {
		b->counters.frames_malformed++;
		return 0;
	}
	/* SYNC goes to every board on the bus, of every version and state: a
	 * board that cannot use it ignores it, never counts it malformed. */
	if (req.channel == VMAC_CH_SYSTEM && req.op == VMAC_SYS_SYNC && !(req.flags & VMAC_FLAG_REPLY))
		return on_sync(b, &req, rx_local_ns);
	/* A board of version 1 knows no later frame: it is malformed to it. */
	if (req.version > b->id.protocol) {
		b->counters.frames_malformed++;
		return 0;
	}
	if (req.flags & VMAC_FLAG_REPLY) {
		b->counters.frames_ignored++; /* another board's answer: not for us */
		return 0;
	}
	if (b->state == VMAC_BOARD_SLEEPING) {
		b->counters.frames_ignored++;
		return 0;
	}
	if (!b->id.keyed && (req.flags & VMAC_FLAG_AUTH)) {
		b->counters.frames_ignored++; /* sealed for a keyed board: we cannot tell */
		return 0;
	}
	if (req.channel == VMAC_CH_SYSTEM)
		return req.op == VMAC_SYS_CYCLIC ? on_cyclic(b, &req, now_ms, rx_local_ns, reply, cap)
		                                 : on_discover(b, &req, reply, cap);
	if (req.op == VMAC_OP_REGISTER)
		return b->id.keyed && !register_opens(b, frame, len, &req) ? 0
		                                                           : on_register(b, &req, now_ms, reply, cap);
	if (b->state != VMAC_BOARD_KNOWN || req.device_id != b->device_id) {
		if (b->id.keyed) { /* another session's frame cannot be told from a forgery: silence */
			b->counters.frames_ignored++;
			return 0;
		}
		return answer_error(b, &req, 0, VMAC_BERR_NOT_REGISTERED, reply, cap);
	}
	if (b->id.keyed && !opens(b, frame, len, &req))
		return 0; /* not the host's: no outputs, no watchdog, no answer */

	b->last_valid_ms = now_ms;
	b->counters.frames_ok++;
	id = b->device_id;
	switch (req.op) {
	case VMAC_OP_UPDATE:
		if (req.flags & VMAC_FLAG_TIMED)
			return on_timed_update(b, &req, rx_local_ns, reply, cap);
		vmac_board_timed_superseded(b);
		drive(b, &req.u.outputs);
		return answer_inputs(b, &req, reply, cap);
	case VMAC_OP_IDLE: return answer_inputs(b, &req, reply, cap);
	case VMAC_OP_SHUTDOWN: {
		/* The acknowledgement is sealed with the session's key before
		 * vmac_board_safe forgets it. */
		int n = answer_ack(b, &req, id, reply, cap);
		vmac_board_safe(b);
		return n;
	}
	case VMAC_OP_SLEEP: {
		int n = answer_ack(b, &req, id, reply, cap);
		vmac_board_safe(b);
		b->state = VMAC_BOARD_SLEEPING;
		b->sleep_until_ms = now_ms + 1000u * req.u.sleep_s;
		return n;
	}
	case VMAC_OP_WATCHDOG: b->watchdog_ms = req.u.watchdog_ms; return answer_ack(b, &req, id, reply, cap);
	case VMAC_OP_SIZE: {
		struct vmac_msg r;
		memset(&r, 0, sizeof(r));
		r.device_id = id;
		r.op = VMAC_OP_SIZE;
		r.u.record_size = VMAC_CYCLIC_RECORD_LEN; /* the generic board's outputs */
		return answer(b, &r, &req, reply, cap);
	}
	case VMAC_OP_OFFSET:
	case VMAC_OP_OFFSET_GET: {
		struct vmac_msg r;
		if (req.op == VMAC_OP_OFFSET)
			b->offset = req.u.offset;
		memset(&r, 0, sizeof(r));
		r.device_id = id;
		r.op = req.op;
		r.u.offset = b->offset; /* the echo is the confirmation (seed 004's 0x02) */
		return answer(b, &r, &req, reply, cap);
	}
	default: return answer_error(b, &req, id, VMAC_BERR_BAD_REQUEST, reply, cap);
	}
}

int vmac_board_identity_valid(const struct vmac_board_identity *id)
{
	struct vmac_msg probe;
	uint8_t frame[VMAC_FRAME_MAX];
	memset(&probe, 0, sizeof(probe));
	probe.flags = VMAC_FLAG_REPLY;
	probe.channel = VMAC_CH_SYSTEM;
	probe.op = VMAC_SYS_ANNOUNCE;
	memcpy(probe.u.announce.driver, id->driver, sizeof(id->driver));
	memcpy(probe.u.announce.board, id->board, sizeof(id->board));
	probe.u.announce.caps = id->caps;
	return vmac_proto_encode(&probe, frame, sizeof(frame)) > 0;
}

const char *vmac_board_state_name(enum vmac_board_state s)
{
	switch (s) {
	case VMAC_BOARD_UNKNOWN: return "unknown";
	case VMAC_BOARD_KNOWN: return "known";
	case VMAC_BOARD_SLEEPING: return "sleeping";
	default: return "?";
	}
}
