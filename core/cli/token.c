/* vmac token create|list|revoke: works on the state folder's store directly,
 * so it runs with the host running or not (SQLite takes care of the two
 * writers). The token is printed once, on standard output, and never again:
 * the store keeps only its hash (core/store/store.h). Each create and
 * revoke leaves a row in the store's audit outbox naming the user who ran
 * it, which the host turns into an audit event (docs/API.md, "Audit
 * trail"). */
#include "token.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../store/store.h"
#include "command.h"

static void print_token(void *ctx, const struct vmac_token_info *t)
{
	char created[32], revoked[32] = "-";
	time_t c = (time_t)t->created, r = (time_t)t->revoked;
	(void)ctx;
	strftime(created, sizeof(created), "%Y-%m-%d %H:%M:%S", localtime(&c));
	if (t->revoked > 0)
		strftime(revoked, sizeof(revoked), "%Y-%m-%d %H:%M:%S", localtime(&r));
	printf("%-16s  %-16s  %-7s  %-19s  %-19s  %s\n", t->id, t->name[0] ? t->name : "-", vmac_scope_name(t->scope),
	       created, revoked, t->note);
}

/* The token store of a's --state: 0, or 1 after saying why. */
static int open_store(const struct vmac_cmd_args *a, struct vmac_store **store)
{
	char err[1024];
	if (vmac_store_open(a->opt[VMAC_CMD_STATE], store, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac token: %s\n", err);
		return 1;
	}
	return 0;
}

enum { CREATE_SCOPE = VMAC_CMD_OWN, CREATE_NAME, CREATE_NOTE };

static const struct vmac_cmd_option create_options[] = {
    [CREATE_SCOPE - VMAC_CMD_OWN] = {"scope", NULL, 0, "read|operate|deploy", NULL, NULL,
                                     "what the token may do (needed)"},
    [CREATE_NAME - VMAC_CMD_OWN] = {"name", NULL, 0, "NAME", NULL, NULL,
                                    "who holds it, as the audit trail names it: 1 to 32 of A-Z a-z 0-9 . _ @ + -"},
    [CREATE_NOTE - VMAC_CMD_OWN] = {"note", NULL, 0, "TEXT", NULL, NULL, "a note on what it is for"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int create_run(const struct vmac_cmd_args *a)
{
	const char *scope_name = a->opt[CREATE_SCOPE], *note = a->opt[CREATE_NOTE] ? a->opt[CREATE_NOTE] : "";
	const char *name = a->opt[CREATE_NAME] ? a->opt[CREATE_NAME] : "";
	struct vmac_store *store;
	enum vmac_scope scope;
	char token[VMAC_TOKEN_LEN + 1], id[VMAC_TOKEN_ID_LEN + 1], err[1024], by[200];
	int rc = 0;
	if (!scope_name || vmac_scope_parse(scope_name, &scope) != 0) {
		fprintf(stderr, "vmac token create: --scope must be read, operate or deploy%s%s\n",
		        scope_name ? ", not " : "", scope_name ? scope_name : "");
		return 2;
	}
	if (strlen(note) > VMAC_TOKEN_NOTE_MAX) {
		fprintf(stderr, "vmac token create: --note is longer than %d characters\n", VMAC_TOKEN_NOTE_MAX);
		return 2;
	}
	if (a->opt[CREATE_NAME] && !vmac_token_name_valid(name)) {
		fprintf(stderr, "vmac token create: --name is 1 to %d of A-Z a-z 0-9 . _ @ + -, not '%s'\n",
		        VMAC_TOKEN_NAME_MAX, name);
		return 2;
	}
	if (open_store(a, &store))
		return 1;
	vmac_cmd_who(by, sizeof(by));
	if (vmac_token_create(store, scope, name, note, by, token, id, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac token: %s\n", err);
		rc = 1;
	} else {
		printf("%s\n", token);
		fprintf(stderr, "vmac token: created %s%s%s%s (scope %s) in %s; this is the only time it is shown\n",
		        id, name[0] ? " \"" : "", name, name[0] ? "\"" : "", vmac_scope_name(scope),
		        a->opt[VMAC_CMD_STATE]);
	}
	vmac_store_close(store);
	return rc;
}

static int list_run(const struct vmac_cmd_args *a)
{
	struct vmac_store *store;
	char err[1024];
	int rc = 0;
	if (open_store(a, &store))
		return 1;
	printf("%-16s  %-16s  %-7s  %-19s  %-19s  %s\n", "ID", "NAME", "SCOPE", "CREATED", "REVOKED", "NOTE");
	if (vmac_token_list(store, print_token, NULL, err, sizeof(err)) < 0) {
		fprintf(stderr, "vmac token: %s\n", err);
		rc = 1;
	}
	vmac_store_close(store);
	return rc;
}

static int revoke_run(const struct vmac_cmd_args *a)
{
	struct vmac_store *store;
	char err[1024], by[200];
	int rc;
	if (open_store(a, &store))
		return 1;
	vmac_cmd_who(by, sizeof(by));
	rc = vmac_token_revoke(store, a->arg[0], by, err, sizeof(err));
	if (rc < 0)
		fprintf(stderr, "vmac token: %s\n", err);
	else if (rc == 1)
		fprintf(stderr, "vmac token: no valid token with ID %s in %s\n", a->arg[0], a->opt[VMAC_CMD_STATE]);
	else
		fprintf(stderr, "vmac token: revoked %s\n", a->arg[0]);
	vmac_store_close(store);
	return rc != 0;
}

#define EXIT_CODES "Exit 0 done, 1 the store cannot be opened or written, 2 wrong usage.\n"

static const struct vmac_cmd create_cmd = {
    .name = "create",
    .summary = "a new token, printed once on standard output; the host keeps only its hash",
    .about = "Make a token of the given scope: read (status, devices, events), operate (+ operator\n"
             "input, cycles, parameters), deploy (+ drivers). It is printed once on standard output and\n"
             "never again: the host keeps only its hash. Its name (--name) and the user who made it are\n"
             "in the host's audit trail (docs/API.md, \"Audit trail\").\n" EXIT_CODES,
    .common = VMAC_CMD_TAKES(VMAC_CMD_STATE),
    .own = create_options,
    .run = create_run};

static const struct vmac_cmd list_cmd = {
    .name = "list",
    .summary = "every token: ID, name, scope, when made, when revoked, note (never a secret)",
    .about = "List every token: ID, name, scope, when made, when revoked, note (never a secret).\n" EXIT_CODES,
    .common = VMAC_CMD_TAKES(VMAC_CMD_STATE),
    .run = list_run};

static const struct vmac_cmd revoke_cmd = {
    .name = "revoke",
    .args = "ID",
    .expect = "one token ID (vmac token list shows them)",
    .min_args = 1,
    .max_args = 1,
    .summary = "the token stops working at the host's next request",
    .about = "Revoke token ID (vmac token list shows them): it stops working at the host's next request,\n"
             "host running or not. The revocation is in the host's audit trail.\n"
             "Exit 0 done, 1 the store cannot be opened or written or no valid token has that ID, 2 wrong\n"
             "usage.\n",
    .common = VMAC_CMD_TAKES(VMAC_CMD_STATE),
    .run = revoke_run};

static const struct vmac_cmd *const actions[] = {&create_cmd, &list_cmd, &revoke_cmd, NULL};

const struct vmac_cmd vmac_token_cmd = {
    .name = "token",
    .args = "ACTION",
    .summary = "create, list and revoke the host's access tokens",
    .about = "The access tokens in the store of a host's state folder (--state DIR), host running or not.\n",
    .sub = actions};
