/* vmac lint FILE...: luacheck with exactly the driver sandbox's globals
 * (docs/CLI.md). */
#ifndef VMAC_CLI_LINT_H
#define VMAC_CLI_LINT_H

#include "command.h"

extern const struct vmac_cmd vmac_lint_cmd;

#endif
