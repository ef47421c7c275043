/* Generic peripheral board logic (thesis 4.5): answers the host, drives the
 * outputs, enforces the comm-loss watchdog. Portable C99: no heap, no OS
 * headers, no clock of its own (the caller passes the time in), so the same
 * code runs on a microcontroller, in vmac-board, and in virtual time. */
#ifndef VMAC_BOARD_H
#define VMAC_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "../core/proto/auth.h"
#include "../core/proto/proto.h"
#include "clock.h"

#define VMAC_FIRMWARE_MAJOR 1
#define VMAC_FIRMWARE_MINOR 2 /* 1.1: TIMED CYCLIC; 1.2: TIMED UPDATE (docs/PROTOCOL.md, "Time-triggered I/O") */
#define VMAC_BOARD_DEFAULT_WATCHDOG_MS 500
/* A receive time the caller does not have (vmac_board_receive): a SYNC
 * frame is then of no use to the clock, and ignored. */
#define VMAC_BOARD_NO_STAMP UINT64_MAX
/* The largest reply a board sends: a frame and its authentication trailer. */
#define VMAC_BOARD_REPLY_MAX (VMAC_FRAME_MAX + VMAC_AUTH_TRAILER_LEN)

/* The board's I/O, provided by the HAL (real pins, or a simulated plant). */
struct vmac_board_io {
	/* Fill digital, analog and encoder; the board fills `applied` itself. */
	void (*read_inputs)(void *ctx, struct vmac_inputs *in);
	/* Drive the outputs. Called with all-zero outputs to make the board safe. */
	void (*write_outputs)(void *ctx, const struct vmac_outputs *out);
};

enum vmac_board_state {
	VMAC_BOARD_UNKNOWN,  /* outputs off; answers discovery */
	VMAC_BOARD_KNOWN,    /* registered; serves its session; watchdog armed */
	VMAC_BOARD_SLEEPING, /* outputs off; silent until sleep_until_ms */
};

struct vmac_board_identity {
	char driver[VMAC_NAME_MAX + 1];
	char board[VMAC_NAME_MAX + 1];
	uint32_t major, minor;
	struct vmac_caps caps;
	uint8_t protocol; /* the highest protocol version it speaks: 1, or 2 (0 means VMAC_PROTO_VERSION) */
	/* Keyed (docs/PROTOCOL.md, "Authenticated frames"): the board answers
	 * only a DISCOVER with a nonce, seals every frame it sends, and obeys
	 * no frame that does not open under its session's key. */
	uint8_t keyed;
	uint8_t key[VMAC_KEY_LEN];
};

struct vmac_board_counters {
	uint32_t frames_ok, frames_malformed, frames_ignored, watchdog_trips;
	uint32_t auth_failed;   /* keyed: a frame unsealed, of a wrong MAC, or replayed: ignored */
	uint32_t sync_ignored;  /* SYNC frames not fed to the clock: version 1, no receive time; unkeyed: sealed;
	                         * keyed: unsealed, before a session and offset, or no MAC for our offset */
	uint32_t sync_two_step; /* clock samples fed with the kernel's transmit time (prev_tx_ns), not host_ns */
	/* TIMED CYCLIC records and TIMED UPDATEs served (docs/TIME.md, "Time-triggered I/O"):
	 * by the clock at the host's instants; on arrival (the clock not
	 * usable, or no receive time); late (by the clock, but an instant
	 * already past on arrival: acted on at once); overrun (a new record
	 * came while an earlier one's action still waited: that one was done
	 * at once). */
	uint32_t timed, timed_arrival, timed_late, timed_overrun;
};

/* The two-step SYNC (docs/TIME.md, "The two-step SYNC"): a SYNC whose
 * sample waits for the next SYNC of its stream to name its transmit time is
 * held only while SYNC frames come at most this far apart, so that no
 * sample reaches the clock more than this late (its holdover counts from a
 * sample's receive time). */
#define VMAC_BOARD_TWO_STEP_GAP_NS 20000000u
/* A prev_tx_ns later than the frame's host_ns by more than this is not
 * believed (the kernel sends within microseconds): the one-step sample. */
#define VMAC_BOARD_TWO_STEP_SPAN_NS 10000000u

/* The last SYNC taken: its seq, its stream (the sealed chunk's first
 * offset; VMAC_OFFSET_NONE for the plain SYNC), host time and receive
 * time, the interval before it, and whether its sample waits (deferred);
 * whether the host names transmit times (two_step: a SYNC named its
 * predecessor's, and fewer than VMAC_BOARD_UNNAMED_MAX since named none). */
#define VMAC_BOARD_UNNAMED_MAX 16
struct vmac_board_sync_last {
	uint8_t valid, deferred, two_step, unnamed;
	uint16_t seq, stream;
	uint64_t host_ns, rx_local_ns;
};

/* One action of time-triggered I/O as the board did it, for its caller's
 * log (vmac_board.acted): an output change or an input latch. */
enum vmac_timed_kind { VMAC_TIMED_OUT, VMAC_TIMED_LATCH };
enum vmac_timed_how {
	VMAC_TIMED_AT_INSTANT, /* at the host's instant, by the clock (a timer compare) */
	VMAC_TIMED_ON_ARRIVAL, /* the clock not usable: on the frame's arrival (the fallback) */
	VMAC_TIMED_LATE,       /* its instant already past when the frame came: at once */
	VMAC_TIMED_OVERRUN,    /* still waiting when the next record came: done at once, before it */
};
struct vmac_timed_action {
	enum vmac_timed_kind kind;
	enum vmac_timed_how how;
	uint64_t local_ns;           /* the board counter's instant it was done at; 0 when the caller gave none */
	uint64_t host_ns;            /* the host instant the frame asked for */
	struct vmac_outputs outputs; /* driven (OUT), or driven at the latch (LATCH: the reply's `applied`) */
};
/* How the board last served a TIMED record (its log's "acting ..." line). */
enum vmac_timed_mode { VMAC_TIMED_MODE_NONE, VMAC_TIMED_MODE_INSTANTS, VMAC_TIMED_MODE_ARRIVAL };

/* What a TIMED CYCLIC left waiting for its instant: at most one output and
 * one latch (no queue, no heap). local: on the board's counter. */
struct vmac_board_timed {
	uint8_t out_pending, latch_pending;
	struct vmac_outputs out;
	uint64_t out_local, out_host;
	enum vmac_timed_how out_how;
	uint64_t latch_local, latch_host;
	enum vmac_timed_how latch_how;
	uint16_t latch_seq;    /* the CYCLIC frame's: the reply's */
	uint8_t latch_stamped; /* the caller gave a receive time: the clock can say when */
	enum vmac_timed_mode mode;
};

struct vmac_board {
	struct vmac_board_identity id;
	enum vmac_board_state state;
	uint32_t device_id;     /* session id from REGISTER; 0 when unknown */
	uint16_t watchdog_ms;   /* comm-loss period while KNOWN */
	uint64_t last_valid_ms; /* time of the last valid frame of our session */
	uint64_t sleep_until_ms;
	uint16_t offset;             /* v2: our record's offset in CYCLIC frames; VMAC_OFFSET_NONE until told */
	struct vmac_outputs outputs; /* what we drive now */
	struct vmac_board_counters counters;
	/* Keyed: the nonce of the DISCOVER last answered, and the session's
	 * keys and counters (the host's last accepted, unicast and cyclic; ours). */
	uint8_t has_nonce;
	uint8_t nonce[VMAC_NONCE_LEN];
	uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
	uint64_t rx_counter, rx_cyclic_counter, tx_counter; /* u64: they never wrap (PROTOCOL.md) */
	uint64_t rx_sync_counter; /* the last sealed SYNC's counter fed to the clock in this session */
	/* The board's clock (docs/TIME.md), on the caller's free-running
	 * counter (ns), fed by the host's SYNC frames in any board state; its
	 * counter at the last feed or vmac_board_clock_poll, the instant its
	 * state was last looked at. */
	struct vmac_clock clock;
	uint64_t clock_local_ns;
	struct vmac_board_sync_last sync_last;
	struct vmac_board_timed timed; /* time-triggered I/O waiting (firmware/timed.c) */
	const struct vmac_board_io *io;
	void *io_ctx;
	/* Optional (NULL: none; set after vmac_board_init): told of every
	 * action of time-triggered I/O as it is done, for a log of instants. */
	void (*acted)(void *ctx, const struct vmac_board *b, const struct vmac_timed_action *a);
	void *acted_ctx;
};

/* Start in UNKNOWN with outputs off. */
void vmac_board_init(struct vmac_board *b, const struct vmac_board_identity *id, const struct vmac_board_io *io,
                     void *io_ctx, uint64_t now_ms);

/* Enforce the watchdog and the end of sleep. Call before every receive and
 * at least every few ms. Returns 1 when this call turned the outputs off
 * because of comm loss, else 0. */
int vmac_board_poll(struct vmac_board *b, uint64_t now_ms);

/* Handle one received datagram. Writes the reply frame into reply (cap bytes,
 * VMAC_BOARD_REPLY_MAX is always enough) and returns its length, or 0 when the
 * board stays silent (malformed frame, not addressed to it, or a discovery it
 * need not answer). A CYCLIC frame is answered only when the record at the
 * board's offset is its session's and due; reading it costs O(1) however
 * many records the frame carries. Never reads past frame + len. */
int vmac_board_receive(struct vmac_board *b, const uint8_t *frame, size_t len, uint64_t now_ms, uint8_t *reply,
                       size_t cap);

/* The same, with the frame's receive time rx_local_ns on the board's own
 * free-running counter (ns; the kernel's receive timestamp in vmac-board,
 * the Ethernet interrupt's timer on a microcontroller): a SYNC frame
 * (docs/PROTOCOL.md, "SYNC") is fed to the board's clock with it. A SYNC
 * frame is never answered and never feeds the watchdog; a board of
 * version 1 and a call without a receive time (VMAC_BOARD_NO_STAMP) count
 * it in sync_ignored and leave the clock alone. An unkeyed board takes
 * only plain SYNC frames; a keyed one only a sealed SYNC whose MAC at its
 * offset opens under its session's key with a fresh counter, so it syncs
 * from its registration on (docs/TIME.md, "Trust"). A TIMED CYCLIC
 * record's or TIMED UPDATE's instants are put on the same counter, the arrival being
 * rx_local_ns (below, "Time-triggered I/O"). */
int vmac_board_receive_at(struct vmac_board *b, const uint8_t *frame, size_t len, uint64_t now_ms, uint64_t rx_local_ns,
                          uint8_t *reply, size_t cap);

/* Time-triggered I/O (docs/PROTOCOL.md, "Time-triggered I/O"; the code in
 * firmware/timed.c). A TIMED CYCLIC record or a TIMED UPDATE (unicast) of
 * the board's session, given to vmac_board_receive_at with its receive
 * time, feeds the watchdog on arrival; with the clock usable its outputs
 * wait for out_at and, DUE (every UPDATE is), its latch for in_at, on the board's counter: the caller arms its timer
 * for vmac_board_next_deadline and calls vmac_board_run_due when it fires, which does what is due and gives the TIMED
 * reply to send. Without a usable clock (or through vmac_board_receive, no receive time) the record is served on
 * arrival and receive_at answers at once (ARRIVAL). A SHUTDOWN, SLEEP, new REGISTER or watchdog trip cancels whatever
 * waits. */

/* The board counter's instant (ns) at which vmac_board_run_due must be
 * called next, into *local_ns: 1, or 0 when nothing waits. */
int vmac_board_next_deadline(const struct vmac_board *b, uint64_t *local_ns);

/* Do what is due at the board counter's now_local_ns, in the order of the
 * instants (an output and a latch at one instant: the output first, so the
 * latch's `applied` is it). Returns the length of the TIMED reply to send
 * (written into reply, cap bytes; VMAC_BOARD_REPLY_MAX is enough; sealed
 * when the session is), or 0 when no latch was due. Call again while
 * vmac_board_next_deadline says something is due. */
int vmac_board_run_due(struct vmac_board *b, uint64_t now_local_ns, uint8_t *reply, size_t cap);

/* Forget whatever waits, doing none of it (the safe state never waits). */
void vmac_board_timed_cancel(struct vmac_board *b);

/* Time passes for the clock (vmac_clock_tick at local_ns: holdover, lost):
 * call as often as its state must be current. Returns its state. */
enum vmac_clock_state vmac_board_clock_poll(struct vmac_board *b, uint64_t local_ns);

/* The clock's estimate of (board counter - host time) at local_ns, ns, into
 * *offset_ns, and its error bound there: 0, or -1 when it has none
 * (unsynced, lost). */
int vmac_board_clock_offset(const struct vmac_board *b, uint64_t local_ns, int64_t *offset_ns, uint64_t *bound_ns);

/* Outputs off, session forgotten: what SHUTDOWN, comm loss and a board
 * process exiting all do. */
void vmac_board_safe(struct vmac_board *b);

/* 1 when every ANNOUNCE of this identity would be valid (names of 1..31
 * [A-Za-z0-9_-], capabilities in range), else 0: a board refuses to start
 * with an identity the host would refuse on every announce. */
int vmac_board_identity_valid(const struct vmac_board_identity *id);

const char *vmac_board_state_name(enum vmac_board_state s);

#endif
