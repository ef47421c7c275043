/* vmac events: reads the Server-Sent Events of GET /api/events and prints
 * one line per event, as they happen (docs/CLI.md, "vmac events"). */
#include "events.h"

#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "client.h"
#include "command.h"

struct follow {
	int json;
	const char *kind; /* only events of this kind; NULL: all */
	long count;       /* stop after this many events; 0: never */
	long seen;
	char line[4096];
	size_t len;
	char data[4096];
};

/* One event, unless --kind leaves it out (then it is not counted). */
static void print_event(struct follow *f)
{
	json_t *e = json_loads(f->data, 0, NULL);
	const char *kind = json_string_value(json_object_get(e, "kind")),
	           *text = json_string_value(json_object_get(e, "text"));
	time_t t = (time_t)json_real_value(json_object_get(e, "time"));
	char when[16];
	if (!e || (f->kind && (!kind || strcmp(kind, f->kind) != 0))) {
		json_decref(e);
		return;
	}
	if (f->json) {
		printf("%s\n", f->data);
	} else {
		strftime(when, sizeof(when), "%H:%M:%S", localtime(&t));
		printf("%lld %s %-14s %s\n", (long long)json_integer_value(json_object_get(e, "seq")), when,
		       kind ? kind : "?", text ? text : "");
	}
	json_decref(e);
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

enum { EVENTS_AFTER = VMAC_CMD_OWN, EVENTS_COUNT, EVENTS_KIND };

static const struct vmac_cmd_option events_options[] = {
    [EVENTS_AFTER - VMAC_CMD_OWN] = {"after", NULL, 0, "SEQ", NULL, NULL,
                                     "only the events after SEQ (default 0: all it keeps)"},
    [EVENTS_COUNT - VMAC_CMD_OWN] = {"count", NULL, 0, "N", NULL, NULL, "stop after N events (default: never)"},
    [EVENTS_KIND - VMAC_CMD_OWN] = {"kind", NULL, 0, "KIND", NULL, NULL,
                                    "only events of this kind, e.g. audit: who changed what (default: all)"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int events_run(const struct vmac_cmd_args *a)
{
	struct follow *f;
	unsigned long long after = 0;
	long count = 0;
	char url[256], path[64], err[512], *end;
	long code;
	int rc;
	if (a->opt[EVENTS_AFTER]) {
		after = strtoull(a->opt[EVENTS_AFTER], &end, 10);
		if (*end || end == a->opt[EVENTS_AFTER]) {
			fprintf(stderr, "vmac events: --after takes an event's seq, not '%s'\n", a->opt[EVENTS_AFTER]);
			return 2;
		}
	}
	if (a->opt[EVENTS_COUNT]) {
		count = strtol(a->opt[EVENTS_COUNT], &end, 10);
		if (*end || end == a->opt[EVENTS_COUNT] || count < 1) {
			fprintf(stderr, "vmac events: --count takes a number >= 1, not '%s'\n", a->opt[EVENTS_COUNT]);
			return 2;
		}
	}
	if (!(f = calloc(1, sizeof(*f))))
		return 2;
	f->json = a->opt[VMAC_CMD_JSON] != NULL;
	f->kind = a->opt[EVENTS_KIND];
	f->count = count;
	snprintf(path, sizeof(path), "/api/events?after=%llu", after);
	vmac_client_url(url, sizeof(url), a->opt[VMAC_CMD_HTTP], path);
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

const struct vmac_cmd vmac_events_cmd = {
    .name = "events",
    .summary = "follow the host's events as they happen",
    .about = "Follow the host's events (attached, dropped, driver errors, ...) as they happen: the ones it\n"
             "still keeps after SEQ, then every new one, one line each: seq, local time, kind, text (with\n"
             "--json: each event's JSON). --kind audit shows the audit trail: every request that changed\n"
             "something, or was refused, with its token, name, scope and address. Needs a token of scope\n"
             "read.\n"
             "Exit 0 when --count is reached or the host ends the stream, 1 when it cannot be followed,\n"
             "2 wrong usage.\n",
    .common = VMAC_CMD_API,
    .own = events_options,
    .run = events_run};
