/* The bus thread (see bus.h): its clock, its tick, sending and receiving,
 * and its set-up (real time, or virtual time for `vmac test`). One tick per
 * slot at start + k x slot (bus_loop: an epoll wait with a timeout to the
 * next tick): drain replies, judge deadlines, discover,
 * send the requests the schedule (core/sched, docs/SCHEDULER.md) puts in
 * this slot. Replies are handled as they arrive (receive.c); the primary
 * board's reply runs its machine's driver at once, and the outputs leave
 * with each board's next service (one period's delay, a phase-aligned
 * transaction). The rest of the thread: devices.c (device and machine
 * lifecycle, the drop policy), keys.c (trust on the wire), mailbox.c
 * (between threads), status.c, swap.c (hot reload at a slot boundary);
 * bus_internal.h holds what they share. */
#include "bus_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
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

/* The bus clock: CLOCK_MONOTONIC, or the caller's in virtual mode. */
int64_t bus_now(const struct vmac_bus *bus)
{
	return bus->virt ? bus->virt_now_ns : vmac_now_ns();
}

double bus_time(const struct vmac_bus *bus)
{
	return (double)(bus_now(bus) - bus->start_ns) / 1e9;
}

/* Per flush at most: one request per device, a WATCHDOG beside it, a
 * DISCOVER, a SYNC and its sealed chunks, a CYCLIC frame per chunk of
 * offsets, sealed and not, and a TIMED one per device due in a slot. */
static int tx_max(const struct vmac_bus *bus)
{
	return 2 * (int)bus->ndev + 3 + (int)bus->nchunks + (int)bus->nauth_chunks + (int)bus->nsync_chunks +
	       (int)bus->cfg.slices_per_slot;
}

struct vmac_packet *bus_tx_slot(struct vmac_bus *bus)
{
	if (bus->ntx >= tx_max(bus))
		bus_flush(bus);           /* cannot happen: see the size in vmac_bus_new */
	bus->tx[bus->ntx].tx_cookie = -1; /* no transmit stamp, but for SYNC */
	return &bus->tx[bus->ntx++];
}

/* Queue a request for d. expect_reply: the deadline applies to it. */
void bus_queue(struct vmac_bus *bus, struct device *d, struct vmac_msg *m, int expect_reply)
{
	struct vmac_packet *p = bus_tx_slot(bus);
	int n;
	if (!p)
		return;
	m->version = d->version;
	m->seq = ++d->seq;
	m->device_id = d->id;
	m->channel = VMAC_CH_DEVICE;
	n = vmac_proto_encode(m, p->data, sizeof(p->data));
	if (n > 0 && d->keyed) /* its session's: the board obeys nothing else */
		n = vmac_proto_seal(p->data, (size_t)n, sizeof(p->data), ++d->tx_counter, d->to_board, NULL, 0);
	if (n <= 0) {
		bus->ntx--;
		return;
	}
	p->len = (size_t)n;
	p->addr = d->addr;
	if (expect_reply) {
		d->pending = 1;
		d->pending_op = m->op;
		d->tx_index = bus->ntx - 1;
		d->sent_ns = 0; /* stamped when the batch has left */
		d->sent_timed = 0;
		d->in_at_ns = 0;
	}
}

void bus_flush(struct vmac_bus *bus)
{
	int64_t sent_ns;
	uint32_t i;
	int sent, had_sync = bus->sync_tx >= 0 || bus->nsync_auth > 0;
	if (bus->ntx == 0)
		return;
	if (had_sync)
		bus_sync_stamp(bus);
	if (bus->virt) {
		bus->link.send(bus->link.ctx, bus->tx, bus->ntx);
		sent = bus->ntx;
	} else {
		sent = vmac_transport_send(&bus->tr, bus->tx, bus->ntx);
		/* A software transmit stamp is there as the send returns (the
		 * driver stamps in its xmit): read now, it costs no wake-up of
		 * this thread by EPOLLERR later; else it comes that way. */
		if (had_sync)
			bus_sync_read_stamps(bus, 0);
	}
	/* The deadline runs from when the request actually left the host, so a
	 * tick the machine delayed never counts against a board. A request the
	 * kernel did not take is marked: its miss is the host's, not the board's. */
	sent_ns = bus_now(bus);
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->pending && d->sent_ns == 0) {
			d->sent_ns = sent_ns;
			d->unsent = d->tx_index >= sent;
		}
	}
	bus->ntx = 0;
}

void bus_send_shutdown(struct vmac_bus *bus, struct device *d, uint8_t reason, int expect_reply)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.op = VMAC_OP_SHUTDOWN;
	m.u.shutdown_reason = reason;
	bus_queue(bus, d, &m, expect_reply);
}

/* ---- the tick ---- */

/* A system frame to every board (the discovery group; broadcast on raw
 * Ethernet, from the interface's own MAC) queued: its slot, or NULL when
 * there is none or it did not encode. */
struct vmac_packet *bus_queue_group(struct vmac_bus *bus, const struct vmac_msg *m)
{
	struct vmac_packet *p = bus_tx_slot(bus);
	int n;
	if (!p)
		return NULL;
	n = vmac_proto_encode(m, p->data, sizeof(p->data));
	if (n <= 0) {
		bus->ntx--;
		return NULL;
	}
	p->len = (size_t)n;
	p->addr = bus->tr.group;
	memset(p->mac, 0, sizeof(p->mac));
	return p;
}

static void send_discover(struct vmac_bus *bus)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.version = 1; /* boards of every version answer it, each in its own */
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_DISCOVER;
	m.seq = ++bus->discover_seq;
	/* A fresh nonce each time: an announcement proves its key over it, so
	 * an old one replayed proves nothing (keys.c). */
	bus_nonce_next(bus);
	m.u.discover.has_nonce = 1;
	memcpy(m.u.discover.nonce, bus->nonce, sizeof(m.u.discover.nonce));
	if (bus_queue_group(bus, &m))
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
		if (d->state == DEV_TO_SLEEP || d->reg_step == REG_REGISTER) {
			m.op = VMAC_OP_REGISTER;
			m.u.reg.major = d->ann.major;
			m.u.reg.minor = d->ann.minor;
			m.u.reg.watchdog_ms =
			    d->state == DEV_REGISTERING ? d->watchdog_ms : (uint16_t)bus->cfg.watchdog_ms;
		} else if (d->reg_step == REG_SIZE) {
			m.op = VMAC_OP_SIZE;
		} else {
			m.op = VMAC_OP_OFFSET;
			m.u.offset = (uint16_t)i; /* its slot: unique while it holds the slot */
		}
		d->register_sent = 1;
		d->reply_window_ns = bus->reply_deadline_ns;
		bus_queue(bus, d, &m, 1);
	}
}

/* A CYCLIC frame of this slot for chunk c (started on first use), its tx
 * index or -1: sealed for a keyed board, TIMED with the instants when
 * timed, one per chunk, kind and pair of instants (boards of older
 * firmware and machines acting on arrival in the plain frames beside). */
static int cyclic_frame(struct vmac_bus *bus, int keyed, uint32_t c, uint32_t per, int timed, uint64_t out_at,
                        uint64_t in_at)
{
	int *tx = keyed ? &bus->auth_chunk_tx[c] : &bus->chunk_tx[c];
	uint32_t first = c * per, count = bus->nused - first;
	struct vmac_packet *p;
	int i, n;
	if (timed) {
		for (i = 0; i < bus->ntimed_frames; i++) {
			const struct timed_frame *f = &bus->timed_frames[i];
			if (f->chunk == c && f->keyed == keyed && f->out_at == out_at && f->in_at == in_at)
				return f->tx;
		}
		if (bus->ntimed_frames >= (int)bus->cfg.slices_per_slot)
			return -1; /* cannot happen: one a device due at most */
	} else if (*tx >= 0) {
		return *tx;
	}
	p = bus_tx_slot(bus);
	if (!p)
		return -1;
	if (count > per)
		count = per;
	if (timed)
		n = vmac_proto_cyclic_begin_timed(p->data, sizeof(p->data), bus->cyclic_seq, (uint16_t)first, count,
		                                  keyed, bus->cyclic_counter, out_at, in_at);
	else if (keyed)
		n = vmac_proto_cyclic_begin_auth(p->data, sizeof(p->data), bus->cyclic_seq, (uint16_t)first, count,
		                                 bus->cyclic_counter);
	else
		n = vmac_proto_cyclic_begin(p->data, sizeof(p->data), bus->cyclic_seq, (uint16_t)first, count);
	if (n <= 0) {
		bus->ntx--;
		return -1;
	}
	p->len = (size_t)n;
	p->addr = bus->tr.group;
	memset(p->mac, 0, sizeof(p->mac));
	if (timed) {
		struct timed_frame *f = &bus->timed_frames[bus->ntimed_frames++];
		f->chunk = c;
		f->keyed = (uint8_t)keyed;
		f->out_at = out_at;
		f->in_at = in_at;
		f->tx = (int)(p - bus->tx);
		return f->tx;
	}
	*tx = (int)(p - bus->tx);
	return *tx;
}

/* Put d's outputs, due, at its offset in this slot's CYCLIC frame of its
 * chunk: a sealed one for an authenticated board, its record carrying a
 * MAC under its session's key, else a plain one; TIMED with the instants
 * of its machine's pattern when its board takes them (timed.c). The
 * frame's seq is the slot's. */
static void cyclic_put(struct vmac_bus *bus, struct device *d, uint64_t slot, unsigned level)
{
	uint32_t offset = bus_slot_of(bus, d), per = d->keyed ? VMAC_CYCLIC_AUTH_RECORDS_MAX : VMAC_CYCLIC_RECORDS_MAX;
	uint64_t out_at = 0, in_at = 0;
	int timed = bus_service_instants(bus, d, slot, level, &out_at, &in_at);
	int tx = cyclic_frame(bus, d->keyed, offset / per, per, timed, out_at, in_at);
	struct vmac_packet *p;
	if (tx < 0)
		return;
	p = &bus->tx[tx];
	vmac_proto_cyclic_put(p->data, offset % per, (uint16_t)(d->id >> 16), VMAC_CYCLIC_DUE, &d->outputs);
	if (d->keyed)
		vmac_proto_cyclic_seal_record(p->data, offset % per, d->to_board);
	d->seq = bus->cyclic_seq;
	d->pending = 1;
	d->tx_index = tx;
	d->pending_op = VMAC_OP_UPDATE;
	d->sent_ns = 0; /* stamped when the batch has left */
	d->sent_timed = (uint8_t)timed;
	d->in_at_ns = (int64_t)in_at;
}

/* The UPDATEs the schedule puts in this slot, in slice order: unicast to
 * version-1 boards (and, cyclic off, to every board), in the slot's
 * CYCLIC frames for the others. */
static void service_slot(struct vmac_bus *bus, uint64_t slot)
{
	int i, n = vmac_sched_slot(bus->sched, slot, bus->slot_entries, (int)bus->cfg.slices_per_slot);
	uint32_t c;
	/* Room for this slot's requests, its WATCHDOGs and its CYCLIC frames
	 * without a flush in between (a flush would move the frames). */
	if (bus->ntx + (int)bus->nchunks + (int)bus->nauth_chunks + 3 * n > tx_max(bus))
		bus_flush(bus);
	bus->ntimed_frames = 0;
	for (c = 0; c < bus->nchunks; c++)
		bus->chunk_tx[c] = -1;
	for (c = 0; c < bus->nauth_chunks; c++)
		bus->auth_chunk_tx[c] = -1;
	bus->cyclic_seq++;
	bus->cyclic_counter++; /* a sealed frame's freshness: one a slot, never repeated in a run */
	for (i = 0; i < n; i++) {
		const struct vmac_sched_entry *e = &bus->slot_entries[i];
		struct device *d = &bus->dev[e->device];
		int64_t period = bus->slot_ns << e->level;
		struct vmac_msg m;
		if (d->state != DEV_RUNNING || d->pending)
			continue;
		d->reply_window_ns = bus->reply_deadline_ns < period ? bus->reply_deadline_ns : period;
		if (d->want_watchdog) {
			memset(&m, 0, sizeof(m));
			m.op = VMAC_OP_WATCHDOG;
			m.u.watchdog_ms = d->want_watchdog;
			bus_queue(bus, d, &m, 0);
			d->aside_seq = d->seq;
			d->watchdog_ms = d->want_watchdog;
			d->want_watchdog = 0;
		}
		bus_release_outputs(bus, d, slot, e->level);
		if (d->cyclic) {
			cyclic_put(bus, d, slot, e->level);
			continue;
		}
		bus_unicast_update(bus, d, slot, e->level);
	}
}

/* Every board is told to go safe at once; every attached machine gets a
 * last job (a checkpoint, then detach) that the stop waits for no longer
 * than for the boards' acks: a driver never holds up a stop. */
void bus_begin_stop(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	bus->stopping = 1;
	bus->stop_deadline_ns = now + STOP_GRACE_PERIODS * bus->slot_ns;
	if (bus->stop_deadline_ns < now + 100000000)
		bus->stop_deadline_ns = now + 100000000; /* at least 100 ms for the acks */
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (d->state == DEV_REGISTERING || d->state == DEV_RUNNING || d->state == DEV_TO_SLEEP) {
			d->pending = 0;
			bus_send_shutdown(bus, d, VMAC_SHUT_HOST_STOP, 1);
			d->reply_window_ns = bus->stop_deadline_ns - now;
			d->state = DEV_ERRANT;
		}
		bus_unschedule(bus, d);
		d->mach = -1;
	}
	bus_flush(bus);
	for (i = 0; i < bus->nused; i++) {
		struct machine *m = &bus->mach[i];
		if (!m->used)
			continue;
		if (!m->drv || !m->attached) {
			bus_free_machine(bus, m);
			continue;
		}
		/* what each machine was doing, for the next start, and detach */
		m->want_attach = m->want_rollback = m->want_tick = 0;
		m->want_stop = 1;
		bus_dispatch(bus, m);
	}
	bus_workers_kick(bus);
}

/* Every board has acked and every machine's last job is done, or the
 * deadline has come: the machines still in a job are given up. */
static int stop_done(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	int done = 1;
	for (i = 0; i < bus->nused && done; i++)
		done = !bus->dev[i].pending && !bus->mach[i].used;
	if (!done && now < bus->stop_deadline_ns)
		return 0;
	for (i = 0; i < bus->nused; i++)
		if (bus->mach[i].used)
			bus_free_machine(bus, &bus->mach[i]);
	return 1;
}

/* One tick at `now`, `expirations` slots after the previous one. Returns 1
 * when the bus has stopped (VMAC_MSG_STOPPED posted), else 0. */
int bus_tick(struct vmac_bus *bus, int64_t now, uint64_t expirations)
{
	/* Lateness from the first tick due: a thread held for a second shows a
	 * second, not how late the last of the ticks it skipped was. */
	int64_t scheduled = bus->start_ns + (int64_t)(bus->tick_index + 1) * bus->slot_ns;
	bus->tick_index += expirations;
	bus->counters.ticks++;
	bus->counters.ticks_skipped += expirations - 1;
	atomic_store_explicit(&bus->heartbeat, bus->counters.ticks, memory_order_relaxed);
	vmac_hist_add(&bus->lateness, (now - scheduled) / 1000);
	if (!bus->virt) {
		vmac_transport_clock_sync(&bus->tr);
		bus_drain(bus);
	}
	bus_check_deadlines(bus, now);
	bus_collect(bus, now); /* the jobs done: their outputs go with this slot's services */
	if (bus->stopping) {
		if (stop_done(bus, now)) {
			struct vmac_bus_msg m;
			bus_publish(bus, now);
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
	if (bus->cfg.clock_sync_ms > 0 && now >= bus->next_sync_ns) {
		int64_t period = (int64_t)bus->cfg.clock_sync_ms * 1000000;
		bus_send_sync(bus);
		bus->next_sync_ns += period;
		if (bus->next_sync_ns <= now) /* late ticks: on from now, no burst */
			bus->next_sync_ns = now + period;
	}
	if (now >= bus->next_discover_ns) {
		send_discover(bus);
		bus->next_discover_ns = now + (int64_t)bus->cfg.discovery_period_ms * 1000000;
	}
	if (now >= bus->next_probation_ns) {
		bus_end_probations(bus, now);
		bus->next_probation_ns = now + STATUS_EVERY_NS;
	}
	service_registration(bus);
	/* Every slot in order, late ones included: the schedule's guarantees
	 * (docs/SCHEDULER.md) hold only if no slot is skipped. */
	while (bus->slots_done < bus->tick_index) {
		bus->slots_done++;
		service_slot(bus, bus->slots_done);
	}
	bus_flush(bus);
	if (now - bus->last_status_ns >= STATUS_EVERY_NS && !bus->virt)
		bus_publish(bus, now); /* vmac test reads vmac_bus_device_status instead */
	return 0;
}

static void *bus_main(void *arg)
{
	struct vmac_bus *bus = arg;
	struct itimerspec its;
	struct timespec start;

	vmac_driver_forbid_thread(); /* no driver runs here (docs/HOST.md, "Threads") */
	bus_commands(bus);           /* what the main thread sent before the start (the keys) */
	bus_try_realtime(bus);
	bus_try_cpu_awake(bus);
	clock_gettime(CLOCK_MONOTONIC, &start);
	bus->start_ns = (int64_t)start.tv_sec * 1000000000 + start.tv_nsec;
	/* Without epoll_pwait2: an absolute periodic timer. */
	memset(&its, 0, sizeof(its));
	its.it_value.tv_sec = (bus->start_ns + bus->slot_ns) / 1000000000;
	its.it_value.tv_nsec = (bus->start_ns + bus->slot_ns) % 1000000000;
	its.it_interval.tv_sec = bus->slot_ns / 1000000000;
	its.it_interval.tv_nsec = bus->slot_ns % 1000000000;
	bus->tick_index = 0;
	if (bus->timerfd_wait)
		timerfd_settime(bus->tfd, TFD_TIMER_ABSTIME, &its, NULL);
	bus->next_discover_ns = bus->start_ns;
	bus->next_sync_ns = bus->start_ns;
	bus_loop(bus);
	atomic_store(&bus->ended, 1); /* a request's waiter gives up at once (mailbox.c) */
	return NULL;
}

/* The ring to the main thread carries events and driver-load requests: room
 * for a load request and two events per device besides the usual traffic,
 * so a whole bus announcing at once is not turned away. A power of two. */
static uint32_t ring_size(const struct vmac_config *cfg)
{
	uint32_t n = 1024;
	while (n < 3 * cfg->max_devices + 1024)
		n <<= 1;
	return n;
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
	bus->epfd = -1;
	bus->wakefd = -1;
	bus->cpu_awake_fd = -1;
	bus->tr.fd = -1;
	bus->sync_tx = -1;
	bus->ndev = cfg->max_devices;
	bus->slot_ns = (int64_t)vmac_config_slot_us(cfg) * 1000;
	bus->reply_deadline_ns = (int64_t)cfg->reply_deadline_us * 1000;
	bus->dev = calloc(bus->ndev, sizeof(*bus->dev));
	bus->mach = calloc(bus->ndev, sizeof(*bus->mach));
	bus->nchunks = (bus->ndev + VMAC_CYCLIC_RECORDS_MAX - 1) / VMAC_CYCLIC_RECORDS_MAX;
	bus->chunk_tx = calloc(bus->nchunks, sizeof(*bus->chunk_tx));
	bus->nauth_chunks = (bus->ndev + VMAC_CYCLIC_AUTH_RECORDS_MAX - 1) / VMAC_CYCLIC_AUTH_RECORDS_MAX;
	bus->auth_chunk_tx = calloc(bus->nauth_chunks, sizeof(*bus->auth_chunk_tx));
	bus->nsync_chunks = (bus->ndev + VMAC_SYNC_AUTH_MACS_MAX - 1) / VMAC_SYNC_AUTH_MACS_MAX;
	bus->sync_auth_tx = calloc(bus->nsync_chunks, sizeof(*bus->sync_auth_tx));
	bus->sync_streams = calloc(1 + bus->nsync_chunks, sizeof(*bus->sync_streams));
	bus->tx = calloc((size_t)tx_max(bus), sizeof(*bus->tx));
	bus->timed_frames = calloc(cfg->slices_per_slot, sizeof(*bus->timed_frames));
	bus->status.devices = calloc(bus->ndev, sizeof(*bus->status.devices));
	bus->status.slot_load = calloc(1u << cfg->max_level, sizeof(*bus->status.slot_load));
	bus->slot_entries = calloc(cfg->slices_per_slot, sizeof(*bus->slot_entries));
	bus->sched = vmac_sched_new(cfg->slices_per_slot, cfg->max_level, cfg->max_devices);
	if (!bus->dev || !bus->mach || !bus->tx || !bus->timed_frames || !bus->chunk_tx || !bus->auth_chunk_tx ||
	    !bus->sync_auth_tx || !bus->sync_streams || !bus->status.devices || !bus->status.slot_load ||
	    !bus->slot_entries || !bus->sched ||
	    vmac_ring_init(&bus->to_main, sizeof(struct vmac_bus_msg), ring_size(cfg)) ||
	    vmac_ring_init(&bus->to_bus, sizeof(struct vmac_host_cmd), 1024) || bus_checkpoints_init(bus) ||
	    bus_jobs_init(bus)) {
		snprintf(err, errlen, "out of memory");
		vmac_bus_free(bus);
		return NULL;
	}
	for (i = 0; i < bus->ndev; i++) {
		bus->dev[i].mach = -1;
		bus->mach[i].worker = -1;
	}
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
		snprintf(err, errlen,
		         "bus '%s': expected MULTICAST_GROUP:PORT (UDP, e.g. 239.255.86.77:5870) or eth:IFACE (raw "
		         "Ethernet, e.g. eth:eth0)",
		         cfg->bus);
		return NULL;
	}
	if (spec.kind == VMAC_TRANSPORT_UDP && inet_pton(AF_INET, cfg->iface, &spec.iface) != 1) {
		snprintf(err, errlen, "iface '%s': expected an IPv4 address", cfg->iface);
		return NULL;
	}
	bus = bus_alloc(cfg, err, errlen);
	if (!bus)
		return NULL;
	bus_nonce_init(bus);
	if (vmac_transport_open_host(&bus->tr, &spec, err, errlen) < 0)
		goto fail;
	/* SYNC's two-step: the kernel's transmit stamps, where it gives them
	 * (off, every prev_tx_ns is 0 and boards take the one-step host_ns;
	 * VMAC_SYNC_ONE_STEP=1 turns them off for a measurement's baseline). */
	if (cfg->clock_sync_ms > 0 && !getenv("VMAC_SYNC_ONE_STEP"))
		vmac_transport_tx_stamps_on(&bus->tr);
	vmac_addr_format(&bus->tr.local, bus->host_addr, sizeof(bus->host_addr));
	bus->tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
	if (bus->tfd < 0) {
		snprintf(err, errlen, "cannot create the tick timer: %s", strerror(errno));
		goto fail;
	}
	if (bus_wait_init(bus, err, errlen) != 0 || bus_workers_init(bus, err, errlen) != 0)
		goto fail;
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
	bus_nonce_init(bus); /* the same nonces every run */
	bus->link = *link;
	bus->tr.group = *group;
	snprintf(bus->host_addr, sizeof(bus->host_addr), "virtual");
	return bus;
}

int vmac_bus_virtual_tick(struct vmac_bus *bus, int64_t now_ns)
{
	uint64_t index = (uint64_t)((now_ns - bus->start_ns) / bus->slot_ns);
	bus->virt_now_ns = now_ns;
	if (index <= bus->tick_index)
		return 0;
	return bus_tick(bus, now_ns, index - bus->tick_index);
}

void vmac_bus_virtual_start_at(struct vmac_bus *bus, int64_t now_ns)
{
	bus->virt_now_ns = now_ns;
	bus->start_ns = now_ns; /* bus time 0, slot 0: as a host that starts now */
	bus->next_discover_ns = now_ns;
}

int64_t vmac_bus_virtual_next_tick(const struct vmac_bus *bus)
{
	return bus->start_ns + (int64_t)(bus->tick_index + 1) * bus->slot_ns;
}

void vmac_bus_virtual_receive(struct vmac_bus *bus, const struct vmac_packet *p)
{
	bus->virt_now_ns = p->rx_ns;
	bus_handle_packet(bus, p);
	bus_flush(bus);
}

void vmac_bus_virtual_commands(struct vmac_bus *bus)
{
	bus_commands(bus);
	bus_requests(bus);
}

void vmac_bus_free(struct vmac_bus *bus)
{
	uint32_t i;
	int stuck;
	if (!bus)
		return;
	bus_workers_fini(bus);
	stuck = bus->workers != NULL; /* a worker still inside a driver's call: what it holds stays */
	if (bus->mach && bus->jobs)
		for (i = 0; i < bus->ndev; i++) {
			struct job *j = &bus->jobs[i];
			int st = atomic_load(&j->state);
			if (!bus->virt && (st == JOB_RUNNING || st == JOB_DROPPED || st == JOB_STALLED))
				continue; /* a worker's (virtual mode has none: a slow driver's call is the bus's) */
			/* a host gone without stopping (vmac test's crash_host) */
			vmac_driver_free(bus->mach[i].drv);
			if (bus->mach[i].prev != bus->mach[i].drv)
				vmac_driver_free(bus->mach[i].prev);
			vmac_recorder_free(bus->mach[i].rec);
			free(j->ckpt);
		}
	if (stuck)
		return; /* the process ends: what a stuck worker reads (the bus, its jobs) stays */
	bus_wait_fini(bus);
	{ /* commands never taken (a host that failed before its bus started) */
		struct vmac_host_cmd c;
		while (bus->to_bus.buf && vmac_ring_pop(&bus->to_bus, &c)) {
			vmac_bus_keys_free(c.keys);
			vmac_driver_free(c.drv);
			vmac_recorder_free(c.rec);
			free(c.ckpt);
		}
	}
	vmac_transport_close(&bus->tr);
	if (bus->tfd >= 0)
		close(bus->tfd);
	if (bus->cpu_awake_fd >= 0)
		close(bus->cpu_awake_fd);
	vmac_ring_fini(&bus->to_main);
	vmac_ring_fini(&bus->to_bus);
	bus_checkpoints_fini(bus);
	for (i = 0; i < VMAC_BUS_REQUESTS; i++)
		sem_destroy(&bus->req[i].done);
	free(bus->dev);
	bus_jobs_fini(bus);
	free(bus->mach);
	free(bus->tx);
	free(bus->chunk_tx);
	free(bus->auth_chunk_tx);
	free(bus->sync_auth_tx);
	free(bus->sync_streams);
	free(bus->timed_frames);
	vmac_bus_keys_free(bus->keys);
	free(bus->status.devices);
	free(bus->status.slot_load);
	free(bus->slot_entries);
	vmac_sched_free(bus->sched);
	free(bus);
}

int vmac_bus_start(struct vmac_bus *bus)
{
	int rc = bus_workers_start(bus);
	if (rc != 0)
		return rc;
	rc = pthread_create(&bus->thread, NULL, bus_main, bus);
	if (rc == 0)
		pthread_setname_np(bus->thread, "vmac-bus"); /* top -H, gdb, the watchdog test */
	return -rc;
}

uint64_t vmac_bus_heartbeat(struct vmac_bus *bus)
{
	return atomic_load_explicit(&bus->heartbeat, memory_order_relaxed);
}

void vmac_bus_join(struct vmac_bus *bus)
{
	pthread_join(bus->thread, NULL);
}

const char *vmac_bus_host_addr(struct vmac_bus *bus)
{
	return bus->host_addr;
}
