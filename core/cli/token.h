/* vmac token: create, list and revoke the host's access tokens (docs/CLI.md). */
#ifndef VMAC_CLI_TOKEN_H
#define VMAC_CLI_TOKEN_H

#include "command.h"

extern const struct vmac_cmd vmac_token_cmd;

#endif
