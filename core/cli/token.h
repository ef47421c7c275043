/* vmac token: create, list and revoke the host's access tokens (docs/CLI.md). */
#ifndef VMAC_CLI_TOKEN_H
#define VMAC_CLI_TOKEN_H

int vmac_token_main(int argc, char **argv);

#endif
