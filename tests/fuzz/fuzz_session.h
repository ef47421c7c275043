/* Shared by fuzz_proto.c and make_corpus.c: the fuzzed board's identity and
 * the record format of a multi-frame session input. */
#ifndef VMAC_FUZZ_SESSION_H
#define VMAC_FUZZ_SESSION_H

/* The board under fuzz answers REGISTER only for this major/minor. */
#define FUZZ_BOARD_MAJOR 1
#define FUZZ_BOARD_MINOR 2

/* A session input is a run of records: [step][len][len bytes of frame].
 * Before each frame the clock advances step * FUZZ_STEP_MS, so a fuzzer can
 * reach watchdog expiry (default 500 ms) within a few records. A short last
 * record is delivered with the bytes that are there. */
#define FUZZ_STEP_MS 4

#endif
