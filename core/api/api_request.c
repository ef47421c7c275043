/* See api_request.h: the route table and routing, request bodies and
 * arguments, and the console's body, with nothing but text in and out (no
 * libmicrohttpd: the answers are HTTP status numbers). */
#include "api_request.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/name.h"

int http_valid_name(const char *s, size_t max)
{
	return vmac_valid_name(s, max); /* core/common/name.h: never "." or ".." */
}

#define HTTP_ROUTE_ROW(endpoint, method, pattern, scope, audit, handler) [endpoint] = {method, pattern, scope, audit},

const struct http_route http_routes[HTTP_ROUTE_COUNT] = {HTTP_ROUTES(HTTP_ROUTE_ROW)};

#define CAPITALS "ABCDEFGHIJKLMNOPQRSTUVWXYZ"

/* path against a pattern of HTTP_ROUTES: 1 when it matches, with its NAME
 * or ID in m->name or its FILE in m->file; 0 leaves m as it was. */
static int match_pattern(const char *pattern, const char *path, struct http_match *m)
{
	const char *hole = strpbrk(pattern, CAPITALS), *suffix;
	size_t np, nh, ns, n;
	char name[sizeof(m->name)];
	if (!hole)
		return strcmp(pattern, path) == 0;
	np = (size_t)(hole - pattern);
	if (strncmp(path, pattern, np) != 0)
		return 0;
	if (strcmp(hole, "FILE") == 0) {
		m->file = path + np;
		return 1;
	}
	nh = strspn(hole, CAPITALS);
	suffix = hole + nh;
	ns = strlen(suffix);
	n = strlen(path);
	if (n < np + ns || strcmp(path + n - ns, suffix) != 0)
		return 0;
	n -= np + ns;
	if (n >= sizeof(name) || memchr(path + np, '/', n))
		return 0;
	memcpy(name, path + np, n);
	name[n] = 0;
	if (!http_valid_name(name, VMAC_NAME_MAX))
		return 0;
	if (nh == 2 && strncmp(hole, "ID", 2) == 0) {
		if (strspn(name, "0123456789") != n)
			return 0;
	} else if (nh != 4 || strncmp(hole, "NAME", 4) != 0) {
		return 0; /* no such placeholder: the row is wrong, and fuzz_http says so */
	}
	memcpy(m->name, name, n + 1);
	return 1;
}

void http_route_find(const char *method, const char *url, struct http_match *m)
{
	int get = strcmp(method, "GET") == 0 || strcmp(method, "HEAD") == 0, post = strcmp(method, "POST") == 0;
	int i;
	memset(m, 0, sizeof(*m));
	if (!get && !post) {
		m->endpoint = HTTP_BAD_METHOD;
		m->need = VMAC_SCOPE_NONE;
		return;
	}
	for (i = 0; i < HTTP_ROUTE_COUNT; i++)
		if (strcmp(http_routes[i].method, get ? "GET" : "POST") == 0 &&
		    match_pattern(http_routes[i].pattern, url, m)) {
			m->endpoint = (enum http_endpoint)i;
			m->need = http_routes[i].need;
			return;
		}
	m->endpoint = HTTP_NOT_FOUND;
	m->need = VMAC_SCOPE_READ;
}

unsigned http_parse_input(const char *device, const char *body, size_t len, int too_big,
                          struct vmac_bus_input_request *req, const char **msg)
{
	json_error_t jerr;
	json_t *root, *name, *value, *persist;
	memset(req, 0, sizeof(*req));
	if (too_big || len > INPUT_MAX) {
		*msg = "the request body is over 64 KiB";
		return 413;
	}
	if (!http_valid_name(device, VMAC_NAME_MAX)) {
		*msg = "no such device";
		return 404;
	}
	root = json_loadb(body ? body : "", len, 0, &jerr);
	name = json_object_get(root, "name");
	value = json_object_get(root, "value");
	persist = json_object_get(root, "persist");
	if (!json_is_object(root) || !json_is_string(name) || (persist && !json_is_boolean(persist)) ||
	    !http_valid_name(json_string_value(name), VMAC_DRIVER_NAME_MAX) ||
	    (value && !json_is_string(value) && !json_is_number(value) && !json_is_boolean(value) &&
	     !json_is_null(value)) ||
	    (json_is_string(value) && strlen(json_string_value(value)) > VMAC_DRIVER_STR_MAX)) {
		json_decref(root);
		*msg = "expected {\"name\": NAME, \"value\": a number, string (at most 63 bytes), "
		       "boolean or null, \"persist\": true or false (optional)}";
		return 400;
	}
	snprintf(req->device, sizeof(req->device), "%s", device);
	snprintf(req->name, sizeof(req->name), "%s", json_string_value(name));
	if (json_is_string(value)) {
		req->value.type = VMAC_VALUE_STRING;
		snprintf(req->value.str, sizeof(req->value.str), "%s", json_string_value(value));
	} else if (json_is_number(value)) {
		req->value.type = VMAC_VALUE_NUMBER;
		req->value.number = json_number_value(value);
	} else if (json_is_boolean(value)) {
		req->value.type = VMAC_VALUE_BOOL;
		req->value.number = json_is_true(value);
	} else {
		req->value.type = VMAC_VALUE_NONE; /* a command without a value */
	}
	req->persist = json_is_true(persist);
	json_decref(root);
	if (req->persist && req->value.type == VMAC_VALUE_NONE) {
		*msg = "a value to persist is needed";
		return 400;
	}
	return 0;
}

unsigned http_parse_cycle(const char *device, const char *body, size_t len, int too_big,
                          struct vmac_bus_input_request *req, const char **msg)
{
	static const char *const actions[] = {"start", "pause", "resume", "cancel"};
	json_error_t jerr;
	json_t *root, *action, *program;
	unsigned i;
	memset(req, 0, sizeof(*req));
	if (too_big || len > INPUT_MAX) {
		*msg = "the request body is over 64 KiB";
		return 413;
	}
	root = json_loadb(body ? body : "", len, 0, &jerr);
	action = json_object_get(root, "action");
	program = json_object_get(root, "program");
	for (i = 0; i < 4 && !(json_is_string(action) && strcmp(json_string_value(action), actions[i]) == 0); i++)
		;
	if (i == 4 || (program && (i != 0 || !json_is_string(program) ||
	                           strlen(json_string_value(program)) > VMAC_DRIVER_STR_MAX))) {
		json_decref(root);
		*msg = "expected {\"action\": \"start\", \"pause\", \"resume\" or \"cancel\", "
		       "\"program\": a programme's name (start only, optional)}";
		return 400;
	}
	snprintf(req->device, sizeof(req->device), "%s", device);
	snprintf(req->name, sizeof(req->name), "%s", actions[i]);
	if (program) {
		req->value.type = VMAC_VALUE_STRING;
		snprintf(req->value.str, sizeof(req->value.str), "%s", json_string_value(program));
	}
	json_decref(root);
	return 0;
}

int http_parse_probation(const char *arg, double default_s, unsigned *ms, double *s)
{
	char *end;
	*s = default_s;
	if (arg) {
		*s = strtod(arg, &end);
		if (!*arg || *end || !(*s >= 0 && *s <= 86400))
			return -1;
	}
	*ms = (unsigned)(*s * 1000 + 0.5);
	return 0;
}

int http_parse_id(const char *arg, long long *id)
{
	char *end;
	*id = arg ? strtoll(arg, &end, 10) : 0;
	return !arg || !*arg || *end || *id < 1 ? -1 : 0;
}

int http_parse_event_log(const char *after_arg, const char *limit_arg, unsigned long long *after, long *limit,
                         const char **msg)
{
	char *end;
	*after = 0;
	*limit = 100;
	if (after_arg) {
		*after = strtoull(after_arg, &end, 10);
		if (!*after_arg || *end || after_arg[0] == '-') {
			*msg = "after must be an event's seq (a whole number)";
			return -1;
		}
	}
	if (limit_arg) {
		*limit = strtol(limit_arg, &end, 10);
		if (!*limit_arg || *end || *limit < 1 || *limit > 1000) {
			*msg = "limit must be 1..1000";
			return -1;
		}
	}
	return 0;
}

int http_parse_events_from(const char *after_arg, const char *resume, unsigned long long *seq)
{
	const char *from = resume ? resume : after_arg;
	char *end;
	*seq = 0;
	if (from) {
		errno = 0;
		*seq = strtoull(from, &end, 10);
		if (errno || end == from || *end)
			return -1;
	}
	return 0;
}

/* Every byte of s that is not part of well-formed UTF-8 made '?': JSON
 * carries only UTF-8, and jansson refuses anything else, which dropped the
 * whole line from the answer (found by tests/fuzz/fuzz_http.c). The
 * console echoes what it was sent, any bytes. */
static void utf8_clean(char *s)
{
	unsigned char *p = (unsigned char *)s;
	while (*p) {
		size_t n = *p < 0x80             ? 1
		           : (*p & 0xE0) == 0xC0 ? 2
		           : (*p & 0xF0) == 0xE0 ? 3
		           : (*p & 0xF8) == 0xF0 ? 4
		                                 : 0;
		unsigned long cp = n == 1 ? *p : *p & (0x7Fu >> n);
		size_t i;
		for (i = 1; i < n && (p[i] & 0xC0) == 0x80; i++) /* stops at the NUL too */
			cp = cp << 6 | (p[i] & 0x3F);
		if (n == 0 || i < n || (n == 2 && cp < 0x80) || (n == 3 && cp < 0x800) ||
		    (n == 4 && (cp < 0x10000 || cp > 0x10FFFF)) || (cp >= 0xD800 && cp <= 0xDFFF)) {
			*p++ = '?'; /* not the start of a sequence, cut short, overlong or no code point */
			continue;
		}
		p += n;
	}
}

json_t *http_console_answer(const struct vmac_console_ops *ops, void (*new_line)(void *ctx), const char *body)
{
	char answer[4096], errors[8192];
	json_t *lines = json_array();
	const char *p = body ? body : "";
	int nerr = 0;
	while (*p) {
		size_t n = strcspn(p, "\n");
		char *line = strndup(p, n), *e, *save = NULL;
		if (line) {
			json_t *errs = json_array();
			if (new_line)
				new_line(ops->ctx);
			nerr += vmac_console_line(ops, line, answer, sizeof(answer), errors, sizeof(errors));
			utf8_clean(answer);
			utf8_clean(errors);
			for (e = strtok_r(errors, "\n", &save); e; e = strtok_r(NULL, "\n", &save))
				json_array_append_new(errs, json_string(e));
			if (strspn(line, " \t\r") < n)
				json_array_append_new(lines, json_pack("{s:s, s:o}", "answer", answer, "errors", errs));
			else
				json_decref(errs);
			free(line);
		}
		p += n;
		if (*p)
			p++;
	}
	return json_pack("{s:o, s:i}", "lines", lines, "errors", nerr);
}

json_t *http_manifest_json(const char *text)
{
	json_error_t jerr;
	/* A driver's strings may hold NUL bytes, which the description keeps
	 * as \u0000: without JSON_ALLOW_NUL such a manifest was a 500 (found by
	 * tests/fuzz/fuzz_manifest.c). */
	return json_loads(text, JSON_ALLOW_NUL, &jerr);
}
