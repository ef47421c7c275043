/* Unit tests of the store (core/store): tokens are created with the scope
 * asked for, checked by hash, refused when malformed, altered, unknown or
 * revoked, listed without their secrets, and kept across a reopen. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../core/store/store.h"

static char dir[] = "/tmp/vmac-test-store-XXXXXX";
static struct vmac_store *store;

static void setup(void)
{
	char err[512] = "";
	snprintf(dir, sizeof(dir), "/tmp/vmac-test-store-XXXXXX");
	ck_assert_msg(mkdtemp(dir) != NULL, "mkdtemp failed");
	ck_assert_msg(vmac_store_open(dir, &store, err, sizeof(err)) == 0, "open failed: %s", err);
}

static void teardown(void)
{
	char cmd[128];
	vmac_store_close(store);
	store = NULL;
	snprintf(cmd, sizeof(cmd), "rm -rf %s", dir);
	ck_assert_int_eq(system(cmd), 0);
}

static void create(enum vmac_scope scope, char *token, char *id)
{
	char err[512] = "";
	ck_assert_msg(vmac_token_create(store, scope, "test", token, id, err, sizeof(err)) == 0, "create: %s", err);
	ck_assert_uint_eq(strlen(token), VMAC_TOKEN_LEN);
}

START_TEST(tokens_carry_their_scope)
{
	char token[VMAC_TOKEN_LEN + 1], other[VMAC_TOKEN_LEN + 1];
	enum vmac_scope scope;
	create(VMAC_SCOPE_READ, token, NULL);
	ck_assert_int_eq(vmac_token_check(store, token), VMAC_SCOPE_READ);
	create(VMAC_SCOPE_DEPLOY, other, NULL);
	ck_assert_int_eq(vmac_token_check(store, other), VMAC_SCOPE_DEPLOY);
	ck_assert_msg(strcmp(token, other) != 0, "two tokens are equal");
	ck_assert_int_eq(vmac_scope_parse("operate", &scope), 0);
	ck_assert_int_eq(scope, VMAC_SCOPE_OPERATE);
	ck_assert_int_eq(vmac_scope_parse("admin", &scope), -1);
	ck_assert_str_eq(vmac_scope_name(VMAC_SCOPE_DEPLOY), "deploy");
}
END_TEST

START_TEST(wrong_tokens_are_refused)
{
	char token[VMAC_TOKEN_LEN + 1], bad[VMAC_TOKEN_LEN + 8];
	create(VMAC_SCOPE_OPERATE, token, NULL);
	/* the secret altered in its last digit */
	memcpy(bad, token, sizeof(token));
	bad[VMAC_TOKEN_LEN - 1] = bad[VMAC_TOKEN_LEN - 1] == '0' ? '1' : '0';
	ck_assert_int_eq(vmac_token_check(store, bad), VMAC_SCOPE_NONE);
	/* an unknown ID with a well-formed secret */
	memcpy(bad, token, sizeof(token));
	bad[5] = bad[5] == '0' ? '1' : '0';
	ck_assert_int_eq(vmac_token_check(store, bad), VMAC_SCOPE_NONE);
	/* malformed: empty, short, long, upper-case hex, no prefix */
	ck_assert_int_eq(vmac_token_check(store, ""), VMAC_SCOPE_NONE);
	ck_assert_int_eq(vmac_token_check(store, "vmac_"), VMAC_SCOPE_NONE);
	snprintf(bad, sizeof(bad), "%s0", token);
	ck_assert_int_eq(vmac_token_check(store, bad), VMAC_SCOPE_NONE);
	memcpy(bad, token, sizeof(token));
	bad[30] = 'A';
	ck_assert_int_eq(vmac_token_check(store, bad), VMAC_SCOPE_NONE);
	memcpy(bad, token, sizeof(token));
	bad[0] = 'x';
	ck_assert_int_eq(vmac_token_check(store, bad), VMAC_SCOPE_NONE);
	ck_assert_int_eq(vmac_token_check(store, token), VMAC_SCOPE_OPERATE);
}
END_TEST

struct seen {
	int n, revoked;
	char ids[4][VMAC_TOKEN_ID_LEN + 1];
};

static void collect(void *ctx, const struct vmac_token_info *t)
{
	struct seen *s = ctx;
	if (s->n < 4)
		memcpy(s->ids[s->n], t->id, sizeof(t->id));
	s->n++;
	s->revoked += t->revoked > 0;
	ck_assert_str_eq(t->note, "test");
}

START_TEST(revoked_tokens_stop_at_once_and_survive_a_reopen)
{
	char token[VMAC_TOKEN_LEN + 1], keep[VMAC_TOKEN_LEN + 1], id[VMAC_TOKEN_ID_LEN + 1], err[512] = "";
	struct seen seen;
	create(VMAC_SCOPE_DEPLOY, token, id);
	create(VMAC_SCOPE_READ, keep, NULL);
	ck_assert_int_eq(vmac_token_revoke(store, id, err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_token_check(store, token), VMAC_SCOPE_NONE);
	ck_assert_int_eq(vmac_token_revoke(store, id, err, sizeof(err)), 1);
	ck_assert_int_eq(vmac_token_revoke(store, "0000000000000000", err, sizeof(err)), 1);

	vmac_store_close(store);
	ck_assert_msg(vmac_store_open(dir, &store, err, sizeof(err)) == 0, "reopen failed: %s", err);
	ck_assert_int_eq(vmac_token_check(store, token), VMAC_SCOPE_NONE);
	ck_assert_int_eq(vmac_token_check(store, keep), VMAC_SCOPE_READ);
	memset(&seen, 0, sizeof(seen));
	ck_assert_int_eq(vmac_token_list(store, collect, &seen, err, sizeof(err)), 2);
	ck_assert_int_eq(seen.revoked, 1);
	ck_assert_msg(strcmp(seen.ids[0], id) == 0 || strcmp(seen.ids[1], id) == 0, "the revoked ID is not listed");
}
END_TEST

START_TEST(a_missing_folder_is_an_error)
{
	struct vmac_store *s = NULL;
	char err[512] = "";
	ck_assert_int_eq(vmac_store_open("/nonexistent/vmac-state", &s, err, sizeof(err)), -1);
	ck_assert_msg(s == NULL, "a store was returned for a missing folder");
	ck_assert_msg(strstr(err, "/nonexistent/vmac-state") != NULL, "the error does not name the folder: %s", err);
}
END_TEST

int main(void)
{
	Suite *s = suite_create("store");
	TCase *tc = tcase_create("tokens");
	SRunner *r;
	int failed;
	tcase_add_checked_fixture(tc, setup, teardown);
	tcase_add_test(tc, tokens_carry_their_scope);
	tcase_add_test(tc, wrong_tokens_are_refused);
	tcase_add_test(tc, revoked_tokens_stop_at_once_and_survive_a_reopen);
	tcase_add_test(tc, a_missing_folder_is_an_error);
	suite_add_tcase(s, tc);
	r = srunner_create(s);
	srunner_run_all(r, CK_NORMAL);
	failed = srunner_ntests_failed(r);
	srunner_free(r);
	return failed ? 1 : 0;
}
