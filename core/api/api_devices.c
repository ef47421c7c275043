/* The endpoints of machines (docs/API.md): GET /api/status and
 * /api/devices[/NAME], operator input and cycles (through the bus's
 * request slots), the line console, and GET /api/live for the web UI.
 * Input, cycles and the console's writes tell the audit trail what they
 * asked, as the console writes it (audit.c). */
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
#include "../host/audit.h"
#include "../loader/loader.h"
#include "../reload/deploy.h"
#include "console.h"
#include "ui_assets.h"

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

/* devices[].clock: null until the board's first TIMED reply. */
static json_t *clock_json(const struct vmac_device_status *d, int64_t started_ns)
{
	static const char *const states[] = {"unsynced", "locking", "locked", "holdover", "lost"};
	const struct vmac_board_clock_status *c = &d->clock;
	if (!c->known)
		return json_null();
	return json_pack(
	    "{s:s, s:b, s:o, s:f, s:o, s:I, s:I}", "state", c->state <= 4 ? states[c->state] : "?", "on_arrival",
	    c->on_arrival, "bound_us", c->bound_ns == 0xFFFFFFFFu ? json_null() : json_real((double)c->bound_ns / 1e3),
	    "offset_s", (double)c->offset_ns / 1e9, "latched_at",
	    c->latched_at_ns ? json_real((double)((int64_t)c->latched_at_ns - started_ns) / 1e9) : json_null(),
	    "services_timed", (json_int_t)c->services_timed, "services_on_arrival", (json_int_t)c->services_arrival);
}

/* devices[].timing: null without a machine. */
static json_t *timing_json(const struct vmac_device_status *d)
{
	int arrival = d->timing.pattern == VMAC_TIMING_ARRIVAL;
	if (d->timing.pattern == VMAC_TIMING_DEFAULT)
		return json_null();
	return json_pack("{s:s, s:o, s:o, s:b, s:I}", "pattern", vmac_timing_name(d->timing.pattern), "in_us",
	                 arrival ? json_null() : json_integer(d->timing.in_us), "out_us",
	                 arrival ? json_null() : json_integer(d->timing.out_us), "timed", d->timing.timed, "mismatched",
	                 (json_int_t)d->timing_mismatch);
}

static json_t *device_json(const struct vmac_device_status *d, int64_t started_ns)
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
	json_object_set_new(o, "misses_host", json_integer((json_int_t)d->misses_host));
	json_object_set_new(o, "drops", json_integer((json_int_t)d->drops));
	json_object_set_new(o, "driver_late", json_integer((json_int_t)d->driver_late));
	json_object_set_new(o, "protocol", json_integer(d->protocol));
	json_object_set_new(o, "service", json_string(d->cyclic ? "cyclic" : "unicast"));
	json_object_set_new(o, "offset", d->cyclic ? json_integer(d->offset) : json_null());
	json_object_set_new(o, "authenticated", json_boolean(d->authenticated));
	json_object_set_new(o, "driver_instructions", json_integer((json_int_t)d->driver_instructions));
	json_object_set_new(o, "driver_call_s", json_real((double)d->driver_call_ns / 1e9));
	json_object_set_new(o, "firmware", json_sprintf("%u.%u", d->firmware_major, d->firmware_minor));
	json_object_set_new(o, "clock", clock_json(d, started_ns));
	json_object_set_new(o, "timing", timing_json(d));
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
		json_array_append_new(devices, device_json(&s->devices[i], s->started_ns));
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
		/* The rest of the counters, one row each. */
		const struct {
			const char *name;
			uint64_t value;
		} more[] = {{"schedule_full", s->counters.schedule_full},
		            {"misses_host", s->counters.misses_host},
		            {"attach_refused", s->counters.attach_refused},
		            {"auth_failed", s->counters.auth_failed},
		            {"takeover_refused", s->counters.takeover_refused},
		            {"waiting", s->counters.waiting},
		            {"syncs", s->counters.syncs},
		            {"syncs_sealed", s->counters.syncs_sealed},
		            {"sync_stamps", s->counters.sync_stamps}};
		for (i = 0; i < (int)(sizeof(more) / sizeof(more[0])); i++)
			json_object_set_new(json_object_get(root, "counters"), more[i].name,
			                    json_integer((json_int_t)more[i].value));
		json_object_set_new(root, "bus_trust", json_string(h->cfg.bus_trust));
		json_object_set_new(root, "board_keys", json_integer((json_int_t)s->board_keys));
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

/* The audit trail's detail of operator input: what the console would
 * write for it (washer-1.door:true, washer-1.program>quick: a param
 * persisted, its own type). */
static void audit_input(const struct conn *k, const struct vmac_bus_input_request *req)
{
	char text[2 * VMAC_NAME_MAX + 2 * VMAC_DRIVER_STR_MAX + 32];
	vmac_audit_input(req, text, sizeof(text));
	http_audit_detail(k, "%s", text);
	if (req->persist)
		http_audit_type(k, "param");
}

/* POST /api/devices/NAME/input {"name": ..., "value": ...}: operator input
 * to the device's driver, through the bus thread. */
enum MHD_Result http_device_input(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *device = k->route.name;
	struct vmac_bus_input_request req;
	char msg[VMAC_EVENT_TEXT + 200];
	const char *why;
	unsigned code = http_parse_input(device, k->body, k->len, k->too_big, &req, &why);
	if (code)
		return http_reply(c, code, http_error_body(why));
	audit_input(k, &req);
	code = run_input(h, &req, msg, sizeof(msg));
	if (code == MHD_HTTP_OK)
		return http_reply(c, MHD_HTTP_OK,
		                  json_pack("{s:b, s:s, s:b}", "ok", 1, "reply", req.reply, "persisted", req.persist));
	return http_reply(c, code, http_error_body(msg));
}

/* POST /api/devices/NAME/cycle {"action": "start", "program": "quick"}:
 * start (a programme, or the driver's default), pause, resume or cancel a
 * cycle: the commands of the same names of the driver (the stdlib's
 * appliance offers them), through the same way as input. */
enum MHD_Result http_device_cycle(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *device = k->route.name;
	struct vmac_bus_input_request req;
	char msg[VMAC_EVENT_TEXT + 200];
	const char *why;
	unsigned code = http_parse_cycle(device, k->body, k->len, k->too_big, &req, &why);
	if (code)
		return http_reply(c, code, http_error_body(why));
	audit_input(k, &req);
	code = run_input(h, &req, msg, sizeof(msg));
	if (code == MHD_HTTP_OK)
		return http_reply(c, MHD_HTTP_OK, json_pack("{s:b, s:s}", "ok", 1, "reply", req.reply));
	return http_reply(c, code, http_error_body(msg));
}

/* GET /api/devices and /api/devices/NAME: the devices of the status. */
enum MHD_Result http_devices(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *name = k->route.name[0] ? k->route.name : NULL;
	struct vmac_status *s = &h->status;
	json_t *list = json_array(), *one = NULL;
	int i;
	pthread_mutex_lock(&h->status_lock);
	vmac_bus_status(h->bus, s);
	for (i = 0; i < s->ndevices; i++)
		if (!name)
			json_array_append_new(list, device_json(&s->devices[i], s->started_ns));
		else if (!one && strcmp(s->devices[i].name, name) == 0)
			one = device_json(&s->devices[i], s->started_ns);
	pthread_mutex_unlock(&h->status_lock);
	if (!name)
		return http_reply(c, MHD_HTTP_OK, json_pack("{s:o}", "devices", list));
	json_decref(list);
	if (!one)
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body("no such device"));
	return http_reply(c, MHD_HTTP_OK, one);
}

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

/* A submessage that wrote: its answer into the audit trail's detail, its
 * device the event's (the first one's). */
static void console_wrote(void *ctx, const char *device, const char *answer)
{
	struct console_ctx *x = ctx;
	if (!x->wrote)
		http_audit_device(x->k, device);
	x->wrote = 1;
	http_audit_detail(x->k, "%s", answer);
}

/* A new line: the status is read again for it. */
static void console_new_line(void *ctx)
{
	struct console_ctx *x = ctx;
	x->fresh = 0;
}

/* The body: lines of submessages. The answer: each line's answer and the
 * messages of its errors (api_request.c). */
enum MHD_Result http_console(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct console_ctx *x;
	struct vmac_console_ops ops;
	json_t *answer;
	if (k->too_big || k->len > INPUT_MAX)
		return http_reply(c, MHD_HTTP_CONTENT_TOO_LARGE, http_error_body("the request body is over 64 KiB"));
	x = malloc(sizeof(*x));
	if (!x)
		return http_reply(c, MHD_HTTP_SERVICE_UNAVAILABLE, http_error_body("out of memory"));
	ops.device = console_device;
	ops.input = console_input;
	ops.wrote = console_wrote;
	ops.ctx = x;
	ops.may_operate = k->scope >= VMAC_SCOPE_OPERATE;
	x->h = h;
	x->k = k;
	x->wrote = 0;
	answer = http_console_answer(&ops, console_new_line, k->body);
	if (!x->wrote)
		http_audit_nothing(k); /* reads only: nothing to audit */
	free(x);
	return http_reply(c, MHD_HTTP_OK, answer);
}

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
	double now = http_mono_s();
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
		double now = http_mono_s();
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

/* GET /api/status: the status as JSON, at most 100 ms old. */
enum MHD_Result http_status(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	(void)k;
	return http_reply(c, MHD_HTTP_OK, status_json(h));
}

enum MHD_Result http_live_stream(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct live *l = calloc(1, sizeof(*l));
	(void)k;
	if (!l)
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body("out of memory"));
	l->h = h;
	l->last_sent = http_mono_s();
	return http_stream_response(c, live_read, l, live_free);
}
