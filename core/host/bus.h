/* The bus thread: discovery, the periodic service of every device, the
 * deadline policy, and the messages it exchanges with the main thread.
 * Nothing on this thread allocates, logs to disk, blocks or runs a driver,
 * except the bus socket itself; drivers run on the driver workers (jobs the
 * bus thread hands them), slow work (loading drivers, JSON, HTTP) is the
 * main thread's, reached through SPSC rings. */
#ifndef VMAC_BUS_H
#define VMAC_BUS_H

#include <pthread.h>
#include <stdint.h>

#include "../common/errors.h"
#include "../common/hist.h"
#include "../common/ring.h"
#include "../config/config.h"
#include "../driver/driver.h"
#include "../recorder/recorder.h"
#include "../transport/transport.h"

#define VMAC_EVENT_TEXT 640

/* A checkpoint of a machine's dev.state, bus thread -> main thread (docs/
 * DRIVERS.md "Recovery after a restart"): in a ring of its own, each slot
 * followed by checkpoint_kib KiB for the data. */
struct vmac_bus_checkpoint {
	char machine[VMAC_NAME_MAX + 1];
	char driver[VMAC_NAME_MAX + 1];
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	int64_t time_ns; /* CLOCK_MONOTONIC (virtual time in vmac test) */
	size_t len;
	uint8_t data[]; /* len bytes used */
};

/* Bus thread -> main thread. */
enum vmac_bus_msg_kind {
	VMAC_MSG_EVENT,     /* something to record and show */
	VMAC_MSG_LOAD,      /* please load driver `driver` for device slot/generation */
	VMAC_MSG_UNLOAD,    /* free this driver (closing a Lua state is slow) */
	VMAC_MSG_STOPPED,   /* every board told to go safe; the bus thread is done */
	VMAC_MSG_RECORDING, /* a machine's recorder, captured (rec->reason says why): write it out, free it */
};

/* What the main thread does with a VMAC_MSG_EVENT beyond recording it; the
 * event's kind (text) is for people and the event log. */
enum vmac_event_code {
	VMAC_EVENT_RECORD = 0,  /* only recorded */
	VMAC_EVENT_ROLLED_BACK, /* a version on probation failed and went back: the store records it (version_id) */
	VMAC_EVENT_STALLED,     /* driver, version, version_id stalled a worker: not to be loaded again */
};

struct vmac_bus_msg {
	enum vmac_bus_msg_kind kind;
	enum vmac_event_code code; /* VMAC_MSG_EVENT */
	int64_t time_ns;
	uint32_t slot, generation;
	struct vmac_driver *drv;
	char device[VMAC_NAME_MAX + 1];
	char driver[VMAC_NAME_MAX + 1];
	char event_kind[24];                       /* attached, dropped, driver_missing, ... */
	int64_t version_id;                        /* rolled_back, stalled: the store's id of the version that failed */
	char version[VMAC_DRIVER_VERSION_MAX + 1]; /* stalled: its version */
	char text[VMAC_EVENT_TEXT];
	struct vmac_recorder *rec; /* RECORDING; UNLOAD: free it too (may be NULL) */
	void *buf;                 /* UNLOAD: a machine's checkpoint buffer to free too (may be NULL) */
	int replace;               /* RECORDING: the machine runs on: send it a new recorder (VMAC_CMD_RECORDER) */
};

/* Main thread -> bus thread. */
enum vmac_host_cmd_kind {
	VMAC_CMD_LOADED,   /* drv loaded (or NULL with text saying why not) */
	VMAC_CMD_STOP,     /* put every board in its safe state and end */
	VMAC_CMD_RECORDER, /* rec for the machine whose primary is slot/generation, after a capture */
	VMAC_CMD_KEYS,     /* keys: the enrolled boards' keys from now on (vmac_bus_set_keys) */
};

struct vmac_host_cmd {
	enum vmac_host_cmd_kind kind;
	uint32_t slot, generation;
	struct vmac_driver *drv;
	struct vmac_recorder *rec;  /* its machine's flight recorder (NULL: none) */
	uint8_t *ckpt;              /* its machine's checkpoint buffer, checkpoint_kib KiB (NULL: none) */
	int missing;                /* no driver file at all (vs. a driver that failed to load) */
	struct vmac_bus_keys *keys; /* KEYS */
	char text[VMAC_EVENT_TEXT];
};

/* A board's clock as its TIMED replies tell it (docs/TIME.md,
 * "Time-triggered I/O"; PROTOCOL.md, "The TIMED reply"). */
struct vmac_board_clock_status {
	int known;                 /* it has sent a TIMED reply: the rest is valid */
	uint8_t state;             /* its clock: 0 unsynced, 1 locking, 2 locked, 3 holdover, 4 lost */
	int on_arrival;            /* its last service was acted on arrival (the fallback), not at the instants */
	uint32_t bound_ns;         /* its clock's estimated error bound (0xFFFFFFFF: unknown) */
	int64_t offset_ns;         /* its counter less host time */
	uint64_t latched_at_ns;    /* host ns (CLOCK_MONOTONIC) its last inputs were latched at; 0: unknown */
	uint64_t services_timed;   /* TIMED replies acted at the host's instants */
	uint64_t services_arrival; /* TIMED replies acted on arrival */
};

/* The kinds of deadline violation (docs/SCHEDULER.md, "The static time
 * manager"). */
enum vmac_violation {
	VMAC_VIOLATION_NONE,
	VMAC_VIOLATION_MISS,        /* a reply not in time: the board's or the wire's */
	VMAC_VIOLATION_MISS_HOST,   /* a request the kernel refused to send: the host's own */
	VMAC_VIOLATION_DRIVER_LATE, /* a tick not done by the machine's next service */
};
const char *vmac_violation_name(int kind);

/* A device as the status shows it (copied out of the bus thread). */
struct vmac_device_status {
	char name[VMAC_NAME_MAX + 1];
	char driver[VMAC_NAME_MAX + 1];
	char driver_version[VMAC_DRIVER_VERSION_MAX + 1]; /* "" when no driver runs it */
	char machine[VMAC_NAME_MAX + 1];                  /* the primary board's name ("" when none) */
	char last_machine[VMAC_NAME_MAX + 1];             /* machine, or the one it was in last ("": never in one) */
	char note[200];                                   /* why it is not running, e.g. "schedule full: ..." */
	const char *state;                                /* attaching, running, sleeping, errant */
	int scheduled;                                    /* level, slot, slice are valid */
	unsigned level, slot, slice;
	int nvars; /* published variables (primary board only) */
	struct vmac_variable vars[VMAC_DRIVER_MAX_VARS];
	int nparams; /* the driver's params and their values now (primary board only) */
	struct vmac_variable params[VMAC_DRIVER_MAX_PARAMS];
	char address[48];
	uint32_t id, major, minor;
	int authenticated; /* its session is sealed: it proved its enrolled key */
	uint32_t period_us;
	uint64_t misses, served;
	uint64_t misses_host; /* of misses: the host's own fault */
	uint64_t drops;       /* times the host dropped it */
	uint64_t driver_late; /* ticks whose outputs came after the machine's next service (primary board only) */
	/* Its last deadline violation (seed 002's vector, docs/SCHEDULER.md):
	 * a VMAC_VIOLATION_*, 0 for none, and when, in the status's time_ns. */
	int violation;
	int64_t violation_ns;
	unsigned protocol; /* the version the board speaks (1 or 2) */
	int cyclic;        /* served by the cyclic frame, at offset (else unicast UPDATEs) */
	unsigned offset;
	struct vmac_inputs inputs;
	struct vmac_outputs outputs;
	struct vmac_board_clock_status clock; /* known = 0 until its first TIMED reply */
	/* Its machine's timing (docs/TIME.md, "The patterns"): pattern a
	 * VMAC_TIMING_* (0: no machine), the instants' offsets from the anchor
	 * slot's planned start; timed: its services go in TIMED frames. */
	struct {
		int pattern;
		uint32_t in_us, out_us;
		int timed;
	} timing;
	uint64_t timing_mismatch; /* replies of the other kind than their frame (plain to TIMED, or back) */
	unsigned firmware_major, firmware_minor; /* as it announced */
	/* The machine's driver (primary board only; 0 when none runs): heap
	 * bytes and its cap, VM instructions in all calls (counted in steps of
	 * 1,000: vmac_driver_instructions) and the budget of one call, and the
	 * wall-clock time of all its calls. */
	size_t driver_memory, driver_memory_cap;
	uint64_t driver_instructions, driver_instruction_budget;
	uint64_t driver_call_ns;
};

struct vmac_bus_counters {
	uint64_t malformed_frames; /* every datagram dropped as malformed, all reasons */
	uint64_t malformed_by_reason[16];
	uint64_t late_replies; /* right sequence, but after the deadline (a miss) */
	uint64_t misses, drops, discoveries, announces;
	uint64_t syncs;        /* times the host sent its clock (clock_sync_ms): a plain SYNC, sealed ones, or both */
	uint64_t syncs_sealed; /* sealed SYNC frames sent (one per chunk of offsets holding a keyed board) */
	uint64_t sync_stamps;  /* the kernel's transmit stamps of SYNC frames, each named in the next (two-step) */
	uint64_t misses_host;  /* of misses: the host's own (a request the kernel refused to send) */
	uint64_t ticks, ticks_skipped;
	uint64_t events_lost; /* event ring full */
	uint64_t table_full;
	uint64_t attach_refused;   /* announcements not let attach: attach_max or attach_rate reached */
	uint64_t auth_failed;      /* frames of an enrolled board (or claiming to be one) that did not prove its key */
	uint64_t takeover_refused; /* announcements of a running board's identity that did not prove its key */
	uint64_t waiting;          /* announcements of boards with no key held back (bus_trust enrolled) */
	uint64_t schedule_full;    /* devices refused by admission control */
	uint64_t checkpoints;      /* machine checkpoints handed to the main thread */
	uint64_t checkpoints_deferred; /* ... put off a tick: the ring was full */
};

/* Indexes of malformed_by_reason. */
enum vmac_malformed_reason {
	VMAC_BAD_SHORT,
	VMAC_BAD_MAGIC,
	VMAC_BAD_VERSION,
	VMAC_BAD_LENGTH,
	VMAC_BAD_OP,
	VMAC_BAD_PAYLOAD,
	VMAC_BAD_NAME,
	VMAC_BAD_VALUE,
	VMAC_BAD_NOT_REPLY,
	VMAC_BAD_STALE_SEQ,
	VMAC_BAD_UNKNOWN_SENDER,
	VMAC_BAD_OFFSET, /* v2: a board confirmed another offset, or wants another record size */
	VMAC_BAD_REASONS
};
extern const char *const vmac_malformed_reason_names[VMAC_BAD_REASONS];

struct vmac_status {
	int64_t time_ns;
	int64_t started_ns;
	char host_addr[48];
	int realtime;        /* SCHED_FIFO obtained */
	uint32_t board_keys; /* enrolled boards' keys the bus holds */
	int ndevices;
	struct vmac_device_status *devices; /* max_devices entries */
	struct vmac_hist lateness;
	struct vmac_bus_counters counters;
	/* The schedule (docs/SCHEDULER.md). */
	unsigned slices_per_slot, slots_per_block, slot_us;
	unsigned capacity_used, capacity_total; /* slice-slots per block */
	uint16_t *slot_load;                    /* slots_per_block entries: devices serviced in each slot */
};

struct vmac_bus; /* opaque */

/* The enrolled boards' keys as the bus thread holds them (keys.c): a hash
 * table by board name, one allocation, built by the main thread from the
 * store and handed over whole. */
struct vmac_bus_keys;
/* Room for n keys; NULL when out of memory. */
struct vmac_bus_keys *vmac_bus_keys_new(uint32_t n);
/* 0, or -ENOSPC when n keys are in already (a name added twice: the last key). */
int vmac_bus_keys_add(struct vmac_bus_keys *k, const char *board, const uint8_t key[16]);
void vmac_bus_keys_free(struct vmac_bus_keys *k);
/* keys become the bus's (0; the old table comes back to the main thread to
 * free), or -EAGAIN when the command ring is full (keys still the
 * caller's). A running board whose key went away is dropped; one whose key
 * changed keeps its session until it announces again. Sent before
 * vmac_bus_start, they are in place before the first discovery. */
int vmac_bus_set_keys(struct vmac_bus *bus, struct vmac_bus_keys *keys);

/* Create the bus (opens the transport, allocates every table it will ever
 * use). Returns NULL with err set. */
struct vmac_bus *vmac_bus_new(const struct vmac_config *cfg, char *err, size_t errlen);
void vmac_bus_free(struct vmac_bus *bus);
/* Start the bus thread. Returns 0 or a negative errno. */
int vmac_bus_start(struct vmac_bus *bus);
/* Wait for the bus thread to end (after VMAC_MSG_STOPPED). */
void vmac_bus_join(struct vmac_bus *bus);

/* Main thread side of the rings. to_main_wakeup is called (from the bus
 * thread) after pushing to the main ring; set it before start. */
void vmac_bus_set_wakeup(struct vmac_bus *bus, void (*wakeup)(void *), void *ctx);
/* How many ticks the bus thread has run, readable from any thread at any
 * time: it grows while the bus thread lives (vmacd's systemd watchdog). */
uint64_t vmac_bus_heartbeat(struct vmac_bus *bus);
int vmac_bus_poll_msg(struct vmac_bus *bus, struct vmac_bus_msg *msg);
/* Wake the main thread (its wakeup callback), from any thread: something
 * it looks after changed (the store's board keys, through the API). */
void vmac_bus_wake_main(struct vmac_bus *bus);
/* The main thread's care of the driver workers, on every wake-up: an
 * ended one joined, a spare kept ready for the next stall (the bus thread
 * lowers a stalled worker's priority itself). */
void vmac_bus_workers_service(struct vmac_bus *bus);
/* The oldest checkpoint not yet taken (NULL: none), valid until
 * vmac_bus_checkpoint_release; main thread (the one consumer). */
const struct vmac_bus_checkpoint *vmac_bus_checkpoint_peek(struct vmac_bus *bus);
void vmac_bus_checkpoint_release(struct vmac_bus *bus);
int vmac_bus_send_cmd(struct vmac_bus *bus, const struct vmac_host_cmd *cmd);

/* The answer to a VMAC_MSG_LOAD: the driver loaded for load's device (drv,
 * now the bus's), or NULL with rc (-ENOENT: no driver file) and text saying
 * why. 0, or -EAGAIN when the command ring is full: drv is freed, and the board
 * is tried again at its next announce. */
int vmac_bus_loaded(struct vmac_bus *bus, const struct vmac_bus_msg *load, int rc, struct vmac_driver *drv,
                    const char *text);

/* Copy the latest published status (taken at most 100 ms ago) into *out,
 * whose devices array has room for max_devices and slot_load for
 * 1 << max_level entries. */
void vmac_bus_status(struct vmac_bus *bus, struct vmac_status *out);
const char *vmac_bus_host_addr(struct vmac_bus *bus);

/* Operator input to the machine `device` belongs to: the driver's
 * input(dev, name, value), run and answered before it returns. Virtual
 * mode only (`vmac test` calls it between steps of its virtual clock);
 * vmacd's threads use vmac_bus_request_input.
 * Returns 0 (accepted), a vmac_refusal (> 0: refused, reply says why),
 * -VMAC_ENOTRUNNING (no running machine of that name) or -VMAC_EDRIVER (its
 * driver failed and the machine was dropped or rolled back); reply says
 * which. */
int vmac_bus_input(struct vmac_bus *bus, const char *device, const char *name, const struct vmac_value *value,
                   char *reply, size_t replylen);

/* The same from any other thread (the HTTP server): hands the request to the
 * bus thread and waits up to timeout_ms for its answer. Returns 0 with rc
 * and reply filled in (rc as vmac_bus_input returns it), or -VMAC_EBUSY when
 * the bus thread took no request (all VMAC_BUS_REQUESTS in use) or did not
 * take it in time (reply says which). The bus thread
 * only looks at the requests, sets the answer and posts a semaphore: it
 * never waits for the caller. */
#define VMAC_BUS_REQUESTS 16
struct vmac_bus_input_request {
	char device[VMAC_NAME_MAX + 1];
	char name[VMAC_NAME_MAX + 1];
	struct vmac_value value;
	int persist; /* set and persist: refused (VMAC_REFUSED_NOT_PERSIST) unless name is a persist = true param */
	int rc;
	char reply[VMAC_EVENT_TEXT];
	char machine[VMAC_NAME_MAX + 1]; /* rc 0: the machine's name (its primary board), what persists under */
};
/* Capture the flight recorder of machine `device` now (vmac record): it
 * goes to the main thread as a recording, and a new one takes its place.
 * 0, or < 0 with reply saying why (no such machine, no recorder). */
int vmac_bus_request_record(struct vmac_bus *bus, const char *device, int timeout_ms, char *reply, size_t replylen);

int vmac_bus_request_input(struct vmac_bus *bus, struct vmac_bus_input_request *req, int timeout_ms);

/* Hot reload from another thread (docs/API.md "Drivers"): drv, loaded for
 * the machine named device and not yet used, takes it over at the next
 * slot boundary (vmac_driver_take_over). With probation_ms > 0 the old
 * instance is kept that long: if drv fails meanwhile, the old one takes
 * over again and an event of kind "rolled_back" carries drv's tag
 * (vmac_driver_tag). Returns -VMAC_EBUSY when the bus thread took no
 * request (*rc the same; reply says why; drv is the caller's), else 0 with
 * *rc: 0 switched (drv is the bus's now), -VMAC_EDRIVER (the take-over
 * stalled, or the machine was dropped during it: drv went with the job and
 * is not the caller's), or, drv the caller's to free and reply saying why,
 * -VMAC_ENOTRUNNING (no running machine of that name) or -VMAC_EREFUSED
 * (the machine would not take drv). The answer comes when the machine's
 * driver worker has run the take-over. */
int vmac_bus_request_swap(struct vmac_bus *bus, const char *device, struct vmac_driver *drv, unsigned probation_ms,
                          int timeout_ms, int *rc, char *reply, size_t replylen);

/* The machines of driver `driver` as the bus thread has them when it takes
 * this request, every command sent with vmac_bus_send_cmd before the call
 * handled first: the names of their primary boards, every machine that has
 * a driver instance (running, or its boards still registering: such a
 * machine refuses a swap as not running until it has attached). Returns
 * how many (at most max), or -VMAC_EBUSY when the bus thread took no
 * request (reply says why). Any thread but the bus thread. */
int vmac_bus_request_machines(struct vmac_bus *bus, const char *driver, char (*names)[VMAC_NAME_MAX + 1], int max,
                              int timeout_ms, char *reply, size_t replylen);

/* ---- virtual mode: `vmac test` (docs/TESTING.md) ----
 * The same bus (discovery, schedule, deadlines, drivers) with no thread, no
 * socket and no timer: the caller owns the clock, carries the frames both
 * ways and answers VMAC_MSG_LOAD itself (vmac_bus_send_cmd, then
 * vmac_bus_virtual_commands). Single-threaded. */
struct vmac_bus_link {
	/* Frames the host sends (to a board's address or to the group). */
	void (*send)(void *ctx, const struct vmac_packet *pkts, int n);
	void *ctx;
};

struct vmac_bus *vmac_bus_new_virtual(const struct vmac_config *cfg, const struct vmac_bus_link *link,
                                      const struct vmac_addr *group, char *err, size_t errlen);
/* Run every tick due at or before now_ns (time 0 is the bus's start; ticks
 * fall on multiples of the slot). Returns 1 once stopped, else 0. */
int vmac_bus_virtual_tick(struct vmac_bus *bus, int64_t now_ns);
/* The earliest time after now_ns at which the next tick falls. */
/* The virtual host starts at now_ns: its bus time 0 and first slot there
 * (a host started again after vt_crash_host). */
void vmac_bus_virtual_start_at(struct vmac_bus *bus, int64_t now_ns);
int64_t vmac_bus_virtual_next_tick(const struct vmac_bus *bus);
/* Model a slow driver: every call of driver `driver` takes cost_ns of
 * virtual time (0: none), its results ready only then; a tick that takes
 * longer than its limit fails as on the host (docs/TESTING.md,
 * driver_cost). At most VMAC_BUS_VIRTUAL_COSTS drivers; -1 when full. */
#define VMAC_BUS_VIRTUAL_COSTS 8
int vmac_bus_virtual_driver_cost(struct vmac_bus *bus, const char *driver, int64_t cost_ns);
/* A frame reaching the host at p->rx_ns. */
void vmac_bus_virtual_receive(struct vmac_bus *bus, const struct vmac_packet *p);
/* Handle the commands sent with vmac_bus_send_cmd. */
void vmac_bus_virtual_commands(struct vmac_bus *bus);
/* The status of one device now (not the 100 ms snapshot): 0, or -1 when no
 * device has that name. */
int vmac_bus_device_status(struct vmac_bus *bus, const char *device, struct vmac_device_status *out);
/* The cheap parts of it, for checks made after every frame: the state
 * ("absent" when no such device) and one published variable (NULL when the
 * device or the variable is not there). */
const char *vmac_bus_device_state(struct vmac_bus *bus, const char *device);
const struct vmac_variable *vmac_bus_device_var(struct vmac_bus *bus, const char *device, const char *name);

#endif
