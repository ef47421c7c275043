/* The entry points libFuzzer calls in every harness of tests/fuzz/ (declared
 * here for the strict warnings; docs/TESTING.md, "Fuzzing"). */
#ifndef VMAC_FUZZ_H
#define VMAC_FUZZ_H

#include <stddef.h>
#include <stdint.h>

/* One input: 0 always; a broken invariant abort()s, and libFuzzer keeps the
 * input that did it. */
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
/* Once, before the first input (optional). */
int LLVMFuzzerInitialize(int *argc, char ***argv);

#endif
