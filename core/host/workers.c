/* Driver workers (docs/HOST.md, "Threads"): the threads that run every
 * call into a driver's state, so that the bus thread never does. Each
 * worker takes the jobs the bus thread queues on it (a ring of machine
 * indexes, one job per machine at a time: struct job in bus_internal.h;
 * a machine stays on its worker, so that its state stays warm there, and
 * moves only when the worker is far behind),
 * runs them, and hands back what they gave through the job itself; its
 * drivers' events and the instances it must dispose of go to the main
 * thread through a ring of its own. A worker the bus thread gave up on (a
 * job that overran: stuck in one C call) is retired: its machines go to a
 * spare, it drops to the lowest priority, and it ends when (if) the call
 * returns. The main thread keeps a spare ready (vmac_bus_workers_service).
 * In virtual mode (vmac test) there are no workers: jobs run inline. */
#include "bus_internal.h"

#include <errno.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

#include "../common/monotime.h"

#define WORKER_PRIORITY 40 /* SCHED_FIFO, below the bus thread's 50 */
#define WORKER_OUT_SLOTS 256
/* Workers given up (a driver's call still holds each) that the host
 * makes room for, beside its own and the spare. */
#define WORKERS_STUCK_MAX 64
#define PARAMS_EVERY_NS 100000000LL /* params copied out at most this often after ticks */
/* A machine moves off its worker only when the oldest job queued there has
 * waited that part of a slot: a move costs the next calls a cold state on
 * another core, and a burst of replies queues many jobs at once. */
#define MOVE_AFTER_SLOTS(slot_ns) ((slot_ns) / 2)

/* ---- a worker's queue: the bus thread pushes, the worker takes ---- */

/* Bus thread. 0, or -1 when the ring is full. */
static int queue_push(struct worker *w, int mi, int64_t t_ns)
{
	uint32_t h = atomic_load_explicit(&w->head, memory_order_relaxed);
	if (h - w->tail_seen > w->mask) {
		w->tail_seen = atomic_load_explicit(&w->tail, memory_order_acquire);
		if (h - w->tail_seen > w->mask)
			return -1;
	}
	w->queue[h & w->mask] = mi;
	w->push_ns[h & w->mask] = t_ns;
	atomic_store_explicit(&w->head, h + 1, memory_order_release);
	return 0;
}

/* Worker. 1 and *mi, or 0 when the ring is empty (as last seen). */
static int queue_take(struct worker *w, int *mi)
{
	uint32_t t = atomic_load_explicit(&w->tail, memory_order_relaxed);
	if (t == w->head_seen) {
		w->head_seen = atomic_load_explicit(&w->head, memory_order_acquire);
		if (t == w->head_seen)
			return 0;
	}
	*mi = w->queue[t & w->mask];
	atomic_store_explicit(&w->tail, t + 1, memory_order_release);
	return 1;
}

/* Worker, about to sleep (after a seq_cst fence): anything pushed since? */
static int queue_pushed(struct worker *w)
{
	w->head_seen = atomic_load(&w->head);
	return atomic_load_explicit(&w->tail, memory_order_relaxed) != w->head_seen;
}

/* ---- running a job (any thread but the bus thread; inline in virtual mode) ---- */

/* The machine's boards and level as the bus has them, told to d first. */
static void sync_instance(struct vmac_driver *d, const struct job *j)
{
	int i;
	for (i = vmac_driver_boards(d); i < j->nboards; i++)
		vmac_driver_add_board(d, j->minor[i], j->board[i]);
	if (vmac_driver_level(d) != j->level)
		vmac_driver_set_level_now(d, j->level);
}

static void take_checkpoint(struct job *j, struct vmac_driver *d)
{
	char err[VMAC_DRIVER_ERR_MAX];
	size_t cap = (size_t)j->bus->cfg.checkpoint_kib * 1024;
	if (!j->ckpt) {
		j->ckpt_rc = -1;
		snprintf(j->ckpt_err, sizeof(j->ckpt_err), "no memory for checkpoints");
		return;
	}
	if (vmac_driver_checkpoint(d, j->ckpt, cap, &j->ckpt_len, err, sizeof(err)) != 0) {
		j->ckpt_rc = -1;
		snprintf(j->ckpt_err, sizeof(j->ckpt_err), "%s", err);
		return;
	}
	j->ckpt_rc = 1;
}

/* What the status shows of the instance that runs the machine now: its
 * variables when they moved, its params after anything but a tick and at
 * most every 100 ms after ticks, its memory, instructions and time. */
static void copy_out(struct job *j, struct vmac_driver *d)
{
	int64_t t_ns = (int64_t)(j->time_s * 1e9);
	int i, n;
	if (d != j->vars_of || vmac_driver_vars_version(d) != j->vars_version) {
		n = vmac_driver_nvars(d);
		for (i = 0; i < n; i++)
			j->vars[i] = *vmac_driver_variable(d, i);
		j->nvars = n;
		j->vars_of = d;
		j->vars_version = vmac_driver_vars_version(d);
		j->vars_fresh = 1;
	}
	if (j->kind != JOB_TICK || t_ns - j->params_ns >= PARAMS_EVERY_NS || t_ns < j->params_ns) {
		j->nparams = vmac_driver_params(d, j->params);
		j->params_ns = t_ns;
		j->params_fresh = 1;
	}
	j->memory = vmac_driver_memory(d);
	j->instructions = vmac_driver_instructions(d);
	j->call_ns = vmac_driver_call_ns(d);
}

void bus_run_job(struct job *j)
{
	struct vmac_driver *d = j->drv, *now = j->drv;
	const struct vmac_inputs *in[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs *out[VMAC_DRIVER_MAX_BOARDS];
	int i, r;
	j->want_level = -1;
	j->ckpt_rc = 0;
	j->vars_fresh = j->params_fresh = 0;
	j->recover_rc = VMAC_RECOVER_NONE; /* err and reply are written only when rc or the kind says so */
	switch (j->kind) {
	case JOB_ATTACH:
		sync_instance(d, j);
		j->rc = vmac_driver_attach(d, j->time_s, j->err, sizeof(j->err));
		if (j->rc == 0) {
			r = vmac_driver_recover(d, j->time_s, j->err, sizeof(j->err));
			j->recover_rc = r;
			j->rc = r < 0 ? -1 : 0;
		}
		break;
	case JOB_TICK:
		sync_instance(d, j);
		for (i = 0; i < j->nboards; i++) {
			in[i] = &j->in[i];
			out[i] = &j->out[i];
		}
		vmac_driver_sample_times(d, j->sample_s, j->nboards);
		j->rc = vmac_driver_tick(d, j->time_s, in, out, j->err, sizeof(j->err));
		j->out_at_s = vmac_driver_output_at(d);
		if (j->rc == 0 && (j->checkpoint || vmac_driver_checkpoint_asked(d)))
			take_checkpoint(j, d);
		break;
	case JOB_INPUT:
		sync_instance(d, j);
		j->rc = vmac_driver_input(d, j->time_s, j->name, &j->value, j->reply, sizeof(j->reply), j->err,
		                          sizeof(j->err));
		break;
	case JOB_SWAP:     /* drv is the running instance, other the new one */
	case JOB_ROLLBACK: /* drv is the previous instance, other the failed one */
		sync_instance(j->kind == JOB_SWAP ? j->other : j->drv, j);
		j->rc = j->kind == JOB_SWAP
		            ? vmac_driver_take_over(j->other, j->drv, j->time_s, j->err, sizeof(j->err))
		            : vmac_driver_take_over(j->drv, j->other, j->time_s, j->err, sizeof(j->err));
		if (j->rc == 0 && j->kind == JOB_SWAP)
			now = j->other;
		break;
	case JOB_STOP:
		if (j->checkpoint)
			take_checkpoint(j, d);
		vmac_driver_detach(d, "host stopping");
		j->rc = 0;
		break;
	}
	copy_out(j, now);
}

/* ---- the workers ---- */

static int64_t thread_cpu_ns(pthread_t t)
{
	clockid_t c;
	struct timespec ts;
	if (pthread_getcpuclockid(t, &c) != 0 || clock_gettime(c, &ts) != 0)
		return -1;
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* To the main thread, from worker w (its own ring: w is the one producer). */
static void worker_post(struct worker *w, const struct vmac_bus_msg *m)
{
	if (vmac_ring_push(&w->out, m) != 0) {
		atomic_fetch_add(&w->events_lost, 1);
		return;
	}
	if (w->bus->wakeup)
		w->bus->wakeup(w->bus->wakeup_ctx);
}

/* A job given up while w ran it: its instances and checkpoint buffer are
 * w's to dispose of (the main thread closes the instances). */
static void dispose(struct worker *w, struct job *j)
{
	struct vmac_bus_msg m;
	struct vmac_driver *d[2] = {j->drv, j->other};
	int i;
	for (i = 0; i < 2; i++) {
		if (!d[i])
			continue;
		memset(&m, 0, sizeof(m));
		m.kind = VMAC_MSG_UNLOAD;
		m.drv = d[i];
		if (vmac_ring_push(&w->out, &m) != 0)
			vmac_driver_free(d[i]); /* the main thread is far behind: slow, but this thread may be */
	}
	free(j->ckpt);
	j->drv = j->other = NULL;
	j->ckpt = NULL;
	if (w->bus->wakeup)
		w->bus->wakeup(w->bus->wakeup_ctx);
}

static void worker_priority(struct worker *w)
{
	struct sched_param sp;
	if (!w->bus->cfg.realtime)
		return;
	memset(&sp, 0, sizeof(sp));
	sp.sched_priority = WORKER_PRIORITY;
	pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp); /* refused: the bus thread said so already */
}

static void *worker_main(void *arg)
{
	struct worker *w = arg;
	struct vmac_bus *bus = w->bus;
	uint64_t n;
	int mi, expect;
	worker_priority(w);
	while (!atomic_load(&w->quit)) {
		struct job *j;
		if (!queue_take(w, &mi)) {
			atomic_store(&w->sleeping, 1);
			/* Store, then load: the bus pushes, then looks at sleeping
			 * (bus_workers_kick); the fences keep either side from
			 * reading before its own write is seen, or a wake is lost. */
			atomic_thread_fence(memory_order_seq_cst);
			if (queue_pushed(w) || atomic_load(&w->quit)) {
				atomic_store(&w->sleeping, 0);
				continue;
			}
			if (read(w->efd, &n, sizeof(n)) < 0 && errno != EINTR && errno != EAGAIN)
				break;
			atomic_store(&w->sleeping, 0);
			continue;
		}
		j = &bus->jobs[mi];
		expect = JOB_QUEUED;
		if (!atomic_compare_exchange_strong(&j->state, &expect, JOB_RUNNING))
			continue; /* taken back, or moved to another worker that took it */
		atomic_store_explicit(&j->runner, w->index, memory_order_relaxed);
		bus_run_job(j);
		expect = JOB_RUNNING;
		if (atomic_compare_exchange_strong(&j->state, &expect, JOB_DONE))
			continue;
		dispose(w, j); /* given up: DROPPED or STALLED */
		atomic_store(&j->state, JOB_DISPOSED);
		if (expect == JOB_STALLED)
			break; /* retired: another worker has its machines */
	}
	atomic_store(&w->state, W_EXITED);
	if (bus->wakeup)
		bus->wakeup(bus->wakeup_ctx);
	return NULL;
}

/* Start a thread in the free worker w as a spare. 0 or a positive errno. */
static int start_worker(struct worker *w, int state)
{
	sigset_t all, old;
	int rc;
	/* Its rings go on from where the thread before left them: a stale job
	 * is skipped (its state says so), and what it left for the main thread
	 * is still read. nmach and kick are the bus thread's (0 since the
	 * machines left it). */
	atomic_store(&w->quit, 0);
	atomic_store(&w->sleeping, 0);
	sigfillset(&all); /* signals are the main thread's */
	pthread_sigmask(SIG_BLOCK, &all, &old);
	rc = pthread_create(&w->thread, NULL, worker_main, w);
	pthread_sigmask(SIG_SETMASK, &old, NULL);
	if (rc == 0) {
		char name[16];
		snprintf(name, sizeof(name), "vmac-worker-%d", w->index % 1000);
		pthread_setname_np(w->thread, name);
		atomic_store(&w->state, state); /* visible to the bus thread only once it runs */
	}
	return rc;
}

static int cpus_to_use(void)
{
	cpu_set_t set;
	int n = 0;
	if (sched_getaffinity(0, sizeof(set), &set) == 0)
		n = CPU_COUNT(&set);
	return n > 0 ? n : 1;
}

/* A slot's eventfd and rings, made when it is first used (main thread,
 * before its thread starts); a slot used before keeps them. */
static int equip(struct worker *w)
{
	if (w->queue)
		return 0;
	w->efd = eventfd(0, EFD_CLOEXEC);
	w->queue = calloc((size_t)w->mask + 1, sizeof(*w->queue));
	w->push_ns = calloc((size_t)w->mask + 1, sizeof(*w->push_ns));
	if (w->efd >= 0 && w->queue && w->push_ns &&
	    vmac_ring_init(&w->out, sizeof(struct vmac_bus_msg), WORKER_OUT_SLOTS) == 0)
		return 0;
	if (w->efd >= 0)
		close(w->efd);
	w->efd = -1;
	free(w->queue);
	free(w->push_ns);
	w->queue = NULL;
	w->push_ns = NULL;
	return -1;
}

int bus_workers_init(struct vmac_bus *bus, char *err, size_t errlen)
{
	int i, ring = 4;
	bus->nworkers = bus->cfg.driver_threads ? (int)bus->cfg.driver_threads : cpus_to_use();
	/* Room for the spare and for workers given up while a driver's call
	 * holds them, until the call returns (a stall of many machines at
	 * once: DRIVERS.md, "Isolation"). Slots are equipped when used. */
	bus->nworkers_max = bus->nworkers + 1 + WORKERS_STUCK_MAX;
	/* Each on lines of its own (struct worker), its sides apart. */
	bus->workers = aligned_alloc(_Alignof(struct worker), (size_t)bus->nworkers_max * sizeof(*bus->workers));
	if (!bus->workers)
		goto fail;
	memset(bus->workers, 0, (size_t)bus->nworkers_max * sizeof(*bus->workers));
	while (ring < 4 * (int)bus->ndev)
		ring <<= 1;
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		w->index = i;
		w->bus = bus;
		w->mask = (uint32_t)ring - 1;
		w->efd = -1;
	}
	for (i = 0; i <= bus->nworkers; i++) /* the active ones and the spare */
		if (equip(&bus->workers[i]) != 0)
			goto fail;
	return 0;
fail:
	snprintf(err, errlen, "cannot set up the driver workers: %s", strerror(errno ? errno : ENOMEM));
	return -1;
}

int bus_workers_start(struct vmac_bus *bus)
{
	int i, rc;
	for (i = 0; i <= bus->nworkers; i++) /* the last one a spare */
		if ((rc = start_worker(&bus->workers[i], i < bus->nworkers ? W_ACTIVE : W_SPARE)) != 0)
			return -rc;
	return 0;
}

/* Main thread, at exit: every worker told to end, and waited for a moment;
 * one still inside a driver's call is left to the process's end, with
 * what it holds. 1 when every worker ended. */
static int stop_workers(struct vmac_bus *bus)
{
	struct timespec until;
	int i, all = 1;
	uint64_t one = 1;
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		if (atomic_load(&w->state) == W_FREE)
			continue;
		atomic_store(&w->quit, 1);
		if (write(w->efd, &one, sizeof(one)) < 0) {
			/* the counter is full: it wakes anyway */
		}
	}
	until = vmac_mono_after_ns(200000000);
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		if (atomic_load(&w->state) == W_FREE)
			continue;
		if (pthread_clockjoin_np(w->thread, NULL, CLOCK_MONOTONIC, &until) != 0) {
			pthread_detach(w->thread);
			all = 0;
		}
	}
	return all;
}

void bus_workers_fini(struct vmac_bus *bus)
{
	int i;
	if (!bus->workers)
		return;
	if (!bus->virt && !stop_workers(bus))
		return; /* a worker still runs a driver's call: what it reads stays */
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		struct vmac_bus_msg m;
		while (w->out.buf && vmac_ring_pop(&w->out, &m))
			if (m.kind == VMAC_MSG_UNLOAD) {
				vmac_driver_free(m.drv);
				vmac_recorder_free(m.rec);
				free(m.buf);
			}
		if (w->efd >= 0)
			close(w->efd);
		free(w->queue);
		free(w->push_ns);
		vmac_ring_fini(&w->out);
	}
	free(bus->workers);
	bus->workers = NULL;
}

/* The active worker with the fewest machines (but skip); -1 when none. */
static int least_loaded(struct vmac_bus *bus, int skip)
{
	int i, best = -1;
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		if (i == skip || atomic_load(&w->state) != W_ACTIVE)
			continue;
		if (best < 0 || w->nmach < bus->workers[best].nmach)
			best = i;
	}
	return best;
}

/* A spare made active; -1 when there is none. */
static int take_spare(struct vmac_bus *bus)
{
	int i, expect;
	for (i = 0; i < bus->nworkers_max; i++) {
		expect = W_SPARE;
		if (atomic_compare_exchange_strong(&bus->workers[i].state, &expect, W_ACTIVE))
			return i;
	}
	return -1;
}

/* Jobs queued on w and not yet taken (stale entries included). */
static uint32_t backlog(struct worker *w)
{
	return atomic_load(&w->head) - atomic_load(&w->tail);
}

/* Has the oldest job queued on w waited past MOVE_AFTER_SLOTS at t_ns?
 * By the bus thread's copy of w's tail, read again only when that copy
 * says so: most pushes do not touch the worker's line. */
static int backed_up(struct vmac_bus *bus, struct worker *w, int64_t t_ns)
{
	uint32_t h = atomic_load_explicit(&w->head, memory_order_relaxed);
	int64_t after = MOVE_AFTER_SLOTS(bus->slot_ns);
	if (h == w->tail_seen || t_ns - w->push_ns[w->tail_seen & w->mask] < after)
		return 0;
	w->tail_seen = atomic_load_explicit(&w->tail, memory_order_acquire);
	return h != w->tail_seen && t_ns - w->push_ns[w->tail_seen & w->mask] >= after;
}

/* Where a machine without a worker goes: the first active worker that is
 * not far behind (backed_up), else the least loaded. Machines are packed
 * on few workers: light drivers then wake one worker a slot, not every
 * one, and drivers that need more than one find it when their worker
 * falls behind (bus_worker_push). */
static int first_free(struct vmac_bus *bus, int64_t t_ns)
{
	int i;
	for (i = 0; i < bus->nworkers_max; i++)
		if (atomic_load(&bus->workers[i].state) == W_ACTIVE && !backed_up(bus, &bus->workers[i], t_ns))
			return i;
	return least_loaded(bus, -1);
}

/* An active worker with nothing queued, other than skip; -1: none. */
static int idle_worker(struct vmac_bus *bus, int skip)
{
	int i;
	for (i = 0; i < bus->nworkers_max; i++)
		if (i != skip && atomic_load(&bus->workers[i].state) == W_ACTIVE && backlog(&bus->workers[i]) == 0 &&
		    atomic_load(&bus->workers[i].sleeping))
			return i;
	return -1;
}

int bus_worker_push(struct vmac_bus *bus, struct machine *m)
{
	int mi = (int)(m - bus->mach);
	int64_t t_ns = bus->jobs[mi].queued_ns;
	struct worker *w;
	if (m->worker >= 0 && atomic_load(&bus->workers[m->worker].state) == W_ACTIVE &&
	    backed_up(bus, &bus->workers[m->worker], t_ns)) {
		/* Its worker is far behind and another sleeps with nothing to
		 * do: the machine moves (a worker keeps nothing of a machine
		 * between jobs but what its core's caches hold). */
		int b = idle_worker(bus, m->worker);
		if (b >= 0) {
			bus->workers[m->worker].nmach--;
			bus->workers[b].nmach++;
			m->worker = b;
		}
	}
	if (m->worker < 0 || atomic_load(&bus->workers[m->worker].state) != W_ACTIVE) {
		int b = first_free(bus, t_ns);
		if (b < 0)
			b = take_spare(bus); /* every worker given up: the spare the main thread made */
		if (b < 0)
			return -1;
		if (m->worker >= 0)
			bus->workers[m->worker].nmach--;
		m->worker = b;
		bus->workers[b].nmach++;
	}
	w = &bus->workers[m->worker];
	if (queue_push(w, mi, t_ns) != 0)
		return -1;
	w->kick = 1;
	if (!bus->held_ns)
		bus->held_ns = t_ns > 0 ? t_ns : 1; /* until bus_workers_kick: wait.c holds it a while */
	return 0;
}

void bus_workers_kick(struct vmac_bus *bus)
{
	uint64_t one = 1;
	int i;
	bus->held_ns = 0;
	if (bus->virt)
		return;
	atomic_thread_fence(memory_order_seq_cst); /* the pushes before the looks at sleeping (worker_main) */
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		if (!w->kick)
			continue;
		w->kick = 0;
		/* Read first: the exchange, a write, only for a worker asleep. */
		if (atomic_load(&w->sleeping) && atomic_exchange(&w->sleeping, 0) &&
		    write(w->efd, &one, sizeof(one)) < 0) {
			/* the counter is full: it wakes anyway */
		}
	}
}

void bus_worker_retire(struct vmac_bus *bus, int wi)
{
	struct worker *old = &bus->workers[wi];
	int i, spare;
	atomic_store(&old->state, W_STALLED);
	spare = take_spare(bus);
	if (spare < 0)
		spare = least_loaded(bus, wi);
	/* Its other machines go on at once on the spare (or the least loaded
	 * worker); a job queued on it is queued again there. */
	for (i = 0; i < (int)bus->nused; i++) {
		struct machine *m = &bus->mach[i];
		if (!m->used || m->worker != wi)
			continue;
		old->nmach--;
		m->worker = spare;
		if (spare >= 0)
			bus->workers[spare].nmach++;
		if (atomic_load(&bus->jobs[i].state) == JOB_QUEUED)
			bus->jobs[i].pushed = bus_worker_push(bus, m) == 0;
	}
	bus_workers_kick(bus);
	/* The lowest priority at once (a system call that does not block), not
	 * when the main thread next runs: a stuck thread at SCHED_FIFO could
	 * starve it. */
	{
		struct sched_param sp;
		memset(&sp, 0, sizeof(sp));
		pthread_setschedparam(old->thread, SCHED_IDLE, &sp);
	}
}

/* ---- the main thread's care of the workers ---- */

void vmac_bus_workers_service(struct vmac_bus *bus)
{
	int i, spares = 0, free_one = -1;
	if (bus->virt || !bus->workers)
		return;
	for (i = 0; i < bus->nworkers_max; i++) {
		struct worker *w = &bus->workers[i];
		int st = atomic_load(&w->state);
		if (st == W_EXITED) {
			pthread_join(w->thread, NULL);
			atomic_store(&w->state, W_FREE);
			st = W_FREE;
		}
		if (st == W_SPARE)
			spares++;
		if (st == W_FREE && free_one < 0)
			free_one = i;
	}
	if (spares == 0 && free_one >= 0 && equip(&bus->workers[free_one]) == 0)
		start_worker(&bus->workers[free_one], W_SPARE);
}

int vmac_bus_poll_msg(struct vmac_bus *bus, struct vmac_bus_msg *msg)
{
	int i;
	for (i = 0; bus->workers && i < bus->nworkers_max; i++)
		if (bus->workers[i].out.buf && vmac_ring_pop(&bus->workers[i].out, msg))
			return 1;
	return vmac_ring_pop(&bus->to_main, msg);
}

int64_t bus_worker_cpu_ns(struct vmac_bus *bus, int wi)
{
	return wi >= 0 && wi < bus->nworkers_max ? thread_cpu_ns(bus->workers[wi].thread) : -1;
}

/* ---- the driver's calls back into the host, on the worker ---- */

/* dev:set_level(n): asked; the bus thread makes the change when it
 * collects the job (docs/DRIVERS.md). */
static int hook_set_level(void *ctx, unsigned level, char *err, size_t errlen)
{
	struct job *j = ctx;
	(void)err;
	(void)errlen;
	j->want_level = (int)level;
	return 0;
}

/* dev:event(text), or the driver module's warning: to the main thread
 * from the worker that runs the job (its ring: no I/O here). */
static void hook_event(void *ctx, const char *kind, const char *text)
{
	struct job *j = ctx;
	struct vmac_bus *bus = j->bus;
	struct vmac_bus_msg m;
	int w = atomic_load(&j->runner);
	memset(&m, 0, sizeof(m));
	m.kind = VMAC_MSG_EVENT;
	m.time_ns = bus->start_ns + (int64_t)(j->time_s * 1e9);
	memcpy(m.device, j->device, sizeof(m.device));
	memcpy(m.driver, j->driver, sizeof(m.driver));
	snprintf(m.event_kind, sizeof(m.event_kind), "%s", kind);
	snprintf(m.text, sizeof(m.text), "%s", text);
	if (bus->virt || w < 0)
		bus_post(bus, &m); /* virtual mode: one thread */
	else
		worker_post(&bus->workers[w], &m);
}

void bus_bind_driver(struct machine *m, struct vmac_driver *drv)
{
	struct vmac_driver_host host;
	host.set_level = hook_set_level;
	host.event = hook_event;
	host.ctx = &m->bus->jobs[m - m->bus->mach];
	m->bus->jobs[m - m->bus->mach].budget_of = NULL; /* its budget read again (jobs.c, limit_of) */
	vmac_driver_bind(drv, &host);
}
