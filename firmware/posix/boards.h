/* vmac-board's set of simulated boards, shared by main.c (options, the
 * loop), boards.c (making the boards, their printed lines, the periodic
 * watchdog and plant step, operator commands) and dispatch.c (routing each
 * received frame to the one board it is for, in O(1), and sending the
 * replies of a batch together). Not portable firmware: POSIX only. */
#ifndef VMAC_POSIX_BOARDS_H
#define VMAC_POSIX_BOARDS_H

#include <stdint.h>
#include <stdio.h>

#include "../../core/driver/driver.h"
#include "../../core/sim/sim.h"
#include "../../core/transport/transport.h"
#include "../board.h"
#include "../report.h"
#include "oscillator.h"

#define BOARD_NONE (-1)        /* an empty entry of a routing table */
#define BOARDS_MAX 65535       /* a board's number (1-based) is the last 16 bits of its MAC */
#define BOARDS_REPLY_MAX 1024  /* replies collected before they are sent at most */
#define BOARDS_LIST_MACS_MAX 8 /* the start-up line lists each MAC up to this many boards */

struct posix_board {
	struct vmac_board board;
	struct vmac_sim sim;             /* the machine behind it: a C or a Lua plant */
	struct vmac_plant_safety safety; /* sim's safety monitor, as the report reads it */
	struct vmac_report report;       /* what its log last said (firmware/report.c) */
	uint16_t routed_offset;          /* the by_offset entry held for it; VMAC_OFFSET_NONE */
	uint32_t routed_device_id;       /* the session by_session points to it for; 0 none */
	int counted_known;               /* counted in board_set.known */
	uint8_t mac[6];                  /* Ethernet: the source MAC of its replies */
	struct oscillator *osc;          /* its counter, when the clocks are simulated (--clock-*); else NULL */
	struct vmac_addr timed_addr;     /* the sender of its last TIMED CYCLIC: where a TIMED reply goes */
	uint8_t waiting;                 /* in board_set.waiting */
};

/* The boards' local counters (--clock-ppm, --clock-offset, --clock-jitter-us,
 * --clock-seed): each board's counter is the oscillator model of the true
 * clock (CLOCK_MONOTONIC, the host's too on one machine), and each receive
 * timestamp is late by a random delay. Off: the counter is CLOCK_MONOTONIC
 * itself and timestamps are the kernel's. */
struct boards_clock_config {
	int on;
	double ppm, offset_s, jitter_us;
	uint64_t seed; /* board i's streams: seed + i */
};

/* What every board of the process is made from (main.c's options). */
struct boards_config {
	const char *plant;               /* a C plant by name ("washer"), unless plant_file */
	const char *plant_file;          /* a Lua plant's file (docs/BOARD.md, "Plant models in Lua") */
	struct vmac_luaplant_limits lua; /* its limits; board i's seed is lua.seed + i */
	double time_scale;               /* plant seconds per real second */
	const char *name;                /* base name: NAME, or NAME-1..NAME-N with count > 1 */
	const char *driver;              /* announced driver */
	long count;                      /* 1..BOARDS_MAX */
	long major;                      /* -1: hash of each board's name */
	long minor;
	uint8_t protocol; /* 1 or 2 */
	int eth;          /* raw Ethernet: each board has a MAC of its own */
	/* Keyed boards (keyfile.h): one board's key file, or a folder of
	 * NAME.key files, one per board; both NULL: unkeyed. */
	const char *key_file;
	const char *key_dir;
	struct boards_clock_config clock;
};

struct board_set {
	struct posix_board *boards;
	int32_t count;
	int quiet; /* print only state changes other than "known", and safety events */
	int eth;
	uint8_t mac_prefix[4]; /* 02:xx:xx:xx, the first four bytes of every board's MAC */

	/* Routing tables, made once; kept true by boards_track after anything a
	 * board does (dispatch.c reads them, never searches). */
	int32_t *by_offset;   /* [VMAC_OFFSET_NONE]: the board holding each cyclic offset */
	int32_t *by_session;  /* [65536], UDP: device_id & 0xFFFF -> the board last registered with it */
	int32_t *by_identity; /* UDP: open-addressed (major, minor) -> board, for REGISTER */
	uint32_t identity_mask;
	int32_t known; /* boards in a session (VMAC_BOARD_KNOWN), kept by boards_track: the housekeeping's pace */

	struct vmac_transport *transport;
	struct vmac_packet *replies; /* [BOARDS_REPLY_MAX]: rx_ns holds the request's receive time */
	int32_t *reply_board;        /* [BOARDS_REPLY_MAX]: which board each reply is from */
	int nreplies;

	double time_scale; /* plant seconds per real second */
	int64_t late_ns;   /* report a reply later than this after its request; 0: never */
	uint64_t late_replies, unroutable, unsent;
	uint64_t last_step_ms; /* plant time */
	int64_t clock_base_ns; /* CLOCK_MONOTONIC at start: the oscillators' true time 0 */
	/* The boards that may have an instant waiting (instants.c): each
	 * listed once (posix_board.waiting), dropped when found with none. */
	int32_t *waiting;
	int32_t nwaiting;
	FILE *io_log; /* --io-log: every timed output change and latch, with its true instant */
};

/* Make cfg->count boards (names, identities, keys, MACs, plants) and the
 * routing tables. Returns 0, or with a readable reason in err -2 (a name
 * the protocol refuses, a key file missing or not one, a Lua plant that
 * does not load, a --clock-offset below the counter's 0) or -1 (out of
 * memory). */
int boards_init(struct board_set *s, const struct boards_config *cfg, uint64_t now_ms, char *err, size_t errlen);
void boards_fini(struct board_set *s);

/* The board of identity (major, minor), for a REGISTER on UDP; an unknown
 * one first when several share it (--major with --count). BOARD_NONE when
 * none has it. */
int32_t boards_by_identity(const struct board_set *s, uint32_t major, uint32_t minor);

/* "02:12:34:56:00:01" into buf (18 bytes at least); returns buf. */
char *boards_mac_format(const uint8_t mac[6], char *buf, size_t len);

/* Make the routing tables agree with board i after anything it did: drop the
 * offset it no longer holds, add the one it holds now, and point its session
 * at it. O(1). */
void boards_track(struct board_set *s, int32_t i);

/* Check board i's watchdog (printing the trip) and keep the tables true. */
void boards_poll_one(struct board_set *s, int32_t i, uint64_t now_ms);

/* The periodic work, at most once per few ms of wall time: every watchdog,
 * the plants stepped to now (times the time scale; a Lua plant that fails
 * is said once and holds its inputs from then on), and the state and
 * output lines. */
void boards_housekeep(struct board_set *s, uint64_t now_ms);

/* Board i's own counter (ns) at CLOCK_MONOTONIC mono_ns: the oscillator's
 * when simulated, else mono_ns. rx: mono_ns is a receive timestamp, late
 * by the model's jitter. A time more than 4 s older than one already asked
 * for (frames queued while the process was stopped) is taken as 4 s. */
uint64_t boards_local_ns(struct board_set *s, int32_t i, int64_t mono_ns, int rx);

/* Every board's clock brought to now (holdover, lost: vmac_board_clock_poll)
 * and its state line printed when it changed. */
void boards_clock_poll(struct board_set *s, int64_t now_ns);

/* Board i's clock line with its sync counters (status, exit), unless it
 * never had a sync frame. */
void boards_print_clock(const struct board_set *s, int32_t i);

/* Print board i's state and output changes since it was last reported, and
 * a line for each unsafe episode its plant entered (even with --quiet). */
void boards_report(struct board_set *s, int32_t i);

/* text (a plant's failure or refusal: a message, maybe a traceback) as
 * one line for the log into out (len bytes at most with its NUL): the
 * message without its traceback, control characters made spaces. Returns
 * out. */
char *boards_one_line(const char *text, char *out, size_t len);

/* The frame counters of board i, one line (firmware/report.c). */
void boards_print_counters(const struct board_set *s, int32_t i);

/* An operator line 'NAME ACTION VALUE' (--commands); 'status' or 'NAME
 * status' prints the counters of every board, or of NAME. */
void boards_command(struct board_set *s, const char *line);

/* Time-triggered I/O (instants.c). Every board tells its actions to the
 * --io-log (s->io_log, when set): call once after boards_init. */
void boards_timed_init(struct board_set *s);

/* Board i was handed a TIMED CYCLIC: if an instant of its waits now, the
 * loop looks at it from now on. */
void boards_timed_track(struct board_set *s, int32_t i);

/* CLOCK_MONOTONIC (ns) at which the loop must wake for the earliest
 * instant any board waits for (its counter's deadline through its
 * oscillator), now_ns when one is due; INT64_MAX when none waits.
 * O(boards waiting). */
int64_t boards_next_instant(struct board_set *s, int64_t now_ns);

/* Every board's due actions at now_ns (its watchdog first), the TIMED
 * replies sent. */
void boards_run_instants(struct board_set *s, int64_t now_ns);

/* Route one batch of received frames to their boards (dispatch.c). The
 * replies collect in s->replies; boards_flush sends them. */
void boards_dispatch(struct board_set *s, struct vmac_packet *pkts, int n, uint64_t now_ms);

/* Send the collected replies, one sendmmsg per VMAC_TRANSPORT_BATCH, and
 * report those that left later than s->late_ns after their request came
 * in. */
void boards_flush(struct board_set *s);

#endif
