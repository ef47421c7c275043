/* vmac bundle (docs/CLI.md): making and showing bundles, and reading what
 * vmac reload sends. */
#ifndef VMAC_CLI_BUNDLE_H
#define VMAC_CLI_BUNDLE_H

#include <stddef.h>

#include "command.h"

extern const struct vmac_cmd vmac_bundle_cmd;

/* What vmac reload PATH sends: a folder or a NAME.lua bundled on the fly
 * (its security counter counter_s, NULL: 0), or a bundle file as it is,
 * with its signature (sig_path, else PATH.minisig when there is one).
 * 0 with *data (*len), *sig (*siglen; NULL: none), the driver's name; or
 * an exit code (1, 2) after saying why on stderr. */
int vmac_cli_bundle_load(const char *path, const char *counter_s, const char *sig_path, char **data, size_t *len,
                         char **sig, size_t *siglen, char *name, size_t namelen);

#endif
