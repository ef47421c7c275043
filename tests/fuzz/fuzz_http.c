/* libFuzzer harness for the HTTP API's requests, without sockets or
 * threads (core/api/api_request.c): the input is a request as on the wire,
 *   METHOD PATH[?QUERY]\n  (Header: value\n)*  \n  BODY
 * routed by http_route as vmacd routes it, then what that endpoint reads
 * parsed by the same functions the endpoint calls: the input and cycle
 * bodies (JSON), the console's lines (against a fake host), the query
 * arguments (probation, id, after, limit), Last-Event-ID, and a manifest's
 * JSON. What only the real host can answer (tokens in the store, the bus
 * thread, the event log) is not reached; docs/TESTING.md, "Fuzzing".
 * Seeds: tests/fuzz/corpus-http/. */
#include <jansson.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/api/api_request.h"
#include "fuzz.h"

#define ARGS_MAX 8

struct request {
	char *method, *path, *body;
	size_t body_len;
	const char *arg_name[ARGS_MAX], *arg_value[ARGS_MAX];
	int nargs;
	const char *last_event_id; /* the header, or NULL */
};

/* ?a=1&b=2 (no %-decoding: libmicrohttpd's is not under test). */
static const char *arg(const struct request *q, const char *name)
{
	int i;
	for (i = 0; i < q->nargs; i++)
		if (strcmp(q->arg_name[i], name) == 0)
			return q->arg_value[i];
	return NULL;
}

/* Splits text (a NUL-terminated copy of the input) into q. 0, or -1 when
 * there is no request line. */
static int parse_request(char *text, size_t size, struct request *q)
{
	char *line_end = strchr(text, '\n'), *sp, *query, *p;
	memset(q, 0, sizeof(*q));
	if (!line_end)
		return -1;
	*line_end = 0;
	sp = strchr(text, ' ');
	if (!sp)
		return -1;
	*sp = 0;
	q->method = text;
	q->path = sp + 1;
	query = strchr(q->path, '?');
	if (query) {
		char *save = NULL, *a;
		*query++ = 0;
		for (a = strtok_r(query, "&", &save); a && q->nargs < ARGS_MAX; a = strtok_r(NULL, "&", &save)) {
			char *eq = strchr(a, '=');
			q->arg_name[q->nargs] = a;
			q->arg_value[q->nargs++] = eq ? (*eq = 0, eq + 1) : "";
		}
	}
	/* Headers to the empty line; the body is the rest, NUL bytes and all. */
	p = line_end + 1;
	while (p < text + size && *p != '\n') {
		char *end = memchr(p, '\n', (size_t)(text + size - p)), *colon;
		if (!end)
			end = text + size;
		*end = 0;
		colon = strchr(p, ':');
		if (colon && strncmp(p, "Last-Event-ID", (size_t)(colon - p)) == 0 && colon - p == 13)
			q->last_event_id = colon[1] == ' ' ? colon + 2 : colon + 1;
		p = end + 1;
	}
	if (p < text + size) {
		q->body = p + 1;
		q->body_len = (size_t)(text + size - q->body);
	} else {
		q->body = text + size;
	}
	return 0;
}

static int has_name(enum http_endpoint e)
{
	return e == HTTP_INPUT || e == HTTP_CYCLE || e == HTTP_ROLLBACK || e == HTTP_ACTIVATE || e == HTTP_UPLOAD ||
	       e == HTTP_DEVICE || e == HTTP_DRIVER || e == HTTP_MANIFEST || e == HTTP_RECORD || e == HTTP_RECORDING;
}

/* The path of a named endpoint, made again from its name: one path per
 * route. */
static void check_named_path(const struct http_route *r, const char *path)
{
	static const struct {
		enum http_endpoint e;
		const char *prefix, *suffix;
	} forms[] = {
	    {HTTP_INPUT, "/api/devices/", "/input"},
	    {HTTP_CYCLE, "/api/devices/", "/cycle"},
	    {HTTP_ROLLBACK, "/api/drivers/", "/rollback"},
	    {HTTP_ACTIVATE, "/api/drivers/", "/activate"},
	    {HTTP_UPLOAD, "/api/drivers/", ""},
	    {HTTP_DEVICE, "/api/devices/", ""},
	    {HTTP_DRIVER, "/api/drivers/", ""},
	    {HTTP_MANIFEST, "/api/drivers/", "/manifest"},
	    {HTTP_RECORD, "/api/devices/", "/record"},
	    {HTTP_RECORDING, "/api/recordings/", ""},
	};
	char again[256];
	size_t i;
	for (i = 0; i < sizeof(forms) / sizeof(forms[0]); i++)
		if (forms[i].e == r->endpoint) {
			snprintf(again, sizeof(again), "%s%s%s", forms[i].prefix, r->name, forms[i].suffix);
			if (strcmp(again, path) != 0)
				abort();
			return;
		}
	abort();
}

static void check_route(const char *method, const char *path, const struct http_route *r)
{
	int known = strcmp(method, "GET") == 0 || strcmp(method, "HEAD") == 0 || strcmp(method, "POST") == 0;
	if (r->endpoint > HTTP_NOT_FOUND || (r->endpoint == HTTP_BAD_METHOD) == known)
		abort();
	if ((r->need == VMAC_SCOPE_NONE) !=
	    (r->endpoint == HTTP_BAD_METHOD || r->endpoint == HTTP_UI || r->endpoint == HTTP_HEALTH))
		abort(); /* a request without a token reaches only the UI and the health check */
	if ((r->need == VMAC_SCOPE_OPERATE) !=
	    (r->endpoint == HTTP_INPUT || r->endpoint == HTTP_CYCLE || r->endpoint == HTTP_RECORD))
		abort();
	if ((r->need == VMAC_SCOPE_DEPLOY) !=
	    (r->endpoint == HTTP_ROLLBACK || r->endpoint == HTTP_ACTIVATE || r->endpoint == HTTP_UPLOAD))
		abort();
	if (r->endpoint == HTTP_UI && (!r->file || strcmp(method, "POST") == 0))
		abort();
	if (has_name(r->endpoint)) {
		if (!http_valid_name(r->name, VMAC_NAME_MAX) || strchr(r->name, '/'))
			abort();
		check_named_path(r, path);
	} else if (r->name[0]) {
		abort();
	}
}

static int name_ok(const char *s, size_t max)
{
	size_t n = strnlen(s, max + 1);
	return n > 0 && n <= max && strspn(s, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-") == n;
}

/* What a parsed operator request must be before it goes to the bus. */
static void check_request(const struct vmac_bus_input_request *req, const char *device)
{
	if (strcmp(req->device, device) != 0 || !name_ok(req->name, VMAC_DRIVER_NAME_MAX))
		abort();
	if (req->value.type > VMAC_VALUE_STRING || !memchr(req->value.str, 0, sizeof(req->value.str)))
		abort();
	if (req->value.type == VMAC_VALUE_BOOL && req->value.number != 0 && req->value.number != 1)
		abort();
	if (req->persist && req->value.type == VMAC_VALUE_NONE)
		abort();
}

/* Every answer is JSON the server can send. */
static void check_answer(json_t *body)
{
	char *text;
	if (!body)
		abort();
	text = json_dumps(body, JSON_COMPACT);
	if (!text)
		abort();
	free(text);
	json_decref(body);
}

static void error_answer(unsigned code, const char *msg)
{
	if (code < 400 || code > 499 || !msg || !msg[0])
		abort();
	check_answer(json_pack("{s:s}", "error", msg));
}

/* ---- the console's fake host: one running device ---- */

static struct vmac_device_status device;
static int lines_begun;

static const struct vmac_device_status *fake_device(void *ctx, const char *name)
{
	(void)ctx;
	return strcmp(name, device.name) == 0 ? &device : NULL;
}

static unsigned fake_input(void *ctx, struct vmac_bus_input_request *req, char *msg, size_t msglen)
{
	(void)ctx;
	if (strcmp(req->name, "refuse") == 0) {
		req->rc = VMAC_REFUSED_BY_DRIVER;
		snprintf(msg, msglen, "refused: %s", req->value.str);
		return 409;
	}
	snprintf(req->reply, sizeof(req->reply), "ok");
	return strcmp(req->device, device.name) == 0 ? 200 : 404;
}

static void new_line(void *ctx)
{
	(void)ctx;
	lines_begun++;
}

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
	(void)argc;
	(void)argv;
	snprintf(device.name, sizeof(device.name), "washer-1");
	device.state = "running";
	device.nvars = 1;
	snprintf(device.vars[0].name, sizeof(device.vars[0].name), "step");
	device.vars[0].value.type = VMAC_VALUE_STRING;
	snprintf(device.vars[0].value.str, sizeof(device.vars[0].value.str), "fill");
	return 0;
}

static void console(const struct request *q, int operate)
{
	struct vmac_console_ops ops = {fake_device, fake_input, NULL, operate};
	json_t *answer, *lines;
	const char *p;
	size_t nonblank = 0;
	lines_begun = 0;
	answer = http_console_answer(&ops, new_line, q->body);
	/* One entry per line that is not blank, in order. */
	for (p = q->body; *p;) {
		size_t n = strcspn(p, "\n");
		if (strspn(p, " \t\r") < n)
			nonblank++;
		p += n;
		if (*p)
			p++;
	}
	lines = json_object_get(answer, "lines");
	if (!json_is_array(lines) || json_array_size(lines) != nonblank || lines_begun < (int)nonblank)
		abort();
	check_answer(answer);
}

static void probation(const struct request *q)
{
	unsigned ms;
	double s;
	if (http_parse_probation(arg(q, "probation"), 30, &ms, &s) == 0 &&
	    (!(s >= 0 && s <= 86400) || ms != (unsigned)(s * 1000 + 0.5)))
		abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct http_route r;
	struct request q;
	struct vmac_bus_input_request req;
	unsigned long long seq;
	const char *msg = NULL;
	char *text;
	unsigned code;
	long long id;
	long limit;
	if (size > 65536 + 1024)
		return 0;
	text = malloc(size + 1);
	if (!text)
		abort();
	memcpy(text, data, size);
	text[size] = 0;
	if (parse_request(text, size, &q) != 0) {
		free(text);
		return 0;
	}
	http_route(q.method, q.path, &r);
	check_route(q.method, q.path, &r);
	switch (r.endpoint) {
	case HTTP_INPUT:
		code = http_parse_input(r.name, q.body, q.body_len, 0, &req, &msg);
		if (code == 0)
			check_request(&req, r.name);
		else if (code != 400 && code != 404 && code != 413)
			abort();
		else
			error_answer(code, msg);
		break;
	case HTTP_CYCLE:
		code = http_parse_cycle(r.name, q.body, q.body_len, 0, &req, &msg);
		if (code == 0) {
			check_request(&req, r.name);
			if (req.value.type != VMAC_VALUE_NONE && strcmp(req.name, "start") != 0)
				abort(); /* a programme only with start */
		} else {
			error_answer(code, msg);
		}
		break;
	case HTTP_ACTIVATE:
		if (http_parse_id(arg(&q, "id"), &id) == 0 && id < 1)
			abort();
		probation(&q);
		break;
	case HTTP_UPLOAD:
	case HTTP_ROLLBACK: probation(&q); break;
	case HTTP_CONSOLE: console(&q, q.body_len & 1); break;
	case HTTP_EVENT_LOG:
		if (http_parse_event_log(arg(&q, "after"), arg(&q, "limit"), &seq, &limit, &msg) == 0) {
			if (limit < 1 || limit > 1000)
				abort();
		} else {
			error_answer(400, msg);
		}
		break;
	case HTTP_EVENTS:
		if (http_parse_events_from(arg(&q, "after"), q.last_event_id, &seq) == 0 && !arg(&q, "after") &&
		    !q.last_event_id && seq != 0)
			abort();
		break;
	case HTTP_MANIFEST: {
		/* The body stands for a driver's declarations: what the API
		 * decodes, it can send again. */
		json_t *m = http_manifest_json(q.body);
		if (m)
			check_answer(m);
		break;
	}
	default: break;
	}
	free(text);
	return 0;
}
