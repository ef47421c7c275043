/* vmac reload, rollback, activate and drivers: hot reload of a running host's drivers
 * over its HTTP API (docs/CLI.md, docs/API.md "Drivers"). */
#include "reload.h"

#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <sodium.h>

#include "../bundle/minisign.h"
#include "bundle.h"
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
	const char *note = json_string_value(json_object_get(a, "note"));
	if (json_is_true(json_object_get(a, "unchanged"))) {
		printf("%s\n", note);
		return;
	}
	if (note && note[0])
		printf("%s\n", note);
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
		       active ? "runs the active version below" : "no version has run yet");
	printf("%5s %-14s %-10s %-12s %-19s %-16s %-12s %4s %-16s\n", "ID", "DRIVER", "VERSION", "STATE", "DEPLOYED",
	       "BY", "HASH", "CTR", "SIGNER");
	json_array_foreach(json_object_get(a, "versions"), i, v)
	{
		time_t t = (time_t)json_number_value(json_object_get(v, "deployed"));
		char when[24];
		const char *note = json_string_value(json_object_get(v, "note"));
		strftime(when, sizeof(when), "%Y-%m-%d %H:%M:%S", localtime(&t));
		const char *signer = json_string_value(json_object_get(v, "signer"));
		const char *by = json_string_value(json_object_get(v, "deployed_by_name"));
		if (!by || !by[0])
			by = json_string_value(json_object_get(v, "deployed_by"));
		printf("%5lld %-14s %-10s %-12s %-19s %-16s %-12.12s %4lld %-16s\n",
		       json_integer_value(json_object_get(v, "id")), json_string_value(json_object_get(v, "driver")),
		       json_string_value(json_object_get(v, "version")), json_string_value(json_object_get(v, "state")),
		       when, by, json_string_value(json_object_get(v, "hash")),
		       json_integer_value(json_object_get(v, "counter")), signer && signer[0] ? signer : "unsigned");
		if (note && note[0])
			printf("      %s\n", note);
	}
}

/* A driver's name as an argument: one path segment that fits. */
static int driver_name_ok(const char *name)
{
	return strlen(name) <= 63 && !strchr(name, '/');
}

enum { RELOAD_DRIVER = VMAC_CMD_OWN, RELOAD_PROBATION, RELOAD_FORCE, RELOAD_SIG, RELOAD_COUNTER };

#define PROBATION_OPTION                                                                                               \
	{                                                                                                              \
		"probation", NULL, 0, "S", NULL, NULL,                                                                 \
		    "seconds of probation, 0: none (default: the host's reload_probation_s)"                           \
	}

static const struct vmac_cmd_option reload_options[] = {
    [RELOAD_DRIVER - VMAC_CMD_OWN] = {"driver", NULL, 0, "NAME", NULL, NULL,
                                      "the driver it must be (default: the bundle's)"},
    [RELOAD_PROBATION - VMAC_CMD_OWN] = PROBATION_OPTION,
    [RELOAD_FORCE - VMAC_CMD_OWN] = {"force", NULL, 0, NULL, NULL, NULL,
                                     "replace a kept version of the same number and other content"},
    [RELOAD_SIG - VMAC_CMD_OWN] = {"sig", NULL, 0, "FILE", NULL, NULL,
                                   "the bundle's minisign signature (default: BUNDLE.minisig when there is one)"},
    [RELOAD_COUNTER - VMAC_CMD_OWN] = {"counter", NULL, 0, "N", NULL, NULL,
                                       "the security counter of a bundle made from a folder (default 0)"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int reload_run(const struct vmac_cmd_args *a)
{
	const char *probation = a->opt[RELOAD_PROBATION], *driver = a->opt[RELOAD_DRIVER];
	char name[64], path[300], *data, *sig, b64[2 * VMAC_MINISIGN_SIG_MAX], header[2 * VMAC_MINISIGN_SIG_MAX + 32];
	size_t len, siglen;
	int rc = vmac_cli_bundle_load(a->arg[0], a->opt[RELOAD_COUNTER], a->opt[RELOAD_SIG], &data, &len, &sig, &siglen,
	                              name, sizeof(name));
	if (rc != 0)
		return rc;
	if (driver && strcmp(driver, name) != 0) {
		fprintf(stderr, "vmac reload: %s is a bundle of %s, not %s\n", a->arg[0], name, driver);
		free(data);
		free(sig);
		return 1;
	}
	snprintf(path, sizeof(path), "/api/drivers/%s?force=%d%s%s", name, a->opt[RELOAD_FORCE] ? 1 : 0,
	         probation ? "&probation=" : "", probation ? probation : "");
	if (sig) {
		sodium_bin2base64(b64, sizeof(b64), (const unsigned char *)sig, siglen, sodium_base64_VARIANT_ORIGINAL);
		snprintf(header, sizeof(header), "Vmac-Signature: %s", b64);
		vmac_client_header(header);
	}
	rc = vmac_client_run(a, "POST", path, data, len, show_deploy);
	free(data);
	free(sig);
	return rc;
}

#define EXIT_CODES "Exit 0 done, 1 the host refused or could not be reached (the reason on stderr), 2 wrong usage.\n"

const struct vmac_cmd vmac_reload_cmd = {
    .name = "reload",
    .args = "BUNDLE|DIR|FILE.lua",
    .min_args = 1,
    .max_args = 1,
    .summary = "deploy a new version of a driver (a bundle); machines switch at a slot boundary",
    .about = "Deploy a bundle (vmac bundle) to a running vmacd, with its signature BUNDLE.minisig when\n"
             "there is one; a folder or a driver file is bundled on the fly (its programmes with it).\n"
             "The host checks the signature (its deploy_keys), the security counter and the version,\n"
             "compiles it in a fresh sandbox against the bundle's programmes only, refuses it with\n"
             "the reason if any of that fails, and otherwise switches every running machine of that\n"
             "driver at a slot boundary, handing the old state to the new version's migrate(). The\n"
             "same content again changes nothing; a kept version number with other content needs\n"
             "--force. A version that fails within its probation is rolled back by the host. Needs a\n"
             "token of scope deploy.\n" EXIT_CODES,
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
    .about = "Go back to the version of DRIVER that ran before the active one (whatever its security\n"
             "counter: the one way back past it), on every running machine, each at a slot boundary\n"
             "with migrate(). Needs a token of scope deploy.\n" EXIT_CODES,
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
    .about = "Make version ID of DRIVER (vmac drivers lists them) the active one again: its bundle is\n"
             "deployed as vmac reload would (a new entry in the list, the same hash), with migrate()\n"
             "and probation; refused when its security counter is below one accepted since (vmac\n"
             "rollback goes back past it). Needs a token of scope deploy.\n" EXIT_CODES,
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
