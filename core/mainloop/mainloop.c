/* The host's main thread: see mainloop.h. */
#include "mainloop.h"

#include <errno.h>
#include <math.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/file.h"
#include "../host/audit.h"
#include "../loader/loader.h"
#include "../recorder/recording.h"
#include "../reload/deploy.h"

#define STALLED_KEPT 32
#define OUTBOX_BATCH 64 /* audit outbox rows taken per look */
/* The store's board keys and audit outbox are looked at no more often
 * than this much bus time: each look asks SQLite for its data_version,
 * and vmac test services every virtual millisecond, where two statements
 * a time were most of its work. vmacd services every 50 ms at least; the
 * host's own writes (the API's) are looked at the next service. */
#define STORE_LOOK_NS 20000000LL
/* A service takes the bus thread's messages for this long at most, then
 * does the rest (keys, outbox, workers, checkpoints, events) and says
 * there is more: machines whose drivers fail as they load, again and
 * again, keep the ring full, and each load or recording can take tens of
 * milliseconds, so draining it first could hold the rest off for good. */
#define SERVICE_MSGS_NS 20000000LL

struct vmac_mainloop {
	const struct vmac_config *cfg;
	struct vmac_bus *bus;
	struct vmac_store *store;
	struct vmac_event_log *log;
	struct vmac_mainloop_hooks hooks;
	uint64_t stored_seq;     /* events up to this one are in the store */
	int store_failing;       /* the last copy of events failed: said once, retried */
	int checkpoints_failing; /* the last save of checkpoints failed: said once, retried */
	int64_t started_ns;      /* wall time this host began: older checkpoints are from before a restart */
	/* Versions that stalled a driver worker: not loaded again until a new
	 * version arrives (a reload gives a new version id). The newest few. */
	struct stalled {
		char driver[VMAC_NAME_MAX + 1];
		char version[VMAC_DRIVER_VERSION_MAX + 1];
		int64_t id;
	} stalled[STALLED_KEPT];
	unsigned nstalled;
	/* The board keys the bus has: the store's at keys_version. */
	uint64_t keys_version;
	int keys_sent;
	/* The audit outbox (`vmac token`'s rows): looked at when its version
	 * changed; rows up to outbox_taken are in the log (a delete that
	 * failed is tried again, the rows not logged twice). */
	uint64_t outbox_version;
	int outbox_looked, outbox_failing;
	/* When the store was last looked at for keys and outbox (bus time),
	 * and this connection's writes then: a write of the host's own (the
	 * API's) is looked at the next service, another process's within
	 * STORE_LOOK_NS. */
	int store_looked;
	int64_t store_looked_ns;
	uint64_t store_writes;
	int64_t outbox_taken, outbox_deleted;
};

static double wall_s(const struct vmac_mainloop *l)
{
	return (double)l->hooks.wall_ns(l->hooks.ctx) / 1e9;
}

static void say(struct vmac_mainloop *l, const char *kind, const char *device, const char *text)
{
	vmac_event_log_add_at(l->log, l->hooks.wall_ns(l->hooks.ctx), kind, device, text);
}

struct restore {
	struct vmac_mainloop *l;
	struct vmac_driver *drv;
	const char *device;
};

static void restore_one(void *ctx, const char *name, const struct vmac_value *v)
{
	struct restore *r = ctx;
	char why[200], text[300];
	if (vmac_driver_restore_param(r->drv, name, v, why, sizeof(why)) != 0) {
		snprintf(text, sizeof(text), "%s: persisted param not restored: %s", r->device, why);
		say(r->l, "warning", r->device, text);
	}
}

/* The params persisted for the machine whose primary is device go back
 * into its freshly loaded driver (before it runs). */
static void restore_params(struct vmac_mainloop *l, struct vmac_driver *drv, const char *device)
{
	struct restore r = {l, drv, device};
	char err[512];
	if (vmac_store_param_list(l->store, device, restore_one, &r, err, sizeof(err)) < 0)
		say(l, "warning", device, err);
}

/* The checkpoints the bus thread has handed over go to the store, in one
 * transaction (a batch at most the ring's size; the store keeps the newest
 * of each machine). A failure (a full disk) is said once; those checkpoints
 * are lost, newer ones follow. */
static void store_checkpoints(struct vmac_mainloop *l)
{
	enum { BATCH = 16 };
	struct vmac_checkpoint cp[BATCH];
	struct vmac_bus_checkpoint head[BATCH]; /* names and time, copied out of the ring */
	uint8_t *data[BATCH];
	const struct vmac_bus_checkpoint *c;
	double bus_to_wall = wall_s(l) - (double)l->hooks.bus_ns(l->hooks.ctx) / 1e9;
	char err[512], text[600];
	int n, i;
	do {
		for (n = 0; n < BATCH && (c = vmac_bus_checkpoint_peek(l->bus)) != NULL; n++) {
			/* Copied out so that the slot goes back to the bus thread at once. */
			memcpy(&head[n], c, sizeof(head[n]));
			data[n] = malloc(c->len ? c->len : 1);
			if (data[n])
				memcpy(data[n], c->data, c->len);
			vmac_bus_checkpoint_release(l->bus);
			if (!data[n]) {
				n--; /* out of memory: this one is lost, a newer one follows */
				continue;
			}
			cp[n].machine = head[n].machine;
			cp[n].driver = head[n].driver;
			cp[n].version = head[n].version;
			cp[n].time = bus_to_wall + (double)head[n].time_ns / 1e9;
			cp[n].data = data[n];
			cp[n].len = head[n].len;
		}
		if (n == 0)
			return;
		if (vmac_store_checkpoints_put(l->store, cp, n, err, sizeof(err)) != 0) {
			if (!l->checkpoints_failing) {
				snprintf(text, sizeof(text), "checkpoints are not being saved: %s", err);
				say(l, "warning", "", text);
			}
			l->checkpoints_failing = 1;
		} else {
			l->checkpoints_failing = 0;
		}
		for (i = 0; i < n; i++)
			free(data[i]);
	} while (n == BATCH);
}

/* The checkpoint of machine `device`, if the store has one of this driver,
 * offered to its freshly loaded instance (for recover, after attach). Its
 * age is by the wall clock (the host may have rebooted); a checkpoint more
 * than CLOCK_BACK_S in the future was taken before the clock was set back
 * (a box without a battery-backed clock, set by NTP after the crash): of
 * unknown age, it is offered as infinitely old, so a driver does not
 * resume an hour-old programme as a fresh one. */
#define CLOCK_BACK_S 1.0
static void offer_checkpoint(struct vmac_mainloop *l, struct vmac_driver *drv, const char *device)
{
	struct vmac_checkpoint_info info;
	char driver[VMAC_NAME_MAX + 1], version[VMAC_DRIVER_VERSION_MAX + 1], err[512], text[700];
	uint8_t *data;
	size_t len;
	double time;
	int rc = vmac_store_checkpoint_get(l->store, device, &data, &len, driver, sizeof(driver), version,
	                                   sizeof(version), &time, err, sizeof(err));
	if (rc < 0)
		say(l, "warning", device, err);
	if (rc != 1)
		return;
	if (strcmp(driver, vmac_driver_name(drv)) == 0) {
		double age_s = wall_s(l) - time;
		int set_back = age_s < -CLOCK_BACK_S; /* the wall clock was set back since: its age unknown */
		info.time = time;
		info.age_s = set_back ? HUGE_VAL : age_s < 0 ? 0 : age_s;
		info.version = version;
		info.restarted = set_back || time < (double)l->started_ns / 1e9; /* set back: a restart since too */
		if (vmac_driver_offer_checkpoint(drv, data, len, &info, err, sizeof(err)) != 0) {
			snprintf(text, sizeof(text), "%s: checkpoint not offered: %s", device, err);
			say(l, "warning", device, text);
		}
	}
	free(data);
}

/* The bundle of the driver version a recording ran (the store's version:
 * every version that runs is one, the drivers folder's too) and its
 * driver's source, each malloc'd; NULL when unknown (a version stored
 * before bundles has its Lua text only). */
static void recorded_bundle(struct vmac_mainloop *l, const struct vmac_recorder *r, char **bundle, size_t *blen,
                            char **src, size_t *srclen)
{
	struct vmac_driver_version v;
	struct vmac_bundle *b;
	char err[VMAC_PATH_MAX + 128], *data = NULL;
	size_t len = 0;
	*bundle = *src = NULL;
	*blen = *srclen = 0;
	if (r->version_id <= 0 ||
	    vmac_store_driver_get(l->store, r->version_id, &v, &data, &len, err, sizeof(err)) != 1)
		return;
	if (!vmac_bundle_is_archive(data, len)) {
		*src = data, *srclen = len;
		return;
	}
	if (vmac_bundle_read(data, len, &b, err, sizeof(err)) == 0) {
		const struct vmac_bundle_file *f = vmac_bundle_driver(b);
		if (f && (*src = malloc(f->len + 1))) {
			memcpy(*src, f->data, f->len + 1);
			*srclen = f->len;
		}
		vmac_bundle_free(b);
	}
	*bundle = data, *blen = len;
}

/* The machine runs on after a capture: a new recorder takes the place of
 * the one captured. */
static void replace_recorder(struct vmac_mainloop *l, const struct vmac_bus_msg *m, double period_s)
{
	struct vmac_host_cmd c;
	memset(&c, 0, sizeof(c));
	c.kind = VMAC_CMD_RECORDER;
	c.slot = m->slot;
	c.generation = m->generation;
	c.rec = vmac_recorder_new(l->cfg->recorder_s, period_s);
	if (c.rec && vmac_bus_send_cmd(l->bus, &c) != 0)
		vmac_recorder_free(c.rec);
}

/* A machine's flight recorder, captured (a drop, a driver failure), goes
 * to the store as a recording file (docs/RECORDING.md); an event says
 * where to find it. */
static void store_recording(struct vmac_mainloop *l, const struct vmac_bus_msg *m)
{
	struct vmac_recorder *r = m->rec;
	struct vmac_recording_info info;
	char err[512], text[700], *file, *src, *bundle;
	size_t len, srclen, blen;
	int64_t id;
	memset(&info, 0, sizeof(info));
	snprintf(info.machine, sizeof(info.machine), "%s", r->machine);
	snprintf(info.driver, sizeof(info.driver), "%s", r->driver);
	snprintf(info.version, sizeof(info.version), "%s", r->version);
	snprintf(info.reason, sizeof(info.reason), "%s", r->reason);
	info.time = wall_s(l) - (double)(l->hooks.bus_ns(l->hooks.ctx) - r->when_ns) / 1e9;
	recorded_bundle(l, r, &bundle, &blen, &src, &srclen);
	file = vmac_recording_write(r, src, srclen, bundle, blen, info.time, &len);
	free(src);
	free(bundle);
	if (m->replace)
		replace_recorder(l, m, r->period_s);
	vmac_recorder_free(r);
	if (!file) {
		say(l, "warning", info.machine, "recording lost: out of memory");
		return;
	}
	if (vmac_store_recording_add(l->store, &info, file, len, (int)l->cfg->recordings_max, &id, err, sizeof(err)) !=
	    0) {
		snprintf(text, sizeof(text), "%s: recording lost: %s", info.machine, err);
		say(l, "warning", info.machine, text);
	} else {
		snprintf(text, sizeof(text), "%s: recording %lld kept (%zu bytes): %s; vmac recording get %lld",
		         info.machine, (long long)id, len, info.reason, (long long)id);
		say(l, "recording", info.machine, text);
	}
	free(file);
}

static int has_stalled(const struct vmac_mainloop *l, const struct vmac_driver *drv)
{
	unsigned i;
	for (i = 0; i < l->nstalled && i < STALLED_KEPT; i++)
		if (l->stalled[i].id == vmac_driver_tag(drv) &&
		    strcmp(l->stalled[i].driver, vmac_driver_name(drv)) == 0 &&
		    strcmp(l->stalled[i].version, vmac_driver_version(drv)) == 0)
			return 1;
	return 0;
}

struct load {
	struct vmac_mainloop *l;
	const struct vmac_bus_msg *m;
};

/* vmac_deploy_load's result goes to the bus thread, with the machine's
 * persisted params and checkpoint in the driver; a version that stalled a
 * worker is refused. */
static void hand_over(void *ctx, int rc, struct vmac_driver *drv, const char *text)
{
	struct load *ld = ctx;
	char why[VMAC_EVENT_TEXT];
	if (drv && has_stalled(ld->l, drv)) {
		snprintf(why, sizeof(why),
		         "driver %s %s stalled a driver worker on this host; it is not loaded again until a new "
		         "version arrives (vmac reload)",
		         vmac_driver_name(drv), vmac_driver_version(drv));
		vmac_driver_free(drv);
		drv = NULL;
		rc = -EPERM;
		text = why;
	}
	if (drv) {
		restore_params(ld->l, drv, ld->m->device);
		offer_checkpoint(ld->l, drv, ld->m->device);
	}
	if (vmac_bus_loaded(ld->l->bus, ld->m, rc, drv, text) != 0)
		say(ld->l, "warning", ld->m->device, "command ring full; device will retry on discovery");
}

static void load_driver(struct vmac_mainloop *l, const struct vmac_bus_msg *m)
{
	struct load ld = {l, m};
	store_checkpoints(l); /* one taken before this load is found by it */
	vmac_deploy_load(l->store, l->cfg, m->driver, m->device, hand_over, &ld);
	if (l->hooks.loaded)
		l->hooks.loaded(l->hooks.ctx);
}

/* The events not yet in the store go there, in one transaction. An event
 * the in-memory log has already dropped is counted. */
static void store_events(struct vmac_mainloop *l)
{
	struct vmac_event ev[VMAC_EVENT_LOG_SIZE];
	struct vmac_stored_event st[VMAC_EVENT_LOG_SIZE];
	char err[512], text[600];
	uint64_t lost;
	int n, i;
	for (;;) {
		n = vmac_event_log_since(l->log, l->stored_seq, ev, VMAC_EVENT_LOG_SIZE, 0, &lost);
		if (n == 0)
			return;
		for (i = 0; i < n; i++) {
			st[i].seq = ev[i].seq;
			st[i].time = (double)ev[i].time_ns / 1e9;
			st[i].kind = ev[i].kind;
			st[i].device = ev[i].device;
			st[i].text = ev[i].text;
		}
		if (vmac_store_events_add(l->store, st, n, err, sizeof(err)) != 0) {
			if (!l->store_failing) { /* this warning is not stored either: it would fail the same way */
				l->store_failing = 1;
				snprintf(text, sizeof(text), "events are not being stored: %s", err);
				say(l, "warning", "", text);
			}
			return;
		}
		l->store_failing = 0;
		l->stored_seq = ev[n - 1].seq;
		if (l->hooks.event)
			for (i = 0; i < n; i++)
				l->hooks.event(l->hooks.ctx, &ev[i]);
		if (lost) {
			snprintf(text, sizeof(text), "%llu events came too fast to be stored",
			         (unsigned long long)lost);
			say(l, "warning", "", text);
		}
	}
}

static void on_event(struct vmac_mainloop *l, const struct vmac_bus_msg *m)
{
	char err[512];
	say(l, m->event_kind, m->device, m->text);
	if (m->code == VMAC_EVENT_ROLLED_BACK && m->version_id) {
		/* A version on probation failed and its machines went back: the
		 * store says so too, so that boards attaching later load the
		 * version before (under the deploy lock: never in the middle of
		 * a deploy). */
		if (vmac_deploy_rolled_back(l->store, m->driver, m->version_id, m->text, err, sizeof(err)) < 0)
			say(l, "warning", m->device, err);
	}
	if (m->code == VMAC_EVENT_STALLED) {
		struct stalled *x = &l->stalled[l->nstalled++ % STALLED_KEPT];
		memcpy(x->driver, m->driver, sizeof(x->driver));
		memcpy(x->version, m->version, sizeof(x->version));
		x->id = m->version_id;
	}
}

struct key_list {
	struct vmac_board_key *k;
	int n, cap, failed;
};

static void collect_key(void *ctx, const struct vmac_board_key *k)
{
	struct key_list *x = ctx;
	if (x->n == x->cap) {
		int cap = x->cap ? 2 * x->cap : 64;
		struct vmac_board_key *more = malloc((size_t)cap * sizeof(*more));
		if (!more) {
			x->failed = 1;
			return;
		}
		if (x->k) {
			memcpy(more, x->k, (size_t)x->n * sizeof(*more));
			sodium_memzero(x->k, (size_t)x->n * sizeof(*more));
		}
		free(x->k);
		x->k = more;
		x->cap = cap;
	}
	x->k[x->n++] = *k;
}

/* The bus gets the store's board keys whenever they changed (enrolled or
 * removed here through the API, or by `vmac board --local` in another
 * process), looked at on a service at once after the API changed them,
 * else at most every STORE_LOOK_NS of bus time (vmacd services at least
 * every 50 ms). */
static void sync_keys(struct vmac_mainloop *l)
{
	struct key_list x = {0};
	struct vmac_bus_keys *keys = NULL;
	uint64_t version;
	char err[512];
	int i, rc;
	version = vmac_board_keys_version(l->store);
	if (l->keys_sent && version == l->keys_version)
		return;
	rc = vmac_board_key_list(l->store, collect_key, &x, err, sizeof(err));
	if (rc >= 0 && !x.failed && (keys = vmac_bus_keys_new((uint32_t)x.n)) != NULL) {
		for (i = 0; i < x.n; i++)
			vmac_bus_keys_add(keys, x.k[i].board, x.k[i].key);
		if (vmac_bus_set_keys(l->bus, keys) == 0) {
			l->keys_version = version;
			l->keys_sent = 1;
		} else {
			vmac_bus_keys_free(keys); /* the ring is full: the next look sends them */
		}
	} else if (rc < 0) {
		say(l, "warning", "", err);
	}
	if (x.k)
		sodium_memzero(x.k, (size_t)x.cap * sizeof(*x.k));
	free(x.k);
}

/* A row of the audit outbox into the log, as an audit event from this
 * machine (`local`), its time in its text: the host takes it after the
 * fact, and its own seq and time are when it did. */
static void take_row(void *ctx, const struct vmac_audit_row *r)
{
	struct vmac_mainloop *l = ctx;
	struct vmac_audit a;
	char why[sizeof(r->why) + 64], when[32];
	time_t t = (time_t)r->time;
	struct tm tm;
	strftime(when, sizeof(when), "%Y-%m-%dT%H:%M:%SZ", gmtime_r(&t, &tm));
	snprintf(why, sizeof(why), "%s%sat %s", r->why, r->why[0] ? "; " : "", when);
	memset(&a, 0, sizeof(a));
	a.type = r->type;
	a.who = r->who;
	a.where = "local";
	a.what = r->what;
	a.result = r->result;
	a.why = why;
	a.device = "";
	a.key = strcmp(r->result, "ok") != 0 ? "local" : NULL; /* a refusal, rate-limited as any */
	vmac_audit_add(l->log, &a);
	if (r->id > l->outbox_taken)
		l->outbox_taken = r->id;
}

/* What `vmac token` changed while the host ran (or before it started):
 * the outbox's rows into the log, then out of the store. Looked at when
 * the store's data_version says another process wrote (as for the board
 * keys), at once at start. A failure is said once. */
static void take_outbox(struct vmac_mainloop *l)
{
	uint64_t version = vmac_store_audit_version(l->store);
	char err[512], text[600];
	int n = 0;
	if (l->outbox_looked && version == l->outbox_version && l->outbox_deleted == l->outbox_taken)
		return;
	l->outbox_looked = 1;
	l->outbox_version = version;
	do {
		n = vmac_store_audit_list(l->store, l->outbox_taken, OUTBOX_BATCH, take_row, l, err, sizeof(err));
	} while (n == OUTBOX_BATCH);
	if (n >= 0 && l->outbox_taken > l->outbox_deleted &&
	    (n = vmac_store_audit_delete(l->store, l->outbox_taken, err, sizeof(err))) == 0)
		l->outbox_deleted = l->outbox_taken;
	if (n < 0 && !l->outbox_failing) {
		snprintf(text, sizeof(text), "the audit outbox of vmac token cannot be taken: %s", err);
		say(l, "warning", "", text);
	}
	l->outbox_failing = n < 0;
}

int vmac_mainloop_service(struct vmac_mainloop *l)
{
	struct vmac_bus_msg m;
	uint64_t writes;
	int64_t now, begun = l->hooks.bus_ns(l->hooks.ctx);
	int more = 0;
	while (!more && vmac_bus_poll_msg(l->bus, &m)) {
		switch (m.kind) {
		case VMAC_MSG_EVENT: on_event(l, &m); break;
		case VMAC_MSG_LOAD: load_driver(l, &m); break;
		case VMAC_MSG_UNLOAD:
			vmac_driver_free(m.drv);
			vmac_recorder_free(m.rec);
			free(m.buf);
			break;
		case VMAC_MSG_RECORDING: store_recording(l, &m); break;
		case VMAC_MSG_STOPPED:
			if (l->hooks.stopped)
				l->hooks.stopped(l->hooks.ctx);
			break;
		}
		/* A burst of events goes to the store before the log's ring
		 * wraps over the ones not yet copied. */
		if (vmac_event_log_next_seq(l->log) - l->stored_seq > VMAC_EVENT_LOG_SIZE / 2)
			store_events(l);
		more = l->hooks.bus_ns(l->hooks.ctx) - begun >= SERVICE_MSGS_NS;
	}
	vmac_bus_workers_service(l->bus);
	now = l->hooks.bus_ns(l->hooks.ctx);
	writes = vmac_store_local_writes(l->store);
	if (!l->store_looked || writes != l->store_writes || now - l->store_looked_ns >= STORE_LOOK_NS ||
	    now < l->store_looked_ns) {
		l->store_looked = 1;
		l->store_looked_ns = now;
		l->store_writes = writes;
		sync_keys(l);
		take_outbox(l);
	}
	vmac_audit_flush(l->log); /* a window of refusals that has ended says what it left unsaid */
	store_checkpoints(l);
	store_events(l);
	return more;
}

struct vmac_mainloop *vmac_mainloop_new(const struct vmac_config *cfg, struct vmac_bus *bus, struct vmac_store *store,
                                        struct vmac_event_log *log, const struct vmac_mainloop_hooks *hooks, char *err,
                                        size_t errlen)
{
	struct vmac_mainloop *l = calloc(1, sizeof(*l));
	if (!l) {
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	l->cfg = cfg;
	l->bus = bus;
	l->store = store;
	l->log = log;
	l->hooks = *hooks;
	if (vmac_store_events_last(store, &l->stored_seq, err, errlen) != 0) {
		free(l);
		return NULL;
	}
	vmac_event_log_start_at(log, l->stored_seq + 1); /* seq goes on across restarts */
	l->started_ns = hooks->wall_ns(hooks->ctx);
	sync_keys(l); /* before the bus starts: in place for the first discovery */
	if (!vmac_config_trust_open(cfg))
		return l;
	say(l, "warning", "",
	    "bus_trust is open: a board without an enrolled key attaches too, and anyone on the bus segment can "
	    "speak for such a board (docs/SECURITY.md)");
	return l;
}

void vmac_mainloop_sync_keys(struct vmac_mainloop *l)
{
	sync_keys(l);
}

void vmac_mainloop_free(struct vmac_mainloop *l)
{
	free(l);
}
