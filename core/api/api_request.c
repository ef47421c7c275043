/* See api_request.h: routing, request bodies and arguments, and the
 * console's body, with nothing but text in and out. */
#include "api_request.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/name.h"
#include "http_internal.h"

int http_valid_name(const char *s, size_t max)
{
	return vmac_valid_name(s, max); /* core/common/name.h: never "." or ".." */
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
	return http_valid_name(name, VMAC_NAME_MAX);
}

/* "/api/drivers/NAME" SUFFIX */
static int driver_path(const char *url, const char *suffix, char *driver, size_t len)
{
	return named_path(url, "/api/drivers/", suffix, driver, len);
}

/* "/api/devices/NAME" SUFFIX */
static int device_path(const char *url, const char *suffix, char *device, size_t len)
{
	return named_path(url, "/api/devices/", suffix, device, len);
}

/* The order of the tests is the order of precedence: the web UI and the
 * health check need no token; input and cycles need operate, drivers
 * deploy; everything else, a 404 too, needs read. */
void http_route(const char *method, const char *url, struct http_route *r)
{
	int get = strcmp(method, "GET") == 0 || strcmp(method, "HEAD") == 0, post = strcmp(method, "POST") == 0;
	char *name = r->name;
	size_t len = sizeof(r->name);
	name[0] = 0;
	r->file = NULL;
	r->need = VMAC_SCOPE_READ;
	if (!get && !post) {
		r->endpoint = HTTP_BAD_METHOD;
		r->need = VMAC_SCOPE_NONE;
	} else if (get && (strcmp(url, "/") == 0 || strncmp(url, "/ui/", 4) == 0)) {
		r->endpoint = HTTP_UI;
		r->need = VMAC_SCOPE_NONE;
		r->file = strcmp(url, "/") == 0 ? "index.html" : url + 4;
	} else if (get && strcmp(url, "/api/health") == 0) {
		r->endpoint = HTTP_HEALTH;
		r->need = VMAC_SCOPE_NONE;
	} else if (post && device_path(url, "/input", name, len)) {
		r->endpoint = HTTP_INPUT;
		r->need = VMAC_SCOPE_OPERATE;
	} else if (post && device_path(url, "/cycle", name, len)) {
		r->endpoint = HTTP_CYCLE;
		r->need = VMAC_SCOPE_OPERATE;
	} else if (post && device_path(url, "/record", name, len)) {
		r->endpoint = HTTP_RECORD;
		r->need = VMAC_SCOPE_OPERATE;
	} else if (post && driver_path(url, "/rollback", name, len)) {
		r->endpoint = HTTP_ROLLBACK;
		r->need = VMAC_SCOPE_DEPLOY;
	} else if (post && driver_path(url, "/activate", name, len)) {
		r->endpoint = HTTP_ACTIVATE;
		r->need = VMAC_SCOPE_DEPLOY;
	} else if (post && driver_path(url, "", name, len)) {
		r->endpoint = HTTP_UPLOAD;
		r->need = VMAC_SCOPE_DEPLOY;
	} else if (post && strcmp(url, "/api/console") == 0)
		r->endpoint = HTTP_CONSOLE;
	else if (get && strcmp(url, "/api/devices") == 0)
		r->endpoint = HTTP_DEVICES;
	else if (get && device_path(url, "", name, len))
		r->endpoint = HTTP_DEVICE;
	else if (get && strcmp(url, "/api/drivers") == 0)
		r->endpoint = HTTP_DRIVERS;
	else if (get && driver_path(url, "", name, len))
		r->endpoint = HTTP_DRIVER;
	else if (get && strcmp(url, "/api/status") == 0)
		r->endpoint = HTTP_STATUS;
	else if (get && strcmp(url, "/api/live") == 0)
		r->endpoint = HTTP_LIVE;
	else if (get && strcmp(url, "/api/whoami") == 0)
		r->endpoint = HTTP_WHOAMI;
	else if (get && driver_path(url, "/manifest", name, len))
		r->endpoint = HTTP_MANIFEST;
	else if (get && strcmp(url, "/api/events/log") == 0)
		r->endpoint = HTTP_EVENT_LOG;
	else if (get && strcmp(url, "/api/events") == 0)
		r->endpoint = HTTP_EVENTS;
	else if (get && strcmp(url, "/api/recordings") == 0)
		r->endpoint = HTTP_RECORDINGS;
	else if (get && named_path(url, "/api/recordings/", "", name, len) &&
	         strspn(name, "0123456789") == strlen(name))
		r->endpoint = HTTP_RECORDING;
	else if (get && strcmp(url, "/api/site") == 0)
		r->endpoint = HTTP_SITE;
	else if (get && strcmp(url, "/api") == 0)
		r->endpoint = HTTP_INDEX;
	else
		r->endpoint = HTTP_NOT_FOUND;
	switch (r->endpoint) {
	case HTTP_INPUT:
	case HTTP_CYCLE:
	case HTTP_RECORD:
	case HTTP_ROLLBACK:
	case HTTP_ACTIVATE:
	case HTTP_UPLOAD:
	case HTTP_DEVICE:
	case HTTP_DRIVER:
	case HTTP_RECORDING:
	case HTTP_MANIFEST: break;
	default: name[0] = 0; /* a path that did not match may have left part of itself there */
	}
}

unsigned http_parse_input(const char *device, const char *body, size_t len, int too_big,
                          struct vmac_bus_input_request *req, const char **msg)
{
	json_error_t jerr;
	json_t *root, *name, *value, *persist;
	memset(req, 0, sizeof(*req));
	if (too_big || len > INPUT_MAX) {
		*msg = "the request body is over 64 KiB";
		return MHD_HTTP_CONTENT_TOO_LARGE;
	}
	if (!http_valid_name(device, VMAC_NAME_MAX)) {
		*msg = "no such device";
		return MHD_HTTP_NOT_FOUND;
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
		return MHD_HTTP_BAD_REQUEST;
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
		return MHD_HTTP_BAD_REQUEST;
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
		return MHD_HTTP_CONTENT_TOO_LARGE;
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
		return MHD_HTTP_BAD_REQUEST;
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
