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
#include "../proto/auth.h"
#include "../sched/sched.h"

/* Hand a driver (or a machine's checkpoint buffer) to the main thread to
 * free (closing a Lua state is slow). */
static void unload(struct vmac_bus *bus, struct vmac_driver *drv, void *buf)
{
	struct vmac_bus_msg m;
	if (!drv && !buf)
		return;
	memset(&m, 0, sizeof(m));
	m.kind = VMAC_MSG_UNLOAD;
	m.drv = drv;
	m.buf = buf;
	if (vmac_ring_push(&bus->to_main, &m) != 0) {
		/* The main thread is far behind; closing here is slow but safe (the
		 * instance runs no Lua: lua_close frees it). */
		vmac_driver_free(m.drv);
		free(buf);
		return;
	}
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
}

void bus_unload(struct vmac_bus *bus, struct vmac_driver *drv)
{
	unload(bus, drv, NULL);
}

void bus_unload_buffer(struct vmac_bus *bus, void *buf)
{
	unload(bus, NULL, buf);
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

/* Everything waiting for m's job is answered: m is going away. */
static void refuse_waiting(struct vmac_bus *bus, struct machine *m)
{
	int i;
	for (i = 0; i < m->ninputs; i++) {
		struct request *q = &bus->req[m->inputs[i]];
		q->r.rc = -VMAC_ENOTRUNNING;
		snprintf(q->r.reply, sizeof(q->r.reply), "the %s machine is not running (dropped)", m->driver);
		bus_answer(bus, m->inputs[i]);
	}
	m->ninputs = 0;
	if (m->want_swap) { /* the new instance is still the caller's */
		struct request *q = &bus->req[m->want_swap - 1];
		q->r.rc = -VMAC_ENOTRUNNING;
		snprintf(q->r.reply, sizeof(q->r.reply), "the %s machine is not running (dropped)", m->driver);
		bus_answer(bus, m->want_swap - 1);
		m->want_swap = 0;
	}
}

/* m's job is given up (a worker still inside it disposes of the instances
 * it holds); everything else of m goes to the main thread. */
void bus_free_machine(struct vmac_bus *bus, struct machine *m)
{
	struct job *j = &bus->jobs[m - bus->mach];
	struct vmac_driver *jdrv, *jother;
	int held = bus_job_release(bus, m, &jdrv, &jother);
	refuse_waiting(bus, m);
	bus_rec_release(bus, m);
	if (!held || (m->drv != jdrv && m->drv != jother))
		bus_unload(bus, m->drv);
	if (!held || (m->prev != jdrv && m->prev != jother))
		bus_unload(bus, m->prev);
	if (!held) { /* held: the job is the worker's, and so is what it holds */
		bus_unload_buffer(bus, j->ckpt);
		j->ckpt = NULL;
		j->drv = j->other = NULL;
		j->req = -1;
	}
	if (m->worker >= 0 && bus->workers)
		bus->workers[m->worker].nmach--;
	memset(m, 0, sizeof(*m));
	m->worker = -1;
}

/* Drop d, and with it every other board of its machine: a machine with a
 * board missing is not safe to run. */
void bus_drop(struct vmac_bus *bus, struct device *d, uint8_t reason, const char *kind, const char *why)
{
	bus_event(bus, d, kind, "%s dropped: %s", d->ann.board, why);
	if (d->mach >= 0)
		bus_rec_failure(bus, &bus->mach[d->mach], VMAC_REC_DROP, why);
	bus->counters.drops++;
	d->drops++;
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
			o->drops++;
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
	d->violated_ns = bus_now(bus);
	d->violated = VMAC_VIOLATION_MISS;
	if (d->unsent) {
		d->misses_host++;
		bus->counters.misses_host++;
		d->violated = VMAC_VIOLATION_MISS_HOST;
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
		if (d->state == DEV_WAITING &&
		    now - d->last_seen_ns > 3 * (int64_t)bus->cfg.discovery_period_ms * 1000000) {
			d->state = DEV_FREE; /* gone (or enrolled under another entry): no longer listed */
			continue;
		}
		if (!d->pending || d->sent_ns == 0 || now - bus_deadline_from(d) <= d->reply_window_ns)
			continue;
		d->pending = 0;
		d->missed_seq = d->seq;
		if (bus->stopping)
			continue;
		snprintf(why, sizeof(why), "no reply to %s seq %u within %.3g ms (sent at %lld ns%s)%s",
		         vmac_proto_opname(VMAC_CH_DEVICE, d->pending_op), (unsigned)d->seq,
		         (double)d->reply_window_ns / 1e6, (long long)d->sent_ns,
		         d->in_at_ns > d->sent_ns ? ", the deadline from its in_at" : "",
		         d->unsent ? "; the host's fault: the kernel refused the request" : "");
		bus_miss(bus, d, why);
	}
}

/* The device of this identity (driver, major, minor), a board waiting
 * for approval aside. */
static struct device *find_by_identity(struct vmac_bus *bus, const struct vmac_announce *a)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->state != DEV_FREE && d->state != DEV_WAITING && d->ann.major == a->major &&
		    d->ann.minor == a->minor && strcmp(d->ann.driver, a->driver) == 0)
			return d;
	}
	return NULL;
}

static struct device *find_waiting(struct vmac_bus *bus, const char *board)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++)
		if (bus->dev[i].state == DEV_WAITING && strcmp(bus->dev[i].ann.board, board) == 0)
			return &bus->dev[i];
	return NULL;
}

/* The device of state st not heard of for the longest (NULL: none); with
 * count, how many are in st. */
static struct device *oldest_in(struct vmac_bus *bus, enum dev_state st, uint32_t *count)
{
	struct device *oldest = NULL;
	uint32_t i, n = 0;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->state != st)
			continue;
		n++;
		if (!oldest || d->last_seen_ns < oldest->last_seen_ns)
			oldest = d;
	}
	if (count)
		*count = n;
	return oldest;
}

static struct device *new_slot(struct vmac_bus *bus)
{
	uint32_t i;
	struct device *d;
	for (i = 0; i < bus->ndev; i++)
		if (bus->dev[i].state == DEV_FREE)
			return &bus->dev[i];
	/* Full: reuse the board waiting for approval, else the errant device,
	 * not heard of for the longest. */
	d = oldest_in(bus, DEV_WAITING, NULL);
	return d ? d : oldest_in(bus, DEV_ERRANT, NULL);
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
	int i;
	for (i = 0; i < m->nboards; i++)
		if (bus->dev[m->board[i]].ann.minor == d->ann.minor)
			break;
	if (m->nboards == VMAC_DRIVER_MAX_BOARDS || i < m->nboards) {
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
	m->tick_in[m->nboards] = d->inputs; /* none yet: a tick asked for before its first reply */
	m->tick_sample_ns[m->nboards] = 0;
	m->board[m->nboards++] = bus_slot_of(bus, d);
	bus_rec_join(bus, m);
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
		} else {
			memcpy(d->last_machine, bus->dev[m->primary].ann.board, sizeof(d->last_machine));
		}
		return;
	}
	/* Below nused, where every loop over machines looks: at most one machine
	 * per device other than d. A slot whose job a worker still holds (given
	 * up) is skipped until the worker lets go. */
	for (mi = 0; mi < (int)bus->nused && (bus->mach[mi].used || !bus_machine_idle(bus, &bus->mach[mi])); mi++)
		;
	if (mi == (int)bus->nused) {
		d->mach = -1;
		d->state = DEV_ERRANT;
		snprintf(d->note, sizeof(d->note), "host busy: asked for again at its next announce");
		return;
	}
	m = &bus->mach[mi];
	memset(m, 0, sizeof(*m));
	m->used = 1;
	m->worker = -1;
	m->bus = bus;
	memcpy(m->driver, d->ann.driver, sizeof(m->driver));
	m->major = d->ann.major;
	m->primary = bus_slot_of(bus, d);
	d->mach = mi;
	memcpy(d->last_machine, d->ann.board, sizeof(d->last_machine));

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

#define FLOOD_WARN_NS 10000000000LL /* a flood or a full table is said at most this often */

/* Devices attaching: driver asked for, registration not yet answered. */
static uint32_t attaching(const struct vmac_bus *bus)
{
	uint32_t i, n = 0;
	for (i = 0; i < bus->nused; i++)
		n += bus->dev[i].state == DEV_LOADING || bus->dev[i].state == DEV_REGISTERING;
	return n;
}

/* May one more device attach now? At most attach_rate a second, in bursts
 * of attach_max, and attach_max at once: a flood of announcements (fake
 * boards, random identities) loads at most that many drivers. The credit
 * is checked first, so that a flood costs a scan of the table only
 * attach_rate times a second. */
static int attach_allowed(struct vmac_bus *bus, int64_t now)
{
	int64_t cost = 1000000000LL / bus->cfg.attach_rate, most = cost * bus->cfg.attach_max;
	if (!bus->attach_credit_set)
		bus->attach_credit_ns = most;
	else
		bus->attach_credit_ns += now - bus->attach_credit_at_ns;
	bus->attach_credit_set = 1;
	if (bus->attach_credit_ns > most)
		bus->attach_credit_ns = most;
	bus->attach_credit_at_ns = now;
	if (bus->attach_credit_ns < cost || attaching(bus) >= bus->cfg.attach_max)
		return 0;
	bus->attach_credit_ns -= cost;
	return 1;
}

/* What the limiter and the full table refused, said at most every
 * FLOOD_WARN_NS. */
static void say_flood(struct vmac_bus *bus, int64_t now)
{
	if (bus->flood_said_ns && now - bus->flood_said_ns < FLOOD_WARN_NS)
		return;
	if (bus->refused_unsaid)
		bus_event(bus, NULL, "flood",
		          "%llu announcements not let attach: at most %u devices attach at once and %u a second "
		          "(attach_max, attach_rate); they announce again at the next discovery",
		          (unsigned long long)bus->refused_unsaid, bus->cfg.attach_max, bus->cfg.attach_rate);
	if (bus->table_full_unsaid)
		bus_event(bus, NULL, "table_full",
		          "%llu announcements of new boards ignored: the device table is full (max_devices %u)",
		          (unsigned long long)bus->table_full_unsaid, bus->cfg.max_devices);
	bus->flood_said_ns = now;
	bus->refused_unsaid = bus->table_full_unsaid = 0;
}

static void refuse_attach(struct vmac_bus *bus, int64_t now)
{
	bus->counters.attach_refused++;
	bus->refused_unsaid++;
	say_flood(bus, now);
}

static void table_full(struct vmac_bus *bus, int64_t now)
{
	bus->counters.table_full++;
	bus->table_full_unsaid++;
	say_flood(bus, now);
}

/* Whether the announcement proves its board's enrolled key over this
 * discovery's nonce: 1 (*key set), 0 (no key enrolled for that name), -1
 * (an enrolled name, not proven: counted and said). */
static int proven(struct vmac_bus *bus, const struct vmac_msg *m, const struct vmac_packet *p, const uint8_t **key)
{
	*key = bus_key_of(bus, m->u.announce.board);
	if (!*key)
		return 0;
	if (!(m->flags & VMAC_FLAG_AUTH)) {
		bus_auth_failed(bus, p, m->u.announce.board,
		                "an enrolled board's announcement, not sealed (was the board given its key?)");
		return -1;
	}
	if (vmac_proto_open(p->data, p->len, *key, bus->nonce, VMAC_NONCE_LEN) != 0) {
		bus_auth_failed(bus, p, m->u.announce.board,
		                "its announcement does not prove the board's enrolled key (a forgery, an old "
		                "announcement replayed, or a board given another key)");
		return -1;
	}
	return 1;
}

/* bus_trust enrolled, and a board that proved no key: listed as waiting
 * for approval (an event says so once), given nothing. A flood of them
 * takes attach credit like any new board and holds at most attach_max
 * entries, the oldest replaced. */
static void hold_back(struct vmac_bus *bus, const struct vmac_msg *m, const struct vmac_packet *p)
{
	const struct vmac_announce *a = &m->u.announce;
	struct device *w = find_waiting(bus, a->board);
	char addr[48];
	int fresh = !w;
	bus->counters.waiting++;
	if (fresh) {
		uint32_t nwaiting;
		struct device *oldest;
		if (!attach_allowed(bus, p->rx_ns)) {
			refuse_attach(bus, p->rx_ns);
			return;
		}
		oldest = oldest_in(bus, DEV_WAITING, &nwaiting);
		w = nwaiting >= bus->cfg.attach_max ? oldest : new_slot(bus);
		if (!w) {
			table_full(bus, p->rx_ns);
			return;
		}
		w->last_machine[0] = 0; /* an entry of another board's, maybe */
	}
	if (bus_slot_of(bus, w) >= bus->nused)
		bus->nused = bus_slot_of(bus, w) + 1;
	w->ann = *a;
	w->version = m->version;
	w->addr = p->addr;
	w->last_seen_ns = p->rx_ns;
	w->state = DEV_WAITING;
	w->mach = -1;
	w->keyed = 0;
	w->pending = 0;
	w->id = 0;
	snprintf(w->note, sizeof(w->note),
	         (m->flags & VMAC_FLAG_AUTH) ? "waiting for approval: it announces with a key this host does not hold "
	                                       "(vmac board enroll %s --key-file ITS_KEY)"
	                                     : "waiting for approval: no key (vmac board enroll %s --out %s.key, then "
	                                       "give the board that key)",
	         a->board, a->board);
	if (fresh)
		bus_event(bus, w, "waiting", "%s (driver %s, major %u minor %u) at %s waits for approval: %s", a->board,
		          a->driver, (unsigned)a->major, (unsigned)a->minor,
		          vmac_addr_format(&p->addr, addr, sizeof(addr)), w->note + strlen("waiting for approval: "));
}

void bus_on_announce(struct vmac_bus *bus, const struct vmac_msg *m, const struct vmac_packet *p)
{
	const struct vmac_announce *a = &m->u.announce;
	const uint8_t *key;
	struct device *d;
	int pr;

	bus->counters.announces++;
	pr = proven(bus, m, p, &key);
	if (pr < 0)
		return;
	d = find_by_identity(bus, a);
	/* An enrolled board's identity is taken only by a board that proves
	 * its key under its name, whatever state it is in. */
	if (d && d->keyed && bus_key_of(bus, d->ann.board) && (!pr || strcmp(d->ann.board, a->board) != 0)) {
		bus->counters.takeover_refused++;
		bus_auth_failed(bus, p, a->board,
		                "announced the identity of an enrolled board without proving its key");
		return;
	}
	if (!pr && !vmac_config_trust_open(&bus->cfg)) {
		hold_back(bus, m, p);
		return;
	}
	/* This discovery's proof seen again: the board's own duplicate, or a
	 * copy of it replayed from elsewhere. */
	if (d && pr && d->proved_nonce == bus->nonce_count && d->state != DEV_ERRANT && d->state != DEV_SLEEPING) {
		if (!vmac_addr_equal(&d->addr, &p->addr))
			bus_auth_failed(bus, p, a->board,
			                "a replayed announcement (this discovery was answered already)");
		return;
	}
	if ((!d || d->state != DEV_LOADING) && !attach_allowed(bus, p->rx_ns)) {
		refuse_attach(bus, p->rx_ns);
		return;
	}
	if (d) {
		switch (d->state) {
		case DEV_LOADING:
			/* It answered a later discovery while its driver loads: its
			 * session is made from that one's nonce. */
			d->addr = p->addr;
			if (pr) {
				bus_session_keys(bus, d, key);
				d->proved_nonce = bus->nonce_count;
			}
			return;
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
		d = find_waiting(bus, a->board); /* approved since: its entry is the board's */
		if (!d)
			d = new_slot(bus);
		if (!d) {
			table_full(bus, p->rx_ns);
			return;
		}
		d->last_machine[0] = 0;
	}
	if (bus_slot_of(bus, d) >= bus->nused)
		bus->nused = bus_slot_of(bus, d) + 1;
	d->ann = m->u.announce;
	d->version = m->version;
	d->cyclic = m->version >= 2 && bus->cfg.cyclic;
	/* TIMED CYCLIC frames from firmware 1.1 on, TIMED UPDATEs (a board of
	 * version 2 served by unicast) from 1.2 (docs/PROTOCOL.md). */
	d->timed_fw = m->version >= 2 && (d->ann.firmware_major > 1 ||
	                                  (d->ann.firmware_major == 1 && d->ann.firmware_minor >= (d->cyclic ? 1 : 2)));
	memset(&d->clock, 0, sizeof(d->clock));
	d->sample_ns = 0;
	d->timed_mismatch = 0;
	d->addr = p->addr;
	/* Never 0: a CYCLIC record's tag is the generation, and tag 0 is empty. */
	d->generation = (uint16_t)(d->generation + 1) ? (uint16_t)(d->generation + 1) : 1;
	d->id = (uint32_t)d->generation << 16 | bus_slot_of(bus, d);
	d->keyed = 0;
	if (pr) { /* every frame of the session is sealed, REGISTER first */
		bus_session_keys(bus, d, key);
		d->proved_nonce = bus->nonce_count;
	}
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

/* m's driver failed in a call (where: "", " in input", ...): a version on
 * probation rolls back (a job: bus_rolled_back says how it went);
 * otherwise the machine is dropped (every board to its safe state). */
void bus_driver_failed(struct vmac_bus *bus, struct machine *m, const char *where, const char *err)
{
	struct device *primary = &bus->dev[m->primary];
	bus_event(bus, primary, "driver_error", "%s: driver %s %s failed%s: %s", primary->ann.board, m->driver,
	          vmac_driver_version(m->drv), where, err);
	bus_rec_failure(bus, m, VMAC_REC_ERROR, err);
	if (bus->stopping) { /* its boards were told to go safe already */
		bus_free_machine(bus, m);
		return;
	}
	if (bus_roll_back(bus, m, err) == 0)
		return;
	bus_drop(bus, primary, VMAC_SHUT_DRIVER, "dropped", "its driver failed");
}

/* The machine's tick, on its primary board's reply: a job for its worker
 * now, or as soon as its job is free. */
void bus_run_machine(struct vmac_bus *bus, struct machine *m)
{
	int i;
	m->want_tick = 1;
	m->tick_ns = bus_now(bus);
	for (i = 0; i < m->nboards; i++) {
		const struct device *b = &bus->dev[m->board[i]];
		m->tick_in[i] = b->inputs;
		m->tick_sample_ns[i] = b->sample_ns;
	}
	m->tick_open = 1;
	m->tick_held = 0;
	m->tick_asked = bus->tick_index;
	bus_collect_done_tick(bus, m);
	if (m->used)
		bus_dispatch(bus, m);
}

/* dev:set_level(level) asked for during m's last job: the schedule changes
 * at a slot boundary it picks, or, with no room, stays and an event says
 * why (the driver's dev.level stays too). */
void bus_apply_level(struct vmac_bus *bus, struct machine *m, unsigned level)
{
	unsigned old = m->level;
	char err[200];
	int i, j;
	if (level == old)
		return;
	if (bus_timing_set(bus, m, level, err, sizeof(err)) != 0) {
		bus_timing_set(bus, m, old, NULL, 0); /* it stays at its level, with its instants */
		bus_event(bus, &bus->dev[m->primary], "level", "%s: level %u -> %u refused: %s", m->driver, old, level,
		          err);
		return;
	}
	for (i = 0; i < m->nboards; i++)
		if (vmac_sched_set_level(bus->sched, m->board[i], level, err, sizeof(err)) != 0) {
			for (j = 0; j < i; j++)
				vmac_sched_set_level(bus->sched, m->board[j], old, NULL, 0);
			bus_timing_set(bus, m, old, NULL, 0);
			bus_event(bus, &bus->dev[m->primary], "level", "%s: level %u -> %u refused: %s", m->driver, old,
			          level, err);
			return;
		}
	m->level = level;
	bus_rec_level(bus, m, level);
	for (i = 0; i < m->nboards; i++) {
		struct device *d = &bus->dev[m->board[i]];
		uint16_t wd = watchdog_for(bus, level);
		if (wd > d->watchdog_ms)
			d->want_watchdog = wd; /* sent before its next UPDATE */
	}
	bus_event(bus, &bus->dev[m->primary], "level", "%s: level %u -> %u (period %.6g ms)", m->driver, old, level,
	          (double)(bus->slot_ns << level) / 1e6);
}

/* m's timing at its level; if it does not fit (the loader checked it at
 * the manifest's level, so a level since changed), it acts on arrival and
 * says so. */
static void timing_or_arrival(struct vmac_bus *bus, struct machine *m, struct device *d)
{
	char err[200];
	if (bus_timing_set(bus, m, m->level, err, sizeof(err)) != 0)
		bus_event(bus, d, "warning", "%s: acting on arrival: %s", m->driver, err);
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
	m->out_at_ns = 0;
	m->staged = 0;
	timing_or_arrival(bus, m, d);
	bus->jobs[mi].ckpt = c->ckpt;
	bus->jobs[mi].nnamed = 0;
	bus->jobs[mi].vars_of = NULL;
	memcpy(bus->jobs[mi].device, d->ann.board, sizeof(bus->jobs[mi].device));
	memcpy(bus->jobs[mi].driver, m->driver, sizeof(bus->jobs[mi].driver));
	/* What the status shows until its first job: the declarations, their
	 * values as loaded; the params' values come with attach. */
	m->nvars = vmac_driver_nvars(c->drv);
	for (i = 0; i < (uint32_t)m->nvars; i++)
		m->vars[i] = *vmac_driver_variable(c->drv, (int)i);
	m->nparams = 0;
	m->memory = vmac_driver_memory(c->drv);
	m->instructions = vmac_driver_instructions(c->drv); /* its loading's */
	m->call_ns = vmac_driver_call_ns(c->drv);
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
