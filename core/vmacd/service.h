/* vmacd as a service (docs/SERVICE.md): its log lines and events, with
 * syslog priorities and fields when stderr is the journal, and systemd's
 * notifications (READY=1 once the bus ticks, STOPPING=1, WATCHDOG=1 from
 * the main thread only while the bus thread ticks). Outside systemd every
 * part of it is plain stderr and no-ops. */
#ifndef VMACD_SERVICE_H
#define VMACD_SERVICE_H

#include <ev.h>
#include <stdint.h>
#include <syslog.h>

#include "../host/bus.h"
#include "../host/events.h"

/* Looks whether stderr is the journal (JOURNAL_STREAM names its device and
 * inode); call once, first. */
void vmacd_log_init(void);
/* One line "vmacd: TEXT" on stderr; under the journal "<PRIORITY>TEXT". */
void vmacd_log(int priority, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* The syslog priority of an event of this kind (docs/API.md's kinds). */
int vmacd_event_priority(const char *kind);
/* An event_log echo: a line as vmacd_log's, or under the journal one entry
 * with fields VMAC_EVENT, VMAC_DEVICE, VMAC_SEQ. */
void vmacd_echo_event(void *ctx, const struct vmac_event *e);

struct vmacd_notify {
	struct vmac_bus *bus;
	ev_timer timer;
	uint64_t watchdog_us; /* WATCHDOG_USEC for this process; 0: no watchdog */
	uint64_t beat;        /* the bus's heartbeat at the last look */
	int64_t beat_ns;      /* when it last moved (CLOCK_MONOTONIC) */
	int ready, starved;
	char status[256]; /* STATUS= sent with READY=1 */
};

/* Starts looking at the bus: READY=1 with STATUS=status once it has ticked,
 * then WATCHDOG=1 every half WatchdogSec while it goes on ticking. */
void vmacd_notify_start(struct vmacd_notify *n, struct ev_loop *loop, struct vmac_bus *bus, const char *status);
/* STOPPING=1: the unit is on its way down. */
void vmacd_notify_stopping(void);

#endif
