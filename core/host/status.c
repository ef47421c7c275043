/* The status the bus thread publishes (at most every 100 ms) for the
 * other threads to copy: every device, the counters, the schedule. */
#include "bus_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <sched.h>
#include <semaphore.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "../common/errors.h"
#include "../sched/sched.h"

/* ---- status ---- */

const char *vmac_violation_name(int kind)
{
	switch (kind) {
	case VMAC_VIOLATION_MISS: return "miss";
	case VMAC_VIOLATION_MISS_HOST: return "miss_host";
	case VMAC_VIOLATION_DRIVER_LATE: return "driver_late";
	default: return NULL;
	}
}

const char *bus_state_name(enum dev_state s)
{
	switch (s) {
	case DEV_LOADING:
	case DEV_REGISTERING: return "attaching";
	case DEV_RUNNING: return "running";
	case DEV_TO_SLEEP:
	case DEV_SLEEPING: return "sleeping";
	case DEV_ERRANT: return "errant";
	case DEV_WAITING: return "waiting";
	default: return "free";
	}
}

/* d's state as the status and vmac test show it: running once its
 * machine's attach() has returned (params and variables are the driver's
 * then), attaching before. */
static const char *state_of(const struct vmac_bus *bus, const struct device *d)
{
	const struct machine *m = d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	return d->state == DEV_RUNNING && m && !m->attached ? "attaching" : bus_state_name(d->state);
}

/* Device slot i as the status shows it. */
static void device_status(struct vmac_bus *bus, uint32_t i, struct vmac_device_status *o)
{
	const struct device *d = &bus->dev[i];
	const struct machine *m = d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	struct vmac_sched_device sd;
	int v;
	memcpy(o->name, d->ann.board, sizeof(o->name));
	memcpy(o->driver, d->ann.driver, sizeof(o->driver));
	snprintf(o->driver_version, sizeof(o->driver_version), "%s", m && m->drv ? vmac_driver_version(m->drv) : "");
	snprintf(o->machine, sizeof(o->machine), "%s", m ? bus->dev[m->primary].ann.board : "");
	memcpy(o->last_machine, d->last_machine, sizeof(o->last_machine));
	snprintf(o->note, sizeof(o->note), "%s", d->note);
	o->state = state_of(bus, d);
	vmac_addr_format(&d->addr, o->address, sizeof(o->address));
	o->id = d->id;
	o->major = d->ann.major;
	o->minor = d->ann.minor;
	o->authenticated = d->keyed && (d->state == DEV_LOADING || d->state == DEV_REGISTERING ||
	                                d->state == DEV_RUNNING || d->state == DEV_TO_SLEEP);
	o->scheduled = d->scheduled && vmac_sched_device(bus->sched, i, &sd) == 0 && sd.state == VMAC_SCHED_RUNNING;
	o->level = o->scheduled ? sd.level : (m ? m->level : 0);
	o->slot = o->scheduled ? sd.offset : 0;
	o->slice = o->scheduled ? sd.slice : 0;
	o->period_us = (uint32_t)((bus->slot_ns << o->level) / 1000);
	o->misses = d->misses;
	o->served = d->served;
	o->misses_host = d->misses_host;
	o->drops = d->drops;
	o->driver_late = m && m->primary == i ? m->late : 0;
	o->violation = d->violated;
	o->violation_ns = d->violated_ns;
	if (o->driver_late && m->late_ns > o->violation_ns) {
		o->violation = VMAC_VIOLATION_DRIVER_LATE;
		o->violation_ns = m->late_ns;
	}
	o->protocol = d->version;
	o->cyclic = d->cyclic;
	o->offset = i;
	o->clock = d->clock;
	o->timing.pattern = m && m->drv ? m->timing.pattern : 0;
	o->timing.in_us = m ? (uint32_t)(m->timing.in_ns / 1000) : 0;
	o->timing.out_us = m ? (uint32_t)(m->timing.out_ns / 1000) : 0;
	o->timing.timed = m && m->drv && d->timed_fw && !bus->virt && m->timing.pattern != VMAC_TIMING_ARRIVAL;
	o->timing_mismatch = d->timed_mismatch;
	o->firmware_major = d->ann.firmware_major;
	o->firmware_minor = d->ann.firmware_minor;
	o->inputs = d->inputs;
	o->outputs = d->state == DEV_RUNNING ? d->inputs.applied : (struct vmac_outputs){0, 0};
	o->driver_memory = m && m->drv && m->primary == i ? m->memory : 0;
	o->driver_memory_cap = m && m->drv && m->primary == i ? vmac_driver_memory_cap(m->drv) : 0;
	o->driver_instructions = m && m->drv && m->primary == i ? m->instructions : 0;
	o->driver_call_ns = m && m->drv && m->primary == i ? m->call_ns : 0;
	o->driver_instruction_budget = m && m->drv && m->primary == i ? vmac_driver_instruction_budget(m->drv) : 0;
	o->nvars = o->nparams = 0;
	if (m && m->drv && m->primary == i) { /* as the machine's last job left them */
		o->nvars = m->nvars;
		for (v = 0; v < o->nvars; v++)
			o->vars[v] = m->vars[v];
		o->nparams = m->nparams;
		memcpy(o->params, m->params, (size_t)m->nparams * sizeof(o->params[0]));
	}
}

void bus_publish(struct vmac_bus *bus, int64_t now)
{
	struct vmac_status *s = &bus->status;
	uint32_t i;
	int n = 0;
	if (pthread_mutex_trylock(&bus->status_lock) != 0)
		return; /* a reader holds it: try again next tick, never wait */
	s->time_ns = now;
	s->started_ns = bus->start_ns;
	s->realtime = bus->realtime;
	s->board_keys = bus_keys_count(bus);
	s->lateness = bus->lateness;
	s->counters = bus->counters;
	s->slices_per_slot = bus->cfg.slices_per_slot;
	s->slots_per_block = 1u << bus->cfg.max_level;
	s->slot_us = (unsigned)(bus->slot_ns / 1000);
	vmac_sched_capacity(bus->sched, &s->capacity_used, &s->capacity_total);
	for (i = 0; i < s->slots_per_block; i++)
		s->slot_load[i] = (uint16_t)vmac_sched_load(bus->sched, i);
	for (i = 0; i < bus->nused; i++)
		if (bus->dev[i].state != DEV_FREE)
			device_status(bus, i, &s->devices[n++]);
	s->ndevices = n;
	pthread_mutex_unlock(&bus->status_lock);
	bus->last_status_ns = now;
}

int vmac_bus_device_status(struct vmac_bus *bus, const char *device, struct vmac_device_status *out)
{
	struct device *d = bus_find_by_name(bus, device);
	if (!d)
		return -1;
	device_status(bus, bus_slot_of(bus, d), out);
	return 0;
}

const char *vmac_bus_device_state(struct vmac_bus *bus, const char *device)
{
	struct device *d = bus_find_by_name(bus, device);
	return d ? state_of(bus, d) : "absent";
}

const struct vmac_variable *vmac_bus_device_var(struct vmac_bus *bus, const char *device, const char *name)
{
	struct device *d = bus_find_by_name(bus, device);
	const struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	int i;
	if (!m || !m->drv || m->primary != bus_slot_of(bus, d))
		return NULL;
	for (i = 0; i < m->nvars; i++)
		if (strcmp(m->vars[i].name, name) == 0)
			return &m->vars[i];
	return NULL;
}

void vmac_bus_status(struct vmac_bus *bus, struct vmac_status *out)
{
	int i;
	struct vmac_device_status *devices = out->devices;
	uint16_t *load = out->slot_load;
	pthread_mutex_lock(&bus->status_lock);
	*out = bus->status;
	out->devices = devices;
	out->slot_load = load;
	memcpy(devices, bus->status.devices, (size_t)bus->status.ndevices * sizeof(*devices));
	memcpy(load, bus->status.slot_load, (size_t)bus->status.slots_per_block * sizeof(*load));
	pthread_mutex_unlock(&bus->status_lock);
	memcpy(out->host_addr, bus->host_addr, sizeof(out->host_addr));
	/* What a driver's worker lost (workers.c), added by the reader: not
	 * the bus thread's work. The workers' table lives as long as the bus. */
	for (i = 0; bus->workers && i < bus->nworkers_max; i++)
		out->counters.events_lost += atomic_load_explicit(&bus->workers[i].events_lost, memory_order_relaxed);
}
