/* The store under kill -9 (tests/integration/test_store.py):
 *
 *   store_crash write DIR   writes forever: persisted param n.count = 1, 2,
 *                           ... and, every tenth write, a driver version
 *                           made active; prints each number once its write
 *                           has returned (acknowledged), flushed at once.
 *   store_crash check DIR N the store opens, passes SQLite's integrity
 *                           check, and holds every acknowledged write: the
 *                           count is N or N + 1 (the write that was running
 *                           when the process died may or may not be there),
 *                           and the active version is the latest one added
 *                           up to it. Exit 0, or 1 saying what is wrong. */
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/store/store.h"

static int writer(const char *dir)
{
	struct vmac_store *s;
	char err[512], src[128];
	long n;
	if (vmac_store_open(dir, &s, err, sizeof(err)) != 0) {
		fprintf(stderr, "store_crash: %s\n", err);
		return 1;
	}
	for (n = 1;; n++) {
		struct vmac_value v = {VMAC_VALUE_NUMBER, (double)n, ""};
		if (vmac_store_param_set(s, "m", "count", &v, err, sizeof(err)) != 0) {
			fprintf(stderr, "store_crash: %s\n", err);
			return 1;
		}
		if (n % 10 == 0) {
			int64_t id;
			char version[32];
			snprintf(version, sizeof(version), "%ld", n);
			snprintf(src, sizeof(src), "return { name = 'd', version = '%ld' }", n);
			if (vmac_store_driver_add(s,
			                          &(struct vmac_driver_upload){"d", version, src, strlen(src), 0, NULL,
			                                                       "crashtest", NULL, NULL},
			                          &id, err, sizeof(err)) != 0 ||
			    vmac_store_driver_activate(s, "d", id, err, sizeof(err)) != 0) {
				fprintf(stderr, "store_crash: %s\n", err);
				return 1;
			}
		}
		printf("%ld\n", n);
		fflush(stdout);
	}
}

struct found {
	double count;
	int seen;
};

static void on_param(void *ctx, const char *name, const struct vmac_value *v)
{
	struct found *f = ctx;
	if (strcmp(name, "count") == 0) {
		f->count = v->number;
		f->seen = 1;
	}
}

static int checker(const char *dir, long acked)
{
	struct vmac_store *s;
	struct vmac_driver_version v;
	struct found f = {0, 0};
	char err[512], path[4096], *msg = NULL;
	sqlite3 *db;
	sqlite3_stmt *st;
	long want_version;
	int rc;
	/* SQLite's own check first, on a plain connection. */
	snprintf(path, sizeof(path), "%s/vmac.db", dir);
	if (sqlite3_open_v2(path, &db, SQLITE_OPEN_READWRITE, NULL) != SQLITE_OK) {
		fprintf(stderr, "store_crash: cannot open %s: %s\n", path, sqlite3_errmsg(db));
		return 1;
	}
	if (sqlite3_prepare_v2(db, "PRAGMA integrity_check", -1, &st, NULL) != SQLITE_OK ||
	    sqlite3_step(st) != SQLITE_ROW || strcmp((const char *)sqlite3_column_text(st, 0), "ok") != 0) {
		fprintf(stderr, "store_crash: integrity check failed: %s\n",
		        st ? (const char *)sqlite3_column_text(st, 0) : sqlite3_errmsg(db));
		return 1;
	}
	sqlite3_finalize(st);
	sqlite3_free(msg);
	sqlite3_close(db);

	if (vmac_store_open(dir, &s, err, sizeof(err)) != 0) {
		fprintf(stderr, "store_crash: the store does not open after the kill: %s\n", err);
		return 1;
	}
	if (vmac_store_param_list(s, "m", on_param, &f, err, sizeof(err)) < 0) {
		fprintf(stderr, "store_crash: %s\n", err);
		return 1;
	}
	if (acked > 0 && (!f.seen || f.count < (double)acked || f.count > (double)acked + 1)) {
		fprintf(stderr, "store_crash: count is %g (%s), but %ld was acknowledged\n", f.count,
		        f.seen ? "stored" : "missing", acked);
		return 1;
	}
	rc = vmac_store_driver_active(s, "d", &v, NULL, NULL, err, sizeof(err));
	want_version = acked / 10 * 10;
	if (rc < 0 || (want_version > 0 && rc != 1) ||
	    (rc == 1 && (atol(v.version) < want_version || atol(v.version) > want_version + 10))) {
		fprintf(stderr, "store_crash: active driver version %s (rc %d, %s), but %ld was acknowledged\n",
		        rc == 1 ? v.version : "none", rc, rc < 0 ? err : "", want_version);
		return 1;
	}
	vmac_store_close(s);
	return 0;
}

int main(int argc, char **argv)
{
	if (argc == 3 && strcmp(argv[1], "write") == 0)
		return writer(argv[2]);
	if (argc == 4 && strcmp(argv[1], "check") == 0)
		return checker(argv[2], atol(argv[3]));
	fprintf(stderr, "usage: store_crash write DIR | store_crash check DIR ACKED\n");
	return 2;
}
