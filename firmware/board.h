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
#define VMAC_FIRMWARE_MINOR 0
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
 * time, the interval before it, and whether its sample waits (deferred). */
struct vmac_board_sync_last {
	uint8_t valid, deferred;
	uint16_t seq, stream;
	uint64_t host_ns, rx_local_ns;
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
	uint32_t rx_counter, rx_cyclic_counter, tx_counter;
	uint32_t rx_sync_counter; /* the last sealed SYNC's counter fed to the clock in this session */
	/* The board's clock (docs/TIME.md), on the caller's free-running
	 * counter (ns), fed by the host's SYNC frames in any board state; its
	 * counter at the last feed or vmac_board_clock_poll, the instant its
	 * state was last looked at. */
	struct vmac_clock clock;
	uint64_t clock_local_ns;
	struct vmac_board_sync_last sync_last;
	const struct vmac_board_io *io;
	void *io_ctx;
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
 * from its registration on (docs/TIME.md, "Trust"). */
int vmac_board_receive_at(struct vmac_board *b, const uint8_t *frame, size_t len, uint64_t now_ms, uint64_t rx_local_ns,
                          uint8_t *reply, size_t cap);

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
