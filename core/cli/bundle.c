/* vmac bundle PATH and vmac bundle show FILE: a machine's software as one
 * file, made from a drivers folder and looked into (docs/CLI.md "vmac
 * bundle", docs/DRIVERS.md "Bundles"); and what vmac reload sends. */
#include "bundle.h"

#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../bundle/bundle.h"
#include "../bundle/minisign.h"
#include "../common/file.h"
#include "../loader/loader.h"

/* The settings a bundle is compiled with on this machine: the shipped
 * stdlib, as vmac test has it. */
static void local_config(struct vmac_config *cfg)
{
	vmac_config_defaults(cfg);
	vmac_config_shipped_dirs(cfg);
	cfg->driver_budget_us = 0; /* the instruction budget only */
}

/* counter as --counter gives it (NULL: 0): 0, or -1. */
static int parse_counter(const char *s, uint64_t *counter)
{
	char *end;
	*counter = 0;
	if (!s)
		return 0;
	*counter = strtoull(s, &end, 10);
	return s[0] >= '0' && s[0] <= '9' && !*end && *counter <= INT64_MAX ? 0 : -1;
}

int vmac_cli_bundle_load(const char *path, const char *counter_s, const char *sig_path, char **data, size_t *len,
                         char **sig, size_t *siglen, char *name, size_t namelen)
{
	struct stat st;
	struct vmac_bundle *b = NULL;
	char err[800], auto_sig[VMAC_PATH_MAX + 16];
	size_t n = strlen(path);
	uint64_t counter;
	int code = 0;
	*data = *sig = NULL;
	*siglen = 0;
	if (parse_counter(counter_s, &counter) != 0) {
		fprintf(stderr, "vmac: --counter must be a whole number, 0 or more, not '%s'\n", counter_s);
		return 2;
	}
	if ((stat(path, &st) == 0 && S_ISDIR(st.st_mode)) || (n > 4 && strcmp(path + n - 4, ".lua") == 0)) {
		struct vmac_config cfg;
		if (sig_path) {
			fprintf(stderr,
			        "vmac: a bundle made on the fly cannot carry a signature: vmac bundle %s, sign "
			        "the file with minisign -S, then vmac reload FILE\n",
			        path);
			return 2;
		}
		local_config(&cfg);
		if (vmac_bundle_make(&cfg, path, counter, &b, err, sizeof(err)) != 0 ||
		    vmac_bundle_write(b, data, len, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmac: %s\n", err);
			vmac_bundle_free(b);
			return 1;
		}
	} else {
		if (counter_s) {
			fprintf(stderr, "vmac: --counter is for a bundle made from a folder; %s has its own\n", path);
			return 2;
		}
		if (!(*data = vmac_read_file(path, VMAC_BUNDLE_MAX, len, err, sizeof(err), &code)) ||
		    vmac_bundle_read(*data, *len, &b, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmac: %s%s%s\n", *data ? path : "", *data ? ": " : "", err);
			free(*data);
			*data = NULL;
			return 1;
		}
		snprintf(auto_sig, sizeof(auto_sig), "%s.minisig", path);
		if (!sig_path && stat(auto_sig, &st) == 0)
			sig_path = auto_sig;
		if (sig_path &&
		    !(*sig = vmac_read_file(sig_path, VMAC_MINISIGN_SIG_MAX, siglen, err, sizeof(err), &code))) {
			fprintf(stderr, "vmac: %s\n", err);
			free(*data);
			*data = NULL;
			vmac_bundle_free(b);
			return 1;
		}
	}
	snprintf(name, namelen, "%s", b->name);
	vmac_bundle_free(b);
	return 0;
}

enum { MAKE_OUT = VMAC_CMD_OWN, MAKE_COUNTER, SHOW_KEYS };

static const struct vmac_cmd_option bundle_options[] = {
    [MAKE_OUT - VMAC_CMD_OWN] = {"output", NULL, 'o', "FILE", NULL, NULL,
                                 "where to write it (default: NAME-VERSION.vbundle here)"},
    [MAKE_COUNTER - VMAC_CMD_OWN] = {"counter", NULL, 0, "N", NULL, NULL,
                                     "its security counter (default 0): a host refuses a bundle whose counter is "
                                     "below one it accepted"},
    [SHOW_KEYS - VMAC_CMD_OWN] = {"keys", NULL, 0, "FILE", NULL, NULL,
                                  "show: check FILE.minisig with these minisign public keys"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int make(const struct vmac_cmd_args *a, const char *path)
{
	struct vmac_config cfg;
	struct vmac_bundle *b;
	char err[800], out[VMAC_PATH_MAX], comment[300], *data;
	size_t len;
	uint64_t counter;
	FILE *f;
	if (parse_counter(a->opt[MAKE_COUNTER], &counter) != 0)
		return vmac_cmd_usage_error(a, "--counter must be a whole number, 0 or more");
	local_config(&cfg);
	if (vmac_bundle_make(&cfg, path, counter, &b, err, sizeof(err)) != 0 ||
	    vmac_bundle_write(b, &data, &len, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac bundle: %s\n", err);
		return 1;
	}
	if (a->opt[MAKE_OUT])
		snprintf(out, sizeof(out), "%s", a->opt[MAKE_OUT]);
	else
		snprintf(out, sizeof(out), "%s-%s.vbundle", b->name, b->version);
	f = fopen(out, "wb");
	if (!f || fwrite(data, 1, len, f) != len || fclose(f) != 0) {
		fprintf(stderr, "vmac bundle: cannot write %s\n", out);
		free(data);
		vmac_bundle_free(b);
		return 1;
	}
	vmac_bundle_comment(b, comment, sizeof(comment));
	printf("%s %s, counter %llu, %d files, %zu bytes: %s\n", b->name, b->version, (unsigned long long)b->counter,
	       b->nfiles, len, out);
	printf("sign it:  minisign -S -s KEY -m %s -t \"%s\"\n", out, comment);
	free(data);
	vmac_bundle_free(b);
	return 0;
}

/* The signature beside file, checked against keys file keys. */
static void show_signature(const struct vmac_bundle *b, const char *file, const char *keys, const char *data,
                           size_t len)
{
	struct vmac_minisign_key k[VMAC_MINISIGN_KEYS];
	struct vmac_minisign_result r;
	char path[VMAC_PATH_MAX + 16], err[600], *sig;
	size_t siglen;
	int n, code = 0;
	snprintf(path, sizeof(path), "%s.minisig", file);
	if (!(sig = vmac_read_file(path, VMAC_MINISIGN_SIG_MAX, &siglen, err, sizeof(err), &code))) {
		printf("signature: none (%s)\n", path);
		return;
	}
	if (!keys) {
		printf("signature: %s (not checked: --keys FILE checks it)\n", path);
	} else if ((n = vmac_minisign_keys_load(keys, k, VMAC_MINISIGN_KEYS, err, sizeof(err))) < 0) {
		printf("signature: not checked: %s\n", err);
	} else if (vmac_minisign_verify(k, n, data, len, sig, siglen, &r, err, sizeof(err)) != 0 ||
	           vmac_bundle_comment_check(b, r.trusted_comment, err, sizeof(err)) != 0) {
		printf("signature: REFUSED: %s\n", err);
	} else {
		printf("signature: good, key %s, trusted comment \"%s\"\n", k[r.key].id_hex, r.trusted_comment);
	}
	free(sig);
}

static int show(const struct vmac_cmd_args *a, const char *file)
{
	struct vmac_bundle *b;
	char err[800], hash[VMAC_BUNDLE_HASH_LEN + 1], *data;
	size_t len;
	int i, code = 0;
	if (!(data = vmac_read_file(file, VMAC_BUNDLE_MAX, &len, err, sizeof(err), &code))) {
		fprintf(stderr, "vmac bundle show: %s\n", err);
		return 1;
	}
	if (vmac_bundle_read(data, len, &b, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac bundle show: %s: %s\n", file, err);
		free(data);
		return 1;
	}
	vmac_bundle_hash(data, len, hash);
	if (a->opt[VMAC_CMD_JSON]) {
		json_t *files = json_array(), *j;
		for (i = 0; i < b->nfiles; i++)
			json_array_append_new(files, json_pack("{s:s, s:I, s:s}", "path", b->files[i].path, "size",
			                                       (json_int_t)b->files[i].len, "hash", b->files[i].hash));
		j = json_pack("{s:s, s:s, s:I, s:s, s:s, s:I, s:o}", "name", b->name, "version", b->version, "counter",
		              (json_int_t)b->counter, "api", b->api, "hash", hash, "size", (json_int_t)len, "files",
		              files);
		json_dumpf(j, stdout, JSON_INDENT(2));
		printf("\n");
		json_decref(j);
	} else {
		printf("%s %s, counter %llu, driver API %s\nhash %s, %zu bytes\n", b->name, b->version,
		       (unsigned long long)b->counter, b->api, hash, len);
		for (i = 0; i < b->nfiles; i++)
			printf("  %-32s %8zu  %.16s\n", b->files[i].path, b->files[i].len, b->files[i].hash);
		show_signature(b, file, a->opt[SHOW_KEYS], data, len);
	}
	vmac_bundle_free(b);
	free(data);
	return 0;
}

static int bundle_run(const struct vmac_cmd_args *a)
{
	if (strcmp(a->arg[0], "show") == 0) {
		if (a->nargs != 2)
			return vmac_cmd_usage_error(a, "vmac bundle show FILE");
		return show(a, a->arg[1]);
	}
	if (a->nargs != 1)
		return vmac_cmd_usage_error(a, "one folder or driver file to bundle");
	if (a->opt[SHOW_KEYS])
		return vmac_cmd_usage_error(a, "--keys is for vmac bundle show");
	return make(a, a->arg[0]);
}

const struct vmac_cmd vmac_bundle_cmd = {
    .name = "bundle",
    .args = "DIR|FILE.lua | show FILE",
    .expect = "a folder or driver file to bundle, or show FILE",
    .min_args = 1,
    .max_args = 2,
    .summary = "make a bundle of a driver, its programmes, plant and tests; or look into one",
    .about = "vmac bundle DIR|DIR/NAME.lua [-o FILE] [--counter N]: one file holding the driver NAME.lua,\n"
             "its programmes (DIR/cycles/NAME/*.lua), its plant (DIR/plants/NAME.lua) and tests\n"
             "(DIR/tests/NAME_test.lua, NAME_*_test.lua) with their hashes, its version from the\n"
             "driver's manifest (the driver is compiled) and the security counter N. The same files\n"
             "always give the same bytes. It prints the minisign command that signs it.\n"
             "vmac bundle show FILE [--keys KEYS]: what FILE holds, and its signature FILE.minisig,\n"
             "checked against the minisign public keys in KEYS. docs/DRIVERS.md \"Bundles\".\n"
             "Exit 0 done, 1 it cannot be made or read (the reason on stderr), 2 wrong usage.\n",
    .common = VMAC_CMD_TAKES(VMAC_CMD_JSON),
    .own = bundle_options,
    .run = bundle_run};
