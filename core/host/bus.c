/* The bus thread: see bus.h. One tick per slot from an absolute timerfd:
 * drain replies, judge deadlines, discover, send the requests the schedule
 * (core/sched, docs/SCHEDULER.md) puts in this slot. Replies are handled as
 * they arrive; the primary board's reply runs its machine's driver at once,
 * and the outputs leave with each board's next service (one period's delay,
 * a phase-aligned transaction). */
#include "bus.h"

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

#define RX_BATCH 64
#define STATUS_EVERY_NS 100000000LL   /* publish status at most every 100 ms */
#define MALFORMED_LOG_EVERY_NS 1000000000LL
#define STOP_GRACE_PERIODS 3          /* wait this long for SHUTDOWN acks */

const char *const vmac_malformed_reason_names[VMAC_BAD_REASONS] = {
    "short", "magic", "version", "length", "op", "payload", "name", "value",
    "not_reply", "stale_seq", "unknown_sender"};

enum dev_state {
	DEV_FREE,
	DEV_LOADING,     /* announce seen, driver being loaded on the main thread */
	DEV_REGISTERING, /* REGISTER sent or to be sent */
	DEV_RUNNING,
	DEV_TO_SLEEP,    /* registered only to be told to SLEEP (no driver) */
	DEV_SLEEPING,
	DEV_ERRANT,      /* dropped; waits for the board to announce again */
};

/* A machine: the boards that share a driver name and major id, run by one
 * driver instance. Board 0 is the primary: its reply runs the tick. */
struct machine {
	int used;
	struct vmac_driver *drv; /* NULL while loading */
	char driver[VMAC_NAME_MAX + 1];
	uint32_t major;
	uint32_t primary;        /* device slot of the primary board */
	uint32_t board[VMAC_DRIVER_MAX_BOARDS]; /* device slots, in the driver's board order */
	int nboards;
	unsigned level;
	int attached;            /* attach() has run */
	/* Hot reload: the instance drv took over from, kept while drv is on
	 * probation (until probation_end_ns) to roll back to if drv fails. */
	struct vmac_driver *prev;
	int64_t probation_end_ns;
	struct vmac_bus *bus;
};

struct device {
	enum dev_state state;
	int mach;          /* index into bus->mach, -1 when none */
	int scheduled;     /* admitted to the schedule */
	int64_t deadline_ns;    /* reply deadline at the device's level */
	uint16_t aside_seq;     /* a request sent without awaiting its answer (WATCHDOG) */
	uint16_t watchdog_ms;   /* what the board was told */
	uint16_t want_watchdog; /* a longer one to send before the next UPDATE (slower level) */
	char note[200];         /* why it is not running ("schedule full: ...") */
	uint16_t generation;
	uint32_t id; /* generation << 16 | slot */
	struct vmac_announce ann;
	struct vmac_addr addr;
	struct vmac_driver *drv;
	int register_sent;
	uint16_t seq;
	uint16_t missed_seq;   /* the request whose deadline passed last (its late reply is no stranger) */
	uint16_t courtesy_seq; /* the SHUTDOWN/SLEEP sent on dropping, whose answer nobody awaits */
	int pending;       /* a request is out, no reply yet */
	uint8_t pending_op;
	int64_t sent_ns;
	uint32_t consecutive_misses;
	uint64_t misses, served;
	struct vmac_inputs inputs;
	struct vmac_outputs outputs; /* sent with the next UPDATE */
	int64_t last_seen_ns;
};

/* A request slot (vmac_bus_request_input): FREE -> FILLING (the caller
 * writes it) -> QUEUED -> RUNNING (the bus thread) -> DONE (answered, sem
 * posted) -> FREE (the caller read it). A caller that gives up moves QUEUED
 * to ABANDONED, and the bus thread frees it without running it; once
 * RUNNING, the caller waits for the answer, which comes without delay. */
enum { REQ_FREE, REQ_FILLING, REQ_QUEUED, REQ_RUNNING, REQ_DONE, REQ_ABANDONED };

enum { REQ_INPUT, REQ_SWAP, REQ_MACHINES };

struct request {
	_Atomic int state;
	sem_t done;
	int kind;
	struct vmac_bus_input_request r;
	struct vmac_driver *drv; /* REQ_SWAP: the new instance */
	int64_t probation_ns;
	/* REQ_MACHINES: the caller's array, written only while RUNNING (a
	 * caller that finds its request RUNNING waits for the answer). */
	char (*names)[VMAC_NAME_MAX + 1];
	int max_names;
};

struct vmac_bus {
	struct vmac_config cfg;
	struct vmac_transport tr;
	struct ev_loop *loop;
	ev_io timer_w, sock_w;
	ev_async cmd_w;
	pthread_t thread;
	int tfd;
	int64_t period_ns, deadline_ns, start_ns; /* period_ns: one slot */
	uint64_t tick_index;
	struct device *dev;
	uint32_t ndev;
	uint32_t nused; /* slots at or past this have never held a device: loops stop here */
	struct machine *mach;
	struct vmac_sched *sched;
	struct vmac_sched_entry *slot_entries;
	int64_t slot_ns;
	uint64_t slots_done;    /* slots handed to the scheduler so far */
	uint16_t discover_seq;
	int64_t next_discover_ns;
	int64_t next_probation_ns; /* next look for reloads whose probation is over */
	struct vmac_packet *tx;
	int ntx;
	struct vmac_packet rx[RX_BATCH];
	struct vmac_hist lateness;
	struct vmac_bus_counters counters;
	int realtime;
	int stopping;
	int64_t stop_deadline_ns;
	int64_t last_status_ns;
	int64_t last_malformed_log_ns;
	uint64_t malformed_suppressed;
	struct vmac_ring to_main, to_bus;
	struct request req[VMAC_BUS_REQUESTS];
	_Atomic int req_queued; /* requests QUEUED since the bus thread last looked */
	void (*wakeup)(void *);
	void *wakeup_ctx;
	pthread_mutex_t status_lock;
	struct vmac_status status;
	char host_addr[48];
	/* Virtual mode (vmac test): no thread, no socket, no timer; the caller
	 * owns the clock and carries the frames (struct vmac_bus_link). */
	int virt;
	int64_t virt_now_ns;
	struct vmac_bus_link link;
};

/* The bus clock: CLOCK_MONOTONIC, or the caller's in virtual mode. */
static int64_t bus_now(const struct vmac_bus *bus)
{
	return bus->virt ? bus->virt_now_ns : vmac_now_ns();
}

/* ---- messages to the main thread (no allocation: fixed ring slots) ---- */

static void post(struct vmac_bus *bus, const struct vmac_bus_msg *m)
{
	if (vmac_ring_push(&bus->to_main, m) != 0) {
		bus->counters.events_lost++;
		return;
	}
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
}

static void event(struct vmac_bus *bus, const struct device *d, const char *kind, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

static void event(struct vmac_bus *bus, const struct device *d, const char *kind, const char *fmt, ...)
{
	struct vmac_bus_msg m;
	va_list ap;
	memset(&m, 0, sizeof(m));
	m.kind = VMAC_MSG_EVENT;
	m.time_ns = bus_now(bus);
	if (d) {
		memcpy(m.device, d->ann.board, sizeof(m.device));
		memcpy(m.driver, d->ann.driver, sizeof(m.driver));
	}
	snprintf(m.event_kind, sizeof(m.event_kind), "%s", kind);
	va_start(ap, fmt);
	vsnprintf(m.text, sizeof(m.text), fmt, ap);
	va_end(ap);
	post(bus, &m);
}

static double bus_time(const struct vmac_bus *bus)
{
	return (double)(bus_now(bus) - bus->start_ns) / 1e9;
}

/* Hand a driver to the main thread to close (closing a Lua state is slow). */
static void unload(struct vmac_bus *bus, struct vmac_driver *drv)
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

/* ---- sending ---- */

static void flush(struct vmac_bus *bus);

static struct vmac_packet *tx_slot(struct vmac_bus *bus)
{
	if (bus->ntx >= 2 * (int)bus->ndev + 2)
		flush(bus); /* cannot happen: see the size in vmac_bus_new */
	return &bus->tx[bus->ntx++];
}

/* Queue a request for d. expect_reply: the deadline applies to it. */
static void queue(struct vmac_bus *bus, struct device *d, struct vmac_msg *m, int expect_reply)
{
	struct vmac_packet *p = tx_slot(bus);
	int n;
	if (!p)
		return;
	m->seq = ++d->seq;
	m->device_id = d->id;
	m->channel = VMAC_CH_DEVICE;
	n = vmac_proto_encode(m, p->data, sizeof(p->data));
	if (n <= 0) {
		bus->ntx--;
		return;
	}
	p->len = (size_t)n;
	p->addr = d->addr;
	if (expect_reply) {
		d->pending = 1;
		d->pending_op = m->op;
		d->sent_ns = 0; /* stamped when the batch has left */
	}
}

static void flush(struct vmac_bus *bus)
{
	int64_t sent_ns;
	uint32_t i;
	if (bus->ntx == 0)
		return;
	if (bus->virt)
		bus->link.send(bus->link.ctx, bus->tx, bus->ntx);
	else
		vmac_transport_send(&bus->tr, bus->tx, bus->ntx);
	/* The deadline runs from when the request actually left the host, so a
	 * tick the machine delayed never counts against a board. */
	sent_ns = bus_now(bus);
	for (i = 0; i < bus->nused; i++)
		if (bus->dev[i].pending && bus->dev[i].sent_ns == 0)
			bus->dev[i].sent_ns = sent_ns;
	bus->ntx = 0;
}

static void send_shutdown(struct vmac_bus *bus, struct device *d, uint8_t reason, int expect_reply)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.op = VMAC_OP_SHUTDOWN;
	m.u.shutdown_reason = reason;
	queue(bus, d, &m, expect_reply);
}

/* ---- the error policy ---- */

static uint32_t slot_of(const struct vmac_bus *bus, const struct device *d)
{
	return (uint32_t)(d - bus->dev);
}

static void unschedule(struct vmac_bus *bus, struct device *d)
{
	if (d->scheduled)
		vmac_sched_remove(bus->sched, slot_of(bus, d));
	d->scheduled = 0;
}

/* One board out of service: told to go safe (SLEEP after a driver failure:
 * the same safe state plus a back-off before the driver is tried again),
 * taken off the schedule, errant until it announces itself again. The
 * command is a courtesy, not awaited: the board's watchdog does the same. */
static void set_aside(struct vmac_bus *bus, struct device *d, uint8_t reason)
{
	d->pending = 0;
	unschedule(bus, d);
	if (reason == VMAC_SHUT_DRIVER) {
		struct vmac_msg m;
		memset(&m, 0, sizeof(m));
		m.op = VMAC_OP_SLEEP;
		m.u.sleep_s = (uint16_t)bus->cfg.sleep_s;
		queue(bus, d, &m, 0);
	} else {
		send_shutdown(bus, d, reason, 0);
	}
	d->courtesy_seq = d->seq;
	d->state = DEV_ERRANT;
	d->mach = -1;
}

static void free_machine(struct vmac_bus *bus, struct machine *m)
{
	unload(bus, m->drv);
	unload(bus, m->prev);
	memset(m, 0, sizeof(*m));
}

/* Drop d, and with it every other board of its machine: a machine with a
 * board missing is not safe to run. */
static void drop(struct vmac_bus *bus, struct device *d, uint8_t reason, const char *kind, const char *why)
{
	event(bus, d, kind, "%s dropped: %s", d->ann.board, why);
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
			event(bus, o, kind, "%s dropped: %s, a board of the same machine, was dropped", o->ann.board,
			      d->ann.board);
			bus->counters.drops++;
			set_aside(bus, o, reason);
		}
		free_machine(bus, &bus->mach[mi]);
	}
	set_aside(bus, d, reason);
}

static void miss(struct vmac_bus *bus, struct device *d, const char *fmt_why)
{
	d->misses++;
	d->consecutive_misses++;
	bus->counters.misses++;
	if (d->consecutive_misses >= bus->cfg.miss_limit || d->state != DEV_RUNNING)
		drop(bus, d, VMAC_SHUT_DROPPED, "dropped", fmt_why);
}

static void check_deadlines(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		char why[120];
		if (!d->pending || d->sent_ns == 0 || now - d->sent_ns <= d->deadline_ns)
			continue;
		d->pending = 0;
		d->missed_seq = d->seq;
		if (bus->stopping)
			continue;
		snprintf(why, sizeof(why), "no reply to %s seq %u within %.3g ms",
		         vmac_proto_opname(VMAC_CH_DEVICE, d->pending_op), (unsigned)d->seq,
		         (double)d->deadline_ns / 1e6);
		miss(bus, d, why);
	}
}

/* ---- receiving ---- */

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
	event(bus, NULL, "malformed", "malformed frame from %s: %s (%llu more since the last report)",
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
		snprintf(d->note, sizeof(d->note), "machine full: at most %d boards per machine", VMAC_DRIVER_MAX_BOARDS);
		event(bus, d, "machine_full", "%s not attached: %s", d->ann.board, d->note);
		return -1;
	}
	if (vmac_sched_add(bus->sched, slot_of(bus, d), m->level, why, sizeof(why)) != 0) {
		snprintf(d->note, sizeof(d->note), "%s", why);
		bus->counters.schedule_full++;
		event(bus, d, "schedule_full", "%s not attached: %s", d->ann.board, why);
		return -1;
	}
	d->scheduled = 1;
	m->board[m->nboards++] = slot_of(bus, d);
	d->state = DEV_REGISTERING;
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
		unschedule(bus, d);
		d->mach = -1;
		d->pending = 0;
		d->register_sent = 0;
		d->state = DEV_TO_SLEEP;
	}
	free_machine(bus, &bus->mach[mi]);
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
	m->primary = slot_of(bus, d);
	d->mach = mi;

	memset(&load, 0, sizeof(load));
	load.kind = VMAC_MSG_LOAD;
	load.slot = slot_of(bus, d);
	load.generation = d->generation;
	memcpy(load.device, d->ann.board, sizeof(load.device));
	memcpy(load.driver, d->ann.driver, sizeof(load.driver));
	post(bus, &load);
}

static void on_announce(struct vmac_bus *bus, const struct vmac_msg *m, const struct vmac_packet *p)
{
	struct device *d = find_by_identity(bus, &m->u.announce);

	bus->counters.announces++;
	if (d) {
		switch (d->state) {
		case DEV_LOADING:
			d->addr = p->addr;
			return;
		case DEV_REGISTERING:
		case DEV_RUNNING:
		case DEV_TO_SLEEP:
			/* The board has lost our session (reset, or its watchdog ran out). */
			drop(bus, d, VMAC_SHUT_DROPPED, "dropped", "board announced itself again (it lost its session)");
			break;
		default:
			break;
		}
	} else {
		d = new_slot(bus);
		if (!d) {
			bus->counters.table_full++;
			return;
		}
	}
	if (slot_of(bus, d) >= bus->nused)
		bus->nused = slot_of(bus, d) + 1;
	d->ann = m->u.announce;
	d->addr = p->addr;
	d->generation = (uint16_t)(d->generation + 1 ? d->generation + 1 : 1);
	d->id = (uint32_t)d->generation << 16 | slot_of(bus, d);
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

static int hook_set_level(void *ctx, unsigned level, char *err, size_t errlen);
static void hook_event(void *ctx, const char *text);
static void end_probations(struct vmac_bus *bus, int64_t now);

/* Bind drv to machine m (dev:set_level, dev:event). */
static void bind_driver(struct machine *m, struct vmac_driver *drv)
{
	struct vmac_driver_host host;
	host.set_level = hook_set_level;
	host.event = hook_event;
	host.ctx = m;
	vmac_driver_bind(drv, &host);
}

/* Hand drv every board of m it does not have yet (in m's order) and m's
 * level. */
static void give_boards(struct vmac_bus *bus, struct machine *m, struct vmac_driver *drv)
{
	int i;
	for (i = vmac_driver_boards(drv); i < m->nboards; i++) {
		const struct device *b = &bus->dev[m->board[i]];
		vmac_driver_add_board(drv, b->ann.minor, b->ann.board);
	}
	vmac_driver_set_level_now(drv, m->level);
}

/* The version on probation failed (why): the instance it took over from
 * takes over again from it. 0, or -1 when that fails too (m->drv is still
 * the failed one; the caller drops the machine). */
static int roll_back(struct vmac_bus *bus, struct machine *m, const char *why)
{
	char err[VMAC_DRIVER_ERR_MAX];
	struct vmac_driver *failed = m->drv, *prev = m->prev;
	struct device *primary = &bus->dev[m->primary];
	struct vmac_bus_msg msg;
	m->prev = NULL;
	give_boards(bus, m, prev);
	if (vmac_driver_take_over(prev, failed, bus_time(bus), err, sizeof(err)) != 0) {
		event(bus, primary, "driver_error", "%s: rolling back to driver %s %s failed too: %s", primary->ann.board,
		      m->driver, vmac_driver_version(prev), err);
		unload(bus, prev);
		return -1;
	}
	m->drv = prev;
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
	post(bus, &msg);
	unload(bus, failed);
	return 0;
}

/* m's driver failed in a call (where: "", " in input", ...): a version on
 * probation rolls back; otherwise, or if that fails, the machine is
 * dropped (every board to its safe state). */
static void driver_failed(struct vmac_bus *bus, struct machine *m, const char *where, const char *err)
{
	struct device *primary = &bus->dev[m->primary];
	event(bus, primary, "driver_error", "%s: driver %s %s failed%s: %s", primary->ann.board, m->driver,
	      vmac_driver_version(m->drv), where, err);
	if (m->prev) {
		int64_t tag = vmac_driver_tag(m->drv);
		uint32_t i;
		if (roll_back(bus, m, err) == 0) {
			/* One version everywhere: every other machine on probation
			 * with the same version goes back too. */
			for (i = 0; i < bus->nused; i++) {
				struct machine *o = &bus->mach[i];
				if (o == m || !o->used || !o->prev || vmac_driver_tag(o->drv) != tag ||
				    strcmp(o->driver, m->driver) != 0)
					continue;
				if (roll_back(bus, o, "the same version failed on another machine") != 0)
					drop(bus, &bus->dev[o->primary], VMAC_SHUT_DRIVER, "dropped", "its driver failed");
			}
			return;
		}
	}
	drop(bus, primary, VMAC_SHUT_DRIVER, "dropped", "its driver failed");
}

/* The machine's tick, on its primary board's reply. */
static void run_machine(struct vmac_bus *bus, struct machine *m)
{
	char err[VMAC_DRIVER_ERR_MAX];
	const struct vmac_inputs *in[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs *out[VMAC_DRIVER_MAX_BOARDS];
	struct device *primary = &bus->dev[m->primary];
	int i;
	for (i = 0; i < m->nboards; i++) {
		in[i] = &bus->dev[m->board[i]].inputs;
		out[i] = &bus->dev[m->board[i]].outputs;
	}
	if (vmac_driver_tick(m->drv, bus_time(bus), in, out, err, sizeof(err)) == 0)
		return;
	(void)primary;
	driver_failed(bus, m, "", err);
}

/* The bus's side of dev:set_level and dev:event (struct vmac_driver_host). */
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
	for (i = 0; i < m->nboards; i++) {
		struct device *d = &bus->dev[m->board[i]];
		uint16_t wd = watchdog_for(bus, level);
		if (wd > d->watchdog_ms)
			d->want_watchdog = wd; /* sent before its next UPDATE */
	}
	event(bus, &bus->dev[m->primary], "level", "%s: level %u -> %u (period %.6g ms)", m->driver, old, level,
	      (double)(bus->slot_ns << level) / 1e6);
	return 0;
}

static void hook_event(void *ctx, const char *text)
{
	struct machine *m = ctx;
	event(m->bus, &m->bus->dev[m->primary], "driver", "%s", text);
}

static void on_reply(struct vmac_bus *bus, struct device *d, const struct vmac_msg *m)
{
	char why[120];
	d->consecutive_misses = 0;
	d->served++;
	if (m->op == VMAC_OP_ERROR) {
		snprintf(why, sizeof(why), "board refused %s (error %u: %s)",
		         vmac_proto_opname(VMAC_CH_DEVICE, m->u.error.op), (unsigned)m->u.error.code,
		         m->u.error.code == VMAC_BERR_NOT_REGISTERED ? "session lost"
		         : m->u.error.code == VMAC_BERR_IDENTITY    ? "identity mismatch"
		                                                   : "bad request");
		drop(bus, d, VMAC_SHUT_DROPPED, "dropped", why);
		return;
	}
	switch (d->state) {
	case DEV_REGISTERING:
		if (m->op != VMAC_OP_REGISTER)
			return;
		d->state = DEV_RUNNING;
		event(bus, d, "attached", "%s attached: driver %s %s, major %u minor %u, level %u, at %s", d->ann.board,
		      d->ann.driver, vmac_driver_version(bus->mach[d->mach].drv), (unsigned)d->ann.major,
		      (unsigned)d->ann.minor, bus->mach[d->mach].level, vmac_addr_format(&d->addr, why, sizeof(why)));
		if (slot_of(bus, d) == bus->mach[d->mach].primary && !bus->mach[d->mach].attached) {
			struct machine *mm = &bus->mach[d->mach];
			char err[VMAC_DRIVER_ERR_MAX];
			mm->attached = 1;
			if (vmac_driver_attach(mm->drv, bus_time(bus), err, sizeof(err)) != 0)
				driver_failed(bus, mm, " in attach", err);
		}
		break;
	case DEV_TO_SLEEP:
		if (m->op == VMAC_OP_REGISTER) {
			struct vmac_msg s;
			memset(&s, 0, sizeof(s));
			s.op = VMAC_OP_SLEEP;
			s.u.sleep_s = (uint16_t)bus->cfg.sleep_s;
			queue(bus, d, &s, 1);
			flush(bus);
		} else if (m->op == VMAC_OP_SLEEP) {
			d->state = DEV_SLEEPING;
		}
		break;
	case DEV_RUNNING:
		if (m->op == VMAC_OP_UPDATE) {
			d->inputs = m->u.inputs;
			if (d->mach >= 0 && bus->mach[d->mach].primary == slot_of(bus, d) && bus->mach[d->mach].attached)
				run_machine(bus, &bus->mach[d->mach]);
		}
		break;
	default:
		break;
	}
}

static void handle_packet(struct vmac_bus *bus, const struct vmac_packet *p)
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
		on_announce(bus, &m, p);
		return;
	}
	slot = m.device_id & 0xFFFF;
	d = slot < bus->ndev ? &bus->dev[slot] : NULL;
	if (!d || d->id != m.device_id || d->state == DEV_FREE || !vmac_addr_equal(&d->addr, &p->addr)) {
		malformed(bus, p, VMAC_BAD_UNKNOWN_SENDER);
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
	if (d->sent_ns != 0 && p->rx_ns - d->sent_ns > d->deadline_ns) {
		char why[120];
		bus->counters.late_replies++;
		snprintf(why, sizeof(why), "reply to %s seq %u came %.3g ms after the request (deadline %.3g ms)",
		         vmac_proto_opname(VMAC_CH_DEVICE, d->pending_op), (unsigned)m.seq,
		         (double)(p->rx_ns - d->sent_ns) / 1e6, (double)d->deadline_ns / 1e6);
		if (!bus->stopping)
			miss(bus, d, why);
		return;
	}
	on_reply(bus, d, &m);
}

static void drain(struct vmac_bus *bus)
{
	for (;;) {
		int i, n = vmac_transport_recv(&bus->tr, bus->tr.fd, bus->rx, RX_BATCH);
		if (n <= 0)
			break;
		for (i = 0; i < n; i++)
			handle_packet(bus, &bus->rx[i]);
		flush(bus); /* anything a reply caused (SHUTDOWN, SLEEP) goes now */
		if (n < RX_BATCH)
			break;
	}
}

/* ---- status ---- */

static const char *state_name(enum dev_state s)
{
	switch (s) {
	case DEV_LOADING:
	case DEV_REGISTERING: return "attaching";
	case DEV_RUNNING: return "running";
	case DEV_TO_SLEEP:
	case DEV_SLEEPING: return "sleeping";
	case DEV_ERRANT: return "errant";
	default: return "free";
	}
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
	snprintf(o->note, sizeof(o->note), "%s", d->note);
	o->state = state_name(d->state);
	vmac_addr_format(&d->addr, o->address, sizeof(o->address));
	o->id = d->id;
	o->major = d->ann.major;
	o->minor = d->ann.minor;
	o->scheduled = d->scheduled && vmac_sched_device(bus->sched, i, &sd) == 0 && sd.state == VMAC_SCHED_RUNNING;
	o->level = o->scheduled ? sd.level : (m ? m->level : 0);
	o->slot = o->scheduled ? sd.offset : 0;
	o->slice = o->scheduled ? sd.slice : 0;
	o->period_us = (uint32_t)((bus->slot_ns << o->level) / 1000);
	o->misses = d->misses;
	o->served = d->served;
	o->inputs = d->inputs;
	o->outputs = d->state == DEV_RUNNING ? d->inputs.applied : (struct vmac_outputs){0, 0};
	o->driver_memory = m && m->drv && m->primary == i ? vmac_driver_memory(m->drv) : 0;
	o->nvars = o->nparams = 0;
	if (m && m->drv && m->primary == i) {
		o->nvars = vmac_driver_nvars(m->drv);
		for (v = 0; v < o->nvars; v++)
			o->vars[v] = *vmac_driver_variable(m->drv, v);
		o->nparams = vmac_driver_nparams(m->drv);
		for (v = 0; v < o->nparams; v++)
			vmac_driver_param(m->drv, v, &o->params[v]);
	}
}

static void publish(struct vmac_bus *bus, int64_t now)
{
	struct vmac_status *s = &bus->status;
	uint32_t i;
	int n = 0;
	if (pthread_mutex_trylock(&bus->status_lock) != 0)
		return; /* a reader holds it: try again next tick, never wait */
	s->time_ns = now;
	s->started_ns = bus->start_ns;
	s->realtime = bus->realtime;
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

/* ---- the tick ---- */

static void send_discover(struct vmac_bus *bus)
{
	struct vmac_packet *p = tx_slot(bus);
	struct vmac_msg m;
	int n;
	if (!p)
		return;
	memset(&m, 0, sizeof(m));
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_DISCOVER;
	m.seq = ++bus->discover_seq;
	n = vmac_proto_encode(&m, p->data, sizeof(p->data));
	if (n <= 0) {
		bus->ntx--;
		return;
	}
	p->len = (size_t)n;
	p->addr = bus->tr.group;
	bus->counters.discoveries++;
}

/* REGISTER goes out at once, whatever the slot: a board is not in the
 * schedule's service until it has a session. */
static void service_registration(struct vmac_bus *bus)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		struct vmac_msg m;
		if (d->pending || d->register_sent || (d->state != DEV_REGISTERING && d->state != DEV_TO_SLEEP))
			continue;
		memset(&m, 0, sizeof(m));
		m.op = VMAC_OP_REGISTER;
		m.u.reg.major = d->ann.major;
		m.u.reg.minor = d->ann.minor;
		m.u.reg.watchdog_ms = d->state == DEV_REGISTERING ? d->watchdog_ms : (uint16_t)bus->cfg.watchdog_ms;
		d->register_sent = 1;
		d->deadline_ns = bus->deadline_ns;
		queue(bus, d, &m, 1);
	}
}

/* The UPDATEs the schedule puts in this slot, in slice order. */
static void service_slot(struct vmac_bus *bus, uint64_t slot)
{
	int i, n = vmac_sched_slot(bus->sched, slot, bus->slot_entries, (int)bus->cfg.slices_per_slot);
	for (i = 0; i < n; i++) {
		const struct vmac_sched_entry *e = &bus->slot_entries[i];
		struct device *d = &bus->dev[e->device];
		int64_t period = bus->slot_ns << e->level;
		struct vmac_msg m;
		if (d->state != DEV_RUNNING || d->pending)
			continue;
		d->deadline_ns = bus->deadline_ns < period ? bus->deadline_ns : period;
		if (d->want_watchdog) {
			memset(&m, 0, sizeof(m));
			m.op = VMAC_OP_WATCHDOG;
			m.u.watchdog_ms = d->want_watchdog;
			queue(bus, d, &m, 0);
			d->aside_seq = d->seq;
			d->watchdog_ms = d->want_watchdog;
			d->want_watchdog = 0;
		}
		memset(&m, 0, sizeof(m));
		m.op = VMAC_OP_UPDATE;
		m.u.outputs = d->outputs;
		queue(bus, d, &m, 1);
	}
}

static void begin_stop(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	bus->stopping = 1;
	bus->stop_deadline_ns = now + STOP_GRACE_PERIODS * bus->period_ns;
	if (bus->stop_deadline_ns < now + 100000000)
		bus->stop_deadline_ns = now + 100000000; /* at least 100 ms for the acks */
	for (i = 0; i < bus->nused; i++)
		if (bus->mach[i].used && bus->mach[i].drv && bus->mach[i].attached)
			vmac_driver_detach(bus->mach[i].drv, "host stopping");
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->state == DEV_REGISTERING || d->state == DEV_RUNNING || d->state == DEV_TO_SLEEP) {
			d->pending = 0;
			send_shutdown(bus, d, VMAC_SHUT_HOST_STOP, 1);
			d->deadline_ns = bus->stop_deadline_ns - now;
			d->state = DEV_ERRANT;
		}
		unschedule(bus, d);
		d->mach = -1;
	}
	for (i = 0; i < bus->nused; i++)
		if (bus->mach[i].used)
			free_machine(bus, &bus->mach[i]);
	flush(bus);
}

static int stop_done(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	if (now >= bus->stop_deadline_ns)
		return 1;
	for (i = 0; i < bus->nused; i++)
		if (bus->dev[i].pending)
			return 0;
	return 1;
}

/* One tick at `now`, `expirations` slots after the previous one. Returns 1
 * when the bus has stopped (VMAC_MSG_STOPPED posted), else 0. */
static int tick(struct vmac_bus *bus, int64_t now, uint64_t expirations)
{
	int64_t scheduled;
	bus->tick_index += expirations;
	bus->counters.ticks++;
	bus->counters.ticks_skipped += expirations - 1;
	scheduled = bus->start_ns + (int64_t)bus->tick_index * bus->period_ns;
	vmac_hist_add(&bus->lateness, (now - scheduled) / 1000);
	if (!bus->virt) {
		vmac_transport_clock_sync(&bus->tr);
		drain(bus);
	}
	check_deadlines(bus, now);
	if (bus->stopping) {
		if (stop_done(bus, now)) {
			struct vmac_bus_msg m;
			publish(bus, now);
			memset(&m, 0, sizeof(m));
			m.kind = VMAC_MSG_STOPPED;
			while (vmac_ring_push(&bus->to_main, &m) != 0)
				sched_yield(); /* last message: must get through */
			if (bus->wakeup)
				bus->wakeup(bus->wakeup_ctx);
			return 1;
		}
		return 0;
	}
	if (now >= bus->next_discover_ns) {
		send_discover(bus);
		bus->next_discover_ns = now + (int64_t)bus->cfg.discovery_period_ms * 1000000;
	}
	if (now >= bus->next_probation_ns) {
		end_probations(bus, now);
		bus->next_probation_ns = now + STATUS_EVERY_NS;
	}
	service_registration(bus);
	/* Every slot in order, late ones included: the schedule's guarantees
	 * (docs/SCHEDULER.md) hold only if no slot is skipped. */
	while (bus->slots_done < bus->tick_index) {
		bus->slots_done++;
		service_slot(bus, bus->slots_done);
	}
	flush(bus);
	if (now - bus->last_status_ns >= STATUS_EVERY_NS && !bus->virt)
		publish(bus, now); /* vmac test reads vmac_bus_device_status instead */
	return 0;
}

static void on_tick(struct ev_loop *loop, ev_io *w, int revents)
{
	struct vmac_bus *bus = w->data;
	uint64_t expirations = 0;
	(void)revents;

	if (read(bus->tfd, &expirations, sizeof(expirations)) != sizeof(expirations) || expirations == 0)
		return;
	if (tick(bus, vmac_now_ns(), expirations))
		ev_break(loop, EVBREAK_ALL);
}

static void on_socket(struct ev_loop *loop, ev_io *w, int revents)
{
	struct vmac_bus *bus = w->data;
	(void)loop;
	(void)revents;
	drain(bus);
}

/* The main thread has loaded (or failed to load) the driver of the machine
 * whose primary is d. */
static void on_loaded(struct vmac_bus *bus, struct device *d, const struct vmac_host_cmd *c)
{
	int mi = d->mach;
	struct machine *m = &bus->mach[mi];
	uint32_t i;
	if (!c->drv) {
		event(bus, d, c->missing ? "driver_missing" : "driver_error", "%s", c->text);
		event(bus, d, "sleeping", "%s told to sleep for %u s: no usable driver '%s'", d->ann.board,
		      (unsigned)bus->cfg.sleep_s, d->ann.driver);
		snprintf(d->note, sizeof(d->note), "%s", c->text);
		machine_to_sleep(bus, mi);
		return;
	}
	m->drv = c->drv;
	m->level = vmac_driver_level(c->drv);
	bind_driver(m, m->drv);
	if (admit(bus, m, d) != 0) {
		char note[sizeof(d->note)];
		memcpy(note, d->note, sizeof(note));
		event(bus, d, "sleeping", "%s told to sleep for %u s: %s", d->ann.board, (unsigned)bus->cfg.sleep_s, note);
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

static struct device *find_by_name(struct vmac_bus *bus, const char *name);

/* Hot reload at this slot boundary (between two ticks): nd takes over the
 * machine named device from the instance running it. 0 done (nd is the
 * bus's); else nd is still the caller's and has not run, or ran only its
 * attach/migrate, and reply says why: -VMAC_ENOTRUNNING (no running
 * machine of that name), -VMAC_EREFUSED (it would not take nd). */
static int swap(struct vmac_bus *bus, const char *device, struct vmac_driver *nd, int64_t probation_ns, char *reply,
                size_t replylen)
{
	char err[VMAC_DRIVER_ERR_MAX];
	struct device *d = find_by_name(bus, device);
	struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	struct vmac_driver *od;
	if (!m || !m->drv || !m->attached || d->state != DEV_RUNNING || bus->stopping) {
		snprintf(reply, replylen, "%s is not running (%s)", device, d ? state_name(d->state) : "no such device");
		return -VMAC_ENOTRUNNING;
	}
	if (strcmp(vmac_driver_name(nd), m->driver) != 0) {
		snprintf(reply, replylen, "%s runs driver %s, not %s", device, m->driver, vmac_driver_name(nd));
		return -VMAC_EREFUSED;
	}
	bind_driver(m, nd);
	give_boards(bus, m, nd);
	od = m->drv;
	if (vmac_driver_take_over(nd, od, bus_time(bus), err, sizeof(err)) != 0) {
		snprintf(reply, replylen, "the new version failed to take over %s: %s", device, err);
		event(bus, d, "reload_refused", "%s: driver %s %s not taken: %s", device, m->driver,
		      vmac_driver_version(nd), err);
		return -VMAC_EREFUSED;
	}
	m->drv = nd;
	/* Said before od is handed over: the main thread may free it at once. */
	event(bus, &bus->dev[m->primary], "reloaded", "%s: driver %s %s -> %s at a slot boundary (probation %.3g s)",
	      bus->dev[m->primary].ann.board, m->driver, vmac_driver_version(od), vmac_driver_version(nd),
	      (double)probation_ns / 1e9);
	snprintf(reply, replylen, "%s: driver %s %s -> %s", device, m->driver, vmac_driver_version(od),
	         vmac_driver_version(nd));
	if (m->prev) /* a version still on probation: the one just replaced is what a rollback goes back to */
		unload(bus, m->prev);
	m->prev = NULL;
	if (probation_ns > 0) {
		m->prev = od;
		m->probation_end_ns = bus_now(bus) + probation_ns;
	} else {
		unload(bus, od);
	}
	return 0;
}

/* Versions whose probation is over keep the machine: the previous
 * instance goes. */
static void end_probations(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct machine *m = &bus->mach[i];
		if (!m->used || !m->prev || now < m->probation_end_ns)
			continue;
		unload(bus, m->prev);
		m->prev = NULL;
		event(bus, &bus->dev[m->primary], "probation_passed", "%s: driver %s %s passed its probation",
		      bus->dev[m->primary].ann.board, m->driver, vmac_driver_version(m->drv));
	}
}

int vmac_bus_input(struct vmac_bus *bus, const char *device, const char *name, const struct vmac_value *value,
                   char *reply, size_t replylen);

/* An input request; with persist, only to a persist = true param. */
static int input_request(struct vmac_bus *bus, struct vmac_bus_input_request *r)
{
	struct device *d = find_by_name(bus, r->device);
	struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	int rc;
	if (r->persist && m && m->drv && vmac_driver_param_persists(m->drv, r->name) != 1) {
		const char *why = vmac_driver_param_persists(m->drv, r->name) < 0
		                      ? "only params persist, and the driver has no such param"
		                      : "this param does not persist (the driver does not declare it persist = true)";
		size_t n = strlen(r->name);
		memcpy(r->reply, r->name, n); /* name and reply are parts of one struct: no snprintf of one into the other */
		snprintf(r->reply + n, sizeof(r->reply) - n, ": %s", why);
		return VMAC_REFUSED_NOT_PERSIST;
	}
	rc = vmac_bus_input(bus, r->device, r->name, &r->value, r->reply, sizeof(r->reply));
	if (rc == 0 && m && m->used)
		memcpy(r->machine, bus->dev[m->primary].ann.board, sizeof(r->machine));
	return rc;
}

/* The machines of driver that have a driver instance (attached, or their
 * boards still registering): their primary boards' names into names, at
 * most max. Returns how many. */
static int list_machines(struct vmac_bus *bus, const char *driver, char (*names)[VMAC_NAME_MAX + 1], int max)
{
	uint32_t i;
	int n = 0;
	if (bus->stopping)
		return 0;
	for (i = 0; i < bus->nused && n < max; i++) {
		const struct machine *m = &bus->mach[i];
		if (m->used && m->drv && strcmp(m->driver, driver) == 0)
			snprintf(names[n++], VMAC_NAME_MAX + 1, "%s", bus->dev[m->primary].ann.board);
	}
	return n;
}

static void commands(struct vmac_bus *bus);

/* The requests other threads queued: run each, answer, post. */
static void requests(struct vmac_bus *bus)
{
	int i, expect;
	if (atomic_exchange(&bus->req_queued, 0) == 0)
		return;
	for (i = 0; i < VMAC_BUS_REQUESTS; i++) {
		struct request *q = &bus->req[i];
		expect = REQ_QUEUED;
		if (!atomic_compare_exchange_strong(&q->state, &expect, REQ_RUNNING)) {
			if (expect == REQ_ABANDONED)
				atomic_store(&q->state, REQ_FREE);
			continue;
		}
		if (q->kind == REQ_SWAP) {
			q->r.rc = swap(bus, q->r.device, q->drv, q->probation_ns, q->r.reply, sizeof(q->r.reply));
		} else if (q->kind == REQ_MACHINES) {
			/* Every command sent before this request was queued is
			 * handled first: a driver the main thread handed over is
			 * in its machine when the list is made. */
			commands(bus);
			q->r.rc = list_machines(bus, q->r.name, q->names, q->max_names);
		} else {
			q->r.rc = input_request(bus, &q->r);
		}
		atomic_store(&q->state, REQ_DONE);
		sem_post(&q->done);
	}
}

static void commands(struct vmac_bus *bus)
{
	struct vmac_host_cmd c;
	while (vmac_ring_pop(&bus->to_bus, &c)) {
		struct device *d;
		if (c.kind == VMAC_CMD_STOP) {
			if (!bus->stopping)
				begin_stop(bus, bus_now(bus));
			continue;
		}
		d = c.slot < bus->ndev ? &bus->dev[c.slot] : NULL;
		if (!d || d->state != DEV_LOADING || d->generation != c.generation || bus->stopping || d->mach < 0 ||
		    bus->mach[d->mach].primary != c.slot || bus->mach[d->mach].drv) {
			unload(bus, c.drv); /* the device went away meanwhile */
			continue;
		}
		on_loaded(bus, d, &c);
	}
}

static void on_cmd(struct ev_loop *loop, ev_async *w, int revents)
{
	(void)revents;
	(void)loop;
	commands(w->data);
	requests(w->data);
}

static void try_realtime(struct vmac_bus *bus)
{
	struct sched_param sp;
	const char *what = NULL;
	int rc;
	if (!bus->cfg.realtime)
		return;
	memset(&sp, 0, sizeof(sp));
	sp.sched_priority = 50;
	rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
	if (rc != 0)
		what = "SCHED_FIFO";
	else
		bus->realtime = 1;
#if !defined(__SANITIZE_ADDRESS__)
	if (!what && mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
		rc = errno;
		what = "mlockall";
	}
#endif
	if (what)
		event(bus, NULL, "warning", "real-time setup refused (%s: %s); running with normal scheduling, "
		      "tick lateness will be higher", what, strerror(rc));
}

static void *bus_main(void *arg)
{
	struct vmac_bus *bus = arg;
	struct itimerspec its;
	struct timespec start;

	try_realtime(bus);
	clock_gettime(CLOCK_MONOTONIC, &start);
	bus->start_ns = (int64_t)start.tv_sec * 1000000000 + start.tv_nsec;
	/* Absolute periodic timer: ticks fall on start + k * period however
	 * late any one of them was handled. */
	memset(&its, 0, sizeof(its));
	its.it_value.tv_sec = (bus->start_ns + bus->period_ns) / 1000000000;
	its.it_value.tv_nsec = (bus->start_ns + bus->period_ns) % 1000000000;
	its.it_interval.tv_sec = bus->period_ns / 1000000000;
	its.it_interval.tv_nsec = bus->period_ns % 1000000000;
	bus->tick_index = 0;
	timerfd_settime(bus->tfd, TFD_TIMER_ABSTIME, &its, NULL);
	bus->next_discover_ns = bus->start_ns;
	ev_run(bus->loop, 0);
	return NULL;
}

/* Everything both modes use: the device, machine and packet tables, the
 * schedule, the rings. Every byte the bus thread will ever use is here. */
static struct vmac_bus *bus_alloc(const struct vmac_config *cfg, char *err, size_t errlen)
{
	struct vmac_bus *bus = calloc(1, sizeof(*bus));
	uint32_t i;
	if (!bus) {
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	bus->cfg = *cfg;
	bus->tfd = -1;
	bus->tr.fd = -1;
	bus->ndev = cfg->max_devices;
	bus->slot_ns = (int64_t)vmac_config_slot_us(cfg) * 1000;
	bus->period_ns = bus->slot_ns;
	bus->deadline_ns = (int64_t)cfg->reply_deadline_us * 1000;
	bus->dev = calloc(bus->ndev, sizeof(*bus->dev));
	bus->mach = calloc(bus->ndev, sizeof(*bus->mach));
	/* Per flush at most: one request per device, a WATCHDOG beside it, a DISCOVER. */
	bus->tx = calloc(2 * bus->ndev + 2, sizeof(*bus->tx));
	bus->status.devices = calloc(bus->ndev, sizeof(*bus->status.devices));
	bus->status.slot_load = calloc(1u << cfg->max_level, sizeof(*bus->status.slot_load));
	bus->slot_entries = calloc(cfg->slices_per_slot, sizeof(*bus->slot_entries));
	bus->sched = vmac_sched_new(cfg->slices_per_slot, cfg->max_level, cfg->max_devices);
	if (!bus->dev || !bus->mach || !bus->tx || !bus->status.devices || !bus->status.slot_load ||
	    !bus->slot_entries || !bus->sched || vmac_ring_init(&bus->to_main, sizeof(struct vmac_bus_msg), 1024) ||
	    vmac_ring_init(&bus->to_bus, sizeof(struct vmac_host_cmd), 1024)) {
		snprintf(err, errlen, "out of memory");
		vmac_bus_free(bus);
		return NULL;
	}
	for (i = 0; i < bus->ndev; i++)
		bus->dev[i].mach = -1;
	for (i = 0; i < VMAC_BUS_REQUESTS; i++)
		sem_init(&bus->req[i].done, 0, 0);
	pthread_mutex_init(&bus->status_lock, NULL);
	return bus;
}

struct vmac_bus *vmac_bus_new(const struct vmac_config *cfg, char *err, size_t errlen)
{
	struct vmac_bus *bus;
	struct vmac_bus_spec spec;
	if (vmac_bus_spec_parse(cfg->bus, &spec) != 0) {
		snprintf(err, errlen, "bus '%s': expected MULTICAST_GROUP:PORT, e.g. 239.255.86.77:5870", cfg->bus);
		return NULL;
	}
	if (inet_pton(AF_INET, cfg->iface, &spec.iface) != 1) {
		snprintf(err, errlen, "iface '%s': expected an IPv4 address", cfg->iface);
		return NULL;
	}
	bus = bus_alloc(cfg, err, errlen);
	if (!bus)
		return NULL;
	if (vmac_transport_open_host(&bus->tr, &spec, err, errlen) < 0)
		goto fail;
	vmac_addr_format(&bus->tr.local, bus->host_addr, sizeof(bus->host_addr));
	bus->tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
	if (bus->tfd < 0) {
		snprintf(err, errlen, "cannot create the tick timer: %s", strerror(errno));
		goto fail;
	}
	bus->loop = ev_loop_new(EVFLAG_AUTO | EVFLAG_NOSIGMASK);
	if (!bus->loop) {
		snprintf(err, errlen, "cannot create the bus event loop");
		goto fail;
	}
	ev_io_init(&bus->timer_w, on_tick, bus->tfd, EV_READ);
	bus->timer_w.data = bus;
	ev_io_init(&bus->sock_w, on_socket, bus->tr.fd, EV_READ);
	bus->sock_w.data = bus;
	ev_async_init(&bus->cmd_w, on_cmd);
	bus->cmd_w.data = bus;
	/* Ticks first: a flood on the socket must not starve the schedule. */
	ev_set_priority(&bus->timer_w, EV_MAXPRI);
	ev_io_start(bus->loop, &bus->timer_w);
	ev_io_start(bus->loop, &bus->sock_w);
	ev_async_start(bus->loop, &bus->cmd_w);
	return bus;
fail:
	vmac_bus_free(bus);
	return NULL;
}

struct vmac_bus *vmac_bus_new_virtual(const struct vmac_config *cfg, const struct vmac_bus_link *link,
                                      const struct vmac_addr *group, char *err, size_t errlen)
{
	struct vmac_bus *bus = bus_alloc(cfg, err, errlen);
	if (!bus)
		return NULL;
	bus->virt = 1;
	bus->link = *link;
	bus->tr.group = *group;
	snprintf(bus->host_addr, sizeof(bus->host_addr), "virtual");
	return bus;
}

int vmac_bus_virtual_tick(struct vmac_bus *bus, int64_t now_ns)
{
	uint64_t index = (uint64_t)(now_ns / bus->period_ns);
	bus->virt_now_ns = now_ns;
	if (index <= bus->tick_index)
		return 0;
	return tick(bus, now_ns, index - bus->tick_index);
}

int64_t vmac_bus_virtual_next_tick(const struct vmac_bus *bus)
{
	return (int64_t)(bus->tick_index + 1) * bus->period_ns;
}

void vmac_bus_virtual_receive(struct vmac_bus *bus, const struct vmac_packet *p)
{
	bus->virt_now_ns = p->rx_ns;
	handle_packet(bus, p);
	flush(bus);
}

void vmac_bus_virtual_commands(struct vmac_bus *bus)
{
	commands(bus);
	requests(bus);
}

static struct device *find_by_name(struct vmac_bus *bus, const char *name)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++)
		if (bus->dev[i].state != DEV_FREE && strcmp(bus->dev[i].ann.board, name) == 0)
			return &bus->dev[i];
	return NULL;
}

int vmac_bus_device_status(struct vmac_bus *bus, const char *device, struct vmac_device_status *out)
{
	struct device *d = find_by_name(bus, device);
	if (!d)
		return -1;
	device_status(bus, slot_of(bus, d), out);
	return 0;
}

const char *vmac_bus_device_state(struct vmac_bus *bus, const char *device)
{
	struct device *d = find_by_name(bus, device);
	return d ? state_name(d->state) : "absent";
}

const struct vmac_variable *vmac_bus_device_var(struct vmac_bus *bus, const char *device, const char *name)
{
	struct device *d = find_by_name(bus, device);
	const struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	int i, n;
	if (!m || !m->drv || m->primary != slot_of(bus, d))
		return NULL;
	n = vmac_driver_nvars(m->drv);
	for (i = 0; i < n; i++) {
		const struct vmac_variable *v = vmac_driver_variable(m->drv, i);
		if (strcmp(v->name, name) == 0)
			return v;
	}
	return NULL;
}

int vmac_bus_input(struct vmac_bus *bus, const char *device, const char *name, const struct vmac_value *value,
                   char *reply, size_t replylen)
{
	char err[VMAC_DRIVER_ERR_MAX];
	struct device *d = find_by_name(bus, device);
	struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	int rc;
	if (!m || !m->drv || !m->attached || d->state != DEV_RUNNING || bus->stopping) {
		snprintf(reply, replylen, "%s is not running (%s)", device, d ? state_name(d->state) : "no such device");
		return -VMAC_ENOTRUNNING;
	}
	rc = vmac_driver_input(m->drv, bus_time(bus), name, value, reply, replylen, err, sizeof(err));
	if (rc >= 0)
		return rc;
	driver_failed(bus, m, " in input", err);
	flush(bus);
	snprintf(reply, replylen, "the driver failed: %s", err);
	return -VMAC_EDRIVER;
}

void vmac_bus_free(struct vmac_bus *bus)
{
	uint32_t i;
	if (!bus)
		return;
	if (bus->mach)
		for (i = 0; i < bus->ndev; i++)
			vmac_driver_free(bus->mach[i].drv);
	if (bus->loop)
		ev_loop_destroy(bus->loop);
	vmac_transport_close(&bus->tr);
	if (bus->tfd >= 0)
		close(bus->tfd);
	vmac_ring_fini(&bus->to_main);
	vmac_ring_fini(&bus->to_bus);
	for (i = 0; i < VMAC_BUS_REQUESTS; i++)
		sem_destroy(&bus->req[i].done);
	free(bus->dev);
	free(bus->mach);
	free(bus->tx);
	free(bus->status.devices);
	free(bus->status.slot_load);
	free(bus->slot_entries);
	vmac_sched_free(bus->sched);
	free(bus);
}

int vmac_bus_start(struct vmac_bus *bus)
{
	return -pthread_create(&bus->thread, NULL, bus_main, bus);
}

void vmac_bus_join(struct vmac_bus *bus)
{
	pthread_join(bus->thread, NULL);
}

void vmac_bus_set_wakeup(struct vmac_bus *bus, void (*wakeup)(void *), void *ctx)
{
	bus->wakeup = wakeup;
	bus->wakeup_ctx = ctx;
}

int vmac_bus_poll_msg(struct vmac_bus *bus, struct vmac_bus_msg *msg)
{
	return vmac_ring_pop(&bus->to_main, msg);
}

int vmac_bus_send_cmd(struct vmac_bus *bus, const struct vmac_host_cmd *cmd)
{
	if (vmac_ring_push(&bus->to_bus, cmd) != 0)
		return -EAGAIN;
	if (!bus->virt)
		ev_async_send(bus->loop, &bus->cmd_w);
	return 0;
}

void vmac_bus_status(struct vmac_bus *bus, struct vmac_status *out)
{
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
}

const char *vmac_bus_host_addr(struct vmac_bus *bus)
{
	return bus->host_addr;
}

static int request(struct vmac_bus *bus, int req_kind, struct vmac_bus_input_request *req, struct vmac_driver *drv,
                   int64_t probation_ns, char (*names)[VMAC_NAME_MAX + 1], int max_names, int timeout_ms)
{
	struct request *q = NULL;
	struct timespec until;
	int i, expect, rc;
	for (i = 0; i < VMAC_BUS_REQUESTS && !q; i++) {
		expect = REQ_FREE;
		if (atomic_compare_exchange_strong(&bus->req[i].state, &expect, REQ_FILLING))
			q = &bus->req[i];
	}
	if (!q) {
		snprintf(req->reply, sizeof(req->reply), "the host is busy with other requests; try again");
		return -VMAC_EBUSY;
	}
	q->kind = req_kind;
	q->r = *req;
	q->drv = drv;
	q->probation_ns = probation_ns;
	q->names = names;
	q->max_names = max_names;
	atomic_store(&q->state, REQ_QUEUED);
	atomic_store(&bus->req_queued, 1);
	if (!bus->virt)
		ev_async_send(bus->loop, &bus->cmd_w);
	clock_gettime(CLOCK_REALTIME, &until);
	until.tv_sec += timeout_ms / 1000;
	until.tv_nsec += (long)(timeout_ms % 1000) * 1000000L;
	if (until.tv_nsec >= 1000000000L) {
		until.tv_sec++;
		until.tv_nsec -= 1000000000L;
	}
	while ((rc = sem_timedwait(&q->done, &until)) != 0 && errno == EINTR)
		;
	if (rc != 0) {
		expect = REQ_QUEUED;
		if (atomic_compare_exchange_strong(&q->state, &expect, REQ_ABANDONED)) {
			snprintf(req->reply, sizeof(req->reply), "the bus thread did not take the request within %d ms",
			         timeout_ms);
			return -VMAC_EBUSY;
		}
		while (sem_wait(&q->done) != 0 && errno == EINTR) /* RUNNING or DONE: the answer is on its way */
			;
	}
	*req = q->r;
	atomic_store(&q->state, REQ_FREE);
	return 0;
}

int vmac_bus_request_input(struct vmac_bus *bus, struct vmac_bus_input_request *req, int timeout_ms)
{
	return request(bus, REQ_INPUT, req, NULL, 0, NULL, 0, timeout_ms);
}

int vmac_bus_request_swap(struct vmac_bus *bus, const char *device, struct vmac_driver *drv, unsigned probation_ms,
                          int timeout_ms, int *rc, char *reply, size_t replylen)
{
	struct vmac_bus_input_request req;
	int r;
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	r = request(bus, REQ_SWAP, &req, drv, (int64_t)probation_ms * 1000000, NULL, 0, timeout_ms);
	*rc = r == 0 ? req.rc : r;
	snprintf(reply, replylen, "%s", req.reply);
	return r;
}

int vmac_bus_request_machines(struct vmac_bus *bus, const char *driver, char (*names)[VMAC_NAME_MAX + 1], int max,
                              int timeout_ms, char *reply, size_t replylen)
{
	struct vmac_bus_input_request req;
	memset(&req, 0, sizeof(req));
	snprintf(req.name, sizeof(req.name), "%s", driver);
	int r = request(bus, REQ_MACHINES, &req, NULL, 0, names, max, timeout_ms);
	if (r != 0) {
		snprintf(reply, replylen, "%s", req.reply);
		return r;
	}
	return req.rc;
}
