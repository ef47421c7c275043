/* The host's in-memory event log: see events.h. */
#include "events.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

void vmac_event_log_init(struct vmac_event_log *log)
{
	memset(log, 0, sizeof(*log));
	pthread_mutex_init(&log->lock, NULL);
	log->next_seq = 1;
}

void vmac_event_log_add(struct vmac_event_log *log, const char *kind, const char *device, const char *text)
{
	struct timespec ts;
	struct vmac_event *e;
	clock_gettime(CLOCK_REALTIME, &ts);
	pthread_mutex_lock(&log->lock);
	e = &log->ring[log->next_seq % VMAC_EVENT_LOG_SIZE];
	e->seq = log->next_seq++;
	e->time_ns = (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
	snprintf(e->kind, sizeof(e->kind), "%s", kind);
	snprintf(e->device, sizeof(e->device), "%s", device ? device : "");
	snprintf(e->text, sizeof(e->text), "%s", text);
	pthread_mutex_unlock(&log->lock);
	fprintf(stderr, "vmacd: [%s] %s\n", kind, text);
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
