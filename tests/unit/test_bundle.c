/* Unit tests of the bundle archive (core/bundle/bundle.c): the same files
 * added in any order give the same bytes, which read back as they were and
 * which GNU tar lists as DRIVERS.md "Bundles" says (bundle.json first, then
 * the files in path order, mode 0644, owner 0/0, time 0); and every archive
 * that is not such a bundle is refused with -VMAC_EBUNDLE and a message that
 * names what is wrong: not a tar, bundle.json missing, misplaced or wrong in
 * any field, a member unlisted, missing, changed or there twice, a path or
 * an entry type the layout does not allow, a member or an archive too large,
 * too many members, a compressed tar, a truncated archive or bytes after its
 * end. The refused archives are made here with libarchive's writer, as ustar
 * and as pax. vmac_bundle_add's and vmac_bundle_write's refusals too. The
 * drivers folder and the signature's comment: test_bundle_folder.c. */
#include <archive.h>
#include <archive_entry.h>
#include <check.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../core/bundle/bundle.h"
#include "../../core/common/errors.h"
#include "check_main.h"

/* The folder of a bundle's tests (written so, the docs test does not take
 * its members for files of the source tree). */
#define TESTS "tests/"

#define USTAR ARCHIVE_FORMAT_TAR_USTAR
#define PAX ARCHIVE_FORMAT_TAR_PAX_RESTRICTED

/* The washer's files as a drivers folder would give them. */
static const char *const WASHER[][2] = {
    {"washer.lua", "return { name = 'washer', version = '1.2.0', io = {} }\n"},
    {"cycles/quick.lua", "return { fill_s = 30, wash_s = 300 }\n"},
    {"cycles/normal.lua", "return { fill_s = 60, wash_s = 1800 }\n"},
    {"plant.lua", "return { drum = true }\n"},
    {TESTS "washer_test.lua", "test('fills', function() end)\n"},
    {TESTS "washer_door_test.lua", "test('door', function() end)\n"},
};
#define NWASHER ((int)(sizeof(WASHER) / sizeof(WASHER[0])))

/* A member of a crafted archive: a plain file of data (len 0: strlen)
 * unless type says otherwise; listed in bundle.json unless unlisted. */
struct member {
	const char *path;
	const char *data;
	size_t len;
	unsigned type;    /* AE_IF*: 0 is AE_IFREG */
	const char *link; /* a symlink's target, or a hardlink's */
	int unlisted;
};

static struct vmac_bundle *washer_in_order(const int *order)
{
	struct vmac_bundle *b;
	char err[256] = "";
	int i;
	ck_assert_msg(vmac_bundle_new("washer", &b, err, sizeof(err)) == 0, "vmac_bundle_new(washer): %s", err);
	for (i = 0; i < NWASHER; i++) {
		const char *const *f = WASHER[order ? order[i] : i];
		ck_assert_msg(vmac_bundle_add(b, f[0], f[1], strlen(f[1]), err, sizeof(err)) == 0, "adding %s: %s",
		              f[0], err);
	}
	snprintf(b->version, sizeof(b->version), "1.2.0");
	snprintf(b->api, sizeof(b->api), "0.2");
	b->counter = 3;
	return b;
}

static char *written(const struct vmac_bundle *b, size_t *len)
{
	char err[256] = "", *data = NULL;
	ck_assert_msg(vmac_bundle_write(b, &data, len, err, sizeof(err)) == 0, "vmac_bundle_write: %s", err);
	ck_assert_msg(data != NULL && *len > 0, "vmac_bundle_write gave nothing");
	return data;
}

static char *washer_archive(size_t *len)
{
	struct vmac_bundle *b = washer_in_order(NULL);
	char *data = written(b, len);
	vmac_bundle_free(b);
	return data;
}

static struct vmac_bundle *read_ok(const void *data, size_t len, const char *what)
{
	struct vmac_bundle *b = NULL;
	char err[512] = "";
	int rc = vmac_bundle_read(data, len, &b, err, sizeof(err));
	ck_assert_msg(rc == 0 && b != NULL, "%s: refused (%d): %s", what, rc, err);
	return b;
}

/* vmac_bundle_read must refuse data with -VMAC_EBUNDLE, *out NULL and a
 * message holding says (NULL: any message). */
static void refused(const void *data, size_t len, const char *says, const char *what)
{
	struct vmac_bundle *b = NULL;
	char err[512] = "";
	int rc = vmac_bundle_read(data, len, &b, err, sizeof(err));
	ck_assert_msg(rc == -VMAC_EBUNDLE, "%s: vmac_bundle_read gave %d, not -VMAC_EBUNDLE (%s)", what, rc,
	              rc == 0 ? "it was accepted" : err);
	ck_assert_msg(b == NULL, "%s: refused, but *out is not NULL", what);
	if (!says)
		ck_assert_msg(err[0] != 0, "%s: refused without a message", what);
	else
		ck_assert_msg(strstr(err, says) != NULL, "%s: the message does not say \"%s\": \"%s\"", what, says,
		              err);
}

static size_t member_len(const struct member *m)
{
	return m->len ? m->len : m->data ? strlen(m->data) : 0;
}

/* bundle.json of driver washer, version 1.2.0, listing the members of m
 * that are not unlisted with the hash of their data (malloc'd). */
static char *meta_listing(const struct member *m, int n)
{
	json_t *files = json_object(), *j;
	char hash[VMAC_BUNDLE_HASH_LEN + 1], *text;
	int i;
	for (i = 0; i < n; i++) {
		if (m[i].unlisted)
			continue;
		vmac_bundle_hash(m[i].data ? m[i].data : "", member_len(&m[i]), hash);
		json_object_set_new(files, m[i].path, json_string(hash));
	}
	j = json_pack("{s:s, s:i, s:s, s:s, s:i, s:s, s:o}", "format", "vmac-bundle", "format_version", 1, "name",
	              "washer", "version", "1.2.0", "counter", 0, "api", "0.2", "files", files);
	ck_assert_msg(j != NULL, "json_pack of bundle.json failed");
	text = json_dumps(j, JSON_SORT_KEYS | JSON_COMPACT);
	json_decref(j);
	return text;
}

static void craft_entry(struct archive *a, const char *path, const char *data, size_t len, unsigned type,
                        const char *link)
{
	struct archive_entry *e = archive_entry_new();
	archive_entry_set_pathname(e, path);
	archive_entry_set_filetype(e, type ? type : AE_IFREG);
	archive_entry_set_perm(e, 0644);
	archive_entry_set_size(e, type && type != AE_IFREG ? 0 : (la_int64_t)len);
	if (type == AE_IFLNK)
		archive_entry_set_symlink(e, link);
	else if (link)
		archive_entry_set_hardlink(e, link);
	if (type == AE_IFCHR || type == AE_IFBLK)
		archive_entry_set_rdev(e, 0x0103);
	ck_assert_msg(archive_write_header(a, e) == ARCHIVE_OK, "writing the header of %s: %s", path,
	              archive_error_string(a));
	if (len && archive_entry_size(e) > 0)
		ck_assert_msg(archive_write_data(a, data, len) == (la_ssize_t)len, "writing %s: %s", path,
		              archive_error_string(a));
	archive_entry_free(e);
}

/* An archive of format (USTAR or PAX) through filter (ARCHIVE_FILTER_NONE
 * or _GZIP): bundle.json holding meta first unless meta is NULL, then
 * every member of m (malloc'd, *len bytes). */
static char *craft_filtered(int format, int filter, const char *meta, const struct member *m, int n, size_t *len)
{
	struct archive *a = archive_write_new();
	size_t cap = (meta ? strlen(meta) : 0) + 4096, used = 0;
	char *buf;
	int i;
	for (i = 0; i < n; i++)
		cap += member_len(&m[i]) + 2048;
	buf = malloc(cap);
	ck_assert_msg(a != NULL && buf != NULL, "out of memory crafting an archive");
	ck_assert_int_eq(archive_write_set_format(a, format), ARCHIVE_OK);
	ck_assert_msg(archive_write_add_filter(a, filter) >= ARCHIVE_WARN, "filter %d: %s", filter,
	              archive_error_string(a));
	ck_assert_int_eq(archive_write_set_bytes_in_last_block(a, 1), ARCHIVE_OK);
	ck_assert_int_eq(archive_write_open_memory(a, buf, cap, &used), ARCHIVE_OK);
	if (meta)
		craft_entry(a, "bundle.json", meta, strlen(meta), AE_IFREG, NULL);
	for (i = 0; i < n; i++)
		craft_entry(a, m[i].path, m[i].data, member_len(&m[i]), m[i].type, m[i].link);
	ck_assert_msg(archive_write_close(a) == ARCHIVE_OK, "closing a crafted archive: %s", archive_error_string(a));
	archive_write_free(a);
	*len = used;
	return buf;
}

static char *craft(int format, const char *meta, const struct member *m, int n, size_t *len)
{
	return craft_filtered(format, ARCHIVE_FILTER_NONE, meta, m, n, len);
}

/* A crafted archive whose bundle.json lists its members (meta_listing). */
static char *craft_listed(int format, const struct member *m, int n, size_t *len)
{
	char *meta = meta_listing(m, n), *data = craft(format, meta, m, n, len);
	free(meta);
	return data;
}

/* The driver of a crafted bundle. */
static const struct member DRIVER = {"washer.lua", "return {}\n", 0, 0, NULL, 0};

/* ---- writing ---- */

START_TEST(the_same_files_in_any_order_give_the_same_bytes)
{
	static const int orders[][NWASHER] = {{5, 4, 3, 2, 1, 0}, {3, 0, 5, 1, 4, 2}};
	struct vmac_bundle *b;
	char err[256] = "", *first, *other;
	size_t first_len, other_len, i;
	first = washer_archive(&first_len);
	for (i = 0; i < 2; i++) {
		b = washer_in_order(orders[i]);
		other = written(b, &other_len);
		ck_assert_msg(other_len == first_len && memcmp(first, other, first_len) == 0,
		              "order %zu gives other bytes (%zu, not %zu)", i, other_len, first_len);
		free(other);
		vmac_bundle_free(b);
	}
	/* A file replaced by vmac_bundle_add is as if it had been added so. */
	b = washer_in_order(NULL);
	ck_assert_msg(vmac_bundle_add(b, "plant.lua", "old", 3, err, sizeof(err)) == 0, "replacing: %s", err);
	ck_assert_int_eq(b->nfiles, NWASHER);
	ck_assert_str_eq(vmac_bundle_get(b, "plant.lua")->data, "old");
	ck_assert_msg(vmac_bundle_add(b, "plant.lua", WASHER[3][1], strlen(WASHER[3][1]), err, sizeof(err)) == 0, "%s",
	              err);
	other = written(b, &other_len);
	ck_assert_msg(other_len == first_len && memcmp(first, other, first_len) == 0,
	              "a replaced file changes the bytes");
	ck_assert_msg(vmac_bundle_is_archive(first, first_len), "vmac_bundle_is_archive says no to a bundle");
	ck_assert_msg(!vmac_bundle_is_archive(WASHER[0][1], strlen(WASHER[0][1])), "a driver's text is taken for one");
	free(other);
	free(first);
	vmac_bundle_free(b);
}
END_TEST

START_TEST(a_written_bundle_reads_back_as_it_was)
{
	struct vmac_bundle *b;
	char hash[VMAC_BUNDLE_HASH_LEN + 1], *data;
	size_t len;
	int i;
	data = washer_archive(&len);
	b = read_ok(data, len, "the washer's bundle");
	ck_assert_str_eq(b->name, "washer");
	ck_assert_str_eq(b->version, "1.2.0");
	ck_assert_str_eq(b->api, "0.2");
	ck_assert_uint_eq(b->counter, 3);
	ck_assert_msg(b->nfiles == NWASHER, "%d files read back, %d written", b->nfiles, NWASHER);
	for (i = 0; i < NWASHER; i++) {
		const struct vmac_bundle_file *f = vmac_bundle_get(b, WASHER[i][0]);
		ck_assert_msg(f != NULL, "%s did not come back", WASHER[i][0]);
		ck_assert_msg(f->len == strlen(WASHER[i][1]) && strcmp(f->data, WASHER[i][1]) == 0,
		              "%s came back as \"%s\"", f->path, f->data);
		vmac_bundle_hash(WASHER[i][1], strlen(WASHER[i][1]), hash);
		ck_assert_msg(strcmp(f->hash, hash) == 0, "%s: hash %s, not %s", f->path, f->hash, hash);
	}
	for (i = 1; i < b->nfiles; i++)
		ck_assert_msg(strcmp(b->files[i - 1].path, b->files[i].path) < 0, "files not in path order at %s",
		              b->files[i].path);
	ck_assert_msg(vmac_bundle_driver(b) == vmac_bundle_get(b, "washer.lua"), "the driver is not washer.lua");
	vmac_bundle_free(b);
	free(data);
}
END_TEST

START_TEST(tar_lists_bundle_json_first_then_the_files_in_path_order)
{
	static const char *const order[] = {"bundle.json", "cycles/normal.lua",          "cycles/quick.lua",
	                                    "plant.lua",   TESTS "washer_door_test.lua", TESTS "washer_test.lua",
	                                    "washer.lua"};
	char path[] = "/tmp/vmac-test-bundle-XXXXXX", cmd[256], line[512], mode[16], owner[32], day[16], time_s[16],
	     name[128];
	size_t len, size;
	char *data = washer_archive(&len);
	int fd = mkstemp(path), n = 0;
	FILE *p;
	ck_assert_msg(fd >= 0 && write(fd, data, len) == (ssize_t)len && close(fd) == 0, "writing %s failed", path);
	if (system("tar --version 2>/dev/null | grep -q 'GNU tar'") != 0) {
		unlink(path);
		free(data);
		vmac_test_cannot_run("the bundle listed by GNU tar", "GNU tar is not installed");
		return;
	}
	snprintf(cmd, sizeof(cmd), "TZ=UTC tar --numeric-owner --full-time -tvf %s 2>&1", path);
	ck_assert_msg((p = popen(cmd, "r")) != NULL, "popen(%s) failed", cmd);
	while (fgets(line, sizeof(line), p)) {
		ck_assert_msg(sscanf(line, "%15s %31s %zu %15s %15s %127s", mode, owner, &size, day, time_s, name) == 6,
		              "tar printed a line that is not a member: %s", line);
		ck_assert_msg(n < 7, "tar lists more members than 7: %s", line);
		ck_assert_msg(strcmp(name, order[n]) == 0, "tar lists %s where %s should be", name, order[n]);
		ck_assert_msg(strcmp(mode, "-rw-r--r--") == 0, "%s has mode %s, not -rw-r--r--", name, mode);
		ck_assert_msg(strcmp(owner, "0/0") == 0, "%s is owned by %s, not 0/0", name, owner);
		ck_assert_msg(strcmp(day, "1970-01-01") == 0 && strcmp(time_s, "00:00:00") == 0,
		              "%s has time %s %s, not 0", name, day, time_s);
		n++;
	}
	ck_assert_msg(pclose(p) == 0, "%s failed", cmd);
	ck_assert_msg(n == 7, "tar lists %d members, not 7", n);
	unlink(path);
	free(data);
}
END_TEST

START_TEST(bundle_json_is_compact_with_sorted_keys)
{
	size_t len;
	char *data = washer_archive(&len), hash[VMAC_BUNDLE_HASH_LEN + 1], want[1024];
	const char *meta = data + 512;
	vmac_bundle_hash(WASHER[0][1], strlen(WASHER[0][1]), hash);
	ck_assert_str_eq(data, "bundle.json");
	ck_assert_msg(strncmp(meta, "{\"api\":\"0.2\",\"counter\":3,\"files\":{\"cycles/normal.lua\":\"", 55) == 0,
	              "bundle.json does not start as it should: %.80s", meta);
	snprintf(want, sizeof(want),
	         "\"washer.lua\":\"%s\"},\"format\":\"vmac-bundle\",\"format_version\":1,"
	         "\"name\":\"washer\",\"version\":\"1.2.0\"}",
	         hash);
	ck_assert_msg(strstr(meta, want) != NULL, "bundle.json does not end as it should: %s", meta);
	free(data);
}
END_TEST

START_TEST(write_refuses_a_bundle_without_version_api_or_driver)
{
	struct vmac_bundle *b = washer_in_order(NULL), *bare;
	char err[256] = "", *data = (char *)1;
	size_t len = 1;
	b->version[0] = 0;
	ck_assert_int_eq(vmac_bundle_write(b, &data, &len, err, sizeof(err)), -VMAC_EBUNDLE);
	ck_assert_msg(data == NULL && len == 0, "a refused write leaves *data and *len set");
	ck_assert_msg(strstr(err, "needs a version") != NULL, "%s", err);
	snprintf(b->version, sizeof(b->version), "1.2.0");
	b->api[0] = 0;
	ck_assert_int_eq(vmac_bundle_write(b, &data, &len, err, sizeof(err)), -VMAC_EBUNDLE);
	ck_assert_msg(vmac_bundle_new("washer", &bare, err, sizeof(err)) == 0, "%s", err);
	snprintf(bare->version, sizeof(bare->version), "1.2.0");
	snprintf(bare->api, sizeof(bare->api), "0.2");
	ck_assert_int_eq(vmac_bundle_add(bare, "plant.lua", "x", 1, err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_bundle_write(bare, &data, &len, err, sizeof(err)), -VMAC_EBUNDLE);
	ck_assert_msg(strstr(err, "washer.lua") != NULL, "no driver, and the message does not say so: %s", err);
	vmac_bundle_free(bare);
	vmac_bundle_free(b);
}
END_TEST

START_TEST(add_refuses_what_the_layout_does_not_allow)
{
	static const char *const bad[] = {"../etc/passwd",
	                                  "/abs.lua",
	                                  "cycles/../../x.lua",
	                                  "cycles/sub/x.lua",
	                                  TESTS ".hidden.lua",
	                                  "other.lua",
	                                  "cycles/a-b.lua",
	                                  "cycles/.lua",
	                                  "washer.lua.bak",
	                                  TESTS "x.txt",
	                                  "Washer.lua",
	                                  "bundle.json",
	                                  "cycles/",
	                                  "",
	                                  "plants/washer.lua",
	                                  TESTS "a/b_test.lua",
	                                  "./washer.lua"};
	struct vmac_bundle *b, *named;
	char err[256], big_name[80];
	size_t i;
	char *big = calloc(1, VMAC_BUNDLE_FILE_MAX + 1);
	ck_assert_ptr_nonnull(big);
	b = washer_in_order(NULL);
	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		err[0] = 0;
		ck_assert_msg(vmac_bundle_add(b, bad[i], "x", 1, err, sizeof(err)) == -VMAC_EBUNDLE, "%s was added",
		              bad[i]);
		ck_assert_msg(strstr(err, bad[i]) != NULL, "the refusal of \"%s\" does not name it: %s", bad[i], err);
	}
	snprintf(big_name, sizeof(big_name), "cycles/%0*d.lua", VMAC_BUNDLE_PATH_MAX - 11, 0);
	ck_assert_msg(vmac_bundle_add(b, big_name, "x", 1, err, sizeof(err)) == -VMAC_EBUNDLE, "a %zu-byte path added",
	              strlen(big_name));
	ck_assert_msg(vmac_bundle_add(b, "cycles/big.lua", big, VMAC_BUNDLE_FILE_MAX + 1, err, sizeof(err)) ==
	                  -VMAC_EBUNDLE,
	              "a member over VMAC_BUNDLE_FILE_MAX was added");
	ck_assert_msg(strstr(err, "cycles/big.lua") && strstr(err, "larger"), "%s", err);
	ck_assert_msg(vmac_bundle_add(b, "cycles/big.lua", big, VMAC_BUNDLE_FILE_MAX, err, sizeof(err)) == 0,
	              "a member of VMAC_BUNDLE_FILE_MAX bytes refused: %s", err);
	ck_assert_int_eq(b->nfiles, NWASHER + 1);
	ck_assert_msg(vmac_bundle_new("../x", &named, err, sizeof(err)) == -VMAC_EBUNDLE && named == NULL,
	              "a bundle of driver ../x was made");
	vmac_bundle_free(b);
	free(big);
}
END_TEST

START_TEST(add_takes_at_most_VMAC_BUNDLE_FILES_members)
{
	struct vmac_bundle *b;
	char err[256] = "", path[VMAC_BUNDLE_PATH_MAX];
	int i;
	ck_assert_int_eq(vmac_bundle_new("washer", &b, err, sizeof(err)), 0);
	for (i = 0; i < VMAC_BUNDLE_FILES; i++) {
		snprintf(path, sizeof(path), "cycles/p%03d.lua", i);
		ck_assert_msg(vmac_bundle_add(b, path, "x", 1, err, sizeof(err)) == 0, "member %d refused: %s", i, err);
	}
	ck_assert_int_eq(vmac_bundle_add(b, "washer.lua", "x", 1, err, sizeof(err)), -VMAC_EBUNDLE);
	ck_assert_msg(strstr(err, "too many files") && strstr(err, "washer.lua"), "%s", err);
	ck_assert_msg(vmac_bundle_add(b, "cycles/p007.lua", "y", 1, err, sizeof(err)) == 0,
	              "replacing a member of a full bundle refused: %s", err);
	ck_assert_int_eq(b->nfiles, VMAC_BUNDLE_FILES);
	vmac_bundle_free(b);
}
END_TEST

START_TEST(write_refuses_a_bundle_larger_than_a_host_reads)
{
	struct vmac_bundle *b = washer_in_order(NULL);
	char err[256] = "", path[32], *data = NULL;
	size_t len = 0;
	char *big = calloc(1, VMAC_BUNDLE_FILE_MAX);
	int i;
	ck_assert_ptr_nonnull(big);
	for (i = 0; i < 4; i++) {
		snprintf(path, sizeof(path), "cycles/big%d.lua", i);
		ck_assert_int_eq(vmac_bundle_add(b, path, big, VMAC_BUNDLE_FILE_MAX, err, sizeof(err)), 0);
	}
	ck_assert_msg(vmac_bundle_write(b, &data, &len, err, sizeof(err)) == -VMAC_EBUNDLE,
	              "a bundle over VMAC_BUNDLE_MAX was written (%zu bytes): no host would read it", len);
	ck_assert_msg(data == NULL && strstr(err, "4 MiB") != NULL, "%s", err);
	vmac_bundle_free(b);
	free(big);
}
END_TEST

/* ---- reading ---- */

START_TEST(what_is_not_a_tar_is_refused)
{
	static const char lua[] = "-- washer\nreturn { name = 'washer', version = '1.2.0' }\n";
	static char garbage[4096], zeros[1024];
	size_t i;
	for (i = 0; i < sizeof(garbage); i++)
		garbage[i] = (char)(i * 7 + 3);
	refused(garbage, sizeof(garbage), "not a bundle", "4 KiB of garbage");
	refused("", 0, "not a bundle", "nothing");
	refused(lua, strlen(lua), "not a bundle", "a driver's Lua text");
	refused(zeros, sizeof(zeros), "not a bundle", "a tar of no member (its end blocks alone)");
}
END_TEST

#define META(format, format_version, name, version, counter)                                                           \
	"{\"format\":" format ",\"format_version\":" format_version ",\"name\":" name ",\"version\":" version          \
	",\"counter\":" counter ",\"api\":\"0.2\",\"files\":{}}"
#define VMB "\"vmac-bundle\""

START_TEST(bundle_json_must_come_first_and_say_what_the_bundle_is)
{
	/* Each bundle.json alone in an archive: the text, what the refusal says, what it is. */
	static const char *const metas[][3] = {
	    {"{\"format\":", "bundle.json is not JSON", "a cut JSON text"},
	    {"[]", "bundle.json is not a JSON object", "an array"},
	    {"{\"format\":\"vmac-bundle\",\"format_version\":1,\"name\":\"washer\",\"version\":\"1\",\"counter\":0,"
	     "\"files\":{}}",
	     "bundle.json lacks the field api", "no api"},
	    {"{\"format\":\"vmac-bundle\",\"format\":\"vmac-bundle\"}", "duplicate", "a key twice"},
	    {META("\"vmac-archive\"", "1", "\"washer\"", "\"1.2.0\"", "0"), "vmac-archive", "format vmac-archive"},
	    {META("7", "1", "\"washer\"", "\"1.2.0\"", "0"), "format is not a string", "a format that is a number"},
	    {META(VMB, "2", "\"washer\"", "\"1.2.0\"", "0"), "format version 2", "format_version 2"},
	    {META(VMB, "\"1\"", "\"washer\"", "\"1.2.0\"", "0"), "format_version is not a whole number",
	     "format_version a string"},
	    {META(VMB, "1", "\"../x\"", "\"1.2.0\"", "0"), "\"../x\" is not a driver's name", "name ../x"},
	    {META(VMB, "1", "\".x\"", "\"1.2.0\"", "0"), "\".x\" is not a driver's name", "name .x"},
	    {META(VMB, "1", "\"a/b\"", "\"1.2.0\"", "0"), "\"a/b\" is not a driver's name", "name a/b"},
	    {META(VMB, "1", "\"\"", "\"1.2.0\"", "0"), "\"\" is not a driver's name", "an empty name"},
	    {META(VMB, "1", "\"washer\"", "\"1 0\"", "0"), "version \"1 0\"", "a version with a space"},
	    {META(VMB, "1", "\"washer\"", "\"\"", "0"), "version \"\"", "an empty version"},
	    {META(VMB, "1", "\"washer\"", "\"1234567890123456789012345678901234567890\"", "0"),
	     "version \"1234567890123456789012345678901234567890\"", "a version of 40 characters"},
	    {META(VMB, "1", "\"washer\"", "\"1.2.0\"", "-1"), "counter -1 is below 0", "counter -1"},
	    {META(VMB, "1", "\"washer\"", "\"1.2.0\"", "1.5"), "counter is not a whole number", "counter 1.5"},
	    {META(VMB, "1", "\"washer\"", "\"1.2.0\"", "99999999999999999999"), "not JSON", "counter 10^20"},
	    {"{\"format\":\"vmac-bundle\",\"format_version\":1,\"name\":\"washer\",\"version\":\"1\",\"counter\":0,"
	     "\"api\":\"\",\"files\":{}}",
	     "api \"\" is not a driver API", "an empty api"},
	    {"{\"format\":\"vmac-bundle\",\"format_version\":1,\"name\":\"washer\",\"version\":\"1\",\"counter\":0,"
	     "\"api\":\"0.2\",\"files\":[]}",
	     "files is not an object", "files an array"},
	    {META(VMB, "1", "\"washer\"", "\"1.2.0\"", "0"), "holds no washer.lua", "no driver"},
	};
	struct member driver[] = {DRIVER, {"bundle.json", "{}", 0, 0, NULL, 0}};
	char *data, *meta, what[128];
	size_t i, len;
	for (i = 0; i < sizeof(metas) / sizeof(metas[0]); i++) {
		data = craft(USTAR, metas[i][0], NULL, 0, &len);
		snprintf(what, sizeof(what), "bundle.json of %s", metas[i][2]);
		refused(data, len, metas[i][1], what);
		free(data);
	}
	data = craft(USTAR, NULL, driver, 1, &len);
	refused(data, len, "its first member is washer.lua, not bundle.json", "no bundle.json");
	free(data);
	meta = meta_listing(driver, 1);
	driver[1].data = meta;
	data = craft(USTAR, NULL, driver, 2, &len);
	refused(data, len, "its first member is washer.lua, not bundle.json", "bundle.json second");
	free(data);
	free(meta);
	meta = calloc(1, 70000);
	memset(meta, ' ', 69999);
	meta[0] = '{';
	meta[69998] = '}';
	data = craft(USTAR, meta, NULL, 0, &len);
	refused(data, len, "bundle.json is larger", "a bundle.json of 70,000 bytes");
	free(data);
	free(meta);
}
END_TEST

START_TEST(every_member_is_listed_and_every_listed_file_is_there)
{
	struct member m[] = {DRIVER, {"cycles/quick.lua", "return {}\n", 0, 0, NULL, 1}};
	char *meta, *data;
	size_t len;
	struct vmac_bundle *b;
	data = craft_listed(USTAR, m, 2, &len);
	refused(data, len, "cycles/quick.lua is not listed in bundle.json", "a member not listed");
	free(data);
	m[1].unlisted = 0;
	meta = meta_listing(m, 2);
	data = craft(USTAR, meta, m, 1, &len);
	refused(data, len, "bundle.json lists cycles/quick.lua, which the bundle does not hold",
	        "a listed file missing");
	free(data);
	free(meta);
	data = craft_listed(PAX, m + 1, 1, &len);
	refused(data, len, "holds no washer.lua", "a bundle without its driver");
	free(data);
	data = craft_listed(PAX, m, 2, &len);
	b = read_ok(data, len, "a bundle written as pax");
	ck_assert_int_eq(b->nfiles, 2);
	vmac_bundle_free(b);
	free(data);
}
END_TEST

START_TEST(a_changed_byte_is_caught_by_its_hash)
{
	char hash[VMAC_BUNDLE_HASH_LEN + 1], *at;
	size_t len;
	char *data = washer_archive(&len);
	ck_assert_ptr_nonnull(at = memmem(data, len, "fill_s = 30", 11));
	at[9] = '4';
	refused(data, len, "cycles/quick.lua does not match its hash in bundle.json", "a byte of a member changed");
	at[9] = '3';
	vmac_bundle_free(read_ok(data, len, "the byte put back"));
	vmac_bundle_hash(WASHER[1][1], strlen(WASHER[1][1]), hash);
	ck_assert_ptr_nonnull(at = memmem(data, len, hash, VMAC_BUNDLE_HASH_LEN));
	at[10] = at[10] == 'a' ? 'b' : 'a';
	refused(data, len, "cycles/quick.lua does not match its hash in bundle.json", "a hash in bundle.json changed");
	free(data);
}
END_TEST

START_TEST(a_member_twice_is_refused)
{
	struct member twice[] = {DRIVER, DRIVER};
	struct member meta_again[] = {DRIVER, {"bundle.json", "{}", 0, 0, NULL, 1}};
	size_t len;
	char *data = craft_listed(USTAR, twice, 2, &len);
	refused(data, len, "washer.lua is in the bundle twice", "washer.lua twice");
	free(data);
	data = craft_listed(USTAR, meta_again, 2, &len);
	refused(data, len, "bundle.json is in the bundle twice", "bundle.json twice");
	free(data);
}
END_TEST

START_TEST(members_the_layout_does_not_allow_are_refused_by_name)
{
	static const char *const bad[] = {"../etc/passwd",     "/abs.lua",   "cycles/../../x.lua", "cycles/sub/x.lua",
	                                  TESTS ".hidden.lua", "other.lua",  "cycles/a-b.lua",     "plants/washer.lua",
	                                  "washer.lua.orig",   "./plant.lua"};
	static const int formats[] = {USTAR, PAX};
	struct member m[] = {DRIVER, {NULL, "return {}\n", 0, 0, NULL, 0}};
	char what[128], *data;
	size_t i, f, len;
	for (f = 0; f < 2; f++)
		for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
			m[1].path = bad[i];
			data = craft_listed(formats[f], m, 2, &len);
			snprintf(what, sizeof(what), "a member %s (%s)", bad[i], f ? "pax" : "ustar");
			refused(data, len, bad[i], what);
			free(data);
		}
}
END_TEST

START_TEST(only_plain_files_are_members)
{
	static const struct member odd[] = {
	    {"cycles/", NULL, 0, AE_IFDIR, NULL, 0},
	    {"cycles/link.lua", NULL, 0, AE_IFLNK, "../washer.lua", 0},
	    {"cycles/hard.lua", NULL, 0, 0, "washer.lua", 0},
	    {"cycles/dev.lua", NULL, 0, AE_IFCHR, NULL, 0},
	    {"cycles/blk.lua", NULL, 0, AE_IFBLK, NULL, 0},
	    {"cycles/fifo.lua", NULL, 0, AE_IFIFO, NULL, 0},
	    {"cycles/hard2.lua", "return {}\n", 0, 0, "washer.lua", 0}, /* a hardlink with data of its own */
	};
	static const int formats[] = {USTAR, PAX};
	struct member m[] = {DRIVER, DRIVER};
	char what[128], says[128], *data;
	size_t i, f, len;
	for (f = 0; f < 2; f++)
		for (i = 0; i < sizeof(odd) / sizeof(odd[0]); i++) {
			m[1] = odd[i];
			data = craft_listed(formats[f], m, 2, &len);
			snprintf(what, sizeof(what), "a member %s of type %o%s (%s)", odd[i].path, odd[i].type,
			         odd[i].link && !odd[i].type ? " (a hardlink)" : "", f ? "pax" : "ustar");
			snprintf(says, sizeof(says), "%s is not a plain file", odd[i].path);
			refused(data, len, says, what);
			free(data);
		}
}
END_TEST

START_TEST(members_and_archives_have_their_size_bounds)
{
	struct member m[] = {DRIVER,
	                     {"cycles/b0.lua", NULL, VMAC_BUNDLE_FILE_MAX + 1, 0, NULL, 0},
	                     {"cycles/b1.lua", NULL, VMAC_BUNDLE_FILE_MAX, 0, NULL, 0},
	                     {"cycles/b2.lua", NULL, VMAC_BUNDLE_FILE_MAX, 0, NULL, 0},
	                     {"cycles/b3.lua", NULL, VMAC_BUNDLE_FILE_MAX, 0, NULL, 0},
	                     {"cycles/b4.lua", NULL, VMAC_BUNDLE_FILE_MAX, 0, NULL, 0}};
	char *big = malloc(VMAC_BUNDLE_FILE_MAX + 1), *data;
	size_t i, len;
	ck_assert_ptr_nonnull(big);
	memset(big, '-', VMAC_BUNDLE_FILE_MAX + 1);
	for (i = 1; i < 6; i++)
		m[i].data = big;
	data = craft_listed(USTAR, m, 2, &len);
	refused(data, len, "cycles/b0.lua is larger than a bundle's member may be", "a member of 1 MiB and a byte");
	free(data);
	m[1].len = VMAC_BUNDLE_FILE_MAX;
	data = craft_listed(USTAR, m, 2, &len);
	vmac_bundle_free(read_ok(data, len, "a member of exactly 1 MiB"));
	free(data);
	data = craft_listed(USTAR, m, 6, &len);
	ck_assert_uint_gt(len, VMAC_BUNDLE_MAX);
	refused(data, len, "at most 4 MiB", "an archive of five 1 MiB members");
	free(data);
	free(big);
}
END_TEST

START_TEST(at_most_VMAC_BUNDLE_FILES_members_are_read)
{
	static char paths[VMAC_BUNDLE_FILES + 1][24];
	struct member m[VMAC_BUNDLE_FILES + 1] = {DRIVER};
	struct vmac_bundle *b;
	size_t len;
	char *data;
	int i;
	for (i = 1; i <= VMAC_BUNDLE_FILES; i++) {
		snprintf(paths[i], sizeof(paths[i]), "cycles/p%03d.lua", i);
		m[i] = (struct member){paths[i], "return 1\n", 0, 0, NULL, 0};
	}
	data = craft_listed(USTAR, m, VMAC_BUNDLE_FILES, &len);
	b = read_ok(data, len, "a bundle of VMAC_BUNDLE_FILES members");
	ck_assert_int_eq(b->nfiles, VMAC_BUNDLE_FILES);
	vmac_bundle_free(b);
	free(data);
	data = craft_listed(USTAR, m, VMAC_BUNDLE_FILES + 1, &len);
	refused(data, len, "too many files in the bundle", "a bundle of VMAC_BUNDLE_FILES + 1 members");
	free(data);
}
END_TEST

START_TEST(a_compressed_tar_is_refused)
{
	static const int filters[] = {ARCHIVE_FILTER_GZIP, ARCHIVE_FILTER_COMPRESS};
	struct member m[] = {DRIVER};
	char *meta = meta_listing(m, 1), *data, what[64];
	size_t i, len;
	for (i = 0; i < 2; i++) {
		data = craft_filtered(USTAR, filters[i], meta, m, 1, &len);
		ck_assert_msg(len > 2 && (unsigned char)data[0] == 0x1f && (unsigned char)data[1] == (i ? 0x9d : 0x8b),
		              "filter %zu did not compress", i);
		snprintf(what, sizeof(what), "a bundle %s", i ? "compressed (.Z)" : "gzip'd");
		refused(data, len, "not a bundle", what);
		free(data);
	}
	free(meta);
}
END_TEST

START_TEST(a_truncated_bundle_is_refused_wherever_it_is_cut)
{
	static const size_t into_block[] = {0, 1, 200, 511};
	char what[64], *longer;
	size_t len, block, i, cut;
	char *data = washer_archive(&len);
	for (block = 0; block < len; block += 512)
		for (i = 0; i < sizeof(into_block) / sizeof(into_block[0]); i++) {
			if ((cut = block + into_block[i]) >= len)
				continue;
			snprintf(what, sizeof(what), "the bundle cut at %zu of %zu bytes", cut, len);
			refused(data, cut, NULL, what);
		}
	refused(data, len - 1024, "cut short", "the bundle without its end-of-archive blocks");
	refused(data, len - 512, "cut short", "the bundle without its last zero block");
	ck_assert_ptr_nonnull(longer = calloc(1, 2 * len + 1024));
	memcpy(longer, data, len);
	refused(longer, len + 1, "after the end of the archive", "a zero byte after the end");
	refused(longer, len + 1024, "after the end of the archive", "two more zero blocks after the end");
	memcpy(longer + len, "garbage", 7);
	refused(longer, len + 7, "after the end of the archive", "garbage after the end");
	memcpy(longer + len, data, len);
	refused(longer, 2 * len, "after the end of the archive", "two bundles one after the other");
	memcpy(longer, data, len);
	longer[len - 1] = 'x';
	refused(longer, len, NULL, "a byte of the end blocks not zero");
	free(longer);
	free(data);
}
END_TEST

static void add_read_tests(TCase *r)
{
	tcase_add_test(r, what_is_not_a_tar_is_refused);
	tcase_add_test(r, bundle_json_must_come_first_and_say_what_the_bundle_is);
	tcase_add_test(r, every_member_is_listed_and_every_listed_file_is_there);
	tcase_add_test(r, a_changed_byte_is_caught_by_its_hash);
	tcase_add_test(r, a_member_twice_is_refused);
	tcase_add_test(r, members_the_layout_does_not_allow_are_refused_by_name);
	tcase_add_test(r, only_plain_files_are_members);
	tcase_add_test(r, members_and_archives_have_their_size_bounds);
	tcase_add_test(r, at_most_VMAC_BUNDLE_FILES_members_are_read);
	tcase_add_test(r, a_compressed_tar_is_refused);
	tcase_add_test(r, a_truncated_bundle_is_refused_wherever_it_is_cut);
}
Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("bundle");
	TCase *w = tcase_create("write"), *r = tcase_create("read");
	tcase_set_timeout(r, 60);
	tcase_add_test(w, the_same_files_in_any_order_give_the_same_bytes);
	tcase_add_test(w, a_written_bundle_reads_back_as_it_was);
	tcase_add_test(w, tar_lists_bundle_json_first_then_the_files_in_path_order);
	tcase_add_test(w, bundle_json_is_compact_with_sorted_keys);
	tcase_add_test(w, write_refuses_a_bundle_without_version_api_or_driver);
	tcase_add_test(w, add_refuses_what_the_layout_does_not_allow);
	tcase_add_test(w, add_takes_at_most_VMAC_BUNDLE_FILES_members);
	tcase_add_test(w, write_refuses_a_bundle_larger_than_a_host_reads);
	add_read_tests(r);
	suite_add_tcase(s, w);
	suite_add_tcase(s, r);
	return s;
}
