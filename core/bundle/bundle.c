/* See bundle.h. The archive in and out of memory (libarchive), the
 * metadata (jansson), the hashes (libsodium's BLAKE2b). */
#include "bundle.h"

#include <archive.h>
#include <archive_entry.h>
#include <errno.h>
#include <jansson.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/errors.h"
#include "../common/name.h"

#define META "bundle.json"
#define META_MAX (64u << 10)
#define FORMAT "vmac-bundle"
#define FORMAT_VERSION 1

static int fail(int code, char *err, size_t errlen, const char *fmt, const char *a, const char *b)
{
	snprintf(err, errlen, fmt, a, b);
	return code;
}

int vmac_bundle_is_archive(const void *data, size_t len)
{
	return len >= 512 && memcmp((const char *)data + 257, "ustar", 5) == 0;
}

void vmac_bundle_hash(const void *data, size_t len, char out[VMAC_BUNDLE_HASH_LEN + 1])
{
	unsigned char h[32];
	crypto_generichash(h, sizeof(h), data, len, NULL, 0);
	sodium_bin2hex(out, VMAC_BUNDLE_HASH_LEN + 1, h, sizeof(h));
}

/* A programme's or a test's file name without ".lua": 1..40 of
 * [A-Za-z0-9_] (a programme's name is a Lua identifier: vmac.cycles()'s
 * table key), a test's may hold '-' and '.' too. */
static int base_ok(const char *s, size_t n, int test)
{
	size_t i;
	if (n == 0 || n > 40)
		return 0;
	for (i = 0; i < n; i++) {
		char c = s[i];
		if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
		      (test && (c == '-' || (c == '.' && i > 0)))))
			return 0;
	}
	return 1;
}

/* Whether path is a member the layout allows in a bundle of driver name. */
static int path_ok(const char *name, const char *path)
{
	size_t n = strlen(path);
	if (n < 5 || n >= VMAC_BUNDLE_PATH_MAX || strcmp(path + n - 4, ".lua") != 0)
		return 0;
	if (strncmp(path, name, n - 4) == 0 && strlen(name) == n - 4)
		return 1;
	if (strcmp(path, "plant.lua") == 0)
		return 1;
	if (strncmp(path, "cycles/", 7) == 0)
		return base_ok(path + 7, n - 11, 0);
	if (strncmp(path, "tests/", 6) == 0)
		return base_ok(path + 6, n - 10, 1);
	return 0;
}

int vmac_bundle_new(const char *name, struct vmac_bundle **out, char *err, size_t errlen)
{
	*out = NULL;
	if (!vmac_valid_name(name, VMAC_BUNDLE_NAME_MAX))
		return fail(-VMAC_EBUNDLE, err, errlen, "'%s' is not a driver's name (1..47 of A-Z a-z 0-9 . _ -)%s",
		            name, "");
	if (!(*out = calloc(1, sizeof(**out))))
		return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
	snprintf((*out)->name, sizeof((*out)->name), "%s", name);
	return 0;
}

const struct vmac_bundle_file *vmac_bundle_get(const struct vmac_bundle *b, const char *path)
{
	int i;
	for (i = 0; i < b->nfiles; i++)
		if (strcmp(b->files[i].path, path) == 0)
			return &b->files[i];
	return NULL;
}

const struct vmac_bundle_file *vmac_bundle_driver(const struct vmac_bundle *b)
{
	char path[VMAC_BUNDLE_PATH_MAX];
	snprintf(path, sizeof(path), "%s.lua", b->name);
	return vmac_bundle_get(b, path);
}

int vmac_bundle_add(struct vmac_bundle *b, const char *path, const void *data, size_t len, char *err, size_t errlen)
{
	struct vmac_bundle_file *f = (struct vmac_bundle_file *)vmac_bundle_get(b, path);
	char *copy;
	int i;
	if (!path_ok(b->name, path)) {
		snprintf(err, errlen,
		         "%s is not a member a bundle may hold (%s.lua, cycles/NAME.lua, plant.lua, tests/NAME.lua)",
		         path, b->name);
		return -VMAC_EBUNDLE;
	}
	if (len > VMAC_BUNDLE_FILE_MAX)
		return fail(-VMAC_EBUNDLE, err, errlen, "%s is larger than a bundle's member may be (1 MiB)%s", path,
		            "");
	if (!f && b->nfiles >= VMAC_BUNDLE_FILES)
		return fail(-VMAC_EBUNDLE, err, errlen,
		            "too many files in the bundle (at most 160); %s is one too many%s", path, "");
	if (!(copy = malloc(len + 1)))
		return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
	memcpy(copy, data, len);
	copy[len] = 0;
	if (!f) {
		struct vmac_bundle_file *more = realloc(b->files, (size_t)(b->nfiles + 1) * sizeof(*more));
		if (!more) {
			free(copy);
			return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
		}
		b->files = more;
		for (i = b->nfiles; i > 0 && strcmp(b->files[i - 1].path, path) > 0; i--)
			b->files[i] = b->files[i - 1]; /* kept in path order */
		f = &b->files[i];
		b->nfiles++;
		memset(f, 0, sizeof(*f));
		snprintf(f->path, sizeof(f->path), "%s", path);
	}
	free(f->data);
	f->data = copy;
	f->len = len;
	vmac_bundle_hash(data, len, f->hash);
	return 0;
}

void vmac_bundle_free(struct vmac_bundle *b)
{
	int i;
	if (!b)
		return;
	for (i = 0; i < b->nfiles; i++)
		free(b->files[i].data);
	free(b->files);
	free(b);
}

/* ---- the metadata ---- */

static char *meta_text(const struct vmac_bundle *b)
{
	json_t *files = json_object(), *m;
	char *text;
	int i;
	for (i = 0; i < b->nfiles; i++)
		json_object_set_new(files, b->files[i].path, json_string(b->files[i].hash));
	m = json_pack("{s:s, s:i, s:s, s:s, s:I, s:s, s:o}", "format", FORMAT, "format_version", FORMAT_VERSION, "name",
	              b->name, "version", b->version, "counter", (json_int_t)b->counter, "api", b->api, "files", files);
	text = m ? json_dumps(m, JSON_SORT_KEYS | JSON_COMPACT) : NULL;
	json_decref(m);
	return text;
}

/* A version as a manifest may give it: 1..31 printable bytes, no space. */
static int version_ok(const char *v)
{
	size_t n = strlen(v);
	if (n == 0 || n > VMAC_BUNDLE_VERSION_MAX)
		return 0;
	for (; *v; v++)
		if (*v <= ' ' || *v > '~')
			return 0;
	return 1;
}

/* bundle.json's fields: each must be there, of its type. */
static const struct {
	const char *key;
	json_type type;
	const char *is;
} META_FIELDS[] = {{"format", JSON_STRING, "a string"},
                   {"format_version", JSON_INTEGER, "a whole number"},
                   {"name", JSON_STRING, "a string"},
                   {"version", JSON_STRING, "a string"},
                   {"counter", JSON_INTEGER, "a whole number"},
                   {"api", JSON_STRING, "a string"},
                   {"files", JSON_OBJECT, "an object of PATH: HASH"}};

/* 0 when m has every field of META_FIELDS, of its type; else a message
 * naming the first that is not. */
static int meta_fields(json_t *m, char *err, size_t errlen)
{
	size_t i;
	if (!json_is_object(m))
		return fail(-VMAC_EBUNDLE, err, errlen, "bundle.json is not a JSON object%s%s", "", "");
	for (i = 0; i < sizeof(META_FIELDS) / sizeof(META_FIELDS[0]); i++) {
		json_t *v = json_object_get(m, META_FIELDS[i].key);
		if (!v)
			return fail(-VMAC_EBUNDLE, err, errlen, "bundle.json lacks the field %s%s", META_FIELDS[i].key,
			            "");
		if (json_typeof(v) != META_FIELDS[i].type)
			return fail(-VMAC_EBUNDLE, err, errlen, "bundle.json: %s is not %s", META_FIELDS[i].key,
			            META_FIELDS[i].is);
	}
	return 0;
}

/* The metadata's fields into b (files are checked against it later); a
 * refusal names the field that is wrong. */
static int meta_read(struct vmac_bundle *b, const char *text, size_t len, json_t **files, char *err, size_t errlen)
{
	json_error_t je;
	json_t *m = json_loadb(text, len, JSON_REJECT_DUPLICATES, &je);
	const char *format = NULL, *name = NULL, *version = NULL, *api = NULL;
	json_int_t fv = 0, counter = -1;
	int rc;
	*files = NULL;
	if (!m)
		return fail(-VMAC_EBUNDLE, err, errlen, "bundle.json is not JSON: %s%s", je.text, "");
	if ((rc = meta_fields(m, err, errlen)) != 0 ||
	    json_unpack(m, "{s:s, s:I, s:s, s:s, s:I, s:s, s:o}", "format", &format, "format_version", &fv, "name",
	                &name, "version", &version, "counter", &counter, "api", &api, "files", files) != 0) {
		rc = rc ? rc : fail(-VMAC_EBUNDLE, err, errlen, "bundle.json cannot be read%s%s", "", "");
	} else if (strcmp(format, FORMAT) != 0) {
		rc = fail(-VMAC_EBUNDLE, err, errlen, "bundle.json's format is \"%.40s\", not \"%s\"", format, FORMAT);
	} else if (fv != FORMAT_VERSION) {
		snprintf(err, errlen, "a bundle of format version %lld: this host reads version %d", (long long)fv,
		         FORMAT_VERSION);
		rc = -VMAC_EBUNDLE;
	} else if (!vmac_valid_name(name, VMAC_BUNDLE_NAME_MAX)) {
		rc = fail(-VMAC_EBUNDLE, err, errlen,
		          "bundle.json: \"%.60s\" is not a driver's name (1..47 of A-Z a-z 0-9 . _ -, not first .)%s",
		          name, "");
	} else if (!version_ok(version)) {
		rc = fail(-VMAC_EBUNDLE, err, errlen,
		          "bundle.json: version \"%.60s\" is not a version (1..31 printable characters, no space)%s",
		          version, "");
	} else if (counter < 0) {
		snprintf(err, errlen, "bundle.json: counter %lld is below 0", (long long)counter);
		rc = -VMAC_EBUNDLE;
	} else if (!api[0] || strlen(api) >= sizeof(b->api)) {
		rc = fail(-VMAC_EBUNDLE, err, errlen, "bundle.json: api \"%.60s\" is not a driver API (1..15 bytes)%s",
		          api, "");
	}
	if (rc != 0) {
		*files = NULL;
		json_decref(m);
		return rc;
	}
	snprintf(b->name, sizeof(b->name), "%s", name);
	snprintf(b->version, sizeof(b->version), "%s", version);
	snprintf(b->api, sizeof(b->api), "%s", api);
	b->counter = (uint64_t)counter;
	json_incref(*files);
	json_decref(m);
	return 0;
}

/* ---- the archive ---- */

static int add_entry(struct archive *a, const char *path, const char *data, size_t len)
{
	struct archive_entry *e = archive_entry_new();
	int ok;
	if (!e)
		return -1;
	archive_entry_set_pathname(e, path);
	archive_entry_set_size(e, (la_int64_t)len);
	archive_entry_set_filetype(e, AE_IFREG);
	archive_entry_set_perm(e, 0644);
	archive_entry_set_mtime(e, 0, 0);
	archive_entry_set_uid(e, 0);
	archive_entry_set_gid(e, 0);
	ok = archive_write_header(a, e) == ARCHIVE_OK &&
	     (len == 0 || archive_write_data(a, data, len) == (la_ssize_t)len);
	archive_entry_free(e);
	return ok ? 0 : -1;
}

int vmac_bundle_write(const struct vmac_bundle *b, char **data, size_t *len, char *err, size_t errlen)
{
	struct archive *a;
	char *meta, *buf;
	size_t cap, used = 0;
	int i, ok, rc;
	*data = NULL;
	*len = 0;
	if (!b->version[0] || !b->api[0] || !vmac_bundle_driver(b))
		return fail(-VMAC_EBUNDLE, err, errlen, "a bundle of %s needs a version, an api and %s.lua", b->name,
		            b->name);
	if (!(meta = meta_text(b)))
		return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
	cap = strlen(meta) + 2048;
	for (i = 0; i < b->nfiles; i++)
		cap += b->files[i].len + 1024; /* a header and the padding */
	if (!(buf = malloc(cap)) || !(a = archive_write_new())) {
		free(meta);
		free(buf);
		return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
	}
	ok = archive_write_set_format_ustar(a) == ARCHIVE_OK && archive_write_add_filter_none(a) == ARCHIVE_OK &&
	     archive_write_set_bytes_in_last_block(a, 1) == ARCHIVE_OK &&
	     archive_write_open_memory(a, buf, cap, &used) == ARCHIVE_OK && add_entry(a, META, meta, strlen(meta)) == 0;
	for (i = 0; ok && i < b->nfiles; i++)
		ok = add_entry(a, b->files[i].path, b->files[i].data, b->files[i].len) == 0;
	rc = ok && archive_write_close(a) == ARCHIVE_OK ? 0 : -VMAC_EFAIL;
	if (rc != 0)
		snprintf(err, errlen, "writing the bundle: %s",
		         archive_error_string(a) ? archive_error_string(a) : "?");
	archive_write_free(a);
	free(meta);
	if (rc == 0 && used > VMAC_BUNDLE_MAX) {
		snprintf(err, errlen, "the bundle of %s would be %zu bytes: a host reads one of at most 4 MiB", b->name,
		         used);
		rc = -VMAC_EBUNDLE;
	}
	if (rc != 0) {
		free(buf);
		return rc;
	}
	*data = buf;
	*len = used;
	return 0;
}

/* The next member's bytes (at most max) into a malloc'd buffer. */
static int entry_data(struct archive *a, struct archive_entry *e, size_t max, char **out, size_t *len, char *err,
                      size_t errlen)
{
	const char *path = archive_entry_pathname(e);
	la_int64_t size = archive_entry_size(e);
	char *buf;
	la_ssize_t got;
	*out = NULL;
	if (archive_entry_filetype(e) != AE_IFREG || !archive_entry_size_is_set(e))
		return fail(-VMAC_EBUNDLE, err, errlen, "%s is not a plain file (a bundle holds files only)%s", path,
		            "");
	if (size < 0 || (uint64_t)size > max)
		return fail(-VMAC_EBUNDLE, err, errlen, "%s is larger than a bundle's member may be%s", path, "");
	if (!(buf = malloc((size_t)size + 1)))
		return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
	got = size ? archive_read_data(a, buf, (size_t)size) : 0;
	if (got != size) {
		free(buf);
		return fail(-VMAC_EBUNDLE, err, errlen, "%s is cut short: the bundle is damaged%s", path, "");
	}
	buf[size] = 0;
	*out = buf;
	*len = (size_t)size;
	return 0;
}

/* Where the member whose header was read last ends in the archive: past
 * its headers (pax's too), its data and their padding to 512 bytes. */
static la_int64_t member_end(struct archive *a, struct archive_entry *e)
{
	return archive_filter_bytes(a, -1) + ((archive_entry_size(e) + 511) & ~(la_int64_t)511);
}

/* What follows the last member, from end: the two zero blocks that end a
 * tar and nothing else, so that a bundle cut short in them, or one with
 * bytes after them (another archive, say), is refused as damaged: libarchive
 * takes both. */
static int end_ok(const char *data, size_t len, la_int64_t end, char *err, size_t errlen)
{
	size_t at = (size_t)end, i;
	if (end < 0 || at > len || len - at < 1024)
		return fail(-VMAC_EBUNDLE, err, errlen,
		            "the bundle is cut short (its end-of-archive blocks are missing): it is damaged%s%s", "",
		            "");
	for (i = at; i < at + 1024; i++)
		if (data[i])
			return fail(-VMAC_EBUNDLE, err, errlen,
			            "the bundle's end-of-archive blocks are not zero: it is damaged%s%s", "", "");
	if (len - at > 1024) {
		snprintf(err, errlen, "%zu bytes after the end of the archive: the bundle is damaged", len - at - 1024);
		return -VMAC_EBUNDLE;
	}
	return 0;
}

/* Every member after bundle.json into b, each checked against files; *end
 * where the last one ends. */
static int read_members(struct archive *a, struct vmac_bundle *b, json_t *files, la_int64_t *end, char *err,
                        size_t errlen)
{
	struct archive_entry *e;
	void *it;
	int r, rc;
	while ((r = archive_read_next_header(a, &e)) == ARCHIVE_OK) {
		const char *path = archive_entry_pathname(e), *want;
		char *data;
		size_t len;
		*end = member_end(a, e);
		if (!path)
			return fail(-VMAC_EBUNDLE, err, errlen, "a member without a name%s%s", "", "");
		if (vmac_bundle_get(b, path) || strcmp(path, META) == 0)
			return fail(-VMAC_EBUNDLE, err, errlen, "%s is in the bundle twice%s", path, "");
		if (!(want = json_string_value(json_object_get(files, path))))
			return fail(-VMAC_EBUNDLE, err, errlen, "%s is not listed in bundle.json%s", path, "");
		if ((rc = entry_data(a, e, VMAC_BUNDLE_FILE_MAX, &data, &len, err, errlen)) != 0)
			return rc;
		rc = vmac_bundle_add(b, path, data, len, err, errlen);
		free(data);
		if (rc != 0)
			return rc;
		if (strcmp(vmac_bundle_get(b, path)->hash, want) != 0)
			return fail(-VMAC_EBUNDLE, err, errlen,
			            "%s does not match its hash in bundle.json: the bundle is damaged%s", path, "");
	}
	if (r != ARCHIVE_EOF)
		return fail(-VMAC_EBUNDLE, err, errlen, "not a bundle: %s%s",
		            archive_error_string(a) ? archive_error_string(a) : "a damaged archive", "");
	for (it = json_object_iter(files); it; it = json_object_iter_next(files, it))
		if (!vmac_bundle_get(b, json_object_iter_key(it)))
			return fail(-VMAC_EBUNDLE, err, errlen,
			            "bundle.json lists %s, which the bundle does not hold%s", json_object_iter_key(it),
			            "");
	if (!vmac_bundle_driver(b))
		return fail(-VMAC_EBUNDLE, err, errlen, "the bundle of %s holds no %s.lua", b->name, b->name);
	return 0;
}

int vmac_bundle_read(const void *data, size_t len, struct vmac_bundle **out, char *err, size_t errlen)
{
	struct archive *a;
	struct archive_entry *e;
	struct vmac_bundle *b;
	json_t *files = NULL;
	char *meta = NULL;
	size_t metalen;
	la_int64_t end;
	int rc;
	*out = NULL;
	if (len > VMAC_BUNDLE_MAX)
		return fail(-VMAC_EBUNDLE, err, errlen, "a bundle is at most 4 MiB%s%s", "", "");
	if (!(b = calloc(1, sizeof(*b))) || !(a = archive_read_new())) {
		free(b);
		return fail(-ENOMEM, err, errlen, "out of memory%s%s", "", "");
	}
	archive_read_support_format_tar(a);
	if (archive_read_open_memory(a, data, len) != ARCHIVE_OK || archive_read_next_header(a, &e) != ARCHIVE_OK) {
		rc = fail(-VMAC_EBUNDLE, err, errlen, "not a bundle (a tar archive): %s%s",
		          archive_error_string(a) ? archive_error_string(a) : "empty", "");
	} else if (!archive_entry_pathname(e) || strcmp(archive_entry_pathname(e), META) != 0) {
		rc = fail(-VMAC_EBUNDLE, err, errlen, "not a bundle: its first member is %s, not bundle.json%s",
		          archive_entry_pathname(e) ? archive_entry_pathname(e) : "unnamed", "");
	} else {
		end = member_end(a, e);
		if ((rc = entry_data(a, e, META_MAX, &meta, &metalen, err, errlen)) == 0 &&
		    (rc = meta_read(b, meta, metalen, &files, err, errlen)) == 0 &&
		    (rc = read_members(a, b, files, &end, err, errlen)) == 0)
			rc = end_ok(data, len, end, err, errlen);
	}
	archive_read_free(a);
	json_decref(files);
	free(meta);
	if (rc != 0) {
		vmac_bundle_free(b);
		return rc;
	}
	*out = b;
	return 0;
}

/* ---- the signature's trusted comment ---- */

void vmac_bundle_comment(const struct vmac_bundle *b, char *out, size_t len)
{
	snprintf(out, len, "vmac-bundle name=%s version=%s counter=%llu", b->name, b->version,
	         (unsigned long long)b->counter);
}

/* The value of word key= in comment (words split at white space), or "". */
static void comment_word(const char *comment, const char *key, char *out, size_t len)
{
	size_t klen = strlen(key);
	const char *p = comment;
	out[0] = 0;
	while (*p) {
		size_t n;
		while (*p == ' ' || *p == '\t')
			p++;
		n = strcspn(p, " \t");
		if (n > klen && strncmp(p, key, klen) == 0 && p[klen] == '=') {
			snprintf(out, len, "%.*s", (int)(n - klen - 1), p + klen + 1);
			return;
		}
		p += n;
	}
}

int vmac_bundle_comment_check(const struct vmac_bundle *b, const char *comment, char *err, size_t errlen)
{
	char counter[24], got[3][64];
	const char *key[3] = {"name", "version", "counter"}, *want[3] = {b->name, b->version, counter};
	int i;
	snprintf(counter, sizeof(counter), "%llu", (unsigned long long)b->counter);
	for (i = 0; i < 3; i++) {
		comment_word(comment, key[i], got[i], sizeof(got[i]));
		if (strcmp(got[i], want[i]) != 0) {
			snprintf(
			    err, errlen,
			    "the signature was made for %s=%s, but the bundle says %s=%s (its trusted comment must "
			    "be \"vmac-bundle name=%s version=%s counter=%s\")",
			    key[i], got[i][0] ? got[i] : "(none)", key[i], want[i], b->name, b->version, counter);
			return -VMAC_ESIGMETA;
		}
	}
	return 0;
}
