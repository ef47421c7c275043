/* vmac events: reads the Server-Sent Events of GET /api/events and prints
 * one line per event, as they happen (docs/CLI.md, "vmac events"). */
#include "events.h"

#include <getopt.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "client.h"

struct follow {
	int json;
	long count; /* stop after this many events; 0: never */
	long seen;
	char line[4096];
	size_t len;
	char data[4096];
};

static void print_event(struct follow *f)
{
	json_t *e;
	if (f->json) {
		printf("%s\n", f->data);
	} else if ((e = json_loads(f->data, 0, NULL)) != NULL) {
		time_t t = (time_t)json_real_value(json_object_get(e, "time"));
		char when[16];
		const char *kind = json_string_value(json_object_get(e, "kind")),
		           *text = json_string_value(json_object_get(e, "text"));
		strftime(when, sizeof(when), "%H:%M:%S", localtime(&t));
		printf("%lld %s %-14s %s\n", (long long)json_integer_value(json_object_get(e, "seq")), when,
		       kind ? kind : "?", text ? text : "");
		json_decref(e);
	}
	fflush(stdout);
	f->seen++;
}

/* One line of the stream (without its newline). */
static int stream_line(struct follow *f)
{
	if (f->len == 0) { /* the blank line ends an event */
		if (f->data[0]) {
			print_event(f);
			f->data[0] = 0;
			if (f->count && f->seen >= f->count)
				return 1;
		}
	} else if (strncmp(f->line, "data: ", 6) == 0) {
		snprintf(f->data, sizeof(f->data), "%s", f->line + 6);
	}
	return 0;
}

static int on_data(void *ctx, const char *data, size_t len)
{
	struct follow *f = ctx;
	size_t i;
	for (i = 0; i < len; i++) {
		if (data[i] == '\n') {
			f->line[f->len] = 0;
			if (stream_line(f))
				return 1;
			f->len = 0;
		} else if (f->len + 1 < sizeof(f->line)) {
			f->line[f->len++] = data[i];
		}
	}
	return 0;
}

int vmac_events_main(int argc, char **argv)
{
	static const struct option opts[] = {{"http", required_argument, 0, 'H'},
	                                     {"host", required_argument, 0, 'H'},
	                                     {"token", required_argument, 0, 't'},
	                                     {"token-file", required_argument, 0, 'f'},
	                                     {"after", required_argument, 0, 'a'},
	                                     {"count", required_argument, 0, 'n'},
	                                     {"json", no_argument, 0, 'j'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {0, 0, 0, 0}};
	const char *http = getenv("VMAC_HTTP") ? getenv("VMAC_HTTP") : "127.0.0.1:8080", *token = NULL, *file = NULL;
	struct follow *f = calloc(1, sizeof(*f));
	unsigned long long after = 0;
	char url[256], path[64], err[512], *end;
	long code;
	int opt, rc;
	if (!f)
		return 2;
	optind = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		switch (opt) {
		case 'H': http = optarg; break;
		case 't': token = optarg; break;
		case 'f': file = optarg; break;
		case 'j': f->json = 1; break;
		case 'a':
			after = strtoull(optarg, &end, 10);
			if (*end || end == optarg) {
				fprintf(stderr, "vmac events: --after takes an event's seq, not '%s'\n", optarg);
				free(f);
				return 2;
			}
			break;
		case 'n':
			f->count = strtol(optarg, &end, 10);
			if (*end || end == optarg || f->count < 1) {
				fprintf(stderr, "vmac events: --count takes a number >= 1, not '%s'\n", optarg);
				free(f);
				return 2;
			}
			break;
		case 'h':
			printf("usage: vmac events [--http ADDR:PORT] [--token T | --token-file F] [--after SEQ] "
			       "[--count N]"
			       " [--json]\n"
			       "Follow the host's events (attached, dropped, driver errors, ...) as they happen: the "
			       "ones it\n"
			       "still keeps after SEQ (default 0: all of them), then every new one, one line each.\n"
			       "  --count N   stop after N events     --json   print each event's JSON\n"
			       "Exit 0 when --count is reached or the host ends the stream, 1 when it cannot be "
			       "followed.\n");
			free(f);
			return 0;
		default: free(f); return 2;
		}
	}
	if (optind < argc) {
		fprintf(stderr, "vmac events: unexpected argument '%s'\n", argv[optind]);
		free(f);
		return 2;
	}
	if (vmac_client_token(token, file) != 0) {
		free(f);
		return 2;
	}
	snprintf(path, sizeof(path), "/api/events?after=%llu", after);
	vmac_client_url(url, sizeof(url), http, path);
	rc = vmac_client_stream(url, on_data, f, &code, err, sizeof(err));
	if (rc != 0) {
		fprintf(stderr, "vmac events: %s\n", err);
		rc = 1;
	} else if (code != 200) {
		fprintf(stderr, "vmac events: the host answered HTTP %ld%s%s\n", code,
		        code == 401 || code == 403 ? "\n" : "",
		        code == 401 || code == 403 ? vmac_client_auth_hint() : "");
		rc = 1;
	} else if (!f->count || f->seen < f->count) {
		fprintf(stderr, "vmac events: the host ended the stream\n");
	}
	free(f);
	return rc;
}
