/* vmac recordings, vmac recording get ID, vmac recording to-test FILE: the
 * flight recordings of a running host (docs/CLI.md, docs/RECORDING.md). */
#include "recordings.h"

#include <curl/curl.h>
#include <getopt.h>
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

int vmac_recordings_main(int argc, char **argv)
{
	struct vmac_cmd o;
	char path[256];
	int rc;
	if (vmac_cmd_only_common(
	        argc, argv, &o,
	        "usage: vmac recordings [options] [MACHINE]\n"
	        "List the flight recordings a running vmacd keeps, newest first: id, when, machine,\n"
	        "driver and version, size, why (a drop, a driver failure). Needs a token of scope read.\n"
	        "Fetch one with vmac recording get ID > FILE; replay it with vmac test --replay FILE.\n",
	        &rc))
		return rc;
	if (optind < argc - 1 || (optind == argc - 1 && (strlen(argv[optind]) > 63 || strpbrk(argv[optind], "/&?#")))) {
		fprintf(stderr, "usage: vmac recordings [options] [MACHINE] (vmac recordings --help)\n");
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0)
		return 2;
	if (optind == argc - 1)
		snprintf(path, sizeof(path), "/api/recordings?machine=%s", argv[optind]);
	else
		snprintf(path, sizeof(path), "/api/recordings");
	return vmac_cmd_run(&o, "GET", path, NULL, 0, show_recordings);
}

static void show_record(json_t *a)
{
	printf("%s\n",
	       json_string_value(json_object_get(a, "text")) ? json_string_value(json_object_get(a, "text")) : "");
}

int vmac_record_main(int argc, char **argv)
{
	struct vmac_cmd o;
	char path[256];
	int rc;
	if (vmac_cmd_only_common(argc, argv, &o,
	                         "usage: vmac record [options] MACHINE\n"
	                         "Capture the flight recorder of a running machine now, without a drop: the last\n"
	                         "seconds become a recording (vmac recordings lists it) and recording goes on.\n"
	                         "Needs a token of scope operate.\n",
	                         &rc))
		return rc;
	if (optind != argc - 1 || strlen(argv[optind]) > 63 || strpbrk(argv[optind], "/&?#")) {
		fprintf(stderr, "usage: vmac record [options] MACHINE (vmac record --help)\n");
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0)
		return 2;
	snprintf(path, sizeof(path), "/api/devices/%s/record", argv[optind]);
	return vmac_cmd_run(&o, "POST", path, NULL, 0, show_record) == 0 ? 0 : 1;
}

/* vmac recording get ID: the file on standard output. */
static int get(int argc, char **argv)
{
	struct vmac_cmd o;
	struct vmac_buffer b = {NULL, 0};
	char path[64], url[512], err[600];
	long code = 0;
	int rc;
	if (vmac_cmd_only_common(argc, argv, &o,
	                         "usage: vmac recording get [options] ID > FILE\n"
	                         "Write recording ID (vmac recordings lists them) to standard output: the file\n"
	                         "vmac test --replay FILE replays (docs/RECORDING.md). Needs a token of scope read.\n",
	                         &rc))
		return rc;
	if (optind != argc - 1 || strspn(argv[optind], "0123456789") != strlen(argv[optind]) || !argv[optind][0] ||
	    strlen(argv[optind]) > 18) {
		fprintf(stderr, "usage: vmac recording get [options] ID (a number; vmac recordings lists them)\n");
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0)
		return 2;
	snprintf(path, sizeof(path), "/api/recordings/%s", argv[optind]);
	vmac_client_url(url, sizeof(url), o.http, path);
	curl_global_init(CURL_GLOBAL_DEFAULT);
	rc = vmac_client_call("GET", url, NULL, &b, &code, err, sizeof(err));
	curl_global_cleanup();
	if (rc != 0) {
		fprintf(stderr, "vmac: %s\n", err);
		return 1;
	}
	if (code != 200) {
		json_t *a = json_loads(b.data ? b.data : "", 0, NULL);
		fprintf(stderr, "vmac: HTTP %ld: %s\n%s", code,
		        a && json_is_string(json_object_get(a, "error"))
		            ? json_string_value(json_object_get(a, "error"))
		            : "(no message)",
		        code == 401 || code == 403 ? vmac_client_auth_hint() : "");
		if (code == 401 || code == 403)
			fputc('\n', stderr);
		json_decref(a);
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

static int to_test(int argc, char **argv)
{
	struct vmac_recording rec;
	char err[600], *text;
	const char *file;
	size_t len, i;
	int code = 0;
	if (argc == 2 && (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0)) {
		printf("usage: vmac recording to-test FILE > NAME_test.lua\n"
		       "Write a vmac test file that replays recording FILE against the driver under test and\n"
		       "fails where an output differs or the driver fails: keep it in tests/drivers/ (the\n"
		       "recording is inside it). docs/RECORDING.md, \"A recording as a test\".\n");
		return 0;
	}
	if (argc != 2) {
		fprintf(stderr, "usage: vmac recording to-test FILE (vmac recording to-test --help)\n");
		return 2;
	}
	file = argv[1];
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

int vmac_recording_main(int argc, char **argv)
{
	if (argc >= 2 && strcmp(argv[1], "get") == 0)
		return get(argc - 1, argv + 1);
	if (argc >= 2 && strcmp(argv[1], "to-test") == 0)
		return to_test(argc - 1, argv + 1);
	if (argc >= 2 && (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0)) {
		printf("usage: vmac recording get ID > FILE      fetch a flight recording of a running vmacd\n"
		       "       vmac recording to-test FILE       write a test that replays it\n"
		       "Replay one with vmac test --replay FILE [--drivers DIR]. docs/RECORDING.md.\n");
		return 0;
	}
	fprintf(stderr, "usage: vmac recording get ID | vmac recording to-test FILE (vmac recording --help)\n");
	return 2;
}
