/* vmac reload, rollback and drivers: hot reload of a running host's drivers
 * over its HTTP API (docs/CLI.md, docs/API.md "Drivers"). */
#include "reload.h"

#include <curl/curl.h>
#include <getopt.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/file.h"
#include "../driver/driver.h"
#include "client.h"
#include "command.h"

static void show_machines(json_t *a)
{
	json_t *m;
	size_t i;
	json_array_foreach(json_object_get(a, "machines"), i, m)
	{
		printf("  %-16s %s  %s\n", json_string_value(json_object_get(m, "device")),
		       json_is_true(json_object_get(m, "ok")) ? "switched" : "NOT switched",
		       json_string_value(json_object_get(m, "text")));
	}
}

static void show_deploy(json_t *a)
{
	if (json_is_true(json_object_get(a, "ok"))) {
		const char *hash = json_string_value(json_object_get(a, "hash"));
		printf("%s %s is active (version id %lld%s%.12s)", json_string_value(json_object_get(a, "driver")),
		       json_string_value(json_object_get(a, "version")), json_integer_value(json_object_get(a, "id")),
		       hash && hash[0] ? ", hash " : "", hash ? hash : "");
		if (json_number_value(json_object_get(a, "probation_s")) > 0)
			printf("; on probation for %.0f s", json_number_value(json_object_get(a, "probation_s")));
		printf("; %zu machine(s)\n", json_array_size(json_object_get(a, "machines")));
	}
	show_machines(a);
}

static void show_versions(json_t *a)
{
	json_t *v;
	size_t i;
	long long active = json_integer_value(json_object_get(a, "active"));
	if (json_is_string(json_object_get(a, "driver")))
		printf("%s: %s\n", json_string_value(json_object_get(a, "driver")),
		       active ? "runs the active version below" : "runs its file (no version uploaded is active)");
	printf("%5s %-14s %-10s %-12s %-19s %-16s %s\n", "ID", "DRIVER", "VERSION", "STATE", "DEPLOYED", "BY", "HASH");
	json_array_foreach(json_object_get(a, "versions"), i, v)
	{
		time_t t = (time_t)json_number_value(json_object_get(v, "deployed"));
		char when[24];
		const char *note = json_string_value(json_object_get(v, "note"));
		strftime(when, sizeof(when), "%Y-%m-%d %H:%M:%S", localtime(&t));
		printf("%5lld %-14s %-10s %-12s %-19s %-16s %.12s\n", json_integer_value(json_object_get(v, "id")),
		       json_string_value(json_object_get(v, "driver")),
		       json_string_value(json_object_get(v, "version")), json_string_value(json_object_get(v, "state")),
		       when, json_string_value(json_object_get(v, "deployed_by")),
		       json_string_value(json_object_get(v, "hash")));
		if (note && note[0])
			printf("      %s\n", note);
	}
}

/* The driver's name from a file name: "path/to/washer.lua" -> "washer". */
static int name_of(const char *path, char *name, size_t len)
{
	const char *base = strrchr(path, '/');
	size_t n;
	base = base ? base + 1 : path;
	n = strlen(base);
	if (n > 4 && strcmp(base + n - 4, ".lua") == 0)
		n -= 4;
	if (n == 0 || n >= len)
		return -1;
	memcpy(name, base, n);
	name[n] = 0;
	return 0;
}

int vmac_reload_main(int argc, char **argv)
{
	static const struct option opts[] = {VMAC_CMD_OPTS,
	                                     {"probation", required_argument, 0, 'p'},
	                                     {"driver", required_argument, 0, 'd'},
	                                     {0, 0, 0, 0}};
	struct vmac_cmd o;
	const char *probation = NULL, *driver = NULL;
	char name[64], path[256], why[600];
	size_t len = 0;
	char *src;
	int opt, rc, code = 0;
	vmac_cmd_init(&o);
	optind = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		if (vmac_cmd_opt(opt, &o))
			continue;
		switch (opt) {
		case 'p': probation = optarg; break;
		case 'd': driver = optarg; break;
		case 'h':
			printf(
			    "usage: vmac reload [options] FILE.lua\n"
			    "Upload a new version of a driver to a running vmacd: the host compiles it in a fresh\n"
			    "sandbox, refuses it with the error and line if it does not compile or its manifest is\n"
			    "wrong, and otherwise switches every running machine of that driver at a slot boundary,\n"
			    "handing the old state to the new version's migrate(). A version that fails within its\n"
			    "probation is rolled back by the host. Needs a token of scope deploy.\n"
			    "  --driver NAME      the driver's name (default: FILE's name without .lua)\n"
			    "  --probation S      seconds of probation (default: the host's reload_probation_s, 30)\n"
			    "%s",
			    VMAC_CMD_HELP);
			return 0;
		default: return 2;
		}
	}
	if (optind != argc - 1) {
		fprintf(stderr, "usage: vmac reload [options] FILE.lua (vmac reload --help)\n");
		return 2;
	}
	if (driver ? snprintf(name, sizeof(name), "%s", driver) >= (int)sizeof(name)
	           : name_of(argv[optind], name, sizeof(name)) != 0) {
		fprintf(stderr, "vmac reload: cannot take a driver name from '%s' (use --driver NAME)\n", argv[optind]);
		return 2;
	}
	src = vmac_read_file(argv[optind], VMAC_DRIVER_FILE_MAX, &len, why, sizeof(why), &code);
	if (!src) {
		fprintf(stderr, "vmac reload: %s\n", why);
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0) {
		free(src);
		return 2;
	}
	if (probation)
		snprintf(path, sizeof(path), "/api/drivers/%s?probation=%s", name, probation);
	else
		snprintf(path, sizeof(path), "/api/drivers/%s", name);
	rc = vmac_cmd_run(&o, "POST", path, src, len, show_deploy);
	free(src);
	return rc;
}

/* The options of a command that takes only the common ones: 0 to go on
 * (optind at the first argument), else the exit code (--help: 0, printed). */

int vmac_rollback_main(int argc, char **argv)
{
	struct vmac_cmd o;
	char path[256];
	int rc;
	if (vmac_cmd_only_common(argc, argv, &o,
	                         "usage: vmac rollback [options] DRIVER\n"
	                         "Go back to the version of DRIVER that was active before the active one (or to the\n"
	                         "driver's file), on every running machine, each at a slot boundary with migrate().\n"
	                         "Needs a token of scope deploy.\n",
	                         &rc))
		return rc;
	if (optind != argc - 1 || strlen(argv[optind]) > 63 || strchr(argv[optind], '/')) {
		fprintf(stderr, "usage: vmac rollback [options] DRIVER (vmac rollback --help)\n");
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0)
		return 2;
	snprintf(path, sizeof(path), "/api/drivers/%s/rollback", argv[optind]);
	return vmac_cmd_run(&o, "POST", path, NULL, 0, show_deploy);
}

int vmac_activate_main(int argc, char **argv)
{
	static const struct option opts[] = {VMAC_CMD_OPTS, {"probation", required_argument, 0, 'p'}, {0, 0, 0, 0}};
	struct vmac_cmd o;
	const char *probation = NULL;
	char path[256], *end;
	long long id;
	int opt;
	vmac_cmd_init(&o);
	optind = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		if (vmac_cmd_opt(opt, &o))
			continue;
		if (opt == 'p') {
			probation = optarg;
			continue;
		}
		if (opt == 'h') {
			printf(
			    "usage: vmac activate [options] DRIVER ID\n"
			    "Make version ID of DRIVER (vmac drivers lists them) the active one again: its source is\n"
			    "deployed as vmac reload would (a new entry in the list, the same hash), with migrate()\n"
			    "and probation. Needs a token of scope deploy.\n"
			    "  --probation S      seconds of probation (default: the host's reload_probation_s, "
			    "30)\n%s",
			    VMAC_CMD_HELP);
			return 0;
		}
		return 2;
	}
	if (optind != argc - 2 || strlen(argv[optind]) > 63 || strchr(argv[optind], '/') ||
	    (id = strtoll(argv[optind + 1], &end, 10)) < 1 || *end) {
		fprintf(stderr, "usage: vmac activate [options] DRIVER ID (vmac activate --help)\n");
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0)
		return 2;
	if (probation)
		snprintf(path, sizeof(path), "/api/drivers/%s/activate?id=%lld&probation=%s", argv[optind], id,
		         probation);
	else
		snprintf(path, sizeof(path), "/api/drivers/%s/activate?id=%lld", argv[optind], id);
	return vmac_cmd_run(&o, "POST", path, NULL, 0, show_deploy);
}

int vmac_drivers_main(int argc, char **argv)
{
	struct vmac_cmd o;
	char path[256];
	int rc;
	if (vmac_cmd_only_common(
	        argc, argv, &o,
	        "usage: vmac drivers [options] [DRIVER]\n"
	        "List the driver versions a running vmacd keeps (uploaded with vmac reload): id, version,\n"
	        "state (active, replaced, rolled_back, refused, pending), when, by which token, hash.\n"
	        "Needs a token of scope read.\n",
	        &rc))
		return rc;
	if (optind < argc - 1 || (optind == argc - 1 && (strlen(argv[optind]) > 63 || strchr(argv[optind], '/')))) {
		fprintf(stderr, "usage: vmac drivers [options] [DRIVER] (vmac drivers --help)\n");
		return 2;
	}
	if (vmac_client_token(o.token, o.token_file) != 0)
		return 2;
	if (optind == argc - 1)
		snprintf(path, sizeof(path), "/api/drivers/%s", argv[optind]);
	else
		snprintf(path, sizeof(path), "/api/drivers");
	return vmac_cmd_run(&o, "GET", path, NULL, 0, show_versions);
}
