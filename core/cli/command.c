/* The one option parser and --help of vmac's commands, and the options
 * they share (docs/CLI.md). Each command is a struct vmac_cmd next to its
 * code; vmac.c lists them.
 *
 * OPTIONS
 * An option is --name, --name VALUE or --name=VALUE; -h and -q are the only
 * short ones. Options and arguments may come in any order ("vmac token
 * revoke ID --state DIR"); "--" ends the options. Names are matched whole,
 * never by a prefix. A value may start with '-' (--after -1 is refused by
 * the command, not taken for an option). The last of a repeated option wins.
 *
 * DEFAULTS
 * An option not given takes its environment variable's value when that is
 * set (even to ""), else its fallback: the parser does this, so a command
 * sees one value and --help says where it came from. */
#include "command.h"

#include <ctype.h>
#include <pwd.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client.h"

#define DEFAULT_STATE "/var/lib/vmac" /* vmacd's default state_dir (docs/HOST.md) */

/* The shared options, by enum vmac_cmd_opt. */
static const struct vmac_cmd_option common[VMAC_CMD_OWN] = {
    [VMAC_CMD_HTTP] = {"http", "host", 0, "ADDR:PORT", "VMAC_HTTP", "127.0.0.1:8080",
                       "the host's HTTP API, https://ADDR:PORT for one that serves TLS (its CA trusted through "
                       "$VMAC_CACERT, a PEM file)"},
    [VMAC_CMD_TOKEN] = {"token", NULL, 0, "T", "VMAC_TOKEN", NULL,
                        "the token for the host's API (docs/CLI.md, \"Tokens\")"},
    [VMAC_CMD_TOKEN_FILE] = {"token-file", NULL, 0, "F", "VMAC_TOKEN_FILE", NULL,
                             "read the token from F's first line, when no --token or $VMAC_TOKEN"},
    [VMAC_CMD_JSON] = {"json", NULL, 0, NULL, NULL, NULL, "print the JSON as the API gives it, not lines for people"},
    [VMAC_CMD_STATE] = {"state", NULL, 0, "DIR", "VMAC_STATE", DEFAULT_STATE,
                        "the host's state folder, as vmacd --state"},
    [VMAC_CMD_QUIET] = {"quiet", NULL, 'q', NULL, NULL, NULL, "no messages on stderr, only the answers"},
};

static const struct vmac_cmd_option help_option = {"help", NULL, 'h', NULL, NULL, NULL, "this text"};

#define HELP_ID (-1)
#define HELP_COLUMN 22 /* where an option's text starts in --help */
#define HELP_WIDTH 100
#define SUMMARY_COLUMN 14 /* where a command's summary starts in its parent's --help */

static void full_name(char *out, size_t len, const struct vmac_cmd *c, const char *parent)
{
	snprintf(out, len, "%s%s%s", parent ? parent : "", parent ? " " : "", c->name);
}

/* One past the id of c's last option: its own are VMAC_CMD_OWN.. (a table
 * longer than VMAC_CMD_OPT_MAX allows is cut there, and the integration
 * tests find the option missing from --help). */
static int ids_end(const struct vmac_cmd *c)
{
	int id = VMAC_CMD_OWN;
	while (c->own && id < VMAC_CMD_OPT_MAX && c->own[id - VMAC_CMD_OWN].name)
		id++;
	return id;
}

/* Option number id of c (HELP_ID for --help), or NULL. */
static const struct vmac_cmd_option *option(const struct vmac_cmd *c, int id)
{
	if (id == HELP_ID)
		return &help_option;
	if (id < VMAC_CMD_OWN)
		return c->common & VMAC_CMD_TAKES(id) ? &common[id] : NULL;
	return c->own ? &c->own[id - VMAC_CMD_OWN] : NULL;
}

/* The id of c's option named (len bytes; or short_name when len is 0): 0..,
 * HELP_ID, or -2 when c has no such option. */
static int find(const struct vmac_cmd *c, const char *name, size_t len, char short_name)
{
	int id;
	for (id = HELP_ID; id < ids_end(c); id++) {
		const struct vmac_cmd_option *o = option(c, id);
		if (!o)
			continue;
		if (len == 0 ? o->short_name && o->short_name == short_name
		             : (strlen(o->name) == len && strncmp(o->name, name, len) == 0) ||
		                   (o->alias && strlen(o->alias) == len && strncmp(o->alias, name, len) == 0))
			return id;
	}
	return -2;
}

/* text, whose first word goes at the current column, indent: wrapped at
 * HELP_WIDTH, each further line indented; a '\n' in it starts a line. */
static void wrapped(FILE *f, const char *text, int indent)
{
	int col = indent, line_start = 1;
	while (*text) {
		size_t word = strcspn(text, " \n");
		if (!line_start && col + 1 + (int)word > HELP_WIDTH) {
			fprintf(f, "\n%*s", indent, "");
			col = indent;
			line_start = 1;
		}
		fprintf(f, "%s%.*s", line_start ? "" : " ", (int)word, text);
		col += (int)word + !line_start;
		line_start = 0;
		text += word;
		if (*text == '\n') {
			fprintf(f, "\n%*s", indent, "");
			col = indent;
			line_start = 1;
		}
		text += strspn(text, " \n");
	}
	fputc('\n', f);
}

static void help_option_line(FILE *f, const struct vmac_cmd_option *o)
{
	char left[128], text[512];
	int n = snprintf(left, sizeof(left), "  ");
	if (o->short_name)
		n += snprintf(left + n, sizeof(left) - (size_t)n, "-%c, ", o->short_name);
	n += snprintf(left + n, sizeof(left) - (size_t)n, "--%s%s%s%s%s", o->name, o->alias ? ", --" : "",
	              o->alias ? o->alias : "", o->value ? " " : "", o->value ? o->value : "");
	snprintf(text, sizeof(text), "%s%s%s%s%s%s", o->help, o->env || o->fallback ? "; default " : "",
	         o->env ? "$" : "", o->env ? o->env : "", o->env && o->fallback ? ", else " : "",
	         o->fallback ? o->fallback : "");
	if (n + 2 > HELP_COLUMN) /* too wide: the text on the next line */
		fprintf(f, "%s\n%*s", left, HELP_COLUMN, "");
	else
		fprintf(f, "%-*s", HELP_COLUMN, left);
	wrapped(f, text, HELP_COLUMN);
}

/* Whether c takes any option but --help. */
static int has_options(const struct vmac_cmd *c)
{
	return c->common || (c->own && c->own[0].name);
}

void vmac_cmd_help(const struct vmac_cmd *c, const char *parent, FILE *f)
{
	char name[128];
	const struct vmac_cmd *const *s;
	int id;
	full_name(name, sizeof(name), c, parent);
	if (c->sub) {
		fprintf(f, "usage: %s %s [options]\n%s\n", name, c->args, c->about);
		for (s = c->sub; *s; s++) {
			fprintf(f, "  %-*s", SUMMARY_COLUMN - 2, (*s)->name);
			wrapped(f, (*s)->summary, SUMMARY_COLUMN);
		}
		fprintf(f, "\nRun '%s %s --help' for its options.\n", name, c->args);
		return;
	}
	fprintf(f, "usage: %s%s%s%s\n%s", name, has_options(c) ? " [options]" : "", c->args ? " " : "",
	        c->args ? c->args : "", c->about);
	fprintf(f, "\nOptions:\n");
	for (id = VMAC_CMD_OWN; id < ids_end(c); id++)
		help_option_line(f, option(c, id));
	for (id = 0; id < VMAC_CMD_OWN; id++)
		if (option(c, id))
			help_option_line(f, option(c, id));
	help_option_line(f, &help_option);
}

int vmac_cmd_usage_error(const struct vmac_cmd_args *a, const char *fmt, ...)
{
	va_list ap;
	fprintf(stderr, "%s: ", a->name);
	va_start(ap, fmt);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	fprintf(stderr, " (%s --help)\n", a->name);
	return VMAC_CMD_USAGE;
}

/* The options of argv into a->opt, the other arguments gathered at the
 * front of argv (every slot they move to has been read already). 0, 1 when
 * --help was printed, or VMAC_CMD_USAGE after saying what is wrong. */
static int parse(const struct vmac_cmd *c, const char *parent, int argc, char **argv, struct vmac_cmd_args *a)
{
	int i, id, options_end = 0;
	a->arg = argv + 1;
	for (i = 1; i < argc; i++) {
		const char *s = argv[i], *eq = NULL, *value;
		const struct vmac_cmd_option *o;
		size_t len = 0;
		if (options_end || s[0] != '-' || s[1] == 0) {
			a->arg[a->nargs++] = argv[i];
			continue;
		}
		if (strcmp(s, "--") == 0) {
			options_end = 1;
			continue;
		}
		if (s[1] == '-') {
			eq = strchr(s + 2, '=');
			len = eq ? (size_t)(eq - s - 2) : strlen(s + 2);
			id = len ? find(c, s + 2, len, 0) : -2;
		} else {
			id = s[2] == 0 ? find(c, NULL, 0, s[1]) : -2;
		}
		if (id == -2) {
			fprintf(stderr, "%s: unknown option '%s' (%s --help lists the options)\n", a->name, s, a->name);
			return VMAC_CMD_USAGE;
		}
		if (id == HELP_ID) {
			vmac_cmd_help(c, parent, stdout);
			return 1;
		}
		o = option(c, id);
		if (!o->value && eq) {
			fprintf(stderr, "%s: %.*s takes no value (%s --help)\n", a->name, (int)(eq - s), s, a->name);
			return VMAC_CMD_USAGE;
		}
		if (!o->value)
			value = "";
		else if (eq)
			value = eq + 1;
		else
			value = i + 1 < argc ? argv[++i] : NULL;
		if (!value) {
			fprintf(stderr, "%s: %s needs a value (%s)\n", a->name, s, o->value);
			return VMAC_CMD_USAGE;
		}
		a->opt[id] = value;
	}
	if (a->nargs >= c->min_args && (c->max_args < 0 || a->nargs <= c->max_args))
		return 0;
	if (a->nargs < c->min_args)
		fprintf(stderr, "%s: expected %s\n", a->name, c->expect ? c->expect : c->args ? c->args : "arguments");
	else
		fprintf(stderr, "%s: unexpected argument '%s'\n", a->name, a->arg[c->max_args]);
	fprintf(stderr, "usage: %s%s%s%s (%s --help)\n", a->name, has_options(c) ? " [options]" : "",
	        c->args ? " " : "", c->args ? c->args : "", a->name);
	return VMAC_CMD_USAGE;
}

/* The options not given: their environment variable's value, or fallback. */
static void defaults(const struct vmac_cmd *c, struct vmac_cmd_args *a)
{
	int id;
	for (id = 0; id < ids_end(c); id++) {
		const struct vmac_cmd_option *o = option(c, id);
		if (a->opt[id] || !o)
			continue;
		a->opt[id] = o->env && getenv(o->env) ? getenv(o->env) : o->fallback;
	}
}

/* "ACTION" -> "action", for "unknown action 'x'". */
static void lower(char *out, size_t len, const char *s)
{
	size_t i;
	for (i = 0; s[i] && i + 1 < len; i++)
		out[i] = (char)tolower((unsigned char)s[i]);
	out[i] = 0;
}

/* A parent (vmac, token, recording): its action, by argv[1]. */
static int dispatch(const struct vmac_cmd *c, const char *parent, const char *name, int argc, char **argv)
{
	const struct vmac_cmd *const *s;
	char what[32];
	if (argc < 2) {
		vmac_cmd_help(c, parent, stderr);
		return VMAC_CMD_USAGE;
	}
	if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
		vmac_cmd_help(c, parent, stdout);
		return 0;
	}
	for (s = c->sub; *s; s++)
		if (strcmp((*s)->name, argv[1]) == 0)
			return vmac_cmd_main(*s, name, argc - 1, argv + 1);
	lower(what, sizeof(what), c->args);
	if (argv[1][0] == '-')
		fprintf(stderr, "%s: the %s comes first, before '%s' (", name, what, argv[1]);
	else
		fprintf(stderr, "%s: unknown %s '%s' (", name, what, argv[1]);
	for (s = c->sub; *s; s++)
		fprintf(stderr, "%s%s", s == c->sub ? "" : ", ", (*s)->name);
	fprintf(stderr, "; %s --help)\n", name);
	return VMAC_CMD_USAGE;
}

int vmac_cmd_main(const struct vmac_cmd *c, const char *parent, int argc, char **argv)
{
	struct vmac_cmd_args a;
	char name[128];
	int rc;
	if (c->run_raw)
		return c->run_raw(argc, argv);
	full_name(name, sizeof(name), c, parent);
	if (c->sub)
		return dispatch(c, parent, name, argc, argv);
	memset(&a, 0, sizeof(a));
	a.name = name;
	rc = parse(c, parent, argc, argv, &a);
	if (rc)
		return rc == 1 ? 0 : rc;
	defaults(c, &a);
	if (c->common & (VMAC_CMD_TAKES(VMAC_CMD_TOKEN) | VMAC_CMD_TAKES(VMAC_CMD_TOKEN_FILE)) &&
	    vmac_client_token(a.opt[VMAC_CMD_TOKEN], a.opt[VMAC_CMD_TOKEN_FILE]) != 0)
		return VMAC_CMD_USAGE;
	return c->run(&a);
}

void vmac_cmd_who(char *out, size_t len)
{
	const struct passwd *pw = getpwuid(getuid());
	const char *sudo = getenv("SUDO_USER"), *name = pw ? pw->pw_name : "";
	char sudo_part[96] = "";
	if (strpbrk(name, "\" \\"))
		name = "";
	if (sudo && sudo[0] && !strpbrk(sudo, "\" \\") && strlen(sudo) < 64)
		snprintf(sudo_part, sizeof(sudo_part), ", sudo by \"%s\"", sudo);
	snprintf(out, len, "user \"%.64s\" (uid %u%s)", name[0] ? name : "?", (unsigned)getuid(), sudo_part);
}
