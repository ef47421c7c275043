/* See deploy.h. */
#include "deploy.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "loader.h"

#define SWAP_TIMEOUT_MS 2000 /* the bus thread takes a request within a tick */

static pthread_mutex_t deploy_lock = PTHREAD_MUTEX_INITIALIZER;

/* A store error as an HTTP status: a full disk is 507, the rest 500. */
static void store_failed(struct vmac_deploy_result *out, const char *err)
{
	out->status = strstr(err, "full") ? 507 : 500;
	snprintf(out->error, sizeof(out->error), "%s", err);
}

/* The names of the running machines of driver (their primary boards), at
 * most max. Returns how many. */
static int machines_of(const struct vmac_deploy_ctx *x, const char *driver, char (*names)[VMAC_NAME_MAX + 1],
                       int max)
{
	struct vmac_status st;
	int i, n = 0;
	memset(&st, 0, sizeof(st));
	st.devices = calloc(x->cfg->max_devices, sizeof(*st.devices));
	st.slot_load = calloc(1u << x->cfg->max_level, sizeof(*st.slot_load));
	if (st.devices && st.slot_load) {
		vmac_bus_status(x->bus, &st);
		for (i = 0; i < st.ndevices && n < max; i++) {
			const struct vmac_device_status *d = &st.devices[i];
			if (strcmp(d->driver, driver) == 0 && strcmp(d->state, "running") == 0 &&
			    strcmp(d->name, d->machine) == 0)
				snprintf(names[n++], VMAC_NAME_MAX + 1, "%s", d->name);
		}
	}
	free(st.devices);
	free(st.slot_load);
	return n;
}

/* Hand every running machine of driver a fresh instance of src (tagged
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
		int rc = -1;
		snprintf(r->device, sizeof(r->device), "%s", names[i]);
		switched[i] = 0;
		if ((src ? vmac_load_driver_source(x->cfg, driver, names[i], src, len, &drv, r->text, sizeof(r->text))
		         : vmac_load_driver(x->cfg, driver, names[i], &drv, r->text, sizeof(r->text))) == 0) {
			vmac_driver_set_tag(drv, tag);
			if (vmac_bus_request_swap(x->bus, names[i], drv, probation_ms, SWAP_TIMEOUT_MS, &rc, r->text,
			                          sizeof(r->text)) != 0)
				rc = -1;
			if (rc != 0)
				vmac_driver_free(drv);
		}
		if (rc == 0) {
			r->ok = switched[i] = 1;
		} else if (strstr(r->text, "is not running")) {
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
	int have_prev;

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
	have_prev = vmac_store_driver_active(x->store, driver, &prev, &prev_src, &prev_len, err, sizeof(err));
	if (have_prev < 0 || vmac_store_driver_add(x->store, driver, out->version, src, len, by, &id, err,
	                                           sizeof(err)) != 0) {
		store_failed(out, err);
		goto done;
	}
	n = machines_of(x, driver, names, VMAC_DEPLOY_MACHINES);
	refused = swap_all(x, driver, src, len, id, probation_ms, names, n, switched, out);
	if (refused == 0) {
		if (vmac_store_driver_activate(x->store, driver, id, err, sizeof(err)) != 0) {
			store_failed(out, err);
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
		if (swap_all(x, driver, have_prev == 1 ? prev_src : NULL, prev_len, have_prev == 1 ? prev.id : 0, 0, one, 1,
		             &sw, &back) != 0)
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
			store_failed(out, err);
		} else {
			out->status = 404;
			snprintf(out->error, sizeof(out->error), "driver %s has no version %lld (vmac drivers %s lists them)",
			         driver, (long long)id, driver);
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
		store_failed(out, err);
		goto done;
	}
	if (rc == 0) {
		out->status = 409;
		snprintf(out->error, sizeof(out->error), "driver %s runs its file: there is no earlier version to go back to",
		         driver);
		goto done;
	}
	if (cur.previous) {
		rc = vmac_store_driver_get(x->store, cur.previous, &target, &src, &len, err, sizeof(err));
		if (rc != 1) {
			store_failed(out, rc < 0 ? err : "store: the previous version is missing");
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
	n = machines_of(x, driver, names, VMAC_DEPLOY_MACHINES);
	swap_all(x, driver, src, len, cur.previous, 0, names, n, switched, out);
	snprintf(why, sizeof(why), "rolled back by hand (token %s)", by);
	rc = vmac_store_driver_roll_back(x->store, driver, cur.id, why, err, sizeof(err));
	if (rc < 0) {
		store_failed(out, err);
		goto done;
	}
	out->status = 200;
	out->id = cur.previous;
done:
	pthread_mutex_unlock(&deploy_lock);
	free(src);
}

int vmac_deploy_load(struct vmac_store *store, const struct vmac_config *cfg, const char *driver, const char *device,
                     struct vmac_driver **out, char *text, size_t textlen)
{
	struct vmac_driver_version v;
	char *src = NULL;
	size_t len = 0;
	int rc = store ? vmac_store_driver_active(store, driver, &v, &src, &len, text, textlen) : 0;
	if (rc < 0)
		return -EIO;
	if (rc == 0)
		return vmac_load_driver(cfg, driver, device, out, text, textlen);
	rc = vmac_load_driver_source(cfg, driver, device, src, len, out, text, textlen);
	free(src);
	if (rc == 0)
		vmac_driver_set_tag(*out, v.id);
	return rc;
}
