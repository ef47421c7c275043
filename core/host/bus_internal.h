/* The bus thread's insides, shared by its files (every file in core/host/
 * but events.c, the main thread's event log); the rest of the host sees
 * only bus.h. Everything here runs on the bus thread unless
 * it says otherwise. Names shared between the files carry the prefix bus_.
 *
 * The bus thread never runs a driver: every call into a driver's state is
 * a job (struct job, one per machine, one at a time) that a driver worker
 * runs (workers.c); jobs.c is the bus thread's side (hand a job over,
 * collect what it gave, judge a job that overran). */
#ifndef VMAC_BUS_INTERNAL_H
#define VMAC_BUS_INTERNAL_H

#include "../sched/timing.h"
#include "bus.h"

#include <pthread.h>
#include <semaphore.h>
#include <stdatomic.h>
#include <stdint.h>

#define RX_BATCH 64

#define STATUS_EVERY_NS 100000000LL /* publish status at most every 100 ms */

#define MALFORMED_LOG_EVERY_NS 1000000000LL

#define STOP_GRACE_PERIODS 3 /* wait this long for SHUTDOWN acks */

enum dev_state {
	DEV_FREE,
	DEV_LOADING,     /* announce seen, driver being loaded on the main thread */
	DEV_REGISTERING, /* REGISTER sent or to be sent */
	DEV_RUNNING,
	DEV_TO_SLEEP, /* registered only to be told to SLEEP (no driver) */
	DEV_SLEEPING,
	DEV_ERRANT,  /* dropped; waits for the board to announce again */
	DEV_WAITING, /* announced without proving a key (bus_trust enrolled): no driver until enrolled */
};

/* The steps of registering a board (DEV_REGISTERING): REGISTER, then for a
 * board served by the cyclic frame, SIZE and OFFSET (docs/PROTOCOL.md,
 * "Version 2"). */
enum reg_step { REG_REGISTER, REG_SIZE, REG_OFFSET };

/* ---- drivers on workers (jobs.c, workers.c) ---- */

enum job_kind {
	JOB_ATTACH = 1, /* attach(dev), then recover(dev, saved) */
	JOB_TICK,       /* tick(dev, inputs), then a checkpoint when due or asked */
	JOB_INPUT,      /* input(dev, name, value) */
	JOB_SWAP,       /* hot reload: other takes over from drv */
	JOB_ROLLBACK,   /* drv (the previous version) takes over again from other (which failed) */
	JOB_STOP,       /* the host stops: a checkpoint, then detach(dev) */
};

/* Who owns a job: IDLE and DONE the bus thread, QUEUED the bus thread
 * until a worker takes it (QUEUED -> RUNNING), RUNNING the worker. The bus
 * thread may give up a RUNNING job: DROPPED (its machine went away) or
 * STALLED (it overran: its worker is retired); the worker that finishes it
 * then disposes of its instances and sets it DISPOSED, which the bus thread
 * takes for IDLE (never for a job that held nothing). */
enum job_state { JOB_IDLE, JOB_QUEUED, JOB_RUNNING, JOB_DONE, JOB_DROPPED, JOB_STALLED, JOB_DISPOSED };

struct job {
	/* A tick moves two or three cache lines between the cores, each way:
	 * the first line (what the worker reads), the results (what the bus
	 * thread reads), and the bus thread's notes stay on lines of their own
	 * (the job is aligned to a line: bus_jobs_init). */
	_Alignas(64) _Atomic int state;
	_Atomic int runner; /* the worker that took it */
	enum job_kind kind;
	int nboards;                                   /* the machine's boards, added to the driver first */
	unsigned level;                                /* the machine's level: told to the driver first */
	int checkpoint;                                /* TICK: one is due; STOP: the machine is attached */
	double time_s;                                 /* bus time of the call */
	struct vmac_driver *drv;                       /* the instance it runs on */
	struct vmac_inputs in[VMAC_DRIVER_MAX_BOARDS]; /* TICK */
	double sample_s[VMAC_DRIVER_MAX_BOARDS];       /* TICK: each board's inputs' instant, bus time (dev.t) */
	/* The worker's, written before DONE. */
	_Alignas(64) struct vmac_outputs out[VMAC_DRIVER_MAX_BOARDS]; /* TICK */
	int rc;
	int want_level; /* dev:set_level during the call; -1: none */
	int ckpt_rc;    /* 1: ckpt_len bytes encoded; -1: refused (ckpt_err) */
	int recover_rc; /* ATTACH */
	int vars_fresh; /* vars hold the instance's published values now */
	int params_fresh;
	size_t memory;
	uint64_t instructions; /* vmac_driver_instructions after the call */
	uint64_t call_ns;      /* vmac_driver_call_ns after the call */
	double out_at_s;       /* TICK: its dev:output_at, -1 none */
	/* The worker's own memory, across jobs. */
	const struct vmac_driver *vars_of;
	uint64_t vars_version;
	int64_t params_ns;
	/* The bus thread's own notes on it, and what it writes before QUEUED
	 * that a tick does not read. */
	_Alignas(64) int64_t queued_ns; /* when it was asked for (a tick: its primary's reply) */
	int64_t seen_ns;                /* when the bus first saw it running (0: not yet) */
	int64_t limit_ns;               /* how long it may run (jobs.c, limit_of), fixed when it is handed over */
	int pushed;                     /* QUEUED and in a worker's ring */
	int nnamed;                     /* boards whose names board[] holds (they only ever grow) */
	int req;                        /* INPUT, SWAP: the request slot to answer; -1: a direct call (vmac test) */
	int input_rc;                   /* INPUT: its answer (kept when a failure frees the machine) */
	struct vmac_driver *other;      /* SWAP: the new instance; ROLLBACK: the one that failed */
	int64_t overdue_ns;             /* past its limit: when the bus first looked, */
	int64_t overdue_cpu_ns;         /* and its worker's CPU time then */
	int64_t ready_ns;               /* virtual mode, a slow driver: when its results are ready */
	uint64_t rec_n;                 /* INPUT: its event in the recorder */
	/* A tick of drv stalls after stall_ns (its budget and half: jobs.c,
	 * STALL_AFTER), read once per instance: the instance's line holds
	 * what its worker writes at every call. */
	const struct vmac_driver *budget_of;
	int64_t stall_ns;
	struct vmac_bus *bus;
	int mach; /* its machine: bus->mach[mach] */
	/* Rarely used: the bus thread's, written before QUEUED. */
	uint32_t minor[VMAC_DRIVER_MAX_BOARDS];
	char board[VMAC_DRIVER_MAX_BOARDS][VMAC_NAME_MAX + 1];
	char device[VMAC_NAME_MAX + 1]; /* the primary's name and the driver's, for events */
	char driver[VMAC_NAME_MAX + 1];
	char name[VMAC_NAME_MAX + 1]; /* INPUT */
	struct vmac_value value;
	uint8_t *ckpt; /* the machine's checkpoint buffer, checkpoint_kib KiB */
	/* Rarely used: the worker's, written before DONE. */
	char err[VMAC_DRIVER_ERR_MAX]; /* rc != 0 */
	char reply[VMAC_EVENT_TEXT];   /* INPUT */
	size_t ckpt_len;
	char ckpt_err[256];
	int nvars, nparams;
	struct vmac_variable vars[VMAC_DRIVER_MAX_VARS];
	struct vmac_variable params[VMAC_DRIVER_MAX_PARAMS];
};

enum worker_state { W_FREE, W_SPARE, W_ACTIVE, W_STALLED, W_EXITED };

/* A driver worker: a thread that runs the jobs the bus thread queues on
 * it (workers.c). Its queue is a ring of machine indexes with one producer
 * (the bus thread) and one consumer (the worker), each side's index and
 * its copy of the other's on a cache line of its own: a push or a take
 * reads the other side's line only when its copy says the ring is full or
 * empty. */
struct worker {
	_Atomic int state;
	int index;
	struct vmac_bus *bus;
	pthread_t thread;
	int efd;              /* eventfd it sleeps on when its ring is empty */
	struct vmac_ring out; /* struct vmac_bus_msg, worker -> main thread (events, unloads) */
	_Atomic uint64_t events_lost;
	_Atomic int quit;
	int *queue;       /* the ring: machine indexes, bus thread -> worker */
	int64_t *push_ns; /* the bus thread's: when each entry was pushed */
	uint32_t mask;    /* the ring's capacity - 1 */
	/* The bus thread's. */
	_Alignas(64) _Atomic uint32_t head; /* the next entry the bus writes */
	uint32_t tail_seen;                 /* tail, as the bus thread last read it */
	int nmach;                          /* machines it runs */
	int kick;                           /* the bus thread pushed: wake it at the end of this pass */
	/* The worker's. */
	_Alignas(64) _Atomic uint32_t tail; /* the next entry it takes */
	uint32_t head_seen;                 /* head, as it last read it */
	_Atomic int sleeping;               /* it is about to sleep or sleeps: a push must wake it */
};

/* A machine: the boards that share a driver name and major id, run by one
 * driver instance. Board 0 is the primary: its reply runs the tick. */
struct machine {
	int used;
	struct vmac_driver *drv; /* NULL while loading */
	char driver[VMAC_NAME_MAX + 1];
	uint32_t major;
	uint32_t primary;                       /* device slot of the primary board */
	uint32_t board[VMAC_DRIVER_MAX_BOARDS]; /* device slots, in the driver's board order */
	int nboards;
	unsigned level;
	int attached; /* attach() has run */
	int worker;   /* the driver worker that runs its jobs; -1: none yet */
	/* Work waiting for the machine's job (jobs.c): dispatched in this order. */
	int want_attach;
	int want_rollback;
	char rollback_why[200];
	int want_swap;                 /* request slot + 1 of a hot reload; 0: none */
	int inputs[VMAC_BUS_REQUESTS]; /* request slots of operator input, oldest first */
	int ninputs;
	int want_tick;
	int64_t tick_ns; /* the primary's reply that asked for it */
	/* Every board's inputs and their instant (0: none yet) as the host
	 * held them at tick_ns: a tick that waits for its job gets these, not
	 * a reply that came after its time. */
	struct vmac_inputs tick_in[VMAC_DRIVER_MAX_BOARDS];
	int64_t tick_sample_ns[VMAC_DRIVER_MAX_BOARDS];
	int want_stop;
	int want_checkpoint; /* a checkpoint was due and not taken: the next tick makes it */
	uint64_t late;       /* services that found its tick not done (held outputs) */
	int64_t late_ns;     /* bus time of the last of them (0: none) */
	int tick_open;       /* a tick asked for (bus_run_machine) and not yet collected, */
	int tick_held;       /* and already counted in late, */
	uint64_t tick_asked; /* asked for in the slot of this tick index */
	/* The instance's published values and params, as its last job left them. */
	int nvars, nparams;
	struct vmac_variable vars[VMAC_DRIVER_MAX_VARS];
	struct vmac_variable params[VMAC_DRIVER_MAX_PARAMS];
	size_t memory;
	uint64_t instructions, call_ns;
	int64_t next_checkpoint_ns; /* checkpoint_s: the next periodic checkpoint */
	int checkpoint_failing;     /* the last one was refused (said once) */
	struct vmac_recorder *rec;  /* the flight recorder (NULL: none) */
	int64_t attach_ns;          /* bus time of attach (a recorder put in later starts after it) */
	/* Hot reload: the instance drv took over from, kept while drv is on
	 * probation (until probation_end_ns) to roll back to if drv fails. */
	struct vmac_driver *prev;
	int64_t probation_end_ns;
	struct vmac_bus *bus;
	struct vmac_timing timing; /* its boards' instants (timed.c): the driver's pattern at its level */
	int64_t out_at_ns;         /* its last tick's dev:output_at after the anchor slot's start; 0: none */
	/* Its last tick's outputs (staged_n boards'), held until the first
	 * service of its next period (bus_release_outputs), so that every board
	 * of one period carries the outputs of one tick. */
	int staged, staged_n;
	struct vmac_outputs staged_out[VMAC_DRIVER_MAX_BOARDS];
	int64_t staged_out_at_ns;
	uint64_t served_period; /* slot >> level of its last service, + 1; 0: none yet */
	unsigned served_level;  /* the level that period was counted at */
};

struct device {
	enum dev_state state;
	int mach;                /* index into bus->mach, -1 when none */
	int scheduled;           /* admitted to the schedule */
	int64_t reply_window_ns; /* its reply deadline: the configured one, at most its period */
	uint16_t aside_seq;      /* a request sent without awaiting its answer (WATCHDOG) */
	uint16_t watchdog_ms;    /* what the board was told */
	uint16_t want_watchdog;  /* a longer one to send before the next UPDATE (slower level) */
	char note[200];          /* why it is not running ("schedule full: ...") */
	uint16_t generation;
	uint32_t id; /* generation << 16 | slot */
	struct vmac_announce ann;
	uint8_t version;  /* the protocol version the board announced: every request to it speaks it */
	uint8_t cyclic;   /* served by the cyclic frame at its offset (its slot); else unicast UPDATEs */
	uint8_t reg_step; /* enum reg_step, while DEV_REGISTERING */
	struct vmac_addr addr;
	struct vmac_driver *drv;
	int register_sent;
	uint16_t seq;
	uint16_t missed_seq;   /* the request whose deadline passed last (its late reply is no stranger) */
	uint16_t courtesy_seq; /* the SHUTDOWN/SLEEP sent on dropping, whose answer nobody awaits */
	int pending;           /* a request is out, no reply yet */
	int tx_index;          /* the pending request's packet in bus->tx until the flush */
	uint8_t unsent;        /* the kernel refused the pending request: a miss of the host's own */
	uint8_t pending_op;
	int64_t sent_ns;
	uint32_t consecutive_misses;
	uint64_t misses, served;
	uint64_t misses_host; /* of misses: caused by the host (its request never left) */
	uint64_t drops;       /* times it was dropped (bus_drop: itself, or a board of its machine) */
	int64_t violated_ns;  /* bus time of its last deadline violation (0: none), ... */
	uint8_t violated;     /* ... and its kind, a VMAC_VIOLATION_* */
	/* The machine it is in, or was in last (its primary's name; "" before
	 * it first joined one): what labels its series in GET /metrics, which
	 * must not change when it is dropped, or its counters would start a
	 * new series exactly when they count. */
	char last_machine[VMAC_NAME_MAX + 1];
	struct vmac_inputs inputs;
	struct vmac_outputs outputs; /* sent with the next UPDATE */
	int64_t last_seen_ns;
	/* Authenticated (keys.c): its announcement proved its enrolled key,
	 * and every frame of its session is sealed with these. */
	uint8_t keyed;
	uint8_t to_board[16], to_host[16];
	uint64_t tx_counter, rx_counter; /* the last sealed by us, the last of its accepted */
	uint64_t proved_nonce;           /* the discovery (bus->nonce_count) its announcement proved its key for */
	/* Time-triggered I/O (timed.c; docs/TIME.md, "The patterns"). */
	uint8_t timed_fw;   /* version 2 and it reads the TIMED form of its service: firmware 1.1 or later
	                     * a TIMED CYCLIC, 1.2 or later (served by unicast) a TIMED UPDATE */
	uint8_t sent_timed; /* the pending service went in a TIMED frame */
	int64_t in_at_ns;   /* that frame's in_at (0: plain): the reply deadline runs from it */
	int64_t sample_ns;  /* the instant of inputs: its latched_at, else the reply's receive time (0: none yet) */
	uint64_t timed_mismatch; /* replies of the other kind than their frame: a plain one to TIMED, or back */
	struct vmac_board_clock_status clock;
};

/* When d's reply deadline starts: when its request left, or its frame's
 * in_at if that is later (a board answers a TIMED record only once it has
 * latched). */
static inline int64_t bus_deadline_from(const struct device *d)
{
	return d->in_at_ns > d->sent_ns ? d->in_at_ns : d->sent_ns;
}

/* A TIMED CYCLIC frame of this slot (timed.c, bus.c's cyclic_put): one per
 * chunk, kind (sealed or not) and pair of instants. */
struct timed_frame {
	uint64_t out_at, in_at;
	uint32_t chunk;
	uint8_t keyed;
	int tx;
};

/* A request slot (vmac_bus_request_input): FREE -> FILLING (the caller
 * writes it) -> QUEUED -> RUNNING (the bus thread) -> DONE (answered, sem
 * posted) -> FREE (the caller read it). A caller that gives up moves QUEUED
 * to ABANDONED, and the bus thread frees it without running it; once
 * RUNNING, the caller waits for the answer, which comes without delay. */
enum { REQ_FREE, REQ_FILLING, REQ_QUEUED, REQ_RUNNING, REQ_DONE, REQ_ABANDONED };

/* What a request slot asks of the bus thread (mailbox.c, request_handlers). */
enum bus_request_kind {
	REQ_INPUT,    /* operator input to a machine's driver */
	REQ_SWAP,     /* hot reload: drv takes over a machine (swap.c) */
	REQ_MACHINES, /* the machines of a driver */
	REQ_RECORD,   /* a flight recording of a machine, now */
	REQ_KINDS
};

struct request {
	_Atomic int state;
	sem_t done;
	enum bus_request_kind kind;
	struct vmac_bus_input_request r;
	struct vmac_driver *drv; /* REQ_SWAP: the new instance */
	int64_t probation_ns;
	/* REQ_MACHINES: the caller's array, written only while RUNNING (a
	 * caller that finds its request RUNNING waits for the answer). */
	char (*names)[VMAC_NAME_MAX + 1];
	int max_names;
};

struct vmac_bus {
	struct vmac_config cfg;
	struct vmac_transport tr;
	int epfd;         /* the bus thread's wait (bus.c, bus_loop): the socket, wakefd (and tfd) */
	int wakefd;       /* eventfd: the main thread has commands or requests (bus_wake) */
	int timerfd_wait; /* no epoll_pwait2 on this kernel: ticks from tfd */
	int64_t held_ns;  /* the first push not yet woken for (bus_worker_push; wait.c's hold), or 0 */
	pthread_t thread;
	int tfd;
	int cpu_awake_fd;          /* /dev/cpu_dma_latency held at 0 (cpu_awake), or -1 */
	int64_t reply_deadline_ns; /* the configured reply deadline (reply_deadline_us) */
	int64_t start_ns;
	uint64_t tick_index;
	struct device *dev;
	uint32_t ndev;
	uint32_t nused; /* slots at or past this have never held a device: loops stop here */
	struct machine *mach;
	struct vmac_sched *sched;
	struct vmac_sched_entry *slot_entries;
	int64_t slot_ns;     /* one slot: the tick's period */
	uint16_t cyclic_seq; /* seq of the latest CYCLIC frames */
	int *chunk_tx;       /* per VMAC_CYCLIC_RECORDS_MAX offsets: its CYCLIC frame in tx this slot, or -1 */
	uint32_t nchunks;
	uint64_t slots_done; /* slots handed to the scheduler so far */
	uint16_t discover_seq;
	int64_t next_discover_ns;
	uint16_t sync_seq;    /* seq of the latest SYNC frame */
	int64_t next_sync_ns; /* when the next SYNC is due (clock_sync_ms) */
	int sync_tx;          /* its index in tx until bus_flush stamps it; -1 none */
	/* Sealed SYNC (keyed boards): one frame per chunk of
	 * VMAC_SYNC_AUTH_MACS_MAX offsets holding a keyed board, stamped and
	 * then sealed by bus_flush; its counter, one a SYNC, never repeated in
	 * a run. */
	int *sync_auth_tx; /* their indices in tx until bus_flush (nsync_auth of them) */
	int nsync_auth;
	uint32_t nsync_chunks; /* chunks of VMAC_SYNC_AUTH_MACS_MAX offsets */
	uint64_t sync_counter; /* sealed SYNC frames' freshness (u64: never wraps) */
	/* The two-step SYNC (sync.c): per stream (the plain SYNC, then each
	 * sealed chunk: 1 + nsync_chunks), its last frame sent and the kernel's
	 * transmit time of it, named in the stream's next frame. */
	struct sync_stream *sync_streams;
	int64_t next_probation_ns; /* next look for reloads whose probation is over */
	struct vmac_packet *tx;
	int ntx;
	struct vmac_packet rx[RX_BATCH];
	struct vmac_hist lateness;
	struct vmac_bus_counters counters;
	_Atomic uint64_t heartbeat; /* counters.ticks for other threads (vmac_bus_heartbeat) */
	/* The attach limiter (devices.c, attach_allowed): credit in ns of
	 * attach_rate, at most attach_max attaches' worth; what it refused
	 * since the last warning, said at most every FLOOD_WARN_NS. */
	int64_t attach_credit_ns, attach_credit_at_ns;
	int attach_credit_set;
	uint64_t refused_unsaid, table_full_unsaid;
	int64_t flood_said_ns;
	/* Trust on the wire (keys.c). */
	struct vmac_bus_keys *keys; /* the enrolled boards' keys (NULL: none yet) */
	uint8_t nonce_key[16];      /* makes each discovery's nonce */
	uint8_t nonce[8];           /* the latest DISCOVER's */
	uint64_t nonce_count;
	uint64_t cyclic_counter; /* authenticated CYCLIC frames' counter */
	int *auth_chunk_tx;      /* per VMAC_CYCLIC_AUTH_RECORDS_MAX offsets: its sealed CYCLIC frame in tx, or -1 */
	uint32_t nauth_chunks;
	struct timed_frame *timed_frames; /* this slot's TIMED frames: at most one per device due (slices_per_slot) */
	int ntimed_frames;
	int64_t auth_said_ns;
	uint64_t auth_unsaid;
	int realtime;
	int stopping;
	int64_t stop_deadline_ns;
	int64_t last_status_ns;
	int64_t last_malformed_log_ns;
	uint64_t malformed_suppressed;
	struct vmac_ring to_main, to_bus;
	struct vmac_ring checkpoints; /* struct vmac_bus_checkpoint + checkpoint_kib KiB each, to the main thread */
	struct request req[VMAC_BUS_REQUESTS];
	_Atomic int req_queued; /* requests QUEUED since the bus thread last looked */
	_Atomic int ended;      /* the bus thread has returned: no request is taken any more */
	void (*wakeup)(void *);
	void *wakeup_ctx;
	pthread_mutex_t status_lock;
	struct vmac_status status;
	char host_addr[48];
	/* Virtual mode (vmac test): no thread, no socket, no timer; the caller
	 * owns the clock and carries the frames (struct vmac_bus_link). */
	int virt;
	int64_t virt_now_ns;
	struct vmac_bus_link link;
	/* Driver workers (workers.c); none in virtual mode, where jobs run
	 * inline. */
	struct job *jobs; /* ndev, one per machine */
	struct worker *workers;
	int nworkers, nworkers_max;
	int64_t job_limit_ns; /* how long a job other than a tick may run */
	struct {              /* virtual mode: drivers whose calls take virtual time */
		char driver[VMAC_NAME_MAX + 1];
		int64_t cost_ns;
	} virt_cost[VMAC_BUS_VIRTUAL_COSTS];
};

/* bus.c */
int64_t bus_now(const struct vmac_bus *bus);
double bus_time(const struct vmac_bus *bus);
/* A packet of this flush's batch to fill (bus_flush first when full). */
struct vmac_packet *bus_tx_slot(struct vmac_bus *bus);
/* A system frame to every board (the discovery group; broadcast on raw
 * Ethernet) queued: its packet, or NULL when it did not encode. */
struct vmac_packet *bus_queue_group(struct vmac_bus *bus, const struct vmac_msg *m);
void bus_queue(struct vmac_bus *bus, struct device *d, struct vmac_msg *m, int expect_reply);
void bus_flush(struct vmac_bus *bus);
void bus_send_shutdown(struct vmac_bus *bus, struct device *d, uint8_t reason, int expect_reply);
void bus_begin_stop(struct vmac_bus *bus, int64_t now);
int bus_tick(struct vmac_bus *bus, int64_t now, uint64_t expirations);

/* sync.c: the SYNC frames and the two-step. Stream 0 is the plain SYNC, 1 + c the
 * sealed chunk c (offsets from c x VMAC_SYNC_AUTH_MACS_MAX). */
struct sync_stream {
	uint16_t seq;    /* its last SYNC frame stamped (host_ns) */
	uint8_t stamped; /* tx_ns is that frame's transmit time, from the kernel */
	int64_t host_ns, tx_ns;
};
/* This tick's SYNC frames queued (the tick they fall due in), before its
 * CYCLIC frames. */
void bus_send_sync(struct vmac_bus *bus);
/* The queued SYNC frames stamped with the host's time, then sealed: the
 * last thing before the batch goes to the kernel (bus_flush). */
void bus_sync_stamp(struct vmac_bus *bus);
/* The transmit stamps waiting on the socket, read (never blocking) and
 * kept for the next frames; all: whatever waits in the error queue, even
 * with no SYNC awaiting its stamp (epoll said EPOLLERR). */
void bus_sync_read_stamps(struct vmac_bus *bus, int all);

/* mailbox.c */
/* 0, or -EAGAIN when the ring to the main thread is full (counted in events_lost). */
int bus_post(struct vmac_bus *bus, const struct vmac_bus_msg *m);
void bus_event(struct vmac_bus *bus, const struct device *d, const char *kind, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
void bus_post_code(struct vmac_bus *bus, enum vmac_event_code code, const struct machine *m, const char *version,
                   int64_t version_id, const char *kind, const char *text);
void bus_requests(struct vmac_bus *bus);
void bus_commands(struct vmac_bus *bus);
/* receive.c: one frame from the bus, judged and acted on. */
void bus_handle_packet(struct vmac_bus *bus, const struct vmac_packet *p);
/* wait.c: the bus thread's wait and loop. bus_wake: what to_bus and the
 * requests hold is there (any thread). bus_drain (receive.c): every reply
 * waiting on the socket; the workers it pushed to are woken by the caller
 * (bus_workers_kick). */
int bus_wait_init(struct vmac_bus *bus, char *err, size_t errlen);
void bus_wait_fini(struct vmac_bus *bus);
void bus_loop(struct vmac_bus *bus);
void bus_wake(struct vmac_bus *bus);
void bus_drain(struct vmac_bus *bus);

/* jobs.c: the bus thread's side of the driver workers */
int bus_jobs_init(struct vmac_bus *bus);
void bus_jobs_fini(struct vmac_bus *bus);
/* Run what m waits for, if its job is free. */
void bus_dispatch(struct vmac_bus *bus, struct machine *m);
/* Operator input in virtual mode: m's job (name, value filled in) runs now;
 * the job's input_rc and reply say how it went. */
void bus_input_now(struct vmac_bus *bus, struct machine *m);
/* Every job done: what it gave applied; every job overrun: failed. */
void bus_collect(struct vmac_bus *bus, int64_t now);
/* Before d is served in slot (at level): at the first service of its
 * machine in a period, its boards take the outputs its last tick left
 * (jobs.c). */
void bus_release_outputs(struct vmac_bus *bus, struct device *d, uint64_t slot, unsigned level);
/* m is going away: its job is given up. 1 when a worker has (or had) it,
 * with the instances *drv and *other it holds and its checkpoint buffer:
 * those are the worker's to dispose of; 0: everything of m is the
 * caller's. */
int bus_job_release(struct vmac_bus *bus, struct machine *m, struct vmac_driver **drv, struct vmac_driver **other);
/* m's last tick, done but not yet collected when its next reply comes
 * (its worker finished after the tick that would have collected it), is
 * collected now: the reply's tick then starts at once, not at the next
 * tick, a slot late, and so every tick after it. */
void bus_collect_done_tick(struct vmac_bus *bus, struct machine *m);
/* Answer request slot i (rc and reply already in it). */
void bus_answer(struct vmac_bus *bus, int i);
/* The machine's job is free, and nothing is queued for it. */
int bus_machine_idle(const struct vmac_bus *bus, const struct machine *m);

/* workers.c */
int bus_workers_init(struct vmac_bus *bus, char *err, size_t errlen);
int bus_workers_start(struct vmac_bus *bus);
void bus_workers_fini(struct vmac_bus *bus);
/* The job of machine mi to its worker (bus thread); 0, or -1 (no worker). */
int bus_worker_push(struct vmac_bus *bus, struct machine *m);
/* Wake the workers pushed to since the last call. */
void bus_workers_kick(struct vmac_bus *bus);
/* A worker overran a job: retired, its queued jobs moved. */
void bus_worker_retire(struct vmac_bus *bus, int w);
/* Run a job (a worker, or the bus in virtual mode). */
void bus_run_job(struct job *j);
/* CPU time worker w has used (ns), -1 when it cannot be read. */
int64_t bus_worker_cpu_ns(struct vmac_bus *bus, int w);

/* Whether d is given an offset while it registers (SIZE, OFFSET): served
 * by the cyclic frame, or a keyed board that reads TIMED UPDATEs while
 * the host sends SYNC, whose offset places its MAC in the sealed SYNC (a
 * keyed board syncs from nothing else; docs/PROTOCOL.md, "The TIMED
 * UPDATE"). */
static inline int bus_holds_offset(const struct vmac_bus *bus, const struct device *d)
{
	return d->cyclic || (d->keyed && d->timed_fw && bus->cfg.clock_sync_ms > 0);
}

/* devices.c */
void bus_unload(struct vmac_bus *bus, struct vmac_driver *drv);
void bus_unload_buffer(struct vmac_bus *bus, void *buf);
uint32_t bus_slot_of(const struct vmac_bus *bus, const struct device *d);
void bus_unschedule(struct vmac_bus *bus, struct device *d);
void bus_free_machine(struct vmac_bus *bus, struct machine *m);
void bus_drop(struct vmac_bus *bus, struct device *d, uint8_t reason, const char *kind, const char *why);
void bus_miss(struct vmac_bus *bus, struct device *d, const char *fmt_why);
void bus_check_deadlines(struct vmac_bus *bus, int64_t now);
void bus_on_announce(struct vmac_bus *bus, const struct vmac_msg *m, const struct vmac_packet *p);
void bus_bind_driver(struct machine *m, struct vmac_driver *drv);
void bus_give_boards(struct vmac_bus *bus, struct machine *m, struct vmac_driver *drv);
void bus_driver_failed(struct vmac_bus *bus, struct machine *m, const char *where, const char *err);
void bus_run_machine(struct vmac_bus *bus, struct machine *m);
void bus_apply_level(struct vmac_bus *bus, struct machine *m, unsigned level);
void bus_on_loaded(struct vmac_bus *bus, struct device *d, const struct vmac_host_cmd *c);
/* The device request slot i names (its name copied into device) and its
 * machine (*m, or NULL); NULL when there is no such device. */
struct device *bus_request_target(struct vmac_bus *bus, int i, char device[VMAC_NAME_MAX + 1], struct machine **m);
struct device *bus_find_by_name(struct vmac_bus *bus, const char *name);

/* swap.c */
/* Roll m back to m->prev (asked: done by a job); -1 when there is none. */
int bus_roll_back(struct vmac_bus *bus, struct machine *m, const char *why);
void bus_rolled_back(struct vmac_bus *bus, struct machine *m, struct job *j);
/* A swap request (slot i): refused now (answered), or waiting for m's job. */
void bus_swap(struct vmac_bus *bus, int i);
void bus_swapped(struct vmac_bus *bus, struct machine *m, struct job *j);
void bus_end_probations(struct vmac_bus *bus, int64_t now);

/* record.c: the flight recorder's bus side (no allocation) */
void bus_rec_attach(struct vmac_bus *bus, struct machine *m, int64_t t_ns);
void bus_rec_join(struct vmac_bus *bus, struct machine *m);
void bus_rec_tick(struct vmac_bus *bus, struct machine *m, int64_t t_ns, int n, const struct vmac_inputs *in,
                  const struct vmac_outputs *out, const double *sample_s);
/* realtime.c, at the bus thread's start. */
void bus_try_realtime(struct vmac_bus *bus);
void bus_try_cpu_awake(struct vmac_bus *bus);
/* A checkpoint of m's dev.state just encoded (now: CLOCK_MONOTONIC, as the
 * tick's), offered to its recorder. */
void bus_rec_state(struct vmac_bus *bus, struct machine *m, int64_t now, const uint8_t *data, size_t len);
/* Operator input, recorded before the driver's input() runs (what that
 * does, a level change, is recorded after it, in time order); its outcome
 * is filled in after (n: what bus_rec_input returned). */
uint64_t bus_rec_input(struct vmac_bus *bus, struct machine *m, int64_t t_ns, const char *name,
                       const struct vmac_value *v);
void bus_rec_input_rc(struct machine *m, uint64_t n, int rc);
void bus_rec_level(struct vmac_bus *bus, struct machine *m, unsigned level);
void bus_rec_miss(struct vmac_bus *bus, struct device *d, const char *why);
void bus_rec_failure(struct vmac_bus *bus, struct machine *m, int kind, const char *text);
/* Another version took over m (a hot reload, a rollback): the recorder says
 * so, and keeps the new version's dev.state after its first tick. */
void bus_rec_swap(struct vmac_bus *bus, struct machine *m);
/* m is going away: its recorder to the main thread, captured when it has a
 * reason, else to be freed. */
void bus_rec_release(struct vmac_bus *bus, struct machine *m);
/* m runs on: its recorder to the main thread, captured with reason why,
 * and a new one asked for. 0, or -1 (no recorder). */
int bus_rec_capture(struct vmac_bus *bus, struct machine *m, const char *why);
/* A new recorder the main thread sent after a capture (VMAC_CMD_RECORDER). */
void bus_rec_install(struct vmac_bus *bus, const struct vmac_host_cmd *c);

/* checkpoint.c */
int bus_checkpoints_init(struct vmac_bus *bus);
void bus_checkpoints_fini(struct vmac_bus *bus);
/* Whether m's next tick should make a checkpoint (checkpoint_s passed). */
int bus_checkpoint_due(struct vmac_bus *bus, struct machine *m, int64_t now);
/* A job of m encoded one (j->ckpt_rc): into the ring for the main thread. */
void bus_checkpoint_taken(struct vmac_bus *bus, struct machine *m, struct job *j, int64_t now);
/* m's primary is registered: attach(), then recover() with the checkpoint
 * offered, as m's job; a failure of either fails the driver. */
void bus_attached(struct vmac_bus *bus, struct machine *m, int64_t now);
void bus_attach_done(struct vmac_bus *bus, struct machine *m, struct job *j);

/* keys.c */
/* board's key, or NULL when it is not enrolled. */
const uint8_t *bus_key_of(const struct vmac_bus *bus, const char *board);
/* How many keys the bus holds. */
uint32_t bus_keys_count(const struct vmac_bus *bus);
/* VMAC_CMD_KEYS: keys in, the old table out; boards whose key went, dropped. */
void bus_keys_install(struct vmac_bus *bus, struct vmac_bus_keys *keys);
void bus_nonce_init(struct vmac_bus *bus);
/* A new bus->nonce, for the next DISCOVER. */
void bus_nonce_next(struct vmac_bus *bus);
/* d (its id set) proved key answering bus->nonce: its session's keys. */
void bus_session_keys(struct vmac_bus *bus, struct device *d, const uint8_t key[16]);
/* A frame that did not prove a key: counted, said at most every 10 s. */
void bus_auth_failed(struct vmac_bus *bus, const struct vmac_packet *p, const char *board, const char *why);

/* timed.c: the host's side of time-triggered I/O */
/* m's timing at level (its driver's pattern resolved, its instants'
 * offsets): 0, or -1 with err (an offset not within that level's period). */
int bus_timing_set(struct vmac_bus *bus, struct machine *m, unsigned level, char *err, size_t errlen);
/* The instants of d's service in slot (level: its entry's): 1 when it goes
 * in a TIMED frame (a TIMED CYCLIC, or served by unicast a TIMED UPDATE),
 * else 0 (a board of older firmware or version 1, a machine acting on
 * arrival, clock sync off, virtual time). */
int bus_service_instants(struct vmac_bus *bus, const struct device *d, uint64_t slot, unsigned level, uint64_t *out_at,
                         uint64_t *in_at);
/* d's outputs in a unicast UPDATE queued (bus.c's service_slot, for a
 * board not served by the cyclic frame): TIMED with its instants when its
 * board reads them, its reply deadline then from in_at. */
void bus_unicast_update(struct vmac_bus *bus, struct device *d, uint64_t slot, unsigned level);
/* An UPDATE reply of d's in time (m): its inputs' instant and, TIMED, its
 * board's clock. */
void bus_timed_reply(struct vmac_bus *bus, struct device *d, const struct vmac_msg *m, int64_t rx_ns);

/* status.c */
const char *bus_state_name(enum dev_state s);
void bus_publish(struct vmac_bus *bus, int64_t now);

#endif
