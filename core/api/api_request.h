/* The HTTP API's pure parts: the table of its routes, which endpoint a
 * request is for and the scope it needs, and what its body and arguments
 * say. No libmicrohttpd, no bus, no store: http.c and the api_*.c files
 * call these and do the rest, and tests/fuzz/fuzz_http.c calls them
 * directly (docs/TESTING.md, "Fuzzing"). Names carry the prefix http_, as
 * in http_internal.h. */
#ifndef VMAC_API_REQUEST_H
#define VMAC_API_REQUEST_H

#include <jansson.h>
#include <stddef.h>

#include "../host/bus.h"
#include "../store/store.h"
#include "console.h"

/* Every route of the API (docs/API.md), declared once:
 *
 *   X(ENDPOINT, METHOD, PATTERN, SCOPE, AUDIT, HANDLER)
 *
 * METHOD is "GET" (HEAD too) or "POST". PATTERN is the path, in which one
 * segment may be NAME (a device's or driver's name: http_valid_name, so
 * never "." or ".."), ID (a name of digits only) or, last, FILE (the rest
 * of the path, whatever it holds). SCOPE is the token the route takes
 * (VMAC_SCOPE_NONE: none). AUDIT is the type of the audit event every
 * request of the route makes (core/host/audit.h; docs/API.md "Audit
 * trail"): every POST changes something and has one; NULL for a read,
 * audited only when its token is refused. HANDLER is the function of http_internal.h that
 * answers it; only http.c reads that column, so this header and
 * api_request.c stay free of libmicrohttpd. From this list api_request.c
 * makes http_routes[] (below), http.c its handlers indexed the same way,
 * and GET /api its list of endpoints; tests/fuzz/fuzz_http.c checks that
 * every row routes back to itself. No path matches two rows (a NAME holds
 * no slash), so the order is only the order GET /api lists them in. */
#define HTTP_ROUTES(X)                                                                                                 \
	X(HTTP_UI_PAGE, "GET", "/", VMAC_SCOPE_NONE, NULL, http_ui)                                                    \
	X(HTTP_UI, "GET", "/ui/FILE", VMAC_SCOPE_NONE, NULL, http_ui)                                                  \
	X(HTTP_HEALTH, "GET", "/api/health", VMAC_SCOPE_NONE, NULL, http_health)                                       \
	X(HTTP_INDEX, "GET", "/api", VMAC_SCOPE_READ, NULL, http_index)                                                \
	X(HTTP_WHOAMI, "GET", "/api/whoami", VMAC_SCOPE_READ, NULL, http_whoami)                                       \
	X(HTTP_STATUS, "GET", "/api/status", VMAC_SCOPE_READ, NULL, http_status)                                       \
	X(HTTP_LIVE, "GET", "/api/live", VMAC_SCOPE_READ, NULL, http_live_stream)                                      \
	X(HTTP_SCHEDULE, "GET", "/api/schedule", VMAC_SCOPE_READ, NULL, http_schedule)                                 \
	X(HTTP_EVENTS, "GET", "/api/events", VMAC_SCOPE_READ, NULL, http_events_stream)                                \
	X(HTTP_EVENT_LOG, "GET", "/api/events/log", VMAC_SCOPE_READ, NULL, http_event_log)                             \
	X(HTTP_DEVICES, "GET", "/api/devices", VMAC_SCOPE_READ, NULL, http_devices)                                    \
	X(HTTP_DEVICE, "GET", "/api/devices/NAME", VMAC_SCOPE_READ, NULL, http_devices)                                \
	X(HTTP_HISTORY, "GET", "/api/devices/NAME/history", VMAC_SCOPE_READ, NULL, http_device_history)                \
	X(HTTP_INPUT, "POST", "/api/devices/NAME/input", VMAC_SCOPE_OPERATE, "input", http_device_input)               \
	X(HTTP_CYCLE, "POST", "/api/devices/NAME/cycle", VMAC_SCOPE_OPERATE, "cycle", http_device_cycle)               \
	X(HTTP_RECORD, "POST", "/api/devices/NAME/record", VMAC_SCOPE_OPERATE, "record", http_record)                  \
	X(HTTP_CONSOLE, "POST", "/api/console", VMAC_SCOPE_READ, "console", http_console)                              \
	X(HTTP_RECORDINGS, "GET", "/api/recordings", VMAC_SCOPE_READ, NULL, http_recordings)                           \
	X(HTTP_RECORDING, "GET", "/api/recordings/ID", VMAC_SCOPE_READ, NULL, http_recording)                          \
	X(HTTP_SITE, "GET", "/api/site", VMAC_SCOPE_READ, NULL, http_site)                                             \
	X(HTTP_DRIVERS, "GET", "/api/drivers", VMAC_SCOPE_READ, NULL, http_driver_versions)                            \
	X(HTTP_DRIVER, "GET", "/api/drivers/NAME", VMAC_SCOPE_READ, NULL, http_driver_versions)                        \
	X(HTTP_MANIFEST, "GET", "/api/drivers/NAME/manifest", VMAC_SCOPE_READ, NULL, http_driver_manifest)             \
	X(HTTP_UPLOAD, "POST", "/api/drivers/NAME", VMAC_SCOPE_DEPLOY, "reload", http_driver_upload)                   \
	X(HTTP_ACTIVATE, "POST", "/api/drivers/NAME/activate", VMAC_SCOPE_DEPLOY, "activate", http_driver_activate)    \
	X(HTTP_ROLLBACK, "POST", "/api/drivers/NAME/rollback", VMAC_SCOPE_DEPLOY, "rollback", http_driver_rollback)    \
	X(HTTP_BOARDS, "GET", "/api/boards", VMAC_SCOPE_READ, NULL, http_boards)                                       \
	X(HTTP_BOARD_ENROLL, "POST", "/api/boards/NAME", VMAC_SCOPE_DEPLOY, "board", http_board_enroll)                \
	X(HTTP_BOARD_REMOVE, "POST", "/api/boards/NAME/remove", VMAC_SCOPE_DEPLOY, "board", http_board_remove)         \
	X(HTTP_METRICS, "GET", "/metrics", VMAC_SCOPE_READ, NULL, http_metrics)

#define HTTP_ROUTE_ENUM(endpoint, method, pattern, scope, audit, handler) endpoint,

/* The rows of HTTP_ROUTES, then what matches none of them. */
enum http_endpoint {
	HTTP_ROUTES(HTTP_ROUTE_ENUM) HTTP_ROUTE_COUNT,
	HTTP_NOT_FOUND = HTTP_ROUTE_COUNT, /* no row (after the token is checked): 404 */
	HTTP_BAD_METHOD,                   /* not GET, HEAD or POST: 405, no token */
};

/* A row of HTTP_ROUTES without its handler: http_routes[endpoint]. */
struct http_route {
	const char *method;
	const char *pattern;
	enum vmac_scope need;
	const char *audit; /* the audit event's type; NULL: a read */
};

extern const struct http_route http_routes[HTTP_ROUTE_COUNT];

/* What http_route_find made of a request. */
struct http_match {
	enum http_endpoint endpoint;
	enum vmac_scope need;         /* the token's scope it takes; VMAC_SCOPE_NONE: no token */
	char name[VMAC_NAME_MAX + 2]; /* the path's NAME or ID, else "" */
	const char *file;             /* the path's FILE (points into it), else NULL */
};

/* A request body other than a driver's upload is at most this long. */
#define INPUT_MAX 65536

/* s is 1..max bytes of [A-Za-z0-9._-]: a device's or driver's name. */
int http_valid_name(const char *s, size_t max);

/* The route of method and url (the path, without its query): the first
 * row of HTTP_ROUTES that matches, HTTP_NOT_FOUND (scope read), or
 * HTTP_BAD_METHOD (scope none). */
void http_route_find(const char *method, const char *url, struct http_match *m);

/* POST /api/devices/DEVICE/input, its body {"name": , "value": ,
 * "persist": } (len bytes; too_big: it was cut at the limit) into req:
 * 0, or the HTTP status to answer (400, 404, 413) with *msg saying why. */
unsigned http_parse_input(const char *device, const char *body, size_t len, int too_big,
                          struct vmac_bus_input_request *req, const char **msg);
/* POST /api/devices/DEVICE/cycle {"action": , "program": } into req (the
 * command of that name): 0, or 400 or 413 with *msg. */
unsigned http_parse_cycle(const char *device, const char *body, size_t len, int too_big,
                          struct vmac_bus_input_request *req, const char **msg);

/* ?probation=S (arg NULL: default_s) into *s and *ms: 0, or -1 (400). */
int http_parse_probation(const char *arg, double default_s, unsigned *ms, double *s);
/* ?id=N of activate: 0, or -1 (400). */
int http_parse_id(const char *arg, long long *id);
/* GET /api/events/log ?after=SEQ &limit=N (either NULL: absent): 0, or
 * -1 with *msg (400). */
int http_parse_event_log(const char *after_arg, const char *limit_arg, unsigned long long *after, long *limit,
                         const char **msg);
/* GET /api/events: Last-Event-ID (resume) or else ?after=SEQ: 0 with *seq
 * (0 when neither), or -1 (400). */
int http_parse_events_from(const char *after_arg, const char *resume, unsigned long long *seq);

/* POST /api/console: every line of body answered through ops (new_line(ctx),
 * if given, before each), as {"lines": [{"answer": , "errors": [...]}],
 * "errors": N}; blank lines have no entry. NULL when out of memory. */
json_t *http_console_answer(const struct vmac_console_ops *ops, void (*new_line)(void *ctx), const char *body);

/* GET /api/drivers/NAME/manifest: a driver's declarations
 * (vmac_driver_describe) as the JSON the API answers with; NULL if text is
 * not JSON. Strings may hold NUL bytes (\u0000), as a driver's may. */
json_t *http_manifest_json(const char *text);

#endif
