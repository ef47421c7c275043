/* The audit trail (docs/API.md, "Audit trail"): who changed what. Every
 * state-changing request, whether it came through the HTTP API
 * (core/api/audit.c), an MQTT command (core/mqtt/) or
 * `vmac token` (the store's audit outbox, taken by the main loop), becomes
 * one event of kind "audit" in the host's event log, in one format:
 *
 *   TYPE by WHO from WHERE: WHAT -> RESULT[ (WHY)]
 *
 *   input by token 0123456789abcdef "alice" (operate) from 127.0.0.1:
 *       POST /api/devices/washer-1/input washer-1.door:true -> 200
 *
 * TYPE is one of vmac_audit_types; WHO says who asked (a token, no token,
 * an MQTT connection, a user of the host's machine); WHERE is one word (an
 * IPv4 or IPv6 address, mqtt://HOST:PORT, local); WHAT is the request and
 * its detail; RESULT an HTTP status or a word (ok, refused, ...); WHY the
 * reason of a refusal, or a note. Refusals (a RESULT of 400 and up, or a
 * word other than ok) pass a rate limit first, kept in the event log so
 * that every thread that can add an event goes through the same one: in a
 * window of VMAC_AUDIT_WINDOW_S at most VMAC_AUDIT_REFUSED_PER_KEY
 * refusals of one key (a token id, a client address) and
 * VMAC_AUDIT_REFUSED_PER_WINDOW in all are said, and at most
 * VMAC_AUDIT_LOCKOUTS_PER_WINDOW lock-outs; when the window ends, one
 * event of type "refused" says how many more there were and from whom.
 * A flood of bad requests costs at most
 * VMAC_AUDIT_REFUSED_PER_WINDOW + VMAC_AUDIT_LOCKOUTS_PER_WINDOW + 1
 * events a window. Any thread; never the bus thread (it takes a lock). */
#ifndef VMAC_AUDIT_H
#define VMAC_AUDIT_H

#include <pthread.h>
#include <stddef.h>

struct vmac_event_log;
struct vmac_bus_input_request;

#define VMAC_AUDIT_WINDOW_S 10.0
#define VMAC_AUDIT_REFUSED_PER_KEY 10
#define VMAC_AUDIT_REFUSED_PER_WINDOW 30
#define VMAC_AUDIT_LOCKOUTS_PER_WINDOW 10
#define VMAC_AUDIT_KEYS 16 /* keys counted by name in a window; more are counted together */
#define VMAC_AUDIT_KEY_MAX 80

/* The types of audit event, which are also the event_types of the Home
 * Assistant event entity (docs/MQTT.md). */
#define VMAC_AUDIT_TYPE_COUNT 14
extern const char *const vmac_audit_types[VMAC_AUDIT_TYPE_COUNT];

/* One request, as the code that served it tells it. Every string but why
 * and key is needed. */
struct vmac_audit {
	const char *type;   /* one of vmac_audit_types */
	const char *who;    /* token 0123456789abcdef "alice" (operate), no token, mqtt client "c" ... */
	const char *where;  /* one word: 127.0.0.1, ::1, mqtt://broker:1883, local */
	const char *what;   /* POST /api/devices/washer-1/input washer-1.door:true */
	const char *result; /* "200", "ok", "refused" ... */
	const char *why;    /* NULL, or the reason of a refusal or a note */
	const char *device; /* the event's device: the machine, driver or board it is about ("": none) */
	const char *key;    /* a refusal: whose, for the rate limit ("address 10.0.0.5"); NULL: not a refusal */
	int lockout;        /* a refusal that locked its key out (counted apart from the others) */
};

/* The rate limit's state (in struct vmac_event_log). */
struct vmac_audit_limit {
	pthread_mutex_t lock;
	double window_start_s; /* CLOCK_MONOTONIC; 0: no window open */
	unsigned refused_said, lockouts_said;
	unsigned long long unsaid, unsaid_lockouts, unsaid_other; /* other: of keys past the table */
	struct {
		char key[VMAC_AUDIT_KEY_MAX];
		unsigned said;
		unsigned long long unsaid;
	} keys[VMAC_AUDIT_KEYS];
	int nkeys;
};

void vmac_audit_limit_init(struct vmac_audit_limit *l);

/* a as the event's text (at most len - 1 bytes: WHAT is shortened, never
 * the result). */
void vmac_audit_text(const struct vmac_audit *a, char *out, size_t len);
/* a into log as an audit event, unless it is a refusal over the limit
 * (then counted for the window's summary). */
void vmac_audit_add(struct vmac_event_log *log, const struct vmac_audit *a);
/* The summary of a window that has ended, if it left refusals unsaid:
 * the main loop calls this on every service. */
void vmac_audit_flush(struct vmac_event_log *log);
/* The same at now_s (CLOCK_MONOTONIC seconds), for tests. */
void vmac_audit_add_at(struct vmac_event_log *log, const struct vmac_audit *a, double now_s);
void vmac_audit_flush_at(struct vmac_event_log *log, double now_s);

/* Operator input as the console writes it: DEVICE.NAME:VALUE,
 * DEVICE.NAME>VALUE (persisted) or DEVICE.NAME! (a command without a
 * value); a string of other characters than [A-Za-z0-9._+-] is quoted as
 * in JSON. */
void vmac_audit_input(const struct vmac_bus_input_request *req, char *out, size_t len);
/* The type of an audit event's text (its first word) into type: 0, or -1
 * when text does not begin with one of vmac_audit_types. */
int vmac_audit_type_of(const char *text, char *type, size_t len);

#endif
