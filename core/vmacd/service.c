/* vmacd's log and systemd notifications: see service.h. */
#include "service.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <systemd/sd-daemon.h>
#include <systemd/sd-journal.h>
#include <time.h>
#include <unistd.h>

static int journal; /* stderr is the journal's stream */

void vmacd_log_init(void)
{
	const char *s = getenv("JOURNAL_STREAM");
	unsigned long long dev, ino;
	struct stat st;
	journal = s && sscanf(s, "%llu:%llu", &dev, &ino) == 2 && fstat(STDERR_FILENO, &st) == 0 &&
	          (unsigned long long)st.st_dev == dev && (unsigned long long)st.st_ino == ino;
}

void vmacd_log(int priority, const char *fmt, ...)
{
	char text[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(text, sizeof(text), fmt, ap);
	va_end(ap);
	if (journal)
		fprintf(stderr, "<%d>%s\n", priority, text);
	else
		fprintf(stderr, "vmacd: %s\n", text);
}

/* Each kind's priority: what an operator must act on is a warning or
 * worse; the bus's ordinary life is a notice or info. */
int vmacd_event_priority(const char *kind)
{
	static const struct {
		const char *kind;
		int priority;
	} kinds[] = {
	    {"driver_error", LOG_ERR},      {"dropped", LOG_WARNING},      {"driver_missing", LOG_WARNING},
	    {"schedule_full", LOG_WARNING}, {"machine_full", LOG_WARNING}, {"malformed", LOG_WARNING},
	    {"flood", LOG_WARNING},         {"table_full", LOG_WARNING},   {"auth", LOG_WARNING},
	    {"http", LOG_WARNING},          {"warning", LOG_WARNING},      {"reload_refused", LOG_WARNING},
	    {"rolled_back", LOG_WARNING},   {"attached", LOG_NOTICE},      {"enrolled", LOG_NOTICE},
	    {"removed", LOG_NOTICE},        {"reloaded", LOG_NOTICE},      {"probation_passed", LOG_NOTICE},
	    {"waiting", LOG_NOTICE},        {"mqtt", LOG_NOTICE},
	};
	size_t i;
	for (i = 0; i < sizeof(kinds) / sizeof(kinds[0]); i++)
		if (strcmp(kinds[i].kind, kind) == 0)
			return kinds[i].priority;
	return LOG_INFO; /* driver, level, sleeping and kinds to come */
}

void vmacd_echo_event(void *ctx, const struct vmac_event *e)
{
	int priority = vmacd_event_priority(e->kind);
	(void)ctx;
	if (journal && sd_journal_send("MESSAGE=[%s] %s", e->kind, e->text, "PRIORITY=%d", priority,
	                               "SYSLOG_IDENTIFIER=vmacd", "VMAC_EVENT=%s", e->kind, "VMAC_DEVICE=%s", e->device,
	                               "VMAC_SEQ=%llu", (unsigned long long)e->seq, NULL) >= 0)
		return;
	vmacd_log(priority, "[%s] %s", e->kind, e->text); /* not under the journal, or its socket refused */
}

/* ---- sd_notify ---- */

static int64_t mono_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* Until READY: every 10 ms, whether the bus has ticked. Then every half
 * WatchdogSec: WATCHDOG=1 if it ticked since the last look, else nothing
 * (systemd restarts a host whose bus thread hangs), said once. */
static void on_notify(struct ev_loop *loop, ev_timer *w, int revents)
{
	struct vmacd_notify *n = w->data;
	uint64_t beat = vmac_bus_heartbeat(n->bus);
	int64_t now = mono_ns();
	int moved = beat != n->beat;
	(void)revents;
	n->beat = beat;
	if (moved)
		n->beat_ns = now;
	if (!n->ready) {
		if (!moved)
			return;
		n->ready = 1;
		sd_notifyf(0, "READY=1\nSTATUS=%s", n->status);
		ev_timer_stop(loop, w);
		if (!n->watchdog_us)
			return;
		ev_timer_set(w, (double)n->watchdog_us / 2e6, (double)n->watchdog_us / 2e6);
		ev_timer_start(loop, w);
		return;
	}
	if (moved) {
		if (n->starved)
			vmacd_log(LOG_NOTICE, "watchdog: the bus thread ticks again: systemd is told vmacd lives");
		n->starved = 0;
		sd_notify(0, "WATCHDOG=1");
	} else if (!n->starved) {
		n->starved = 1;
		vmacd_log(LOG_CRIT,
		          "watchdog: the bus thread has not ticked for %lld ms: systemd is not told vmacd lives "
		          "(it restarts vmacd after WatchdogSec)",
		          (long long)((now - n->beat_ns) / 1000000));
	}
}

void vmacd_notify_start(struct vmacd_notify *n, struct ev_loop *loop, struct vmac_bus *bus, const char *status)
{
	uint64_t usec = 0;
	memset(n, 0, sizeof(*n));
	n->bus = bus;
	snprintf(n->status, sizeof(n->status), "%s", status);
	if (sd_watchdog_enabled(0, &usec) > 0)
		n->watchdog_us = usec;
	n->beat = vmac_bus_heartbeat(bus);
	n->beat_ns = mono_ns();
	ev_timer_init(&n->timer, on_notify, 0.01, 0.01);
	n->timer.data = n;
	ev_timer_start(loop, &n->timer);
}

void vmacd_notify_stopping(void)
{
	sd_notify(0, "STOPPING=1\nSTATUS=putting every board in its safe state");
}
