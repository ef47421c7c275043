/* The host's event log: the last events (attached, dropped, driver errors,
 * missing drivers, malformed frames, audit: audit.h) kept in memory for the status API and
 * the event stream, echoed (vmacd: to stderr or the journal), and copied into the store by the main
 * thread (vmac_store_events_add). Written by the main thread (and by the API's and MQTT's threads:
 * the audit trail, audit.h), read by the HTTP threads. */
#ifndef VMAC_EVENTS_H
#define VMAC_EVENTS_H

#include <pthread.h>
#include <stdint.h>

#include "audit.h"
#include "bus.h"

#define VMAC_EVENT_LOG_SIZE 100
#define VMAC_EVENT_KINDS 48 /* kinds counted by name; the host has some 30 (docs/API.md, "events") */

struct vmac_event {
	uint64_t seq;    /* 1, 2, ... in order of recording */
	int64_t time_ns; /* CLOCK_REALTIME */
	char kind[24];
	char device[VMAC_NAME_MAX + 1];
	char text[VMAC_EVENT_TEXT];
};

/* How many events of one kind the log has taken since the host started. */
struct vmac_event_count {
	char kind[24];
	uint64_t count;
};

struct vmac_event_log {
	pthread_mutex_t lock;
	pthread_cond_t grew; /* broadcast on every add (CLOCK_MONOTONIC) */
	uint64_t next_seq;
	/* Each event, once recorded, is also handed to echo (outside the lock:
	 * vmacd writes it to stderr or the journal); NULL: not. */
	void (*echo)(void *ctx, const struct vmac_event *e);
	void *echo_ctx;
	struct vmac_event ring[VMAC_EVENT_LOG_SIZE];
	struct vmac_event_count kinds[VMAC_EVENT_KINDS]; /* in order of first sight; the last counts the rest */
	int nkinds;
	/* The audit trail's rate limit on refusals (audit.h): in the log, so
	 * that every thread that adds events goes through the same one. */
	struct vmac_audit_limit audit;
};

void vmac_event_log_init(struct vmac_event_log *log);
/* Number the events from seq on (after the ones a store already holds),
 * before the first is added. */
void vmac_event_log_start_at(struct vmac_event_log *log, uint64_t seq);
void vmac_event_log_add(struct vmac_event_log *log, const char *kind, const char *device, const char *text);
/* The same at time_ns (Unix time in ns: vmac test's events carry its virtual clock). */
void vmac_event_log_add_at(struct vmac_event_log *log, int64_t time_ns, const char *kind, const char *device,
                           const char *text);
/* The count of every kind of event taken so far (GET /metrics), in order of
 * first sight, into out (room for VMAC_EVENT_KINDS). Returns how many; a
 * kind past the first VMAC_EVENT_KINDS - 1 is counted as "other". */
int vmac_event_log_counts(struct vmac_event_log *log, struct vmac_event_count *out);
/* The seq the next event will have. */
uint64_t vmac_event_log_next_seq(struct vmac_event_log *log);
/* Copy the newest events, oldest first, into out (room for max). Returns how many. */
int vmac_event_log_latest(struct vmac_event_log *log, struct vmac_event *out, int max);
/* The events after seq `after`, oldest first, at most max; when there is
 * none yet, waits up to timeout_ms for one. Returns how many (0: none came).
 * *lost: how many after `after` had already been overwritten (the log keeps
 * the last VMAC_EVENT_LOG_SIZE). For the event stream (GET /api/events). */
int vmac_event_log_since(struct vmac_event_log *log, uint64_t after, struct vmac_event *out, int max, int timeout_ms,
                         uint64_t *lost);

#endif
