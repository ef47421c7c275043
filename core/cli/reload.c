/* vmac reload, rollback, activate and drivers: hot reload of a running host's drivers
 * over its HTTP API (docs/CLI.md, docs/API.md "Drivers"). */
#include "reload.h"

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

/* A driver's name as an argument: one path segment that fits. */
static int driver_name_ok(const char *name)
{
	return strlen(name) <= 63 && !strchr(name, '/');
}

enum { RELOAD_DRIVER = VMAC_CMD_OWN, RELOAD_PROBATION };

#define PROBATION_OPTION                                                                                               \
	{                                                                                                              \
		"probation", NULL, 0, "S", NULL, NULL,                                                                 \
		    "seconds of probation, 0: none (default: the host's reload_probation_s)"                           \
	}

static const struct vmac_cmd_option reload_options[] = {
    [RELOAD_DRIVER - VMAC_CMD_OWN] = {"driver", NULL, 0, "NAME", NULL, NULL,
                                      "the driver's name (default: FILE's name without .lua)"},
    [RELOAD_PROBATION - VMAC_CMD_OWN] = PROBATION_OPTION,
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int reload_run(const struct vmac_cmd_args *a)
{
	const char *file = a->arg[0], *probation = a->opt[RELOAD_PROBATION], *driver = a->opt[RELOAD_DRIVER];
	char name[64], path[256], why[600];
	size_t len = 0;
	char *src;
	int rc, code = 0;
	if (driver ? snprintf(name, sizeof(name), "%s", driver) >= (int)sizeof(name)
	           : name_of(file, name, sizeof(name)) != 0) {
		fprintf(stderr, "vmac reload: cannot take a driver name from '%s' (use --driver NAME)\n", file);
		return 2;
	}
	src = vmac_read_file(file, VMAC_DRIVER_FILE_MAX, &len, why, sizeof(why), &code);
	if (!src) {
		fprintf(stderr, "vmac reload: %s\n", why);
		return 2;
	}
	if (probation)
		snprintf(path, sizeof(path), "/api/drivers/%s?probation=%s", name, probation);
	else
		snprintf(path, sizeof(path), "/api/drivers/%s", name);
	rc = vmac_client_run(a, "POST", path, src, len, show_deploy);
	free(src);
	return rc;
}

#define EXIT_CODES "Exit 0 done, 1 the host refused or could not be reached (the reason on stderr), 2 wrong usage.\n"

const struct vmac_cmd vmac_reload_cmd = {
    .name = "reload",
    .args = "FILE.lua",
    .min_args = 1,
    .max_args = 1,
    .summary = "upload a new version of a driver; machines switch at a slot boundary",
    .about = "Upload a new version of a driver to a running vmacd: the host compiles it in a fresh\n"
             "sandbox, refuses it with the error and line if it does not compile or its manifest is\n"
             "wrong, and otherwise switches every running machine of that driver at a slot boundary,\n"
             "handing the old state to the new version's migrate(). A version that fails within its\n"
             "probation is rolled back by the host. Needs a token of scope deploy.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .own = reload_options,
    .run = reload_run};

static int rollback_run(const struct vmac_cmd_args *a)
{
	char path[256];
	if (!driver_name_ok(a->arg[0]))
		return vmac_cmd_usage_error(a, "'%s' is not a driver's name", a->arg[0]);
	snprintf(path, sizeof(path), "/api/drivers/%s/rollback", a->arg[0]);
	return vmac_client_run(a, "POST", path, NULL, 0, show_deploy);
}

const struct vmac_cmd vmac_rollback_cmd = {
    .name = "rollback",
    .args = "DRIVER",
    .min_args = 1,
    .max_args = 1,
    .summary = "go back to a driver's previous version",
    .about = "Go back to the version of DRIVER that was active before the active one (or to the\n"
             "driver's file), on every running machine, each at a slot boundary with migrate().\n"
             "Needs a token of scope deploy.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .run = rollback_run};

enum { ACTIVATE_PROBATION = VMAC_CMD_OWN };

static const struct vmac_cmd_option activate_options[] = {[ACTIVATE_PROBATION - VMAC_CMD_OWN] = PROBATION_OPTION,
                                                          {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int activate_run(const struct vmac_cmd_args *a)
{
	const char *probation = a->opt[ACTIVATE_PROBATION];
	char path[256], *end;
	long long id = strtoll(a->arg[1], &end, 10);
	if (!driver_name_ok(a->arg[0]))
		return vmac_cmd_usage_error(a, "'%s' is not a driver's name", a->arg[0]);
	if (id < 1 || *end || end == a->arg[1])
		return vmac_cmd_usage_error(a, "ID is a version's number (vmac drivers lists them), not '%s'",
		                            a->arg[1]);
	if (probation)
		snprintf(path, sizeof(path), "/api/drivers/%s/activate?id=%lld&probation=%s", a->arg[0], id, probation);
	else
		snprintf(path, sizeof(path), "/api/drivers/%s/activate?id=%lld", a->arg[0], id);
	return vmac_client_run(a, "POST", path, NULL, 0, show_deploy);
}

const struct vmac_cmd vmac_activate_cmd = {
    .name = "activate",
    .args = "DRIVER ID",
    .min_args = 2,
    .max_args = 2,
    .summary = "make a kept driver version the active one again",
    .about = "Make version ID of DRIVER (vmac drivers lists them) the active one again: its source is\n"
             "deployed as vmac reload would (a new entry in the list, the same hash), with migrate()\n"
             "and probation. Needs a token of scope deploy.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .own = activate_options,
    .run = activate_run};

static int drivers_run(const struct vmac_cmd_args *a)
{
	char path[256];
	if (a->nargs == 1 && !driver_name_ok(a->arg[0]))
		return vmac_cmd_usage_error(a, "'%s' is not a driver's name", a->arg[0]);
	if (a->nargs == 1)
		snprintf(path, sizeof(path), "/api/drivers/%s", a->arg[0]);
	else
		snprintf(path, sizeof(path), "/api/drivers");
	return vmac_client_run(a, "GET", path, NULL, 0, show_versions);
}

const struct vmac_cmd vmac_drivers_cmd = {
    .name = "drivers",
    .args = "[DRIVER]",
    .max_args = 1,
    .summary = "list the driver versions the host keeps",
    .about = "List the driver versions a running vmacd keeps (uploaded with vmac reload): id, version,\n"
             "state (active, replaced, rolled_back, refused, pending), when, by which token, hash.\n"
             "Needs a token of scope read.\n" EXIT_CODES,
    .common = VMAC_CMD_API,
    .run = drivers_run};
