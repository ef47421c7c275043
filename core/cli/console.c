/* The line console over the HTTP API: see console.h and docs/CLI.md.
 * `?` reads a published variable or a param from GET /api/status (one
 * fetch per line); `:`, `>` (with "persist": true) and `!` go to
 * POST /api/devices/DEVICE/input. */
#include "console.h"

#include <getopt.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client.h"

/* Error codes of a `#` answer (docs/CLI.md, "Console"). */
enum {
	E_SYNTAX = 1,     /* the submessage does not parse */
	E_DEVICE = 2,     /* no running device of that name */
	E_NAME = 3,       /* the device has no such variable, param or command */
	E_REFUSED = 4,    /* the driver refused the value */
	E_READ_ONLY = 5,  /* a published variable an operator may not set */
	E_PERSIST = 6,    /* `>` on a name that is not a persist = true param, or the store could not write */
	E_ACCESS = 7,     /* the token is missing, invalid or lacks the scope */
	E_HOST = 8,       /* the host cannot be reached, is busy, or answered nonsense */
};

struct session {
	char http[128];
	json_t *status; /* this line's status, fetched on the first `?` */
	int errors;
	int verbose;    /* say each error's message on stderr */
};

/* An error answer's message for people, on stderr. */
static void say(struct session *s, const char *what, const char *why)
{
	if (s->verbose && why && *why)
		fprintf(stderr, "vmac: %s: %s\n", what, why);
	s->errors++;
}

static const char *text(json_t *v)
{
	const char *t = json_string_value(v);
	return t ? t : "";
}

static int valid_name(const char *p, size_t n)
{
	size_t i;
	if (n == 0 || !((p[0] >= 'a' && p[0] <= 'z') || (p[0] >= 'A' && p[0] <= 'Z')))
		return 0;
	for (i = 0; i < n; i++)
		if (!((p[i] >= 'a' && p[i] <= 'z') || (p[i] >= 'A' && p[i] <= 'Z') || (p[i] >= '0' && p[i] <= '9') ||
		      p[i] == '_' || p[i] == '-'))
			return 0;
	return 1;
}

/* A value as JSON: true/false, a number, or a string (bare or "quoted"). */
static json_t *parse_value(const char *v)
{
	char *end;
	double d;
	size_t n = strlen(v);
	if (strcmp(v, "true") == 0)
		return json_true();
	if (strcmp(v, "false") == 0)
		return json_false();
	if (n >= 2 && v[0] == '"' && v[n - 1] == '"')
		return json_stringn(v + 1, n - 2);
	d = strtod(v, &end);
	if (n > 0 && *end == 0)
		return json_real(d);
	return json_string(v);
}

static void print_value(FILE *out, json_t *v)
{
	if (json_is_true(v))
		fputs("true", out);
	else if (json_is_false(v))
		fputs("false", out);
	else if (json_is_integer(v))
		fprintf(out, "%lld", (long long)json_integer_value(v));
	else if (json_is_real(v))
		fprintf(out, "%.6g", json_real_value(v));
	else if (json_is_string(v))
		fputs(json_string_value(v), out);
	else
		fputs("-", out);
}

static int request(struct session *s, const char *device, const char *name, const char *what)
{
	char url[256], err[512];
	struct vmac_buffer b = {NULL, 0};
	long code;
	json_t *d;
	size_t i;
	if (!s->status) {
		vmac_client_url(url, sizeof(url), s->http, "/api/status");
		if (vmac_client_call("GET", url, NULL, &b, &code, err, sizeof(err)) != 0) {
			say(s, what, err);
			return E_HOST;
		}
		if (code == 401 || code == 403) {
			say(s, what, vmac_client_auth_hint());
			free(b.data);
			return E_ACCESS;
		}
		s->status = code == 200 ? json_loads(b.data ? b.data : "", 0, NULL) : NULL;
		free(b.data);
		if (!s->status) {
			say(s, what, "the host's status is not readable");
			return E_HOST;
		}
	}
	json_array_foreach(json_object_get(s->status, "devices"), i, d)
	{
		json_t *v;
		if (strcmp(text(json_object_get(d, "name")), device) != 0)
			continue;
		if (strcmp(text(json_object_get(d, "state")), "running") != 0)
			break;
		v = json_object_get(json_object_get(d, "variables"), name);
		if (!v)
			v = json_object_get(json_object_get(d, "params"), name);
		if (!v) {
			say(s, what, "no such published variable or param");
			return E_NAME;
		}
		printf("%s:", what);
		print_value(stdout, v);
		return 0;
	}
	say(s, what, "no running device of that name");
	return E_DEVICE;
}

static int input(struct session *s, const char *device, const char *name, json_t *value, int persist,
                 const char *what)
{
	char url[256], path[160], err[512], *body;
	struct vmac_buffer b = {NULL, 0};
	long code;
	json_t *req = json_pack("{s:s}", "name", name), *ans;
	const char *msg;
	int rc;
	if (value)
		json_object_set(req, "value", value);
	if (persist)
		json_object_set_new(req, "persist", json_true());
	body = json_dumps(req, JSON_COMPACT);
	json_decref(req);
	snprintf(path, sizeof(path), "/api/devices/%s/input", device);
	vmac_client_url(url, sizeof(url), s->http, path);
	rc = vmac_client_call("POST", url, body ? body : "{}", &b, &code, err, sizeof(err));
	free(body);
	if (rc != 0) {
		say(s, what, err);
		return E_HOST;
	}
	ans = json_loads(b.data ? b.data : "", 0, NULL);
	free(b.data);
	msg = json_string_value(json_object_get(ans, "error"));
	switch (code) {
	case 200: rc = 0; break;
	case 401:
	case 403: rc = E_ACCESS; msg = msg ? msg : vmac_client_auth_hint(); break;
	case 404: rc = E_DEVICE; break;
	case 409:
		rc = msg && strstr(msg, "no such variable, param or command") ? E_NAME
		     : msg && strstr(msg, "is read-only")                     ? E_READ_ONLY
		     : msg && strstr(msg, "persist")                          ? E_PERSIST
		                                                              : E_REFUSED;
		break;
	case 500:
	case 507: rc = persist ? E_PERSIST : E_HOST; break;
	default: rc = E_HOST; break;
	}
	if (rc == 0) {
		fputs(what, stdout);
		if (value) {
			putchar(persist ? '>' : ':');
			print_value(stdout, value);
		} else {
			putchar('!');
		}
	} else {
		say(s, what, msg ? msg : "unexpected answer");
	}
	json_decref(ans);
	return rc;
}

/* One submessage: answers on stdout (no newline). */
static void submessage(struct session *s, const char *m)
{
	const char *dot = strchr(m, '.'), *op = dot ? strpbrk(dot + 1, "?:>!") : NULL;
	char device[64], name[64], what[160];
	int rc;
	size_t nd, nn;
	if (!dot || !op || (nd = (size_t)(dot - m)) >= sizeof(device) || (nn = (size_t)(op - dot - 1)) >= sizeof(name) ||
	    !valid_name(m, nd) || !valid_name(dot + 1, nn) || ((*op == '?' || *op == '!') && op[1] != 0) ||
	    ((*op == ':' || *op == '>') && op[1] == 0)) {
		printf("%.*s#%d", (int)strcspn(m, "?:>!"), m, E_SYNTAX);
		say(s, m, "expected DEVICE.NAME? DEVICE.NAME:VALUE DEVICE.NAME>VALUE or DEVICE.NAME!");
		return;
	}
	memcpy(device, m, nd);
	device[nd] = 0;
	memcpy(name, dot + 1, nn);
	name[nn] = 0;
	snprintf(what, sizeof(what), "%s.%s", device, name);
	if (*op == '?') {
		rc = request(s, device, name, what);
	} else {
		json_t *v = *op == ':' || *op == '>' ? parse_value(op + 1) : NULL;
		rc = input(s, device, name, v, *op == '>', what);
		json_decref(v);
	}
	if (rc)
		printf("%s#%d", what, rc);
}

/* One line of submessages, answered on one line. */
static void line(struct session *s, char *text)
{
	char *save = NULL, *m;
	int first = 1;
	for (m = strtok_r(text, " \t\r\n", &save); m; m = strtok_r(NULL, " \t\r\n", &save)) {
		if (!first)
			putchar(' ');
		first = 0;
		submessage(s, m);
	}
	if (!first)
		putchar('\n');
	fflush(stdout);
	json_decref(s->status);
	s->status = NULL;
}

static int setup(struct session *s, int argc, char **argv, const char *usage, int *first_arg)
{
	static const struct option opts[] = {{"http", required_argument, 0, 'H'},
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

#define COMMON_OPTIONS                                                                                              \
	"  --http ADDR:PORT   the host (default $VMAC_HTTP or 127.0.0.1:8080)\n"                                        \
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
	static const char usage[] = "usage: vmac get [options] DEVICE.NAME...\n"
	                            "Print published variables, e.g. vmac get washer-1.state washer-1.drum_rpm\n" COMMON_OPTIONS;
	return one_line(argc, argv, usage, 1);
}

int vmac_set_main(int argc, char **argv)
{
	static const char usage[] = "usage: vmac set [options] DEVICE.NAME:VALUE|DEVICE.NAME!...\n"
	                            "Operator input, e.g. vmac set lights-1.kitchen:true, vmac set washer-1.start:quick,\n"
	                            "vmac set washer-1.cancel!\n" COMMON_OPTIONS;
	return one_line(argc, argv, usage, 0);
}
