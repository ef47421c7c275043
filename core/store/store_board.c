/* Board keys: enrolled, listed, removed, and a version that tells the host
 * to read them again (store.h, "board keys"); part of the store. */
#include "store_internal.h"

#include <errno.h>
#include <pthread.h>
#include <sodium.h>
#include <sqlite3.h>
#include <stdio.h>
#include <string.h>

int vmac_board_name_valid(const char *name)
{
	size_t n = 0;
	for (; *name; name++, n++)
		if (n >= VMAC_BOARD_NAME_MAX || !((*name >= 'a' && *name <= 'z') || (*name >= 'A' && *name <= 'Z') ||
		                                  (*name >= '0' && *name <= '9') || *name == '-' || *name == '_'))
			return 0;
	return n > 0;
}

void vmac_board_key_fingerprint(const uint8_t key[VMAC_BOARD_KEY_LEN], char out[VMAC_BOARD_FINGERPRINT_LEN + 1])
{
	unsigned char h[VMAC_BOARD_FINGERPRINT_LEN / 2];
	crypto_generichash(h, sizeof(h), key, VMAC_BOARD_KEY_LEN, NULL, 0);
	store_hex(h, sizeof(h), out);
}

int vmac_board_keys_set(struct vmac_store *s, const struct vmac_board_key *k, int n, int replace, int *kept, char *err,
                        size_t errlen)
{
	sqlite3_stmt *st = NULL;
	int i, ok = 1;
	*kept = 0;
	for (i = 0; i < n; i++)
		if (!vmac_board_name_valid(k[i].board)) {
			snprintf(err, errlen, "board name '%.40s': 1..%d of A-Z a-z 0-9 _ -", k[i].board,
			         VMAC_BOARD_NAME_MAX);
			return -EINVAL;
		}
	/* One transaction: a fleet of boards costs one commit, not one each. */
	if (store_begin(s) != 0 ||
	    sqlite3_prepare_v2(s->db,
	                       replace
	                           ? "INSERT OR REPLACE INTO board_keys (board, key, created, note) VALUES (?, ?, ?, ?)"
	                           : "INSERT OR IGNORE INTO board_keys (board, key, created, note) VALUES (?, ?, ?, ?)",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_end(s, 0, "enrolling a board", err, errlen);
	for (i = 0; i < n && ok; i++) {
		sqlite3_reset(st);
		sqlite3_bind_text(st, 1, k[i].board, -1, SQLITE_TRANSIENT);
		sqlite3_bind_blob(st, 2, k[i].key, VMAC_BOARD_KEY_LEN, SQLITE_TRANSIENT);
		sqlite3_bind_double(st, 3, store_now_s());
		sqlite3_bind_text(st, 4, k[i].note, (int)strnlen(k[i].note, VMAC_BOARD_NOTE_MAX), SQLITE_TRANSIENT);
		ok = sqlite3_step(st) == SQLITE_DONE;
		*kept += ok && sqlite3_changes(s->db) == 0;
	}
	sqlite3_finalize(st);
	if (ok)
		atomic_fetch_add(&s->key_writes, 1);
	return store_end(s, ok, "enrolling a board", err, errlen);
}

int vmac_board_key_set(struct vmac_store *s, const char *board, const uint8_t key[VMAC_BOARD_KEY_LEN], int replace,
                       const char *note, char *err, size_t errlen)
{
	struct vmac_board_key k;
	int kept, rc;
	memset(&k, 0, sizeof(k));
	if (strlen(board) > VMAC_BOARD_NAME_MAX) {
		snprintf(err, errlen, "board name '%.40s': 1..%d of A-Z a-z 0-9 _ -", board, VMAC_BOARD_NAME_MAX);
		return -EINVAL;
	}
	memcpy(k.board, board, strlen(board));
	memcpy(k.key, key, VMAC_BOARD_KEY_LEN);
	snprintf(k.note, sizeof(k.note), "%s", note ? note : "");
	rc = vmac_board_keys_set(s, &k, 1, replace, &kept, err, errlen);
	sodium_memzero(k.key, sizeof(k.key));
	return rc < 0 ? rc : kept;
}

int vmac_board_key_remove(struct vmac_store *s, const char *board, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc, changed;
	if (store_lock_write(s) != 0 ||
	    sqlite3_prepare_v2(s->db, "DELETE FROM board_keys WHERE board = ?", -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "removing a board's key", err, errlen);
	sqlite3_bind_text(st, 1, board, -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "removing a board's key", err, errlen);
	changed = sqlite3_changes(s->db);
	atomic_fetch_add(&s->key_writes, 1);
	pthread_mutex_unlock(&s->lock);
	return changed == 1 ? 0 : 1;
}

int vmac_board_key_list(struct vmac_store *s, void (*fn)(void *ctx, const struct vmac_board_key *k), void *ctx,
                        char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT board, key, created, note FROM board_keys ORDER BY board", -1, &st,
	                       NULL) != SQLITE_OK)
		return store_fail_unlock(s, "listing board keys", err, errlen);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_board_key k;
		memset(&k, 0, sizeof(k));
		store_text_col(st, 0, k.board, sizeof(k.board));
		if (sqlite3_column_bytes(st, 1) != VMAC_BOARD_KEY_LEN)
			continue; /* not a key this host wrote: never used */
		memcpy(k.key, sqlite3_column_blob(st, 1), VMAC_BOARD_KEY_LEN);
		vmac_board_key_fingerprint(k.key, k.fingerprint);
		k.created = sqlite3_column_double(st, 2);
		store_text_col(st, 3, k.note, sizeof(k.note));
		fn(ctx, &k);
		sodium_memzero(k.key, sizeof(k.key));
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "listing board keys", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}

uint64_t store_data_version(struct vmac_store *s)
{
	uint64_t version = 0;
	pthread_mutex_lock(&s->lock);
	/* Prepared once: the host asks often, and parsing it was the cost. */
	if (s->data_version_st ||
	    sqlite3_prepare_v2(s->db, "PRAGMA data_version", -1, &s->data_version_st, NULL) == SQLITE_OK) {
		if (sqlite3_step(s->data_version_st) == SQLITE_ROW)
			version = (uint64_t)sqlite3_column_int64(s->data_version_st, 0);
		sqlite3_reset(s->data_version_st);
	}
	pthread_mutex_unlock(&s->lock);
	return version;
}

uint64_t vmac_store_local_writes(struct vmac_store *s)
{
	return atomic_load(&s->key_writes) + atomic_load(&s->audit_writes);
}

uint64_t vmac_board_keys_version(struct vmac_store *s)
{
	/* data_version changes with every commit of another connection (of
	 * any table: reading the keys again then costs little); this
	 * connection's own writes are counted in key_writes. */
	return store_data_version(s) << 32 ^ atomic_load(&s->key_writes);
}
