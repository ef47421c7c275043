/* The endpoints of drivers (docs/API.md "Drivers: hot reload"): the
 * versions kept, an upload (compiled and switched by core/reload/deploy.c),
 * activate, rollback, and a version's manifest for user interfaces. */
#include "http_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <jansson.h>
#include <microhttpd.h>
#include <sodium.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../common/addr.h"
#include "../common/errors.h"
#include "../loader/loader.h"
#include "../reload/deploy.h"
#include "console.h"
#include "ui_assets.h"

/* ---- drivers: versions, upload (hot reload), rollback ---- */

static json_t *version_json(const struct vmac_driver_version *v)
{
	return json_pack("{s:I, s:s, s:s, s:s, s:f, s:s, s:s, s:I, s:s, s:I, s:I, s:s, s:s}", "id", (json_int_t)v->id,
	                 "driver", v->driver, "version", v->version, "hash", v->hash, "deployed", v->deployed,
	                 "deployed_by", v->deployed_by, "state", v->state, "previous", (json_int_t)v->previous, "note",
	                 v->note, "size", (json_int_t)v->size, "counter", (json_int_t)v->counter, "signer", v->signer,
	                 "origin", v->origin);
}

/* The names of the tokens (id -> name, as JSON), that a version's
 * deployed_by_name says who deployed it. */
static void add_token_name(void *ctx, const struct vmac_token_info *t)
{
	if (t->name[0])
		json_object_set_new(ctx, t->id, json_string(t->name));
}

struct versions_ctx {
	json_t *list, *names;
};

static void append_version(void *ctx, const struct vmac_driver_version *v)
{
	struct versions_ctx *x = ctx;
	json_t *j = version_json(v);
	const char *name = json_string_value(json_object_get(x->names, v->deployed_by));
	json_object_set_new(j, "deployed_by_name", json_string(name ? name : ""));
	json_array_append_new(x->list, j);
}

/* GET /api/drivers and /api/drivers/NAME: the versions kept. */
enum MHD_Result http_driver_versions(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *driver = k->route.name[0] ? k->route.name : NULL;
	char err[512];
	json_t *list = json_array(), *body;
	struct versions_ctx x = {list, json_object()};
	struct vmac_driver_version active;
	int rc;
	vmac_token_list(h->store, add_token_name, x.names, err, sizeof(err)); /* none: ids only */
	rc = vmac_store_driver_list(h->store, driver, append_version, &x, err, sizeof(err));
	json_decref(x.names);
	if (rc < 0) {
		json_decref(list);
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body(err));
	}
	if (!driver)
		return http_reply(c, MHD_HTTP_OK, json_pack("{s:o}", "versions", list));
	rc = vmac_store_driver_active(h->store, driver, &active, NULL, NULL, err, sizeof(err));
	if (rc < 0) {
		json_decref(list);
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body(err));
	}
	body = json_pack("{s:s, s:I, s:o}", "driver", driver, "active", (json_int_t)(rc == 1 ? active.id : 0),
	                 "versions", list);
	return http_reply(c, MHD_HTTP_OK, body);
}

static enum MHD_Result deploy_reply(struct MHD_Connection *c, const char *driver, const struct vmac_deploy_result *r,
                                    double probation_s)
{
	json_t *machines = json_array(), *body;
	int i;
	for (i = 0; i < r->nmachines; i++)
		json_array_append_new(machines, json_pack("{s:s, s:b, s:s}", "device", r->machines[i].device, "ok",
		                                          r->machines[i].ok, "text", r->machines[i].text));
	if (r->status != 200) {
		body = json_pack("{s:s, s:s, s:o}", "error", r->error, "code",
		                 r->code ? vmac_err_name(r->code) : "failed", "machines", machines);
		return http_reply(c, (unsigned)r->status, body);
	}
	body = json_pack("{s:b, s:s, s:I, s:s, s:s, s:I, s:s, s:b, s:s, s:f, s:o}", "ok", 1, "driver", driver, "id",
	                 (json_int_t)r->id, "version", r->version, "hash", r->hash, "counter", (json_int_t)r->counter,
	                 "signer", r->signer, "unchanged", r->unchanged, "note", r->note, "probation_s", probation_s,
	                 "machines", machines);
	return http_reply(c, MHD_HTTP_OK, body);
}

/* The id of the token a request was authorized by ("vmac_ID_..."). */
static void token_id(struct MHD_Connection *c, char *id, size_t len)
{
	const char *auth = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
	snprintf(id, len, "%.*s", VMAC_TOKEN_ID_LEN, auth && strlen(auth) > 12 ? auth + 12 : "?");
}

/* ?probation=S into *ms (default: the host's reload_probation_s): 0, or -1
 * with the 400 answer queued into *ret. */
static int probation_arg(struct vmac_http *h, struct MHD_Connection *c, unsigned *ms, double *s, enum MHD_Result *ret)
{
	const char *arg = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "probation");
	if (http_parse_probation(arg, h->cfg.reload_probation_s, ms, s) != 0) {
		*ret = http_reply(c, MHD_HTTP_BAD_REQUEST, http_error_body("probation must be seconds, 0..86400"));
		return -1;
	}
	return 0;
}

/* What a deploy request asks: an upload (its bundle, signature and
 * --force), a version to activate (id) or a rollback, with its probation.
 * kind indexes h->deploys (GET /metrics). */
struct deploy_ask {
	enum { ASK_UPLOAD, ASK_ACTIVATE, ASK_ROLLBACK } kind;
	struct vmac_deploy_upload up;
	long long id;
	double probation_s;
};

/* Run a deploy request for driver and answer it (the result is large: on
 * the heap, not the connection thread's stack). */
static enum MHD_Result deploy_and_reply(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k,
                                        struct deploy_ask *a)
{
	const char *driver = k->route.name;
	struct vmac_deploy_ctx x = {h->bus, h->store, &h->cfg, &h->trust};
	struct vmac_deploy_result *r = malloc(sizeof(*r));
	char by[VMAC_TOKEN_ID_LEN + 1];
	enum MHD_Result ret;
	if (!r)
		return http_reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, http_error_body("out of memory"));
	token_id(c, by, sizeof(by));
	a->up.by = by;
	switch (a->kind) {
	case ASK_UPLOAD: vmac_deploy(&x, driver, &a->up, r); break;
	case ASK_ACTIVATE: vmac_deploy_activate(&x, driver, a->id, by, a->up.probation_ms, r); break;
	case ASK_ROLLBACK: vmac_deploy_rollback(&x, driver, by, r); break;
	}
	atomic_fetch_add(&h->deploys[a->kind][r->status == 200 ? 0 : r->status < 500 ? 1 : 2], 1);
	if (r->version[0]) /* the audit trail says which version, its counter and signer */
		http_audit_detail(k, "%s %s (id %lld, counter %llu, %s%s%s)", driver, r->version, (long long)r->id,
		                  (unsigned long long)r->counter, r->signer[0] ? "signed by " : "unsigned", r->signer,
		                  r->unchanged ? ", unchanged"
		                  : r->note[0] ? ", --force"
		                               : "");
	ret = deploy_reply(c, driver, r, a->probation_s);
	free(r);
	return ret;
}

/* The Vmac-Signature header: base64 of a .minisig file's text, decoded
 * into sig. 0 (*len 0: none), or -1 (not base64, too long). */
static int signature_header(struct MHD_Connection *c, char *sig, size_t max, size_t *len)
{
	const char *v = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Vmac-Signature");
	*len = 0;
	if (!v || !v[0])
		return 0;
	return sodium_base642bin((unsigned char *)sig, max, v, strlen(v), " ", len, NULL,
	                         sodium_base64_VARIANT_ORIGINAL) == 0
	           ? 0
	           : -1;
}

/* POST /api/drivers/NAME[?probation=S][&force=1], the body a bundle (or a
 * driver's Lua text), its signature in the Vmac-Signature header. */
enum MHD_Result http_driver_upload(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct deploy_ask a;
	const char *force = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "force");
	char sig[VMAC_MINISIGN_SIG_MAX];
	enum MHD_Result ret;
	memset(&a, 0, sizeof(a));
	a.kind = ASK_UPLOAD;
	if (k->too_big)
		return http_reply(c, MHD_HTTP_CONTENT_TOO_LARGE, http_error_body("a bundle is at most 4 MiB"));
	if (!k->len)
		return http_reply(
		    c, MHD_HTTP_BAD_REQUEST,
		    http_error_body("the request body must be a bundle (vmac bundle) or a driver's Lua text"));
	if (signature_header(c, sig, sizeof(sig), &a.up.siglen) != 0)
		return http_reply(c, MHD_HTTP_BAD_REQUEST,
		                  http_error_body("Vmac-Signature must be the .minisig file in base64, at most 4 KiB"));
	if (probation_arg(h, c, &a.up.probation_ms, &a.probation_s, &ret) != 0)
		return ret;
	a.up.data = k->body;
	a.up.len = k->len;
	a.up.sig = a.up.siglen ? sig : NULL;
	a.up.force = force && (strcmp(force, "1") == 0 || strcmp(force, "true") == 0);
	return deploy_and_reply(h, c, k, &a);
}

/* POST /api/drivers/NAME/activate?id=N[&probation=S] */
enum MHD_Result http_driver_activate(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct deploy_ask a;
	const char *id_s = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "id");
	enum MHD_Result ret;
	memset(&a, 0, sizeof(a));
	a.kind = ASK_ACTIVATE;
	if (http_parse_id(id_s, &a.id) != 0)
		return http_reply(c, MHD_HTTP_BAD_REQUEST,
		                  http_error_body("id must be a version's id (vmac drivers lists them)"));
	if (probation_arg(h, c, &a.up.probation_ms, &a.probation_s, &ret) != 0)
		return ret;
	return deploy_and_reply(h, c, k, &a);
}

/* POST /api/drivers/NAME/rollback */
enum MHD_Result http_driver_rollback(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct deploy_ask a;
	memset(&a, 0, sizeof(a));
	a.kind = ASK_ROLLBACK;
	return deploy_and_reply(h, c, k, &a);
}

/* GET /api/drivers/NAME/manifest?version=V: a loaded version's declarations. */
enum MHD_Result http_driver_manifest(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *driver = k->route.name;
	const char *version = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "version");
	char *json = version ? vmac_loaded_manifest(driver, version) : NULL;
	json_t *body;
	(void)h;
	if (!version)
		return http_reply(c, MHD_HTTP_BAD_REQUEST,
		                  http_error_body("version is needed: ?version=V (a device's driver_version)"));
	if (!json)
		return http_reply(c, MHD_HTTP_NOT_FOUND,
		                  http_error_body("that driver version has not been loaded on this host"));
	body = http_manifest_json(json);
	free(json);
	return body ? http_reply(c, MHD_HTTP_OK, body)
	            : http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body("bad manifest"));
}
