/* vmac's commands as tables: the options they share, declared once, each
 * command's own options, one parser and one --help for all (command.c). */
#ifndef VMAC_CLI_COMMAND_H
#define VMAC_CLI_COMMAND_H

#include <stdio.h>

/* The exit code of wrong usage, the same for every command (docs/CLI.md). */
#define VMAC_CMD_USAGE 2

/* The options several commands take; each command names the ones it takes
 * in its mask. Their declarations are vmac_cmd_common in command.c. */
enum vmac_cmd_opt {
	VMAC_CMD_HTTP,       /* --http ADDR:PORT (or --host) */
	VMAC_CMD_TOKEN,      /* --token T */
	VMAC_CMD_TOKEN_FILE, /* --token-file F */
	VMAC_CMD_JSON,       /* --json */
	VMAC_CMD_STATE,      /* --state DIR */
	VMAC_CMD_QUIET,      /* --quiet, -q */
	VMAC_CMD_OWN,        /* a command's own options: VMAC_CMD_OWN + its index in own[] */
	VMAC_CMD_OPT_MAX = VMAC_CMD_OWN + 12
};

#define VMAC_CMD_TAKES(opt) (1u << (opt))
/* What every command on a running host's HTTP API takes (docs/CLI.md,
 * "Reaching a host", "Tokens"). */
#define VMAC_CMD_API                                                                                                   \
	(VMAC_CMD_TAKES(VMAC_CMD_HTTP) | VMAC_CMD_TAKES(VMAC_CMD_TOKEN) | VMAC_CMD_TAKES(VMAC_CMD_TOKEN_FILE) |        \
	 VMAC_CMD_TAKES(VMAC_CMD_JSON))

/* One option: --name, or --name VALUE / --name=VALUE when value is set. */
struct vmac_cmd_option {
	const char *name;     /* without the dashes; NULL ends a table */
	const char *alias;    /* another long name for it, or NULL */
	char short_name;      /* -q; 0: none */
	const char *value;    /* the value's name in --help; NULL: a flag, which takes none */
	const char *env;      /* the environment variable of its default, or NULL */
	const char *fallback; /* the default when env is not set, or NULL */
	const char *help;     /* what it does, for --help (the default is added) */
};

/* What the parser hands a command. */
struct vmac_cmd_args {
	const char *name; /* "vmac token create": how messages name the command */
	/* Each option by enum vmac_cmd_opt (own ones at VMAC_CMD_OWN + i): its
	 * value, its default, "" for a flag given, or NULL. */
	const char *opt[VMAC_CMD_OPT_MAX];
	char **arg; /* the arguments that are not options, in order (inside argv) */
	int nargs;
};

/* A command (or a subcommand: an action of token, recording). */
struct vmac_cmd {
	const char *name;    /* the word that names it after its parent's */
	const char *args;    /* its arguments in the usage line ("FILE.lua", "[DRIVER]"; a parent's "ACTION") */
	const char *expect;  /* what a wrong number of arguments is told it expects (NULL: args) */
	int min_args;        /* how many arguments it takes, at least */
	int max_args;        /* ... at most; -1: any number */
	const char *summary; /* one line in its parent's --help */
	const char *about;   /* its --help between the usage line and the options */
	unsigned common;     /* VMAC_CMD_TAKES() of the common options it takes */
	const struct vmac_cmd_option *own; /* its own options, ended by {NULL}; or NULL */
	/* Runs the command once the options are parsed (and the token taken,
	 * when it takes one): the exit code. */
	int (*run)(const struct vmac_cmd_args *a);
	/* Instead of run and the tables: takes argv as it is and parses it
	 * itself (vmac test, whose options core/vtest/runner.lua declares). */
	int (*run_raw)(int argc, char **argv);
	const struct vmac_cmd *const *sub; /* a parent: its actions, ended by NULL */
};

/* Runs c (argv[0] is its name; parent: the command line before it, "vmac",
 * or NULL for vmac itself): --help, unknown options, missing values and a
 * wrong number of arguments are answered here (exit 0 or VMAC_CMD_USAGE,
 * saying which option or argument), the rest by c->run. Reorders argv. */
int vmac_cmd_main(const struct vmac_cmd *c, const char *parent, int argc, char **argv);

/* c's --help on f. */
void vmac_cmd_help(const struct vmac_cmd *c, const char *parent, FILE *f);

/* Who runs this command, for the audit trail of what it changes in a
 * store itself (vmac token, vmac board --local): 'user "alice" (uid
 * 1000)', with the user sudo was run by when there is one. A name with a
 * quote or a blank (which the audit's grammar cannot hold) is said by its
 * uid alone. */
void vmac_cmd_who(char *out, size_t len);

/* "vmac CMD: MESSAGE (vmac CMD --help)" on stderr; returns VMAC_CMD_USAGE. */
int vmac_cmd_usage_error(const struct vmac_cmd_args *a, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

#endif
