/* vmac board enroll|list|remove: the keys of the boards this host trusts
 * (docs/CLI.md, docs/SECURITY.md "Enrolling boards"). Through a running
 * host's API (a deploy token to change, read to list), or with --local on
 * the store of --state directly, host running or not: a running host reads
 * the keys again at once (API) or within 50 ms (--local). A key is made
 * here (libsodium's randombytes) unless --key-file gives one; it is written
 * to --out (mode 0600) or printed once, and never shown again. */
#include "board.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "../common/file.h"
#include "../store/store.h"
#include "client.h"
#include "command.h"

#define KEY_HEX (2 * VMAC_BOARD_KEY_LEN)

enum { OPT_LOCAL = VMAC_CMD_OWN, OPT_KEY_FILE, OPT_OUT, OPT_KEY_DIR, OPT_REPLACE, OPT_NOTE };
#define OPT_QUIET_N VMAC_CMD_QUIET

#define LOCAL_OPTION                                                                                                   \
	{                                                                                                              \
		"local", NULL, 0, NULL, NULL, NULL,                                                                    \
		    "work on the store of --state directly, not through a running host's API (host running or not)"    \
	}

static const struct vmac_cmd_option enroll_options[] = {
    [OPT_LOCAL - VMAC_CMD_OWN] = LOCAL_OPTION,
    [OPT_KEY_FILE - VMAC_CMD_OWN] = {"key-file", NULL, 0, "FILE", NULL, NULL,
                                     "the board's key, 32 hex digits (default: a new random key)"},
    [OPT_OUT - VMAC_CMD_OWN] = {"out", NULL, 0, "FILE", NULL, NULL,
                                "write the new key to FILE (made with mode 0600; never overwritten) for the "
                                "board (vmac-board --key-file FILE); default: print it"},
    [OPT_KEY_DIR - VMAC_CMD_OWN] = {"key-dir", NULL, 0, "DIR", NULL, NULL,
                                    "each board's key in DIR/NAME.key: read when it is there, else made and "
                                    "written (mode 0600); for several boards (vmac-board --key-dir DIR)"},
    [OPT_REPLACE - VMAC_CMD_OWN] = {"replace", NULL, 0, NULL, NULL, NULL,
                                    "replace the key of a board enrolled already (key rotation)"},
    [OPT_NOTE - VMAC_CMD_OWN] = {"note", NULL, 0, "TEXT", NULL, NULL, "a note on the board (at most 120 characters)"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static const struct vmac_cmd_option local_options[] = {[OPT_LOCAL - VMAC_CMD_OWN] = LOCAL_OPTION,
                                                       {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

/* The key in file: 32 hex digits, a newline after them or not. 0, or 1
 * after saying why. */
static int read_key(const struct vmac_cmd_args *a, const char *file, uint8_t key[VMAC_BOARD_KEY_LEN])
{
	char err[512], *text;
	size_t len, n;
	int code;
	text = vmac_read_file(file, 4096, &len, err, sizeof(err), &code);
	if (!text) {
		fprintf(stderr, "%s: %s\n", a->name, err);
		return 1;
	}
	if (len > 0 && text[len - 1] == '\n')
		len--;
	if (len != KEY_HEX || sodium_hex2bin(key, VMAC_BOARD_KEY_LEN, text, len, NULL, &n, NULL) != 0 ||
	    n != VMAC_BOARD_KEY_LEN) {
		fprintf(stderr, "%s: %s: expected a key of 32 hex digits (and a newline or not), nothing else\n",
		        a->name, file);
		sodium_memzero(text, len);
		free(text);
		return 1;
	}
	sodium_memzero(text, len);
	free(text);
	return 0;
}

/* The new key to file (0600, never over an existing file), or printed. 0,
 * or 1 after saying why. */
static int give_key(const struct vmac_cmd_args *a, const char *file, const uint8_t key[VMAC_BOARD_KEY_LEN])
{
	char hex[KEY_HEX + 2];
	int fd, ok;
	sodium_bin2hex(hex, KEY_HEX + 1, key, VMAC_BOARD_KEY_LEN);
	hex[KEY_HEX] = '\n';
	hex[KEY_HEX + 1] = 0;
	if (!file) {
		fputs(hex, stdout);
		sodium_memzero(hex, sizeof(hex));
		return 0;
	}
	fd = open(file, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
	if (fd < 0) {
		fprintf(stderr, "%s: cannot make %s: %s%s\n", a->name, file, strerror(errno),
		        errno == EEXIST ? " (a key file is never overwritten: remove it first)" : "");
		sodium_memzero(hex, sizeof(hex));
		return 1;
	}
	ok = write(fd, hex, KEY_HEX + 1) == KEY_HEX + 1;
	ok = close(fd) == 0 && ok;
	sodium_memzero(hex, sizeof(hex));
	if (!ok) {
		fprintf(stderr, "%s: cannot write %s: %s\n", a->name, file, strerror(errno));
		unlink(file);
		return 1;
	}
	return 0;
}

static int open_store(const struct vmac_cmd_args *a, struct vmac_store **store)
{
	char err[1024];
	if (vmac_store_open(a->opt[VMAC_CMD_STATE], store, err, sizeof(err)) != 0) {
		fprintf(stderr, "%s: %s\n", a->name, err);
		return 1;
	}
	return 0;
}

static void show_enrolled(json_t *answer)
{
	fprintf(stderr, "vmac board: %s enrolled, key fingerprint %s\n",
	        json_string_value(json_object_get(answer, "board")),
	        json_string_value(json_object_get(answer, "fingerprint")));
}

/* Board k->board's key into k->key, as the options say: --key-file, or
 * DIR/NAME.key of --key-dir when it exists, else a new one (written to
 * --out, or DIR/NAME.key; *made: printed after enrolling). 0, or 1 after
 * saying why. */
static int key_for(const struct vmac_cmd_args *a, struct vmac_board_key *k, int *made)
{
	const char *dir = a->opt[OPT_KEY_DIR];
	char path[4096];
	*made = 0;
	if (a->opt[OPT_KEY_FILE])
		return read_key(a, a->opt[OPT_KEY_FILE], k->key);
	if (dir) {
		snprintf(path, sizeof(path), "%s/%s.key", dir, k->board);
		if (access(path, F_OK) == 0)
			return read_key(a, path, k->key);
		if (mkdir(dir, 0700) != 0 && errno != EEXIST) {
			fprintf(stderr, "%s: cannot make %s: %s\n", a->name, dir, strerror(errno));
			return 1;
		}
	}
	randombytes_buf(k->key, sizeof(k->key));
	if (dir || a->opt[OPT_OUT])
		return give_key(a, dir ? path : a->opt[OPT_OUT], k->key);
	*made = 1;
	return 0;
}

/* Over the API, one POST each: 0, or 1 when any failed (said why). */
static int enroll_api(const struct vmac_cmd_args *a, const struct vmac_board_key *k, int n)
{
	int i, failed = 0;
	for (i = 0; i < n; i++) {
		char hex[KEY_HEX + 1], *text, path[128];
		json_t *body;
		sodium_bin2hex(hex, sizeof(hex), k[i].key, sizeof(k[i].key));
		body =
		    json_pack("{s:s, s:b, s:s}", "key", hex, "replace", a->opt[OPT_REPLACE] != NULL, "note", k[i].note);
		text = body ? json_dumps(body, JSON_COMPACT) : NULL;
		json_decref(body);
		sodium_memzero(hex, sizeof(hex));
		snprintf(path, sizeof(path), "/api/boards/%s", k[i].board);
		failed |= text ? vmac_client_run_json(a, "POST", path, text, show_enrolled) : 1;
		if (text)
			sodium_memzero(text, strlen(text));
		free(text);
	}
	return failed;
}

/* A change made in the store by --local, for the host's audit trail
 * (docs/API.md, "Audit trail"): said on stderr when it cannot be kept. */
static void audit_local(const struct vmac_cmd_args *a, struct vmac_store *store, const char *what, const char *why)
{
	struct vmac_audit_row row;
	char err[512];
	memset(&row, 0, sizeof(row));
	snprintf(row.type, sizeof(row.type), "board");
	vmac_cmd_who(row.who, sizeof(row.who));
	snprintf(row.what, sizeof(row.what), "%s", what);
	snprintf(row.result, sizeof(row.result), "ok");
	snprintf(row.why, sizeof(row.why), "%s", why);
	if (vmac_store_audit_add(store, &row, err, sizeof(err)) != 0)
		fprintf(stderr, "%s: done, but not in the audit trail: %s\n", a->name, err);
}

static int enroll_local(const struct vmac_cmd_args *a, const struct vmac_board_key *k, int n)
{
	struct vmac_store *store;
	char err[1024];
	int rc, kept, i;
	if (open_store(a, &store))
		return 1;
	rc = vmac_board_keys_set(store, k, n, a->opt[OPT_REPLACE] != NULL, &kept, err, sizeof(err));
	if (rc < 0) {
		vmac_store_close(store);
		fprintf(stderr, "%s: %s\n", a->name, err);
		return 1;
	}
	for (i = 0; i < n; i++) {
		char what[200], why[100] = "";
		snprintf(what, sizeof(what), "vmac board enroll %s key %s%s", k[i].board, k[i].fingerprint,
		         a->opt[OPT_REPLACE] ? " (replace)" : "");
		if (kept)
			snprintf(why, sizeof(why), "%d of the %d boards had a key already and kept it", kept, n);
		audit_local(a, store, what, why);
	}
	vmac_store_close(store);
	if (kept)
		fprintf(stderr,
		        "%s: %d of the boards were enrolled already and kept their keys (--replace gives them "
		        "these)\n",
		        a->name, kept);
	for (i = 0; i < n && !a->opt[OPT_QUIET_N]; i++)
		fprintf(stderr, "vmac board: %s enrolled, key fingerprint %s\n", k[i].board, k[i].fingerprint);
	return kept != 0;
}

static int enroll_run(const struct vmac_cmd_args *a)
{
	const char *note = a->opt[OPT_NOTE] ? a->opt[OPT_NOTE] : "";
	struct vmac_board_key *k;
	int i, rc = 0, made = 0, one = !a->opt[OPT_KEY_DIR];
	if (a->opt[OPT_KEY_FILE] && a->opt[OPT_OUT])
		return vmac_cmd_usage_error(a, "--key-file gives a key, --out writes a new one: one or the other");
	if (a->opt[OPT_KEY_DIR] && (a->opt[OPT_KEY_FILE] || a->opt[OPT_OUT]))
		return vmac_cmd_usage_error(a, "--key-dir holds every board's key: not with --key-file or --out");
	if (one && a->nargs > 1)
		return vmac_cmd_usage_error(a, "several boards take --key-dir DIR (a key file each)");
	if (strlen(note) > VMAC_BOARD_NOTE_MAX)
		return vmac_cmd_usage_error(a, "--note is longer than %d characters", VMAC_BOARD_NOTE_MAX);
	for (i = 0; i < a->nargs; i++)
		if (!vmac_board_name_valid(a->arg[i]))
			return vmac_cmd_usage_error(a, "'%s' is not a board's name (1..31 of A-Z a-z 0-9 _ -)",
			                            a->arg[i]);
	k = calloc((size_t)a->nargs, sizeof(*k));
	if (!k) {
		fprintf(stderr, "%s: out of memory\n", a->name);
		return 1;
	}
	for (i = 0; i < a->nargs && rc == 0; i++) {
		snprintf(k[i].board, sizeof(k[i].board), "%s", a->arg[i]);
		snprintf(k[i].note, sizeof(k[i].note), "%s", note);
		rc = key_for(a, &k[i], &made);
		vmac_board_key_fingerprint(k[i].key, k[i].fingerprint);
	}
	if (rc == 0)
		rc = a->opt[OPT_LOCAL] ? enroll_local(a, k, a->nargs) : enroll_api(a, k, a->nargs);
	if (rc == 0 && made)
		give_key(a, NULL, k[0].key); /* printed once: nowhere else to find it */
	if (rc != 0 && one && a->opt[OPT_OUT] && !a->opt[OPT_KEY_FILE])
		unlink(a->opt[OPT_OUT]); /* not enrolled: the new key is nobody's */
	sodium_memzero(k, (size_t)a->nargs * sizeof(*k));
	free(k);
	return rc != 0;
}

static void print_key(void *ctx, const struct vmac_board_key *k)
{
	char created[32];
	time_t t = (time_t)k->created;
	(void)ctx;
	strftime(created, sizeof(created), "%Y-%m-%d %H:%M:%S", localtime(&t));
	printf("%-31s  %-16s  %-19s  %-9s  %s\n", k->board, k->fingerprint, created, "-", k->note);
}

static void show_boards(json_t *answer)
{
	json_t *b;
	size_t i;
	printf("%-31s  %-16s  %-19s  %-9s  %s\n", "BOARD", "KEY", "ENROLLED", "STATE", "NOTE");
	json_array_foreach(json_object_get(answer, "enrolled"), i, b)
	{
		char created[32];
		time_t t = (time_t)json_number_value(json_object_get(b, "created"));
		const char *state = json_string_value(json_object_get(b, "state"));
		strftime(created, sizeof(created), "%Y-%m-%d %H:%M:%S", localtime(&t));
		printf("%-31s  %-16s  %-19s  %-9s  %s\n", json_string_value(json_object_get(b, "board")),
		       json_string_value(json_object_get(b, "fingerprint")), created, state ? state : "absent",
		       json_string_value(json_object_get(b, "note")));
	}
	if (json_array_size(json_object_get(answer, "waiting")) == 0)
		return;
	printf("\nwaiting for approval (vmac board enroll NAME):\n");
	json_array_foreach(json_object_get(answer, "waiting"), i, b)
	    printf("%-31s  driver %s at %s\n", json_string_value(json_object_get(b, "board")),
	           json_string_value(json_object_get(b, "driver")), json_string_value(json_object_get(b, "address")));
}

static int list_run(const struct vmac_cmd_args *a)
{
	struct vmac_store *store;
	char err[1024];
	int rc = 0;
	if (!a->opt[OPT_LOCAL])
		return vmac_client_run(a, "GET", "/api/boards", NULL, 0, show_boards);
	if (open_store(a, &store))
		return 1;
	printf("%-31s  %-16s  %-19s  %-9s  %s\n", "BOARD", "KEY", "ENROLLED", "STATE", "NOTE");
	if (vmac_board_key_list(store, print_key, NULL, err, sizeof(err)) < 0) {
		fprintf(stderr, "%s: %s\n", a->name, err);
		rc = 1;
	}
	vmac_store_close(store);
	return rc;
}

static void show_removed(json_t *answer)
{
	fprintf(stderr, "vmac board: %s's key removed\n", json_string_value(json_object_get(answer, "board")));
}

static int remove_run(const struct vmac_cmd_args *a)
{
	struct vmac_store *store;
	char err[1024], path[128];
	int rc;
	if (!vmac_board_name_valid(a->arg[0]))
		return vmac_cmd_usage_error(a, "'%s' is not a board's name (1..31 of A-Z a-z 0-9 _ -)", a->arg[0]);
	if (!a->opt[OPT_LOCAL]) {
		snprintf(path, sizeof(path), "/api/boards/%s/remove", a->arg[0]);
		return vmac_client_run(a, "POST", path, NULL, 0, show_removed);
	}
	if (open_store(a, &store))
		return 1;
	rc = vmac_board_key_remove(store, a->arg[0], err, sizeof(err));
	if (rc == 0) {
		char what[100];
		snprintf(what, sizeof(what), "vmac board remove %s", a->arg[0]);
		audit_local(a, store, what, "");
	}
	vmac_store_close(store);
	if (rc < 0)
		fprintf(stderr, "%s: %s\n", a->name, err);
	else if (rc == 1)
		fprintf(stderr, "%s: %s is not enrolled\n", a->name, a->arg[0]);
	else
		fprintf(stderr, "vmac board: %s's key removed\n", a->arg[0]);
	return rc != 0;
}

#define COMMON (VMAC_CMD_API | VMAC_CMD_TAKES(VMAC_CMD_STATE))
#define EXIT_CODES                                                                                                     \
	"Exit 0 done, 1 the host unreachable, the token refused, the store or a file unusable, 2 wrong usage.\n"

static const struct vmac_cmd enroll_cmd = {
    .name = "enroll",
    .args = "NAME...",
    .expect = "board names (what the boards announce)",
    .min_args = 1,
    .max_args = -1,
    .summary = "trust board NAME: its key, given or made (printed or --out FILE)",
    .about = "Enroll board NAME: the host attaches it only when its announcement proves this key, and\n"
             "seals every frame of its session (docs/SECURITY.md). A new random key is made unless\n"
             "--key-file gives one; it is written to --out FILE or printed once, for the board\n"
             "(vmac-board --key-file FILE; scripts/qemu-board-config.py --key-file FILE). Several\n"
             "boards at once take --key-dir DIR. --replace rotates a key: the board's running session\n"
             "goes on until it announces with the new one. Through the API needs a token of scope\n"
             "deploy.\n" EXIT_CODES,
    .common = COMMON | VMAC_CMD_TAKES(VMAC_CMD_QUIET),
    .own = enroll_options,
    .run = enroll_run};

static const struct vmac_cmd list_cmd = {
    .name = "list",
    .summary = "the enrolled boards (key fingerprints, never keys) and those waiting for approval",
    .about = "List the enrolled boards: name, key fingerprint, when enrolled, state on the bus, note;\n"
             "through the API also the boards waiting for approval (announcing without a key this\n"
             "host holds). Through the API needs a token of scope read.\n" EXIT_CODES,
    .common = COMMON,
    .own = local_options,
    .run = list_run};

static const struct vmac_cmd remove_cmd = {
    .name = "remove",
    .args = "NAME",
    .expect = "one board name (vmac board list shows them)",
    .min_args = 1,
    .max_args = 1,
    .summary = "stop trusting board NAME: its key removed, the board dropped if it runs",
    .about = "Remove board NAME's key: the host no longer trusts it; a running board is dropped (told to\n"
             "go safe) at once. Through the API needs a token of scope deploy.\n" EXIT_CODES,
    .common = COMMON,
    .own = local_options,
    .run = remove_run};

static const struct vmac_cmd *const actions[] = {&enroll_cmd, &list_cmd, &remove_cmd, NULL};

const struct vmac_cmd vmac_board_cmd = {
    .name = "board",
    .args = "ACTION",
    .summary = "enroll, list and remove the boards this host trusts (their keys)",
    .about = "The keys of the boards this host trusts (docs/SECURITY.md, \"Enrolling boards\").\n",
    .sub = actions};
