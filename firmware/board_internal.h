/* What firmware/board.c shares with firmware/timed.c and nobody else: the
 * board's one way to drive its outputs, its sealing of a reply, and the
 * timed service board.c hands a TIMED CYCLIC record or a TIMED UPDATE to. Not an API: callers use
 * board.h. */
#ifndef VMAC_BOARD_INTERNAL_H
#define VMAC_BOARD_INTERNAL_H

#include "board.h"

/* Drive out and remember it as what the board drives. */
void vmac_board_drive(struct vmac_board *b, const struct vmac_outputs *out);

/* A reply of n bytes, sealed with the session's key when the board is
 * keyed: its length, or 0 when it cannot be sent. */
int vmac_board_seal(struct vmac_board *b, uint8_t *reply, int n, size_t cap);

/* One timed service, whichever frame brought it: a TIMED CYCLIC record or
 * a TIMED UPDATE (docs/PROTOCOL.md, "Time-triggered I/O"). */
struct vmac_board_service {
	struct vmac_outputs outputs;
	uint64_t out_at, in_at; /* the host instants of the outputs and of the latch */
	uint16_t seq;           /* the frame's: the TIMED reply echoes it */
	uint8_t due;            /* answer it (a DUE record; every UPDATE) */
};

/* Plain outputs of the board's session are about to be driven on
 * arrival: TIMED outputs still waiting for their instant are older, and
 * are dropped (the newest outputs win); a waiting latch keeps its instant
 * (timed.c). */
void vmac_board_timed_superseded(struct vmac_board *b);

/* A timed service of the board's session, checked and its watchdog fed
 * (board.c): schedule it, or act on arrival (timed.c). rx_local_ns is the
 * frame's receive time on the board's counter, or VMAC_BOARD_NO_STAMP.
 * Returns the length of a reply to send now, or 0. */
int vmac_board_timed_service(struct vmac_board *b, const struct vmac_board_service *s, uint64_t rx_local_ns,
                             uint8_t *reply, size_t cap);

#endif
