/* The HTTP server (see http.h): libmicrohttpd with its own threads, TLS
 * when configured, bearer tokens checked against the store (guard.c: failed
 * attempts locked out, a request's deadlines), and every request handed to the
 * handler its route names (docs/API.md; the routes are HTTP_ROUTES in
 * api_request.h): the web UI's files, the health check, GET /api and
 * whoami here, the others in api_devices.c, api_drivers.c, api_events.c,
 * api_recordings.c, api_site.c, history.c and api_metrics.c (GET /metrics, and its
 * listener without a token). Every answer is counted by its status code
 * when it ends (GET /metrics shows them), and every request that changes
 * something, or is refused its token, is in the audit trail (audit.c).
 * http_internal.h holds what they share. */
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
#include "../common/file.h"
#include "../loader/loader.h"
#include "../reload/deploy.h"
#include "console.h"
#include "ui_assets.h"

double http_mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* The "error" of the last answer of 400 and up this thread queued
 * (http_last_error). */
static _Thread_local char last_error[240];

/* Queue code with body as JSON (consumed) and one extra header if given. */
enum MHD_Result http_reply_header(struct MHD_Connection *c, unsigned code, json_t *body, const char *header,
                                  const char *value)
{
	const char *error = code >= 400 ? json_string_value(json_object_get(body, "error")) : NULL;
	char *text = body ? json_dumps(body, JSON_COMPACT) : NULL;
	struct MHD_Response *r;
	enum MHD_Result ret;
	if (error)
		snprintf(last_error, sizeof(last_error), "%s", error);
	json_decref(body);
	if (!text) {
		static char oom[] = "{\"error\":\"out of memory\"}";
		r = MHD_create_response_from_buffer(sizeof(oom) - 1, oom, MHD_RESPMEM_PERSISTENT);
		code = MHD_HTTP_INTERNAL_SERVER_ERROR;
	} else {
		r = MHD_create_response_from_buffer(strlen(text), text, MHD_RESPMEM_MUST_FREE);
	}
	if (!r)
		return MHD_NO;
	MHD_add_response_header(r, "Content-Type", "application/json");
	MHD_add_response_header(r, "Cache-Control", "no-store");
	if (header)
		MHD_add_response_header(r, header, value);
	ret = MHD_queue_response(c, code, r);
	MHD_destroy_response(r);
	return ret;
}

enum MHD_Result http_reply(struct MHD_Connection *c, unsigned code, json_t *body)
{
	return http_reply_header(c, code, body, NULL, NULL);
}

json_t *http_error_body(const char *msg)
{
	return json_pack("{s:s}", "error", msg);
}

const char *http_last_error(void)
{
	return last_error;
}

void http_last_error_clear(void)
{
	last_error[0] = 0;
}

void http_count_answer(struct vmac_http *h, struct MHD_Connection *c)
{
	const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_HTTP_STATUS);
	if (ci && ci->http_status >= HTTP_CODE_FIRST && ci->http_status < HTTP_CODE_FIRST + HTTP_CODES)
		atomic_fetch_add(&h->answered[ci->http_status - HTTP_CODE_FIRST], 1);
}

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls, enum MHD_RequestTerminationCode why)
{
	struct conn *k = *con_cls;
	(void)why;
	http_count_answer(cls, c);
	http_guard_phase(c, cls, GUARD_IDLE); /* kept alive: the next request's deadline starts at its first byte */
	if (k) {
		free(k->body);
		free(k);
	}
	*con_cls = NULL;
}

/* A Server-Sent Events answer whose bytes come from read(cls); cls is
 * freed with done(cls) when the stream ends, or now if it cannot start. */
enum MHD_Result http_stream_response(struct MHD_Connection *c, MHD_ContentReaderCallback read, void *cls,
                                     MHD_ContentReaderFreeCallback done)
{
	struct MHD_Response *r = MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 16384, read, cls, done);
	enum MHD_Result ret;
	if (!r) {
		done(cls);
		return MHD_NO;
	}
	MHD_add_response_header(r, "Content-Type", "text/event-stream");
	MHD_add_response_header(r, "Cache-Control", "no-store");
	ret = MHD_queue_response(c, MHD_HTTP_OK, r);
	MHD_destroy_response(r);
	return ret;
}

/* GET / and /ui/FILE: the web UI's files (docs/UI.md), from the binary. */
enum MHD_Result http_ui(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *name = k->route.file ? k->route.file : "index.html";
	const struct vmac_ui_asset *a;
	struct MHD_Response *r;
	enum MHD_Result ret;
	(void)h;
	for (a = vmac_ui_assets; a->name && strcmp(a->name, name) != 0; a++)
		;
	if (!a->name)
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body("no such file of the web UI"));
	r = MHD_create_response_from_buffer(a->len, (void *)a->data, MHD_RESPMEM_PERSISTENT);
	if (!r)
		return MHD_NO;
	MHD_add_response_header(r, "Content-Type", a->content_type);
	MHD_add_response_header(r, "Cache-Control", "no-cache");
	MHD_add_response_header(r, "X-Content-Type-Options", "nosniff");
	MHD_add_response_header(r, "Content-Security-Policy",
	                        "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'");
	ret = MHD_queue_response(c, MHD_HTTP_OK, r);
	MHD_destroy_response(r);
	return ret;
}

/* GET /api/health */
enum MHD_Result http_health(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	(void)h;
	(void)k;
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:b, s:s}", "ok", 1, "version", VMAC_VERSION_STRING));
}

/* GET /api: the path of every endpoint under /api/, once each, in the
 * order of HTTP_ROUTES. */
enum MHD_Result http_index(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	json_t *paths = json_array();
	int i, j;
	(void)h;
	(void)k;
	for (i = 0; i < HTTP_ROUTE_COUNT; i++) {
		const char *p = http_routes[i].pattern;
		for (j = 0; j < i && strcmp(http_routes[j].pattern, p) != 0; j++)
			;
		if (j == i && strncmp(p, "/api/", 5) == 0)
			json_array_append_new(paths, json_string(p));
	}
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:s, s:o}", "vmacd", VMAC_VERSION_STRING, "endpoints", paths));
}

/* GET /api/whoami */
enum MHD_Result http_whoami(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	(void)h;
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:s}", "scope", vmac_scope_name(k->scope)));
}

#define HTTP_ROUTE_HANDLER(endpoint, method, pattern, scope, audit, handler) [endpoint] = handler,

/* The handler of each row of HTTP_ROUTES, indexed as http_routes[]. */
static http_handler *const handlers[] = {HTTP_ROUTES(HTTP_ROUTE_HANDLER)};

_Static_assert(sizeof(handlers) / sizeof(handlers[0]) == HTTP_ROUTE_COUNT, "a handler for every route");

/* The whole request is in: the answer its route's handler queues, or the
 * refusal of its method, token or path. */
static enum MHD_Result answer(struct vmac_http *h, struct MHD_Connection *c, struct conn *k, const char *method,
                              const char *url)
{
	enum MHD_Result ret;
	http_last_error_clear();
	http_route_find(method, url, &k->route); /* which endpoint, and the scope it needs (api_request.c) */
	if (k->route.endpoint == HTTP_BAD_METHOD)
		return http_reply(c, MHD_HTTP_METHOD_NOT_ALLOWED,
		                  http_error_body("only GET, HEAD and POST are used here"));
	k->audit->type = k->route.endpoint < HTTP_ROUTE_COUNT ? http_routes[k->route.endpoint].audit : NULL;
	if (k->route.need != VMAC_SCOPE_NONE && !(k->scope = http_authorized(h, c, k, &ret)))
		return ret;
	if (k->route.endpoint == HTTP_NOT_FOUND)
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body("no such endpoint (see docs/API.md)"));
	return handlers[k->route.endpoint](h, c, k);
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url, const char *method,
                                  const char *version, const char *upload_data, size_t *upload_size, void **con_cls)
{
	struct vmac_http *h = cls;
	struct conn *k = *con_cls;
	enum MHD_Result ret;
	(void)version;
	if (!k) { /* first call: headers only */
		k = calloc(1, sizeof(*k));
		if (!k)
			return MHD_NO;
		k->audit = &k->note;
		*con_cls = k;
		http_guard_phase(c, h, GUARD_BODY); /* the headers came in time; now the body's deadline */
		return MHD_YES;
	}
	if (*upload_size) {
		if (k->len + *upload_size > BODY_MAX) {
			k->too_big = 1;
		} else {
			char *b = realloc(k->body, k->len + *upload_size + 1);
			if (!b)
				return MHD_NO;
			memcpy(b + k->len, upload_data, *upload_size);
			k->body = b;
			k->len += *upload_size;
			b[k->len] = 0;
		}
		*upload_size = 0;
		return MHD_YES;
	}
	http_guard_phase(c, h, GUARD_ANSWERING); /* the whole request is in: no deadline while answering */
	ret = answer(h, c, k, method, url);
	http_audit_request(h, c, k, method, url); /* once, with the status just queued (audit.c) */
	return ret;
}

/* A PEM file's text (at most 64 KiB), or NULL with err. */
static char *read_pem(const char *path, const char *what, char *err, size_t errlen)
{
	char why[600];
	size_t n = 0;
	int code = 0;
	char *buf = vmac_read_file(path, 64 << 10, &n, why, sizeof(why), &code);
	if (!buf) {
		snprintf(err, errlen, "%s %s", what, why);
		return NULL;
	}
	if (n == 0 || !strstr(buf, "-----BEGIN ")) {
		snprintf(err, errlen, "%s %s: not a PEM file (or empty)", what, path);
		free(buf);
		return NULL;
	}
	return buf;
}

struct vmac_http *vmac_http_start(const char *listen, struct vmac_bus *bus, struct vmac_event_log *log,
                                  struct vmac_store *store, const struct vmac_config *cfg, char *err, size_t errlen)
{
	struct vmac_http *h;
	struct sockaddr_in sin;
	uint16_t port;
	const union MHD_DaemonInfo *info;

	memset(&sin, 0, sizeof(sin));
	sin.sin_family = AF_INET;
	if (vmac_addr_parse(listen, &sin.sin_addr, &port) != 0) {
		snprintf(err, errlen, "http '%s': expected IPv4ADDR:PORT, e.g. 127.0.0.1:8080", listen);
		return NULL;
	}
	sin.sin_port = htons(port);
	h = calloc(1, sizeof(*h));
	if (!h) {
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	h->bus = bus;
	h->log = log;
	h->store = store;
	h->cfg = *cfg;
	if (vmac_deploy_trust_load(cfg, &h->trust, err, errlen) != 0) {
		free(h);
		return NULL;
	}
	if (http_guard_start(h) != 0) {
		snprintf(err, errlen, "cannot start the API's guard thread");
		free(h);
		return NULL;
	}
	pthread_mutex_init(&h->status_lock, NULL);
	pthread_mutex_init(&h->live_lock, NULL);
	h->status.devices = calloc(cfg->max_devices, sizeof(*h->status.devices));
	h->status.slot_load = calloc(1u << cfg->max_level, sizeof(*h->status.slot_load));
	if (!h->status.devices || !h->status.slot_load || http_history_start(h) != 0) {
		snprintf(err, errlen, "out of memory, or cannot start the API's history thread");
		vmac_http_stop(h);
		return NULL;
	}
	if (cfg->tls_cert[0] || cfg->tls_key[0]) {
		if (!cfg->tls_cert[0] || !cfg->tls_key[0]) {
			snprintf(err, errlen, "TLS needs both tls_cert and tls_key (PEM files)");
			vmac_http_stop(h);
			return NULL;
		}
		if (!MHD_is_feature_supported(MHD_FEATURE_TLS)) {
			snprintf(err, errlen, "TLS: this libmicrohttpd was built without TLS support");
			vmac_http_stop(h);
			return NULL;
		}
		h->tls_cert = read_pem(cfg->tls_cert, "tls_cert", err, errlen);
		h->tls_key = h->tls_cert ? read_pem(cfg->tls_key, "tls_key", err, errlen) : NULL;
		if (!h->tls_key) {
			vmac_http_stop(h);
			return NULL;
		}
	}
	/* A thread per connection: an operator input waits for the bus thread
	 * without holding up other clients. */
	h->daemon = MHD_start_daemon(
	    MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_THREAD_PER_CONNECTION | MHD_USE_ERROR_LOG |
	        (h->tls_cert ? MHD_USE_TLS : 0),
	    0, NULL, NULL, on_request, h, MHD_OPTION_NOTIFY_COMPLETED, on_completed, h, MHD_OPTION_NOTIFY_CONNECTION,
	    http_guard_notify, h, MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&sin, MHD_OPTION_CONNECTION_TIMEOUT,
	    (unsigned)HTTP_IDLE_TIMEOUT_S, MHD_OPTION_CONNECTION_LIMIT, (unsigned)HTTP_CONNECTIONS_MAX,
	    MHD_OPTION_PER_IP_CONNECTION_LIMIT, (unsigned)cfg->http_connections_per_address,
	    /* the certificate and key, or nothing */
	    h->tls_cert ? MHD_OPTION_HTTPS_MEM_CERT : MHD_OPTION_END, h->tls_cert, MHD_OPTION_HTTPS_MEM_KEY, h->tls_key,
	    MHD_OPTION_END);
	if (!h->daemon) {
		snprintf(err, errlen, "cannot listen on %s (address in use, not an address of this machine%s)", listen,
		         h->tls_cert ? ", or a certificate and key that do not go together" : "");
		vmac_http_stop(h);
		return NULL;
	}
	info = MHD_get_daemon_info(h->daemon, MHD_DAEMON_INFO_BIND_PORT);
	h->port = info ? info->port : (unsigned)port;
	if (cfg->metrics_http[0] && http_metrics_listen(h, cfg->metrics_http, err, errlen) != 0) {
		vmac_http_stop(h);
		return NULL;
	}
	return h;
}

int vmac_http_tls(const struct vmac_http *h)
{
	return h->tls_cert != NULL;
}

unsigned vmac_http_port(const struct vmac_http *h)
{
	return h->port;
}

void vmac_http_set_site(struct vmac_http *h, struct vmac_site *site)
{
	atomic_store(&h->site, site);
}

void vmac_http_stop(struct vmac_http *h)
{
	if (!h)
		return;
	atomic_store(&h->stopping, 1); /* event streams end within SSE_WAIT_MS */
	if (h->metrics_daemon)
		MHD_stop_daemon(h->metrics_daemon);
	if (h->daemon)
		MHD_stop_daemon(h->daemon);
	http_history_stop(h); /* it uses the status copy and its lock */
	pthread_mutex_destroy(&h->status_lock);
	http_guard_stop(h);
	pthread_mutex_destroy(&h->live_lock);
	free(h->live_json);
	free(h->status.devices);
	free(h->status.slot_load);
	free(h->tls_cert);
	if (h->tls_key)
		sodium_memzero(h->tls_key, strlen(h->tls_key));
	free(h->tls_key);
	free(h);
}
