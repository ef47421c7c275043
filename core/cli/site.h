/* vmac site: every vmac host on one MQTT broker, its devices and their last
 * values, from the broker alone (docs/CLI.md, "vmac site"). */
#ifndef VMAC_CLI_SITE_H
#define VMAC_CLI_SITE_H

#include "command.h"

extern const struct vmac_cmd vmac_site_cmd;

#endif
