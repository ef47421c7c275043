/* vmac lint FILE...: luacheck with exactly the driver sandbox's globals
 * (docs/CLI.md). Returns the exit code. */
#ifndef VMAC_CLI_LINT_H
#define VMAC_CLI_LINT_H

int vmac_lint_main(int argc, char **argv);

#endif
