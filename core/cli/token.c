/* vmac token create|list|revoke: works on the state folder's store directly,
 * so it runs with the host running or not (SQLite takes care of the two
 * writers). The token is printed once, on standard output, and never again:
 * the store keeps only its hash (core/store/store.h). */
#include "token.h"

#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../store/store.h"

#define DEFAULT_STATE "/var/lib/vmac" /* vmacd's default state_dir (docs/HOST.md) */

static void usage(FILE *f)
{
	fprintf(f,
	        "usage: vmac token create --scope read|operate|deploy [--note TEXT] [--state DIR]\n"
	        "       vmac token list [--state DIR]\n"
	        "       vmac token revoke ID [--state DIR]\n"
	        "Access tokens of the host whose state folder is DIR (default $VMAC_STATE, else %s).\n"
	        "Scopes: read (status, devices, events), operate (+ operator input, cycles, parameters),\n"
	        "deploy (+ drivers). create prints the new token once on standard output; the host keeps\n"
	        "only its hash. revoke takes effect at once, host running or not.\n",
	        DEFAULT_STATE);
}

static void print_token(void *ctx, const struct vmac_token_info *t)
{
	char created[32], revoked[32] = "-";
	time_t c = (time_t)t->created, r = (time_t)t->revoked;
	(void)ctx;
	strftime(created, sizeof(created), "%Y-%m-%d %H:%M:%S", localtime(&c));
	if (t->revoked > 0)
		strftime(revoked, sizeof(revoked), "%Y-%m-%d %H:%M:%S", localtime(&r));
	printf("%-16s  %-7s  %-19s  %-19s  %s\n", t->id, vmac_scope_name(t->scope), created, revoked, t->note);
}

int vmac_token_main(int argc, char **argv)
{
	static const struct option opts[] = {{"state", required_argument, 0, 's'},
	                                     {"scope", required_argument, 0, 'c'},
	                                     {"note", required_argument, 0, 'n'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {0, 0, 0, 0}};
	const char *state = getenv("VMAC_STATE") ? getenv("VMAC_STATE") : DEFAULT_STATE, *scope_name = NULL, *note = "",
	           *action;
	struct vmac_store *store;
	char err[1024];
	int opt, rc = 0;

	if (argc < 2 || strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
		usage(argc < 2 ? stderr : stdout);
		return argc < 2 ? 2 : 0;
	}
	action = argv[1];
	if (strcmp(action, "create") != 0 && strcmp(action, "list") != 0 && strcmp(action, "revoke") != 0) {
		fprintf(stderr, "vmac token: unknown action '%s' (create, list or revoke)\n", action);
		return 2;
	}
	optind = 2;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		switch (opt) {
		case 's': state = optarg; break;
		case 'c': scope_name = optarg; break;
		case 'n': note = optarg; break;
		case 'h': usage(stdout); return 0;
		default: return 2;
		}
	}
	if (strcmp(action, "create") == 0) {
		enum vmac_scope scope;
		char token[VMAC_TOKEN_LEN + 1], id[VMAC_TOKEN_ID_LEN + 1];
		if (optind < argc) {
			fprintf(stderr, "vmac token create: unexpected argument '%s'\n", argv[optind]);
			return 2;
		}
		if (!scope_name || vmac_scope_parse(scope_name, &scope) != 0) {
			fprintf(stderr, "vmac token create: --scope must be read, operate or deploy%s%s\n",
			        scope_name ? ", not " : "", scope_name ? scope_name : "");
			return 2;
		}
		if (strlen(note) > VMAC_TOKEN_NOTE_MAX) {
			fprintf(stderr, "vmac token create: --note is longer than %d characters\n",
			        VMAC_TOKEN_NOTE_MAX);
			return 2;
		}
		if (vmac_store_open(state, &store, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmac token: %s\n", err);
			return 1;
		}
		if (vmac_token_create(store, scope, note, token, id, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmac token: %s\n", err);
			rc = 1;
		} else {
			printf("%s\n", token);
			fprintf(stderr, "vmac token: created %s (scope %s) in %s; this is the only time it is shown\n",
			        id, vmac_scope_name(scope), state);
		}
	} else if (strcmp(action, "list") == 0) {
		if (optind < argc) {
			fprintf(stderr, "vmac token list: unexpected argument '%s'\n", argv[optind]);
			return 2;
		}
		if (vmac_store_open(state, &store, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmac token: %s\n", err);
			return 1;
		}
		printf("%-16s  %-7s  %-19s  %-19s  %s\n", "ID", "SCOPE", "CREATED", "REVOKED", "NOTE");
		if (vmac_token_list(store, print_token, NULL, err, sizeof(err)) < 0) {
			fprintf(stderr, "vmac token: %s\n", err);
			rc = 1;
		}
	} else {
		if (optind != argc - 1) {
			fprintf(stderr, "vmac token revoke: give exactly one token ID (vmac token list shows them)\n");
			return 2;
		}
		if (vmac_store_open(state, &store, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmac token: %s\n", err);
			return 1;
		}
		rc = vmac_token_revoke(store, argv[optind], err, sizeof(err));
		if (rc < 0)
			fprintf(stderr, "vmac token: %s\n", err);
		else if (rc == 1)
			fprintf(stderr, "vmac token: no valid token with ID %s in %s\n", argv[optind], state);
		else
			fprintf(stderr, "vmac token: revoked %s\n", argv[optind]);
		rc = rc != 0;
	}
	vmac_store_close(store);
	return rc;
}
