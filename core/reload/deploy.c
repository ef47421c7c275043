/* See deploy.h. */
#include "deploy.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../common/errors.h"
#include "../loader/loader.h"
#include "accept.h"

#define SWAP_TIMEOUT_MS 2000 /* the bus thread takes a request within a tick */
#define ATTACH_POLL_US 5000  /* how often a machine still registering is looked at again */

/* Held through a whole deploy or rollback (store and machines), by the
 * store's record of a probation rollback (vmac_deploy_rolled_back), and by
 * vmac_deploy_load from reading the store until the new machine's driver
 * is handed to the bus thread. So a machine that comes while a deploy is
 * under way either was handed its driver before the deploy began (the
 * deploy then finds it, vmac_bus_request_machines, and switches it) or
 * loads after the deploy has ended (the store then says which version
 * won): none keeps the version the deploy replaced. */
static pthread_mutex_t deploy_lock = PTHREAD_MUTEX_INITIALIZER;

/* Test-only knob: VMAC_TEST_DEPLOY_PAUSE_MS=N makes every deploy and
 * rollback wait N ms (at most 60 s) after switching the machines and before
 * writing the store, the moment a board attaching would once have loaded
 * the old version (tests/integration/test_reload.py makes one attach
 * then). Unset, the default, nothing waits. It only delays a deploy: the
 * deploy lock is held the whole time, so it cannot change an outcome. */
static void test_pause(const char *driver)
{
	const char *v = getenv("VMAC_TEST_DEPLOY_PAUSE_MS");
	long ms = v ? strtol(v, NULL, 10) : 0;
	if (ms <= 0)
		return;
	if (ms > 60000)
		ms = 60000;
	fprintf(stderr, "vmacd: deploy of %s paused %ld ms between its steps (VMAC_TEST_DEPLOY_PAUSE_MS)\n", driver,
	        ms);
	usleep((useconds_t)ms * 1000);
}

static int64_t mono_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

/* A store error (code as the store returns it) as an HTTP status: a full
 * disk is 507, the rest 500. */
static void store_failed(struct vmac_deploy_result *out, int code, const char *err)
{
	out->status = code == -VMAC_ESTOREFULL ? 507 : 500;
	out->code = code;
	snprintf(out->error, sizeof(out->error), "%s", err);
}

/* The machines of driver (their primary boards' names), at most max, as
 * the bus thread has them now: running ones, and ones handed their driver
 * whose boards are still registering. Returns how many, or -1 (the bus
 * thread took no request) with out's status 503. */
static int machines_of(const struct vmac_deploy_ctx *x, const char *driver, char (*names)[VMAC_NAME_MAX + 1], int max,
                       struct vmac_deploy_result *out)
{
	char why[VMAC_EVENT_TEXT];
	int n = vmac_bus_request_machines(x->bus, driver, names, max, SWAP_TIMEOUT_MS, why, sizeof(why));
	if (n < 0) {
		out->status = 503;
		snprintf(out->error, sizeof(out->error), "%s", why);
	}
	return n;
}

/* Whether name is still one of driver's machines (with a driver instance). */
static int still_a_machine(const struct vmac_deploy_ctx *x, const char *driver, const char *name)
{
	char names[VMAC_DEPLOY_MACHINES][VMAC_NAME_MAX + 1], why[VMAC_EVENT_TEXT];
	int i, n = vmac_bus_request_machines(x->bus, driver, names, VMAC_DEPLOY_MACHINES, SWAP_TIMEOUT_MS, why,
	                                     sizeof(why));
	for (i = 0; i < n; i++)
		if (strcmp(names[i], name) == 0)
			return 1;
	return 0;
}

/* A fresh instance of bundle b (tagged tag) takes over machine `name`
 * (vmac_bus_request_swap). A machine whose boards are still registering
 * refuses as not running: it is waited for (it attaches with the version
 * it was loaded with, then takes the new one over like the others) while
 * it is still a machine of driver, at most two reply deadlines and a
 * second (a board that does not answer REGISTER is dropped within one).
 * Each try loads an instance of its own: one refused as not running may
 * have taken over a machine dropped before the bus collected it, and
 * holds that machine's boards and state. 0 switched; else not, text says
 * why. */
static int swap_one(const struct vmac_deploy_ctx *x, const char *driver, const char *name, const struct vmac_bundle *b,
                    int64_t tag, unsigned probation_ms, char *text, size_t textlen)
{
	int64_t until = mono_ms() + 2 * (int64_t)x->cfg->reply_deadline_us / 1000 + 1000;
	for (;;) {
		struct vmac_driver *drv = NULL;
		int rc = -1, asked;
		if (vmac_load_driver_bundle(x->cfg, b, name, &drv, text, textlen) != 0)
			return -VMAC_EFAIL;
		vmac_driver_set_tag(drv, tag);
		asked =
		    vmac_bus_request_swap(x->bus, name, drv, probation_ms, SWAP_TIMEOUT_MS, &rc, text, textlen) == 0;
		if (rc != 0 && rc != -VMAC_EDRIVER) /* EDRIVER: it stalled, and went with its worker */
			vmac_driver_free(drv);
		if (!asked || rc != -VMAC_ENOTRUNNING || mono_ms() > until || !still_a_machine(x, driver, name))
			return rc;
		usleep(ATTACH_POLL_US);
	}
}

/* Hand every machine of names a fresh instance of bundle b (tagged tag).
 * Records each machine in out; returns how many refused. switched[i] says
 * which took it. */
static int swap_all(const struct vmac_deploy_ctx *x, const char *driver, const struct vmac_bundle *b, int64_t tag,
                    unsigned probation_ms, char (*names)[VMAC_NAME_MAX + 1], int n, int *switched,
                    struct vmac_deploy_result *out)
{
	int i, refused = 0;
	out->nmachines = 0;
	for (i = 0; i < n; i++) {
		struct vmac_deploy_machine *r = &out->machines[out->nmachines++];
		int rc = swap_one(x, driver, names[i], b, tag, probation_ms, r->text, sizeof(r->text));
		snprintf(r->device, sizeof(r->device), "%s", names[i]);
		switched[i] = 0;
		if (rc == 0) {
			r->ok = switched[i] = 1;
		} else if (rc == -VMAC_ENOTRUNNING) {
			out->nmachines--; /* it went away meanwhile: nothing to switch */
		} else {
			refused++;
		}
	}
	return refused;
}

/* Refuse with code and the message in out. */
static void refuse(struct vmac_deploy_result *out, int code, const char *err)
{
	out->code = code;
	out->status = deploy_status_of(code);
	snprintf(out->error, sizeof(out->error), "%s", err);
}

/* Version id's bundle from the store: 1 and *b (*v), 0 none, < 0 with err. */
static int stored_bundle(const struct vmac_deploy_ctx *x, const char *driver, int64_t id, struct vmac_driver_version *v,
                         struct vmac_bundle **b, char *err, size_t errlen)
{
	char *data = NULL;
	size_t len = 0;
	int rc = vmac_store_driver_get(x->store, id, v, &data, &len, err, errlen);
	*b = NULL;
	if (rc == 1 && strcmp(v->driver, driver) != 0)
		rc = 0;
	if (rc == 1 && vmac_bundle_of_data(x->cfg, driver, data, len, b, err, errlen) != 0)
		rc = -VMAC_EFAIL;
	free(data);
	return rc;
}

/* The kept versions' rules, under the deploy lock (docs/API.md "Drivers:
 * hot reload"): the same content as the active version is no change; the
 * counter must not be below one accepted before; a version number kept
 * with other content needs force. 0 go on, 1 nothing to do (out says
 * so), -1 refused (out says why). */
struct same_version {
	const struct vmac_bundle *b;
	const char *hash;
	int64_t id; /* a kept version of that number and other content */
	char hash_kept[65];
};

static void find_same_version(void *ctx, const struct vmac_driver_version *v)
{
	struct same_version *q = ctx;
	if (strcmp(v->version, q->b->version) == 0 && strcmp(v->hash, q->hash) != 0 &&
	    (strcmp(v->state, "active") == 0 || strcmp(v->state, "replaced") == 0 ||
	     strcmp(v->state, "rolled_back") == 0)) {
		q->id = v->id;
		snprintf(q->hash_kept, sizeof(q->hash_kept), "%s", v->hash);
	}
}

static int version_rules(const struct vmac_deploy_ctx *x, const struct vmac_bundle *b, const char *hash, int force,
                         struct vmac_deploy_result *out)
{
	struct vmac_driver_version active;
	struct same_version q = {b, hash, 0, ""};
	char err[VMAC_EVENT_TEXT];
	uint64_t max;
	int have = vmac_store_driver_active(x->store, b->name, &active, NULL, NULL, err, sizeof(err)), rc = have;
	if (rc < 0 || (rc = vmac_store_driver_counter(x->store, b->name, &max, err, sizeof(err))) < 0 ||
	    (rc = vmac_store_driver_list(x->store, b->name, find_same_version, &q, err, sizeof(err))) < 0) {
		store_failed(out, rc, err);
		return -1;
	}
	if (have == 1 && strcmp(active.hash, hash) == 0) {
		out->status = 200;
		out->unchanged = 1;
		out->id = active.id;
		snprintf(out->note, sizeof(out->note), "%s %s (hash %.12s) is active already: nothing changed", b->name,
		         b->version, hash);
		return 1;
	}
	if (b->counter < max) {
		snprintf(err, sizeof(err),
		         "%s %s has security counter %llu, below %llu, the highest this host has accepted for %s: "
		         "vmac rollback is the way back to an older version",
		         b->name, b->version, (unsigned long long)b->counter, (unsigned long long)max, b->name);
		refuse(out, -VMAC_ECOUNTER, err);
		return -1;
	}
	if (q.id && !force) {
		snprintf(err, sizeof(err),
		         "version %s of %s is kept already (id %lld, hash %.12s) with other content: give the new one "
		         "another version number, or --force to replace it",
		         b->version, b->name, (long long)q.id, q.hash_kept);
		refuse(out, -VMAC_EREFUSED, err);
		return -1;
	}
	if (q.id)
		snprintf(out->note, sizeof(out->note), "replaced %s %s of id %lld (hash %.12s), --force", b->name,
		         b->version, (long long)q.id, q.hash_kept);
	return 0;
}

/* Store bundle b (its bytes data) as a new version and put it on every
 * machine of driver; under the deploy lock. On a refusal, the machines
 * that switched go back to the version before. */
static void put_in_place(const struct vmac_deploy_ctx *x, const char *driver, const struct vmac_bundle *b,
                         const struct vmac_driver_upload *u, unsigned probation_ms, struct vmac_deploy_result *out)
{
	char names[VMAC_DEPLOY_MACHINES][VMAC_NAME_MAX + 1], err[VMAC_EVENT_TEXT];
	int switched[VMAC_DEPLOY_MACHINES], n, i, refused, have_prev, rc;
	struct vmac_driver_version prev, cur;
	struct vmac_bundle *prev_b = NULL;
	int64_t id;

	n = machines_of(x, driver, names, VMAC_DEPLOY_MACHINES, out);
	if (n < 0)
		return;
	have_prev = rc = vmac_store_driver_active(x->store, driver, &prev, NULL, NULL, err, sizeof(err));
	if (rc < 0 || (rc = vmac_store_driver_add(x->store, u, &id, err, sizeof(err))) != 0) {
		store_failed(out, rc, err);
		return;
	}
	refused = swap_all(x, driver, b, id, probation_ms, names, n, switched, out);
	test_pause(driver);
	if (refused == 0) {
		if ((rc = vmac_store_driver_activate(x->store, driver, id, err, sizeof(err))) != 0) {
			store_failed(out, rc, err);
			return;
		}
		out->status = 200;
		out->id = id;
		if (vmac_store_driver_get(x->store, id, &cur, NULL, NULL, err, sizeof(err)) == 1)
			snprintf(out->hash, sizeof(out->hash), "%s", cur.hash);
		return;
	}
	/* Some machine would not take it: one version everywhere, so the ones
	 * that switched go back to what ran before. */
	if (have_prev == 1 && stored_bundle(x, driver, prev.id, &prev, &prev_b, err, sizeof(err)) != 1)
		prev_b = NULL;
	for (i = 0; i < n; i++) {
		struct vmac_deploy_result back;
		char one[1][VMAC_NAME_MAX + 1];
		int sw;
		if (!switched[i])
			continue;
		memcpy(one[0], names[i], sizeof(one[0]));
		memset(&back, 0, sizeof(back));
		if (!prev_b || swap_all(x, driver, prev_b, prev.id, 0, one, 1, &sw, &back) != 0)
			snprintf(out->machines[i].text, sizeof(out->machines[i].text),
			         "took the new version, but going back failed: %s",
			         prev_b ? back.machines[0].text : "the version before cannot be read");
		else
			snprintf(out->machines[i].text, sizeof(out->machines[i].text),
			         "took the new version and went back (another machine refused it)");
		out->machines[i].ok = 0;
	}
	vmac_bundle_free(prev_b);
	for (i = 0; i < out->nmachines && out->machines[i].ok; i++)
		;
	snprintf(out->error, sizeof(out->error), "version %s of %s was refused: %s", out->version, driver,
	         i < out->nmachines ? out->machines[i].text : "a machine refused it");
	vmac_store_driver_refuse(x->store, id, out->error, err, sizeof(err));
	out->status = 409;
	out->code = -VMAC_EREFUSED;
	out->id = have_prev == 1 ? prev.id : 0;
}

/* Whether b's driver compiles with its programmes and declares b's
 * version: 0, or -VMAC_EFAIL / -VMAC_EBUNDLE with err. */
static int compiles(const struct vmac_deploy_ctx *x, const struct vmac_bundle *b, char *err, size_t errlen)
{
	struct vmac_driver *check = NULL;
	int rc = vmac_load_driver_bundle(x->cfg, b, "(upload)", &check, err, errlen);
	vmac_driver_free(check);
	return rc == 0 || rc == -VMAC_EBUNDLE ? rc : -VMAC_EFAIL;
}

void vmac_deploy(const struct vmac_deploy_ctx *x, const char *driver, const struct vmac_deploy_upload *u,
                 struct vmac_deploy_result *out)
{
	struct vmac_bundle *b = NULL;
	struct vmac_driver_upload up;
	char err[VMAC_EVENT_TEXT], *data = NULL;
	size_t len;
	int rc;

	memset(out, 0, sizeof(*out));
	/* A bundle of driver, signed as the host needs (checked before any of
	 * it runs, even sandboxed), that compiles: off the bus thread and
	 * before the lock. A Lua text alone is compiled to learn its version,
	 * so it is never taken where a signature counts. */
	if (!vmac_bundle_is_archive(u->data, u->len) && (u->sig || (x->trust && x->trust->require))) {
		refuse(out, u->sig ? -VMAC_ESIGMETA : -VMAC_ESIGMISSING,
		       "a driver's Lua text alone cannot be checked against a signature: make a bundle (vmac bundle), "
		       "sign that, and send it");
		return;
	}
	if ((rc = vmac_bundle_of_data(x->cfg, driver, u->data, u->len, &b, err, sizeof(err))) != 0 ||
	    (rc = deploy_check_signature(x->trust, b, u->data, u->len, u->sig, u->siglen, out->signer, err,
	                                 sizeof(err))) != 0 ||
	    (rc = compiles(x, b, err, sizeof(err))) != 0) {
		refuse(out, rc, err);
		vmac_bundle_free(b);
		return;
	}
	snprintf(out->version, sizeof(out->version), "%s", b->version);
	out->counter = b->counter;
	/* An archive is kept as it came (its hash is what was signed); a Lua
	 * text as the bundle it makes. */
	if (!vmac_bundle_is_archive(u->data, u->len) &&
	    (rc = vmac_bundle_write(b, &data, &len, err, sizeof(err))) != 0) {
		refuse(out, rc, err);
		vmac_bundle_free(b);
		return;
	}
	up = (struct vmac_driver_upload){driver,
	                                 b->version,
	                                 data ? data : u->data,
	                                 data ? len : u->len,
	                                 b->counter,
	                                 out->signer[0] ? out->signer : NULL,
	                                 u->by,
	                                 "upload",
	                                 NULL};
	vmac_bundle_hash(up.data, up.len, out->hash);

	pthread_mutex_lock(&deploy_lock);
	if (version_rules(x, b, out->hash, u->force, out) == 0) {
		up.note = out->note[0] ? out->note : NULL;
		put_in_place(x, driver, b, &up, u->probation_ms, out);
	}
	pthread_mutex_unlock(&deploy_lock);
	vmac_bundle_free(b);
	free(data);
}

void vmac_deploy_activate(const struct vmac_deploy_ctx *x, const char *driver, int64_t id, const char *by,
                          unsigned probation_ms, struct vmac_deploy_result *out)
{
	struct vmac_driver_version v;
	struct vmac_bundle *b = NULL;
	struct vmac_driver_upload up;
	char *data = NULL, err[VMAC_EVENT_TEXT];
	size_t len = 0;
	int rc;

	memset(out, 0, sizeof(*out));
	pthread_mutex_lock(&deploy_lock);
	rc = vmac_store_driver_get(x->store, id, &v, &data, &len, err, sizeof(err));
	if (rc == 1 && strcmp(v.driver, driver) != 0)
		rc = 0;
	if (rc < 0) {
		store_failed(out, rc, err);
	} else if (rc == 0) {
		out->status = 404;
		snprintf(out->error, sizeof(out->error), "driver %s has no version %lld (vmac drivers %s lists them)",
		         driver, (long long)id, driver);
	} else if ((rc = vmac_bundle_of_data(x->cfg, driver, data, len, &b, err, sizeof(err))) != 0) {
		refuse(out, rc, err);
	} else {
		b->counter = v.counter;
		snprintf(out->version, sizeof(out->version), "%s", b->version);
		snprintf(out->signer, sizeof(out->signer), "%s", v.signer);
		snprintf(out->hash, sizeof(out->hash), "%s", v.hash);
		out->counter = v.counter;
		up = (struct vmac_driver_upload){driver, v.version, data, len, v.counter, v.signer[0] ? v.signer : NULL,
		                                 by,     v.origin,  NULL};
		if (version_rules(x, b, v.hash, 1, out) == 0)
			put_in_place(x, driver, b, &up, probation_ms, out);
	}
	pthread_mutex_unlock(&deploy_lock);
	vmac_bundle_free(b);
	free(data);
}

void vmac_deploy_rollback(const struct vmac_deploy_ctx *x, const char *driver, const char *by,
                          struct vmac_deploy_result *out)
{
	char names[VMAC_DEPLOY_MACHINES][VMAC_NAME_MAX + 1], err[VMAC_EVENT_TEXT], why[120];
	int switched[VMAC_DEPLOY_MACHINES], n, rc;
	struct vmac_driver_version cur, target;
	struct vmac_bundle *b = NULL;

	memset(out, 0, sizeof(*out));
	pthread_mutex_lock(&deploy_lock);
	rc = vmac_store_driver_active(x->store, driver, &cur, NULL, NULL, err, sizeof(err));
	if (rc < 0) {
		store_failed(out, rc, err);
		goto done;
	}
	if (rc == 0 || !cur.previous) {
		out->status = 409;
		out->code = -VMAC_EREFUSED;
		snprintf(out->error, sizeof(out->error), "driver %s has no earlier version that ran to go back to%s%s",
		         driver, rc ? ": version " : "", rc ? cur.version : "");
		goto done;
	}
	rc = stored_bundle(x, driver, cur.previous, &target, &b, err, sizeof(err));
	if (rc != 1) {
		store_failed(out, rc < 0 ? rc : -VMAC_ESTORE, rc < 0 ? err : "store: the previous version is missing");
		goto done;
	}
	b->counter = target.counter;
	snprintf(out->version, sizeof(out->version), "%s", target.version);
	snprintf(out->hash, sizeof(out->hash), "%s", target.hash);
	snprintf(out->signer, sizeof(out->signer), "%s", target.signer);
	out->counter = target.counter;
	n = machines_of(x, driver, names, VMAC_DEPLOY_MACHINES, out);
	if (n < 0)
		goto done;
	swap_all(x, driver, b, cur.previous, 0, names, n, switched, out);
	test_pause(driver);
	snprintf(why, sizeof(why), "rolled back by hand (token %s)", by);
	rc = vmac_store_driver_roll_back(x->store, driver, cur.id, why, err, sizeof(err));
	if (rc < 0) {
		store_failed(out, rc, err);
		goto done;
	}
	out->status = 200;
	out->id = cur.previous;
done:
	pthread_mutex_unlock(&deploy_lock);
	vmac_bundle_free(b);
}

int vmac_deploy_rolled_back(struct vmac_store *store, const char *driver, int64_t id, const char *why, char *err,
                            size_t errlen)
{
	int rc;
	pthread_mutex_lock(&deploy_lock);
	rc = vmac_store_driver_roll_back(store, driver, id, why, err, errlen);
	pthread_mutex_unlock(&deploy_lock);
	return rc;
}

/* The drivers whose folder this process has looked at (vmac_deploy_load):
 * once per driver while it runs. Under the deploy lock. */
#define FOLDERS_SEEN 256
static char folders_seen[FOLDERS_SEEN][VMAC_NAME_MAX + 1];
static int nfolders_seen;

static int folder_seen(const char *driver)
{
	int i;
	for (i = 0; i < nfolders_seen; i++)
		if (strcmp(folders_seen[i], driver) == 0)
			return 1;
	if (nfolders_seen < FOLDERS_SEEN)
		snprintf(folders_seen[nfolders_seen++], sizeof(folders_seen[0]), "%s", driver);
	return 0;
}

/* What the folder holds for driver, as a version: stored (origin folder)
 * and made active, when nothing is active or the active version came from
 * the folder and differs. 0 (*id the active version's, 0 when the store
 * keeps none), or < 0 with text. *drv: the folder's instance, loaded for
 * device, when the folder was read and its content is what is active now
 * (or, the store failing, nothing was); else NULL. Under the deploy lock. */
static int folder_version(struct vmac_store *store, const struct vmac_config *cfg, const char *driver,
                          const char *device, int active, const struct vmac_driver_version *v, int64_t *id,
                          struct vmac_driver **drv, char *text, size_t textlen)
{
	struct vmac_bundle *b;
	struct vmac_driver *d = NULL;
	struct vmac_driver_upload up;
	char *data = NULL, hash[65];
	size_t len;
	int rc;
	*id = active ? v->id : 0;
	*drv = NULL;
	if (active && (strcmp(v->origin, "folder") != 0 || folder_seen(driver)))
		return 0; /* an upload is active, or the folder was looked at already */
	if (!active)
		folder_seen(driver);
	if ((rc = vmac_folder_bundle(cfg, driver, device, &b, &d, text, textlen)) != 0)
		return active ? 0 : rc; /* a folder that no longer loads leaves the version that ran */
	if ((rc = vmac_bundle_write(b, &data, &len, text, textlen)) == 0) {
		vmac_bundle_hash(data, len, hash);
		if (!active || strcmp(hash, v->hash) != 0) {
			up = (struct vmac_driver_upload){driver, b->version, data,     len, 0,
			                                 NULL,   "folder",   "folder", NULL};
			if ((rc = vmac_store_driver_add(store, &up, id, text, textlen)) == 0)
				rc = vmac_store_driver_activate(store, driver, *id, text, textlen);
		}
	}
	if (rc == 0 || (!active && (rc == -VMAC_ESTORE || rc == -VMAC_ESTOREFULL)))
		*drv = d, d = NULL;
	vmac_driver_free(d);
	free(data);
	vmac_bundle_free(b);
	return rc;
}

void vmac_deploy_load(struct vmac_store *store, const struct vmac_config *cfg, const char *driver, const char *device,
                      void (*hand_over)(void *ctx, int rc, struct vmac_driver *drv, const char *text), void *ctx)
{
	struct vmac_driver_version v;
	struct vmac_driver *drv = NULL;
	struct vmac_bundle *b = NULL;
	char *data = NULL, text[VMAC_EVENT_TEXT] = "";
	size_t len = 0;
	int64_t id = 0;
	int rc;
	pthread_mutex_lock(&deploy_lock); /* waits for a deploy under way: see deploy_lock */
	if (!store) {
		rc = vmac_load_driver(cfg, driver, device, &drv, text, sizeof(text));
		goto out;
	}
	rc = vmac_store_driver_active(store, driver, &v, NULL, NULL, text, sizeof(text));
	if (rc >= 0) {
		int active = rc == 1;
		rc = folder_version(store, cfg, driver, device, active, &v, &id, &drv, text, sizeof(text));
		if (rc == -VMAC_ESTORE || rc == -VMAC_ESTOREFULL) {
			/* The store cannot keep the folder's version (a full disk): the
			 * machine runs anyway, the active version or the folder's as
			 * it is, unrecorded (drv, untagged). */
			if (!active) {
				rc = drv ? 0 : -EIO;
				goto out;
			}
			rc = 0, id = v.id;
		}
	}
	if (rc == 0 && drv) { /* the folder's, read just now: what is active */
		vmac_driver_set_tag(drv, id);
		goto out;
	}
	if (rc == 0 && id == 0)
		rc = -ENOENT;
	if (rc == 0 && (rc = vmac_store_driver_get(store, id, &v, &data, &len, text, sizeof(text))) == 1)
		rc = vmac_bundle_of_data(cfg, driver, data, len, &b, text, sizeof(text));
	else if (rc == 0)
		rc = -EIO;
	if (rc == 0 && (rc = vmac_load_driver_bundle(cfg, b, device, &drv, text, sizeof(text))) == 0)
		vmac_driver_set_tag(drv, id);
	if (rc == -VMAC_ESTORE || rc == -VMAC_ESTOREFULL)
		rc = -EIO;
out:
	free(data);
	vmac_bundle_free(b);
	hand_over(ctx, rc, drv, text);
	pthread_mutex_unlock(&deploy_lock);
}
