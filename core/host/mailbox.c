/* Between the bus thread and the others, without waiting and without
 * allocating on the bus thread: events and unloaded drivers to the main
 * thread (a ring), commands from it (a ring and an eventfd), and the
 * request slots through which the HTTP threads hand in operator input, a
 * hot-reload swap or a question, and wait for the answer. What the bus
 * thread does with each kind of request is request_handlers, apart from
 * the slots' own mechanics. */
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
#include "../common/monotime.h"
#include "../sched/sched.h"

#define REQUEST_SLICE_MS 50 /* a waiter for the bus thread looks this often whether it has ended */

int vmac_bus_input(struct vmac_bus *bus, const char *device, const char *name, const struct vmac_value *value,
                   char *reply, size_t replylen);

/* ---- messages to the main thread (no allocation: fixed ring slots) ---- */

int bus_post(struct vmac_bus *bus, const struct vmac_bus_msg *m)
{
	if (vmac_ring_push(&bus->to_main, m) != 0) {
		bus->counters.events_lost++;
		return -EAGAIN;
	}
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
	return 0;
}

void bus_event(struct vmac_bus *bus, const struct device *d, const char *kind, const char *fmt, ...)
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
	bus_post(bus, &m);
}

/* An event the main thread acts on besides recording it (code: a version
 * rolled back or stalled, version_id and version saying which). */
void bus_post_code(struct vmac_bus *bus, enum vmac_event_code code, const struct machine *m, const char *version,
                   int64_t version_id, const char *kind, const char *text)
{
	struct vmac_bus_msg msg;
	memset(&msg, 0, sizeof(msg));
	msg.kind = VMAC_MSG_EVENT;
	msg.code = code;
	msg.time_ns = bus_now(bus);
	memcpy(msg.device, bus->dev[m->primary].ann.board, sizeof(msg.device));
	memcpy(msg.driver, m->driver, sizeof(msg.driver));
	snprintf(msg.version, sizeof(msg.version), "%s", version);
	msg.version_id = version_id;
	snprintf(msg.event_kind, sizeof(msg.event_kind), "%s", kind);
	snprintf(msg.text, sizeof(msg.text), "%s", text);
	bus_post(bus, &msg);
}

/* ---- what each kind of request does, on the bus thread ---- */

/* Input request slot i: refused now (answered), or waiting for its
 * machine's job, which answers it (jobs.c); with persist, only to a
 * persist = true param. */
struct device *bus_request_target(struct vmac_bus *bus, int i, char device[VMAC_NAME_MAX + 1], struct machine **m)
{
	struct device *d;
	/* Copied out: the reply and the device's name are parts of one struct,
	 * and the reply is written while the name is still needed. */
	memcpy(device, bus->req[i].r.device, VMAC_NAME_MAX + 1);
	d = bus_find_by_name(bus, device);
	*m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	return d;
}

static void input_request(struct vmac_bus *bus, int i)
{
	struct request *q = &bus->req[i];
	struct vmac_bus_input_request *r = &q->r;
	char device[VMAC_NAME_MAX + 1];
	struct machine *m;
	struct device *d = bus_request_target(bus, i, device, &m);
	if (!m || !m->drv || !m->attached || d->state != DEV_RUNNING || bus->stopping) {
		snprintf(r->reply, sizeof(r->reply), "%s is not running (%s)", device,
		         d ? bus_state_name(d->state) : "no such device");
		r->rc = -VMAC_ENOTRUNNING;
		bus_answer(bus, i);
		return;
	}
	if (r->persist && vmac_driver_param_persists(m->drv, r->name) != 1) {
		const char *why = vmac_driver_param_persists(m->drv, r->name) < 0
		                      ? "only params persist, and the driver has no such param"
		                      : "this param does not persist (the driver does not declare it persist = true)";
		size_t n = strlen(r->name);
		memcpy(r->reply, r->name,
		       n); /* name and reply are parts of one struct: no snprintf of one into the other */
		snprintf(r->reply + n, sizeof(r->reply) - n, ": %s", why);
		r->rc = VMAC_REFUSED_NOT_PERSIST;
		bus_answer(bus, i);
		return;
	}
	m->inputs[m->ninputs++] = i; /* room: one per request slot */
	bus_dispatch(bus, m);
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

/* Record request slot i: the machine's flight recorder captured now. */
static void record_request(struct vmac_bus *bus, int i)
{
	struct request *q = &bus->req[i];
	char device[VMAC_NAME_MAX + 1];
	struct machine *m;
	struct device *d = bus_request_target(bus, i, device, &m);
	if (!m || !m->attached || d->state != DEV_RUNNING) {
		snprintf(q->r.reply, sizeof(q->r.reply), "%s: no running machine of that name", device);
		q->r.rc = -VMAC_ENOTRUNNING;
	} else if (bus_rec_capture(bus, m, "asked for (vmac record)") != 0) {
		snprintf(q->r.reply, sizeof(q->r.reply),
		         "%s: no flight recorder (recorder_s is 0, or a capture is being written)", device);
		q->r.rc = -VMAC_EFAIL;
	} else {
		snprintf(q->r.reply, sizeof(q->r.reply), "%s: captured; GET /api/recordings lists it", device);
		q->r.rc = 0;
	}
	bus_answer(bus, i);
}

/* Machines request slot i: the machines of the driver q->r.name. Every
 * command sent before it was queued is handled first: a driver the main
 * thread handed over is in its machine when the list is made. */
static void machines_request(struct vmac_bus *bus, int i)
{
	struct request *q = &bus->req[i];
	bus_commands(bus);
	q->r.rc = list_machines(bus, q->r.name, q->names, q->max_names);
	bus_answer(bus, i);
}

/* What the bus thread does with request slot i of each kind: answer it
 * (bus_answer), or hand it to its machine's job, which answers it. */
typedef void request_handler(struct vmac_bus *bus, int i);

static request_handler *const request_handlers[] = {
    [REQ_INPUT] = input_request,
    [REQ_SWAP] = bus_swap,
    [REQ_MACHINES] = machines_request,
    [REQ_RECORD] = record_request,
};

_Static_assert(sizeof(request_handlers) / sizeof(request_handlers[0]) == REQ_KINDS, "a handler for every kind");

/* ---- the request slots (see struct request) ---- */

/* The requests other threads queued: each slot QUEUED taken (RUNNING)
 * and handed to the handler of its kind; each ABANDONED freed. */
void bus_requests(struct vmac_bus *bus)
{
	int i, expect;
	if (atomic_exchange(&bus->req_queued, 0) == 0)
		return;
	for (i = 0; i < VMAC_BUS_REQUESTS; i++) {
		struct request *q = &bus->req[i];
		expect = REQ_QUEUED;
		if (atomic_compare_exchange_strong(&q->state, &expect, REQ_RUNNING))
			request_handlers[q->kind](bus, i);
		else if (expect == REQ_ABANDONED)
			atomic_store(&q->state, REQ_FREE);
	}
	bus_workers_kick(bus);
}

/* Hands req (and drv, probation_ns, names: what the kind needs) to the bus
 * thread in a free slot and waits up to timeout_ms for the answer, which
 * is copied back into req: 0, or -VMAC_EBUSY (no free slot, or not taken
 * in time) with req->reply saying which. Any thread but the bus thread. */
static int bus_request(struct vmac_bus *bus, enum bus_request_kind kind, struct vmac_bus_input_request *req,
                       struct vmac_driver *drv, int64_t probation_ns, char (*names)[VMAC_NAME_MAX + 1], int max_names,
                       int timeout_ms)
{
	struct request *q = NULL;
	int i, expect, rc, waited, slice;
	if (atomic_load(&bus->ended)) {
		snprintf(req->reply, sizeof(req->reply), "the host is stopping");
		return -VMAC_EBUSY;
	}
	for (i = 0; i < VMAC_BUS_REQUESTS && !q; i++) {
		expect = REQ_FREE;
		if (atomic_compare_exchange_strong(&bus->req[i].state, &expect, REQ_FILLING))
			q = &bus->req[i];
	}
	if (!q) {
		snprintf(req->reply, sizeof(req->reply), "the host is busy with other requests; try again");
		return -VMAC_EBUSY;
	}
	q->kind = kind;
	q->r = *req;
	q->drv = drv;
	q->probation_ns = probation_ns;
	q->names = names;
	q->max_names = max_names;
	atomic_store(&q->state, REQ_QUEUED);
	atomic_store(&bus->req_queued, 1);
	if (!bus->virt)
		bus_wake(bus);
	/* In slices of 50 ms: a bus thread that ends meanwhile (the host
	 * stopping) takes no more requests, and its waiter need not wait out
	 * the whole time (a deploy stopped by SIGTERM has many to make). */
	for (waited = 0;; waited += slice) {
		struct timespec until;
		slice = timeout_ms - waited < REQUEST_SLICE_MS ? timeout_ms - waited : REQUEST_SLICE_MS;
		until = vmac_mono_after_ns((int64_t)slice * 1000000);
		while ((rc = sem_clockwait(&q->done, CLOCK_MONOTONIC, &until)) != 0 && errno == EINTR)
			;
		if (rc == 0 || atomic_load(&bus->ended) || waited + slice >= timeout_ms)
			break;
	}
	if (rc != 0) {
		expect = REQ_QUEUED;
		if (atomic_compare_exchange_strong(&q->state, &expect, REQ_ABANDONED)) {
			if (atomic_load(&bus->ended))
				snprintf(req->reply, sizeof(req->reply), "the host is stopping");
			else
				snprintf(req->reply, sizeof(req->reply),
				         "the bus thread did not take the request within %d ms", timeout_ms);
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
	return bus_request(bus, REQ_INPUT, req, NULL, 0, NULL, 0, timeout_ms);
}

int vmac_bus_request_swap(struct vmac_bus *bus, const char *device, struct vmac_driver *drv, unsigned probation_ms,
                          int timeout_ms, int *rc, char *reply, size_t replylen)
{
	struct vmac_bus_input_request req;
	int r;
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	r = bus_request(bus, REQ_SWAP, &req, drv, (int64_t)probation_ms * 1000000, NULL, 0, timeout_ms);
	*rc = r == 0 ? req.rc : r;
	snprintf(reply, replylen, "%s", req.reply);
	return r;
}

int vmac_bus_request_record(struct vmac_bus *bus, const char *device, int timeout_ms, char *reply, size_t replylen)
{
	struct vmac_bus_input_request req;
	int r;
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	r = bus_request(bus, REQ_RECORD, &req, NULL, 0, NULL, 0, timeout_ms);
	snprintf(reply, replylen, "%s", req.reply);
	return r != 0 ? r : req.rc;
}

int vmac_bus_request_machines(struct vmac_bus *bus, const char *driver, char (*names)[VMAC_NAME_MAX + 1], int max,
                              int timeout_ms, char *reply, size_t replylen)
{
	struct vmac_bus_input_request req;
	memset(&req, 0, sizeof(req));
	snprintf(req.name, sizeof(req.name), "%s", driver);
	int r = bus_request(bus, REQ_MACHINES, &req, NULL, 0, names, max, timeout_ms);
	if (r != 0) {
		snprintf(reply, replylen, "%s", req.reply);
		return r;
	}
	return req.rc;
}

/* ---- commands from the main thread; input in virtual mode ---- */

void bus_commands(struct vmac_bus *bus)
{
	struct vmac_host_cmd c;
	while (vmac_ring_pop(&bus->to_bus, &c)) {
		struct device *d;
		if (c.kind == VMAC_CMD_STOP) {
			if (!bus->stopping)
				bus_begin_stop(bus, bus_now(bus));
			continue;
		}
		if (c.kind == VMAC_CMD_RECORDER) {
			bus_rec_install(bus, &c);
			continue;
		}
		if (c.kind == VMAC_CMD_KEYS) {
			bus_keys_install(bus, c.keys);
			continue;
		}
		d = c.slot < bus->ndev ? &bus->dev[c.slot] : NULL;
		if (!d || d->state != DEV_LOADING || d->generation != c.generation || bus->stopping || d->mach < 0 ||
		    bus->mach[d->mach].primary != c.slot || bus->mach[d->mach].drv) {
			if (c.drv || c.rec || c.ckpt) { /* the device went away meanwhile */
				struct vmac_bus_msg u;
				memset(&u, 0, sizeof(u));
				u.kind = VMAC_MSG_UNLOAD;
				u.drv = c.drv;
				u.rec = c.rec;
				u.buf = c.ckpt;
				if (bus_post(bus, &u) != 0) { /* slow but safe: the main thread is far behind */
					vmac_driver_free(c.drv);
					vmac_recorder_free(c.rec);
					free(c.ckpt);
				}
			}
			continue;
		}
		bus_on_loaded(bus, d, &c);
	}
}

int vmac_bus_input(struct vmac_bus *bus, const char *device, const char *name, const struct vmac_value *value,
                   char *reply, size_t replylen)
{
	struct device *d = bus_find_by_name(bus, device);
	struct machine *m = d && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	struct job *j;
	if (!bus->virt) {
		snprintf(reply, replylen, "host error: vmac_bus_input is for virtual mode; use vmac_bus_request_input");
		return -VMAC_EFAIL;
	}
	if (!m || !m->drv || !m->attached || d->state != DEV_RUNNING || bus->stopping) {
		snprintf(reply, replylen, "%s is not running (%s)", device,
		         d ? bus_state_name(d->state) : "no such device");
		return -VMAC_ENOTRUNNING;
	}
	if (!bus_machine_idle(bus, m)) {
		snprintf(reply, replylen, "%s is busy: its driver's last call has not returned yet (driver_cost)",
		         device);
		return -VMAC_EBUSY;
	}
	/* One thread: the job runs and is collected before this returns. */
	j = &bus->jobs[m - bus->mach];
	snprintf(j->name, sizeof(j->name), "%s", name);
	j->value = *value;
	j->input_rc = -VMAC_ENOTRUNNING;
	bus_input_now(bus, m);
	snprintf(reply, replylen, "%s", j->reply);
	if (atomic_load(&j->state) == JOB_RUNNING) /* a slow driver (driver_cost): run, collected later */
		return j->rc < 0 ? -VMAC_EDRIVER : j->rc;
	return j->input_rc; /* the job's: a failure has freed the machine */
}

void vmac_bus_set_wakeup(struct vmac_bus *bus, void (*wakeup)(void *), void *ctx)
{
	bus->wakeup = wakeup;
	bus->wakeup_ctx = ctx;
}

void vmac_bus_wake_main(struct vmac_bus *bus)
{
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
}

int vmac_bus_send_cmd(struct vmac_bus *bus, const struct vmac_host_cmd *cmd)
{
	if (vmac_ring_push(&bus->to_bus, cmd) != 0)
		return -EAGAIN;
	if (!bus->virt)
		bus_wake(bus);
	return 0;
}

int vmac_bus_loaded(struct vmac_bus *bus, const struct vmac_bus_msg *load, int rc, struct vmac_driver *drv,
                    const char *text)
{
	struct vmac_host_cmd c;
	memset(&c, 0, sizeof(c));
	c.kind = VMAC_CMD_LOADED;
	c.slot = load->slot;
	c.generation = load->generation;
	c.drv = drv;
	if (drv) { /* sized for recorder_s at the driver's level */
		c.rec = vmac_recorder_new(bus->cfg.recorder_s, (double)(bus->slot_ns << vmac_driver_level(drv)) / 1e9);
		c.ckpt = malloc((size_t)bus->cfg.checkpoint_kib * 1024); /* NULL: its checkpoints say so */
	}
	c.missing = rc == -ENOENT;
	snprintf(c.text, sizeof(c.text), "%s", text);
	if (vmac_bus_send_cmd(bus, &c) != 0) {
		vmac_driver_free(drv);
		vmac_recorder_free(c.rec);
		free(c.ckpt);
		return -EAGAIN;
	}
	return 0;
}
