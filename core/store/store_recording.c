/* Flight recordings in the store: see store.h. */
#include "store_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int vmac_store_recording_add(struct vmac_store *s, const struct vmac_recording_info *info, const char *data, size_t len,
                             int keep, int64_t *id, char *err, size_t errlen)
{
	sqlite3_stmt *st = NULL;
	int ok;
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "keeping a recording", err, errlen);
	ok = sqlite3_prepare_v2(s->db,
	                        "INSERT INTO recordings (machine, driver, version, reason, time, data) "
	                        "VALUES (?, ?, ?, ?, ?, ?)",
	                        -1, &st, NULL) == SQLITE_OK;
	if (ok) {
		sqlite3_bind_text(st, 1, info->machine, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 2, info->driver, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 3, info->version, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 4, info->reason, -1, SQLITE_TRANSIENT);
		sqlite3_bind_double(st, 5, info->time);
		sqlite3_bind_blob64(st, 6, data, len, SQLITE_TRANSIENT);
		ok = sqlite3_step(st) == SQLITE_DONE;
		*id = sqlite3_last_insert_rowid(s->db);
	}
	sqlite3_finalize(st);
	st = NULL;
	if (ok && sqlite3_prepare_v2(s->db,
	                             "DELETE FROM recordings WHERE id NOT IN "
	                             "(SELECT id FROM recordings ORDER BY id DESC LIMIT ?)",
	                             -1, &st, NULL) == SQLITE_OK) {
		sqlite3_bind_int(st, 1, keep);
		ok = sqlite3_step(st) == SQLITE_DONE;
	}
	sqlite3_finalize(st);
	return store_end(s, ok, "keeping a recording", err, errlen);
}

int vmac_store_recording_list(struct vmac_store *s, const char *machine,
                              void (*fn)(void *ctx, const struct vmac_recording_info *r), void *ctx, char *err,
                              size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db,
	                       "SELECT id, machine, driver, version, reason, time, length(data) FROM recordings "
	                       "WHERE ?1 IS NULL OR machine = ?1 ORDER BY id DESC",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "listing recordings", err, errlen);
	if (machine)
		sqlite3_bind_text(st, 1, machine, -1, SQLITE_TRANSIENT);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_recording_info r;
		memset(&r, 0, sizeof(r));
		r.id = sqlite3_column_int64(st, 0);
		store_text_col(st, 1, r.machine, sizeof(r.machine));
		store_text_col(st, 2, r.driver, sizeof(r.driver));
		store_text_col(st, 3, r.version, sizeof(r.version));
		store_text_col(st, 4, r.reason, sizeof(r.reason));
		r.time = sqlite3_column_double(st, 5);
		r.size = (size_t)sqlite3_column_int64(st, 6);
		fn(ctx, &r);
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "listing recordings", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}

int vmac_store_recording_get(struct vmac_store *s, int64_t id, char **data, size_t *len, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc, found = 0;
	*data = NULL;
	*len = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT data FROM recordings WHERE id = ?", -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading a recording", err, errlen);
	sqlite3_bind_int64(st, 1, id);
	rc = sqlite3_step(st);
	if (rc == SQLITE_ROW) {
		int n = sqlite3_column_bytes(st, 0);
		*data = malloc((size_t)n + 1);
		if (*data) {
			memcpy(*data, sqlite3_column_blob(st, 0), (size_t)n);
			(*data)[n] = 0;
			*len = (size_t)n;
			found = 1;
		}
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_fail_unlock(s, "reading a recording", err, errlen);
	pthread_mutex_unlock(&s->lock);
	if (rc == SQLITE_ROW && !found) {
		snprintf(err, errlen, "store: reading a recording: out of memory");
		return -VMAC_EFAIL;
	}
	return found;
}
