/* vmac events and vmac logs: read the Server-Sent Events of GET
 * /api/events and print one line per event, as they happen (docs/CLI.md,
 * "vmac events", "vmac logs"). vmac logs is a view of the same stream:
 * the events of drivers' output, by machine and level. */
#include "events.h"

#include <errno.h>
#include <jansson.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "client.h"
#include "command.h"

/* What vmac logs shows: a driver's output by the kind of its event, with
 * the level it is read as (docs/CLI.md, "vmac logs"). */
enum log_level { LOG_INFO, LOG_WARN, LOG_ERROR };
static const struct {
	const char *kind;
	enum log_level level;
} log_kinds[] = {
    {"driver", LOG_INFO},        /* dev:event(text) */
    {"warning", LOG_WARN},       /* the host's word on a machine: a cut text value, ... */
    {"driver_error", LOG_ERROR}, /* the driver failed: file, line, traceback */
};
static const char *const log_level_names[] = {"info", "warn", "error"};

struct follow {
	int json;
	const char *kind; /* only events of this kind; NULL: all */
	long count;       /* stop after this many events; 0: never */
	long seen;
	int logs;                      /* vmac logs: only log_kinds, as log lines */
	const char *device;            /* logs: only this machine's; NULL: every machine's */
	enum log_level at_least;       /* logs: only this level and above */
	unsigned long long stop_after; /* stop once an event of this seq or later came; 0: never */
	int done;
	char line[4096];
	size_t len;
	char data[4096];
};

/* The level vmac logs reads an event as, or -1: not a driver's output. */
static int log_level_of(const char *kind, const char *device)
{
	size_t i;
	if (!kind || !device || !device[0])
		return -1;
	for (i = 0; i < sizeof(log_kinds) / sizeof(log_kinds[0]); i++)
		if (strcmp(kind, log_kinds[i].kind) == 0)
			return (int)log_kinds[i].level;
	return -1;
}

/* One event, unless --kind, or vmac logs' machine and level, leave it out
 * (then it is not counted). */
static void print_event(struct follow *f)
{
	json_t *e = json_loads(f->data, 0, NULL);
	const char *kind = json_string_value(json_object_get(e, "kind")),
	           *text = json_string_value(json_object_get(e, "text")),
	           *device = json_string_value(json_object_get(e, "device"));
	time_t t = (time_t)json_real_value(json_object_get(e, "time"));
	unsigned long long seq = (unsigned long long)json_integer_value(json_object_get(e, "seq"));
	int level = log_level_of(kind, device);
	char when[16];
	if (f->stop_after && seq >= f->stop_after)
		f->done = 1;
	if (!e || (f->kind && (!kind || strcmp(kind, f->kind) != 0)) ||
	    (f->logs && (level < (int)f->at_least || (f->device && strcmp(device, f->device) != 0)))) {
		json_decref(e);
		return;
	}
	strftime(when, sizeof(when), "%H:%M:%S", localtime(&t));
	if (f->json)
		printf("%s\n", f->data);
	else if (f->logs)
		printf("%s %-5s %s: %s\n", when, log_level_names[level], device, text ? text : "");
	else
		printf("%llu %s %-14s %s\n", seq, when, kind ? kind : "?", text ? text : "");
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
			if ((f->count && f->seen >= f->count) || f->done)
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

/* Follow GET /api/events after seq `after` into f until f says stop or
 * the host ends it: 0, or 1 after saying why (who: "vmac events"). */
static int stream(const struct vmac_cmd_args *a, const char *who, struct follow *f, unsigned long long after)
{
	char url[256], path[64], err[512];
	long code;
	snprintf(path, sizeof(path), "/api/events?after=%llu", after);
	vmac_client_url(url, sizeof(url), a->opt[VMAC_CMD_HTTP], path);
	if (vmac_client_stream(url, on_data, f, &code, err, sizeof(err)) != 0) {
		fprintf(stderr, "%s: %s\n", who, err);
		return 1;
	}
	if (code != 200) {
		fprintf(stderr, "%s: the host answered HTTP %ld%s%s\n", who, code,
		        code == 401 || code == 403 ? "\n" : "",
		        code == 401 || code == 403 ? vmac_client_auth_hint() : "");
		return 1;
	}
	if (!f->done && (!f->count || f->seen < f->count))
		fprintf(stderr, "%s: the host ended the stream\n", who);
	return 0;
}

static int events_run(const struct vmac_cmd_args *a)
{
	struct follow *f;
	unsigned long long after = 0;
	long count = 0;
	char *end;
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
	rc = stream(a, "vmac events", f, after);
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

/* ---- vmac logs ---- */

enum { LOGS_FOLLOW = VMAC_CMD_OWN, LOGS_LEVEL, LOGS_BOARD_LOG };

static const struct vmac_cmd_option logs_options[] = {
    [LOGS_FOLLOW - VMAC_CMD_OWN] = {"follow", NULL, 'f', NULL, NULL, NULL,
                                    "keep following: print each new line as it comes (default: stop)"},
    [LOGS_LEVEL - VMAC_CMD_OWN] = {"level", NULL, 0, "LEVEL", NULL, NULL,
                                   "only lines of this level and above: info, warn, error (default: info)"},
    [LOGS_BOARD_LOG - VMAC_CMD_OWN] = {"board-log", NULL, 0, "FILE", NULL, NULL,
                                       "also the simulated boards' lines (their plants' unsafe episodes and "
                                       "failures, watchdog trips) from vmac-board's output kept in FILE (make "
                                       "run: STATE/boards.log)"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

/* The seq of the newest event the host has (0: none), from its status. 0,
 * or 1 after saying why. */
static int newest_seq(const struct vmac_cmd_args *a, unsigned long long *seq)
{
	struct vmac_buffer b = {NULL, 0};
	char url[256], err[512];
	long code;
	json_t *s, *e;
	size_t i;
	*seq = 0;
	vmac_client_url(url, sizeof(url), a->opt[VMAC_CMD_HTTP], "/api/status");
	if (vmac_client_call("GET", url, NULL, &b, &code, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac logs: %s\n", err);
		return 1;
	}
	if (code != 200 || !(s = json_loads(b.data, 0, NULL))) {
		fprintf(stderr, "vmac logs: the host answered HTTP %ld to its status%s%s\n", code,
		        code == 401 || code == 403 ? "\n" : "",
		        code == 401 || code == 403 ? vmac_client_auth_hint() : "");
		free(b.data);
		return 1;
	}
	json_array_foreach(json_object_get(s, "events"), i, e)
	{
		unsigned long long n = (unsigned long long)json_integer_value(json_object_get(e, "seq"));
		if (n > *seq)
			*seq = n;
	}
	json_decref(s);
	free(b.data);
	return 0;
}

/* ---- a simulator's lines (vmac logs --board-log) ---- */

struct board_log {
	FILE *file;
	const char *device; /* only this board's; NULL: every board's */
	enum log_level at_least;
	int json;
	int stop; /* set by the main thread: the stream ended */
};

/* The board a vmac-board line is about ("NAME: ...", "PLANT UNSAFE: NAME
 * ..."), into name; 0, or -1 for a line of the process itself. */
static int board_of(const char *text, char *name, size_t len)
{
	const char *u = strstr(text, " UNSAFE: "), *start = u ? u + 9 : text, *end = start;
	while (*end && *end != ':' && *end != ' ')
		end++;
	if (end == start || (!u && *end != ':') || (size_t)(end - start) >= len ||
	    strncmp(start, "vmac-board", 10) == 0)
		return -1;
	memcpy(name, start, (size_t)(end - start));
	name[end - start] = 0;
	return 0;
}

/* The level of a vmac-board line: a plant's unsafe episode or failure is
 * an error, a watchdog trip, a refusal or a late reply a warning. */
static enum log_level board_level(const char *text)
{
	if (strstr(text, " UNSAFE: ") || strstr(text, ": plant failed: "))
		return LOG_ERROR;
	if (strstr(text, ": watchdog: ") || strstr(text, ": refused ") || strstr(text, ": late reply ") ||
	    strstr(text, ": clock lost"))
		return LOG_WARN;
	return LOG_INFO;
}

/* One line of the board log ("HH:MM:SS TEXT" as make run keeps it, or
 * vmac-board's TEXT alone), printed as vmac logs prints a host's line. */
static void board_line(const struct board_log *b, char *line)
{
	char name[64], when[9] = "--:--:--";
	const char *text = line;
	enum log_level level;
	json_t *j;
	char *s;
	line[strcspn(line, "\r\n")] = 0;
	if (strlen(line) > 9 && line[2] == ':' && line[5] == ':' && line[8] == ' ') {
		memcpy(when, line, 8);
		text = line + 9;
	}
	if (board_of(text, name, sizeof(name)) != 0 || (b->device && strcmp(name, b->device) != 0))
		return;
	if ((level = board_level(text)) < b->at_least)
		return;
	if (!b->json) {
		printf("%s %-5s %s\n", when, log_level_names[level], text);
	} else if ((j = json_pack("{s:s, s:s, s:s, s:s}", "kind", "board", "level", log_level_names[level], "device",
	                          name, "text", text)) != NULL) {
		if ((s = json_dumps(j, JSON_COMPACT)) != NULL)
			printf("%s\n", s);
		free(s);
		json_decref(j);
	}
	fflush(stdout);
}

/* Every line of the board log now; then, following, each new one as it
 * is written, until the stream ends (a thread beside the stream's). */
static void *board_log_run(void *arg)
{
	struct board_log *b = arg;
	char line[1024];
	for (;;) {
		while (fgets(line, sizeof(line), b->file))
			board_line(b, line);
		if (__atomic_load_n(&b->stop, __ATOMIC_ACQUIRE))
			return NULL;
		clearerr(b->file);
		nanosleep(&(struct timespec){0, 200000000}, NULL); /* as tail -f looks for more */
	}
}

/* The host's lines as board's filter says (its machine, level, --json),
 * up to the event of seq stop_after (0: until the host ends the stream). */
static int host_lines(const struct vmac_cmd_args *a, const struct board_log *board, unsigned long long stop_after)
{
	struct follow *f = calloc(1, sizeof(*f));
	int rc;
	if (!f)
		return 2;
	f->json = board->json;
	f->logs = 1;
	f->device = board->device;
	f->at_least = board->at_least;
	f->stop_after = stop_after;
	rc = stream(a, "vmac logs", f, 0);
	free(f);
	return rc;
}

static int logs_run(const struct vmac_cmd_args *a)
{
	struct board_log board = {0};
	pthread_t tail;
	int tailing = 0;
	const char *level = a->opt[LOGS_LEVEL] ? a->opt[LOGS_LEVEL] : "info";
	unsigned long long newest = 0;
	int rc, i, at = -1;
	for (i = 0; i < (int)(sizeof(log_level_names) / sizeof(log_level_names[0])); i++)
		if (strcmp(level, log_level_names[i]) == 0)
			at = i;
	if (at < 0) {
		fprintf(stderr, "vmac logs: --level is info, warn or error, not '%s'\n", level);
		return 2;
	}
	if (a->opt[LOGS_BOARD_LOG] && !(board.file = fopen(a->opt[LOGS_BOARD_LOG], "r"))) {
		fprintf(stderr, "vmac logs: --board-log %s: %s\n", a->opt[LOGS_BOARD_LOG], strerror(errno));
		return 2;
	}
	board.device = a->nargs > 0 ? a->arg[0] : NULL;
	board.at_least = (enum log_level)at;
	board.json = a->opt[VMAC_CMD_JSON] != NULL;
	rc = 0;
	if (!a->opt[LOGS_FOLLOW] && (rc = newest_seq(a, &newest)) == 0 && newest > 0) {
		rc = host_lines(a, &board, newest);
	} else if (a->opt[LOGS_FOLLOW]) {
		/* the boards' lines beside the host's, each as it comes */
		tailing = board.file && pthread_create(&tail, NULL, board_log_run, &board) == 0;
		rc = host_lines(a, &board, 0);
		__atomic_store_n(&board.stop, 1, __ATOMIC_RELEASE);
		if (tailing)
			pthread_join(tail, NULL);
	}
	if (board.file && !a->opt[LOGS_FOLLOW] && rc == 0) {
		board.stop = 1;
		board_log_run(&board); /* the boards' lines after the host's */
	}
	if (board.file)
		fclose(board.file);
	return rc;
}

const struct vmac_cmd vmac_logs_cmd = {
    .name = "logs",
    .args = "[MACHINE]",
    .max_args = 1,
    .summary = "show drivers' output (dev:event, warnings, failures), of one machine or all",
    .about = "Show what drivers said, from the host's event stream: dev:event(text) as info, the host's\n"
             "warnings about a machine (a cut text value, ...) as warn, and a driver's failure with its\n"
             "traceback as error; one line each: local time, level, machine, text (with --json: each\n"
             "event's JSON). Without -f, the lines among the events the host still keeps (the last 100 of\n"
             "all kinds), then stop; with -f, those and then each new one as it comes. --board-log FILE\n"
             "adds the simulated boards' lines (vmac-board's output, as make run keeps it in\n"
             "STATE/boards.log): a plant's unsafe episode or failure as error, a watchdog trip or a\n"
             "refused action as warn, the rest as info. Needs a token of scope read.\n"
             "Exit 0 when done or the host ends the stream, 1 when it cannot be followed, 2 wrong usage.\n",
    .common = VMAC_CMD_API,
    .own = logs_options,
    .run = logs_run};
