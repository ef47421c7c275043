/* HTTP status API on libmicrohttpd (internal polling thread) with jansson
 * for JSON: see http.h and docs/API.md. */
#include "http.h"

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
#include "../reload/deploy.h"
#include "../reload/loader.h"
#include "console.h"
#include "ui_assets.h"

#define VMAC_VERSION_STRING "0.1.0"
#define STATUS_EVENTS 20

/* Failed attempts: at most FAIL_LIMIT per client address in FAIL_WINDOW_S;
 * past that, every request from there gets 429 until the window ends. The
 * table is small and reused oldest first: it only has to slow a guesser
 * down (a token has 256 random bits), not remember everyone. */
#define FAIL_LIMIT 10
#define FAIL_WINDOW_S 60.0
#define FAIL_CLIENTS 64

struct fail_count {
	struct in_addr addr;
	double window_start;
	unsigned fails;
};

struct vmac_http {
	struct MHD_Daemon *daemon;
	struct vmac_bus *bus;
	struct vmac_event_log *log;
	struct vmac_config cfg;
	pthread_mutex_t status_lock; /* guards the status copy below */
	struct vmac_status status;
	unsigned port;
	struct vmac_store *store;
	char *tls_cert, *tls_key;   /* PEM texts while the daemon runs (TLS) */
	pthread_mutex_t live_lock;  /* the live streams' shared message: */
	double live_at;             /* when it was built */
	char *live_json;            /* the newest status as JSON */
	_Atomic int stopping;       /* event streams end */
	pthread_mutex_t fails_lock; /* connection threads share the table */
	struct fail_count fails[FAIL_CLIENTS];
};

static double mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

static json_t *bools(uint32_t bits, int n)
{
	json_t *a = json_array();
	int i;
	for (i = 0; i < n; i++)
		json_array_append_new(a, json_boolean((bits >> i) & 1));
	return a;
}

static json_t *value_json(const struct vmac_value *v)
{
	switch (v->type) {
	case VMAC_VALUE_NUMBER: return json_real(v->number);
	case VMAC_VALUE_BOOL: return json_boolean(v->number != 0);
	case VMAC_VALUE_STRING: return json_string(v->str);
	default: return json_null();
	}
}

static json_t *device_json(const struct vmac_device_status *d)
{
	json_t *o, *vars = json_object(), *params = json_object();
	int i;
	for (i = 0; i < d->nvars; i++)
		json_object_set_new(vars, d->vars[i].name, value_json(&d->vars[i].value));
	for (i = 0; i < d->nparams; i++)
		json_object_set_new(params, d->params[i].name, value_json(&d->params[i].value));
	json_t *in =
	    json_pack("{s:o, s:[i,i], s:I}", "digital", bools(d->inputs.digital, VMAC_DIGITAL_INPUTS), "analog",
	              (int)d->inputs.analog[0], (int)d->inputs.analog[1], "encoder", (json_int_t)d->inputs.encoder);
	json_t *out = json_pack("{s:o, s:i}", "digital", bools(d->outputs.digital, VMAC_DIGITAL_OUTPUTS), "pwm",
	                        (int)d->outputs.pwm);
	o = json_pack("{s:s, s:s, s:s, s:s, s:s, s:I, s:I, s:I, s:I, s:I, s:I, s:o, s:o, s:o, s:I}", "name", d->name,
	              "driver", d->driver, "driver_version", d->driver_version, "state", d->state, "address",
	              d->address, "id", (json_int_t)d->id, "major", (json_int_t)d->major, "minor", (json_int_t)d->minor,
	              "period_us", (json_int_t)d->period_us, "misses", (json_int_t)d->misses, "served",
	              (json_int_t)d->served, "inputs", in, "outputs", out, "variables", vars, "driver_memory",
	              (json_int_t)d->driver_memory);
	if (!o)
		return NULL;
	json_object_set_new(o, "level", d->scheduled || d->level ? json_integer(d->level) : json_null());
	json_object_set_new(o, "slot", d->scheduled ? json_integer(d->slot) : json_null());
	json_object_set_new(o, "slice", d->scheduled ? json_integer(d->slice) : json_null());
	json_object_set_new(o, "machine", d->machine[0] ? json_string(d->machine) : json_null());
	json_object_set_new(o, "note", d->note[0] ? json_string(d->note) : json_null());
	json_object_set_new(o, "params", params);
	return o;
}

static json_t *status_json(struct vmac_http *h)
{
	struct vmac_status *s = &h->status;
	struct vmac_event ev[STATUS_EVENTS];
	json_t *root, *devices, *events, *reasons;
	int i, n;

	pthread_mutex_lock(&h->status_lock);
	vmac_bus_status(h->bus, s);
	devices = json_array();
	for (i = 0; i < s->ndevices; i++)
		json_array_append_new(devices, device_json(&s->devices[i]));
	reasons = json_object();
	for (i = 0; i < VMAC_BAD_REASONS; i++)
		json_object_set_new(reasons, vmac_malformed_reason_names[i],
		                    json_integer((json_int_t)s->counters.malformed_by_reason[i]));
	root = json_pack(
	    "{s:s, s:f, s:{s:s, s:s, s:s, s:I, s:I, s:I, s:I, s:I, s:b}, s:o,"
	    " s:{s:I, s:I, s:{s:I, s:I, s:I, s:I}},"
	    " s:{s:I, s:o, s:I, s:I, s:I, s:I, s:I, s:I}}",
	    "version", VMAC_VERSION_STRING, "uptime_s",
	    s->started_ns ? (double)(s->time_ns - s->started_ns) / 1e9 : 0.0, "bus", "group", h->cfg.bus, "iface",
	    h->cfg.iface, "host_addr", s->host_addr, "slot_us", (json_int_t)vmac_config_slot_us(&h->cfg),
	    "reply_deadline_us", (json_int_t)h->cfg.reply_deadline_us, "discovery_period_ms",
	    (json_int_t)h->cfg.discovery_period_ms, "watchdog_ms", (json_int_t)h->cfg.watchdog_ms, "miss_limit",
	    (json_int_t)h->cfg.miss_limit, "realtime", s->realtime, "devices", devices, "tick", "count",
	    (json_int_t)s->counters.ticks, "skipped", (json_int_t)s->counters.ticks_skipped, "lateness_us", "p50",
	    (json_int_t)vmac_hist_quantile(&s->lateness, 0.50), "p99",
	    (json_int_t)vmac_hist_quantile(&s->lateness, 0.99), "p999",
	    (json_int_t)vmac_hist_quantile(&s->lateness, 0.999), "max", (json_int_t)s->lateness.max_us, "counters",
	    "malformed_frames", (json_int_t)s->counters.malformed_frames, "malformed_by_reason", reasons,
	    "late_replies", (json_int_t)s->counters.late_replies, "misses", (json_int_t)s->counters.misses, "drops",
	    (json_int_t)s->counters.drops, "discoveries", (json_int_t)s->counters.discoveries, "announces",
	    (json_int_t)s->counters.announces, "events_lost", (json_int_t)s->counters.events_lost, "table_full",
	    (json_int_t)s->counters.table_full);
	if (root) {
		json_t *load = json_array();
		for (i = 0; i < (int)s->slots_per_block; i++)
			json_array_append_new(load, json_integer(s->slot_load[i]));
		json_object_set_new(json_object_get(root, "counters"), "schedule_full",
		                    json_integer((json_int_t)s->counters.schedule_full));
		json_object_set_new(
		    root, "schedule",
		    json_pack("{s:I, s:I, s:I, s:I, s:I, s:I, s:I, s:o}", "slices_per_slot",
		              (json_int_t)s->slices_per_slot, "slots_per_block", (json_int_t)s->slots_per_block,
		              "slot_us", (json_int_t)s->slot_us, "slice_us", (json_int_t)h->cfg.slice_us, "max_level",
		              (json_int_t)h->cfg.max_level, "capacity_used", (json_int_t)s->capacity_used,
		              "capacity_total", (json_int_t)s->capacity_total, "slot_load", load));
	}
	pthread_mutex_unlock(&h->status_lock);

	events = json_array();
	n = vmac_event_log_latest(h->log, ev, STATUS_EVENTS);
	for (i = 0; i < n; i++)
		json_array_append_new(events, json_pack("{s:I, s:f, s:s, s:s, s:s}", "seq", (json_int_t)ev[i].seq,
		                                        "time", (double)ev[i].time_ns / 1e9, "kind", ev[i].kind,
		                                        "device", ev[i].device, "text", ev[i].text));
	if (root)
		json_object_set_new(root, "events", events);
	else
		json_decref(events);
	return root;
}

/* Queue code with body as JSON (consumed) and one extra header if given. */
static enum MHD_Result reply_with(struct MHD_Connection *c, unsigned code, json_t *body, const char *header,
                                  const char *value)
{
	char *text = body ? json_dumps(body, JSON_COMPACT) : NULL;
	struct MHD_Response *r;
	enum MHD_Result ret;
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

static enum MHD_Result reply(struct MHD_Connection *c, unsigned code, json_t *body)
{
	return reply_with(c, code, body, NULL, NULL);
}

static json_t *error_body(const char *msg)
{
	return json_pack("{s:s}", "error", msg);
}

/* The failure record of the client's address (a new or the oldest slot). */
static struct fail_count *fails_of(struct vmac_http *h, struct MHD_Connection *c, double now)
{
	const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
	struct in_addr addr = {0};
	struct fail_count *oldest = &h->fails[0];
	int i;
	if (ci && ci->client_addr && ci->client_addr->sa_family == AF_INET)
		addr = ((const struct sockaddr_in *)ci->client_addr)->sin_addr;
	for (i = 0; i < FAIL_CLIENTS; i++) {
		struct fail_count *f = &h->fails[i];
		if (f->fails && f->addr.s_addr == addr.s_addr) {
			if (now - f->window_start >= FAIL_WINDOW_S)
				f->fails = 0, f->window_start = now;
			return f;
		}
		if (!f->fails || f->window_start < oldest->window_start)
			oldest = f;
	}
	memset(oldest, 0, sizeof(*oldest));
	oldest->addr = addr;
	oldest->window_start = now;
	return oldest;
}

/* The scope of the request's token when it has at least `need`; else
 * VMAC_SCOPE_NONE (0), with the answer (401, 403 or 429) queued into *ret. */
static enum vmac_scope authorized(struct vmac_http *h, struct MHD_Connection *c, enum vmac_scope need,
                                  enum MHD_Result *ret)
{
	const char *auth = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
	double now = mono_s(), wait_s = 0;
	struct fail_count *f;
	enum vmac_scope have = VMAC_SCOPE_NONE;
	char msg[160];
	int locked;
	pthread_mutex_lock(&h->fails_lock);
	f = fails_of(h, c, now);
	locked = f->fails >= FAIL_LIMIT;
	if (locked)
		wait_s = FAIL_WINDOW_S - (now - f->window_start);
	pthread_mutex_unlock(&h->fails_lock);
	if (locked) {
		snprintf(msg, sizeof(msg), "too many failed attempts from this address; try again in %.0f s",
		         wait_s + 0.5);
		*ret = reply(c, MHD_HTTP_TOO_MANY_REQUESTS, error_body(msg));
		return VMAC_SCOPE_NONE;
	}
	if (auth && strncmp(auth, "Bearer ", 7) == 0)
		have = vmac_token_check(h->store, auth + 7);
	if (have == VMAC_SCOPE_NONE) {
		pthread_mutex_lock(&h->fails_lock);
		fails_of(h, c, now)->fails++; /* the record again: another thread may have reused it */
		pthread_mutex_unlock(&h->fails_lock);
		*ret =
		    reply_with(c, MHD_HTTP_UNAUTHORIZED,
		               error_body(auth ? "the token is not valid (unknown, revoked or malformed)"
		                               : "a token is needed: Authorization: Bearer TOKEN (vmac token create)"),
		               MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"vmac\"");
		return VMAC_SCOPE_NONE;
	}
	if (have < need) {
		snprintf(msg, sizeof(msg), "this needs a token of scope %s; this one is %s", vmac_scope_name(need),
		         vmac_scope_name(have));
		*ret = reply(c, MHD_HTTP_FORBIDDEN, error_body(msg));
		return VMAC_SCOPE_NONE;
	}
	return have;
}

/* A connection's request body (POST), kept up to BODY_MAX bytes (a driver
 * upload); other requests take at most INPUT_MAX. */
#define BODY_MAX (1 << 20)
#define INPUT_MAX 65536
#define INPUT_TIMEOUT_MS 2000 /* the bus thread answers within a tick; this bounds a stuck host */

struct conn {
	char *body;
	size_t len;
	int too_big;
};

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls, enum MHD_RequestTerminationCode why)
{
	struct conn *k = *con_cls;
	(void)cls;
	(void)c;
	(void)why;
	if (k) {
		free(k->body);
		free(k);
	}
	*con_cls = NULL;
}

static int valid_name(const char *s, size_t max)
{
	size_t n = 0;
	for (; *s; s++, n++)
		if (n >= max || !((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') || (*s >= '0' && *s <= '9') ||
		                  *s == '-' || *s == '_' || *s == '.'))
			return 0;
	return n > 0;
}

/* Operator input through the bus thread, and into the store when it
 * persists. Returns the HTTP status; msg says why on anything but 200. */
static unsigned run_input(struct vmac_http *h, struct vmac_bus_input_request *req, char *msg, size_t msglen)
{
	char err[512];
	int rc;
	if (vmac_bus_request_input(h->bus, req, INPUT_TIMEOUT_MS) != 0) {
		snprintf(msg, msglen, "%s", req->reply);
		return MHD_HTTP_SERVICE_UNAVAILABLE;
	}
	if (req->rc == 0 && req->persist &&
	    (rc = vmac_store_param_set(h->store, req->machine, req->name, &req->value, err, sizeof(err))) != 0) {
		snprintf(msg, msglen, "%s.%s is set, but it could not be persisted: %s", req->machine, req->name, err);
		return rc == -VMAC_ESTOREFULL ? 507 : MHD_HTTP_INTERNAL_SERVER_ERROR;
	}
	if (req->rc == 0)
		return MHD_HTTP_OK;
	snprintf(msg, msglen, "%s", req->reply);
	if (req->rc > 0) /* refused (a vmac_refusal) */
		return MHD_HTTP_CONFLICT;
	return req->rc == -VMAC_ENOTRUNNING ? MHD_HTTP_NOT_FOUND : MHD_HTTP_BAD_GATEWAY; /* else -VMAC_EDRIVER */
}

/* POST /api/devices/NAME/input {"name": ..., "value": ...}: operator input
 * to the device's driver, through the bus thread. */
static enum MHD_Result device_input(struct vmac_http *h, struct MHD_Connection *c, const char *device,
                                    const struct conn *k)
{
	struct vmac_bus_input_request req;
	json_error_t jerr;
	json_t *body, *name, *value, *persist;
	char msg[VMAC_EVENT_TEXT + 200];
	unsigned code;
	memset(&req, 0, sizeof(req));
	if (k->too_big || k->len > INPUT_MAX)
		return reply(c, MHD_HTTP_CONTENT_TOO_LARGE, error_body("the request body is over 64 KiB"));
	if (!valid_name(device, VMAC_NAME_MAX))
		return reply(c, MHD_HTTP_NOT_FOUND, error_body("no such device"));
	body = json_loadb(k->body ? k->body : "", k->len, 0, &jerr);
	name = json_object_get(body, "name");
	value = json_object_get(body, "value");
	persist = json_object_get(body, "persist");
	if (!json_is_object(body) || !json_is_string(name) || (persist && !json_is_boolean(persist)) ||
	    !valid_name(json_string_value(name), VMAC_DRIVER_NAME_MAX) ||
	    (value && !json_is_string(value) && !json_is_number(value) && !json_is_boolean(value) &&
	     !json_is_null(value)) ||
	    (json_is_string(value) && strlen(json_string_value(value)) > VMAC_DRIVER_STR_MAX)) {
		json_decref(body);
		return reply(c, MHD_HTTP_BAD_REQUEST,
		             error_body("expected {\"name\": NAME, \"value\": a number, string (at most 63 bytes), "
		                        "boolean or null, \"persist\": true or false (optional)}"));
	}
	snprintf(req.device, sizeof(req.device), "%s", device);
	snprintf(req.name, sizeof(req.name), "%s", json_string_value(name));
	if (json_is_string(value)) {
		req.value.type = VMAC_VALUE_STRING;
		snprintf(req.value.str, sizeof(req.value.str), "%s", json_string_value(value));
	} else if (json_is_number(value)) {
		req.value.type = VMAC_VALUE_NUMBER;
		req.value.number = json_number_value(value);
	} else if (json_is_boolean(value)) {
		req.value.type = VMAC_VALUE_BOOL;
		req.value.number = json_is_true(value);
	} else {
		req.value.type = VMAC_VALUE_NONE; /* a command without a value */
	}
	req.persist = json_is_true(persist);
	json_decref(body);
	if (req.persist && req.value.type == VMAC_VALUE_NONE)
		return reply(c, MHD_HTTP_BAD_REQUEST, error_body("a value to persist is needed"));
	code = run_input(h, &req, msg, sizeof(msg));
	if (code == MHD_HTTP_OK)
		return reply(c, MHD_HTTP_OK,
		             json_pack("{s:b, s:s, s:b}", "ok", 1, "reply", req.reply, "persisted", req.persist));
	return reply(c, code, error_body(msg));
}

/* POST /api/devices/NAME/cycle {"action": "start", "program": "quick"}:
 * start (a programme, or the driver's default), pause, resume or cancel a
 * cycle: the commands of the same names of the driver (the stdlib's
 * appliance offers them), through the same way as input. */
static enum MHD_Result device_cycle(struct vmac_http *h, struct MHD_Connection *c, const char *device,
                                    const struct conn *k)
{
	static const char *const actions[] = {"start", "pause", "resume", "cancel"};
	struct vmac_bus_input_request req;
	char msg[VMAC_EVENT_TEXT + 200];
	json_error_t jerr;
	json_t *body = json_loadb(k->body ? k->body : "", k->len, 0, &jerr), *action, *program;
	unsigned code, i;
	if (k->too_big || k->len > INPUT_MAX) {
		json_decref(body);
		return reply(c, MHD_HTTP_CONTENT_TOO_LARGE, error_body("the request body is over 64 KiB"));
	}
	action = json_object_get(body, "action");
	program = json_object_get(body, "program");
	for (i = 0; i < 4 && !(json_is_string(action) && strcmp(json_string_value(action), actions[i]) == 0); i++)
		;
	if (i == 4 || (program && (i != 0 || !json_is_string(program) ||
	                           strlen(json_string_value(program)) > VMAC_DRIVER_STR_MAX))) {
		json_decref(body);
		return reply(c, MHD_HTTP_BAD_REQUEST,
		             error_body("expected {\"action\": \"start\", \"pause\", \"resume\" or \"cancel\", "
		                        "\"program\": a programme's name (start only, optional)}"));
	}
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	snprintf(req.name, sizeof(req.name), "%s", actions[i]);
	if (program) {
		req.value.type = VMAC_VALUE_STRING;
		snprintf(req.value.str, sizeof(req.value.str), "%s", json_string_value(program));
	}
	json_decref(body);
	code = run_input(h, &req, msg, sizeof(msg));
	if (code == MHD_HTTP_OK)
		return reply(c, MHD_HTTP_OK, json_pack("{s:b, s:s}", "ok", 1, "reply", req.reply));
	return reply(c, code, error_body(msg));
}

/* GET /api/devices and /api/devices/NAME: the devices of the status. */
static enum MHD_Result devices(struct vmac_http *h, struct MHD_Connection *c, const char *name)
{
	struct vmac_status *s = &h->status;
	json_t *list = json_array(), *one = NULL;
	int i;
	pthread_mutex_lock(&h->status_lock);
	vmac_bus_status(h->bus, s);
	for (i = 0; i < s->ndevices; i++)
		if (!name)
			json_array_append_new(list, device_json(&s->devices[i]));
		else if (!one && strcmp(s->devices[i].name, name) == 0)
			one = device_json(&s->devices[i]);
	pthread_mutex_unlock(&h->status_lock);
	if (!name)
		return reply(c, MHD_HTTP_OK, json_pack("{s:o}", "devices", list));
	json_decref(list);
	if (!one)
		return reply(c, MHD_HTTP_NOT_FOUND, error_body("no such device"));
	return reply(c, MHD_HTTP_OK, one);
}

/* GET /api/events/log[?after=SEQ][&limit=N]: the events the store keeps. */
static void append_event(void *ctx, const struct vmac_stored_event *e)
{
	json_array_append_new(ctx, json_pack("{s:I, s:f, s:s, s:s, s:s}", "seq", (json_int_t)e->seq, "time", e->time,
	                                     "kind", e->kind, "device", e->device, "text", e->text));
}

static enum MHD_Result event_log(struct vmac_http *h, struct MHD_Connection *c)
{
	const char *after_s = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "after");
	const char *limit_s = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "limit");
	unsigned long long after = 0;
	long limit = 100;
	char *end, err[512];
	json_t *list;
	if (after_s) {
		after = strtoull(after_s, &end, 10);
		if (!*after_s || *end || after_s[0] == '-')
			return reply(c, MHD_HTTP_BAD_REQUEST,
			             error_body("after must be an event's seq (a whole number)"));
	}
	if (limit_s) {
		limit = strtol(limit_s, &end, 10);
		if (!*limit_s || *end || limit < 1 || limit > 1000)
			return reply(c, MHD_HTTP_BAD_REQUEST, error_body("limit must be 1..1000"));
	}
	list = json_array();
	if (vmac_store_events_list(h->store, after, (int)limit, append_event, list, err, sizeof(err)) < 0) {
		json_decref(list);
		return reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, error_body(err));
	}
	return reply(c, MHD_HTTP_OK, json_pack("{s:o}", "events", list));
}

/* ---- POST /api/console: the line console ---- */

struct console_ctx {
	struct vmac_http *h;
	int fresh; /* the status was read for this line */
	struct vmac_device_status dev;
};

static const struct vmac_device_status *console_device(void *ctx, const char *name)
{
	struct console_ctx *x = ctx;
	struct vmac_status *s = &x->h->status;
	int i, found = 0;
	pthread_mutex_lock(&x->h->status_lock);
	if (!x->fresh) {
		vmac_bus_status(x->h->bus, s);
		x->fresh = 1;
	}
	for (i = 0; i < s->ndevices && !found; i++)
		if (strcmp(s->devices[i].name, name) == 0 && strcmp(s->devices[i].state, "running") == 0) {
			x->dev = s->devices[i];
			found = 1;
		}
	pthread_mutex_unlock(&x->h->status_lock);
	return found ? &x->dev : NULL;
}

static unsigned console_input(void *ctx, struct vmac_bus_input_request *req, char *msg, size_t msglen)
{
	struct console_ctx *x = ctx;
	return run_input(x->h, req, msg, msglen);
}

/* The body: lines of submessages. The answer: each line's answer and the
 * messages of its errors. */
static enum MHD_Result console(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k, int operate)
{
	struct console_ctx *x = malloc(sizeof(*x));
	struct vmac_console_ops ops;
	char answer[4096], errors[8192];
	json_t *lines = json_array();
	const char *p = k->body ? k->body : "";
	int nerr = 0;
	if (!x)
		return reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, error_body("out of memory"));
	ops.device = console_device;
	ops.input = console_input;
	ops.ctx = x;
	ops.may_operate = operate;
	x->h = h;
	while (*p) {
		size_t n = strcspn(p, "\n");
		char *line = strndup(p, n), *e, *save = NULL;
		json_t *errs = json_array();
		x->fresh = 0;
		nerr += line ? vmac_console_line(&ops, line, answer, sizeof(answer), errors, sizeof(errors)) : 0;
		for (e = strtok_r(errors, "\n", &save); line && e; e = strtok_r(NULL, "\n", &save))
			json_array_append_new(errs, json_string(e));
		if (line && strspn(line, " \t\r") < n)
			json_array_append_new(lines, json_pack("{s:s, s:o}", "answer", answer, "errors", errs));
		else
			json_decref(errs);
		free(line);
		p += n;
		if (*p)
			p++;
	}
	free(x);
	return reply(c, MHD_HTTP_OK, json_pack("{s:o, s:i}", "lines", lines, "errors", nerr));
}

/* ---- drivers: versions, upload (hot reload), rollback ---- */

static json_t *version_json(const struct vmac_driver_version *v)
{
	return json_pack("{s:I, s:s, s:s, s:s, s:f, s:s, s:s, s:I, s:s, s:I}", "id", (json_int_t)v->id, "driver",
	                 v->driver, "version", v->version, "hash", v->hash, "deployed", v->deployed, "deployed_by",
	                 v->deployed_by, "state", v->state, "previous", (json_int_t)v->previous, "note", v->note,
	                 "size", (json_int_t)v->size);
}

static void append_version(void *ctx, const struct vmac_driver_version *v)
{
	json_array_append_new(ctx, version_json(v));
}

/* GET /api/drivers and /api/drivers/NAME: the versions kept. */
static enum MHD_Result driver_versions(struct vmac_http *h, struct MHD_Connection *c, const char *driver)
{
	char err[512];
	json_t *list = json_array(), *body;
	struct vmac_driver_version active;
	int rc;
	if (vmac_store_driver_list(h->store, driver, append_version, list, err, sizeof(err)) < 0) {
		json_decref(list);
		return reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, error_body(err));
	}
	if (!driver)
		return reply(c, MHD_HTTP_OK, json_pack("{s:o}", "versions", list));
	rc = vmac_store_driver_active(h->store, driver, &active, NULL, NULL, err, sizeof(err));
	if (rc < 0) {
		json_decref(list);
		return reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, error_body(err));
	}
	body = json_pack("{s:s, s:I, s:o}", "driver", driver, "active", (json_int_t)(rc == 1 ? active.id : 0),
	                 "versions", list);
	return reply(c, MHD_HTTP_OK, body);
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
		body = json_pack("{s:s, s:o}", "error", r->error, "machines", machines);
		return reply(c, (unsigned)r->status, body);
	}
	body = json_pack("{s:b, s:s, s:I, s:s, s:s, s:f, s:o}", "ok", 1, "driver", driver, "id", (json_int_t)r->id,
	                 "version", r->version, "hash", r->hash, "probation_s", probation_s, "machines", machines);
	return reply(c, MHD_HTTP_OK, body);
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
	char *end;
	*s = h->cfg.reload_probation_s;
	if (arg) {
		*s = strtod(arg, &end);
		if (!*arg || *end || !(*s >= 0 && *s <= 86400)) {
			*ret = reply(c, MHD_HTTP_BAD_REQUEST, error_body("probation must be seconds, 0..86400"));
			return -1;
		}
	}
	*ms = (unsigned)(*s * 1000 + 0.5);
	return 0;
}

/* POST /api/drivers/NAME[?probation=S], the body a driver's source text. */
static enum MHD_Result driver_upload(struct vmac_http *h, struct MHD_Connection *c, const char *driver,
                                     const struct conn *k)
{
	struct vmac_deploy_ctx x = {h->bus, h->store, &h->cfg};
	struct vmac_deploy_result *r;
	double probation_s;
	unsigned probation_ms;
	char by[VMAC_TOKEN_ID_LEN + 1];
	enum MHD_Result ret;
	if (k->too_big)
		return reply(c, MHD_HTTP_CONTENT_TOO_LARGE, error_body("a driver file is at most 1 MiB"));
	if (!k->len)
		return reply(c, MHD_HTTP_BAD_REQUEST,
		             error_body("the request body must be the driver's source (Lua text)"));
	if (probation_arg(h, c, &probation_ms, &probation_s, &ret) != 0)
		return ret;
	r = malloc(sizeof(*r));
	if (!r)
		return reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, error_body("out of memory"));
	token_id(c, by, sizeof(by));
	vmac_deploy(&x, driver, k->body, k->len, by, probation_ms, r);
	ret = deploy_reply(c, driver, r, probation_s);
	free(r);
	return ret;
}

/* POST /api/drivers/NAME/activate?id=N[&probation=S] */
static enum MHD_Result driver_activate(struct vmac_http *h, struct MHD_Connection *c, const char *driver)
{
	struct vmac_deploy_ctx x = {h->bus, h->store, &h->cfg};
	struct vmac_deploy_result *r;
	const char *id_s = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "id");
	double probation_s;
	unsigned probation_ms;
	char by[VMAC_TOKEN_ID_LEN + 1], *end;
	long long id = id_s ? strtoll(id_s, &end, 10) : 0;
	enum MHD_Result ret;
	if (!id_s || !*id_s || *end || id < 1)
		return reply(c, MHD_HTTP_BAD_REQUEST,
		             error_body("id must be a version's id (vmac drivers lists them)"));
	if (probation_arg(h, c, &probation_ms, &probation_s, &ret) != 0)
		return ret;
	r = malloc(sizeof(*r));
	if (!r)
		return reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, error_body("out of memory"));
	token_id(c, by, sizeof(by));
	vmac_deploy_activate(&x, driver, id, by, probation_ms, r);
	ret = deploy_reply(c, driver, r, probation_s);
	free(r);
	return ret;
}

/* POST /api/drivers/NAME/rollback */
static enum MHD_Result driver_rollback(struct vmac_http *h, struct MHD_Connection *c, const char *driver)
{
	struct vmac_deploy_ctx x = {h->bus, h->store, &h->cfg};
	struct vmac_deploy_result *r = malloc(sizeof(*r));
	char by[VMAC_TOKEN_ID_LEN + 1];
	enum MHD_Result ret;
	if (!r)
		return reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, error_body("out of memory"));
	token_id(c, by, sizeof(by));
	vmac_deploy_rollback(&x, driver, by, r);
	ret = deploy_reply(c, driver, r, 0);
	free(r);
	return ret;
}

/* PREFIX NAME SUFFIX: NAME into name (at most len - 1 bytes, no slash, a
 * valid name); 0 when url is not of that form. */
static int named_path(const char *url, const char *prefix, const char *suffix, char *name, size_t len)
{
	size_t np = strlen(prefix), ns = strlen(suffix), n = strlen(url);
	if (n <= np + ns || strncmp(url, prefix, np) != 0 || strcmp(url + n - ns, suffix) != 0)
		return 0;
	n -= np + ns;
	if (n >= len || memchr(url + np, '/', n))
		return 0;
	memcpy(name, url + np, n);
	name[n] = 0;
	return valid_name(name, VMAC_NAME_MAX);
}

/* "/api/drivers/NAME" SUFFIX */
static int driver_path(const char *url, const char *suffix, char *driver, size_t len)
{
	return named_path(url, "/api/drivers/", suffix, driver, len);
}

/* ---- GET /api/events: Server-Sent Events ---- */

#define SSE_WAIT_MS 1000     /* how often a waiting stream looks at `stopping` */
#define SSE_KEEPALIVE_S 15.0 /* a comment line when nothing else was sent */
#define SSE_BATCH 8

struct sse {
	struct vmac_http *h;
	uint64_t after; /* the last event sent */
	double last_sent;
	size_t len, off;
	char buf[SSE_BATCH * (2 * VMAC_EVENT_TEXT + 256)];
};

static void sse_append(struct sse *e, const char *text)
{
	size_t n = strlen(text);
	if (e->len + n < sizeof(e->buf)) {
		memcpy(e->buf + e->len, text, n);
		e->len += n;
	}
}

/* The stream's next bytes: blocks (its own connection thread) until an
 * event, a keep-alive or the host's stop. */
static ssize_t sse_read(void *cls, uint64_t pos, char *out, size_t max)
{
	struct sse *e = cls;
	size_t n;
	(void)pos;
	while (e->off == e->len) {
		struct vmac_event ev[SSE_BATCH];
		uint64_t lost;
		char line[128];
		double now;
		int i, got;
		if (atomic_load(&e->h->stopping))
			return MHD_CONTENT_READER_END_OF_STREAM;
		got = vmac_event_log_since(e->h->log, e->after, ev, SSE_BATCH, SSE_WAIT_MS, &lost);
		now = mono_s();
		e->len = e->off = 0;
		if (lost) {
			snprintf(line, sizeof(line), ": %llu events were lost (the log keeps the last %d)\n\n",
			         (unsigned long long)lost, VMAC_EVENT_LOG_SIZE);
			sse_append(e, line);
		}
		for (i = 0; i < got; i++) {
			json_t *j = json_pack("{s:I, s:f, s:s, s:s, s:s}", "seq", (json_int_t)ev[i].seq, "time",
			                      (double)ev[i].time_ns / 1e9, "kind", ev[i].kind, "device", ev[i].device,
			                      "text", ev[i].text);
			char *data = j ? json_dumps(j, JSON_COMPACT) : NULL;
			json_decref(j);
			snprintf(line, sizeof(line), "id: %llu\nevent: %s\ndata: ", (unsigned long long)ev[i].seq,
			         ev[i].kind);
			sse_append(e, line);
			sse_append(e, data ? data : "{}");
			sse_append(e, "\n\n");
			free(data);
			e->after = ev[i].seq;
		}
		if (e->len == 0 && now - e->last_sent >= SSE_KEEPALIVE_S)
			sse_append(e, ": keep-alive\n\n");
		if (e->len)
			e->last_sent = now;
	}
	n = e->len - e->off < max ? e->len - e->off : max;
	memcpy(out, e->buf + e->off, n);
	e->off += n;
	return (ssize_t)n;
}

/* A Server-Sent Events answer whose bytes come from read(cls); cls is
 * freed with done(cls) when the stream ends, or now if it cannot start. */
static enum MHD_Result stream_response(struct MHD_Connection *c, MHD_ContentReaderCallback read, void *cls,
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

static enum MHD_Result events_stream(struct vmac_http *h, struct MHD_Connection *c)
{
	const char *after = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "after");
	const char *resume = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Last-Event-ID");
	struct sse *e;
	char *end;
	const char *from = resume ? resume : after;
	unsigned long long seq = 0;
	if (from) {
		errno = 0;
		seq = strtoull(from, &end, 10);
		if (errno || end == from || *end)
			return reply(c, MHD_HTTP_BAD_REQUEST,
			             error_body("after (or Last-Event-ID) must be an event's seq"));
	}
	e = calloc(1, sizeof(*e));
	if (!e)
		return reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, error_body("out of memory"));
	e->h = h;
	e->after = seq;
	e->last_sent = mono_s();
	/* Something at once, so the client sees the stream is open before the
	 * first event (and how soon to reconnect when it ends). */
	sse_append(e, "retry: 2000\n: vmac events\n\n");
	return stream_response(c, sse_read, e, free);
}

/* ---- GET /api/live: the status pushed, for the web UI ---- */

#define LIVE_PERIOD_MS 250 /* how often a client gets the latest status (if it changed) */

struct live {
	struct vmac_http *h;
	double last_sent, next;
	char *text; /* what is being sent */
	size_t len, off;
	char *last; /* the last status sent (not sent again unchanged) */
};

static void live_free(void *cls)
{
	struct live *l = cls;
	free(l->text);
	free(l->last);
	free(l);
}

/* The stream's next bytes: every LIVE_PERIOD_MS the latest status, if it
 * changed. A slow client is asked nothing until it has read what it got,
 * and then gets the newest status: it never backs anything up. */
/* The newest status as JSON for the live streams, a malloc'd copy: built
 * at most once a period however many clients read it. */
static char *live_snapshot(struct vmac_http *h)
{
	double now = mono_s();
	char *copy;
	pthread_mutex_lock(&h->live_lock);
	if (!h->live_json || now - h->live_at >= LIVE_PERIOD_MS / 1000.0 * 0.8) {
		json_t *s = status_json(h);
		char *data = s ? json_dumps(s, JSON_COMPACT) : NULL;
		json_decref(s);
		if (data) {
			free(h->live_json);
			h->live_json = data;
			h->live_at = now;
		}
	}
	copy = h->live_json ? strdup(h->live_json) : NULL;
	pthread_mutex_unlock(&h->live_lock);
	return copy;
}

static ssize_t live_read(void *cls, uint64_t pos, char *out, size_t max)
{
	struct live *l = cls;
	size_t n;
	(void)pos;
	while (l->off == l->len) {
		double now = mono_s();
		char *data;
		if (atomic_load(&l->h->stopping))
			return MHD_CONTENT_READER_END_OF_STREAM;
		if (now < l->next) {
			usleep((useconds_t)((l->next - now) * 1e6));
			continue;
		}
		l->next = now + LIVE_PERIOD_MS / 1000.0;
		free(l->text);
		l->text = NULL;
		l->len = l->off = 0;
		data = live_snapshot(l->h);
		if (data && (!l->last || strcmp(data, l->last) != 0)) {
			size_t dn = strlen(data);
			l->text = malloc(dn + 16);
			if (l->text) {
				memcpy(l->text, "data: ", 6);
				memcpy(l->text + 6, data, dn);
				memcpy(l->text + 6 + dn, "\n\n", 2);
				l->len = dn + 8;
			}
			free(l->last);
			l->last = data;
			l->last_sent = now;
		} else {
			free(data);
			if (now - l->last_sent >= SSE_KEEPALIVE_S) {
				l->text = strdup(": keep-alive\n\n");
				l->len = l->text ? strlen(l->text) : 0;
				l->last_sent = now;
			}
		}
	}
	n = l->len - l->off < max ? l->len - l->off : max;
	memcpy(out, l->text + l->off, n);
	l->off += n;
	return (ssize_t)n;
}

static enum MHD_Result live_stream(struct vmac_http *h, struct MHD_Connection *c)
{
	struct live *l = calloc(1, sizeof(*l));
	if (!l)
		return reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, error_body("out of memory"));
	l->h = h;
	l->last_sent = mono_s();
	return stream_response(c, live_read, l, live_free);
}

/* GET /api/drivers/NAME/manifest?version=V: a loaded version's declarations. */
static enum MHD_Result driver_manifest(struct MHD_Connection *c, const char *driver)
{
	const char *version = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "version");
	char *json = version ? vmac_loaded_manifest(driver, version) : NULL;
	json_error_t jerr;
	json_t *body;
	if (!version)
		return reply(c, MHD_HTTP_BAD_REQUEST,
		             error_body("version is needed: ?version=V (a device's driver_version)"));
	if (!json)
		return reply(c, MHD_HTTP_NOT_FOUND, error_body("that driver version has not been loaded on this host"));
	body = json_loads(json, 0, &jerr);
	free(json);
	return body ? reply(c, MHD_HTTP_OK, body)
	            : reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, error_body("bad manifest"));
}

/* "/api/devices/NAME" SUFFIX */
static int device_path(const char *url, const char *suffix, char *device, size_t len)
{
	return named_path(url, "/api/devices/", suffix, device, len);
}

/* GET / and /ui/NAME: the web UI's files (docs/UI.md), from the binary. */
static enum MHD_Result ui_asset(struct MHD_Connection *c, const char *name)
{
	const struct vmac_ui_asset *a;
	struct MHD_Response *r;
	enum MHD_Result ret;
	for (a = vmac_ui_assets; a->name && strcmp(a->name, name) != 0; a++)
		;
	if (!a->name)
		return reply(c, MHD_HTTP_NOT_FOUND, error_body("no such file of the web UI"));
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

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url, const char *method,
                                  const char *version, const char *upload_data, size_t *upload_size, void **con_cls)
{
	struct vmac_http *h = cls;
	struct conn *k = *con_cls;
	enum MHD_Result ret;
	enum vmac_scope scope;
	char device[VMAC_NAME_MAX + 2];
	int get = strcmp(method, "GET") == 0 || strcmp(method, "HEAD") == 0, post = strcmp(method, "POST") == 0;
	(void)version;
	if (!k) { /* first call: headers only */
		k = calloc(1, sizeof(*k));
		if (!k)
			return MHD_NO;
		*con_cls = k;
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
	if (!get && !post)
		return reply(c, MHD_HTTP_METHOD_NOT_ALLOWED, error_body("only GET, HEAD and POST are used here"));
	if (get && (strcmp(url, "/") == 0 || strncmp(url, "/ui/", 4) == 0)) /* the web UI: no token, nothing secret */
		return ui_asset(c, strcmp(url, "/") == 0 ? "index.html" : url + 4);
	if (get && strcmp(url, "/api/health") == 0) /* the one request without a token */
		return reply(c, MHD_HTTP_OK, json_pack("{s:b, s:s}", "ok", 1, "version", VMAC_VERSION_STRING));
	if (post && device_path(url, "/input", device, sizeof(device))) {
		if (!authorized(h, c, VMAC_SCOPE_OPERATE, &ret))
			return ret;
		return device_input(h, c, device, k);
	}
	if (post && device_path(url, "/cycle", device, sizeof(device))) {
		if (!authorized(h, c, VMAC_SCOPE_OPERATE, &ret))
			return ret;
		return device_cycle(h, c, device, k);
	}
	if (post &&
	    (driver_path(url, "/rollback", device, sizeof(device)) ||
	     driver_path(url, "/activate", device, sizeof(device)) || driver_path(url, "", device, sizeof(device)))) {
		if (!authorized(h, c, VMAC_SCOPE_DEPLOY, &ret))
			return ret;
		if (driver_path(url, "/rollback", device, sizeof(device)))
			return driver_rollback(h, c, device);
		if (driver_path(url, "/activate", device, sizeof(device)))
			return driver_activate(h, c, device);
		return driver_upload(h, c, device, k);
	}
	if (!(scope = authorized(h, c, VMAC_SCOPE_READ, &ret)))
		return ret;
	if (post && strcmp(url, "/api/console") == 0) {
		if (k->too_big || k->len > INPUT_MAX)
			return reply(c, MHD_HTTP_CONTENT_TOO_LARGE, error_body("the request body is over 64 KiB"));
		return console(h, c, k, scope >= VMAC_SCOPE_OPERATE);
	}
	if (get && strcmp(url, "/api/devices") == 0)
		return devices(h, c, NULL);
	if (get && device_path(url, "", device, sizeof(device)))
		return devices(h, c, device);
	if (get && strcmp(url, "/api/drivers") == 0)
		return driver_versions(h, c, NULL);
	if (get && driver_path(url, "", device, sizeof(device)))
		return driver_versions(h, c, device);
	if (get && strcmp(url, "/api/status") == 0)
		return reply(c, MHD_HTTP_OK, status_json(h));
	if (get && strcmp(url, "/api/live") == 0)
		return live_stream(h, c);
	if (get && strcmp(url, "/api/whoami") == 0)
		return reply(c, MHD_HTTP_OK, json_pack("{s:s}", "scope", vmac_scope_name(scope)));
	if (get && driver_path(url, "/manifest", device, sizeof(device)))
		return driver_manifest(c, device);
	if (get && strcmp(url, "/api/events/log") == 0)
		return event_log(h, c);
	if (get && strcmp(url, "/api/events") == 0)
		return events_stream(h, c);
	if (get && strcmp(url, "/api") == 0)
		return reply(c, MHD_HTTP_OK,
		             json_pack("{s:s, s:[s,s,s,s,s,s,s,s,s,s,s,s,s]}", "vmacd", VMAC_VERSION_STRING,
		                       "endpoints", "/api/status", "/api/health", "/api/events",
		                       "/api/devices/NAME/input", "/api/drivers", "/api/drivers/NAME",
		                       "/api/drivers/NAME/rollback", "/api/console", "/api/devices",
		                       "/api/devices/NAME", "/api/devices/NAME/cycle", "/api/events/log",
		                       "/api/drivers/NAME/activate"));
	return reply(c, MHD_HTTP_NOT_FOUND, error_body("no such endpoint (see docs/API.md)"));
}

/* A PEM file's text (at most 64 KiB), or NULL with err. */
static char *read_pem(const char *path, const char *what, char *err, size_t errlen)
{
	FILE *f = fopen(path, "rb");
	char *buf;
	size_t n;
	if (!f) {
		snprintf(err, errlen, "%s %s: %s", what, path, strerror(errno));
		return NULL;
	}
	buf = malloc(65537);
	if (!buf) {
		fclose(f);
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	n = fread(buf, 1, 65536, f);
	fclose(f);
	buf[n] = 0;
	if (n == 0 || n == 65536 || !strstr(buf, "-----BEGIN ")) {
		snprintf(err, errlen, "%s %s: not a PEM file (or empty, or over 64 KiB)", what, path);
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
	pthread_mutex_init(&h->status_lock, NULL);
	pthread_mutex_init(&h->fails_lock, NULL);
	pthread_mutex_init(&h->live_lock, NULL);
	h->status.devices = calloc(cfg->max_devices, sizeof(*h->status.devices));
	h->status.slot_load = calloc(1u << cfg->max_level, sizeof(*h->status.slot_load));
	if (!h->status.devices || !h->status.slot_load) {
		snprintf(err, errlen, "out of memory");
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
	h->daemon = MHD_start_daemon(MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_THREAD_PER_CONNECTION |
	                                 MHD_USE_ERROR_LOG | (h->tls_cert ? MHD_USE_TLS : 0),
	                             0, NULL, NULL, on_request, h, MHD_OPTION_NOTIFY_COMPLETED, on_completed, NULL,
	                             MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&sin, MHD_OPTION_CONNECTION_TIMEOUT,
	                             (unsigned)30, MHD_OPTION_CONNECTION_LIMIT, (unsigned)256,
	                             /* the certificate and key, or nothing */
	                             h->tls_cert ? MHD_OPTION_HTTPS_MEM_CERT : MHD_OPTION_END, h->tls_cert,
	                             MHD_OPTION_HTTPS_MEM_KEY, h->tls_key, MHD_OPTION_END);
	if (!h->daemon) {
		snprintf(err, errlen, "cannot listen on %s (address in use, not an address of this machine%s)", listen,
		         h->tls_cert ? ", or a certificate and key that do not go together" : "");
		vmac_http_stop(h);
		return NULL;
	}
	info = MHD_get_daemon_info(h->daemon, MHD_DAEMON_INFO_BIND_PORT);
	h->port = info ? info->port : (unsigned)port;
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

void vmac_http_stop(struct vmac_http *h)
{
	if (!h)
		return;
	atomic_store(&h->stopping, 1); /* event streams end within SSE_WAIT_MS */
	if (h->daemon)
		MHD_stop_daemon(h->daemon);
	pthread_mutex_destroy(&h->status_lock);
	pthread_mutex_destroy(&h->fails_lock);
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
