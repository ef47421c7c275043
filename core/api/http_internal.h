/* The HTTP server's insides, shared by http.c and the api_*.c files that
 * serve its endpoints; the rest of the host sees only http.h. Names shared
 * between the files carry the prefix http_. */
#ifndef VMAC_HTTP_INTERNAL_H
#define VMAC_HTTP_INTERNAL_H

#include "api_request.h"
#include "http.h"

#include <jansson.h>
#include <microhttpd.h>
#include <stdatomic.h>

#include "../common/version.h"
#include "../reload/deploy.h"

#define STATUS_EVENTS 20

/* Failed attempts (guard.c): at most FAIL_LIMIT per key (a token id, or
 * the client's address for a request without a token of the right shape)
 * in FAIL_WINDOW_S; past that, that key's failing requests get 429 until
 * the window ends. A token has 256 random bits: the lock-out only slows a
 * guesser down (a token of the right shape is still checked against the
 * store first, so that a valid one always gets in). */
#define FAIL_LIMIT 10

#define FAIL_WINDOW_S 60.0

#define GUARD_FAIL_SLOTS 1024

#define HTTP_CONNECTIONS_MAX 256 /* libmicrohttpd's connection limit */

#define GUARD_CONNS HTTP_CONNECTIONS_MAX

/* Answers counted by status code (GET /metrics), 100..599. */
#define HTTP_CODE_FIRST 100
#define HTTP_CODES 500

/* Deploys counted by action (upload, activate, rollback: the order of
 * struct deploy_ask in api_drivers.c) and result (ok, refused, failed). */
#define HTTP_DEPLOY_ACTIONS 3
#define HTTP_DEPLOY_RESULTS 3

/* metrics_http, the listener without a token (api_metrics.c): a
 * connection idle this long is closed; at most this many connections, and
 * this many from one address. */
#define HTTP_METRICS_TIMEOUT_S 10
#define HTTP_METRICS_CONNECTIONS 16
#define HTTP_METRICS_PER_ADDRESS 4

struct guard_fail {
	char key[80]; /* "token ID" or "address A"; "" = unused */
	double window_start;
	unsigned fails;
	int said; /* its lock-out is in the events */
};

/* Where a connection is: receiving a request's headers, its body,
 * answering (a stream may answer for hours), or idle: new or kept alive
 * between two requests, no byte of the next request yet (GUARD_HEADERS
 * from the first). */
enum guard_phase { GUARD_HEADERS, GUARD_BODY, GUARD_ANSWERING, GUARD_IDLE };
/* A connection idle this long is closed, quietly: an idle
 * client is not an attack (libmicrohttpd's own timeout, reset by every
 * byte, is the same). */
#define HTTP_IDLE_TIMEOUT_S 30

struct guard_conn {
	int fd;            /* -1: unused */
	double since;      /* when its phase began */
	double idle_since; /* when it was last idle (new, or its last answer done) */
	enum guard_phase phase;
	uint64_t idle_bytes; /* bytes the kernel had received when its last request was in, 0 when none was
	                        (GUARD_IDLE's baseline) */
	uint64_t idle_sent;  /* bytes the kernel had sent when it went idle */
	char addr[48];
};

struct http_guard {
	pthread_mutex_t lock; /* the tables below; the reaper waits on wake */
	pthread_cond_t wake;
	pthread_t reaper;
	int running, stop;
	struct guard_fail fails[GUARD_FAIL_SLOTS];
	int full_said; /* "every entry is locked" is in the events */
	struct guard_conn conns[GUARD_CONNS];
	double header_timeout_s, body_timeout_s;
	unsigned long long cut_unsaid; /* connections cut off since the last event */
	double cut_said_at;
};

/* ---- GET /api/devices/NAME/history: the plots' history (history.c) ---- */

#define HISTORY_PERIOD_MS 500 /* a sample every half second: twice the live stream's period */
#define HISTORY_SAMPLES 240   /* the last 120 s */
#define HISTORY_SERIES 8      /* plotted variables a machine keeps, the first of ui.plots */

struct history_machine;

struct http_history {
	pthread_mutex_t lock; /* machines and what they point at; the sampler waits on wake */
	pthread_cond_t wake;
	pthread_t thread;
	int inited, running, stop;
	unsigned cap;                      /* max_devices */
	struct history_machine **machines; /* cap entries; NULL: unused */
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
	char *tls_cert, *tls_key;              /* PEM texts while the daemon runs (TLS) */
	pthread_mutex_t live_lock;             /* the live streams' shared message: */
	double live_at;                        /* when it was built */
	char *live_json;                       /* the newest status as JSON */
	_Atomic int stopping;                  /* event streams end */
	struct http_guard guard;               /* lock-outs and deadlines (guard.c) */
	struct http_history history;           /* the plots' history (history.c) */
	struct vmac_site *_Atomic site;        /* GET /api/site (api_site.c); NULL: MQTT off */
	_Atomic uint64_t answered[HTTP_CODES]; /* answers by status code - HTTP_CODE_FIRST */
	_Atomic uint64_t deploys[HTTP_DEPLOY_ACTIONS][HTTP_DEPLOY_RESULTS];
	struct MHD_Daemon *metrics_daemon; /* metrics_http (NULL: none) */
	unsigned metrics_port;
	struct vmac_deploy_trust trust; /* deploy_keys (core/reload/deploy.h) */
};

/* A connection's request body (POST), kept up to BODY_MAX bytes (a bundle
 * upload); other requests take at most INPUT_MAX (api_request.h). */
#define BODY_MAX VMAC_BUNDLE_MAX

#define INPUT_TIMEOUT_MS 2000 /* the bus thread answers within a tick; this bounds a stuck host */

/* The token a request came with, as the audit trail names it. */
enum http_token_state {
	HTTP_TOKEN_ABSENT,    /* no Authorization header: "no token" */
	HTTP_TOKEN_MALFORMED, /* a header, but not a token of the right shape: "a malformed token" */
	HTTP_TOKEN_INVALID,   /* vmac_ID_SECRET the store does not take: "token ID (not valid)" */
	HTTP_TOKEN_VALID,     /* "token ID "NAME" (SCOPE)" */
};

/* What the audit trail is told of a request (audit.c): the token it came
 * with (guard.c), and what its handler adds to what the route says. */
struct http_audit_note {
	const char *type; /* the audit event's type: the route's AUDIT, "lockout", or as a handler says */
	enum http_token_state token;
	char token_id[VMAC_TOKEN_ID_LEN + 1];
	char token_name[VMAC_TOKEN_NAME_MAX + 1];
	enum vmac_scope token_scope; /* a valid token's, whether or not it was enough */
	char key[80];                /* whose refusal it is: the guard's key, "token ID" or "address A" */
	int refused;                 /* its token did not get in (401, 403, 429) */
	char lockout[240];           /* this request locked its key out: what the guard says of it */
	char device[VMAC_NAME_MAX + 1];
	char detail[400];
	int nothing; /* nothing to audit: it changed nothing and was not refused (a console of reads) */
};

/* A request as its handler gets it: the body, the route and the scope of
 * the token sent. audit points at note: a handler that gets k as const
 * may still tell the audit trail more (http_audit_detail). */
struct conn {
	char *body;
	size_t len;
	int too_big;
	struct http_match route; /* route.name: the path's NAME or ID; "" when it has none */
	enum vmac_scope scope;   /* the token's; VMAC_SCOPE_NONE for a route that takes none */
	struct http_audit_note *audit;
	struct http_audit_note note;
};

/* The HANDLER of a row of HTTP_ROUTES (api_request.h): answers k on c. */
typedef enum MHD_Result http_handler(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k);

/* ---- POST /api/console: the line console ---- */

struct console_ctx {
	struct vmac_http *h;
	const struct conn *k; /* the request: its writes are told to the audit trail */
	int fresh;            /* the status was read for this line */
	int wrote;            /* a submessage of the body wrote (:, >, !) */
	struct vmac_device_status dev;
};

/* ---- GET /api/events: Server-Sent Events ---- */

#define SSE_WAIT_MS 1000 /* how often a waiting stream looks at `stopping` */

#define SSE_KEEPALIVE_S 15.0 /* a comment line when nothing else was sent */

#define SSE_BATCH 8

struct sse {
	struct vmac_http *h;
	uint64_t after; /* the last event sent */
	double last_sent;
	size_t len, off;
	char buf[SSE_BATCH * (2 * VMAC_EVENT_TEXT + 256)];
};

/* ---- GET /api/live: the status pushed, for the web UI ---- */

#define LIVE_PERIOD_MS 250 /* how often a client gets the latest status (if it changed) */

struct live {
	struct vmac_http *h;
	double last_sent, next;
	char *text; /* what is being sent */
	size_t len, off;
	char *last; /* the last status sent (not sent again unchanged) */
};

/* http.c */
double http_mono_s(void);
enum MHD_Result http_reply(struct MHD_Connection *c, unsigned code, json_t *body);
/* The same with one extra header. */
enum MHD_Result http_reply_header(struct MHD_Connection *c, unsigned code, json_t *body, const char *header,
                                  const char *value);
json_t *http_error_body(const char *msg);
/* The "error" of the last answer of 400 and up this thread queued through
 * http_reply since http_last_error_clear ("" for none): the why of a
 * refusal in the audit trail (a request is answered on one thread). */
const char *http_last_error(void);
void http_last_error_clear(void);
/* The answer of the request on c has ended: counted by its status code (MHD_OPTION_NOTIFY_COMPLETED). */
void http_count_answer(struct vmac_http *h, struct MHD_Connection *c);

/* guard.c: the scope of the request's token when it has at least the
 * route's k->route.need; else VMAC_SCOPE_NONE (0), with the answer (401,
 * 403 or 429) queued into *ret. Either way the token, and a lock-out this
 * request caused, are in k->audit. */
enum vmac_scope http_authorized(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k,
                                enum MHD_Result *ret);
/* The client's address (IPv4 or IPv6) into out, "?" when unknown. */
void http_client_address(struct MHD_Connection *c, char *out, size_t len);
/* MHD_OPTION_NOTIFY_CONNECTION: a connection's deadlines start and end. */
void http_guard_notify(void *cls, struct MHD_Connection *c, void **socket_context,
                       enum MHD_ConnectionNotificationCode code);
/* The connection of c is now in phase (its deadline counts from now). */
void http_guard_phase(struct MHD_Connection *c, struct vmac_http *h, enum guard_phase phase);
/* The reaper thread: 0, or a negative errno. */
int http_guard_start(struct vmac_http *h);
void http_guard_stop(struct vmac_http *h);
enum MHD_Result http_stream_response(struct MHD_Connection *c, MHD_ContentReaderCallback read, void *cls,
                                     MHD_ContentReaderFreeCallback done);

/* audit.c: the audit trail of the API (docs/API.md, "Audit trail").
 * Once per request, after its answer was queued: an audit event when the
 * request changes something (its route has an AUDIT type, every POST) or
 * its token was refused, with the route, the status, the token's id,
 * name and scope, the client's address and the handler's detail. */
void http_audit_request(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k, const char *method,
                        const char *url);
/* A handler's word on its request, added to what the route says (several
 * calls are joined by a blank): "washer-1.door:true", "washer 1.1.0 (id
 * 3)". At most 400 bytes in all. */
void http_audit_detail(const struct conn *k, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* The machine, driver or board the event is about, when the path does not
 * name it (the console). */
void http_audit_device(const struct conn *k, const char *device);
/* Another type than the route's (an input that persists is a "param"). */
void http_audit_type(const struct conn *k, const char *type);
/* The request changed nothing and asked to change nothing (a console of
 * reads only): no event, unless its token was refused. */
void http_audit_nothing(const struct conn *k);

/* history.c: the sampler thread, started once the status copy is
 * allocated: 0, or a negative errno. Stop frees every machine's history. */
int http_history_start(struct vmac_http *h);
void http_history_stop(struct vmac_http *h);

/* The handlers of HTTP_ROUTES, by the file they are in. */
/* http.c */
http_handler http_ui, http_health, http_index, http_whoami;
/* api_devices.c */
http_handler http_status, http_devices, http_device_input, http_device_cycle, http_console, http_live_stream;
/* history.c */
http_handler http_device_history;
/* api_schedule.c */
http_handler http_schedule;
/* api_events.c */
http_handler http_events_stream, http_event_log;
/* api_recordings.c */
http_handler http_recordings, http_recording, http_record;
/* api_site.c */
http_handler http_site;
/* api_drivers.c */
http_handler http_driver_versions, http_driver_manifest, http_driver_upload, http_driver_activate, http_driver_rollback;
/* api_boards.c */
http_handler http_boards, http_board_enroll, http_board_remove;
/* api_metrics.c */
http_handler http_metrics;
/* The text of GET /metrics (malloc'd, *len bytes), or NULL when out of memory. */
char *http_metrics_text(struct vmac_http *h, size_t *len);
/* Serve GET /metrics without a token on listen ("ADDR:PORT", metrics_http):
 * 0, or -1 with err. vmac_http_stop stops it. */
int http_metrics_listen(struct vmac_http *h, const char *listen, char *err, size_t errlen);

#endif
