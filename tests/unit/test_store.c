/* Unit tests of the store (core/store): tokens are created with the scope
 * asked for, checked by hash, refused when malformed, altered, unknown or
 * revoked, listed without their secrets, and kept across a reopen; two
 * threads using every function at once on the one connection get the
 * answers each would get alone; a full disk is told by its own code;
 * tokens have names, and what `vmac token` changes waits in the audit
 * outbox for the host. */
#include <check.h>
#include <errno.h>
#include <pthread.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../core/store/store.h"
#include "check_main.h"

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
	ck_assert_msg(vmac_token_create(store, scope, NULL, "test", NULL, token, id, err, sizeof(err)) == 0,
	              "create: %s", err);
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
	ck_assert_int_eq(vmac_token_revoke(store, id, NULL, err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_token_check(store, token), VMAC_SCOPE_NONE);
	ck_assert_int_eq(vmac_token_revoke(store, id, NULL, err, sizeof(err)), 1);
	ck_assert_int_eq(vmac_token_revoke(store, "0000000000000000", NULL, err, sizeof(err)), 1);

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
	ck_assert_int_eq(vmac_store_open("/nonexistent/vmac-state", &s, err, sizeof(err)), -ENOENT);
	ck_assert_msg(s == NULL, "a store was returned for a missing folder");
	ck_assert_msg(strstr(err, "/nonexistent/vmac-state") != NULL, "the error does not name the folder: %s", err);
}
END_TEST

/* ---- two threads on one store (the host's HTTP and main threads) ----
 * Each round of a thread uses every function of the store on names of its
 * own and checks what comes back. Without the store's lock around each
 * call, the other thread's statements run in between: sqlite3_changes()
 * and sqlite3_last_insert_rowid() of the one connection then answer for
 * the other thread's statement (a revoke says "no such token", a version
 * added gets another row's id), and a statement can land inside the other
 * thread's transaction. */
#define HAMMER_ROUNDS 150

struct hammer {
	int index; /* 0 or 1: names and event numbers of this thread's own */
	int rounds;
	char problem[400]; /* the first wrong answer, "" when none */
};

static void count_token(void *ctx, const struct vmac_token_info *t)
{
	(void)t;
	++*(int *)ctx;
}

static void count_version(void *ctx, const struct vmac_driver_version *v)
{
	(void)v;
	++*(int *)ctx;
}

static void last_param(void *ctx, const char *name, const struct vmac_value *v)
{
	(void)name;
	*(double *)ctx = v->number;
}

static void count_event(void *ctx, const struct vmac_stored_event *e)
{
	(void)e;
	++*(int *)ctx;
}

#define HAMMER_CHECK(cond, ...)                                                                                        \
	do {                                                                                                           \
		if (!(cond)) {                                                                                         \
			snprintf(h->problem, sizeof(h->problem), __VA_ARGS__);                                         \
			return NULL;                                                                                   \
		}                                                                                                      \
	} while (0)

static void *hammer(void *arg)
{
	struct hammer *h = arg;
	char token[VMAC_TOKEN_LEN + 1], id[VMAC_TOKEN_ID_LEN + 1], err[512] = "", driver[16], machine[16], version[32],
	                                                           src[64];
	int i;
	snprintf(driver, sizeof(driver), "drv%d", h->index);
	snprintf(machine, sizeof(machine), "machine-%d", h->index);
	for (i = 0; i < HAMMER_ROUNDS; i++, h->rounds++) {
		struct vmac_driver_version v;
		struct vmac_value value;
		struct vmac_stored_event ev = {(uint64_t)(2 * i + h->index + 1), 1.0, "test", machine, "hammered"};
		char *back = NULL;
		size_t len = 0;
		int64_t vid = 0;
		int n = 0, rc;
		double got = -1;
		uint64_t last = 0;

		rc = vmac_token_create(store, VMAC_SCOPE_OPERATE, NULL, "test", NULL, token, id, err, sizeof(err));
		HAMMER_CHECK(rc == 0, "round %d: token create: %d %s", i, rc, err);
		HAMMER_CHECK(vmac_token_check(store, token) == VMAC_SCOPE_OPERATE, "round %d: a new token is refused",
		             i);
		rc = vmac_token_revoke(store, id, NULL, err, sizeof(err));
		HAMMER_CHECK(rc == 0, "round %d: revoking a valid token answered %d (%s)", i, rc, err);
		rc = vmac_token_revoke(store, id, NULL, err, sizeof(err));
		HAMMER_CHECK(rc == 1, "round %d: revoking it again answered %d, not 1 (%s)", i, rc, err);
		HAMMER_CHECK(vmac_token_check(store, token) == VMAC_SCOPE_NONE, "round %d: a revoked token is valid",
		             i);
		rc = vmac_token_list(store, count_token, &n, err, sizeof(err));
		HAMMER_CHECK(rc > i && rc == n, "round %d: token list: %d (%d seen) %s", i, rc, n, err);

		snprintf(version, sizeof(version), "1.%d.%d", h->index, i);
		snprintf(src, sizeof(src), "return {name = '%s', version = '%s'}", driver, version);
		rc = vmac_store_driver_add(
		    store, &(struct vmac_driver_upload){driver, version, src, strlen(src), 0, NULL, "test", NULL, NULL},
		    &vid, err, sizeof(err));
		HAMMER_CHECK(rc == 0, "round %d: driver add: %d %s", i, rc, err);
		rc = vmac_store_driver_get(store, vid, &v, &back, &len, err, sizeof(err));
		HAMMER_CHECK(rc == 1 && strcmp(v.driver, driver) == 0 && strcmp(v.version, version) == 0 && back &&
		                 strcmp(back, src) == 0,
		             "round %d: version %s of %s was stored as id %lld, which holds %d %s %s", i, version,
		             driver, (long long)vid, rc, rc == 1 ? v.driver : "-", rc == 1 ? v.version : err);
		free(back);
		rc = vmac_store_driver_activate(store, driver, vid, err, sizeof(err));
		HAMMER_CHECK(rc == 0, "round %d: activate: %d %s", i, rc, err);
		rc = vmac_store_driver_active(store, driver, &v, NULL, NULL, err, sizeof(err));
		HAMMER_CHECK(rc == 1 && v.id == vid, "round %d: the active version is %d %lld, not %lld", i, rc,
		             (long long)v.id, (long long)vid);
		n = 0;
		rc = vmac_store_driver_list(store, driver, count_version, &n, err, sizeof(err));
		HAMMER_CHECK(rc == i + 1 && n == i + 1, "round %d: %s has %d versions listed (%d seen) %s", i, driver,
		             rc, n, err);
		if (i % 3 == 2) {
			rc = vmac_store_driver_roll_back(store, driver, vid, "test", err, sizeof(err));
			HAMMER_CHECK(rc == 0, "round %d: roll back: %d %s", i, rc, err);
		} else if (i % 3 == 1) {
			rc = vmac_store_driver_refuse(store, vid, "test", err, sizeof(err));
			HAMMER_CHECK(rc == 0, "round %d: refuse: %d %s", i, rc, err);
		}

		memset(&value, 0, sizeof(value));
		value.type = VMAC_VALUE_NUMBER;
		value.number = i;
		rc = vmac_store_param_set(store, machine, "count", &value, err, sizeof(err));
		HAMMER_CHECK(rc == 0, "round %d: param set: %d %s", i, rc, err);
		rc = vmac_store_param_list(store, machine, last_param, &got, err, sizeof(err));
		HAMMER_CHECK(rc == 1 && got == i, "round %d: param list: %d, value %g", i, rc, got);

		rc = vmac_store_events_add(store, &ev, 1, err, sizeof(err));
		HAMMER_CHECK(rc == 0, "round %d: events add: %d %s", i, rc, err);
		rc = vmac_store_events_last(store, &last, err, sizeof(err));
		HAMMER_CHECK(rc == 0 && last >= ev.seq, "round %d: events last: %d, %llu", i, rc,
		             (unsigned long long)last);
		n = 0;
		rc = vmac_store_events_list(store, ev.seq - 1, 1, count_event, &n, err, sizeof(err));
		HAMMER_CHECK(rc == 1 && n == 1, "round %d: events list: %d %s", i, rc, err);
	}
	return NULL;
}

START_TEST(two_threads_at_once_get_their_own_answers)
{
	struct hammer h[2];
	pthread_t th[2];
	int i;
	memset(h, 0, sizeof(h));
	for (i = 0; i < 2; i++) {
		h[i].index = i;
		ck_assert_int_eq(pthread_create(&th[i], NULL, hammer, &h[i]), 0);
	}
	for (i = 0; i < 2; i++)
		pthread_join(th[i], NULL);
	for (i = 0; i < 2; i++)
		ck_assert_msg(h[i].problem[0] == 0, "thread %d, after %d good rounds: %s", i, h[i].rounds,
		              h[i].problem);
	ck_assert_int_eq(h[0].rounds + h[1].rounds, 2 * HAMMER_ROUNDS);
}
END_TEST

/* ---- a full disk ----
 * A VFS in front of SQLite's own that, while disk_full is set, fails every
 * write with SQLITE_FULL, as a file system with no space left does (the
 * store opens its database through the default VFS). */
static sqlite3_vfs *real_vfs, full_vfs;
static sqlite3_io_methods full_methods;
static int disk_full; /* 1: writes fail with SQLITE_FULL; 2: with SQLITE_IOERR_WRITE */

struct full_file {
	sqlite3_file base;
	sqlite3_file *real; /* SQLite's own file, right after this struct */
};

#define REAL(f) (((struct full_file *)(f))->real)

static int full_close(sqlite3_file *f)
{
	return REAL(f)->pMethods->xClose(REAL(f));
}
static int full_read(sqlite3_file *f, void *buf, int n, sqlite3_int64 off)
{
	return REAL(f)->pMethods->xRead(REAL(f), buf, n, off);
}
static int full_write(sqlite3_file *f, const void *buf, int n, sqlite3_int64 off)
{
	return disk_full == 1 ? SQLITE_FULL
	       : disk_full    ? SQLITE_IOERR_WRITE
	                      : REAL(f)->pMethods->xWrite(REAL(f), buf, n, off);
}
static int full_truncate(sqlite3_file *f, sqlite3_int64 size)
{
	return REAL(f)->pMethods->xTruncate(REAL(f), size);
}
static int full_sync(sqlite3_file *f, int flags)
{
	return REAL(f)->pMethods->xSync(REAL(f), flags);
}
static int full_size(sqlite3_file *f, sqlite3_int64 *size)
{
	return REAL(f)->pMethods->xFileSize(REAL(f), size);
}
static int full_lock(sqlite3_file *f, int level)
{
	return REAL(f)->pMethods->xLock(REAL(f), level);
}
static int full_unlock(sqlite3_file *f, int level)
{
	return REAL(f)->pMethods->xUnlock(REAL(f), level);
}
static int full_reserved(sqlite3_file *f, int *out)
{
	return REAL(f)->pMethods->xCheckReservedLock(REAL(f), out);
}
static int full_control(sqlite3_file *f, int op, void *arg)
{
	return REAL(f)->pMethods->xFileControl(REAL(f), op, arg);
}
static int full_sector(sqlite3_file *f)
{
	return REAL(f)->pMethods->xSectorSize(REAL(f));
}
static int full_device(sqlite3_file *f)
{
	return REAL(f)->pMethods->xDeviceCharacteristics(REAL(f));
}
static int full_shm_map(sqlite3_file *f, int page, int size, int extend, void volatile **out)
{
	return REAL(f)->pMethods->xShmMap(REAL(f), page, size, extend, out);
}
static int full_shm_lock(sqlite3_file *f, int offset, int n, int flags)
{
	return REAL(f)->pMethods->xShmLock(REAL(f), offset, n, flags);
}
static void full_shm_barrier(sqlite3_file *f)
{
	REAL(f)->pMethods->xShmBarrier(REAL(f));
}
static int full_shm_unmap(sqlite3_file *f, int delete_flag)
{
	return REAL(f)->pMethods->xShmUnmap(REAL(f), delete_flag);
}

static int full_open(sqlite3_vfs *vfs, const char *name, sqlite3_file *f, int flags, int *out_flags)
{
	struct full_file *ff = (struct full_file *)f;
	int rc;
	(void)vfs;
	ff->real = (sqlite3_file *)&ff[1];
	rc = real_vfs->xOpen(real_vfs, name, ff->real, flags, out_flags);
	/* SQLite calls xClose only when pMethods is set: only on success. */
	ff->base.pMethods = rc == SQLITE_OK && ff->real->pMethods ? &full_methods : NULL;
	return rc;
}

/* full_vfs, the default from now on (in this test's own process). */
static void install_full_vfs(void)
{
	real_vfs = sqlite3_vfs_find(NULL);
	ck_assert_msg(real_vfs != NULL, "no default VFS");
	full_vfs = *real_vfs;
	full_vfs.zName = "vmac-full-disk";
	full_vfs.szOsFile = (int)sizeof(struct full_file) + real_vfs->szOsFile;
	full_vfs.xOpen = full_open;
	full_methods = (sqlite3_io_methods){
	    2,           full_close,   full_read,     full_write,       full_truncate,  full_sync,
	    full_size,   full_lock,    full_unlock,   full_reserved,    full_control,   full_sector,
	    full_device, full_shm_map, full_shm_lock, full_shm_barrier, full_shm_unmap, NULL,
	    NULL};
	ck_assert_int_eq(sqlite3_vfs_register(&full_vfs, 1), SQLITE_OK);
}

struct rows;
static int outbox_rows(struct rows *x);

START_TEST(a_full_disk_is_told_by_its_own_code)
{
	char token[VMAC_TOKEN_LEN + 1], err[512] = "";
	const char *src = "return {name = 'drv', version = '1.0.0'}";
	struct vmac_value value;
	struct vmac_stored_event ev = {1, 1.0, "test", "machine-1", "full"};
	int64_t id = 0;
	int rc;
	vmac_store_close(store); /* open again through the VFS that can fill up */
	install_full_vfs();
	ck_assert_msg(vmac_store_open(dir, &store, err, sizeof(err)) == 0, "reopen failed: %s", err);
	memset(&value, 0, sizeof(value));
	value.type = VMAC_VALUE_NUMBER;

	disk_full = 1;
	rc = vmac_store_driver_add(
	    store, &(struct vmac_driver_upload){"drv", "1.0.0", src, strlen(src), 0, NULL, "test", NULL, NULL}, &id,
	    err, sizeof(err));
	ck_assert_msg(rc == -VMAC_ESTOREFULL && strstr(err, "full"), "a version added to a full disk: %d %s", rc, err);
	rc = vmac_store_param_set(store, "machine-1", "count", &value, err, sizeof(err));
	ck_assert_msg(rc == -VMAC_ESTOREFULL, "a param persisted to a full disk: %d %s", rc, err);
	rc =
	    vmac_token_create(store, VMAC_SCOPE_READ, "x", "test", "user \"t\" (uid 1)", token, NULL, err, sizeof(err));
	ck_assert_msg(rc == -VMAC_ESTOREFULL, "a token created on a full disk: %d %s", rc, err);
	ck_assert_msg(outbox_rows(NULL) == 0, "a token refused by a full disk is in the audit outbox");
	rc = vmac_store_events_add(store, &ev, 1, err, sizeof(err));
	ck_assert_msg(rc == -VMAC_ESTOREFULL, "events added on a full disk: %d %s", rc, err);
	ck_assert_str_eq(vmac_strerror(rc), "the store's disk is full");

	disk_full = 0; /* space again: the same writes go through */
	rc = vmac_store_driver_add(
	    store, &(struct vmac_driver_upload){"drv", "1.0.0", src, strlen(src), 0, NULL, "test", NULL, NULL}, &id,
	    err, sizeof(err));
	ck_assert_msg(rc == 0, "a version added once there is space: %d %s", rc, err);
	rc = vmac_store_driver_activate(store, "drv", id, err, sizeof(err));
	ck_assert_msg(rc == 0, "activating once there is space: %d %s", rc, err);
	rc = vmac_store_param_set(store, "machine-1", "count", &value, err, sizeof(err));
	ck_assert_msg(rc == 0, "a param persisted once there is space: %d %s", rc, err);

	disk_full = 2; /* a write that fails otherwise (an I/O error) is not a full disk */
	rc = vmac_store_param_set(store, "machine-1", "count", &value, err, sizeof(err));
	ck_assert_msg(rc == -VMAC_ESTORE, "a param persisted on a failing disk: %d %s", rc, err);
	disk_full = 0;
}
END_TEST

/* ---- token names and the audit outbox ---- */

struct rows {
	int n;
	struct vmac_audit_row r[4];
};

static void see_row(void *ctx, const struct vmac_audit_row *r)
{
	struct rows *x = ctx;
	if (x->n < 4)
		x->r[x->n] = *r;
	x->n++;
}

/* How many rows the outbox holds (with x: them). */
static int outbox_rows(struct rows *x)
{
	struct rows none;
	char err[512] = "";
	int n;
	if (!x)
		x = &none;
	memset(x, 0, sizeof(*x));
	n = vmac_store_audit_list(store, 0, 100, see_row, x, err, sizeof(err));
	ck_assert_msg(n >= 0, "listing the outbox: %s", err);
	return n;
}

static void see_name(void *ctx, const struct vmac_token_info *t)
{
	snprintf(ctx, VMAC_TOKEN_NAME_MAX + 1, "%s", t->name);
}

START_TEST(tokens_have_names_the_audit_trail_shows)
{
	char token[VMAC_TOKEN_LEN + 1], id[VMAC_TOKEN_ID_LEN + 1], err[512] = "", listed[VMAC_TOKEN_NAME_MAX + 1] = "";
	static const char *const bad[] = {"with blank", "\"quoted\"", "back\\slash",
	                                  "abcdefghijklmnopqrstuvwxyz0123456"};
	struct vmac_token_info who;
	size_t i;
	ck_assert_msg(
	    vmac_token_create(store, VMAC_SCOPE_OPERATE, "alice@panel-1", "", NULL, token, id, err, sizeof(err)) == 0,
	    "create: %s", err);
	memset(&who, 0, sizeof(who));
	ck_assert_int_eq(vmac_token_check_info(store, token, &who), VMAC_SCOPE_OPERATE);
	ck_assert_str_eq(who.name, "alice@panel-1");
	ck_assert_str_eq(who.id, id);
	ck_assert_int_eq(who.scope, VMAC_SCOPE_OPERATE);
	ck_assert_int_eq(vmac_token_list(store, see_name, listed, err, sizeof(err)), 1);
	ck_assert_str_eq(listed, "alice@panel-1");
	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		ck_assert_msg(!vmac_token_name_valid(bad[i]), "'%s' taken as a name", bad[i]);
		ck_assert_int_lt(
		    vmac_token_create(store, VMAC_SCOPE_READ, bad[i], "", NULL, token, NULL, err, sizeof(err)), 0);
	}
	ck_assert_int_eq(vmac_token_list(store, see_name, listed, err, sizeof(err)), 1);
}
END_TEST

START_TEST(token_changes_wait_in_the_audit_outbox_for_the_host)
{
	char token[VMAC_TOKEN_LEN + 1], id[VMAC_TOKEN_ID_LEN + 1], err[512] = "";
	const char *by = "user \"alice\" (uid 1000)";
	struct vmac_store *other;
	struct rows x;
	uint64_t v0 = vmac_store_audit_version(store), v1;
	int64_t last;
	ck_assert_msg(vmac_token_create(store, VMAC_SCOPE_DEPLOY, "ci", "", by, token, id, err, sizeof(err)) == 0,
	              "create: %s", err);
	ck_assert_msg(vmac_store_audit_version(store) != v0, "a row of this connection did not change the version");
	ck_assert_int_eq(vmac_token_revoke(store, id, by, err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_token_revoke(store, "0123456789abcdef", by, err, sizeof(err)), 1);
	ck_assert_int_eq(outbox_rows(&x), 3);
	ck_assert_str_eq(x.r[0].type, "token");
	ck_assert_str_eq(x.r[0].who, by);
	ck_assert_msg(strstr(x.r[0].what, "vmac token create ") && strstr(x.r[0].what, id) &&
	                  strstr(x.r[0].what, "\"ci\" (deploy)"),
	              "create said as %s", x.r[0].what);
	ck_assert_str_eq(x.r[0].result, "ok");
	ck_assert_msg(strstr(x.r[1].what, "vmac token revoke ") && strstr(x.r[1].what, "\"ci\""), "revoke said as %s",
	              x.r[1].what);
	ck_assert_str_eq(x.r[2].result, "refused");
	ck_assert_msg(strstr(x.r[2].why, "no valid token"), "a revocation refused: %s", x.r[2].why);
	ck_assert_msg(x.r[0].id < x.r[1].id && x.r[1].id < x.r[2].id && x.r[0].time > 0, "ids in order");
	last = x.r[2].id;
	ck_assert_msg(vmac_store_audit_delete(store, last, err, sizeof(err)) == 0, "delete: %s", err);
	ck_assert_int_eq(outbox_rows(NULL), 0);
	/* Another process's row (another connection): the version says so,
	 * and its id is past every id taken before, the table emptied or not. */
	v1 = vmac_store_audit_version(store);
	ck_assert_msg(vmac_store_open(dir, &other, err, sizeof(err)) == 0, "second connection: %s", err);
	ck_assert_msg(vmac_token_create(other, VMAC_SCOPE_READ, NULL, "", by, token, NULL, err, sizeof(err)) == 0, "%s",
	              err);
	vmac_store_close(other);
	ck_assert_msg(vmac_store_audit_version(store) != v1, "another connection's row did not change the version");
	ck_assert_int_eq(outbox_rows(&x), 1);
	ck_assert_msg(x.r[0].id > last, "an id was used again after the rows were deleted: %lld <= %lld",
	              (long long)x.r[0].id, (long long)last);
	ck_assert_msg(strstr(x.r[0].what, "(read)") && !strstr(x.r[0].what, "\""), "an unnamed token: %s", x.r[0].what);
}
END_TEST

/* ---- board keys ---- */

struct seen_keys {
	int n;
	char names[4][VMAC_BOARD_NAME_MAX + 1];
	uint8_t keys[4][VMAC_BOARD_KEY_LEN];
	char fingerprints[4][VMAC_BOARD_FINGERPRINT_LEN + 1];
};

static void see_key(void *ctx, const struct vmac_board_key *k)
{
	struct seen_keys *x = ctx;
	ck_assert_int_lt(x->n, 4);
	memcpy(x->names[x->n], k->board, sizeof(x->names[0]));
	memcpy(x->keys[x->n], k->key, VMAC_BOARD_KEY_LEN);
	memcpy(x->fingerprints[x->n], k->fingerprint, sizeof(x->fingerprints[0]));
	x->n++;
}

START_TEST(board_keys_enroll_replace_and_remove)
{
	uint8_t k1[VMAC_BOARD_KEY_LEN], k2[VMAC_BOARD_KEY_LEN];
	struct seen_keys seen;
	char err[512] = "", fp[VMAC_BOARD_FINGERPRINT_LEN + 1];
	uint64_t v0 = vmac_board_keys_version(store), v1;
	memset(k1, 1, sizeof(k1));
	memset(k2, 2, sizeof(k2));
	ck_assert_msg(vmac_board_key_set(store, "lamp", k1, 0, "hall", err, sizeof(err)) == 0, "%s", err);
	v1 = vmac_board_keys_version(store);
	ck_assert_msg(v1 != v0, "enrolling did not change the keys' version");
	/* Enrolled already: kept unless replaced. */
	ck_assert_int_eq(vmac_board_key_set(store, "lamp", k2, 0, "", err, sizeof(err)), 1);
	memset(&seen, 0, sizeof(seen));
	ck_assert_int_eq(vmac_board_key_list(store, see_key, &seen, err, sizeof(err)), 1);
	ck_assert_msg(memcmp(seen.keys[0], k1, sizeof(k1)) == 0, "a key was replaced without replace");
	vmac_board_key_fingerprint(k1, fp);
	ck_assert_str_eq(seen.fingerprints[0], fp);
	ck_assert_int_eq((int)strlen(fp), VMAC_BOARD_FINGERPRINT_LEN);
	ck_assert_int_eq(vmac_board_key_set(store, "lamp", k2, 1, "", err, sizeof(err)), 0);
	memset(&seen, 0, sizeof(seen));
	vmac_board_key_list(store, see_key, &seen, err, sizeof(err));
	ck_assert_msg(memcmp(seen.keys[0], k2, sizeof(k2)) == 0, "replace did not replace the key");
	/* Names a board cannot announce are refused; nothing is stored. */
	ck_assert_int_lt(vmac_board_key_set(store, "..", k1, 0, "", err, sizeof(err)), 0);
	ck_assert_int_lt(vmac_board_key_set(store, "a.b", k1, 0, "", err, sizeof(err)), 0);
	ck_assert_int_lt(vmac_board_key_set(store, "", k1, 0, "", err, sizeof(err)), 0);
	ck_assert_int_lt(vmac_board_key_set(store, "abcdefghijklmnopqrstuvwxyz0123456", k1, 0, "", err, sizeof(err)),
	                 0);
	ck_assert_int_eq(vmac_board_key_remove(store, "lamp", err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_board_key_remove(store, "lamp", err, sizeof(err)), 1);
	ck_assert_int_eq(vmac_board_key_list(store, see_key, &seen, err, sizeof(err)), 0);
}
END_TEST

START_TEST(board_keys_many_in_one_transaction)
{
	struct vmac_board_key k[3];
	struct seen_keys seen;
	char err[512] = "";
	int kept = -1, i;
	memset(k, 0, sizeof(k));
	for (i = 0; i < 3; i++) {
		snprintf(k[i].board, sizeof(k[i].board), "g-%d", i + 1);
		memset(k[i].key, i + 1, sizeof(k[i].key));
	}
	ck_assert_msg(vmac_board_keys_set(store, k, 3, 0, &kept, err, sizeof(err)) == 0, "%s", err);
	ck_assert_int_eq(kept, 0);
	ck_assert_int_eq(vmac_board_keys_set(store, k, 3, 0, &kept, err, sizeof(err)), 0);
	ck_assert_int_eq(kept, 3);
	/* One bad name: none of them is enrolled. */
	snprintf(k[1].board, sizeof(k[1].board), "bad name");
	snprintf(k[0].board, sizeof(k[0].board), "h-1");
	ck_assert_int_lt(vmac_board_keys_set(store, k, 3, 1, &kept, err, sizeof(err)), 0);
	memset(&seen, 0, sizeof(seen));
	ck_assert_int_eq(vmac_board_key_list(store, see_key, &seen, err, sizeof(err)), 3);
	ck_assert_str_eq(seen.names[0], "g-1");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("store");
	TCase *tc = tcase_create("tokens");
	tcase_add_checked_fixture(tc, setup, teardown);
	tcase_add_test(tc, tokens_carry_their_scope);
	tcase_add_test(tc, wrong_tokens_are_refused);
	tcase_add_test(tc, revoked_tokens_stop_at_once_and_survive_a_reopen);
	tcase_add_test(tc, a_missing_folder_is_an_error);
	tcase_add_test(tc, two_threads_at_once_get_their_own_answers);
	tcase_add_test(tc, a_full_disk_is_told_by_its_own_code);
	tcase_add_test(tc, tokens_have_names_the_audit_trail_shows);
	tcase_add_test(tc, token_changes_wait_in_the_audit_outbox_for_the_host);
	tcase_add_test(tc, board_keys_enroll_replace_and_remove);
	tcase_add_test(tc, board_keys_many_in_one_transaction);
	tcase_set_timeout(tc, 60);
	suite_add_tcase(s, tc);
	return s;
}
