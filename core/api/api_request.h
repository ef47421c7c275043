/* The HTTP API's pure parts: which endpoint a request is for and the scope
 * it needs, and what its body and arguments say. No libmicrohttpd, no bus,
 * no store: http.c and the api_*.c files call these and do the rest, and
 * tests/fuzz/fuzz_http.c calls them directly (docs/TESTING.md, "Fuzzing").
 * Names carry the prefix http_, as in http_internal.h. */
#ifndef VMAC_API_REQUEST_H
#define VMAC_API_REQUEST_H

#include <jansson.h>
#include <stddef.h>

#include "../host/bus.h"
#include "../store/store.h"
#include "console.h"

/* Every request a client can make (docs/API.md). */
enum http_endpoint {
	HTTP_BAD_METHOD, /* not GET, HEAD or POST: 405 */
	HTTP_UI,         /* GET / and /ui/FILE: the web UI's files, no token */
	HTTP_HEALTH,     /* GET /api/health, no token */
	HTTP_INPUT,      /* POST /api/devices/NAME/input */
	HTTP_CYCLE,      /* POST /api/devices/NAME/cycle */
	HTTP_RECORD,     /* POST /api/devices/NAME/record */
	HTTP_ROLLBACK,   /* POST /api/drivers/NAME/rollback */
	HTTP_ACTIVATE,   /* POST /api/drivers/NAME/activate */
	HTTP_UPLOAD,     /* POST /api/drivers/NAME */
	HTTP_CONSOLE,    /* POST /api/console */
	HTTP_DEVICES,    /* GET /api/devices */
	HTTP_DEVICE,     /* GET /api/devices/NAME */
	HTTP_DRIVERS,    /* GET /api/drivers */
	HTTP_DRIVER,     /* GET /api/drivers/NAME */
	HTTP_STATUS,     /* GET /api/status */
	HTTP_LIVE,       /* GET /api/live */
	HTTP_WHOAMI,     /* GET /api/whoami */
	HTTP_MANIFEST,   /* GET /api/drivers/NAME/manifest */
	HTTP_EVENT_LOG,  /* GET /api/events/log */
	HTTP_EVENTS,     /* GET /api/events */
	HTTP_RECORDINGS, /* GET /api/recordings */
	HTTP_RECORDING,  /* GET /api/recordings/ID */
	HTTP_SITE,       /* GET /api/site */
	HTTP_INDEX,      /* GET /api */
	HTTP_NOT_FOUND,  /* anything else (after the token is checked): 404 */
};

struct http_route {
	enum http_endpoint endpoint;
	enum vmac_scope need;         /* the token's scope it takes; VMAC_SCOPE_NONE: no token */
	char name[VMAC_NAME_MAX + 2]; /* the device or driver NAME in the path, else "" */
	const char *file;             /* HTTP_UI: the file's name (points into url or is static) */
};

/* s is 1..max bytes of [A-Za-z0-9._-]: a device's or driver's name. */
int http_valid_name(const char *s, size_t max);

/* The route of method and url (the path, without its query). */
void http_route(const char *method, const char *url, struct http_route *r);

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
