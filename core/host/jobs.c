/* The bus thread's side of the driver workers (workers.c): every call into
 * a machine's driver is its job, one at a time. The bus thread fills the
 * job (the inputs of every board, the operator's input, the instance that
 * takes over) and queues it; at every tick it collects the jobs that are
 * done (the outputs go with each board's next service: the phase-aligned
 * transaction with one period's delay of docs/PROTOCOL.md) and judges the
 * ones still running: a job that has run past its limit is a failure of
 * its driver, detected here and not by the driver, and its worker is given
 * up (workers.c). Nothing here waits, allocates or runs Lua. In virtual
 * mode (vmac test) a job runs inline and is collected at once. */
#include "bus_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A call is judged stalled half as long again after its budget: the
 * driver's own check fails a busy call at 1.25 budgets (core/driver/
 * protect.c, held_off), and its error, which names the driver's line,
 * comes first. */
#define STALL_AFTER(budget_ns) ((budget_ns) + (budget_ns) / 2)

int bus_jobs_init(struct vmac_bus *bus)
{
	uint32_t i;
	int64_t budget = (int64_t)bus->cfg.driver_budget_us * 1000;
	/* On lines of their own (struct job): no job shares one with another's. */
	bus->jobs = aligned_alloc(_Alignof(struct job), bus->ndev * sizeof(*bus->jobs));
	if (!bus->jobs)
		return -1;
	memset(bus->jobs, 0, bus->ndev * sizeof(*bus->jobs));
	for (i = 0; i < bus->ndev; i++) {
		bus->jobs[i].bus = bus;
		bus->jobs[i].mach = (int)i;
		bus->jobs[i].req = -1;
		atomic_init(&bus->jobs[i].state, JOB_IDLE);
		atomic_init(&bus->jobs[i].runner, -1);
	}
	/* attach, input, a hot reload's take-over: a few calls each, at most
	 * VMAC_DRIVER_LOAD_FACTOR budgets, and never less than 100 ms. */
	bus->job_limit_ns = STALL_AFTER(budget * VMAC_DRIVER_LOAD_FACTOR);
	if (bus->job_limit_ns < 100000000)
		bus->job_limit_ns = 100000000;
	return 0;
}

void bus_jobs_fini(struct vmac_bus *bus)
{
	free(bus->jobs);
	bus->jobs = NULL;
}

static struct job *job_of(struct vmac_bus *bus, const struct machine *m)
{
	return &bus->jobs[m - bus->mach];
}

/* The job is free: IDLE, or DISPOSED by the worker that had it (made IDLE
 * here, the bus thread's again). */
static int job_free(struct job *j)
{
	int expect = JOB_DISPOSED;
	return atomic_compare_exchange_strong(&j->state, &expect, JOB_IDLE) || expect == JOB_IDLE;
}

int bus_machine_idle(const struct vmac_bus *bus, const struct machine *m)
{
	return job_free(&bus->jobs[m - bus->mach]);
}

void bus_answer(struct vmac_bus *bus, int i)
{
	struct request *q = &bus->req[i];
	atomic_store(&q->state, REQ_DONE);
	sem_post(&q->done);
}

static int64_t limit_of(const struct vmac_bus *bus, const struct machine *m, struct job *j);

static void fill(struct vmac_bus *bus, struct machine *m, struct job *j, enum job_kind kind, int64_t t_ns)
{
	int i;
	j->kind = kind;
	j->queued_ns = t_ns;
	j->seen_ns = 0;
	j->time_s = (double)(t_ns - bus->start_ns) / 1e9;
	j->drv = m->drv;
	j->other = NULL;
	j->level = m->level;
	j->nboards = m->nboards;
	for (i = j->nnamed; i < m->nboards; i++) { /* a machine's boards only ever grow */
		const struct device *b = &bus->dev[m->board[i]];
		j->minor[i] = b->ann.minor;
		memcpy(j->board[i], b->ann.board, sizeof(j->board[i]));
	}
	j->nnamed = m->nboards;
	j->req = -1;
	j->checkpoint = 0;
	j->overdue_ns = 0;
	j->limit_ns = limit_of(bus, m, j);
	atomic_store_explicit(&j->runner, -1, memory_order_relaxed);
}

static void collect_one(struct vmac_bus *bus, struct machine *m, struct job *j, int64_t now);

static int64_t virtual_cost(const struct vmac_bus *bus, const struct machine *m)
{
	int i;
	for (i = 0; i < VMAC_BUS_VIRTUAL_COSTS; i++)
		if (bus->virt_cost[i].cost_ns && strcmp(bus->virt_cost[i].driver, m->driver) == 0)
			return bus->virt_cost[i].cost_ns;
	return 0;
}

int vmac_bus_virtual_driver_cost(struct vmac_bus *bus, const char *driver, int64_t cost_ns)
{
	int i, free_one = -1;
	for (i = 0; i < VMAC_BUS_VIRTUAL_COSTS; i++) {
		if (strcmp(bus->virt_cost[i].driver, driver) == 0 && bus->virt_cost[i].driver[0]) {
			bus->virt_cost[i].cost_ns = cost_ns;
			return 0;
		}
		if (!bus->virt_cost[i].driver[0] && free_one < 0)
			free_one = i;
	}
	if (free_one < 0)
		return -1;
	snprintf(bus->virt_cost[free_one].driver, sizeof(bus->virt_cost[free_one].driver), "%s", driver);
	bus->virt_cost[free_one].cost_ns = cost_ns;
	return 0;
}

/* j, filled, to a worker; in virtual mode run and collected now, or, for a
 * driver made slow (vmac_bus_virtual_driver_cost), run now and collected
 * when its virtual time has passed (bus_collect), or judged there as a
 * worker's job is. */
static void hand_over(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	if (bus->virt) {
		int64_t cost = virtual_cost(bus, m);
		atomic_store(&j->state, JOB_RUNNING);
		bus_run_job(j);
		if (cost > 0) {
			j->seen_ns = bus_now(bus);
			j->ready_ns = j->seen_ns + cost;
			j->overdue_ns = 0;
			return;
		}
		atomic_store(&j->state, JOB_DONE);
		collect_one(bus, m, j, bus_now(bus));
		bus_dispatch(bus, m); /* what the job's results asked for (a roll-back) */
		return;
	}
	atomic_store(&j->state, JOB_QUEUED);
	if (bus_worker_push(bus, m) != 0)
		j->pushed = 0; /* no worker, or its ring full: pushed again by bus_collect */
	else
		j->pushed = 1;
}

/* An input request from the machine's queue into j. */
static void fill_input(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	int i = m->inputs[0];
	struct request *q = &bus->req[i];
	memmove(m->inputs, m->inputs + 1, (size_t)(--m->ninputs) * sizeof(m->inputs[0]));
	fill(bus, m, j, JOB_INPUT, bus_now(bus));
	memcpy(j->name, q->r.name, sizeof(j->name));
	j->value = q->r.value;
	j->req = i;
	j->rec_n = bus_rec_input(bus, m, bus_now(bus) - bus->start_ns, j->name, &j->value);
}

void bus_input_now(struct vmac_bus *bus, struct machine *m)
{
	struct job *j = job_of(bus, m);
	fill(bus, m, j, JOB_INPUT, bus_now(bus));
	j->rec_n = bus_rec_input(bus, m, bus_now(bus) - bus->start_ns, j->name, &j->value);
	hand_over(bus, m, j);
}

void bus_collect_done_tick(struct vmac_bus *bus, struct machine *m)
{
	struct job *j = job_of(bus, m);
	int64_t now = bus_now(bus);
	if (j->kind != JOB_TICK)
		return;
	if (bus->virt && atomic_load(&j->state) == JOB_RUNNING && now >= j->ready_ns && now - j->seen_ns <= j->limit_ns)
		atomic_store(&j->state, JOB_DONE); /* a slow driver's tick, done in virtual time (bus_collect) */
	if (atomic_load(&j->state) == JOB_DONE)
		collect_one(bus, m, j, now);
}

/* m's tick into j: the inputs every board had at the tick's time (a tick
 * that waited for its job does not take a reply that came after it). */
static void fill_tick(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	int i;
	m->want_tick = 0;
	fill(bus, m, j, JOB_TICK, m->tick_ns);
	for (i = 0; i < m->nboards; i++) {
		j->in[i] = m->tick_in[i];
		j->sample_s[i] =
		    m->tick_sample_ns[i] ? (double)(m->tick_sample_ns[i] - bus->start_ns) / 1e9 : j->time_s;
	}
	j->checkpoint = m->want_checkpoint || bus_checkpoint_due(bus, m, m->tick_ns);
	m->want_checkpoint = 0;
}

void bus_dispatch(struct vmac_bus *bus, struct machine *m)
{
	struct job *j = job_of(bus, m);
	int64_t now;
	if (!m->used || !m->drv || !job_free(j))
		return;
	if (m->want_tick && m->attached && !m->want_attach && !m->want_rollback && !m->want_stop && !m->want_swap &&
	    m->ninputs == 0) {
		/* The common case first, with the reply's time: no clock read. */
		fill_tick(bus, m, j);
		hand_over(bus, m, j);
		return;
	}
	now = bus_now(bus);
	if (m->want_attach) {
		m->want_attach = 0;
		fill(bus, m, j, JOB_ATTACH, now);
	} else if (m->want_rollback) {
		m->want_rollback = 0;
		fill(bus, m, j, JOB_ROLLBACK, now);
		j->drv = m->prev;
		j->other = m->drv;
	} else if (m->want_stop) {
		m->want_stop = 0;
		fill(bus, m, j, JOB_STOP, now);
		j->checkpoint = m->attached;
	} else if (!m->attached) {
		return; /* nothing runs before attach */
	} else if (m->want_swap) {
		struct request *q = &bus->req[m->want_swap - 1];
		fill(bus, m, j, JOB_SWAP, now);
		j->other = q->drv;
		j->req = m->want_swap - 1;
		m->want_swap = 0;
		bus_bind_driver(m, j->other);
	} else if (m->ninputs > 0) {
		fill_input(bus, m, j);
	} else if (m->want_tick) {
		fill_tick(bus, m, j);
	} else {
		return;
	}
	hand_over(bus, m, j);
}

/* What every job leaves for the status: variables, params, memory, instructions, time. */
static void copy_in(struct machine *m, const struct job *j)
{
	if (j->vars_fresh) {
		m->nvars = j->nvars;
		memcpy(m->vars, j->vars, (size_t)m->nvars * sizeof(m->vars[0]));
	}
	if (j->params_fresh) {
		m->nparams = j->nparams;
		memcpy(m->params, j->params, (size_t)m->nparams * sizeof(m->params[0]));
	}
	m->memory = j->memory;
	m->instructions = j->instructions;
	m->call_ns = j->call_ns;
}

static void tick_done(struct vmac_bus *bus, struct machine *m, struct job *j, int64_t now)
{
	int64_t t_ns = (int64_t)(j->time_s * 1e9 + 0.5); /* the nearest: a replay's t / 1e9 is time_s again */
	/* with these outputs; a failed tick's (all off) at the pattern's instant */
	int64_t out_at_ns = j->rc == 0 && j->out_at_s > 0 ? (int64_t)(j->out_at_s * 1e9 + 0.5) : 0;
	int i;
	/* released with the machine's next period (bus_release_outputs), to
	 * every board of it at once */
	for (i = 0; i < j->nboards && i < m->nboards; i++)
		m->staged_out[i] = j->out[i];
	m->staged_n = i;
	m->staged_out_at_ns = out_at_ns;
	m->staged = 1;
	m->tick_open = m->want_tick; /* one asked for since is still to come */
	bus_rec_tick(bus, m, t_ns, j->nboards < m->nboards ? j->nboards : m->nboards, j->in, j->out,
	             j->sample_s); /* a failed tick too: its inputs replay the failure */
	if (j->rc != 0) {
		bus_driver_failed(bus, m, "", j->err);
		return;
	}
	if (j->ckpt_rc != 0)
		bus_checkpoint_taken(bus, m, j, now);
}

void bus_release_outputs(struct vmac_bus *bus, struct device *d, uint64_t slot, unsigned level)
{
	struct machine *m;
	uint64_t period = (slot >> level) + 1;
	int i;
	if (d->mach < 0)
		return;
	m = &bus->mach[d->mach];
	if (m->served_period == period && m->served_level == level)
		return; /* a later board of this period: the outputs its first board took */
	m->served_period = period;
	m->served_level = level;
	if (m->tick_open && !m->tick_held && m->tick_asked < bus->tick_index) {
		/* The tick asked for in an earlier slot is not done: this service
		 * sends the outputs before it, if any (counted once a tick). Judged in
		 * slots, not by the time between the reply and the collecting
		 * tick, which a tick later than the one before stretches past
		 * a period with every output on time. */
		m->late++;
		m->late_ns = bus_now(bus);
		m->tick_held = 1;
	}
	if (!m->staged)
		return;
	for (i = 0; i < m->staged_n; i++)
		bus->dev[m->board[i]].outputs = m->staged_out[i];
	m->out_at_ns = m->staged_out_at_ns;
	m->staged = 0;
}

static void input_done(struct vmac_bus *bus, struct machine *m, struct job *j)
{
	struct request *q = j->req >= 0 ? &bus->req[j->req] : NULL;
	bus_rec_input_rc(m, j->rec_n, j->rc);
	if (j->rc < 0)
		snprintf(j->reply, sizeof(j->reply), "the driver failed: %s", j->err);
	j->input_rc = j->rc < 0 ? -VMAC_EDRIVER : j->rc;
	if (q) { /* answered first: a failure below may free the machine */
		q->r.rc = j->input_rc;
		memcpy(q->r.reply, j->reply, sizeof(q->r.reply));
		if (q->r.rc == 0)
			memcpy(q->r.machine, bus->dev[m->primary].ann.board, sizeof(q->r.machine));
		bus_answer(bus, j->req);
		j->req = -1;
	}
	if (j->rc < 0) {
		bus_driver_failed(bus, m, " in input", j->err);
		bus_flush(bus);
	}
}

/* A done job's results applied; the job is free again. The handlers
 * below only ask for what comes next (the caller dispatches it), and each
 * sets j->req to -1 once it has answered the request. */
static void collect_one(struct vmac_bus *bus, struct machine *m, struct job *j, int64_t now)
{
	copy_in(m, j);
	/* A level asked for by a call that failed is not made: the call did
	 * not return. A refused input (rc > 0) returned. */
	if (j->want_level >= 0 && j->kind != JOB_STOP && (j->kind == JOB_INPUT ? j->rc >= 0 : j->rc == 0))
		bus_apply_level(bus, m, (unsigned)j->want_level);
	switch (j->kind) {
	case JOB_ATTACH: bus_attach_done(bus, m, j); break;
	case JOB_TICK: tick_done(bus, m, j, now); break;
	case JOB_INPUT: input_done(bus, m, j); break;
	case JOB_SWAP: bus_swapped(bus, m, j); break;
	case JOB_ROLLBACK: bus_rolled_back(bus, m, j); break;
	case JOB_STOP:
		if (j->ckpt_rc != 0)
			bus_checkpoint_taken(bus, m, j, now);
		bus_free_machine(bus, m);
		break;
	}
	atomic_store(&j->state, JOB_IDLE);
	j->req = -1;
}

/* What a job was doing, for people. */
static const char *job_name(enum job_kind k)
{
	switch (k) {
	case JOB_ATTACH: return "attach";
	case JOB_TICK: return "tick";
	case JOB_INPUT: return "input";
	case JOB_SWAP: return "take-over (attach, migrate)";
	case JOB_ROLLBACK: return "roll-back take-over";
	case JOB_STOP: return "detach";
	}
	return "call";
}

/* How long j may run: a tick, its machine's period or 1.5 times its
 * driver's budget, whichever is longer; anything else, 75 of its driver's
 * budgets or bus->job_limit_ns, whichever is longer. A job no worker
 * has taken for ten times that (at least a second) drops its machine. */
#define QUEUED_MAX(limit) ((limit)*10 > 1000000000 ? (limit)*10 : 1000000000)
static int64_t limit_of(const struct vmac_bus *bus, const struct machine *m, struct job *j)
{
	int64_t period = bus->slot_ns << m->level;
	if (j->kind != JOB_TICK) { /* its driver's own budget (driver.NAME.budget_us) when that is the longer */
		int64_t own = m->drv ? STALL_AFTER(vmac_driver_budget_ns(m->drv) * VMAC_DRIVER_LOAD_FACTOR) : 0;
		return own > bus->job_limit_ns ? own : bus->job_limit_ns;
	}
	if (j->budget_of != j->drv) { /* reset when an instance is bound to the machine (bus_bind_driver) */
		j->budget_of = j->drv;
		j->stall_ns = STALL_AFTER(vmac_driver_budget_ns(j->drv));
	}
	return j->stall_ns > period ? j->stall_ns : period;
}

/* j has run past its limit, and its worker was on a CPU for it: the driver
 * failed, by the bus's judgement. Its worker is retired with the job (and
 * the instances it holds); the machine is dropped, every board told to go
 * safe; the version is not loaded again until a new one arrives. */
static void stalled(struct vmac_bus *bus, struct machine *m, struct job *j, int64_t now)
{
	struct device *primary = &bus->dev[m->primary];
	/* What the job holds is read before it is given up: after that, its
	 * worker may dispose of it at any moment. */
	struct vmac_driver *stuck = j->kind == JOB_SWAP ? j->other : j->drv, *jdrv = j->drv, *jother = j->other;
	const char *call = vmac_driver_lib_call(stuck);
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	int64_t tag = vmac_driver_tag(stuck);
	uint8_t *ckpt = j->ckpt;
	char why[VMAC_DRIVER_ERR_MAX], text[VMAC_EVENT_TEXT];
	int expect = JOB_RUNNING, w = atomic_load(&j->runner);
	snprintf(version, sizeof(version), "%s", vmac_driver_version(stuck));
	snprintf(why, sizeof(why), "%s still running after %.3g ms (its limit %.3g ms)%s%s", job_name(j->kind),
	         (double)(now - j->seen_ns) / 1e6, (double)j->limit_ns / 1e6, call ? ": inside " : "",
	         call ? call : "");
	if (!atomic_compare_exchange_strong(&j->state, &expect, JOB_STALLED))
		return; /* it has just finished */
	snprintf(text, sizeof(text),
	         "%s: driver %s %s stalled: %s; its worker is given up, and this version is not loaded again "
	         "until a new one arrives",
	         primary->ann.board, m->driver, version, why);
	bus_post_code(bus, VMAC_EVENT_STALLED, m, version, tag, "driver_error", text);
	bus_rec_failure(bus, m, VMAC_REC_ERROR, why);
	if (j->req >= 0) { /* the instances went with the worker: nothing to give back */
		struct request *q = &bus->req[j->req];
		q->r.rc = -VMAC_EDRIVER;
		snprintf(q->r.reply, sizeof(q->r.reply), "the driver failed: %s", why);
		bus_answer(bus, j->req);
		j->req = -1; /* the bus thread's field: no worker touches it */
	}
	if (m->prev && j->kind != JOB_ROLLBACK) {
		/* On probation: the store goes back to the version before, which
		 * the boards load when they announce themselves again. */
		snprintf(text, sizeof(text),
		         "%s: driver %s %s stalled on probation; the version before it is active again",
		         primary->ann.board, m->driver, version);
		bus_post_code(bus, VMAC_EVENT_ROLLED_BACK, m, version, tag, "rolled_back", text);
	}
	/* The instances the job holds went with it: its worker may dispose of
	 * them (and clear the job's fields) at any moment now, so the machine
	 * lets go of them here rather than have bus_free_machine read the job
	 * for them after that, and unload them a second time. */
	if (m->drv == jdrv || m->drv == jother)
		m->drv = NULL;
	if (m->prev == jdrv || m->prev == jother)
		m->prev = NULL;
	if (w >= 0)
		bus_worker_retire(bus, w);
	if (bus->stopping) /* its boards were told to go safe already */
		bus_free_machine(bus, m);
	else
		bus_drop(bus, primary, VMAC_SHUT_DRIVER, "dropped", "its driver stalled");
	if (bus->virt) { /* no worker holds it: the job's instances go now */
		bus_unload(bus, jdrv);
		bus_unload(bus, jother);
		bus_unload_buffer(bus, ckpt);
		j->drv = j->other = NULL;
		j->ckpt = NULL;
		atomic_store(&j->state, JOB_IDLE);
	}
}

/* Past its limit, has its worker been on a CPU for it? 1 once the
 * worker's CPU time since the first look past the limit reaches a quarter
 * of the limit, or past ten limits whatever the reason; 0 before. Time
 * the machine kept the worker off its CPUs is not the driver's: a worker
 * back on a CPU gets its own budget check first, which ends a call that
 * runs on (the budget, too, does not count the time its thread was held
 * off: core/driver/protect.c). */
static int overran(struct vmac_bus *bus, struct job *j, int64_t now)
{
	int64_t cpu;
	int w;
	if (j->seen_ns == 0) { /* it began since the last look: counted from now (a slot late at most) */
		j->seen_ns = now;
		j->overdue_ns = 0;
		return 0;
	}
	if (now - j->seen_ns <= j->limit_ns)
		return 0;
	if (bus->virt) /* vmac test: the job had every virtual moment since it began (driver_cost) */
		return 1;
	w = atomic_load(&j->runner);
	if (w < 0) /* taken, its worker not said yet (held off the CPU between the two): not its driver's time */
		return now - j->seen_ns > 10 * j->limit_ns;
	cpu = bus_worker_cpu_ns(bus, w);
	if (now - j->seen_ns > 10 * j->limit_ns || cpu < 0)
		return 1;
	if (!j->overdue_ns) {
		j->overdue_ns = now;
		j->overdue_cpu_ns = cpu;
		return 0;
	}
	return cpu - j->overdue_cpu_ns >= j->limit_ns / 4;
}

/* A job given up when its machine went away (DROPPED) still holds its
 * worker: past its limit, that worker is given up too, so that no new
 * machine waits behind it. */
static void orphan_overran(struct vmac_bus *bus, struct job *j, int64_t now)
{
	int expect = JOB_DROPPED, w = atomic_load(&j->runner);
	char text[VMAC_EVENT_TEXT];
	if (!overran(bus, j, now) || !atomic_compare_exchange_strong(&j->state, &expect, JOB_STALLED))
		return;
	snprintf(text, sizeof(text),
	         "driver %s, whose machine %s was dropped during its %s, kept its worker past its limit (%.3g ms): "
	         "the worker is given up",
	         j->driver, j->device, job_name(j->kind), (double)j->limit_ns / 1e6);
	bus_event(bus, NULL, "warning", "%s", text);
	if (w >= 0)
		bus_worker_retire(bus, w);
}

void bus_collect(struct vmac_bus *bus, int64_t now)
{
	uint32_t i;
	for (i = 0; i < bus->nused; i++) {
		struct machine *m = &bus->mach[i];
		struct job *j = &bus->jobs[i];
		int st = atomic_load(&j->state);
		if (!m->used) {
			if (st == JOB_DROPPED)
				orphan_overran(bus, j, now);
			continue;
		}
		if (st == JOB_DONE) {
			collect_one(bus, m, j, now);
			bus_dispatch(bus, m);
		} else if (st == JOB_RUNNING && bus->virt && now >= j->ready_ns && now - j->seen_ns <= j->limit_ns) {
			atomic_store(&j->state, JOB_DONE); /* a slow driver's call, done in virtual time */
			collect_one(bus, m, j, now);
			bus_dispatch(bus, m);
		} else if (st == JOB_RUNNING) {
			if (overran(bus, j, now))
				stalled(bus, m, j, now);
		} else if (st == JOB_QUEUED && now - j->queued_ns > QUEUED_MAX(j->limit_ns)) {
			/* No worker took it: the host is short of workers, not the
			 * driver at fault; the machine cannot go on without its calls. */
			char why[160];
			snprintf(why, sizeof(why),
			         "no driver worker took its %s within %.3g s (the host is short of workers)",
			         job_name(j->kind), (double)(now - j->queued_ns) / 1e9);
			bus_drop(bus, &bus->dev[m->primary], VMAC_SHUT_DROPPED, "dropped", why);
		} else if (st == JOB_QUEUED && !j->pushed) {
			j->pushed = bus_worker_push(bus, m) == 0;
		} else if (st == JOB_IDLE || st == JOB_DISPOSED) {
			bus_dispatch(bus, m);
		}
	}
	bus_workers_kick(bus);
}

int bus_job_release(struct vmac_bus *bus, struct machine *m, struct vmac_driver **drv, struct vmac_driver **other)
{
	struct job *j = job_of(bus, m);
	int expect = JOB_QUEUED, held = 0;
	*drv = j->drv; /* read while the job cannot be disposed of: before it is given up */
	*other = j->other;
	if (bus->virt) { /* no worker: a slow driver's call is done, unread; a stalled one stalled() frees */
		held = atomic_load(&j->state) == JOB_STALLED;
		if (!held)
			atomic_store(&j->state, JOB_IDLE);
	} else if (atomic_compare_exchange_strong(&j->state, &expect, JOB_IDLE)) {
		held = 0; /* no worker took it: it never runs */
	} else if (expect == JOB_RUNNING) {
		if (atomic_compare_exchange_strong(&j->state, &expect, JOB_DROPPED))
			held = 1; /* the worker disposes of what it holds */
		else
			atomic_store(&j->state, JOB_IDLE); /* it has just finished: the results go unread */
	} else if (expect == JOB_STALLED || expect == JOB_DROPPED || expect == JOB_DISPOSED) {
		held = 1; /* the worker's, or disposed of already */
	} else {
		atomic_store(&j->state, JOB_IDLE); /* DONE, unread; or IDLE */
	}
	if (j->req >= 0) {
		struct request *q = &bus->req[j->req];
		if (j->kind == JOB_SWAP && held) {
			q->r.rc = -VMAC_EDRIVER; /* the new instance went with the job */
			snprintf(q->r.reply, sizeof(q->r.reply), "the %s machine was dropped during the take-over",
			         m->driver);
		} else {
			q->r.rc = -VMAC_ENOTRUNNING;
			snprintf(q->r.reply, sizeof(q->r.reply), "the %s machine was dropped meanwhile", m->driver);
		}
		bus_answer(bus, j->req);
		j->req = -1;
	}
	return held;
}
