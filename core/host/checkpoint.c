/* The bus thread's side of checkpoints (docs/DRIVERS.md "Recovery after a
 * restart"): after a machine's tick, when its driver asked
 * (dev:checkpoint()) or checkpoint_s has passed, its worker encodes
 * dev.state into the machine's buffer, and the bus thread copies it into a
 * slot of the checkpoint ring (allocated at start; no allocation, no disk,
 * no waiting here) for the main thread to store. After attach,
 * recover(dev, saved) gets the checkpoint the main thread offered. */
#include "bus_internal.h"

#include <stdio.h>
#include <string.h>

#define CHECKPOINTS_IN_FLIGHT 16

int bus_checkpoints_init(struct vmac_bus *bus)
{
	size_t cap = (size_t)bus->cfg.checkpoint_kib * 1024;
	return vmac_ring_init(&bus->checkpoints, sizeof(struct vmac_bus_checkpoint) + cap, CHECKPOINTS_IN_FLIGHT);
}

void bus_checkpoints_fini(struct vmac_bus *bus)
{
	vmac_ring_fini(&bus->checkpoints);
}

/* A checkpoint m's job encoded (j->ckpt_rc 1: j->ckpt holds j->ckpt_len
 * bytes; -1: refused, said once in an event until one succeeds) goes into
 * the ring. A full ring leaves it due for the next tick, which encodes the
 * newer state: newest wins. */
void bus_checkpoint_taken(struct vmac_bus *bus, struct machine *m, struct job *j, int64_t now)
{
	const struct device *primary = &bus->dev[m->primary];
	struct vmac_bus_checkpoint *cp;
	if (j->ckpt_rc < 0) {
		if (!m->checkpoint_failing)
			bus_event(bus, primary, "checkpoint", "%s: dev.state not saved: %s", primary->ann.board,
			          j->ckpt_err);
		m->checkpoint_failing = 1;
		m->next_checkpoint_ns = now + (int64_t)bus->cfg.checkpoint_s * 1000000000;
		return;
	}
	cp = vmac_ring_reserve(&bus->checkpoints);
	if (!cp) {
		bus->counters.checkpoints_deferred++;
		m->want_checkpoint = 1;
		return;
	}
	m->checkpoint_failing = 0;
	m->next_checkpoint_ns = now + (int64_t)bus->cfg.checkpoint_s * 1000000000;
	memcpy(cp->machine, primary->ann.board, sizeof(cp->machine));
	memcpy(cp->driver, m->driver, sizeof(cp->driver));
	snprintf(cp->version, sizeof(cp->version), "%s", vmac_driver_version(m->drv ? m->drv : j->drv));
	cp->time_ns = now;
	cp->len = j->ckpt_len;
	memcpy(cp->data, j->ckpt, j->ckpt_len);
	bus_rec_state(bus, m, now, cp->data, cp->len); /* before the commit: the main thread may take the slot */
	vmac_ring_commit(&bus->checkpoints);
	bus->counters.checkpoints++;
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
}

int bus_checkpoint_due(struct vmac_bus *bus, struct machine *m, int64_t now)
{
	return bus->cfg.checkpoint_s && now >= m->next_checkpoint_ns;
}

void bus_attached(struct vmac_bus *bus, struct machine *m, int64_t now)
{
	m->next_checkpoint_ns = now + (int64_t)bus->cfg.checkpoint_s * 1000000000;
	m->want_attach = 1;
	bus_dispatch(bus, m);
}

/* attach() and recover() have run (j): the machine runs, or its driver
 * failed. */
void bus_attach_done(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	const struct device *primary = &bus->dev[m->primary];
	int64_t t_ns = (int64_t)(j->time_s * 1e9); /* bus time, for attach and the recorder alike */
	m->attached = 1;
	bus_rec_attach(bus, m, t_ns);
	if (j->rc != 0) {
		bus_driver_failed(bus, m, j->recover_rc < 0 ? " in recover" : " in attach", j->err);
		return;
	}
	if (j->recover_rc == VMAC_RECOVER_DONE)
		bus_event(bus, primary, "recovered", "%s: recover() ran with the last checkpoint", primary->ann.board);
	else if (j->recover_rc == VMAC_RECOVER_UNUSED)
		bus_event(bus, primary, "recovered", "%s: checkpoint not used: driver %s has no recover()",
		          primary->ann.board, m->driver);
}

const struct vmac_bus_checkpoint *vmac_bus_checkpoint_peek(struct vmac_bus *bus)
{
	return vmac_ring_peek(&bus->checkpoints);
}

void vmac_bus_checkpoint_release(struct vmac_bus *bus)
{
	vmac_ring_release(&bus->checkpoints);
}
