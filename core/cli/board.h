/* vmac board: enroll, list and remove the boards a host trusts (docs/CLI.md). */
#ifndef VMAC_CLI_BOARD_H
#define VMAC_CLI_BOARD_H

#include "command.h"

extern const struct vmac_cmd vmac_board_cmd;

#endif
