/* libFuzzer harness for bundles (core/bundle/bundle.c): any bytes read as
 * a bundle, as a host reads an upload or a version from its store. What
 * must hold: vmac_bundle_read takes them or refuses with -VMAC_EBUNDLE (or
 * -ENOMEM) and a message, leaving *out NULL; a bundle it takes is one
 * bundle.h describes (a driver's name, a version and an api, its driver
 * among at most VMAC_BUNDLE_FILES files in path order, each NUL-terminated,
 * at most VMAC_BUNDLE_FILE_MAX bytes and of the hash it carries); written
 * again it reads back equal, and that archive written once more gives the
 * same bytes; its trusted comment passes vmac_bundle_comment_check. Seeds:
 * tests/fuzz/corpus-bundle/ (tests/fuzz/make_bundle_corpus.py: bundles of
 * the shipped drivers by vmac bundle, and broken ones); words in
 * tests/fuzz/bundle.dict. */
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/bundle/bundle.h"
#include "../../core/common/errors.h"
#include "../../core/common/name.h"
#include "fuzz.h"

static void broken(const char *what, const char *err)
{
	fprintf(stderr, "fuzz_bundle: %s%s%s\n", what, err ? ": " : "", err ? err : "");
	abort();
}

/* What bundle.h promises of a bundle vmac_bundle_read took. */
static void check_bundle(const struct vmac_bundle *b)
{
	char hash[VMAC_BUNDLE_HASH_LEN + 1];
	int i;
	if (!vmac_valid_name(b->name, VMAC_BUNDLE_NAME_MAX) || !b->version[0] || !b->api[0] ||
	    !memchr(b->version, 0, sizeof(b->version)) || !memchr(b->api, 0, sizeof(b->api)))
		broken("a bundle taken with a bad name, version or api", b->name);
	if (!vmac_bundle_driver(b))
		broken("a bundle taken without its driver", b->name);
	if (b->nfiles < 1 || b->nfiles > VMAC_BUNDLE_FILES)
		broken("a bundle taken with too many files", NULL);
	for (i = 0; i < b->nfiles; i++) {
		const struct vmac_bundle_file *f = &b->files[i];
		if (i > 0 && strcmp(b->files[i - 1].path, f->path) >= 0)
			broken("files out of path order at", f->path);
		if (f->len > VMAC_BUNDLE_FILE_MAX || f->data[f->len] != 0)
			broken("a file too large or not NUL-terminated", f->path);
		vmac_bundle_hash(f->data, f->len, hash);
		if (strcmp(hash, f->hash) != 0)
			broken("a file taken whose hash is not its data's", f->path);
	}
}

static void check_same(const struct vmac_bundle *a, const struct vmac_bundle *b)
{
	int i;
	if (strcmp(a->name, b->name) != 0 || strcmp(a->version, b->version) != 0 || strcmp(a->api, b->api) != 0 ||
	    a->counter != b->counter || a->nfiles != b->nfiles)
		broken("written and read again, the metadata changed", a->name);
	for (i = 0; i < a->nfiles; i++)
		if (strcmp(a->files[i].path, b->files[i].path) != 0 || a->files[i].len != b->files[i].len ||
		    memcmp(a->files[i].data, b->files[i].data, a->files[i].len) != 0 ||
		    strcmp(a->files[i].hash, b->files[i].hash) != 0)
			broken("written and read again, a file changed", a->files[i].path);
}

/* b written, read back, written again: the same bundle, the same bytes. */
static void check_round_trip(const struct vmac_bundle *b)
{
	struct vmac_bundle *again = NULL;
	char err[512] = "", *first, *second;
	size_t first_len, second_len;
	if (vmac_bundle_write(b, &first, &first_len, err, sizeof(err)) != 0)
		broken("a bundle taken cannot be written", err);
	if (vmac_bundle_read(first, first_len, &again, err, sizeof(err)) != 0)
		broken("a bundle taken and written is refused", err);
	check_same(b, again);
	if (vmac_bundle_write(again, &second, &second_len, err, sizeof(err)) != 0)
		broken("a bundle written and read cannot be written", err);
	if (second_len != first_len || memcmp(first, second, first_len) != 0)
		broken("the same bundle written twice gives other bytes", b->name);
	free(first);
	free(second);
	vmac_bundle_free(again);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct vmac_bundle *b = (struct vmac_bundle *)&b;
	char err[512] = "", comment[256];
	int rc = vmac_bundle_read(data, size, &b, err, sizeof(err));
	(void)vmac_bundle_is_archive(data, size);
	if (rc != 0) {
		if ((rc != -VMAC_EBUNDLE && rc != -ENOMEM) || b != NULL || !err[0])
			broken("a refusal without -VMAC_EBUNDLE, a message, or with *out set", err);
		return 0;
	}
	if (!b)
		broken("taken, but *out is NULL", NULL);
	check_bundle(b);
	check_round_trip(b);
	vmac_bundle_comment(b, comment, sizeof(comment));
	if (vmac_bundle_comment_check(b, comment, err, sizeof(err)) != 0)
		broken("a bundle's own trusted comment does not pass its check", err);
	vmac_bundle_free(b);
	return 0;
}
