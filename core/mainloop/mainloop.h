/* The host's main thread, one loop for vmacd and `vmac test` alike: it
 * answers the bus thread's messages (load a driver with the machine's
 * persisted params and checkpoint, free one, keep a recording, log an
 * event), keeps the driver workers, and copies checkpoints and events into
 * the store. vmacd's store is SQLite in its state folder; `vmac test`'s is
 * the same store in memory (vmac_store_open_memory), so a driver under test
 * goes through the path it will take on a host. Main thread only. */
#ifndef VMAC_MAINLOOP_H
#define VMAC_MAINLOOP_H

#include <stddef.h>
#include <stdint.h>

#include "../config/config.h"
#include "../host/bus.h"
#include "../host/events.h"
#include "../store/store.h"

/* What differs between a host and a test: the clocks, and what to do
 * around the messages. Any hook but the clocks may be NULL. */
struct vmac_mainloop_hooks {
	void *ctx;
	int64_t (*wall_ns)(void *ctx); /* Unix time: CLOCK_REALTIME, or vmac test's virtual clock */
	int64_t (*bus_ns)(void *ctx);  /* the bus's clock (vmac_bus_msg.time_ns) */
	/* Each event as it goes to the store, in order (vmac test keeps them
	 * all for its checks). */
	void (*event)(void *ctx, const struct vmac_event *e);
	void (*loaded)(void *ctx);  /* a driver went to the bus (virtual mode runs its commands now) */
	void (*stopped)(void *ctx); /* the bus thread has put every board in its safe state and ended */
};

struct vmac_mainloop;

/* A loop for `bus`, storing into `store`, logging into `log` (which the
 * HTTP and MQTT threads read; its numbering goes on from the store's last
 * event). NULL and err when out of memory or the store cannot be read. */
struct vmac_mainloop *vmac_mainloop_new(const struct vmac_config *cfg, struct vmac_bus *bus, struct vmac_store *store,
                                        struct vmac_event_log *log, const struct vmac_mainloop_hooks *hooks, char *err,
                                        size_t errlen);
/* What the bus thread has handed over, answered (for 20 ms at most); then
 * the store's board keys and audit outbox looked at, checkpoints and
 * events into the store. On every wake-up, and after the bus thread has
 * ended. 1 when its 20 ms ran out before the ring was seen empty (call
 * again soon, after anything else waiting), else 0. */
int vmac_mainloop_service(struct vmac_mainloop *l);
/* The store's board keys to the bus now, if they changed (every
 * vmac_mainloop_service looks too). */
void vmac_mainloop_sync_keys(struct vmac_mainloop *l);
void vmac_mainloop_free(struct vmac_mainloop *l);

#endif
