/* The heap of the fuzz targets that run Lua (tests/fuzz/fuzz_arena.c):
 * one mapping that a driver's state lives in (vmac_driver_limits.heap),
 * which can be snapshotted once a driver is loaded and restored before
 * every input, so each input starts from a state identical to the first,
 * byte for byte, without building a sandbox again. docs/TESTING.md,
 * "Fuzzing", says what this gains and what the corpus replay under the
 * C library's allocator checks in its stead. */
#ifndef VMAC_FUZZ_ARENA_H
#define VMAC_FUZZ_ARENA_H

#include <stddef.h>
#include <stdint.h>

#include "../../core/driver/driver.h"

/* Whether the targets use the arena: VMAC_FUZZ_FRESH unset or 0 (the
 * default), or every input in a fresh sandbox from the C library's
 * allocator, as the host runs drivers (VMAC_FUZZ_FRESH=1; make fuzz
 * replays each corpus that way). */
int fuzz_arena_on(void);

/* Before loading a driver for this input: with the arena on, empty it and
 * give limits its allocator; off, nothing. */
void fuzz_arena_prepare(struct vmac_driver_limits *limits);

/* The kept driver restored to its snapshot, or NULL: none kept yet, or the
 * arena is off (the caller loads one). */
struct vmac_driver *fuzz_arena_kept(void);

/* Keep d, loaded just now after fuzz_arena_prepare, and snapshot the arena
 * and d's C side; the arena off, nothing. */
void fuzz_arena_keep(struct vmac_driver *d);

/* For a target that runs one fixed driver: src (named fuzz.lua) loaded with
 * this memory cap and instruction budget (levels 10, default 4), kept and
 * restored with the functions above, or loaded afresh with the arena off.
 * Aborts, naming target, when it does not load. fuzz_arena_done after. */
struct vmac_driver *fuzz_arena_fixed_driver(const char *target, const char *src, size_t len, size_t memory_bytes,
                                            uint64_t instructions);

/* After an input: free d unless it is the kept one (restored, not freed). */
void fuzz_arena_done(struct vmac_driver *d);

#endif
