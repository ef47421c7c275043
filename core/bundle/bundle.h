/* A machine's software as one file (docs/DRIVERS.md "Bundles"): its
 * driver, its programmes, its plant model and tests when it has them, and
 * metadata (name, version, security counter, the driver API it needs, the
 * BLAKE2b-256 hash of every file), in a POSIX ustar archive written by
 * libarchive so that the same contents always give the same bytes:
 * bundle.json first, then the files in path order, each with mode 0644,
 * owner 0/0 without names and time 0. Members:
 *   bundle.json        {"format": "vmac-bundle", "format_version": 1,
 *                       "name", "version", "counter", "api",
 *                       "files": {PATH: HASH, ...}} (sorted keys, compact)
 *   NAME.lua           the driver (NAME its name)
 *   cycles/PROG.lua    a programme (vmac.cycles())
 *   plant.lua          the machine's plant model
 *   tests/T.lua        a test of the driver (vmac test)
 * Nothing else is accepted. Reading checks everything (the layout, every
 * hash, sizes, names) and refuses with -VMAC_EBUNDLE and a message that
 * says what is wrong. Any thread; no global state. */
#ifndef VMAC_BUNDLE_H
#define VMAC_BUNDLE_H

#include <stddef.h>
#include <stdint.h>

#define VMAC_BUNDLE_MAX (4u << 20)      /* bytes of a bundle file */
#define VMAC_BUNDLE_FILES 160           /* members besides bundle.json */
#define VMAC_BUNDLE_PATH_MAX 64         /* bytes of a member's path, NUL included */
#define VMAC_BUNDLE_FILE_MAX (1u << 20) /* bytes of one member */
#define VMAC_BUNDLE_NAME_MAX 47
#define VMAC_BUNDLE_VERSION_MAX 31
#define VMAC_BUNDLE_HASH_LEN 64 /* hex digits of a BLAKE2b-256 hash */

struct vmac_bundle_file {
	char path[VMAC_BUNDLE_PATH_MAX];
	char *data; /* malloc'd, len bytes and a NUL after them */
	size_t len;
	char hash[VMAC_BUNDLE_HASH_LEN + 1];
};

struct vmac_bundle {
	char name[VMAC_BUNDLE_NAME_MAX + 1];
	char version[VMAC_BUNDLE_VERSION_MAX + 1];
	uint64_t counter; /* the security counter: never lower than one accepted before */
	char api[16];     /* the driver API it needs ("0.2"; vmac.version) */
	int nfiles;
	struct vmac_bundle_file *files; /* sorted by path */
};

/* An empty bundle of driver `name` (version, counter and api empty/0):
 * 0, or -VMAC_EBUNDLE (name not a driver's name) / -ENOMEM with err. */
int vmac_bundle_new(const char *name, struct vmac_bundle **out, char *err, size_t errlen);

/* Add (or replace) member path with a copy of data: 0, or -VMAC_EBUNDLE
 * with err (a path the layout does not allow, too large, too many). */
int vmac_bundle_add(struct vmac_bundle *b, const char *path, const void *data, size_t len, char *err, size_t errlen);

/* Member path, or NULL. */
const struct vmac_bundle_file *vmac_bundle_get(const struct vmac_bundle *b, const char *path);
/* The driver (NAME.lua), or NULL. */
const struct vmac_bundle_file *vmac_bundle_driver(const struct vmac_bundle *b);

/* A bundle of what a drivers folder holds for one driver (DRIVERS.md
 * "Bundles"): path is a driver file D/NAME.lua, or a folder D that holds
 * exactly one driver file. It takes D/NAME.lua; the programmes in
 * cycles_dir, or when that is NULL in D/cycles/NAME/ (else
 * D/../cycles/NAME/, the source tree's scripts/ layout); D/plants/NAME.lua
 * as plant.lua; D/tests/NAME_test.lua and D/tests/NAME_*_test.lua as
 * tests/. Version, counter and api are left for the caller. 0, or < 0
 * with err (-ENOENT: no such driver). */
int vmac_bundle_from_folder(const char *path, const char *cycles_dir, struct vmac_bundle **out, char *err,
                            size_t errlen);

/* The archive of b (malloc'd, *len bytes): the same b always gives the
 * same bytes. 0, or < 0 with err (a bundle without version or driver, or
 * one larger than VMAC_BUNDLE_MAX, which no host reads). */
int vmac_bundle_write(const struct vmac_bundle *b, char **data, size_t *len, char *err, size_t errlen);

/* Read an archive: 0 and *out, or -VMAC_EBUNDLE with err. */
int vmac_bundle_read(const void *data, size_t len, struct vmac_bundle **out, char *err, size_t errlen);

/* Whether data looks like an archive (ustar's magic at offset 257), not
 * a driver's Lua text. */
int vmac_bundle_is_archive(const void *data, size_t len);

/* BLAKE2b-256 of data as lowercase hex (the hash of a member, and of a
 * whole bundle: what the store and recordings name it by). */
void vmac_bundle_hash(const void *data, size_t len, char out[VMAC_BUNDLE_HASH_LEN + 1]);

/* The trusted comment a signature of b carries (SECURITY.md "Signed
 * bundles"): "vmac-bundle name=NAME version=V counter=C". */
void vmac_bundle_comment(const struct vmac_bundle *b, char *out, size_t len);
/* Whether a signature's trusted comment agrees with b's metadata: its
 * whitespace-separated words hold name=, version= and counter= equal to
 * b's (other words, minisign's timestamp for one, are let be). 0, or
 * -VMAC_ESIGMETA with err saying which disagrees. */
int vmac_bundle_comment_check(const struct vmac_bundle *b, const char *comment, char *err, size_t errlen);

void vmac_bundle_free(struct vmac_bundle *b);

#endif
