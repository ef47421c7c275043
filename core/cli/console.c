/* The line console over the HTTP API: see console.h and docs/CLI.md.
 * Each line goes to the host's POST /api/console, which answers it
 * (core/api/console.c): the console's rules live in one place. */
#include "console.h"

#include <getopt.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client.h"

/* Error codes the client gives itself (docs/CLI.md, "Console"): the host
 * answers every other one. */
enum {
	E_ACCESS = 7, /* the token is missing, invalid or lacks the scope */
	E_HOST = 8,   /* the host cannot be reached, is busy, or answered nonsense */
};

struct session {
	char http[128];
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

static int setup(struct session *s, int argc, char **argv, const char *usage, int *first_arg)
{
	static const struct option opts[] = {{"http", required_argument, 0, 'H'},
	                                     {"host", required_argument, 0, 'H'},
	                                     {"token", required_argument, 0, 't'},
	                                     {"token-file", required_argument, 0, 'f'},
	                                     {"quiet", no_argument, 0, 'q'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {0, 0, 0, 0}};
	const char *token = NULL, *file = NULL;
	int opt;
	memset(s, 0, sizeof(*s));
	snprintf(s->http, sizeof(s->http), "%s", getenv("VMAC_HTTP") ? getenv("VMAC_HTTP") : "127.0.0.1:8080");
	s->verbose = 1;
	optind = 1;
	while ((opt = getopt_long(argc, argv, "hq", opts, NULL)) != -1) {
		switch (opt) {
		case 'H': snprintf(s->http, sizeof(s->http), "%s", optarg); break;
		case 't': token = optarg; break;
		case 'f': file = optarg; break;
		case 'q': s->verbose = 0; break;
		case 'h': fputs(usage, stdout); return 1;
		default: return 2;
		}
	}
	*first_arg = optind;
	return vmac_client_token(token, file) != 0 ? 2 : 0;
}

#define COMMON_OPTIONS                                                                                                 \
	"  --http ADDR:PORT   the host (default $VMAC_HTTP or 127.0.0.1:8080)\n"                                       \
	"  --token T, --token-file F   the token (default $VMAC_TOKEN, $VMAC_TOKEN_FILE): read for ?, operate for\n"   \
	"                     : and !\n"                                                                               \
	"  --quiet            no messages on stderr, only the answers\n"                                               \
	"Answers DEVICE.NAME:VALUE, DEVICE.NAME! or DEVICE.NAME#CODE; codes in docs/CLI.md (\"Console\").\n"

int vmac_console_main(int argc, char **argv)
{
	static const char usage[] = "usage: vmac console [--http ADDR:PORT] [--token T | --token-file F] [--quiet]\n"
	                            "Read lines of DEVICE.NAME?  DEVICE.NAME:VALUE  DEVICE.NAME!  from standard input\n"
	                            "(typed, or from a pipe) and answer each on one line.\n" COMMON_OPTIONS
	                            "Exit 0 when every submessage was answered without #, else 1.\n";
	struct session s;
	char buf[4096];
	int first, rc = setup(&s, argc, argv, usage, &first);
	int interactive = isatty(STDIN_FILENO);
	if (rc)
		return rc == 1 ? 0 : rc;
	if (first < argc) {
		fprintf(stderr, "vmac console: unexpected argument '%s' (submessages come on standard input)\n",
		        argv[first]);
		return 2;
	}
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

/* vmac get / set: the arguments as one console line. */
static int one_line(int argc, char **argv, const char *usage, int get)
{
	struct session s;
	char buf[4096] = "";
	size_t n = 0;
	int first, i, rc = setup(&s, argc, argv, usage, &first);
	if (rc)
		return rc == 1 ? 0 : rc;
	if (first >= argc) {
		fputs(usage, stderr);
		return 2;
	}
	for (i = first; i < argc; i++) {
		int w = snprintf(buf + n, sizeof(buf) - n, "%s%s%s", n ? " " : "", argv[i],
		                 get && !strpbrk(argv[i], "?:>!") ? "?" : "");
		if (w < 0 || (size_t)w >= sizeof(buf) - n) {
			fprintf(stderr, "vmac: too many submessages for one line\n");
			return 2;
		}
		n += (size_t)w;
	}
	line(&s, buf);
	return s.errors ? 1 : 0;
}

int vmac_get_main(int argc, char **argv)
{
	static const char usage[] =
	    "usage: vmac get [options] DEVICE.NAME...\n"
	    "Print published variables, e.g. vmac get washer-1.state washer-1.drum_rpm\n" COMMON_OPTIONS;
	return one_line(argc, argv, usage, 1);
}

int vmac_set_main(int argc, char **argv)
{
	static const char usage[] =
	    "usage: vmac set [options] DEVICE.NAME:VALUE|DEVICE.NAME!...\n"
	    "Operator input, e.g. vmac set lights-1.kitchen:true, vmac set washer-1.start:quick,\n"
	    "vmac set washer-1.cancel!\n" COMMON_OPTIONS;
	return one_line(argc, argv, usage, 0);
}
