/* Replay of a flight recording against a driver (replay.c). */
#ifndef VMAC_VTEST_REPLAY_H
#define VMAC_VTEST_REPLAY_H

#include <stddef.h>

#include "../config/config.h"

/* Replay the recording text (len bytes) with cfg's drivers and stdlib: the
 * driver source in the recording (use_recorded, when it has one) or the
 * driver cfg finds (--drivers DIR, then the shipped ones). Returns 0 when
 * every output is as recorded (or the recorded failure does not happen),
 * 1 when an output differs or the driver fails, -1 when it cannot run (the
 * file, the driver); report says what, for people. */
int vt_replay(const char *text, size_t len, const struct vmac_config *cfg, int use_recorded, char *report,
              size_t reportlen);

#endif
