/* The persistent store on SQLite (see store.h): opening it and its schema,
 * driver versions, persisted params, the event log. */
#include "store_internal.h"

#include <errno.h>
#include <pthread.h>
#include <sodium.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#define BUSY_MS 5000 /* another process (vmac token, a second reader) holding the lock */

/* Schema versions, applied in order; PRAGMA user_version says how many ran. */
static const char *const migrations[] = {
    "CREATE TABLE tokens ("
    " id TEXT PRIMARY KEY,"
    " hash BLOB NOT NULL,"
    " scope INTEGER NOT NULL,"
    " created REAL NOT NULL,"
    " revoked REAL,"
    " note TEXT NOT NULL DEFAULT '')",
    "CREATE TABLE driver_versions ("
    " id INTEGER PRIMARY KEY,"
    " driver TEXT NOT NULL,"
    " version TEXT NOT NULL,"
    " hash TEXT NOT NULL,"
    " source BLOB NOT NULL,"
    " deployed REAL NOT NULL,"
    " deployed_by TEXT NOT NULL,"
    " state TEXT NOT NULL,"
    " previous INTEGER NOT NULL DEFAULT 0,"
    " note TEXT NOT NULL DEFAULT '');"
    "CREATE INDEX driver_versions_by_driver ON driver_versions (driver, id)",
    "CREATE TABLE params ("
    " machine TEXT NOT NULL,"
    " name TEXT NOT NULL,"
    " type INTEGER NOT NULL,"
    " number REAL NOT NULL DEFAULT 0,"
    " string TEXT NOT NULL DEFAULT '',"
    " updated REAL NOT NULL,"
    " PRIMARY KEY (machine, name))",
    "CREATE TABLE events ("
    " seq INTEGER PRIMARY KEY,"
    " time REAL NOT NULL,"
    " kind TEXT NOT NULL,"
    " device TEXT NOT NULL,"
    " text TEXT NOT NULL)",
    "CREATE TABLE checkpoints ("
    " machine TEXT PRIMARY KEY,"
    " driver TEXT NOT NULL,"
    " version TEXT NOT NULL,"
    " time REAL NOT NULL,"
    " data BLOB NOT NULL)",
    "CREATE TABLE recordings ("
    " id INTEGER PRIMARY KEY,"
    " machine TEXT NOT NULL,"
    " driver TEXT NOT NULL,"
    " version TEXT NOT NULL,"
    " reason TEXT NOT NULL,"
    " time REAL NOT NULL,"
    " data BLOB NOT NULL)",
    "CREATE TABLE board_keys ("
    " board TEXT PRIMARY KEY,"
    " key BLOB NOT NULL,"
    " created REAL NOT NULL,"
    " note TEXT NOT NULL DEFAULT '')",
    /* The audit trail: who holds a token, and what `vmac token` changed,
     * waiting for the host (store_token.c). */
    "ALTER TABLE tokens ADD COLUMN name TEXT NOT NULL DEFAULT '';"
    "CREATE TABLE audit_outbox ("
    " id INTEGER PRIMARY KEY AUTOINCREMENT,"
    " time REAL NOT NULL,"
    " type TEXT NOT NULL,"
    " who TEXT NOT NULL,"
    " what TEXT NOT NULL,"
    " result TEXT NOT NULL,"
    " why TEXT NOT NULL DEFAULT '')",
    /* bundles (docs/DRIVERS.md "Bundles"): each version's security counter,
     * signer and origin */
    "ALTER TABLE driver_versions ADD COLUMN counter INTEGER NOT NULL DEFAULT 0;"
    "ALTER TABLE driver_versions ADD COLUMN signer TEXT NOT NULL DEFAULT '';"
    "ALTER TABLE driver_versions ADD COLUMN origin TEXT NOT NULL DEFAULT 'upload'",
    /* the bundles (the archive; Lua text in versions stored before them)
     * in a table of their own, by version id: a blob before the columns a
     * query reads made every look at a driver's versions read every
     * bundle it ever kept (a deploy slowed with each one) */
    "CREATE TABLE driver_bundles (id INTEGER PRIMARY KEY, data BLOB NOT NULL);"
    "INSERT INTO driver_bundles (id, data) SELECT id, source FROM driver_versions;"
    "ALTER TABLE driver_versions ADD COLUMN size INTEGER NOT NULL DEFAULT 0;"
    "UPDATE driver_versions SET size = length(source), source = x''",
};

double store_now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* err says what failed and SQLite's why; returns the code of it: the disk
 * is full (SQLITE_FULL), or any other failure. */
int store_fail(struct vmac_store *s, const char *what, char *err, size_t errlen)
{
	int full;
	if (s && s->gone) {
		snprintf(err, errlen,
		         "store: %s: the database %s was removed or replaced while the host ran; nothing more is "
		         "written to it (restart the host to open the store again)",
		         what, s->path);
		atomic_fetch_add(&s->failures[VMAC_STORE_FAILED_REPLACED], 1);
		return -VMAC_ESTORE;
	}
	snprintf(err, errlen, "store: %s: %s", what, s && s->db ? sqlite3_errmsg(s->db) : "cannot open");
	full = s && s->db && (sqlite3_extended_errcode(s->db) & 0xff) == SQLITE_FULL;
	if (s)
		atomic_fetch_add(&s->failures[full ? VMAC_STORE_FAILED_FULL : VMAC_STORE_FAILED_OTHER], 1);
	return full ? -VMAC_ESTOREFULL : -VMAC_ESTORE;
}

/* store_fail(), then let the other threads in: the message is the one of this
 * thread's statement. */
int store_fail_unlock(struct vmac_store *s, const char *what, char *err, size_t errlen)
{
	int rc = store_fail(s, what, err, errlen);
	pthread_mutex_unlock(&s->lock);
	return rc;
}

static int exec(struct vmac_store *s, const char *sql, char *err, size_t errlen)
{
	char *msg = NULL;
	if (sqlite3_exec(s->db, sql, NULL, NULL, &msg) != SQLITE_OK) {
		snprintf(err, errlen, "store: %s", msg ? msg : sqlite3_errmsg(s->db));
		sqlite3_free(msg);
		return -1;
	}
	return 0;
}

static int migrate(struct vmac_store *s, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int version = 0, n = (int)(sizeof(migrations) / sizeof(migrations[0]));
	char sql[64];
	if (sqlite3_prepare_v2(s->db, "PRAGMA user_version", -1, &st, NULL) != SQLITE_OK)
		return store_fail(s, "reading the schema version", err, errlen);
	if (sqlite3_step(st) == SQLITE_ROW)
		version = sqlite3_column_int(st, 0);
	sqlite3_finalize(st);
	if (version > n) {
		snprintf(err, errlen, "store: the database is of a newer vmac (schema %d, this one knows %d)", version,
		         n);
		return -1;
	}
	for (; version < n; version++) {
		if (exec(s, "BEGIN IMMEDIATE", err, errlen) != 0)
			return -1;
		snprintf(sql, sizeof(sql), "PRAGMA user_version = %d", version + 1);
		if (exec(s, migrations[version], err, errlen) != 0 || exec(s, sql, err, errlen) != 0) {
			sqlite3_exec(s->db, "ROLLBACK", NULL, NULL, NULL);
			return -1;
		}
		if (exec(s, "COMMIT", err, errlen) != 0)
			return -1;
	}
	return 0;
}

/* The store at path (":memory:" for one in memory), its schema brought up
 * to date. */
static int open_at(const char *path, struct vmac_store **out, char *err, size_t errlen)
{
	struct vmac_store *s = calloc(1, sizeof(*s));
	if (!s) {
		snprintf(err, errlen, "store: out of memory");
		return -ENOMEM;
	}
	pthread_mutex_init(&s->lock, NULL);
	if (sqlite3_open_v2(path, &s->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX, NULL) !=
	    SQLITE_OK) {
		snprintf(err, errlen, "store: %s: %s", path, s->db ? sqlite3_errmsg(s->db) : "cannot open");
		vmac_store_close(s);
		return -EIO;
	}
	sqlite3_busy_timeout(s->db, BUSY_MS);
	if (strcmp(path, ":memory:") != 0) {
		struct stat st;
		if (stat(path, &st) != 0) {
			snprintf(err, errlen, "store: %s: %s", path, strerror(errno));
			vmac_store_close(s);
			return -EIO;
		}
		snprintf(s->path, sizeof(s->path), "%s", path);
		s->dev = st.st_dev;
		s->ino = st.st_ino;
	}
	/* WAL: readers never wait for the writer; synchronous FULL: a commit
	 * that returned is on the disk, power loss included. A page cache of
	 * 512 KiB, not SQLite's 2 MiB: the store mostly appends, its reads are
	 * rare and small, and the operating system caches the file anyway; the
	 * default made vmacd's memory grow with the database for half an hour
	 * (docs/RELIABILITY.md, "Soak"). */
	if (exec(s, "PRAGMA journal_mode = WAL", err, errlen) != 0 ||
	    exec(s, "PRAGMA synchronous = FULL", err, errlen) != 0 ||
	    exec(s, "PRAGMA cache_size = -512", err, errlen) != 0 || migrate(s, err, errlen) != 0) {
		char why[512];
		snprintf(why, sizeof(why), "%s", err);
		snprintf(err, errlen, "%s (database %s)", why, path);
		vmac_store_close(s);
		return -EIO;
	}
	*out = s;
	return 0;
}

int vmac_store_open(const char *dir, struct vmac_store **out, char *err, size_t errlen)
{
	char path[4096];
	*out = NULL;
	if (sodium_init() < 0) {
		snprintf(err, errlen, "store: libsodium cannot start");
		return -EIO;
	}
	if (snprintf(path, sizeof(path), "%s/vmac.db", dir) >= (int)sizeof(path)) {
		snprintf(err, errlen, "store: state folder path too long");
		return -ENAMETOOLONG;
	}
	if (mkdir(dir, 0700) != 0 && errno != EEXIST) {
		int e = errno;
		snprintf(err, errlen, "store: cannot create the state folder %s: %s (choose one with --state DIR)", dir,
		         strerror(e));
		return -e;
	}
	return open_at(path, out, err, errlen);
}

int vmac_store_open_memory(struct vmac_store **out, char *err, size_t errlen)
{
	*out = NULL;
	if (sodium_init() < 0) {
		snprintf(err, errlen, "store: libsodium cannot start");
		return -EIO;
	}
	return open_at(":memory:", out, err, errlen);
}

void vmac_store_close(struct vmac_store *s)
{
	if (!s)
		return;
	sqlite3_finalize(s->data_version_st);
	sqlite3_close(s->db);
	pthread_mutex_destroy(&s->lock);
	free(s);
}

void vmac_store_stats(struct vmac_store *s, struct vmac_store_stats *out)
{
	char wal[sizeof(s->path) + 8];
	struct stat st;
	int i;
	memset(out, 0, sizeof(*out));
	for (i = 0; i < VMAC_STORE_FAILURE_KINDS; i++)
		out->failures[i] = atomic_load(&s->failures[i]);
	if (!s->path[0])
		return; /* in memory */
	if (stat(s->path, &st) == 0)
		out->database_bytes = (uint64_t)st.st_size;
	snprintf(wal, sizeof(wal), "%s-wal", s->path);
	if (stat(wal, &st) == 0)
		out->wal_bytes = (uint64_t)st.st_size;
}

void store_hex(const unsigned char *b, size_t n, char *out)
{
	static const char digits[] = "0123456789abcdef";
	size_t i;
	for (i = 0; i < n; i++) {
		out[2 * i] = digits[b[i] >> 4];
		out[2 * i + 1] = digits[b[i] & 15];
	}
	out[2 * n] = 0;
}

/* ---- driver versions ---- */

#define VERSION_COLUMNS                                                                                                \
	"id, driver, version, hash, deployed, deployed_by, state, previous, note, size, counter, signer, "             \
	"origin"
#define VERSION_NCOLUMNS 13

void store_text_col(sqlite3_stmt *st, int i, char *out, size_t len)
{
	const unsigned char *t = sqlite3_column_text(st, i);
	snprintf(out, len, "%s", t ? (const char *)t : "");
}

static void version_row(sqlite3_stmt *st, struct vmac_driver_version *v)
{
	memset(v, 0, sizeof(*v));
	v->id = sqlite3_column_int64(st, 0);
	store_text_col(st, 1, v->driver, sizeof(v->driver));
	store_text_col(st, 2, v->version, sizeof(v->version));
	store_text_col(st, 3, v->hash, sizeof(v->hash));
	v->deployed = sqlite3_column_double(st, 4);
	store_text_col(st, 5, v->deployed_by, sizeof(v->deployed_by));
	store_text_col(st, 6, v->state, sizeof(v->state));
	v->previous = sqlite3_column_int64(st, 7);
	store_text_col(st, 8, v->note, sizeof(v->note));
	v->size = (size_t)sqlite3_column_int64(st, 9);
	v->counter = (uint64_t)sqlite3_column_int64(st, 10);
	store_text_col(st, 11, v->signer, sizeof(v->signer));
	store_text_col(st, 12, v->origin, sizeof(v->origin));
}

/* The active version's id of driver (0: none, the file runs); -1 on error. */
static int64_t active_id(struct vmac_store *s, const char *driver)
{
	sqlite3_stmt *st;
	int64_t id = 0;
	int rc;
	if (sqlite3_prepare_v2(s->db, "SELECT id FROM driver_versions WHERE driver = ? AND state = 'active'", -1, &st,
	                       NULL) != SQLITE_OK)
		return -1;
	sqlite3_bind_text(st, 1, driver, -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	if (rc == SQLITE_ROW)
		id = sqlite3_column_int64(st, 0);
	sqlite3_finalize(st);
	return rc == SQLITE_ROW || rc == SQLITE_DONE ? id : -1;
}

int vmac_store_driver_add(struct vmac_store *s, const struct vmac_driver_upload *u, int64_t *id, char *err,
                          size_t errlen)
{
	unsigned char h[32];
	char hash[65];
	sqlite3_stmt *st;
	int64_t prev;
	int rc;
	crypto_generichash(h, sizeof(h), (const unsigned char *)u->data, u->len, NULL, 0);
	store_hex(h, sizeof(h), hash);
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "storing a driver version", err, errlen);
	prev = active_id(s, u->driver);
	if (prev < 0 || sqlite3_prepare_v2(
	                    s->db,
	                    "INSERT INTO driver_versions (driver, version, hash, source, size, deployed, deployed_by, "
	                    "state, previous, counter, signer, origin, note) "
	                    "VALUES (?, ?, ?, x'', ?, ?, ?, 'pending', ?, ?, ?, ?, ?)",
	                    -1, &st, NULL) != SQLITE_OK)
		return store_end(s, 0, "storing a driver version", err, errlen);
	sqlite3_bind_text(st, 1, u->driver, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 2, u->version, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 3, hash, -1, SQLITE_TRANSIENT);
	sqlite3_bind_int64(st, 4, (sqlite3_int64)u->len);
	sqlite3_bind_double(st, 5, store_now_s());
	sqlite3_bind_text(st, 6, u->by, -1, SQLITE_TRANSIENT);
	sqlite3_bind_int64(st, 7, prev);
	sqlite3_bind_int64(st, 8, (sqlite3_int64)u->counter);
	sqlite3_bind_text(st, 9, u->signer ? u->signer : "", -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 10, u->origin ? u->origin : "upload", -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 11, u->note ? u->note : "", -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_end(s, 0, "storing a driver version", err, errlen);
	*id = sqlite3_last_insert_rowid(s->db); /* of this statement: no other ran since */
	if (sqlite3_prepare_v2(s->db, "INSERT INTO driver_bundles (id, data) VALUES (?, ?)", -1, &st, NULL) !=
	    SQLITE_OK)
		return store_end(s, 0, "storing a driver version", err, errlen);
	sqlite3_bind_int64(st, 1, *id);
	sqlite3_bind_blob(st, 2, u->data, (int)u->len, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	return store_end(s, rc == SQLITE_DONE, "storing a driver version", err, errlen);
}

int vmac_store_driver_counter(struct vmac_store *s, const char *driver, uint64_t *max, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc;
	*max = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db,
	                       "SELECT max(counter) FROM driver_versions WHERE driver = ? AND state IN "
	                       "('active', 'replaced', 'rolled_back')",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading driver versions", err, errlen);
	sqlite3_bind_text(st, 1, driver, -1, SQLITE_TRANSIENT);
	rc = sqlite3_step(st);
	if (rc == SQLITE_ROW)
		*max = (uint64_t)sqlite3_column_int64(st, 0); /* NULL (none) reads 0 */
	sqlite3_finalize(st);
	if (rc != SQLITE_ROW)
		return store_fail_unlock(s, "reading driver versions", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return 0;
}

/* UPDATE driver_versions SET state = ?, note = ? WHERE id = ? */
static int set_state(struct vmac_store *s, int64_t id, const char *state, const char *note)
{
	sqlite3_stmt *st;
	int rc;
	if (sqlite3_prepare_v2(s->db,
	                       note ? "UPDATE driver_versions SET state = ?, note = ? WHERE id = ?"
	                            : "UPDATE driver_versions SET state = ? WHERE id = ?",
	                       -1, &st, NULL) != SQLITE_OK)
		return -1;
	sqlite3_bind_text(st, 1, state, -1, SQLITE_TRANSIENT);
	if (note) {
		sqlite3_bind_text(st, 2, note, (int)strnlen(note, 400), SQLITE_TRANSIENT);
		sqlite3_bind_int64(st, 3, id);
	} else {
		sqlite3_bind_int64(st, 2, id);
	}
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	return rc == SQLITE_DONE ? 0 : -1;
}

int store_lock_write(struct vmac_store *s)
{
	struct stat now;
	pthread_mutex_lock(&s->lock);
	if (!s->path[0])
		return 0;
	if (!s->gone && (stat(s->path, &now) != 0 || now.st_dev != s->dev || now.st_ino != s->ino))
		s->gone = 1;
	return s->gone ? -1 : 0;
}

/* Take the lock and open a write transaction: 0, or -1 still holding the
 * lock (the caller says why with fail_unlock). */
int store_begin(struct vmac_store *s)
{
	if (store_lock_write(s) != 0)
		return -1;
	return sqlite3_exec(s->db, "BEGIN IMMEDIATE", NULL, NULL, NULL) == SQLITE_OK ? 0 : -1;
}

/* Commit when ok, else roll back; let the other threads in. 0, or < 0
 * with err. */
int store_end(struct vmac_store *s, int ok, const char *what, char *err, size_t errlen)
{
	int rc;
	if (ok && sqlite3_exec(s->db, "COMMIT", NULL, NULL, NULL) == SQLITE_OK) {
		pthread_mutex_unlock(&s->lock);
		return 0;
	}
	rc = store_fail(s, what, err, errlen); /* before the ROLLBACK: SQLite's why is the failed statement's */
	sqlite3_exec(s->db, "ROLLBACK", NULL, NULL, NULL);
	pthread_mutex_unlock(&s->lock);
	return rc;
}

int vmac_store_driver_activate(struct vmac_store *s, const char *driver, int64_t id, char *err, size_t errlen)
{
	int64_t prev;
	int ok;
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "activating a driver version", err, errlen);
	prev = active_id(s, driver);
	ok = prev >= 0 && (prev == 0 || prev == id || set_state(s, prev, "replaced", NULL) == 0) &&
	     set_state(s, id, "active", NULL) == 0;
	return store_end(s, ok, "activating a driver version", err, errlen);
}

int vmac_store_driver_refuse(struct vmac_store *s, int64_t id, const char *why, char *err, size_t errlen)
{
	if (store_lock_write(s) != 0 || set_state(s, id, "refused", why) != 0)
		return store_fail_unlock(s, "marking a driver version refused", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return 0;
}

int vmac_store_driver_roll_back(struct vmac_store *s, const char *driver, int64_t id, const char *why, char *err,
                                size_t errlen)
{
	sqlite3_stmt *st;
	int64_t prev = 0;
	int ok, rc;
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "rolling back a driver version", err, errlen);
	if (active_id(s, driver) != id) { /* already rolled back, or replaced meanwhile */
		store_end(s, 1, "", err, errlen);
		return 1;
	}
	ok = sqlite3_prepare_v2(s->db, "SELECT previous FROM driver_versions WHERE id = ?", -1, &st, NULL) == SQLITE_OK;
	if (ok) {
		sqlite3_bind_int64(st, 1, id);
		rc = sqlite3_step(st);
		if (rc == SQLITE_ROW)
			prev = sqlite3_column_int64(st, 0);
		sqlite3_finalize(st);
		ok = rc == SQLITE_ROW;
	}
	ok = ok && set_state(s, id, "rolled_back", why) == 0 && (prev == 0 || set_state(s, prev, "active", NULL) == 0);
	return store_end(s, ok, "rolling back a driver version", err, errlen);
}

/* One version by a WHERE clause with one parameter; with its source when
 * src is not NULL. 1 found, 0 none, -1 err. */
static int version_where(struct vmac_store *s, const char *where, const char *text_arg, int64_t int_arg,
                         struct vmac_driver_version *v, char **src, size_t *len, char *err, size_t errlen)
{
	char sql[512];
	sqlite3_stmt *st;
	int rc, found = 0;
	snprintf(sql, sizeof(sql), "SELECT " VERSION_COLUMNS "%s FROM driver_versions WHERE %s",
	         src ? ", (SELECT data FROM driver_bundles b WHERE b.id = driver_versions.id)" : "", where);
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, sql, -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading driver versions", err, errlen);
	if (text_arg)
		sqlite3_bind_text(st, 1, text_arg, -1, SQLITE_TRANSIENT);
	else
		sqlite3_bind_int64(st, 1, int_arg);
	rc = sqlite3_step(st);
	if (rc == SQLITE_ROW) {
		found = 1;
		version_row(st, v);
		if (src) {
			*len = (size_t)sqlite3_column_bytes(st, VERSION_NCOLUMNS);
			*src = malloc(*len + 1);
			if (*src) {
				if (*len)
					memcpy(*src, sqlite3_column_blob(st, VERSION_NCOLUMNS), *len);
				(*src)[*len] = 0;
			} else {
				found = -1;
			}
		}
	}
	sqlite3_finalize(st);
	if (found < 0) {
		pthread_mutex_unlock(&s->lock);
		snprintf(err, errlen, "store: out of memory");
		return -1;
	}
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_fail_unlock(s, "reading driver versions", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return found;
}

int vmac_store_driver_active(struct vmac_store *s, const char *driver, struct vmac_driver_version *v, char **src,
                             size_t *len, char *err, size_t errlen)
{
	return version_where(s, "driver = ? AND state = 'active'", driver, 0, v, src, len, err, errlen);
}

int vmac_store_driver_get(struct vmac_store *s, int64_t id, struct vmac_driver_version *v, char **src, size_t *len,
                          char *err, size_t errlen)
{
	return version_where(s, "id = ?", NULL, id, v, src, len, err, errlen);
}

int vmac_store_driver_list(struct vmac_store *s, const char *driver,
                           void (*fn)(void *ctx, const struct vmac_driver_version *v), void *ctx, char *err,
                           size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db,
	                       driver ? "SELECT " VERSION_COLUMNS " FROM driver_versions WHERE driver = ? ORDER BY id"
	                              : "SELECT " VERSION_COLUMNS " FROM driver_versions ORDER BY driver, id",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "listing driver versions", err, errlen);
	if (driver)
		sqlite3_bind_text(st, 1, driver, -1, SQLITE_TRANSIENT);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_driver_version v;
		version_row(st, &v);
		fn(ctx, &v);
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "listing driver versions", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}

/* ---- persisted parameters ---- */

int vmac_store_param_set(struct vmac_store *s, const char *machine, const char *name, const struct vmac_value *v,
                         char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc;
	if (store_lock_write(s) != 0 ||
	    sqlite3_prepare_v2(s->db,
	                       "INSERT OR REPLACE INTO params (machine, name, type, number, string, updated) "
	                       "VALUES (?, ?, ?, ?, ?, ?)",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "persisting a param", err, errlen);
	sqlite3_bind_text(st, 1, machine, -1, SQLITE_TRANSIENT);
	sqlite3_bind_text(st, 2, name, -1, SQLITE_TRANSIENT);
	sqlite3_bind_int(st, 3, (int)v->type);
	sqlite3_bind_double(st, 4, v->type == VMAC_VALUE_STRING ? 0 : v->number);
	sqlite3_bind_text(st, 5, v->type == VMAC_VALUE_STRING ? v->str : "", -1, SQLITE_TRANSIENT);
	sqlite3_bind_double(st, 6, store_now_s());
	rc = sqlite3_step(st);
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "persisting a param", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return 0;
}

int vmac_store_param_list(struct vmac_store *s, const char *machine,
                          void (*fn)(void *ctx, const char *name, const struct vmac_value *v), void *ctx, char *err,
                          size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT name, type, number, string FROM params WHERE machine = ? ORDER BY name",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading persisted params", err, errlen);
	sqlite3_bind_text(st, 1, machine, -1, SQLITE_TRANSIENT);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_value v;
		char name[64];
		memset(&v, 0, sizeof(v));
		store_text_col(st, 0, name, sizeof(name));
		v.type = (enum vmac_value_type)sqlite3_column_int(st, 1);
		v.number = sqlite3_column_double(st, 2);
		store_text_col(st, 3, v.str, sizeof(v.str));
		fn(ctx, name, &v);
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "reading persisted params", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}

/* ---- the event log ---- */

int vmac_store_events_add(struct vmac_store *s, const struct vmac_stored_event *ev, int n, char *err, size_t errlen)
{
	sqlite3_stmt *st = NULL;
	int i, ok;
	if (n <= 0)
		return 0;
	if (store_begin(s) != 0)
		return store_fail_unlock(s, "recording events", err, errlen);
	ok = sqlite3_prepare_v2(s->db,
	                        "INSERT OR REPLACE INTO events (seq, time, kind, device, text) VALUES (?, ?, ?, ?, ?)",
	                        -1, &st, NULL) == SQLITE_OK;
	for (i = 0; ok && i < n; i++) {
		sqlite3_reset(st);
		sqlite3_bind_int64(st, 1, (sqlite3_int64)ev[i].seq);
		sqlite3_bind_double(st, 2, ev[i].time);
		sqlite3_bind_text(st, 3, ev[i].kind, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 4, ev[i].device, -1, SQLITE_TRANSIENT);
		sqlite3_bind_text(st, 5, ev[i].text, -1, SQLITE_TRANSIENT);
		ok = sqlite3_step(st) == SQLITE_DONE;
	}
	sqlite3_finalize(st);
	if (ok && ev[n - 1].seq > VMAC_STORE_EVENTS && ev[n - 1].seq % 100 < (uint64_t)n) { /* now and then */
		char sql[96];
		snprintf(sql, sizeof(sql), "DELETE FROM events WHERE seq <= %llu",
		         (unsigned long long)(ev[n - 1].seq - VMAC_STORE_EVENTS));
		ok = sqlite3_exec(s->db, sql, NULL, NULL, NULL) == SQLITE_OK;
	}
	return store_end(s, ok, "recording events", err, errlen);
}

int vmac_store_events_last(struct vmac_store *s, uint64_t *seq, char *err, size_t errlen)
{
	sqlite3_stmt *st;
	int rc;
	*seq = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db, "SELECT max(seq) FROM events", -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading the event log", err, errlen);
	rc = sqlite3_step(st);
	if (rc == SQLITE_ROW && sqlite3_column_type(st, 0) != SQLITE_NULL)
		*seq = (uint64_t)sqlite3_column_int64(st, 0);
	sqlite3_finalize(st);
	if (rc != SQLITE_ROW)
		return store_fail_unlock(s, "reading the event log", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return 0;
}

int vmac_store_events_list(struct vmac_store *s, uint64_t after, int limit,
                           void (*fn)(void *ctx, const struct vmac_stored_event *e), void *ctx, char *err,
                           size_t errlen)
{
	sqlite3_stmt *st;
	int rc, n = 0;
	pthread_mutex_lock(&s->lock);
	if (sqlite3_prepare_v2(s->db,
	                       "SELECT seq, time, kind, device, text FROM events WHERE seq > ? ORDER BY seq LIMIT ?",
	                       -1, &st, NULL) != SQLITE_OK)
		return store_fail_unlock(s, "reading the event log", err, errlen);
	sqlite3_bind_int64(st, 1, (sqlite3_int64)after);
	sqlite3_bind_int(st, 2, limit);
	while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
		struct vmac_stored_event e;
		e.seq = (uint64_t)sqlite3_column_int64(st, 0);
		e.time = sqlite3_column_double(st, 1);
		e.kind = (const char *)sqlite3_column_text(st, 2);
		e.device = (const char *)sqlite3_column_text(st, 3);
		e.text = (const char *)sqlite3_column_text(st, 4);
		fn(ctx, &e);
		n++;
	}
	sqlite3_finalize(st);
	if (rc != SQLITE_DONE)
		return store_fail_unlock(s, "reading the event log", err, errlen);
	pthread_mutex_unlock(&s->lock);
	return n;
}
