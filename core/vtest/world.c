/* The virtual world: see world.h. */
#include "world.h"

#include <arpa/inet.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../common/name.h"
#include "../loader/loader.h"
#include "../mainloop/mainloop.h"
#include "../proto/auth.h"
#include "../store/store.h"

struct vt_pkt {
	int64_t at;
	uint64_t order;
	int to_host; /* else to board `board` (-1: every board, the group) */
	int board;   /* sender when to_host */
	struct vmac_packet p;
};

static uint64_t rng_next(struct vt_world *w)
{
	uint64_t x = w->rng;
	x ^= x >> 12;
	x ^= x << 25;
	x ^= x >> 27;
	w->rng = x;
	return x * 0x2545F4914F6CDD1DULL;
}

/* Uniform in [0, 1). */
static double rng_unit(struct vt_world *w)
{
	return (double)(rng_next(w) >> 11) / 9007199254740992.0;
}

static int chance(struct vt_world *w, double p)
{
	return p > 0 && rng_unit(w) < p;
}

/* ---- the queue of frames in flight: a binary heap by (at, order) ---- */

static int before(const struct vt_pkt *a, const struct vt_pkt *b)
{
	return a->at < b->at || (a->at == b->at && a->order < b->order);
}

static int push(struct vt_world *w, const struct vt_pkt *p)
{
	size_t i;
	if (w->nq == w->capq) {
		size_t cap = w->capq ? 2 * w->capq : 64;
		struct vt_pkt *q = realloc(w->q, cap * sizeof(*q));
		if (!q)
			return -1;
		w->q = q;
		w->capq = cap;
	}
	i = w->nq++;
	w->q[i] = *p;
	w->q[i].order = w->order++;
	while (i > 0 && before(&w->q[i], &w->q[(i - 1) / 2])) {
		struct vt_pkt t = w->q[i];
		w->q[i] = w->q[(i - 1) / 2];
		w->q[(i - 1) / 2] = t;
		i = (i - 1) / 2;
	}
	return 0;
}

static void pop(struct vt_world *w, struct vt_pkt *out)
{
	size_t i = 0;
	*out = w->q[0];
	w->q[0] = w->q[--w->nq];
	for (;;) {
		size_t l = 2 * i + 1, r = l + 1, m = i;
		struct vt_pkt t;
		if (l < w->nq && before(&w->q[l], &w->q[m]))
			m = l;
		if (r < w->nq && before(&w->q[r], &w->q[m]))
			m = r;
		if (m == i)
			break;
		t = w->q[i];
		w->q[i] = w->q[m];
		w->q[m] = t;
		i = m;
	}
}

/* A frame leaving `from` (a board, or the host when NULL) with the faults of
 * the board at either end applied. */
static void send_frame(struct vt_world *w, struct vt_board *b, struct vt_pkt *p, int64_t extra_ns)
{
	p->at = w->now_ns + VT_WIRE_NS + extra_ns;
	if (b) {
		if (!b->plugged || chance(w, b->faults.drop))
			return;
		if (chance(w, b->faults.delay_fraction))
			p->at += b->faults.delay_ns;
		if (p->p.len > 0 && chance(w, b->faults.corrupt))
			p->p.data[rng_next(w) % p->p.len] ^= (uint8_t)(1u + rng_next(w) % 255);
	}
	push(w, p);
}

/* struct vmac_bus_link: frames from the host. */
static void host_send(void *ctx, const struct vmac_packet *pkts, int n)
{
	struct vt_world *w = ctx;
	int i, j;
	for (i = 0; i < n; i++) {
		struct vt_pkt p;
		memset(&p, 0, sizeof(p));
		p.p = pkts[i];
		if (vmac_addr_equal(&pkts[i].addr, &w->bus_group)) {
			/* A multicast reaches every board, each with its own faults. */
			for (j = 0; j < w->nboards; j++) {
				p.board = j;
				send_frame(w, w->boards[j], &p, 0);
			}
			continue;
		}
		for (j = 0; j < w->nboards && !vmac_addr_equal(&pkts[i].addr, &w->boards[j]->addr); j++)
			;
		if (j == w->nboards)
			continue; /* nobody at that address any more */
		p.board = j;
		send_frame(w, w->boards[j], &p, 0);
	}
}

/* ---- the host's main thread: vmacd's own loop (core/mainloop/) ---- */

static int64_t world_ns(void *ctx)
{
	const struct vt_world *w = ctx;
	return w->now_ns;
}

/* Every event, kept for the checks (w:events()). */
static void keep_event(void *ctx, const struct vmac_event *ev)
{
	struct vt_world *w = ctx;
	struct vt_event *e;
	if (w->nevents == w->capevents) {
		size_t cap = w->capevents ? 2 * w->capevents : 64;
		struct vt_event *n = realloc(w->events, cap * sizeof(*n));
		if (!n)
			return;
		w->events = n;
		w->capevents = cap;
	}
	e = &w->events[w->nevents++];
	w->moved = 1;
	e->t_ns = ev->time_ns;
	memcpy(e->kind, ev->kind, sizeof(e->kind));
	memcpy(e->device, ev->device, sizeof(e->device));
	memcpy(e->text, ev->text, sizeof(e->text));
}

/* In virtual mode the bus takes a loaded driver at once. */
static void run_commands(void *ctx)
{
	struct vt_world *w = ctx;
	vmac_bus_virtual_commands(w->bus);
}

static void pump(struct vt_world *w)
{
	if (w->main)
		while (vmac_mainloop_service(w->main)) /* virtual time stands still in it: once, in fact */
			;
}

/* ---- boards ---- */

static void record_service(struct vt_world *w, struct vt_board *b, int64_t t)
{
	struct vt_service *s = &b->hist[b->nhist++ % VT_HISTORY];
	int i;
	s->t_ns = t;
	vmac_sim_sense(&b->sim, &s->in);
	s->out = b->fw.outputs;
	if (!w->trace)
		return;
	for (i = 0; i < b->nio; i++) {
		double v;
		int is_bool;
		vt_io_value(w, b, b->io[i].name, &v, &is_bool);
		fprintf(w->trace, "%s,%.6f,%s,%s,%.6g\n", w->trace_test, (double)t / 1e9, b->fw.id.board, b->io[i].name,
		        v);
	}
}

static void deliver(struct vt_world *w, struct vt_pkt *p)
{
	w->frames++;
	if (p->to_host) {
		p->p.rx_ns = w->now_ns;
		if (w->bus) /* else the host is down: the frame is lost */
			vmac_bus_virtual_receive(w->bus, &p->p);
		return;
	}
	{
		struct vt_board *b = w->boards[p->board];
		uint64_t ms = (uint64_t)(w->now_ns / 1000000);
		struct vt_pkt r;
		int len;
		if (!b->powered || !b->plugged)
			return;
		vmac_board_poll(&b->fw, ms);
		memset(&r, 0, sizeof(r));
		/* Stamped by the board's counter as its receive path would: SYNC
		 * feeds its clock with it (clocks.h). */
		len = vmac_board_receive_at(&b->fw, p->p.data, p->p.len, ms, vt_clock_local_ns(w, b, 1), r.p.data,
		                            sizeof(r.p.data));
		if (len <= 0)
			return;
		record_service(w, b, w->now_ns);
		r.to_host = 1;
		r.board = p->board;
		r.p.len = (size_t)len;
		r.p.addr = b->addr;
		send_frame(w, b, &r, b->faults.late_ns);
	}
}

/* 0, or VT_PLANT_FAILED when a Lua plant failed at this step. */
static int step_plants(struct vt_world *w)
{
	uint64_t ms = (uint64_t)(w->now_ns / 1000000);
	int i, rc = 0;
	for (i = 0; i < w->nboards; i++) {
		struct vt_board *b = w->boards[i];
		if (vmac_sim_step(&b->sim, (double)VT_PLANT_STEP_NS / 1e9) == -2 && rc == 0) {
			snprintf(w->plant_failure, sizeof(w->plant_failure), "the %s plant of board %s failed: %s",
			         vmac_sim_name(&b->sim), b->fw.id.board, vmac_sim_failure(&b->sim));
			rc = VT_PLANT_FAILED;
		}
		if (b->powered && vmac_board_poll(&b->fw, ms))
			w->moved = 1; /* the watchdog turned the outputs off */
	}
	vt_clock_poll(w); /* holdover and lost come with time, not only with frames */
	return rc;
}

/* When the next action a board holds (TIMED outputs or a latch,
 * firmware/timed.c) falls due: the world time at which that board's
 * counter reaches its instant (vt_clock_world_ns), never before now;
 * INT64_MAX when no board holds one. */
static int64_t next_board_action(const struct vt_world *w)
{
	int64_t next = INT64_MAX;
	int i;
	for (i = 0; i < w->nboards; i++) {
		struct vt_board *b = w->boards[i];
		uint64_t local;
		int64_t at;
		if (!b->powered || !vmac_board_next_deadline(&b->fw, &local))
			continue;
		at = vt_clock_world_ns(b, local);
		if (at < w->now_ns)
			at = w->now_ns;
		if (at < next)
			next = at;
	}
	return next;
}

/* Every board action due by now, its replies sent as deliver() sends
 * them. The counter read now can be one ns short of the instant the world
 * time was computed from (rounding), so the instant itself is the floor. */
static void run_board_actions(struct vt_world *w)
{
	int i;
	for (i = 0; i < w->nboards; i++) {
		struct vt_board *b = w->boards[i];
		uint64_t local;
		int rounds = 0;
		while (b->powered && rounds++ < 4 && vmac_board_next_deadline(&b->fw, &local) &&
		       vt_clock_world_ns(b, local) <= w->now_ns) {
			uint64_t now_local = vt_clock_local_ns(w, b, 0);
			struct vt_pkt r;
			int len;
			if (now_local < local)
				now_local = local;
			memset(&r, 0, sizeof(r));
			len = vmac_board_run_due(&b->fw, now_local, r.p.data, sizeof(r.p.data));
			if (len <= 0)
				continue;
			record_service(w, b, w->now_ns);
			r.to_host = 1;
			r.board = i;
			r.p.len = (size_t)len;
			r.p.addr = b->addr;
			send_frame(w, b, &r, b->faults.late_ns);
		}
	}
}

int vt_run(struct vt_world *w, int64_t until_ns, vt_check_fn check, void *ctx)
{
	while (w->now_ns < until_ns) {
		int64_t next_tick = w->bus ? vmac_bus_virtual_next_tick(w->bus) : INT64_MAX, t = next_tick;
		int64_t next_act = next_board_action(w);
		if (w->next_plant_ns < t)
			t = w->next_plant_ns;
		if (w->nq > 0 && w->q[0].at < t)
			t = w->q[0].at;
		if (next_act < t)
			t = next_act;
		if (until_ns < t)
			t = until_ns;
		w->now_ns = t;
		if (t >= w->next_plant_ns) {
			int rc = step_plants(w);
			w->next_plant_ns += VT_PLANT_STEP_NS;
			w->plant_moved = 1;
			if (rc)
				return rc;
		}
		while (w->nq > 0 && w->q[0].at <= t) {
			struct vt_pkt p;
			pop(w, &p);
			deliver(w, &p);
			w->moved = 1;
		}
		if (t >= next_act) { /* after the frames of this instant: they may have set or cancelled one */
			run_board_actions(w);
			w->moved = 1;
		}
		if (t < next_tick && (w->bus || t < w->next_plant_ns - VT_PLANT_STEP_NS))
			continue;
		if (w->bus) {
			vmac_bus_virtual_tick(w->bus, t);
			pump(w);
		} /* else no host (vt_crash_host): checks run on the plant grid */
		/* Checks run at each bus tick at which something they read may
		 * have changed (world.h, `moved`): every change a driver, a board
		 * or a plant makes is seen at the tick it happens. */
		if (check && (w->moved || (w->plant_moved && w->check_reads_plant))) {
			int rc;
			w->moved = w->plant_moved = w->reads_plant = 0;
			rc = check(ctx);
			w->check_reads_plant = w->reads_plant;
			if (rc)
				return rc;
		}
	}
	return 0;
}

static int load_io_map(struct vt_world *w, struct vt_board *b, const char *driver, int primary)
{
	struct vmac_driver *drv;
	int i, n;
	if (vmac_load_driver(&w->cfg, driver, b->fw.id.board, &drv, b->io_note, sizeof(b->io_note)) != 0)
		return -1;
	n = vmac_driver_nio(drv);
	for (i = 0; i < n && b->nio < VMAC_DRIVER_MAX_IO; i++) {
		struct vmac_driver_io io;
		struct vt_io *o = &b->io[b->nio];
		vmac_driver_io_info(drv, i, &io);
		if (io.has_minor ? io.minor != b->fw.id.minor : !primary)
			continue;
		snprintf(o->name, sizeof(o->name), "%s", io.name);
		o->kind = io.kind;
		o->channel = io.channel;
		o->scale = io.scale;
		o->offset = io.offset;
		b->nio++;
	}
	n = primary ? vmac_driver_nvars(drv) : 0;
	for (i = 0; i < n; i++) {
		double every_s = vmac_driver_variable_every_s(drv, i);
		if (every_s > 0 && b->ntimers < VMAC_DRIVER_MAX_VARS) {
			struct vt_timer_var *tv = &b->timers[b->ntimers++];
			snprintf(tv->name, sizeof(tv->name), "%s", vmac_driver_variable(drv, i)->name);
			tv->every_s = every_s;
		}
	}
	vmac_driver_free(drv);
	return 0;
}

/* Every board of a test is keyed and enrolled, as on a host with bus_trust
 * enrolled: its frames go through the authenticated path. Its key is made
 * from its name, the same every run. */
static int enroll(struct vt_world *w, struct vmac_board_identity *id, char *err, size_t errlen)
{
	static const uint8_t test_key[VMAC_KEY_LEN] = "vmac test keys!";
	id->keyed = 1;
	vmac_siphash24_128(test_key, (const uint8_t *)id->board, strlen(id->board), id->key);
	if (vmac_board_key_set(w->store, id->board, id->key, 1, "vmac test", err, errlen) < 0)
		return -1;
	if (w->main) { /* the host runs: it has the key before the board's first announcement */
		vmac_mainloop_sync_keys(w->main);
		vmac_bus_virtual_commands(w->bus);
	}
	return 0;
}

/* The plant named: plants/NAME.lua of the drivers folder, else the C
 * plant. 0, or -1 with err. */
static int make_sim(struct vt_world *w, const char *plant, struct vmac_sim *sim, char *err, size_t errlen)
{
	char path[VMAC_PATH_MAX + 64];
	struct vmac_luaplant_limits lim;
	struct stat st;
	memset(&lim, 0, sizeof(lim));
	lim.seed = w->seed + (uint64_t)w->nboards; /* virtual time: no wall-clock budget */
	if (w->cfg.drivers_dir[0] && vmac_valid_name(plant, VMAC_NAME_MAX)) {
		snprintf(path, sizeof(path), "%s/plants/%s.lua", w->cfg.drivers_dir, plant);
		if (stat(path, &st) == 0)
			return vmac_sim_init_lua(sim, path, &lim, err, errlen);
	}
	if (vmac_sim_init_c(sim, plant) == 0)
		return 0;
	snprintf(err, errlen,
	         "unknown plant '%s': no plants/%s.lua in %s, and no C plant of that name (washer, dishwasher, "
	         "lights, generic)",
	         plant, plant, w->cfg.drivers_dir[0] ? w->cfg.drivers_dir : "the drivers folder (none: --drivers DIR)");
	return -1;
}

/* firmware/timed.c's log of an action: an output change, as the world
 * saw it happen (fw is a vt_board's first member). */
static void board_acted(void *ctx, const struct vmac_board *fw, const struct vmac_timed_action *a)
{
	struct vt_world *w = ctx;
	struct vt_board *b = (struct vt_board *)(void *)fw;
	if (a->kind != VMAC_TIMED_OUT)
		return;
	b->acted.t_ns = w->now_ns;
	b->acted.asked_ns = a->host_ns;
	b->acted.how = (int)a->how;
	b->acted.count++;
}

static void board_firmware_init(struct vt_world *w, struct vt_board *b, struct vmac_board_identity *id)
{
	vmac_board_init(&b->fw, id, &vmac_sim_io, &b->sim, (uint64_t)(w->now_ns / 1000000));
	b->fw.acted = board_acted;
	b->fw.acted_ctx = w;
}

struct vt_board *vt_board_add(struct vt_world *w, const char *name, const char *plant, const char *driver,
                              uint32_t major, uint32_t minor, char *err, size_t errlen)
{
	struct vmac_sim sim;
	struct vmac_board_identity id;
	struct sockaddr_in *sin;
	struct vt_board *b;
	int i, primary = 1;
	if (w->nboards == VT_MAX_BOARDS) {
		snprintf(err, errlen, "at most %d boards in one test", VT_MAX_BOARDS);
		return NULL;
	}
	if (!name || !*name || strlen(name) > VMAC_NAME_MAX || vt_board_find(w, name)) {
		snprintf(err, errlen, "board name '%s': must be 1..%d characters and not used yet", name ? name : "",
		         VMAC_NAME_MAX);
		return NULL;
	}
	if (make_sim(w, plant, &sim, err, errlen) != 0)
		return NULL;
	if (!driver)
		driver = vmac_sim_driver(&sim);
	if (strlen(driver) > VMAC_NAME_MAX) {
		snprintf(err, errlen, "driver name '%s' is longer than %d characters", driver, VMAC_NAME_MAX);
		vmac_sim_fini(&sim);
		return NULL;
	}
	for (i = 0; i < w->nboards; i++)
		if (w->boards[i]->fw.id.major == major && strcmp(w->boards[i]->fw.id.driver, driver) == 0)
			primary = 0; /* joins a machine that already has its primary */
	b = calloc(1, sizeof(*b));
	if (!b) {
		snprintf(err, errlen, "out of memory");
		vmac_sim_fini(&sim);
		return NULL;
	}
	memset(&id, 0, sizeof(id));
	snprintf(id.board, sizeof(id.board), "%s", name);
	snprintf(id.driver, sizeof(id.driver), "%s", driver);
	id.major = major;
	id.minor = minor;
	id.caps = vmac_sim_caps(&sim);
	if (enroll(w, &id, err, errlen) != 0) {
		vmac_sim_fini(&sim);
		free(b);
		return NULL;
	}
	b->sim = sim;
	b->plugged = b->powered = 1;
	sin = (struct sockaddr_in *)&b->addr.ss;
	sin->sin_family = AF_INET;
	sin->sin_port = htons(5870);
	sin->sin_addr.s_addr = htonl(0x0A4D0000u | (uint32_t)(w->nboards + 1)); /* 10.77.0.N */
	b->addr.len = sizeof(*sin);
	board_firmware_init(w, b, &id);
	load_io_map(w, b, driver, primary);
	w->boards[w->nboards++] = b;
	return b;
}

struct vt_board *vt_board_find(struct vt_world *w, const char *name)
{
	int i;
	for (i = 0; i < w->nboards; i++)
		if (strcmp(w->boards[i]->fw.id.board, name) == 0)
			return w->boards[i];
	return NULL;
}

void vt_board_power(struct vt_world *w, struct vt_board *b, int on)
{
	if (on && !b->powered) {
		struct vmac_board_identity id = b->fw.id;
		board_firmware_init(w, b, &id);
	} else if (!on) {
		vmac_board_safe(&b->fw);
	}
	b->powered = on;
}

int vt_io_value(struct vt_world *w, const struct vt_board *b, const char *name, double *value, int *is_bool)
{
	struct vmac_inputs in;
	int i;
	for (i = 0; i < b->nio && strcmp(b->io[i].name, name) != 0; i++)
		;
	if (i == b->nio)
		return -1;
	*is_bool = 0;
	switch (b->io[i].kind) {
	case VMAC_IO_DO:
		*is_bool = 1;
		*value = (b->fw.outputs.digital >> b->io[i].channel) & 1;
		return 0;
	case VMAC_IO_PWM: *value = b->fw.outputs.pwm; return 0;
	default: break;
	}
	w->reads_plant = 1;
	vmac_sim_sense(&b->sim, &in);
	if (b->io[i].kind == VMAC_IO_DI) {
		*is_bool = 1;
		*value = (in.digital >> b->io[i].channel) & 1;
	} else if (b->io[i].kind == VMAC_IO_AI) {
		*value = in.analog[b->io[i].channel] * b->io[i].scale + b->io[i].offset;
	} else {
		*value = in.encoder;
	}
	return 0;
}

int vt_input(struct vt_world *w, const char *device, const char *name, const struct vmac_value *value, char *reply,
             size_t replylen)
{
	int rc;
	if (!w->bus) {
		snprintf(reply, replylen, "the host is down (crash_host)");
		return -VMAC_ENOTRUNNING;
	}
	rc = vmac_bus_input(w->bus, device, name, value, reply, replylen);
	pump(w);
	return rc;
}

const struct vmac_device_status *vt_device(struct vt_world *w, const char *device)
{
	return w->bus && vmac_bus_device_status(w->bus, device, &w->status) == 0 ? &w->status : NULL;
}

void vt_stop_host(struct vt_world *w)
{
	struct vmac_host_cmd c;
	memset(&c, 0, sizeof(c));
	c.kind = VMAC_CMD_STOP;
	if (!w->bus)
		return;
	vmac_bus_send_cmd(w->bus, &c);
	vmac_bus_virtual_commands(w->bus);
	pump(w);
}

void vt_crash_host(struct vt_world *w)
{
	if (!w->bus)
		return;
	pump(w); /* what reached the store before the crash */
	vmac_mainloop_free(w->main);
	w->main = NULL;
	vmac_bus_free(w->bus); /* no detach, no SHUTDOWN: the boards' watchdogs end it */
	w->bus = NULL;
	w->moved = 1;
}

int vt_driver_cost(struct vt_world *w, const char *driver, int64_t cost_ns, char *err, size_t errlen)
{
	int i;
	for (i = 0; i < VMAC_BUS_VIRTUAL_COSTS; i++)
		if (!w->costs[i].driver[0] || strcmp(w->costs[i].driver, driver) == 0)
			break;
	if (i == VMAC_BUS_VIRTUAL_COSTS) {
		snprintf(err, errlen, "driver_cost: at most %d drivers", VMAC_BUS_VIRTUAL_COSTS);
		return -1;
	}
	snprintf(w->costs[i].driver, sizeof(w->costs[i].driver), "%s", driver);
	w->costs[i].cost_ns = cost_ns;
	if (w->bus)
		vmac_bus_virtual_driver_cost(w->bus, driver, cost_ns);
	return 0;
}

int vt_start_host(struct vt_world *w, char *err, size_t errlen)
{
	struct vmac_bus_link link;
	int i;
	if (w->bus) {
		snprintf(err, errlen, "the host is running");
		return -1;
	}
	link.send = host_send;
	link.ctx = w;
	w->bus = vmac_bus_new_virtual(&w->cfg, &link, &w->bus_group, err, errlen);
	if (!w->bus)
		return -1;
	vmac_bus_virtual_start_at(w->bus, w->now_ns);
	w->host_start_ns = w->now_ns;
	{
		const struct vmac_mainloop_hooks hooks = {
		    .ctx = w, .wall_ns = world_ns, .bus_ns = world_ns, .event = keep_event, .loaded = run_commands};
		vmac_event_log_init(&w->log); /* a new process's log: its numbering goes on from the store */
		w->main = vmac_mainloop_new(&w->cfg, w->bus, w->store, &w->log, &hooks, err, errlen);
		if (!w->main) {
			vmac_bus_free(w->bus);
			w->bus = NULL;
			return -1;
		}
		vmac_bus_virtual_commands(w->bus); /* the board keys, before the first discovery */
	}
	for (i = 0; i < VMAC_BUS_VIRTUAL_COSTS; i++)
		if (w->costs[i].driver[0])
			vmac_bus_virtual_driver_cost(w->bus, w->costs[i].driver, w->costs[i].cost_ns);
	w->moved = 1;
	return 0;
}

struct vt_world *vt_world_new(const struct vmac_config *cfg, uint64_t seed, char *err, size_t errlen)
{
	struct vt_world *w = calloc(1, sizeof(*w));
	struct vmac_bus_link link;
	struct sockaddr_in *sin;
	if (!w) {
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	w->cfg = *cfg;
	w->seed = seed;
	w->rng = seed * 0x9E3779B97F4A7C15ULL + 0x632BE59BD9B4E019ULL;
	if (!w->rng)
		w->rng = 1;
	sin = (struct sockaddr_in *)&w->bus_group.ss;
	sin->sin_family = AF_INET;
	sin->sin_port = htons(5870);
	sin->sin_addr.s_addr = htonl(0xEFFF564Du); /* 239.255.86.77 */
	w->bus_group.len = sizeof(*sin);
	(void)link;
	if (vmac_store_open_memory(&w->store, err, errlen) != 0) {
		free(w);
		return NULL;
	}
	if (vt_start_host(w, err, errlen) != 0) {
		vmac_store_close(w->store);
		free(w);
		return NULL;
	}
	w->next_plant_ns = VT_PLANT_STEP_NS;
	return w;
}

void vt_world_free(struct vt_world *w)
{
	int i;
	if (!w)
		return;
	if (w->bus) {
		pump(w);
		vmac_mainloop_free(w->main);
		vmac_bus_free(w->bus);
	}
	vmac_store_close(w->store);
	for (i = 0; i < w->nboards; i++) {
		vmac_sim_fini(&w->boards[i]->sim);
		vt_clock_free(w->boards[i]);
		free(w->boards[i]);
	}
	free(w->q);
	free(w->events);
	free(w);
}
