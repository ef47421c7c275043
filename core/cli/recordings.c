/* vmac recordings, vmac recording get ID, vmac recording to-test FILE: the
 * flight recordings of a running host (docs/CLI.md, docs/RECORDING.md). */
#include "recordings.h"

#include <curl/curl.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/file.h"
#include "../recorder/recording.h"
#include "client.h"
#include "command.h"

#define RECORDING_FILE_MAX ((size_t)64 << 20) /* a washer's 60 s is about 170 KiB (docs/RECORDING.md) */

static void show_recordings(json_t *a)
{
	json_t *r;
	size_t i;
	if (json_array_size(json_object_get(a, "recordings")) == 0)
		printf("no recordings (a drop or a driver failure makes one)\n");
	json_array_foreach(json_object_get(a, "recordings"), i, r)
	{
		time_t t = (time_t)json_number_value(json_object_get(r, "time"));
		char when[32];
		strftime(when, sizeof(when), "%Y-%m-%d %H:%M:%S", localtime(&t));
		printf("%5lld  %s  %-16s %s %s  %7lld bytes  %s\n",
		       (long long)json_integer_value(json_object_get(r, "id")), when,
		       json_string_value(json_object_get(r, "machine")),
		       json_string_value(json_object_get(r, "driver")),
		       json_string_value(json_object_get(r, "version")),
		       (long long)json_integer_value(json_object_get(r, "size")),
		       json_string_value(json_object_get(r, "reason")));
	}
}

/* A machine's name as an argument: it goes into a path or a query. */
static int machine_name_ok(const char *name)
{
	return strlen(name) <= 63 && !strpbrk(name, "/&?#");
}

#define EXIT_CODES "Exit 0 done, 1 the host refused or could not be reached, 2 wrong usage.\n"

static int recordings_run(const struct vmac_cmd_args *a)
{
	char path[256];
	if (a->nargs == 1 && !machine_name_ok(a->arg[0]))
		return vmac_cmd_usage_error(a, "'%s' is not a machine's name", a->arg[0]);
	if (a->nargs == 1)
		snprintf(path, sizeof(path), "/api/recordings?machine=%s", a->arg[0]);
	else
		snprintf(path, sizeof(path), "/api/recordings");
	return vmac_client_run(a, "GET", path, NULL, 0, show_recordings);
}

const struct vmac_cmd vmac_recordings_cmd = {
    .name = "recordings",
    .args = "[MACHINE]",
    .max_args = 1,
    .summary = "list the flight recordings the host keeps (drops, driver failures)",
    .about = "List the flight recordings a running vmacd keeps, newest first: id, when, machine,\n"
             "driver and version, size, why (a drop, a driver failure). Needs a token of scope read.\n"
             "Fetch one with vmac recording get ID > FILE; replay it with vmac test --replay FILE.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .run = recordings_run};

static void show_record(json_t *a)
{
	printf("%s\n",
	       json_string_value(json_object_get(a, "text")) ? json_string_value(json_object_get(a, "text")) : "");
}

static int record_run(const struct vmac_cmd_args *a)
{
	char path[256];
	if (!machine_name_ok(a->arg[0]))
		return vmac_cmd_usage_error(a, "'%s' is not a machine's name", a->arg[0]);
	snprintf(path, sizeof(path), "/api/devices/%s/record", a->arg[0]);
	return vmac_client_run(a, "POST", path, NULL, 0, show_record) == 0 ? 0 : 1;
}

const struct vmac_cmd vmac_record_cmd = {
    .name = "record",
    .args = "MACHINE",
    .min_args = 1,
    .max_args = 1,
    .summary = "capture a running machine's flight recorder now",
    .about = "Capture the flight recorder of a running machine now, without a drop: the last\n"
             "seconds become a recording (vmac recordings lists it) and recording goes on.\n"
             "Needs a token of scope operate.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .run = record_run};

/* vmac recording get ID: the file on standard output. */
static int get_run(const struct vmac_cmd_args *a)
{
	struct vmac_buffer b = {NULL, 0};
	char path[64], url[512], err[600];
	long code = 0;
	int rc;
	if (strspn(a->arg[0], "0123456789") != strlen(a->arg[0]) || !a->arg[0][0] || strlen(a->arg[0]) > 18)
		return vmac_cmd_usage_error(a, "ID is a number (vmac recordings lists them), not '%s'", a->arg[0]);
	snprintf(path, sizeof(path), "/api/recordings/%s", a->arg[0]);
	vmac_client_url(url, sizeof(url), a->opt[VMAC_CMD_HTTP], path);
	curl_global_init(CURL_GLOBAL_DEFAULT);
	rc = vmac_client_call("GET", url, NULL, &b, &code, err, sizeof(err));
	curl_global_cleanup();
	if (rc != 0) {
		fprintf(stderr, "vmac: %s\n", err);
		return 1;
	}
	if (code != 200) {
		json_t *answer = json_loads(b.data ? b.data : "", 0, NULL);
		fprintf(stderr, "vmac: HTTP %ld: %s\n%s", code,
		        answer && json_is_string(json_object_get(answer, "error"))
		            ? json_string_value(json_object_get(answer, "error"))
		            : "(no message)",
		        code == 401 || code == 403 ? vmac_client_auth_hint() : "");
		if (code == 401 || code == 403)
			fputc('\n', stderr);
		json_decref(answer);
		free(b.data);
		return 1;
	}
	rc = fwrite(b.data, 1, b.len, stdout) == b.len && fflush(stdout) == 0 ? 0 : 1;
	if (rc)
		fprintf(stderr, "vmac: writing the recording failed\n");
	free(b.data);
	return rc;
}

/* vmac recording to-test FILE: a test file that replays it. */
/* Text into a Lua comment: on the comment's one line (control bytes,
 * newlines above all, become spaces), whatever the recording says. */
static void comment_text(const char *s)
{
	for (; *s; s++)
		putchar((unsigned char)*s < 0x20 || *s == 0x7f ? ' ' : *s);
}

static int to_test_run(const struct vmac_cmd_args *a)
{
	struct vmac_recording rec;
	char err[600], *text;
	const char *file = a->arg[0];
	size_t len, i;
	int code = 0;
	text = vmac_read_file(file, RECORDING_FILE_MAX, &len, err, sizeof(err), &code);
	if (!text) {
		fprintf(stderr, "vmac: %s\n", err);
		return 2;
	}
	if (vmac_recording_read(text, len, &rec, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac: %s: %s\n", file, err);
		free(text);
		return 2;
	}
	/* A long bracket no line of the recording can close (it is JSON:
	 * "]" followed by "=" signs only inside strings, so use enough). What
	 * goes into the comments is kept to one line each; the machine and the
	 * driver are names (vmac_recording_read refuses others), safe in the
	 * test's name. */
	printf("-- Made by vmac recording to-test from ");
	comment_text(file);
	printf(": machine %s, driver %s ", rec.machine, rec.driver);
	comment_text(rec.version);
	printf(",\n-- recorded because: ");
	comment_text(rec.reason);
	printf("\n-- It replays the recording against the driver under test (docs/RECORDING.md).\n\n"
	       "test(\"%s replays as recorded (%s)\", function()\n\treplay [=======[\n",
	       rec.machine, rec.driver);
	for (i = 0; i < len; i++)
		if (text[i] == ']' && strncmp(text + i, "]=======]", 9) == 0) {
			fprintf(stderr, "vmac: %s: holds the text that would end the test's string\n", file);
			vmac_recording_free(&rec);
			free(text);
			return 1;
		}
	fwrite(text, 1, len, stdout);
	printf("]=======]\nend)\n");
	vmac_recording_free(&rec);
	free(text);
	return 0;
}

static const struct vmac_cmd get_cmd = {
    .name = "get",
    .args = "ID",
    .min_args = 1,
    .max_args = 1,
    .summary = "write recording ID to standard output (> FILE)",
    .about = "Write recording ID (vmac recordings lists them) to standard output: the file\n"
             "vmac test --replay FILE replays (docs/RECORDING.md). Needs a token of scope read.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .run = get_run};

static const struct vmac_cmd to_test_cmd = {
    .name = "to-test",
    .args = "FILE",
    .min_args = 1,
    .max_args = 1,
    .summary = "write a test that replays recording FILE (> NAME_test.lua)",
    .about = "Write a vmac test file that replays recording FILE against the driver under test and\n"
             "fails where an output differs or the driver fails: keep it in tests/drivers/ (the\n"
             "recording is inside it). docs/RECORDING.md, \"A recording as a test\". No host needed.\n"
             "Exit 0 done, 1 the recording cannot be made a test, 2 wrong usage or FILE not a recording.\n",
    .run = to_test_run};

static const struct vmac_cmd *const actions[] = {&get_cmd, &to_test_cmd, NULL};

const struct vmac_cmd vmac_recording_cmd = {
    .name = "recording",
    .args = "ACTION",
    .summary = "fetch a flight recording (get ID > FILE), make one a test (to-test FILE)",
    .about = "One flight recording of a running vmacd (docs/RECORDING.md). Replay one with\n"
             "vmac test --replay FILE [--drivers DIR].\n",
    .sub = actions};
