/* vmac reload FILE, vmac rollback DRIVER, vmac drivers [DRIVER]: hot reload
 * of a running host's drivers (docs/CLI.md). Each returns the exit code. */
#ifndef VMAC_CLI_RELOAD_H
#define VMAC_CLI_RELOAD_H

int vmac_reload_main(int argc, char **argv);
int vmac_rollback_main(int argc, char **argv);
int vmac_drivers_main(int argc, char **argv);
int vmac_activate_main(int argc, char **argv);

#endif
