/* The host's persistent store: one SQLite database in write-ahead-log mode,
 * STATE_DIR/vmac.db, shared by vmacd and the `vmac token` command (host
 * running or not). It holds the access tokens; persisted parameters, driver
 * versions and the event log come with the rest of docs/API.md's control
 * API. Never used on the bus thread: every call may touch the disk. Any
 * other thread may call any function at any time: each holds the store's
 * lock around its statements (one connection is shared).
 *
 * Tokens (docs/API.md, "Access"): "vmac_" ID "_" SECRET, ID 16 and SECRET 64
 * hex digits, both random. The store keeps the ID, the scope and a BLAKE2b
 * hash of the secret, never the secret; a check hashes what it is shown and
 * compares in constant time.
 *
 * Errors ("< 0 with err" below): -VMAC_ESTOREFULL when the disk is full
 * (SQLITE_FULL: an HTTP answer makes it 507), -VMAC_ESTORE for any other
 * failure of the database, -VMAC_EFAIL (-1) for a wrong argument or no
 * memory (core/common/errors.h); err says what, for people. */
#ifndef VMAC_STORE_H
#define VMAC_STORE_H

#include <stddef.h>
#include <stdint.h>

#include "../common/errors.h"
#include "../common/value.h"

#define VMAC_TOKEN_ID_LEN 16
#define VMAC_TOKEN_LEN (5 + VMAC_TOKEN_ID_LEN + 1 + 64) /* without the NUL */
#define VMAC_TOKEN_NOTE_MAX 120
#define VMAC_TOKEN_NAME_MAX 32

struct vmac_store;

/* What a token may do; each scope includes the ones before it. */
enum vmac_scope {
	VMAC_SCOPE_NONE = 0, /* no valid token */
	VMAC_SCOPE_READ,     /* status, devices, variables, events */
	VMAC_SCOPE_OPERATE,  /* + operator input, cycles, parameters */
	VMAC_SCOPE_DEPLOY,   /* + drivers: upload, activate, roll back */
};

const char *vmac_scope_name(enum vmac_scope scope);
/* 0, or -1 when name is not read, operate or deploy. */
int vmac_scope_parse(const char *name, enum vmac_scope *scope);

/* Open the store of state folder dir, creating the folder (mode 0700; its
 * parent must exist), the database and its tables when missing. 0, or a
 * negative errno with err. */
int vmac_store_open(const char *dir, struct vmac_store **out, char *err, size_t errlen);
/* A store of the same tables in memory, gone when closed (`vmac test`). */
int vmac_store_open_memory(struct vmac_store **out, char *err, size_t errlen);
void vmac_store_close(struct vmac_store *s);

/* What GET /metrics shows of the store: its files' sizes (0 in memory) and
 * the calls that failed since it opened, by why: the disk was full
 * (-VMAC_ESTOREFULL), the file was removed or replaced under the host, any
 * other failure of the database. Any thread; it takes no lock. */
enum vmac_store_failure { VMAC_STORE_FAILED_FULL, VMAC_STORE_FAILED_REPLACED, VMAC_STORE_FAILED_OTHER };
#define VMAC_STORE_FAILURE_KINDS 3
struct vmac_store_stats {
	uint64_t database_bytes, wal_bytes; /* vmac.db and vmac.db-wal */
	uint64_t failures[VMAC_STORE_FAILURE_KINDS];
};
void vmac_store_stats(struct vmac_store *s, struct vmac_store_stats *out);

struct vmac_token_info {
	char id[VMAC_TOKEN_ID_LEN + 1];
	char name[VMAC_TOKEN_NAME_MAX + 1]; /* who holds it (vmac token create --name); "" for none */
	enum vmac_scope scope;
	double created; /* Unix time */
	double revoked; /* Unix time, 0 while valid */
	char note[VMAC_TOKEN_NOTE_MAX + 1];
};

/* Whether name can be a token's name: 1..VMAC_TOKEN_NAME_MAX of
 * [A-Za-z0-9._@+-] (no blank, no quote: the audit trail quotes it). */
int vmac_token_name_valid(const char *name);

/* A new token of this scope, named name ("" or NULL: none; else
 * vmac_token_name_valid): writes it to token (VMAC_TOKEN_LEN + 1 bytes)
 * and its ID to id (may be NULL). by (NULL: not audited) says who made it
 * ('user "alice" (uid 1000)'): the same transaction puts a row in the
 * audit outbox (below). 0, or < 0 with err (nothing stored). */
int vmac_token_create(struct vmac_store *s, enum vmac_scope scope, const char *name, const char *note, const char *by,
                      char *token, char *id, char *err, size_t errlen);
/* Revoke by ID: 0 done, 1 no such token (or already revoked), < 0 err.
 * by as above: the outbox row says the revocation, or its refusal. */
int vmac_token_revoke(struct vmac_store *s, const char *id, const char *by, char *err, size_t errlen);
/* Every token, oldest first. Returns how many, or < 0 with err. */
int vmac_token_list(struct vmac_store *s, void (*fn)(void *ctx, const struct vmac_token_info *t), void *ctx, char *err,
                    size_t errlen);
/* The scope of a presented token: VMAC_SCOPE_NONE when malformed, unknown,
 * revoked, or when the store cannot be read. */
enum vmac_scope vmac_token_check(struct vmac_store *s, const char *token);
/* The same, and with a valid token its id, name and scope in *info (the
 * audit trail names who asked); info untouched otherwise. */
enum vmac_scope vmac_token_check_info(struct vmac_store *s, const char *token, struct vmac_token_info *info);
/* Whether token has a token's shape (vmac_ID_SECRET, hex): 0 and its ID in
 * id, or -1. Nothing is looked up. */
int vmac_token_id(const char *token, char id[VMAC_TOKEN_ID_LEN + 1]);

/* ---- the audit outbox (docs/API.md, "Audit trail"; store_token.c) ----
 * What changed the store from outside the host (`vmac token create` and
 * `revoke`, in a process of their own, host running or not) waits here
 * for the host: its main loop takes the rows into its event log as
 * `audit` events, numbered by the host (vmac_event_log), then deletes
 * them. Ids only grow (a row taken is never confused with a new one). */
struct vmac_audit_row {
	int64_t id;
	double time;     /* Unix time of the change */
	char type[16];   /* the audit event's type: "token" */
	char who[160];   /* user "alice" (uid 1000) */
	char what[320];  /* vmac token create 0123456789abcdef "alice" (operate) */
	char result[32]; /* ok, refused */
	char why[200];   /* "" or why it was refused */
};

/* One more row (id and time are set here). 0, or < 0 with err. */
int vmac_store_audit_add(struct vmac_store *s, const struct vmac_audit_row *row, char *err, size_t errlen);
/* The rows after id after, oldest first, at most limit. Returns how many,
 * or < 0 with err. */
int vmac_store_audit_list(struct vmac_store *s, int64_t after, int limit,
                          void (*fn)(void *ctx, const struct vmac_audit_row *r), void *ctx, char *err, size_t errlen);
/* Delete the rows up to id upto (taken). 0, or < 0 with err. */
int vmac_store_audit_delete(struct vmac_store *s, int64_t upto, char *err, size_t errlen);
/* A number that changes whenever the outbox may have grown, by this
 * process or another one (the store's data_version, as the board keys'
 * vmac_board_keys_version): the host looks at the rows only then. */
uint64_t vmac_store_audit_version(struct vmac_store *s);

/* ---- persisted parameters (the console's `>`; docs/API.md) ----
 * A param value per machine (its primary board's name) and param name,
 * restored into dev.params when the machine's driver loads again. */

/* Store (or replace) one value. 0, or < 0 with err (nothing changed). */
int vmac_store_param_set(struct vmac_store *s, const char *machine, const char *name, const struct vmac_value *v,
                         char *err, size_t errlen);
/* Every persisted value of machine, in name order. Returns how many, or < 0
 * with err. */
int vmac_store_param_list(struct vmac_store *s, const char *machine,
                          void (*fn)(void *ctx, const char *name, const struct vmac_value *v), void *ctx, char *err,
                          size_t errlen);

/* ---- the event log ----
 * Every event of the host, numbered as the event stream numbers them (seq
 * goes on across restarts); the newest VMAC_STORE_EVENTS are kept. */
#define VMAC_STORE_EVENTS 100000

struct vmac_stored_event {
	uint64_t seq;
	double time; /* Unix time */
	const char *kind, *device, *text;
};

/* Add n events in one transaction (one disk sync). 0, or < 0 with err. */
int vmac_store_events_add(struct vmac_store *s, const struct vmac_stored_event *ev, int n, char *err, size_t errlen);
/* The highest seq stored (0: none). 0, or < 0 with err. */
int vmac_store_events_last(struct vmac_store *s, uint64_t *seq, char *err, size_t errlen);
/* The events after seq after, oldest first, at most limit. Returns how
 * many, or < 0 with err. */
int vmac_store_events_list(struct vmac_store *s, uint64_t after, int limit,
                           void (*fn)(void *ctx, const struct vmac_stored_event *e), void *ctx, char *err,
                           size_t errlen);

/* ---- driver versions (hot reload, docs/API.md "Drivers") ----
 * Every version deployed is kept: its bundle (docs/DRIVERS.md "Bundles";
 * versions stored before bundles hold the driver's Lua text instead), a
 * BLAKE2b-256 hash of it, when, by which token (or "folder": what the
 * drivers folder held when a machine of it first loaded), its security
 * counter and signer (the minisign key id, "" unsigned), and its state:
 * pending (being put in place), active (what machines of that driver load;
 * at most one per driver; none: the folder's), replaced, rolled_back or
 * refused (with a note saying why). previous: the version that was active
 * when it came (0: none), what a rollback returns to. */
struct vmac_driver_version {
	int64_t id;
	char driver[64];
	char version[32];
	char hash[65];
	double deployed; /* Unix time */
	char deployed_by[VMAC_TOKEN_ID_LEN + 1];
	char state[16];
	int64_t previous;
	char note[400];
	size_t size; /* bytes of the bundle */
	uint64_t counter;
	char signer[17];
	char origin[12]; /* "upload", "folder" */
};

/* A version to store. */
struct vmac_driver_upload {
	const char *driver, *version;
	const char *data; /* the bundle's bytes */
	size_t len;
	uint64_t counter;
	const char *signer; /* NULL: unsigned */
	const char *by;     /* the token's id, or "folder" */
	const char *origin; /* "upload" (NULL) or "folder" */
	const char *note;   /* NULL: none */
};

/* Store a new version, state pending: 0 and *id, or < 0 with err (nothing
 * stored: e.g. the disk is full). */
int vmac_store_driver_add(struct vmac_store *s, const struct vmac_driver_upload *u, int64_t *id, char *err,
                          size_t errlen);
/* The highest security counter of driver's versions that were accepted
 * (active, replaced or rolled back): 0 (*max; 0 when none), < 0 with err. */
int vmac_store_driver_counter(struct vmac_store *s, const char *driver, uint64_t *max, char *err, size_t errlen);
/* Make version id the active one of driver (the one active before becomes
 * replaced), in one transaction. 0, or < 0 with err. */
int vmac_store_driver_activate(struct vmac_store *s, const char *driver, int64_t id, char *err, size_t errlen);
/* A version that did not take: state refused, note why. 0, or < 0 with err. */
int vmac_store_driver_refuse(struct vmac_store *s, int64_t id, const char *why, char *err, size_t errlen);
/* If version id is driver's active one: it becomes rolled_back (note why)
 * and its previous one active again (or none: the file). 0 done, 1 id was
 * not active (nothing changed), < 0 err. */
int vmac_store_driver_roll_back(struct vmac_store *s, const char *driver, int64_t id, const char *why, char *err,
                                size_t errlen);
/* driver's active version (1), or none (0: the folder's runs), or < 0 with
 * err. With src: its bundle's bytes too (or an old version's Lua text), in
 * malloc'd memory (NUL-terminated), *len. */
int vmac_store_driver_active(struct vmac_store *s, const char *driver, struct vmac_driver_version *v, char **src,
                             size_t *len, char *err, size_t errlen);
/* Version id: 1, 0 no such version, < 0 err; src as above. */
int vmac_store_driver_get(struct vmac_store *s, int64_t id, struct vmac_driver_version *v, char **src, size_t *len,
                          char *err, size_t errlen);
/* Every version of driver (NULL: of every driver), oldest first. Returns
 * how many, or < 0 with err. */
int vmac_store_driver_list(struct vmac_store *s, const char *driver,
                           void (*fn)(void *ctx, const struct vmac_driver_version *v), void *ctx, char *err,
                           size_t errlen);

/* ---- checkpoints of machine state (docs/DRIVERS.md "Recovery after a
 * restart"; store_checkpoint.c) ----
 * One per machine (its primary board's name), the newest: the encoded
 * dev.state (core/driver/checkpoint.c), the driver and version that wrote
 * it, and when (Unix time). */
struct vmac_checkpoint {
	const char *machine, *driver, *version;
	double time;
	const uint8_t *data;
	size_t len;
};

/* Store n checkpoints in one transaction (one disk sync), each replacing
 * its machine's. 0, or < 0 with err (nothing stored). */
int vmac_store_checkpoints_put(struct vmac_store *s, const struct vmac_checkpoint *cp, int n, char *err, size_t errlen);
/* machine's checkpoint: 1 with *data (malloc'd, the caller frees), *len,
 * driver, version (VMAC_NAME_MAX + 1 and 32 bytes) and *time; 0 when there
 * is none; < 0 with err. */
int vmac_store_checkpoint_get(struct vmac_store *s, const char *machine, uint8_t **data, size_t *len, char *driver,
                              size_t driverlen, char *version, size_t versionlen, double *time, char *err,
                              size_t errlen);

/* ---- flight recordings (docs/RECORDING.md; store_recording.c) ----
 * The newest `keep` are kept; adding one removes the oldest past that. */
struct vmac_recording_info {
	int64_t id;
	char machine[64], driver[64], version[32];
	char reason[200];
	double time; /* Unix time it was captured */
	size_t size; /* bytes of the file */
};

/* Store one (the file's text): 0 and *id, or < 0 with err. */
int vmac_store_recording_add(struct vmac_store *s, const struct vmac_recording_info *info, const char *data, size_t len,
                             int keep, int64_t *id, char *err, size_t errlen);
/* Every recording kept, newest first (machine: only its; NULL: all).
 * Returns how many, or < 0 with err. */
int vmac_store_recording_list(struct vmac_store *s, const char *machine,
                              void (*fn)(void *ctx, const struct vmac_recording_info *r), void *ctx, char *err,
                              size_t errlen);
/* Recording id: 1 with *data (malloc'd) and *len, 0 no such one, < 0 err. */
int vmac_store_recording_get(struct vmac_store *s, int64_t id, char **data, size_t *len, char *err, size_t errlen);

/* ---- board keys (docs/SECURITY.md, "Enrolling boards") ----
 * The secret key of each enrolled board, by board name: the host proves
 * a board's announcement with it and seals the board's session with keys
 * made from it (docs/PROTOCOL.md, "Authenticated frames"). */
#define VMAC_BOARD_KEY_LEN 16
#define VMAC_BOARD_NAME_MAX 31
#define VMAC_BOARD_NOTE_MAX 120
#define VMAC_BOARD_FINGERPRINT_LEN 16 /* hex digits */

struct vmac_board_key {
	char board[VMAC_BOARD_NAME_MAX + 1];
	uint8_t key[VMAC_BOARD_KEY_LEN];
	char fingerprint[VMAC_BOARD_FINGERPRINT_LEN + 1];
	double created; /* Unix time */
	char note[VMAC_BOARD_NOTE_MAX + 1];
};

/* Whether name can be a board's (what an ANNOUNCE may carry: 1..31 of
 * [A-Za-z0-9_-]). */
int vmac_board_name_valid(const char *name);
/* A key's fingerprint, what lists show instead of the key: the first 16
 * hex digits of its BLAKE2b hash. */
void vmac_board_key_fingerprint(const uint8_t key[VMAC_BOARD_KEY_LEN], char out[VMAC_BOARD_FINGERPRINT_LEN + 1]);
/* Enroll board with key: 0 stored, 1 the board has a key already and
 * replace is 0 (nothing changed), < 0 with err. */
int vmac_board_key_set(struct vmac_store *s, const char *board, const uint8_t key[VMAC_BOARD_KEY_LEN], int replace,
                       const char *note, char *err, size_t errlen);
/* Enroll n boards (k[i].board, .key, .note) in one transaction: 0 (*kept:
 * how many had a key already and kept it, replace being 0), < 0 with err
 * (none enrolled). */
int vmac_board_keys_set(struct vmac_store *s, const struct vmac_board_key *k, int n, int replace, int *kept, char *err,
                        size_t errlen);
/* Remove a board's key: 0 done, 1 no such board, < 0 with err. */
int vmac_board_key_remove(struct vmac_store *s, const char *board, char *err, size_t errlen);
/* Every board key, by name. Returns how many, or < 0 with err. */
int vmac_board_key_list(struct vmac_store *s, void (*fn)(void *ctx, const struct vmac_board_key *k), void *ctx,
                        char *err, size_t errlen);
/* A number that changes whenever the board keys may have changed, by this
 * process or another one (`vmac board enroll --state`): the host reads
 * the keys again when it does. */
uint64_t vmac_board_keys_version(struct vmac_store *s);
/* The board keys and audit rows written through this connection so far:
 * a counter, no statement (the host looks at the store at once when it
 * moved, else at intervals: core/mainloop/). */
uint64_t vmac_store_local_writes(struct vmac_store *s);

#endif
