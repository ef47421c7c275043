/* vmac console / get / set: the line console of docs/CLI.md ("Console"),
 * after Olsen and Heyerdahl's article "Symbolic Access To Embedded
 * Controllers" (March 1994): a line of submessages DEVICE.NAME?
 * DEVICE.NAME:VALUE  DEVICE.NAME!  answered DEVICE.NAME:VALUE, or
 * DEVICE.NAME#CODE on an error. */
#ifndef VMAC_CLI_CONSOLE_H
#define VMAC_CLI_CONSOLE_H

#include "command.h"

extern const struct vmac_cmd vmac_console_cmd, vmac_get_cmd, vmac_set_cmd;

#endif
