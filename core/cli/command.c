/* What vmac's commands on a running host's API share (docs/CLI.md): the
 * options --http, --token, --token-file, --json, --help and one call with
 * its answer for people. */
#include "command.h"

#include <curl/curl.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client.h"

/* The options every one of these commands takes; returns 1 when handled. */
int vmac_cmd_opt(int opt, struct vmac_cmd *o)
{
	switch (opt) {
	case 'H': o->http = optarg; return 1;
	case 't': o->token = optarg; return 1;
	case 'f': o->token_file = optarg; return 1;
	case 'j': o->json = 1; return 1;
	default: return 0;
	}
}

const char VMAC_CMD_HELP[] = "  --http ADDR:PORT   the host's HTTP address (default $VMAC_HTTP or 127.0.0.1:8080)\n"
                             "  --json             print the host's JSON answer as it is\n"
                             "  --token T          a token (default $VMAC_TOKEN)\n"
                             "  --token-file F     read the token from F's first line (default $VMAC_TOKEN_FILE)\n";

/* One call and its answer for people: 0 on HTTP 200, 1 otherwise. */
int vmac_cmd_run(const struct vmac_cmd *o, const char *method, const char *path, const char *body, size_t len,
                 void (*show)(json_t *answer))
{
	char url[512], err[600];
	struct vmac_buffer b = {NULL, 0};
	long code = 0;
	json_t *a;
	json_error_t jerr;
	int rc;
	vmac_client_url(url, sizeof(url), o->http, path);
	curl_global_init(CURL_GLOBAL_DEFAULT);
	rc = body ? vmac_client_upload(url, body, len, &b, &code, err, sizeof(err))
	          : vmac_client_call(method, url, NULL, &b, &code, err, sizeof(err));
	curl_global_cleanup();
	if (rc != 0) {
		fprintf(stderr, "vmac: %s\n", err);
		return 1;
	}
	if (o->json) {
		printf("%s\n", b.data ? b.data : "");
		free(b.data);
		return code == 200 ? 0 : 1;
	}
	a = json_loads(b.data ? b.data : "", 0, &jerr);
	free(b.data);
	if (code == 401 || code == 403) {
		fprintf(stderr, "vmac: HTTP %ld: %s\n%s\n", code, json_string_value(json_object_get(a, "error")),
		        vmac_client_auth_hint());
		json_decref(a);
		return 1;
	}
	if (!a) {
		fprintf(stderr, "vmac: HTTP %ld, and the answer is not JSON (%s)\n", code, jerr.text);
		return 1;
	}
	if (code != 200)
		fprintf(stderr, "vmac: HTTP %ld: %s\n", code, json_string_value(json_object_get(a, "error")));
	show(a);
	json_decref(a);
	return code == 200 ? 0 : 1;
}

void vmac_cmd_init(struct vmac_cmd *o)
{
	memset(o, 0, sizeof(*o));
	o->http = getenv("VMAC_HTTP") ? getenv("VMAC_HTTP") : "127.0.0.1:8080";
}

int vmac_cmd_only_common(int argc, char **argv, struct vmac_cmd *o, const char *help, int *exit_code)
{
	static const struct option opts[] = {VMAC_CMD_OPTS, {0, 0, 0, 0}};
	int opt;
	vmac_cmd_init(o);
	optind = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		if (vmac_cmd_opt(opt, o))
			continue;
		if (opt == 'h')
			printf("%s%s", help, VMAC_CMD_HELP);
		*exit_code = opt == 'h' ? 0 : 2;
		return 1;
	}
	return 0;
}
