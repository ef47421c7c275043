/* The bus thread's receiving side: every frame from the bus read, judged
 * (malformed, a stranger's, unauthenticated, late) and, when it is a
 * board's answer in time, acted on: an announcement to devices.c, a
 * registration step, a tick's inputs to the machine's driver (jobs.c).
 * Sending and the tick are bus.c's. */
#include "bus_internal.h"

#include <stdio.h>
#include <string.h>

#include "../proto/auth.h"

const char *const vmac_malformed_reason_names[VMAC_BAD_REASONS] = {
    "short", "magic",     "version",   "length",         "op",    "payload", "name",
    "value", "not_reply", "stale_seq", "unknown_sender", "offset"};

static void malformed(struct vmac_bus *bus, const struct vmac_packet *p, int reason)
{
	char addr[48];
	int64_t now = p->rx_ns;
	bus->counters.malformed_frames++;
	bus->counters.malformed_by_reason[reason]++;
	if (now - bus->last_malformed_log_ns < MALFORMED_LOG_EVERY_NS) {
		bus->malformed_suppressed++;
		return;
	}
	bus_event(bus, NULL, "malformed", "malformed frame from %s: %s (%llu more since the last report)",
	          vmac_addr_format(&p->addr, addr, sizeof(addr)), vmac_malformed_reason_names[reason],
	          (unsigned long long)bus->malformed_suppressed);
	bus->malformed_suppressed = 0;
	bus->last_malformed_log_ns = now;
}

static int reason_of(int proto_err)
{
	switch (proto_err) {
	case VMAC_EPROTO_SHORT: return VMAC_BAD_SHORT;
	case VMAC_EPROTO_MAGIC: return VMAC_BAD_MAGIC;
	case VMAC_EPROTO_VERSION: return VMAC_BAD_VERSION;
	case VMAC_EPROTO_LENGTH: return VMAC_BAD_LENGTH;
	case VMAC_EPROTO_PAYLOAD: return VMAC_BAD_PAYLOAD;
	case VMAC_EPROTO_NAME: return VMAC_BAD_NAME;
	case VMAC_EPROTO_VALUE: return VMAC_BAD_VALUE;
	default: return VMAC_BAD_OP;
	}
}

/* A reply to a registration step: 1 when the board is now registered, 0
 * when another step follows (or it was dropped). */
static int registered(struct vmac_bus *bus, struct device *d, const struct vmac_msg *m)
{
	static const uint8_t step_op[] = {VMAC_OP_REGISTER, VMAC_OP_SIZE, VMAC_OP_OFFSET};
	char why[120];
	if (m->op != step_op[d->reg_step])
		return 0;
	if (!bus_holds_offset(bus, d) || d->reg_step == REG_OFFSET) {
		if (bus_holds_offset(bus, d) && m->u.offset != bus_slot_of(bus, d)) {
			bus->counters.malformed_frames++;
			bus->counters.malformed_by_reason[VMAC_BAD_OFFSET]++;
			snprintf(why, sizeof(why), "board confirmed offset %u, but was given %u", (unsigned)m->u.offset,
			         (unsigned)bus_slot_of(bus, d));
			bus_drop(bus, d, VMAC_SHUT_DROPPED, "dropped", why);
			return 0;
		}
		return 1;
	}
	if (d->reg_step == REG_SIZE && m->u.record_size != VMAC_CYCLIC_RECORD_LEN) {
		bus->counters.malformed_frames++;
		bus->counters.malformed_by_reason[VMAC_BAD_OFFSET]++;
		snprintf(why, sizeof(why), "board wants %u-byte cyclic records; this host sends %d",
		         (unsigned)m->u.record_size, VMAC_CYCLIC_RECORD_LEN);
		bus_drop(bus, d, VMAC_SHUT_DROPPED, "dropped", why);
		return 0;
	}
	d->reg_step++;
	d->register_sent = 0; /* service_registration sends the next step */
	return 0;
}

static void on_reply(struct vmac_bus *bus, struct device *d, const struct vmac_msg *m, int64_t rx_ns)
{
	char why[120];
	d->consecutive_misses = 0;
	d->served++;
	if (m->op == VMAC_OP_ERROR) {
		snprintf(why, sizeof(why), "board refused %s (error %u: %s)",
		         vmac_proto_opname(VMAC_CH_DEVICE, m->u.error.op), (unsigned)m->u.error.code,
		         m->u.error.code == VMAC_BERR_NOT_REGISTERED ? "session lost"
		         : m->u.error.code == VMAC_BERR_IDENTITY     ? "identity mismatch"
		                                                     : "bad request");
		bus_drop(bus, d, VMAC_SHUT_DROPPED, "dropped", why);
		return;
	}
	switch (d->state) {
	case DEV_REGISTERING:
		if (!registered(bus, d, m))
			return;
		d->state = DEV_RUNNING;
		bus_event(bus, d, "attached", "%s attached: driver %s %s, major %u minor %u, level %u, at %s",
		          d->ann.board, d->ann.driver, vmac_driver_version(bus->mach[d->mach].drv),
		          (unsigned)d->ann.major, (unsigned)d->ann.minor, bus->mach[d->mach].level,
		          vmac_addr_format(&d->addr, why, sizeof(why)));
		if (bus_slot_of(bus, d) == bus->mach[d->mach].primary && !bus->mach[d->mach].attached)
			bus_attached(bus, &bus->mach[d->mach], bus_now(bus));
		break;
	case DEV_TO_SLEEP:
		if (m->op == VMAC_OP_REGISTER) {
			struct vmac_msg s;
			memset(&s, 0, sizeof(s));
			s.op = VMAC_OP_SLEEP;
			s.u.sleep_s = (uint16_t)bus->cfg.sleep_s;
			bus_queue(bus, d, &s, 1);
			bus_flush(bus);
		} else if (m->op == VMAC_OP_SLEEP) {
			d->state = DEV_SLEEPING;
		}
		break;
	case DEV_RUNNING:
		if (m->op == VMAC_OP_UPDATE) {
			d->inputs = m->u.inputs;
			bus_timed_reply(bus, d, m, rx_ns);
			if (d->mach >= 0 && bus->mach[d->mach].primary == bus_slot_of(bus, d) &&
			    bus->mach[d->mach].attached)
				bus_run_machine(bus, &bus->mach[d->mach]);
		}
		break;
	default: break;
	}
}

/* m, not of d's session, is a late reply of an earlier session of the
 * board d holds (it was dropped and announced again): d is in a session
 * (a board waiting for approval has none, nor does a free entry), m's id
 * one of the slot's other generations, and it comes from d's address.
 * Anything else is a sender we do not know. */
static int earlier_session(const struct device *d, const struct vmac_msg *m, const struct vmac_packet *p)
{
	return d && d->state != DEV_FREE && d->state != DEV_WAITING && m->device_id != d->id &&
	       (m->device_id >> 16) != 0 && vmac_addr_equal(&d->addr, &p->addr);
}

void bus_handle_packet(struct vmac_bus *bus, const struct vmac_packet *p)
{
	struct vmac_msg m;
	struct device *d;
	uint32_t slot;
	int rc = vmac_proto_decode(p->data, p->len, &m);

	if (rc != 0) {
		malformed(bus, p, reason_of(rc));
		return;
	}
	if (!(m.flags & VMAC_FLAG_REPLY)) {
		malformed(bus, p, VMAC_BAD_NOT_REPLY);
		return;
	}
	if (m.channel == VMAC_CH_SYSTEM) {
		/* Only an answer to the latest discovery counts. */
		if (m.seq != bus->discover_seq || bus->stopping) {
			malformed(bus, p, VMAC_BAD_STALE_SEQ);
			return;
		}
		bus_on_announce(bus, &m, p);
		return;
	}
	slot = m.device_id & 0xFFFF;
	d = slot < bus->ndev ? &bus->dev[slot] : NULL;
	if (!d || d->id != m.device_id || d->state == DEV_FREE || !vmac_addr_equal(&d->addr, &p->addr)) {
		malformed(bus, p, earlier_session(d, &m, p) ? VMAC_BAD_STALE_SEQ : VMAC_BAD_UNKNOWN_SENDER);
		return;
	}
	if (d->keyed) {
		/* Its session's, newer than the last accepted, or not the board's:
		 * ignored as if never received (a forger cannot answer for it). */
		if (!(m.flags & VMAC_FLAG_AUTH) || m.counter <= d->rx_counter ||
		    vmac_proto_open(p->data, p->len, d->to_host, NULL, 0) != 0) {
			bus_auth_failed(bus, p, d->ann.board,
			                !(m.flags & VMAC_FLAG_AUTH)  ? "not sealed"
			                : m.counter <= d->rx_counter ? "a replay (its counter is not new)"
			                                             : "its MAC does not verify");
			return;
		}
		d->rx_counter = m.counter;
	} else if (m.flags & VMAC_FLAG_AUTH) {
		malformed(bus, p, VMAC_BAD_UNKNOWN_SENDER); /* sealed, but we gave it no session key */
		return;
	}
	d->last_seen_ns = p->rx_ns;
	if (!d->pending || m.seq != d->seq) {
		/* Expected and harmless: the late answer to a request already
		 * judged a miss, and the answer to the SHUTDOWN or SLEEP sent on
		 * dropping the device. Anything else is stale. */
		if (m.seq == d->missed_seq)
			bus->counters.late_replies++;
		else if (m.seq == d->aside_seq && d->aside_seq != 0)
			; /* the answer to a WATCHDOG sent alongside an UPDATE */
		else if (m.seq != d->courtesy_seq || d->state != DEV_ERRANT)
			malformed(bus, p, VMAC_BAD_STALE_SEQ);
		return;
	}
	d->pending = 0;
	if (d->sent_ns != 0 && p->rx_ns - bus_deadline_from(d) > d->reply_window_ns) {
		char why[200];
		bus->counters.late_replies++;
		/* The times are CLOCK_MONOTONIC, so a board on the same machine can
		 * be lined up with them (vmac-board's late-reply lines). */
		snprintf(why, sizeof(why),
		         "reply to %s seq %u came %.3g ms after the %s (deadline %.3g ms; sent at %lld ns, "
		         "received at %lld ns)",
		         vmac_proto_opname(VMAC_CH_DEVICE, d->pending_op), (unsigned)m.seq,
		         (double)(p->rx_ns - bus_deadline_from(d)) / 1e6,
		         d->in_at_ns > d->sent_ns ? "instant it was to latch at" : "request",
		         (double)d->reply_window_ns / 1e6, (long long)d->sent_ns, (long long)p->rx_ns);
		if (!bus->stopping)
			bus_miss(bus, d, why);
		return;
	}
	on_reply(bus, d, &m, p->rx_ns);
}

void bus_drain(struct vmac_bus *bus)
{
	/* The transmit stamps of the SYNC frames sent (the two-step, sync.c) */
	bus_sync_read_stamps(bus, 0);
	for (;;) {
		int i, n = vmac_transport_recv(&bus->tr, bus->tr.fd, bus->rx, RX_BATCH);
		if (n <= 0)
			break;
		for (i = 0; i < n; i++)
			bus_handle_packet(bus, &bus->rx[i]);
		bus_flush(bus); /* anything a reply caused (SHUTDOWN, SLEEP) goes now */
		if (n < RX_BATCH)
			break;
	}
}
