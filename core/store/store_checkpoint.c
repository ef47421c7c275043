/* Checkpoints of machine state in the store: see store.h. */
#include "store_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int vmac_store_checkpoints_put(struct vmac_store *s, const struct vmac_checkpoint *cp, int n, char *err, size_t errlen)
{
	sqlite3_stmt *st = NULL;
	int i, ok;
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "saving checkpoints", err, errlen);
	ok = sqlite3_prepare_v2(s->db,
	                        "INSERT OR REPLACE INTO checkpoints (machine, driver, version, time, data) "
	                        "VALUES (?, ?, ?, ?, ?)",
	                        -1, &st, NULL) == SQLITE_OK;
	for (i = 0; ok && i < n; i++) {
		sqlite3_reset(st);
		sqlite3_bind_text(st, 1, cp[i].machine, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 2, cp[i].driver, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 3, cp[i].version, -1, SQLITE_TRANSIENT);
		sqlite3_bind_double(st, 4, cp[i].time);
		sqlite3_bind_blob(st, 5, cp[i].data, (int)cp[i].len, SQLITE_TRANSIENT);
		ok = sqlite3_step(st) == SQLITE_DONE;
	}
	sqlite3_finalize(st);
	return store_end(s, ok, "saving checkpoints", err, errlen);
}

int vmac_store_checkpoint_get(struct vmac_store *s, const char *machine, uint8_t **data, size_t *len, char *driver,
                              size_t driverlen, char *version, size_t versionlen, double *time, char *err,
                              size_t errlen)
{
	sqlite3_stmt *st;
	int rc, found = 0;
	*data = NULL;
	*len = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT driver, version, time, data FROM checkpoints WHERE machine = ?", -1, &st,
	                       NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading a checkpoint", err, errlen);
	sqlite3_bind_text(st, 1, machine, -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	if (rc == SQLITE_ROW) {
		const void *blob = sqlite3_column_blob(st, 3);
		int n = sqlite3_column_bytes(st, 3);
		store_text_col(st, 0, driver, driverlen);
		store_text_col(st, 1, version, versionlen);
		*time = sqlite3_column_double(st, 2);
		*data = malloc(n > 0 ? (size_t)n : 1);
		if (!*data) {
			sqlite3_finalize(st);
			pthread_mutex_unlock(&s->lock);
			snprintf(err, errlen, "store: reading a checkpoint: out of memory");
			return -VMAC_EFAIL;
		}
		if (n > 0)
			memcpy(*data, blob, (size_t)n);
		*len = (size_t)n;
		found = 1;
	} else if (rc != SQLITE_DONE) {
		sqlite3_finalize(st);
		return store_fail_unlock(s, "reading a checkpoint", err, errlen);
	}
	sqlite3_finalize(st);
	pthread_mutex_unlock(&s->lock);
	return found;
}
