/* vmac recordings, vmac record, vmac recording get / to-test: a running
 * host's flight recordings (recordings.c, docs/CLI.md). */
#ifndef VMAC_CLI_RECORDINGS_H
#define VMAC_CLI_RECORDINGS_H

#include "command.h"

extern const struct vmac_cmd vmac_recordings_cmd, vmac_recording_cmd, vmac_record_cmd;

#endif
