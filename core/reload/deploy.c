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

/* drv takes over machine `name` (vmac_bus_request_swap). A machine whose
 * boards are still registering refuses as not running: it is waited for
 * (it attaches with the version it was loaded with, then takes the new
 * one over like the others) while it is still a machine of driver, at most
 * two reply deadlines and a second (a board that does not answer REGISTER
 * is dropped within one). 0 switched; else not, text says why. */
static int swap_one(const struct vmac_deploy_ctx *x, const char *driver, const char *name, struct vmac_driver *drv,
                    unsigned probation_ms, char *text, size_t textlen)
{
	int64_t until = mono_ms() + 2 * (int64_t)x->cfg->reply_deadline_us / 1000 + 1000;
	int rc = -1;
	for (;;) {
		if (vmac_bus_request_swap(x->bus, name, drv, probation_ms, SWAP_TIMEOUT_MS, &rc, text, textlen) != 0)
			return rc;
		if (rc != -VMAC_ENOTRUNNING || mono_ms() > until || !still_a_machine(x, driver, name))
			return rc;
		usleep(ATTACH_POLL_US);
	}
}

/* Hand every machine of names a fresh instance of driver's src (tagged
 * tag; src NULL: the driver's file). Records each machine in out; returns
 * how many refused. switched[i] says which took it. */
static int swap_all(const struct vmac_deploy_ctx *x, const char *driver, const char *src, size_t len, int64_t tag,
                    unsigned probation_ms, char (*names)[VMAC_NAME_MAX + 1], int n, int *switched,
                    struct vmac_deploy_result *out)
{
	int i, refused = 0;
	out->nmachines = 0;
	for (i = 0; i < n; i++) {
		struct vmac_deploy_machine *r = &out->machines[out->nmachines++];
		struct vmac_driver *drv = NULL;
		int rc = -VMAC_EFAIL;
		snprintf(r->device, sizeof(r->device), "%s", names[i]);
		switched[i] = 0;
		if ((src ? vmac_load_driver_source(x->cfg, driver, names[i], src, len, &drv, r->text, sizeof(r->text))
		         : vmac_load_driver(x->cfg, driver, names[i], &drv, r->text, sizeof(r->text))) == 0) {
			vmac_driver_set_tag(drv, tag);
			rc = swap_one(x, driver, names[i], drv, probation_ms, r->text, sizeof(r->text));
			if (rc != 0 && rc != -VMAC_EDRIVER) /* EDRIVER: it stalled, and went with its worker */
				vmac_driver_free(drv);
		}
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

void vmac_deploy(const struct vmac_deploy_ctx *x, const char *driver, const char *src, size_t len, const char *by,
                 unsigned probation_ms, struct vmac_deploy_result *out)
{
	char names[VMAC_DEPLOY_MACHINES][VMAC_NAME_MAX + 1], err[VMAC_EVENT_TEXT];
	int switched[VMAC_DEPLOY_MACHINES], n, i, refused;
	struct vmac_driver *check = NULL;
	struct vmac_driver_version prev, cur;
	char *prev_src = NULL;
	size_t prev_len = 0;
	int64_t id;
	int have_prev, rc;

	memset(out, 0, sizeof(*out));
	/* Compile it and check its manifest, off the bus thread. */
	if (vmac_load_driver_source(x->cfg, driver, "(upload)", src, len, &check, err, sizeof(err)) != 0) {
		out->status = 400;
		snprintf(out->error, sizeof(out->error), "%s", err);
		return;
	}
	snprintf(out->version, sizeof(out->version), "%s", vmac_driver_version(check));
	vmac_driver_free(check);

	pthread_mutex_lock(&deploy_lock);
	n = machines_of(x, driver, names, VMAC_DEPLOY_MACHINES, out);
	if (n < 0)
		goto done;
	have_prev = rc = vmac_store_driver_active(x->store, driver, &prev, &prev_src, &prev_len, err, sizeof(err));
	if (rc < 0 ||
	    (rc = vmac_store_driver_add(x->store, driver, out->version, src, len, by, &id, err, sizeof(err))) != 0) {
		store_failed(out, rc, err);
		goto done;
	}
	refused = swap_all(x, driver, src, len, id, probation_ms, names, n, switched, out);
	test_pause(driver);
	if (refused == 0) {
		if ((rc = vmac_store_driver_activate(x->store, driver, id, err, sizeof(err))) != 0) {
			store_failed(out, rc, err);
			goto done;
		}
		out->status = 200;
		out->id = id;
		if (vmac_store_driver_get(x->store, id, &cur, NULL, NULL, err, sizeof(err)) == 1)
			snprintf(out->hash, sizeof(out->hash), "%s", cur.hash);
		goto done;
	}
	/* Some machine would not take it: one version everywhere, so the ones
	 * that switched go back to what ran before. */
	for (i = 0; i < n; i++) {
		struct vmac_deploy_result back;
		char one[1][VMAC_NAME_MAX + 1];
		int sw;
		if (!switched[i])
			continue;
		memcpy(one[0], names[i], sizeof(one[0]));
		memset(&back, 0, sizeof(back));
		if (swap_all(x, driver, have_prev == 1 ? prev_src : NULL, prev_len, have_prev == 1 ? prev.id : 0, 0,
		             one, 1, &sw, &back) != 0)
			snprintf(out->machines[i].text, sizeof(out->machines[i].text),
			         "took the new version, but going back failed: %s", back.machines[0].text);
		else
			snprintf(out->machines[i].text, sizeof(out->machines[i].text),
			         "took the new version and went back (another machine refused it)");
		out->machines[i].ok = 0;
	}
	for (i = 0; i < out->nmachines && out->machines[i].ok; i++)
		;
	snprintf(out->error, sizeof(out->error), "version %s of %s was refused: %s", out->version, driver,
	         i < out->nmachines ? out->machines[i].text : "a machine refused it");
	vmac_store_driver_refuse(x->store, id, out->error, err, sizeof(err));
	out->status = 409;
	out->id = have_prev == 1 ? prev.id : 0;
done:
	pthread_mutex_unlock(&deploy_lock);
	free(prev_src);
}

void vmac_deploy_activate(const struct vmac_deploy_ctx *x, const char *driver, int64_t id, const char *by,
                          unsigned probation_ms, struct vmac_deploy_result *out)
{
	struct vmac_driver_version v;
	char *src = NULL, err[VMAC_EVENT_TEXT];
	size_t len = 0;
	int rc = vmac_store_driver_get(x->store, id, &v, &src, &len, err, sizeof(err));
	if (rc != 1 || strcmp(v.driver, driver) != 0) {
		memset(out, 0, sizeof(*out));
		if (rc < 0) {
			store_failed(out, rc, err);
		} else {
			out->status = 404;
			snprintf(out->error, sizeof(out->error),
			         "driver %s has no version %lld (vmac drivers %s lists them)", driver, (long long)id,
			         driver);
		}
		free(src);
		return;
	}
	vmac_deploy(x, driver, src, len, by, probation_ms, out);
	free(src);
}

void vmac_deploy_rollback(const struct vmac_deploy_ctx *x, const char *driver, const char *by,
                          struct vmac_deploy_result *out)
{
	char names[VMAC_DEPLOY_MACHINES][VMAC_NAME_MAX + 1], err[VMAC_EVENT_TEXT], why[120];
	int switched[VMAC_DEPLOY_MACHINES], n, rc;
	struct vmac_driver_version cur, target;
	char *src = NULL;
	size_t len = 0;

	memset(out, 0, sizeof(*out));
	pthread_mutex_lock(&deploy_lock);
	rc = vmac_store_driver_active(x->store, driver, &cur, NULL, NULL, err, sizeof(err));
	if (rc < 0) {
		store_failed(out, rc, err);
		goto done;
	}
	if (rc == 0) {
		out->status = 409;
		snprintf(out->error, sizeof(out->error),
		         "driver %s runs its file: there is no earlier version to go back to", driver);
		goto done;
	}
	if (cur.previous) {
		rc = vmac_store_driver_get(x->store, cur.previous, &target, &src, &len, err, sizeof(err));
		if (rc != 1) {
			store_failed(out, rc, rc < 0 ? err : "store: the previous version is missing");
			goto done;
		}
		snprintf(out->version, sizeof(out->version), "%s", target.version);
		snprintf(out->hash, sizeof(out->hash), "%s", target.hash);
	} else {
		struct vmac_driver *check = NULL;
		if (vmac_load_driver(x->cfg, driver, "(rollback)", &check, err, sizeof(err)) != 0) {
			out->status = 409;
			snprintf(out->error, sizeof(out->error), "going back to the driver's file: %s", err);
			goto done;
		}
		snprintf(out->version, sizeof(out->version), "%s", vmac_driver_version(check));
		vmac_driver_free(check);
	}
	n = machines_of(x, driver, names, VMAC_DEPLOY_MACHINES, out);
	if (n < 0)
		goto done;
	swap_all(x, driver, src, len, cur.previous, 0, names, n, switched, out);
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
	free(src);
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

void vmac_deploy_load(struct vmac_store *store, const struct vmac_config *cfg, const char *driver, const char *device,
                      void (*hand_over)(void *ctx, int rc, struct vmac_driver *drv, const char *text), void *ctx)
{
	struct vmac_driver_version v;
	struct vmac_driver *drv = NULL;
	char *src = NULL, text[VMAC_EVENT_TEXT] = "";
	size_t len = 0;
	int rc;
	pthread_mutex_lock(&deploy_lock); /* waits for a deploy under way: see deploy_lock */
	rc = store ? vmac_store_driver_active(store, driver, &v, &src, &len, text, sizeof(text)) : 0;
	if (rc < 0) {
		rc = -EIO;
	} else if (rc == 0) {
		rc = vmac_load_driver(cfg, driver, device, &drv, text, sizeof(text));
	} else {
		rc = vmac_load_driver_source(cfg, driver, device, src, len, &drv, text, sizeof(text));
		if (rc == 0)
			vmac_driver_set_tag(drv, v.id);
	}
	free(src);
	hand_over(ctx, rc, drv, text);
	pthread_mutex_unlock(&deploy_lock);
}
