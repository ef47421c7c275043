/* vmac events and vmac logs: follow a host's event stream (GET /api/events,
 * docs/CLI.md). */
#ifndef VMAC_CLI_EVENTS_H
#define VMAC_CLI_EVENTS_H

#include "command.h"

extern const struct vmac_cmd vmac_events_cmd;
extern const struct vmac_cmd vmac_logs_cmd;

#endif
