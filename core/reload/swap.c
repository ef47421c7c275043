/* Hot reload on the bus thread (docs/DRIVERS.md "Hot reload"): a new
 * instance takes over a machine at a slot boundary, is on probation for a
 * while, and the old one takes over again if it fails; deploy.c drives it
 * from an HTTP thread through the request slots. */
#include "../host/bus_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <ev.h>
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

/* The version on probation failed (why): the instance it took over from
 * takes over again from it. 0, or -1 when that fails too (m->drv is still
 * the failed one; the caller drops the machine). */
int bus_roll_back(struct vmac_bus *bus, struct machine *m, const char *why)
{
	char err[VMAC_DRIVER_ERR_MAX];
	struct vmac_driver *failed = m->drv, *prev = m->prev;
	struct device *primary = &bus->dev[m->primary];
	struct vmac_bus_msg msg;
	m->prev = NULL;
	bus_give_boards(bus, m, prev);
	if (vmac_driver_take_over(prev, failed, bus_time(bus), err, sizeof(err)) != 0) {
		bus_event(bus, primary, "driver_error", "%s: rolling back to driver %s %s failed too: %s",
		          primary->ann.board, m->driver, vmac_driver_version(prev), err);
		bus_unload(bus, prev);
		return -1;
	}
	m->drv = prev;
	bus_rec_swap(bus, m);
	memset(&msg, 0, sizeof(msg));
	msg.kind = VMAC_MSG_EVENT;
	msg.time_ns = bus_now(bus);
	memcpy(msg.device, primary->ann.board, sizeof(msg.device));
	memcpy(msg.driver, m->driver, sizeof(msg.driver));
	snprintf(msg.event_kind, sizeof(msg.event_kind), "rolled_back");
	msg.code = VMAC_EVENT_ROLLED_BACK;
	msg.version_id = vmac_driver_tag(failed);
	snprintf(msg.text, sizeof(msg.text), "%s: driver %s %s failed on probation and was rolled back to %s: %.400s",
	         primary->ann.board, m->driver, vmac_driver_version(failed), vmac_driver_version(prev), why);
	bus_post(bus, &msg);
	bus_unload(bus, failed);
	return 0;
}

/* Hot reload at this slot boundary (between two ticks): nd takes over the
 * machine named device from the instance running it. 0 done (nd is the
 * bus's); else nd is still the caller's and has not run, or ran only its
 * attach/migrate, and reply says why: -VMAC_ENOTRUNNING (no running
 * machine of that name), -VMAC_EREFUSED (it would not take nd). */
int bus_swap(struct vmac_bus *bus, const char *device, struct vmac_driver *nd, int64_t probation_ns, char *reply,
             size_t replylen)
{
	char err[VMAC_DRIVER_ERR_MAX];
	struct device *d = bus_find_by_name(bus, device);
	struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	struct vmac_driver *od;
	if (!m || !m->drv || !m->attached || d->state != DEV_RUNNING || bus->stopping) {
		snprintf(reply, replylen, "%s is not running (%s)", device,
		         d ? bus_state_name(d->state) : "no such device");
		return -VMAC_ENOTRUNNING;
	}
	if (strcmp(vmac_driver_name(nd), m->driver) != 0) {
		snprintf(reply, replylen, "%s runs driver %s, not %s", device, m->driver, vmac_driver_name(nd));
		return -VMAC_EREFUSED;
	}
	bus_bind_driver(m, nd);
	bus_give_boards(bus, m, nd);
	od = m->drv;
	if (vmac_driver_take_over(nd, od, bus_time(bus), err, sizeof(err)) != 0) {
		snprintf(reply, replylen, "the new version failed to take over %s: %s", device, err);
		bus_event(bus, d, "reload_refused", "%s: driver %s %s not taken: %s", device, m->driver,
		          vmac_driver_version(nd), err);
		return -VMAC_EREFUSED;
	}
	m->drv = nd;
	bus_rec_swap(bus, m);
	/* Said before od is handed over: the main thread may free it at once. */
	bus_event(bus, &bus->dev[m->primary], "reloaded",
	          "%s: driver %s %s -> %s at a slot boundary (probation %.3g s)", bus->dev[m->primary].ann.board,
	          m->driver, vmac_driver_version(od), vmac_driver_version(nd), (double)probation_ns / 1e9);
	snprintf(reply, replylen, "%s: driver %s %s -> %s", device, m->driver, vmac_driver_version(od),
	         vmac_driver_version(nd));
	if (m->prev) /* a version still on probation: the one just replaced is what a rollback goes back to */
		bus_unload(bus, m->prev);
	m->prev = NULL;
	if (probation_ns > 0) {
		m->prev = od;
		m->probation_end_ns = bus_now(bus) + probation_ns;
	} else {
		bus_unload(bus, od);
	}
	return 0;
}

/* Versions whose probation is over keep the machine: the previous
 * instance goes. */
void bus_end_probations(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct machine *m = &bus->mach[i];
		if (!m->used || !m->prev || now < m->probation_end_ns)
			continue;
		bus_unload(bus, m->prev);
		m->prev = NULL;
		bus_event(bus, &bus->dev[m->primary], "probation_passed", "%s: driver %s %s passed its probation",
		          bus->dev[m->primary].ann.board, m->driver, vmac_driver_version(m->drv));
	}
}
