/* Hot reload on the bus thread (docs/DRIVERS.md "Hot reload"): a new
 * instance takes over a machine at a slot boundary (a job on the machine's
 * driver worker, between two of its ticks), is on probation for a while,
 * and the old one takes over again if it fails; core/reload/deploy.c drives it from an
 * HTTP thread through the request slots. */
#include "bus_internal.h"

#include <stdio.h>
#include <string.h>

#include "../common/errors.h"

int bus_roll_back(struct vmac_bus *bus, struct machine *m, const char *why)
{
	(void)bus;
	if (!m->prev)
		return -1;
	m->want_rollback = 1;
	snprintf(m->rollback_why, sizeof(m->rollback_why), "%s", why);
	return 0;
}

/* The roll-back job ran (j->drv, the previous version, took over from
 * j->other, the one that failed): the machine runs on the previous version,
 * or, if that failed too, is dropped. */
void bus_rolled_back(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	struct vmac_driver *failed = j->other, *prev = j->drv;
	struct device *primary = &bus->dev[m->primary];
	char why[VMAC_REC_TEXT_MAX + 1], text[VMAC_EVENT_TEXT];
	int64_t tag = vmac_driver_tag(failed);
	uint32_t i;
	m->prev = NULL;
	if (j->rc != 0) {
		bus_event(bus, primary, "driver_error", "%s: rolling back to driver %s %s failed too: %s",
		          primary->ann.board, m->driver, vmac_driver_version(prev), j->err);
		bus_unload(bus, prev);
		bus_drop(bus, primary, VMAC_SHUT_DRIVER, "dropped", "its driver failed");
		return;
	}
	/* The failing version's seconds, its recording named after it (and the
	 * tick it took over at); the machine runs on with a new recorder. */
	snprintf(why, sizeof(why), "rolled back: %s", m->rollback_why);
	bus_rec_capture(bus, m, why);
	m->drv = prev;
	bus_timing_set(bus, m, m->level, NULL, 0); /* its own pattern again */
	snprintf(text, sizeof(text), "%s: driver %s %s failed on probation and was rolled back to %s: %.400s",
	         primary->ann.board, m->driver, vmac_driver_version(failed), vmac_driver_version(prev),
	         m->rollback_why);
	bus_post_code(bus, VMAC_EVENT_ROLLED_BACK, m, vmac_driver_version(failed), tag, "rolled_back", text);
	bus_unload(bus, failed);
	/* One version everywhere: every other machine on probation with the
	 * same version goes back too. */
	for (i = 0; i < bus->nused; i++) {
		struct machine *o = &bus->mach[i];
		if (o == m || !o->used || !o->prev || vmac_driver_tag(o->drv) != tag ||
		    strcmp(o->driver, m->driver) != 0)
			continue;
		bus_roll_back(bus, o, "the same version failed on another machine"); /* when its job is free */
	}
}

/* Hot reload, swap request slot i: nd takes over the machine named device
 * at a slot boundary. Refused at once (answered; nd still the caller's):
 * -VMAC_ENOTRUNNING (no running machine of that name), -VMAC_EREFUSED (it
 * runs another driver); else the machine's job does it (bus_swapped). */
void bus_swap(struct vmac_bus *bus, int i)
{
	struct request *q = &bus->req[i];
	char device[VMAC_NAME_MAX + 1];
	struct machine *m;
	struct device *d = bus_request_target(bus, i, device, &m);
	if (!m || !m->drv || !m->attached || d->state != DEV_RUNNING || bus->stopping || m->want_swap) {
		snprintf(q->r.reply, sizeof(q->r.reply), "%s is not running (%s)", device,
		         !d                  ? "no such device"
		         : m && m->want_swap ? "another reload is under way"
		                             : bus_state_name(d->state));
		q->r.rc = -VMAC_ENOTRUNNING;
	} else if (strcmp(vmac_driver_name(q->drv), m->driver) != 0) {
		snprintf(q->r.reply, sizeof(q->r.reply), "%s runs driver %s, not %s", device, m->driver,
		         vmac_driver_name(q->drv));
		q->r.rc = -VMAC_EREFUSED;
	} else {
		m->want_swap = i + 1;
		bus_dispatch(bus, m);
		return;
	}
	bus_answer(bus, i);
}

/* The swap job ran: j->other took over from j->drv, or refused. */
void bus_swapped(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	struct request *q = &bus->req[j->req];
	struct vmac_driver *nd = j->other, *od = j->drv;
	struct device *primary = &bus->dev[m->primary];
	char err[200];
	if (j->rc != 0) {
		snprintf(q->r.reply, sizeof(q->r.reply), "the new version failed to take over %s: %s",
		         primary->ann.board, j->err);
		bus_event(bus, primary, "reload_refused", "%s: driver %s %s not taken: %s", primary->ann.board,
		          m->driver, vmac_driver_version(nd), j->err);
		q->r.rc = -VMAC_EREFUSED; /* nd is the caller's again */
		bus_answer(bus, j->req);
		j->req = -1;
		return;
	}
	m->drv = nd;
	if (bus_timing_set(bus, m, m->level, err, sizeof(err)) != 0)
		bus_event(bus, primary, "warning", "%s: driver %s %s acts on arrival: %s", primary->ann.board,
		          m->driver, vmac_driver_version(nd), err);
	bus_rec_swap(bus, m);
	/* Said before od is handed over: the main thread may free it at once. */
	bus_event(bus, primary, "reloaded", "%s: driver %s %s -> %s at a slot boundary (probation %.3g s)",
	          primary->ann.board, m->driver, vmac_driver_version(od), vmac_driver_version(nd),
	          (double)q->probation_ns / 1e9);
	snprintf(q->r.reply, sizeof(q->r.reply), "%s: driver %s %s -> %s", primary->ann.board, m->driver,
	         vmac_driver_version(od), vmac_driver_version(nd));
	if (m->prev) /* a version still on probation: the one just replaced is what a rollback goes back to */
		bus_unload(bus, m->prev);
	m->prev = NULL;
	if (q->probation_ns > 0) {
		m->prev = od;
		m->probation_end_ns = bus_now(bus) + q->probation_ns;
	} else {
		bus_unload(bus, od);
	}
	q->r.rc = 0;
	bus_answer(bus, j->req);
	j->req = -1;
}

/* Versions whose probation is over keep the machine: the previous
 * instance goes (unless a job holds it: a roll-back under way). */
void bus_end_probations(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct machine *m = &bus->mach[i];
		if (!m->used || !m->prev || now < m->probation_end_ns || m->want_rollback || !bus_machine_idle(bus, m))
			continue;
		bus_unload(bus, m->prev);
		m->prev = NULL;
		bus_event(bus, &bus->dev[m->primary], "probation_passed", "%s: driver %s %s passed its probation",
		          bus->dev[m->primary].ann.board, m->driver, vmac_driver_version(m->drv));
	}
}
