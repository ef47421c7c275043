/* The host's in-memory event log: see events.h. */
#include "events.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

#include "../common/monotime.h"

void vmac_event_log_init(struct vmac_event_log *log)
{
	pthread_condattr_t attr;
	memset(log, 0, sizeof(*log));
	pthread_mutex_init(&log->lock, NULL);
	pthread_condattr_init(&attr);
	pthread_condattr_setclock(&attr, CLOCK_MONOTONIC);
	pthread_cond_init(&log->grew, &attr);
	pthread_condattr_destroy(&attr);
	log->next_seq = 1;
	vmac_audit_limit_init(&log->audit);
}

void vmac_event_log_start_at(struct vmac_event_log *log, uint64_t seq)
{
	pthread_mutex_lock(&log->lock);
	log->next_seq = seq ? seq : 1;
	pthread_mutex_unlock(&log->lock);
}

void vmac_event_log_add(struct vmac_event_log *log, const char *kind, const char *device, const char *text)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	vmac_event_log_add_at(log, (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec, kind, device, text);
}

/* One more event of kind; under log->lock. */
static void count_kind(struct vmac_event_log *log, const char *kind)
{
	int i;
	for (i = 0; i < log->nkinds && strcmp(log->kinds[i].kind, kind) != 0; i++)
		;
	if (i == log->nkinds) {
		if (log->nkinds >= VMAC_EVENT_KINDS - 1) /* the last entry is for the rest */
			kind = "other";
		for (i = 0; i < log->nkinds && strcmp(log->kinds[i].kind, kind) != 0; i++)
			;
		if (i == log->nkinds) {
			snprintf(log->kinds[i].kind, sizeof(log->kinds[i].kind), "%s", kind);
			log->nkinds++;
		}
	}
	log->kinds[i].count++;
}

int vmac_event_log_counts(struct vmac_event_log *log, struct vmac_event_count *out)
{
	int n;
	pthread_mutex_lock(&log->lock);
	n = log->nkinds;
	memcpy(out, log->kinds, (size_t)n * sizeof(*out));
	pthread_mutex_unlock(&log->lock);
	return n;
}

void vmac_event_log_add_at(struct vmac_event_log *log, int64_t time_ns, const char *kind, const char *device,
                           const char *text)
{
	struct vmac_event *e, copy;
	pthread_mutex_lock(&log->lock);
	e = &log->ring[log->next_seq % VMAC_EVENT_LOG_SIZE];
	e->seq = log->next_seq++;
	e->time_ns = time_ns;
	snprintf(e->kind, sizeof(e->kind), "%s", kind);
	snprintf(e->device, sizeof(e->device), "%s", device ? device : "");
	snprintf(e->text, sizeof(e->text), "%s", text);
	count_kind(log, e->kind);
	if (log->echo)
		copy = *e;
	pthread_cond_broadcast(&log->grew);
	pthread_mutex_unlock(&log->lock);
	if (log->echo)
		log->echo(log->echo_ctx, &copy);
}

uint64_t vmac_event_log_next_seq(struct vmac_event_log *log)
{
	uint64_t seq;
	pthread_mutex_lock(&log->lock);
	seq = log->next_seq;
	pthread_mutex_unlock(&log->lock);
	return seq;
}

int vmac_event_log_latest(struct vmac_event_log *log, struct vmac_event *out, int max)
{
	uint64_t first, s;
	int n = 0;
	pthread_mutex_lock(&log->lock);
	first = log->next_seq > (uint64_t)max ? log->next_seq - (uint64_t)max : 1;
	if (log->next_seq > VMAC_EVENT_LOG_SIZE && first < log->next_seq - VMAC_EVENT_LOG_SIZE)
		first = log->next_seq - VMAC_EVENT_LOG_SIZE;
	for (s = first; s < log->next_seq; s++)
		out[n++] = log->ring[s % VMAC_EVENT_LOG_SIZE];
	pthread_mutex_unlock(&log->lock);
	return n;
}

int vmac_event_log_since(struct vmac_event_log *log, uint64_t after, struct vmac_event *out, int max, int timeout_ms,
                         uint64_t *lost)
{
	struct timespec until;
	uint64_t first, s;
	int n = 0;
	until = vmac_mono_after_ns((int64_t)timeout_ms * 1000000);
	pthread_mutex_lock(&log->lock);
	while (log->next_seq <= after + 1 && timeout_ms > 0)
		if (pthread_cond_timedwait(&log->grew, &log->lock, &until) != 0)
			break;
	first = after + 1;
	*lost = 0;
	if (log->next_seq > VMAC_EVENT_LOG_SIZE && first < log->next_seq - VMAC_EVENT_LOG_SIZE) {
		*lost = log->next_seq - VMAC_EVENT_LOG_SIZE - first;
		first = log->next_seq - VMAC_EVENT_LOG_SIZE;
	}
	for (s = first; s < log->next_seq && n < max; s++)
		out[n++] = log->ring[s % VMAC_EVENT_LOG_SIZE];
	pthread_mutex_unlock(&log->lock);
	return n;
}
