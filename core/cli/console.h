/* vmac console / get / set: the line console of docs/CLI.md ("Console"),
 * after Olsen and Heyerdahl's article "Symbolic Access To Embedded
 * Controllers" (March 1994): a line of submessages DEVICE.NAME?
 * DEVICE.NAME:VALUE  DEVICE.NAME!  answered DEVICE.NAME:VALUE, or
 * DEVICE.NAME#CODE on an error. */
#ifndef VMAC_CLI_CONSOLE_H
#define VMAC_CLI_CONSOLE_H

int vmac_console_main(int argc, char **argv); /* vmac console */
int vmac_get_main(int argc, char **argv);     /* vmac get DEVICE.NAME... */
int vmac_set_main(int argc, char **argv);     /* vmac set DEVICE.NAME:VALUE|DEVICE.NAME!... */

#endif
