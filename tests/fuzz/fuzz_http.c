/* libFuzzer harness for the HTTP API's requests, without sockets or
 * threads (core/api/api_request.c): the input is a request as on the wire,
 *   METHOD PATH[?QUERY]\n  (Header: value\n)*  \n  BODY
 * routed by http_route_find as vmacd routes it, then what that endpoint
 * reads parsed by the same functions the endpoint calls: the input and
 * cycle bodies (JSON), the console's lines (against a fake host), the query
 * arguments (probation, id, after, limit), Last-Event-ID, and a manifest's
 * JSON. What only the real host can answer (tokens in the store, the bus
 * thread, the event log) is not reached; docs/TESTING.md, "Fuzzing".
 * Before the first input, every row of the route table (HTTP_ROUTES) is
 * routed from a path made of its pattern, and must come back as itself;
 * with "." or ".." for its NAME or ID, as no route at all (404); and every
 * POST has an audit type, every GET none.
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

#define CAPITALS "ABCDEFGHIJKLMNOPQRSTUVWXYZ"

/* The placeholder of a route's pattern (NAME, ID, FILE), or "". */
static const char *placeholder(const char *pattern, size_t *len)
{
	const char *hole = strpbrk(pattern, CAPITALS);
	*len = hole ? strspn(hole, CAPITALS) : 0;
	return hole ? hole : "";
}

static int is_placeholder(const char *pattern, const char *word)
{
	size_t n;
	const char *hole = placeholder(pattern, &n);
	return n == strlen(word) && strncmp(hole, word, n) == 0;
}

/* The path of pattern with part for its placeholder. */
static void make_path(const char *pattern, const char *part, char *path, size_t len)
{
	size_t n;
	const char *hole = placeholder(pattern, &n);
	if (!n)
		snprintf(path, len, "%s", pattern);
	else
		snprintf(path, len, "%.*s%s%s", (int)(hole - pattern), pattern, part, hole + n);
}

/* The scope docs/API.md gives a request that found its route, said from
 * the method and the path alone (not read from the table, which this
 * checks): the web UI and the health check none, operator input under
 * /api/devices/ operate, drivers and board keys deploy, everything else
 * read. */
static enum vmac_scope documented_scope(const char *method, const char *path)
{
	int post = strcmp(method, "POST") == 0;
	if (!post && (strcmp(path, "/") == 0 || strncmp(path, "/ui/", 4) == 0 || strcmp(path, "/api/health") == 0))
		return VMAC_SCOPE_NONE;
	if (post && strncmp(path, "/api/devices/", 13) == 0)
		return VMAC_SCOPE_OPERATE;
	if (post && (strncmp(path, "/api/drivers/", 13) == 0 || strncmp(path, "/api/boards/", 12) == 0))
		return VMAC_SCOPE_DEPLOY;
	return VMAC_SCOPE_READ;
}

static void fail_route(const char *method, const char *path, const struct http_match *m, const char *why)
{
	fprintf(stderr, "fuzz_http: %s %s routed to endpoint %d (scope %d, name \"%s\"): %s\n", method, path,
	        (int)m->endpoint, (int)m->need, m->name, why);
	abort();
}

/* What http_route_find made of method and path agrees with the table: a
 * route's method, scope and path (made again from its NAME, ID or FILE),
 * and with docs/API.md's scopes. */
static void check_route(const char *method, const char *path, const struct http_match *m)
{
	int known = strcmp(method, "GET") == 0 || strcmp(method, "HEAD") == 0 || strcmp(method, "POST") == 0;
	const struct http_route *row;
	char again[256];
	if (m->endpoint > HTTP_BAD_METHOD || (m->endpoint == HTTP_BAD_METHOD) == known)
		fail_route(method, path, m, "405 for a method of the API, or none for another");
	if (m->endpoint >= HTTP_ROUTE_COUNT) {
		if (m->need != (m->endpoint == HTTP_BAD_METHOD ? VMAC_SCOPE_NONE : VMAC_SCOPE_READ) || m->name[0] ||
		    m->file)
			fail_route(method, path, m,
			           "a request of no route takes scope read (405: none) and has no name");
		return;
	}
	row = &http_routes[m->endpoint];
	if (strcmp(row->method, strcmp(method, "POST") == 0 ? "POST" : "GET") != 0)
		fail_route(method, path, m, "not the route's method");
	if (m->need != row->need || m->need != documented_scope(method, path))
		fail_route(method, path, m, "not the scope of the table, or not the one docs/API.md gives");
	if (is_placeholder(row->pattern, "FILE")) {
		if (!m->file || m->name[0])
			fail_route(method, path, m, "a FILE route without its file");
		make_path(row->pattern, m->file, again, sizeof(again));
	} else if (is_placeholder(row->pattern, "NAME") || is_placeholder(row->pattern, "ID")) {
		if (m->file || !http_valid_name(m->name, VMAC_NAME_MAX) || strchr(m->name, '/') ||
		    (is_placeholder(row->pattern, "ID") && strspn(m->name, "0123456789") != strlen(m->name)))
			fail_route(method, path, m, "a NAME that is no name, or an ID that is no number");
		make_path(row->pattern, m->name, again, sizeof(again));
	} else {
		if (m->file || m->name[0])
			fail_route(method, path, m, "a name for a route without one");
		make_path(row->pattern, "", again, sizeof(again));
	}
	if (strcmp(again, path) != 0)
		fail_route(method, path, m, "the path made again from the route is another");
}

/* Every row of the table routes back to itself from a path made of its
 * pattern (GET rows by HEAD too); with a dot name, a slash or a non-number
 * for its NAME or ID, to no route (404); by another method, elsewhere. */
static void check_table(void)
{
	static const char *const not_names[] = {".", "..", ".hidden", "a/b", "", "x y", "1.5/../2"};
	struct http_match m;
	char path[256];
	int i;
	size_t b;
	memset(&m, 0, sizeof(m));
	for (i = 0; i < HTTP_ROUTE_COUNT; i++) {
		const struct http_route *row = &http_routes[i];
		int get = strcmp(row->method, "GET") == 0;
		const char *part = is_placeholder(row->pattern, "FILE")   ? "app.js"
		                   : is_placeholder(row->pattern, "ID")   ? "12"
		                   : is_placeholder(row->pattern, "NAME") ? "washer-1"
		                                                          : "";
		if (!get && strcmp(row->method, "POST") != 0)
			fail_route(row->method, row->pattern, &m, "a row whose method is not GET or POST");
		if (!get != (row->audit != NULL))
			fail_route(row->method, row->pattern, &m,
			           "a POST without an audit type, or a read with one (docs/API.md, \"Audit trail\")");
		make_path(row->pattern, part, path, sizeof(path));
		http_route_find(row->method, path, &m);
		if ((int)m.endpoint != i)
			fail_route(row->method, path, &m, "a route of the table does not route to itself");
		check_route(row->method, path, &m);
		if (get) {
			http_route_find("HEAD", path, &m);
			if ((int)m.endpoint != i)
				fail_route("HEAD", path, &m, "HEAD does not route as GET");
		}
		http_route_find(get ? "POST" : "GET", path, &m);
		if ((int)m.endpoint == i)
			fail_route(get ? "POST" : "GET", path, &m, "a route taken by the other method");
		http_route_find("PUT", path, &m);
		if (m.endpoint != HTTP_BAD_METHOD)
			fail_route("PUT", path, &m, "not 405");
		if (!is_placeholder(row->pattern, "NAME") && !is_placeholder(row->pattern, "ID"))
			continue;
		for (b = 0; b < sizeof(not_names) / sizeof(not_names[0]); b++) {
			make_path(row->pattern, not_names[b], path, sizeof(path));
			http_route_find(row->method, path, &m);
			if (m.endpoint != HTTP_NOT_FOUND)
				fail_route(row->method, path, &m, "a path with no name in it is not a 404");
		}
		if (is_placeholder(row->pattern, "ID")) {
			make_path(row->pattern, "12a", path, sizeof(path));
			http_route_find(row->method, path, &m);
			if (m.endpoint != HTTP_NOT_FOUND)
				fail_route(row->method, path, &m, "an ID that is no number is not a 404");
		}
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
	check_table();
	return 0;
}

static void console(const struct request *q, int operate)
{
	struct vmac_console_ops ops = {fake_device, fake_input, NULL, operate, NULL};
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
	struct http_match r;
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
	http_route_find(q.method, q.path, &r);
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
