/* The store's insides, shared by its files (store.c: params, driver
 * versions, events, opening; store_token.c: access tokens and the audit
 * outbox; store_checkpoint.c: checkpoints of
 * machine state; store_recording.c: flight recordings; store_board.c:
 * board keys). The rest of the
 * host sees only store.h. */
#ifndef VMAC_STORE_INTERNAL_H
#define VMAC_STORE_INTERNAL_H

#include "store.h"

#include <pthread.h>
#include <sqlite3.h>
#include <stdatomic.h>
#include <stdint.h>
#include <sys/types.h>

struct vmac_store {
	sqlite3 *db;
	/* Held by every function below from its first statement until its
	 * error text is written: the one connection is shared by the host's
	 * threads, and what it says about the last statement
	 * (sqlite3_changes, sqlite3_last_insert_rowid, sqlite3_errmsg) or
	 * which transaction a statement joins is only true while no other
	 * thread's statement runs in between. */
	pthread_mutex_t lock;
	/* The database file as opened ("" in memory): a write first checks
	 * that it is still there, the same file (device and inode), so that a
	 * store removed or replaced under a running host stops it writing, and
	 * says why, instead of its writes going to a deleted file. */
	char path[4096];
	dev_t dev;
	ino_t ino;
	int gone;                      /* it was removed or replaced: nothing more is written */
	_Atomic uint64_t key_writes;   /* board keys written through this connection (store_board.c) */
	_Atomic uint64_t audit_writes; /* audit outbox rows written through this connection (store_token.c) */
	sqlite3_stmt *data_version_st; /* PRAGMA data_version, prepared once (store_data_version), under lock */
	_Atomic uint64_t failures[VMAC_STORE_FAILURE_KINDS]; /* every store_fail, by kind (vmac_store_stats) */
};

/* n bytes as 2n lower-case hex digits and a NUL into out. */
void store_hex(const unsigned char *b, size_t n, char *out);
/* Unix time now. */
double store_now_s(void);
/* err says what failed and SQLite's why; returns the code of it. */
int store_fail(struct vmac_store *s, const char *what, char *err, size_t errlen);
/* store_fail(), then let the other threads in. */
int store_fail_unlock(struct vmac_store *s, const char *what, char *err, size_t errlen);
/* Column i of a row as text into out. */
void store_text_col(sqlite3_stmt *st, int i, char *out, size_t len);
/* Take the lock for a write: 0, or -1 still holding it when the database
 * file was removed or replaced (store_fail says so). */
int store_lock_write(struct vmac_store *s);
/* Take the lock and open a write transaction: 0, or -1 still holding the lock. */
int store_begin(struct vmac_store *s);
/* Commit when ok, else roll back; let the other threads in. 0, or < 0 with err. */
int store_end(struct vmac_store *s, int ok, const char *what, char *err, size_t errlen);
/* SQLite's data_version: it changes with every commit of another
 * connection to the database (store_board.c; the board keys and the audit
 * outbox are looked at again when it does). */
uint64_t store_data_version(struct vmac_store *s);

#endif
