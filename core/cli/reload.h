/* vmac reload FILE, rollback DRIVER, activate DRIVER ID, drivers [DRIVER]:
 * hot reload of a running host's drivers (docs/CLI.md). */
#ifndef VMAC_CLI_RELOAD_H
#define VMAC_CLI_RELOAD_H

#include "command.h"

extern const struct vmac_cmd vmac_reload_cmd, vmac_rollback_cmd, vmac_activate_cmd, vmac_drivers_cmd;

#endif
