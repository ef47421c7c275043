/* Access tokens: made, listed, revoked and checked, only their hash kept
 * (docs/API.md, "Access"); part of the store (store.h). */
#include "store_internal.h"

#include <pthread.h>
#include <sodium.h>
#include <sqlite3.h>
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

int vmac_token_create(struct vmac_store *s, enum vmac_scope scope, const char *note, char *token, char *id, char *err,
                      size_t errlen)
{
	unsigned char rid[VMAC_TOKEN_ID_LEN / 2], secret[SECRET_LEN / 2], h[HASH_LEN];
	char id_hex[VMAC_TOKEN_ID_LEN + 1], secret_hex[SECRET_LEN + 1];
	sqlite3_stmt *st;
	int rc;
	if (scope < VMAC_SCOPE_READ || scope > VMAC_SCOPE_DEPLOY) {
		snprintf(err, errlen, "token: scope must be read, operate or deploy");
		return -1;
	}
	randombytes_buf(rid, sizeof(rid));
	randombytes_buf(secret, sizeof(secret));
	store_hex(rid, sizeof(rid), id_hex);
	store_hex(secret, sizeof(secret), secret_hex);
	hash_secret(secret_hex, h);
	if (store_lock_write(s) != 0 ||
	    sqlite3_prepare_v2(s->db, "INSERT INTO tokens (id, hash, scope, created, note) VALUES (?, ?, ?, ?, ?)", -1,
	                       &st, NULL) != SQLITE_OK) {
		sodium_memzero(secret, sizeof(secret));
		sodium_memzero(secret_hex, sizeof(secret_hex));
		return store_fail_unlock(s, "creating a token", err, errlen);
	}
	sqlite3_bind_text(st, 1, id_hex, -1, SQLITE_TRANSIENT);
	sqlite3_bind_blob(st, 2, h, HASH_LEN, SQLITE_TRANSIENT);
	sqlite3_bind_int(st, 3, (int)scope);
	sqlite3_bind_double(st, 4, store_now_s());
	sqlite3_bind_text(st, 5, note ? note : "", note ? (int)strnlen(note, VMAC_TOKEN_NOTE_MAX) : 0,
	                  SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	sodium_memzero(secret, sizeof(secret));
	if (rc != SQLITE_DONE) {
		sodium_memzero(secret_hex, sizeof(secret_hex));
		return store_fail_unlock(s, "creating a token", err, errlen);
	}
	pthread_mutex_unlock(&s->lock);
	snprintf(token, VMAC_TOKEN_LEN + 1, "vmac_%s_%s", id_hex, secret_hex);
	sodium_memzero(secret_hex, sizeof(secret_hex));
	if (id)
		memcpy(id, id_hex, sizeof(id_hex));
	return 0;
}

int vmac_token_revoke(struct vmac_store *s, const char *id, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc, changed;
	if (store_lock_write(s) != 0 ||
	    sqlite3_prepare_v2(s->db, "UPDATE tokens SET revoked = ? WHERE id = ? AND revoked IS NULL", -1, &st,
	                       NULL) != SQLITE_OK)
		return store_fail_unlock(s, "revoking a token", err, errlen);
	sqlite3_bind_double(st, 1, store_now_s());
	sqlite3_bind_text(st, 2, id, -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "revoking a token", err, errlen);
	changed = sqlite3_changes(s->db); /* of this statement: no other ran since */
	pthread_mutex_unlock(&s->lock);
	return changed == 1 ? 0 : 1;
}

int vmac_token_list(struct vmac_store *s, void (*fn)(void *ctx, const struct vmac_token_info *t), void *ctx, char *err,
                    size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT id, scope, created, revoked, note FROM tokens ORDER BY created, id", -1,
	                       &st, NULL) != SQLITE_OK)
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
	static const unsigned char zero[HASH_LEN];
	unsigned char h[HASH_LEN], stored[HASH_LEN];
	char id[VMAC_TOKEN_ID_LEN + 1];
	const char *secret;
	enum vmac_scope scope = VMAC_SCOPE_NONE;
	sqlite3_stmt *st;
	int found = 0;
	if (vmac_token_id(token, id) != 0)
		return VMAC_SCOPE_NONE;
	secret = token + 5 + VMAC_TOKEN_ID_LEN + 1;
	memcpy(stored, zero, sizeof(stored));
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT hash, scope FROM tokens WHERE id = ? AND revoked IS NULL", -1, &st,
	                       NULL) != SQLITE_OK) {
		pthread_mutex_unlock(&s->lock);
		return VMAC_SCOPE_NONE;
	}
	sqlite3_bind_text(st, 1, id, -1, SQLITE_TRANSIENT);
	if (sqlite3_step(st) == SQLITE_ROW && sqlite3_column_bytes(st, 0) == HASH_LEN) {
		memcpy(stored, sqlite3_column_blob(st, 0), HASH_LEN);
		scope = (enum vmac_scope)sqlite3_column_int(st, 1);
		found = 1;
	}
	sqlite3_finalize(st);
	pthread_mutex_unlock(&s->lock);
	/* Hash and compare whether or not the ID exists: the time taken says
	 * nothing about the secret. */
	hash_secret(secret, h);
	if (sodium_memcmp(h, stored, HASH_LEN) != 0 || !found || scope < VMAC_SCOPE_READ || scope > VMAC_SCOPE_DEPLOY)
		return VMAC_SCOPE_NONE;
	return scope;
}
