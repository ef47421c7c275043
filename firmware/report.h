/* The board's log lines (docs/BOARD.md, "What it prints"), made in one
 * place for vmac-board (firmware/posix/) and the firmware on a
 * microcontroller (firmware/mcu/): what changed since the last report (its
 * state, its outputs, the plant's unsafe episodes), a watchdog trip and
 * the frame counters, each one line of text that people and the tests
 * read. Portable C99, no printf, no heap. */
#ifndef VMAC_REPORT_H
#define VMAC_REPORT_H

#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "plant.h"

#define VMAC_REPORT_LINE 160 /* room for any line, its NUL included */

/* What the log last said of one board. */
struct vmac_report {
	enum vmac_board_state state;
	struct vmac_outputs outputs;
	uint32_t unsafe;             /* the plant's unsafe episodes already named */
	enum vmac_clock_state clock; /* the board clock's state last named */
	enum vmac_timed_mode timed;  /* how it served TIMED records, last named */
	int quiet;                   /* only what matters for safety: leaving a session, unsafe episodes */
};

/* Start from what board b and the safety monitor s of its machine
 * (plant.h) are now: nothing to say yet. */
void vmac_report_init(struct vmac_report *r, const struct vmac_board *b, const struct vmac_plant_safety *s, int quiet);

/* The next line about what changed since the last one said, into line
 * (len bytes, VMAC_REPORT_LINE is enough): 1, or 0 when nothing more has
 * changed. Call until 0. */
int vmac_report_next(struct vmac_report *r, const struct vmac_board *b, const struct vmac_plant_safety *s, char *line,
                     size_t len);

/* Among the lines of vmac_report_next, when the way the board serves TIMED
 * records changes: "NAME: acting at host instants", or "NAME: acting on
 * arrival (clock STATE)" (with --quiet only the second). */

/* The line of a watchdog trip ("NAME: watchdog: no frame for N ms, outputs
 * off"); the caller may add the times its clock gives. */
void vmac_report_watchdog(const struct vmac_board *b, char *line, size_t len);

/* The board clock's line (docs/BOARD.md, "What it prints"): "NAME: clock
 * STATE, offset S s, drift P ppm, bound B us" at the instant it was last
 * looked at (b->clock_local_ns), offset being the board's counter less
 * host time; lost or unsynced, "NAME: clock lost, acting on arrival".
 * with_counters adds "; sync accepted N, rejected N, ignored N". A change
 * of state is said by vmac_report_next (with --quiet only lost). */
void vmac_report_clock(const struct vmac_board *b, int with_counters, char *line, size_t len);

/* The board's frame counters, one line: "NAME: frames ok N, malformed N,
 * ignored N, watchdog trips N, auth_failed N" (auth_failed: frames of a
 * keyed board's session that did not open under its key, or replays). */
void vmac_report_counters(const struct vmac_board *b, char *line, size_t len);

/* The board's TIMED CYCLIC services, one line: "NAME: timed N, on arrival
 * N, late N, overrun N" (firmware/board.h says what each counts); 0 and
 * no line when it never had one. */
int vmac_report_timed(const struct vmac_board *b, char *line, size_t len);

#endif
