/* Access tokens: made, listed, revoked and checked, only their hash kept
 * (docs/API.md, "Access"); and the audit outbox, where `vmac token` says
 * what it changed for the host to put in its event log (docs/API.md,
 * "Audit trail"). Part of the store (store.h). */
#include "store_internal.h"

#include <pthread.h>
#include <sodium.h>
#include <sqlite3.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>

#define SECRET_LEN 64 /* hex digits */
#define HASH_LEN crypto_generichash_BYTES

static const char *const scope_names[] = {"none", "read", "operate", "deploy"};

const char *vmac_scope_name(enum vmac_scope scope)
{
	return (unsigned)scope < sizeof(scope_names) / sizeof(scope_names[0]) ? scope_names[scope] : "none";
}

int vmac_scope_parse(const char *name, enum vmac_scope *scope)
{
	int i;
	for (i = VMAC_SCOPE_READ; i <= VMAC_SCOPE_DEPLOY; i++)
		if (strcmp(name, scope_names[i]) == 0) {
			*scope = (enum vmac_scope)i;
			return 0;
		}
	return -1;
}

/* BLAKE2b of the secret, keyed by nothing: the secret is 256 random bits,
 * so a fast hash is enough (no password stretching needed). */
static void hash_secret(const char *secret, unsigned char out[HASH_LEN])
{
	crypto_generichash(out, HASH_LEN, (const unsigned char *)secret, SECRET_LEN, NULL, 0);
}

static int is_hex(const char *s, size_t n)
{
	size_t i;
	for (i = 0; i < n; i++)
		if (!((s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f')))
			return 0;
	return 1;
}

int vmac_token_name_valid(const char *name)
{
	size_t i, n = name ? strlen(name) : 0;
	if (n == 0 || n > VMAC_TOKEN_NAME_MAX)
		return 0;
	for (i = 0; i < n; i++)
		if (!((name[i] >= 'a' && name[i] <= 'z') || (name[i] >= 'A' && name[i] <= 'Z') ||
		      (name[i] >= '0' && name[i] <= '9') || strchr("._@+-", name[i])))
			return 0;
	return 1;
}

/* INSERT INTO audit_outbox, in the caller's transaction (under s->lock). */
static int outbox_insert(struct vmac_store *s, const struct vmac_audit_row *r)
{
	sqlite3_stmt *st;
	int rc;
	if (sqlite3_prepare_v2(
	        s->db, "INSERT INTO audit_outbox (time, type, who, what, result, why) VALUES (?, ?, ?, ?, ?, ?)", -1,
	        &st, NULL) != SQLITE_OK)
		return -1;
	sqlite3_bind_double(st, 1, store_now_s());
	sqlite3_bind_text(st, 2, r->type, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 3, r->who, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 4, r->what, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 5, r->result, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 6, r->why, -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return -1;
	atomic_fetch_add(&s->audit_writes, 1);
	return 0;
}

/* The outbox row of a token made or revoked by `by`: what says which
 * ('vmac token create ID "NAME" (SCOPE)'). */
static void token_row(struct vmac_audit_row *r, const char *by, const char *action, const char *id, const char *name,
                      const char *scope, const char *why)
{
	char named[VMAC_TOKEN_NAME_MAX + 4] = "";
	memset(r, 0, sizeof(*r));
	if (name && name[0])
		snprintf(named, sizeof(named), " \"%s\"", name);
	snprintf(r->type, sizeof(r->type), "token");
	snprintf(r->who, sizeof(r->who), "%s", by);
	snprintf(r->what, sizeof(r->what), "vmac token %s %s%s%s%s%s", action, id, named, scope ? " (" : "",
	         scope ? scope : "", scope ? ")" : "");
	snprintf(r->result, sizeof(r->result), "%s", why ? "refused" : "ok");
	snprintf(r->why, sizeof(r->why), "%s", why ? why : "");
}

/* INSERT INTO tokens, in the caller's transaction. */
static int token_insert(struct vmac_store *s, const char *id_hex, const unsigned char *h, enum vmac_scope scope,
                        const char *name, const char *note)
{
	sqlite3_stmt *st;
	int rc;
	if (sqlite3_prepare_v2(s->db,
	                       "INSERT INTO tokens (id, hash, scope, created, name, note) VALUES (?, ?, ?, ?, ?, ?)",
	                       -1, &st, NULL) != SQLITE_OK)
		return -1;
	sqlite3_bind_text(st, 1, id_hex, -1, SQLITE_TRANSIENT);
	sqlite3_bind_blob(st, 2, h, HASH_LEN, SQLITE_TRANSIENT);
	sqlite3_bind_int(st, 3, (int)scope);
	sqlite3_bind_double(st, 4, store_now_s());
	sqlite3_bind_text(st, 5, name, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 6, note ? note : "", note ? (int)strnlen(note, VMAC_TOKEN_NOTE_MAX) : 0,
	                  SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	return rc == SQLITE_DONE ? 0 : -1;
}

int vmac_token_create(struct vmac_store *s, enum vmac_scope scope, const char *name, const char *note, const char *by,
                      char *token, char *id, char *err, size_t errlen)
{
	unsigned char rid[VMAC_TOKEN_ID_LEN / 2], secret[SECRET_LEN / 2], h[HASH_LEN];
	char id_hex[VMAC_TOKEN_ID_LEN + 1], secret_hex[SECRET_LEN + 1];
	struct vmac_audit_row row;
	int ok, rc;
	if (scope < VMAC_SCOPE_READ || scope > VMAC_SCOPE_DEPLOY) {
		snprintf(err, errlen, "token: scope must be read, operate or deploy");
		return -1;
	}
	if (!name)
		name = "";
	if (name[0] && !vmac_token_name_valid(name)) {
		snprintf(err, errlen, "token: a name is 1 to %d of A-Z a-z 0-9 . _ @ + -", VMAC_TOKEN_NAME_MAX);
		return -1;
	}
	randombytes_buf(rid, sizeof(rid));
	randombytes_buf(secret, sizeof(secret));
	store_hex(rid, sizeof(rid), id_hex);
	store_hex(secret, sizeof(secret), secret_hex);
	hash_secret(secret_hex, h);
	sodium_memzero(secret, sizeof(secret));
	if (by)
		token_row(&row, by, "create", id_hex, name, vmac_scope_name(scope), NULL);
	if (store_begin(s) != 0) {
		sodium_memzero(secret_hex, sizeof(secret_hex));
		return store_fail_unlock(s, "creating a token", err, errlen);
	}
	ok = token_insert(s, id_hex, h, scope, name, note) == 0 && (!by || outbox_insert(s, &row) == 0);
	rc = store_end(s, ok, "creating a token", err, errlen);
	if (rc != 0) {
		sodium_memzero(secret_hex, sizeof(secret_hex));
		return rc;
	}
	snprintf(token, VMAC_TOKEN_LEN + 1, "vmac_%s_%s", id_hex, secret_hex);
	sodium_memzero(secret_hex, sizeof(secret_hex));
	if (id)
		memcpy(id, id_hex, sizeof(id_hex));
	return 0;
}

/* The name of token id (into name, "" when none or no such token), in
 * the caller's lock. */
static void name_of(struct vmac_store *s, const char *id, char *name, size_t len)
{
	sqlite3_stmt *st;
	name[0] = 0;
	if (sqlite3_prepare_v2(s->db, "SELECT name FROM tokens WHERE id = ?", -1, &st, NULL) != SQLITE_OK)
		return;
	sqlite3_bind_text(st, 1, id, -1, SQLITE_TRANSIENT);
	if (sqlite3_step(st) == SQLITE_ROW)
		store_text_col(st, 0, name, len);
	sqlite3_finalize(st);
}

int vmac_token_revoke(struct vmac_store *s, const char *id, const char *by, char *err, size_t errlen)
{
	struct vmac_audit_row row;
	char name[VMAC_TOKEN_NAME_MAX + 1], shown[VMAC_TOKEN_ID_LEN + 1];
	sqlite3_stmt *st;
	int ok, changed = 0, rc;
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "revoking a token", err, errlen);
	name_of(s, id, name, sizeof(name));
	ok = sqlite3_prepare_v2(s->db, "UPDATE tokens SET revoked = ? WHERE id = ? AND revoked IS NULL", -1, &st,
	                        NULL) == SQLITE_OK;
	if (ok) {
		sqlite3_bind_double(st, 1, store_now_s());
		sqlite3_bind_text(st, 2, id, -1, SQLITE_TRANSIENT);
		ok = sqlite3_step(st) == SQLITE_DONE;
		sqlite3_finalize(st);
		changed = sqlite3_changes(s->db); /* of this statement: no other ran since */
	}
	if (ok && by) {
		/* An id of any bytes is said as at most its first 16 of [0-9a-f]. */
		snprintf(shown, sizeof(shown), "%.*s", (int)strspn(id, "0123456789abcdef"), id);
		token_row(&row, by, "revoke", shown[0] ? shown : "-", name, NULL,
		          changed == 1 ? NULL : "no valid token has that ID");
		ok = outbox_insert(s, &row) == 0;
	}
	rc = store_end(s, ok, "revoking a token", err, errlen);
	if (rc != 0)
		return rc;
	return changed == 1 ? 0 : 1;
}

int vmac_token_list(struct vmac_store *s, void (*fn)(void *ctx, const struct vmac_token_info *t), void *ctx, char *err,
                    size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT id, scope, created, revoked, note, name FROM tokens ORDER BY created, id",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "listing tokens", err, errlen);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_token_info t;
		const unsigned char *text;
		memset(&t, 0, sizeof(t));
		text = sqlite3_column_text(st, 0);
		snprintf(t.id, sizeof(t.id), "%s", text ? (const char *)text : "");
		t.scope = (enum vmac_scope)sqlite3_column_int(st, 1);
		t.created = sqlite3_column_double(st, 2);
		t.revoked = sqlite3_column_type(st, 3) == SQLITE_NULL ? 0 : sqlite3_column_double(st, 3);
		text = sqlite3_column_text(st, 4);
		snprintf(t.note, sizeof(t.note), "%s", text ? (const char *)text : "");
		store_text_col(st, 5, t.name, sizeof(t.name));
		fn(ctx, &t);
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "listing tokens", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}

int vmac_token_id(const char *token, char id[VMAC_TOKEN_ID_LEN + 1])
{
	if (!token || strlen(token) != VMAC_TOKEN_LEN || strncmp(token, "vmac_", 5) != 0 ||
	    token[5 + VMAC_TOKEN_ID_LEN] != '_' || !is_hex(token + 5, VMAC_TOKEN_ID_LEN) ||
	    !is_hex(token + 5 + VMAC_TOKEN_ID_LEN + 1, SECRET_LEN))
		return -1;
	memcpy(id, token + 5, VMAC_TOKEN_ID_LEN);
	id[VMAC_TOKEN_ID_LEN] = 0;
	return 0;
}

enum vmac_scope vmac_token_check(struct vmac_store *s, const char *token)
{
	return vmac_token_check_info(s, token, NULL);
}

enum vmac_scope vmac_token_check_info(struct vmac_store *s, const char *token, struct vmac_token_info *info)
{
	static const unsigned char zero[HASH_LEN];
	unsigned char h[HASH_LEN], stored[HASH_LEN];
	char id[VMAC_TOKEN_ID_LEN + 1], name[VMAC_TOKEN_NAME_MAX + 1] = "";
	const char *secret;
	enum vmac_scope scope = VMAC_SCOPE_NONE;
	sqlite3_stmt *st;
	int found = 0;
	if (vmac_token_id(token, id) != 0)
		return VMAC_SCOPE_NONE;
	secret = token + 5 + VMAC_TOKEN_ID_LEN + 1;
	memcpy(stored, zero, sizeof(stored));
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT hash, scope, name FROM tokens WHERE id = ? AND revoked IS NULL", -1, &st,
	                       NULL) != SQLITE_OK) {
		pthread_mutex_unlock(&s->lock);
		return VMAC_SCOPE_NONE;
	}
	sqlite3_bind_text(st, 1, id, -1, SQLITE_TRANSIENT);
	if (sqlite3_step(st) == SQLITE_ROW && sqlite3_column_bytes(st, 0) == HASH_LEN) {
		memcpy(stored, sqlite3_column_blob(st, 0), HASH_LEN);
		scope = (enum vmac_scope)sqlite3_column_int(st, 1);
		store_text_col(st, 2, name, sizeof(name));
		found = 1;
	}
	sqlite3_finalize(st);
	pthread_mutex_unlock(&s->lock);
	/* Hash and compare whether or not the ID exists: the time taken says
	 * nothing about the secret. */
	hash_secret(secret, h);
	if (sodium_memcmp(h, stored, HASH_LEN) != 0 || !found || scope < VMAC_SCOPE_READ || scope > VMAC_SCOPE_DEPLOY)
		return VMAC_SCOPE_NONE;
	if (info) {
		memset(info, 0, sizeof(*info));
		memcpy(info->id, id, sizeof(id));
		memcpy(info->name, name, sizeof(name));
		info->scope = scope;
	}
	return scope;
}

/* ---- the audit outbox ---- */

int vmac_store_audit_add(struct vmac_store *s, const struct vmac_audit_row *row, char *err, size_t errlen)
{
	if (store_lock_write(s) != 0 || outbox_insert(s, row) != 0)
		return store_fail_unlock(s, "adding to the audit outbox", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return 0;
}

int vmac_store_audit_list(struct vmac_store *s, int64_t after, int limit,
                          void (*fn)(void *ctx, const struct vmac_audit_row *r), void *ctx, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(
	        s->db,
	        "SELECT id, time, type, who, what, result, why FROM audit_outbox WHERE id > ? ORDER BY id "
	        "LIMIT ?",
	        -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading the audit outbox", err, errlen);
	sqlite3_bind_int64(st, 1, after);
	sqlite3_bind_int(st, 2, limit);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_audit_row r;
		r.id = sqlite3_column_int64(st, 0);
		r.time = sqlite3_column_double(st, 1);
		store_text_col(st, 2, r.type, sizeof(r.type));
		store_text_col(st, 3, r.who, sizeof(r.who));
		store_text_col(st, 4, r.what, sizeof(r.what));
		store_text_col(st, 5, r.result, sizeof(r.result));
		store_text_col(st, 6, r.why, sizeof(r.why));
		fn(ctx, &r);
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "reading the audit outbox", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}

int vmac_store_audit_delete(struct vmac_store *s, int64_t upto, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc;
	if (store_lock_write(s) != 0 ||
	    sqlite3_prepare_v2(s->db, "DELETE FROM audit_outbox WHERE id <= ?", -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "emptying the audit outbox", err, errlen);
	sqlite3_bind_int64(st, 1, upto);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "emptying the audit outbox", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return 0;
}

uint64_t vmac_store_audit_version(struct vmac_store *s)
{
	return store_data_version(s) << 32 ^ atomic_load(&s->audit_writes);
}
