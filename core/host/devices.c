/* Devices and machines on the bus thread: a board announcing itself,
 * admission to the schedule, its machine's driver loaded (by the main
 * thread) and run on its primary's reply, and the error policy: a device
 * that misses its deadline or whose driver fails is dropped, its boards
 * told to go safe, and the others never notice. */
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

static int hook_set_level(void *ctx, unsigned level, char *err, size_t errlen);
static void hook_event(void *ctx, const char *text);

/* Hand a driver to the main thread to close (closing a Lua state is slow). */
void bus_unload(struct vmac_bus *bus, struct vmac_driver *drv)
{
	struct vmac_bus_msg m;
	if (!drv)
		return;
	memset(&m, 0, sizeof(m));
	m.kind = VMAC_MSG_UNLOAD;
	m.drv = drv;
	if (vmac_ring_push(&bus->to_main, &m) != 0) {
		/* The main thread is far behind; closing here is slow but safe. */
		vmac_driver_free(m.drv);
		return;
	}
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
}

/* ---- the error policy ---- */

uint32_t bus_slot_of(const struct vmac_bus *bus, const struct device *d)
{
	return (uint32_t)(d - bus->dev);
}

void bus_unschedule(struct vmac_bus *bus, struct device *d)
{
	if (d->scheduled)
		vmac_sched_remove(bus->sched, bus_slot_of(bus, d));
	d->scheduled = 0;
}

/* One board out of service: told to go safe (SLEEP after a driver failure:
 * the same safe state plus a back-off before the driver is tried again),
 * taken off the schedule, errant until it announces itself again. The
 * command is a courtesy, not awaited: the board's watchdog does the same. */
static void set_aside(struct vmac_bus *bus, struct device *d, uint8_t reason)
{
	d->pending = 0;
	bus_unschedule(bus, d);
	if (reason == VMAC_SHUT_DRIVER) {
		struct vmac_msg m;
		memset(&m, 0, sizeof(m));
		m.op = VMAC_OP_SLEEP;
		m.u.sleep_s = (uint16_t)bus->cfg.sleep_s;
		bus_queue(bus, d, &m, 0);
	} else {
		bus_send_shutdown(bus, d, reason, 0);
	}
	d->courtesy_seq = d->seq;
	d->state = DEV_ERRANT;
	d->mach = -1;
}

void bus_free_machine(struct vmac_bus *bus, struct machine *m)
{
	bus_rec_release(bus, m);
	bus_unload(bus, m->drv);
	bus_unload(bus, m->prev);
	memset(m, 0, sizeof(*m));
}

/* Drop d, and with it every other board of its machine: a machine with a
 * board missing is not safe to run. */
void bus_drop(struct vmac_bus *bus, struct device *d, uint8_t reason, const char *kind, const char *why)
{
	bus_event(bus, d, kind, "%s dropped: %s", d->ann.board, why);
	if (d->mach >= 0)
		bus_rec_failure(bus, &bus->mach[d->mach], VMAC_REC_DROP, why);
	bus->counters.drops++;
	if (d->mach >= 0) {
		int mi = d->mach;
		uint32_t i;
		for (i = 0; i < bus->nused; i++) {
			struct device *o = &bus->dev[i];
			if (o == d || o->mach != mi || o->state == DEV_FREE)
				continue;
			if (o->state == DEV_LOADING) {
				o->state = DEV_ERRANT;
				o->mach = -1;
				continue;
			}
			bus_event(bus, o, kind, "%s dropped: %s, a board of the same machine, was dropped",
			          o->ann.board, d->ann.board);
			bus->counters.drops++;
			set_aside(bus, o, reason);
		}
		bus_free_machine(bus, &bus->mach[mi]);
	}
	set_aside(bus, d, reason);
}

void bus_miss(struct vmac_bus *bus, struct device *d, const char *fmt_why)
{
	d->misses++;
	d->consecutive_misses++;
	bus->counters.misses++;
	bus_rec_miss(bus, d, fmt_why);
	if (d->unsent) {
		d->misses_host++;
		bus->counters.misses_host++;
	}
	if (d->consecutive_misses >= bus->cfg.miss_limit || d->state != DEV_RUNNING)
		bus_drop(bus, d, VMAC_SHUT_DROPPED, "dropped", fmt_why);
}

void bus_check_deadlines(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		char why[200];
		if (!d->pending || d->sent_ns == 0 || now - d->sent_ns <= d->reply_window_ns)
			continue;
		d->pending = 0;
		d->missed_seq = d->seq;
		if (bus->stopping)
			continue;
		snprintf(why, sizeof(why), "no reply to %s seq %u within %.3g ms (sent at %lld ns)%s",
		         vmac_proto_opname(VMAC_CH_DEVICE, d->pending_op), (unsigned)d->seq,
		         (double)d->reply_window_ns / 1e6, (long long)d->sent_ns,
		         d->unsent ? "; the host's fault: the kernel refused the request" : "");
		bus_miss(bus, d, why);
	}
}

static struct device *find_by_identity(struct vmac_bus *bus, const struct vmac_announce *a)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->state != DEV_FREE && d->ann.major == a->major && d->ann.minor == a->minor &&
		    strcmp(d->ann.driver, a->driver) == 0)
			return d;
	}
	return NULL;
}

static struct device *new_slot(struct vmac_bus *bus)
{
	uint32_t i;
	struct device *oldest = NULL;
	for (i = 0; i < bus->ndev; i++)
		if (bus->dev[i].state == DEV_FREE)
			return &bus->dev[i];
	/* Full: reuse the errant device not heard of for the longest. */
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->state == DEV_ERRANT && (!oldest || d->last_seen_ns < oldest->last_seen_ns))
			oldest = d;
	}
	return oldest;
}

/* The comm-loss period a board at this level is given: the configured one,
 * or three service periods when that is longer. */
static uint16_t watchdog_for(const struct vmac_bus *bus, unsigned level)
{
	int64_t ms = (bus->slot_ns << level) * 3 / 1000000;
	if (ms < bus->cfg.watchdog_ms)
		ms = bus->cfg.watchdog_ms;
	return (uint16_t)(ms > 60000 ? 60000 : ms);
}

/* Admit board d of machine m to the schedule and to the driver. */
static int admit(struct vmac_bus *bus, struct machine *m, struct device *d)
{
	char why[200];
	if (m->nboards == VMAC_DRIVER_MAX_BOARDS || vmac_driver_add_board(m->drv, d->ann.minor, d->ann.board) != 0) {
		snprintf(d->note, sizeof(d->note), "machine full: at most %d boards per machine",
		         VMAC_DRIVER_MAX_BOARDS);
		bus_event(bus, d, "machine_full", "%s not attached: %s", d->ann.board, d->note);
		return -1;
	}
	if (vmac_sched_add(bus->sched, bus_slot_of(bus, d), m->level, why, sizeof(why)) != 0) {
		snprintf(d->note, sizeof(d->note), "%s", why);
		bus->counters.schedule_full++;
		bus_event(bus, d, "schedule_full", "%s not attached: %s", d->ann.board, why);
		return -1;
	}
	d->scheduled = 1;
	m->board[m->nboards++] = bus_slot_of(bus, d);
	d->state = DEV_REGISTERING;
	d->reg_step = REG_REGISTER;
	d->register_sent = 0;
	d->watchdog_ms = watchdog_for(bus, m->level);
	d->want_watchdog = 0;
	d->note[0] = 0;
	return 0;
}

/* No driver, or no room: every board of machine mi is told to sleep. */
static void machine_to_sleep(struct vmac_bus *bus, int mi)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->mach != mi)
			continue;
		bus_unschedule(bus, d);
		d->mach = -1;
		d->pending = 0;
		d->register_sent = 0;
		d->state = DEV_TO_SLEEP;
	}
	bus_free_machine(bus, &bus->mach[mi]);
}

static int find_machine(const struct vmac_bus *bus, const char *driver, uint32_t major)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++)
		if (bus->mach[i].used && bus->mach[i].major == major && strcmp(bus->mach[i].driver, driver) == 0)
			return (int)i;
	return -1;
}

/* A new board: join its machine if there is one, else start a machine and
 * ask the main thread for the driver. */
static void join_or_load(struct vmac_bus *bus, struct device *d)
{
	struct vmac_bus_msg load;
	int mi = find_machine(bus, d->ann.driver, d->ann.major);
	struct machine *m;
	if (mi >= 0) {
		m = &bus->mach[mi];
		d->mach = mi;
		if (m->drv && admit(bus, m, d) != 0) { /* else joins when the driver arrives */
			d->mach = -1;
			d->state = DEV_TO_SLEEP;
		}
		return;
	}
	for (mi = 0; mi < (int)bus->ndev && bus->mach[mi].used; mi++)
		;
	m = &bus->mach[mi]; /* never full: at most one machine per device */
	memset(m, 0, sizeof(*m));
	m->used = 1;
	m->bus = bus;
	memcpy(m->driver, d->ann.driver, sizeof(m->driver));
	m->major = d->ann.major;
	m->primary = bus_slot_of(bus, d);
	d->mach = mi;

	memset(&load, 0, sizeof(load));
	load.kind = VMAC_MSG_LOAD;
	load.slot = bus_slot_of(bus, d);
	load.generation = d->generation;
	memcpy(load.device, d->ann.board, sizeof(load.device));
	memcpy(load.driver, d->ann.driver, sizeof(load.driver));
	if (bus_post(bus, &load) != 0) {
		/* The main thread is behind (a crowd announcing at once): nothing
		 * waits for a load that was never asked for. The board is still
		 * unknown and announces again at the next discovery. */
		m->used = 0;
		d->mach = -1;
		d->state = DEV_ERRANT;
		snprintf(d->note, sizeof(d->note),
		         "host busy: its driver load is asked for again at its next announce");
	}
}

void bus_on_announce(struct vmac_bus *bus, const struct vmac_msg *m, const struct vmac_packet *p)
{
	struct device *d = find_by_identity(bus, &m->u.announce);

	bus->counters.announces++;
	if (d) {
		switch (d->state) {
		case DEV_LOADING: d->addr = p->addr; return;
		case DEV_REGISTERING:
		case DEV_RUNNING:
		case DEV_TO_SLEEP:
			/* The board has lost our session (reset, or its watchdog ran out). */
			bus_drop(bus, d, VMAC_SHUT_DROPPED, "dropped",
			         "board announced itself again (it lost its session)");
			break;
		default: break;
		}
	} else {
		d = new_slot(bus);
		if (!d) {
			bus->counters.table_full++;
			return;
		}
	}
	if (bus_slot_of(bus, d) >= bus->nused)
		bus->nused = bus_slot_of(bus, d) + 1;
	d->ann = m->u.announce;
	d->version = m->version;
	d->cyclic = m->version >= 2 && bus->cfg.cyclic;
	d->addr = p->addr;
	/* Never 0: a CYCLIC record's tag is the generation, and tag 0 is empty. */
	d->generation = (uint16_t)(d->generation + 1) ? (uint16_t)(d->generation + 1) : 1;
	d->id = (uint32_t)d->generation << 16 | bus_slot_of(bus, d);
	d->state = DEV_LOADING;
	d->pending = 0;
	d->register_sent = 0;
	d->consecutive_misses = 0;
	d->last_seen_ns = p->rx_ns;
	d->mach = -1;
	d->note[0] = 0;
	memset(&d->outputs, 0, sizeof(d->outputs));
	memset(&d->inputs, 0, sizeof(d->inputs));
	join_or_load(bus, d);
}

/* Bind drv to machine m (dev:set_level, dev:event). */
void bus_bind_driver(struct machine *m, struct vmac_driver *drv)
{
	struct vmac_driver_host host;
	host.set_level = hook_set_level;
	host.event = hook_event;
	host.ctx = m;
	vmac_driver_bind(drv, &host);
}

/* Hand drv every board of m it does not have yet (in m's order) and m's
 * level. */
void bus_give_boards(struct vmac_bus *bus, struct machine *m, struct vmac_driver *drv)
{
	int i;
	for (i = vmac_driver_boards(drv); i < m->nboards; i++) {
		const struct device *b = &bus->dev[m->board[i]];
		vmac_driver_add_board(drv, b->ann.minor, b->ann.board);
	}
	vmac_driver_set_level_now(drv, m->level);
}

/* m's driver failed in a call (where: "", " in input", ...): a version on
 * probation rolls back; otherwise, or if that fails, the machine is
 * dropped (every board to its safe state). */
void bus_driver_failed(struct vmac_bus *bus, struct machine *m, const char *where, const char *err)
{
	struct device *primary = &bus->dev[m->primary];
	bus_event(bus, primary, "driver_error", "%s: driver %s %s failed%s: %s", primary->ann.board, m->driver,
	          vmac_driver_version(m->drv), where, err);
	bus_rec_failure(bus, m, VMAC_REC_ERROR, err);
	if (m->prev) {
		int64_t tag = vmac_driver_tag(m->drv);
		uint32_t i;
		if (bus_roll_back(bus, m, err) == 0) {
			char why[VMAC_REC_TEXT_MAX + 1];
			snprintf(why, sizeof(why), "rolled back: %s", err);
			bus_rec_capture(bus, m, why); /* the failing version's last seconds; the machine runs on */
			/* One version everywhere: every other machine on probation
			 * with the same version goes back too. */
			for (i = 0; i < bus->nused; i++) {
				struct machine *o = &bus->mach[i];
				if (o == m || !o->used || !o->prev || vmac_driver_tag(o->drv) != tag ||
				    strcmp(o->driver, m->driver) != 0)
					continue;
				if (bus_roll_back(bus, o, "the same version failed on another machine") != 0)
					bus_drop(bus, &bus->dev[o->primary], VMAC_SHUT_DRIVER, "dropped",
					         "its driver failed");
			}
			return;
		}
	}
	bus_drop(bus, primary, VMAC_SHUT_DRIVER, "dropped", "its driver failed");
}

/* The machine's tick, on its primary board's reply. */
void bus_run_machine(struct vmac_bus *bus, struct machine *m)
{
	char err[VMAC_DRIVER_ERR_MAX];
	const struct vmac_inputs *in[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs *out[VMAC_DRIVER_MAX_BOARDS];
	int64_t now = bus_now(bus), t_ns = now - bus->start_ns; /* bus time: the driver's inputs.time */
	int i, rc;
	for (i = 0; i < m->nboards; i++) {
		in[i] = &bus->dev[m->board[i]].inputs;
		out[i] = &bus->dev[m->board[i]].outputs;
	}
	rc = vmac_driver_tick(m->drv, (double)t_ns / 1e9, in, out, err, sizeof(err));
	bus_rec_tick(bus, m, t_ns); /* a failed tick too: its inputs replay the failure */
	if (rc == 0) {
		bus_checkpoint_due(bus, m, now);
		return;
	}
	bus_driver_failed(bus, m, "", err);
}

/* The bus's side of dev:set_level and dev:bus_event (struct vmac_driver_host). */
static int hook_set_level(void *ctx, unsigned level, char *err, size_t errlen)
{
	struct machine *m = ctx;
	struct vmac_bus *bus = m->bus;
	unsigned old = m->level;
	int i, j;
	if (level == old)
		return 0;
	for (i = 0; i < m->nboards; i++)
		if (vmac_sched_set_level(bus->sched, m->board[i], level, err, errlen) != 0) {
			for (j = 0; j < i; j++)
				vmac_sched_set_level(bus->sched, m->board[j], old, NULL, 0);
			return -1;
		}
	m->level = level;
	vmac_driver_set_level_now(m->drv, level);
	bus_rec_level(bus, m, level);
	for (i = 0; i < m->nboards; i++) {
		struct device *d = &bus->dev[m->board[i]];
		uint16_t wd = watchdog_for(bus, level);
		if (wd > d->watchdog_ms)
			d->want_watchdog = wd; /* sent before its next UPDATE */
	}
	bus_event(bus, &bus->dev[m->primary], "level", "%s: level %u -> %u (period %.6g ms)", m->driver, old, level,
	          (double)(bus->slot_ns << level) / 1e6);
	return 0;
}

static void hook_event(void *ctx, const char *text)
{
	struct machine *m = ctx;
	bus_event(m->bus, &m->bus->dev[m->primary], "driver", "%s", text);
}

/* The main thread has loaded (or failed to load) the driver of the machine
 * whose primary is d. */
void bus_on_loaded(struct vmac_bus *bus, struct device *d, const struct vmac_host_cmd *c)
{
	int mi = d->mach;
	struct machine *m = &bus->mach[mi];
	uint32_t i;
	if (!c->drv) {
		bus_event(bus, d, c->missing ? "driver_missing" : "driver_error", "%s", c->text);
		bus_event(bus, d, "sleeping", "%s told to sleep for %u s: no usable driver '%s'", d->ann.board,
		          (unsigned)bus->cfg.sleep_s, d->ann.driver);
		snprintf(d->note, sizeof(d->note), "%s", c->text);
		machine_to_sleep(bus, mi);
		return;
	}
	m->drv = c->drv;
	m->rec = c->rec;
	m->level = vmac_driver_level(c->drv);
	bus_bind_driver(m, m->drv);
	if (admit(bus, m, d) != 0) {
		char note[sizeof(d->note)];
		memcpy(note, d->note, sizeof(note));
		bus_event(bus, d, "sleeping", "%s told to sleep for %u s: %s", d->ann.board, (unsigned)bus->cfg.sleep_s,
		          note);
		machine_to_sleep(bus, mi);
		memcpy(d->note, note, sizeof(note));
		return;
	}
	for (i = 0; i < bus->nused; i++) { /* boards that announced while the driver loaded */
		struct device *o = &bus->dev[i];
		if (o != d && o->mach == mi && o->state == DEV_LOADING && admit(bus, m, o) != 0) {
			o->mach = -1;
			o->state = DEV_TO_SLEEP;
		}
	}
}

struct device *bus_find_by_name(struct vmac_bus *bus, const char *name)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++)
		if (bus->dev[i].state != DEV_FREE && strcmp(bus->dev[i].ann.board, name) == 0)
			return &bus->dev[i];
	return NULL;
}
