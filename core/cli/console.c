/* The line console over the HTTP API: see console.h and docs/CLI.md.
 * Each line goes to the host's POST /api/console, which answers it
 * (core/api/console.c): the console's rules live in one place. */
#include "console.h"

#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client.h"
#include "command.h"

/* Error codes the client gives itself (docs/CLI.md, "Console"): the host
 * answers every other one. */
enum {
	E_ACCESS = 7, /* the token is missing, invalid or lacks the scope */
	E_HOST = 8,   /* the host cannot be reached, is busy, or answered nonsense */
};

struct session {
	const char *http;
	int errors;
	int verbose; /* say each error's message on stderr */
};

/* Every submessage of text answered #code, the reason said once. */
static void all_failed(struct session *s, const char *text, int code, const char *why)
{
	const char *p = text;
	int first = 1;
	for (;;) {
		size_t n;
		p += strspn(p, " \t\r\n");
		if (!*p)
			break;
		n = strcspn(p, " \t\r\n");
		printf("%s%.*s#%d", first ? "" : " ", (int)strcspn(p, "?:>! \t\r\n"), p, code);
		s->errors++;
		first = 0;
		p += n;
	}
	if (!first)
		putchar('\n');
	if (s->verbose && why && *why)
		fprintf(stderr, "vmac: %s\n", why);
}

/* One line of submessages: POST /api/console, its answer on stdout. */
static void line(struct session *s, const char *text)
{
	char url[256], err[512];
	struct vmac_buffer b = {NULL, 0};
	long code;
	json_t *ans, *l, *e;
	size_t i, j;
	if (strspn(text, " \t\r\n") == strlen(text))
		return;
	vmac_client_url(url, sizeof(url), s->http, "/api/console");
	if (vmac_client_upload(url, text, strlen(text), &b, &code, err, sizeof(err)) != 0) {
		all_failed(s, text, E_HOST, err);
		fflush(stdout);
		return;
	}
	ans = json_loads(b.data ? b.data : "", 0, NULL);
	free(b.data);
	if (code == 401 || code == 403)
		all_failed(s, text, E_ACCESS, vmac_client_auth_hint());
	else if (code != 200 || !json_is_array(json_object_get(ans, "lines")))
		all_failed(s, text, E_HOST, json_string_value(json_object_get(ans, "error")));
	json_array_foreach(code == 200 ? json_object_get(ans, "lines") : NULL, i, l)
	{
		printf("%s\n", json_string_value(json_object_get(l, "answer")));
		json_array_foreach(json_object_get(l, "errors"), j, e)
		{
			if (s->verbose)
				fprintf(stderr, "vmac: %s\n", json_string_value(e));
		}
	}
	if (code == 200)
		s->errors += (int)json_integer_value(json_object_get(ans, "errors"));
	json_decref(ans);
	fflush(stdout);
}

static void setup(struct session *s, const struct vmac_cmd_args *a)
{
	memset(s, 0, sizeof(*s));
	s->http = a->opt[VMAC_CMD_HTTP];
	s->verbose = !a->opt[VMAC_CMD_QUIET];
}

/* What console, get and set take. */
#define CONSOLE_OPTIONS                                                                                                \
	(VMAC_CMD_TAKES(VMAC_CMD_HTTP) | VMAC_CMD_TAKES(VMAC_CMD_TOKEN) | VMAC_CMD_TAKES(VMAC_CMD_TOKEN_FILE) |        \
	 VMAC_CMD_TAKES(VMAC_CMD_QUIET))

#define ANSWERS                                                                                                        \
	"Answers DEVICE.NAME:VALUE, DEVICE.NAME! or DEVICE.NAME#CODE; codes in docs/CLI.md (\"Console\").\n"           \
	"Exit 0 when every submessage was answered without #, else 1; 2 wrong usage.\n"

static int console_run(const struct vmac_cmd_args *a)
{
	struct session s;
	char buf[4096];
	int interactive = isatty(STDIN_FILENO);
	setup(&s, a);
	for (;;) {
		if (interactive) {
			fputs("vmac> ", stderr);
			fflush(stderr);
		}
		if (!fgets(buf, sizeof(buf), stdin))
			break;
		line(&s, buf);
	}
	return s.errors ? 1 : 0;
}

const struct vmac_cmd vmac_console_cmd = {
    .name = "console",
    .summary = "the line console: DEVICE.NAME?  DEVICE.NAME:VALUE  DEVICE.NAME!",
    .about = "Read lines of DEVICE.NAME?  DEVICE.NAME:VALUE  DEVICE.NAME!  DEVICE.NAME>VALUE  from standard\n"
             "input (typed, or from a pipe; it takes no arguments) and answer each on one line. Needs a\n"
             "token of scope read for ?, operate for the others.\n" ANSWERS,
    .common = CONSOLE_OPTIONS,
    .run = console_run};

/* vmac get / set: the arguments as one console line. */
static int one_line(const struct vmac_cmd_args *a, int get)
{
	struct session s;
	char buf[4096] = "";
	size_t n = 0;
	int i;
	setup(&s, a);
	for (i = 0; i < a->nargs; i++) {
		int w = snprintf(buf + n, sizeof(buf) - n, "%s%s%s", n ? " " : "", a->arg[i],
		                 get && !strpbrk(a->arg[i], "?:>!") ? "?" : "");
		if (w < 0 || (size_t)w >= sizeof(buf) - n) {
			fprintf(stderr, "vmac: too many submessages for one line\n");
			return 2;
		}
		n += (size_t)w;
	}
	line(&s, buf);
	return s.errors ? 1 : 0;
}

static int get_run(const struct vmac_cmd_args *a)
{
	return one_line(a, 1);
}

static int set_run(const struct vmac_cmd_args *a)
{
	return one_line(a, 0);
}

const struct vmac_cmd vmac_get_cmd = {
    .name = "get",
    .args = "DEVICE.NAME...",
    .min_args = 1,
    .max_args = -1,
    .summary = "print published variables (DEVICE.NAME...)",
    .about = "Print published variables and params, e.g. vmac get washer-1.state washer-1.drum_rpm\n"
             "(a console line of DEVICE.NAME? each). Needs a token of scope read.\n" ANSWERS,
    .common = CONSOLE_OPTIONS,
    .run = get_run};

const struct vmac_cmd vmac_set_cmd = {
    .name = "set",
    .args = "DEVICE.NAME:VALUE|DEVICE.NAME!|DEVICE.NAME>VALUE...",
    .min_args = 1,
    .max_args = -1,
    .summary = "operator input (DEVICE.NAME:VALUE, DEVICE.NAME!)",
    .about = "Operator input as one console line, e.g. vmac set lights-1.kitchen:true, vmac set\n"
             "washer-1.start:quick, vmac set washer-1.cancel!, vmac set washer-1.program>wool (kept).\n"
             "Needs a token of scope operate.\n" ANSWERS,
    .common = CONSOLE_OPTIONS,
    .run = set_run};
