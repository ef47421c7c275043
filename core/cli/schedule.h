/* vmac schedule: a running host's schedule as seed 002's static time
 * manager's table, with each service's deadline violations (schedule.c,
 * docs/CLI.md). */
#ifndef VMAC_CLI_SCHEDULE_H
#define VMAC_CLI_SCHEDULE_H

#include "command.h"

extern const struct vmac_cmd vmac_schedule_cmd;

#endif
