/* The bus thread's side of checkpoints (docs/DRIVERS.md "Recovery after a
 * restart"): after a machine's tick, when its driver asked
 * (dev:checkpoint()) or checkpoint_s has passed, dev.state is encoded
 * straight into a slot of the checkpoint ring (allocated at start; no
 * allocation, no disk, no waiting here) for the main thread to store. A
 * full ring leaves the checkpoint due for the next tick, which encodes the
 * newer state: newest wins. After attach, recover(dev, saved) gets the
 * checkpoint the main thread offered. */
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

/* Encode machine m's dev.state into the ring now. 0, or -1 (ring full or
 * the encoding refused: said once in an event until one succeeds). */
static int checkpoint_now(struct vmac_bus *bus, struct machine *m, int64_t now)
{
	struct vmac_bus_checkpoint *cp = vmac_ring_reserve(&bus->checkpoints);
	const struct device *primary = &bus->dev[m->primary];
	char err[VMAC_DRIVER_ERR_MAX];
	size_t len;
	if (!cp) {
		bus->counters.checkpoints_deferred++;
		return -1;
	}
	if (vmac_driver_checkpoint(m->drv, cp->data, (size_t)bus->cfg.checkpoint_kib * 1024, &len, err, sizeof(err)) !=
	    0) {
		if (!m->checkpoint_failing)
			bus_event(bus, primary, "checkpoint", "%s: dev.state not saved: %s", primary->ann.board, err);
		m->checkpoint_failing = 1;
		return -1;
	}
	m->checkpoint_failing = 0;
	memcpy(cp->machine, primary->ann.board, sizeof(cp->machine));
	memcpy(cp->driver, m->driver, sizeof(cp->driver));
	snprintf(cp->version, sizeof(cp->version), "%s", vmac_driver_version(m->drv));
	cp->time_ns = now;
	cp->len = len;
	bus_rec_state(bus, m, now, cp->data, len); /* before the commit: the main thread may take the slot */
	vmac_ring_commit(&bus->checkpoints);
	bus->counters.checkpoints++;
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
	return 0;
}

void bus_checkpoint_due(struct vmac_bus *bus, struct machine *m, int64_t now)
{
	int periodic = bus->cfg.checkpoint_s && now >= m->next_checkpoint_ns;
	if (!m->drv || !m->attached || (!periodic && !vmac_driver_checkpoint_asked(m->drv)))
		return;
	if (checkpoint_now(bus, m, now) == 0 || m->checkpoint_failing)
		m->next_checkpoint_ns = now + (int64_t)bus->cfg.checkpoint_s * 1000000000;
}

void bus_checkpoint_all(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++)
		if (bus->mach[i].used && bus->mach[i].drv && bus->mach[i].attached)
			checkpoint_now(bus, &bus->mach[i], now);
}

void bus_attached(struct vmac_bus *bus, struct machine *m, int64_t now)
{
	const struct device *primary = &bus->dev[m->primary];
	char err[VMAC_DRIVER_ERR_MAX];
	int64_t t_ns = now - bus->start_ns; /* bus time, for attach and the recorder alike */
	int rc;
	m->attached = 1;
	m->next_checkpoint_ns = now + (int64_t)bus->cfg.checkpoint_s * 1000000000;
	bus_rec_attach(bus, m, t_ns);
	if (vmac_driver_attach(m->drv, (double)t_ns / 1e9, err, sizeof(err)) != 0) {
		bus_driver_failed(bus, m, " in attach", err);
		return;
	}
	rc = vmac_driver_recover(m->drv, (double)t_ns / 1e9, err, sizeof(err));
	if (rc < 0)
		bus_driver_failed(bus, m, " in recover", err);
	else if (rc == VMAC_RECOVER_DONE)
		bus_event(bus, primary, "recovered", "%s: recover() ran with the last checkpoint", primary->ann.board);
	else if (rc == VMAC_RECOVER_UNUSED)
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
