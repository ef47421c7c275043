/* The options and the call vmac's API commands share (command.c). */
#ifndef VMAC_CLI_COMMAND_H
#define VMAC_CLI_COMMAND_H

#include <jansson.h>
#include <stddef.h>

struct vmac_cmd {
	const char *http, *token, *token_file;
	int json;
};

#define VMAC_CMD_OPTS                                                                                                  \
	{"http", required_argument, 0, 'H'}, {"host", required_argument, 0, 'H'},                                      \
	    {"token", required_argument, 0, 't'}, {"token-file", required_argument, 0, 'f'},                           \
	    {"json", no_argument, 0, 'j'},                                                                             \
	{                                                                                                              \
		"help", no_argument, 0, 'h'                                                                            \
	}

extern const char VMAC_CMD_HELP[];

void vmac_cmd_init(struct vmac_cmd *o);
/* One of the shared options (getopt's opt): 1 when handled. */
int vmac_cmd_opt(int opt, struct vmac_cmd *o);
/* Commands with only the shared options: 1 when the command is done
 * (--help, a bad option; *exit_code), else 0 with optind at the arguments. */
int vmac_cmd_only_common(int argc, char **argv, struct vmac_cmd *o, const char *help, int *exit_code);
/* method path [body, len: an upload] and the answer shown by show (or as
 * JSON with --json): 0 on HTTP 200, 1 otherwise. */
int vmac_cmd_run(const struct vmac_cmd *o, const char *method, const char *path, const char *body, size_t len,
                 void (*show)(json_t *answer));

#endif
