/* The host's side of time-triggered I/O (docs/TIME.md, "The patterns";
 * docs/PROTOCOL.md, "Time-triggered I/O"): a machine's timing resolved
 * from its driver's pattern and its level, the instants of a service
 * (which bus.c writes into a TIMED CYCLIC frame, cyclic_put, or a TIMED
 * UPDATE, bus_unicast_update, for the boards that read them), and a
 * reply's latch time and board clock taken in. Bus thread; the two
 * per-service functions allocate nothing, log nothing, never block. */
#include "bus_internal.h"

#include <string.h>

#include "../sched/sched.h"

int bus_timing_set(struct vmac_bus *bus, struct machine *m, unsigned level, char *err, size_t errlen)
{
	struct vmac_timing_want want;
	struct vmac_timing t;
	uint32_t slot_us = vmac_config_slot_us(&bus->cfg);
	memset(&want, 0, sizeof(want));
	if (m->drv)
		vmac_driver_timing(m->drv, &want);
	if (vmac_timing_resolve(&want, bus->cfg.clock_sync_ms, vmac_timing_lead_us(bus->cfg.timed_lead_us, slot_us),
	                        slot_us << level, &t, err, errlen) != 0) {
		m->timing = t; /* arrival */
		return -1;
	}
	m->timing = t;
	return 0;
}

/* The instants count from the planned start of the machine's anchor slot:
 * the slot itself for a machine of one board; for several, the latest of
 * its boards' slots in this period, so that every board, whichever slot
 * carries its frame, acts at one instant, and none is asked for an
 * instant before its frame has left. */
int bus_service_instants(struct vmac_bus *bus, const struct device *d, uint64_t slot, unsigned level, uint64_t *out_at,
                         uint64_t *in_at)
{
	const struct machine *m;
	uint64_t anchor = slot;
	int i;
	if (!d->timed_fw || d->mach < 0)
		return 0;
	m = &bus->mach[d->mach];
	if (m->timing.pattern == VMAC_TIMING_ARRIVAL)
		return 0;
	if (m->nboards > 1) {
		uint64_t start = slot & ~(((uint64_t)1 << level) - 1);
		for (i = 0; i < m->nboards; i++) {
			struct vmac_sched_device s;
			if (vmac_sched_device(bus->sched, m->board[i], &s) == 0 && s.state == VMAC_SCHED_RUNNING &&
			    s.level == level && start + s.offset > anchor)
				anchor = start + s.offset;
		}
	}
	vmac_timing_instants(&m->timing, bus->start_ns + (int64_t)anchor * bus->slot_ns, out_at, in_at);
	/* dev:output_at: later within the period (the driver checked it at
	 * its level; a level changed since is checked again here). */
	if (m->out_at_ns > 0 && m->out_at_ns >= m->timing.out_ns && m->out_at_ns < bus->slot_ns << level)
		*out_at = (uint64_t)(bus->start_ns + (int64_t)anchor * bus->slot_ns + m->out_at_ns);
	return 1;
}

/* d's outputs in a unicast UPDATE: TIMED with the instants of its
 * machine's pattern when its board reads them (version 2, firmware 1.2:
 * bus_service_instants), the reply deadline then from in_at as for a
 * TIMED CYCLIC. */
void bus_unicast_update(struct vmac_bus *bus, struct device *d, uint64_t slot, unsigned level)
{
	struct vmac_msg m;
	uint64_t out_at = 0, in_at = 0;
	int timed = bus_service_instants(bus, d, slot, level, &out_at, &in_at);
	memset(&m, 0, sizeof(m));
	m.op = VMAC_OP_UPDATE;
	m.u.outputs = d->outputs;
	if (timed) {
		m.flags = VMAC_FLAG_TIMED;
		m.out_at = out_at;
		m.in_at = in_at;
	}
	bus_queue(bus, d, &m, 1);
	if (timed && d->pending && d->pending_op == VMAC_OP_UPDATE) { /* queued: its deadline from in_at */
		d->sent_timed = 1;
		d->in_at_ns = (int64_t)in_at;
	}
}

/* A latch time is the inputs' instant if it is plausible: not after the
 * reply came (beyond a clock's error), not long before. */
#define LATCH_AHEAD_NS 1000000LL     /* 1 ms */
#define LATCH_BEHIND_NS 1000000000LL /* 1 s */

void bus_timed_reply(struct vmac_bus *bus, struct device *d, const struct vmac_msg *m, int64_t rx_ns)
{
	struct vmac_board_clock_status *c = &d->clock;
	int timed = (m->flags & VMAC_FLAG_TIMED) != 0;
	uint64_t at = m->latch.latched_at; /* any 64 bits a board (or a forger on an open bus) sent */
	(void)bus;
	d->sample_ns = rx_ns;
	if (timed != d->sent_timed)
		d->timed_mismatch++; /* the inputs are taken all the same (docs/PROTOCOL.md) */
	if (!timed)
		return;
	c->known = 1;
	c->state = m->latch.clock & VMAC_CLOCK_STATE_MASK;
	c->on_arrival = (m->latch.clock & VMAC_CLOCK_ARRIVAL) != 0;
	c->bound_ns = m->latch.bound_ns;
	c->offset_ns = m->latch.offset_ns;
	c->latched_at_ns = m->latch.latched_at;
	if (c->on_arrival)
		c->services_arrival++;
	else
		c->services_timed++;
	/* Compared unsigned (rx_ns is positive): a time of 2^63 or more is
	 * never taken for one long ago. */
	if (at != 0 && at <= (uint64_t)rx_ns + LATCH_AHEAD_NS &&
	    (at >= (uint64_t)rx_ns || (uint64_t)rx_ns - at < LATCH_BEHIND_NS))
		d->sample_ns = (int64_t)at;
}
