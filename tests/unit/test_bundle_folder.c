/* Unit tests of a bundle made from a drivers folder (core/bundle/folder.c,
 * vmac_bundle_from_folder) and of a signature's trusted comment
 * (vmac_bundle_comment, _comment_check in core/bundle/bundle.c): which
 * files of a folder D belong to driver x (D/x.lua; its programmes in
 * D/cycles/x/, else D/../cycles/x/, or the folder the caller gives; its
 * plant D/plants/x.lua; its tests D/tests/x_test.lua and x_*_test.lua, not
 * another driver's; .lua files only), the same by the driver file and by
 * the folder; a folder of two drivers, of none, a file that is no driver, a
 * programme of a name the layout does not allow, and a driver named plant
 * with a plant model are refused with their reason; and a trusted comment
 * is checked word by word, in any order and among other words, each word
 * that disagrees with the bundle named. */
#include <check.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../../core/bundle/bundle.h"
#include "../../core/common/errors.h"
#include "check_main.h"

/* The folder of a bundle's tests (written so, the docs test does not take
 * its members for files of the source tree). */
#define TESTS "tests/"

static char root[] = "/tmp/vmac-test-bundle-folder-XXXXXX";

static void setup(void)
{
	snprintf(root, sizeof(root), "/tmp/vmac-test-bundle-folder-XXXXXX");
	ck_assert_msg(mkdtemp(root) != NULL, "mkdtemp failed");
}

static void teardown(void)
{
	char cmd[128];
	snprintf(cmd, sizeof(cmd), "rm -rf %s", root);
	ck_assert_int_eq(system(cmd), 0);
}

/* root/rel (its folders made as needed) holding text; text NULL: a folder. */
static void put(const char *rel, const char *text)
{
	char path[512];
	char *slash;
	FILE *f;
	snprintf(path, sizeof(path), "%s/%s", root, rel);
	for (slash = strchr(path + strlen(root) + 1, '/'); slash; slash = strchr(slash + 1, '/')) {
		*slash = 0;
		ck_assert_msg(mkdir(path, 0755) == 0 || errno == EEXIST, "mkdir %s failed", path);
		*slash = '/';
	}
	if (!text) {
		ck_assert_msg(mkdir(path, 0755) == 0 || errno == EEXIST, "mkdir %s failed", path);
		return;
	}
	ck_assert_msg((f = fopen(path, "w")) != NULL, "cannot write %s", path);
	ck_assert_int_eq(fputs(text, f) >= 0, 1);
	ck_assert_int_eq(fclose(f), 0);
}

static const char *in_root(const char *rel, char *buf, size_t len)
{
	snprintf(buf, len, "%s/%s", root, rel);
	return buf;
}

/* The drivers folder of the brief: driver x with two programmes, a plant,
 * two tests; another driver's test, a note and a hidden file beside them. */
static void drivers_folder(void)
{
	put("D/x.lua", "return { name = 'x' }\n");
	put("D/cycles/x/a.lua", "return 'a'\n");
	put("D/cycles/x/b.lua", "return 'b'\n");
	put("D/cycles/x/notes.txt", "not a programme\n");
	put("D/cycles/x/.draft.lua", "return 'draft'\n");
	put("D/plants/x.lua", "return 'plant of x'\n");
	put("D/plants/y.lua", "return 'plant of y'\n");
	put("D/tests/x_test.lua", "-- x's test\n");
	put("D/tests/x_more_test.lua", "-- x's second test\n");
	put("D/tests/y_test.lua", "-- y's test\n");
	put("D/tests/xy_test.lua", "-- xy's test\n");
	put("D/tests/x.lua", "-- not a test's name\n");
}

static struct vmac_bundle *from_folder(const char *rel, const char *cycles_rel)
{
	struct vmac_bundle *b = NULL;
	char err[512] = "", path[512], cycles[512];
	int rc = vmac_bundle_from_folder(in_root(rel, path, sizeof(path)),
	                                 cycles_rel ? in_root(cycles_rel, cycles, sizeof(cycles)) : NULL, &b, err,
	                                 sizeof(err));
	ck_assert_msg(rc == 0 && b != NULL, "vmac_bundle_from_folder(%s) refused (%d): %s", rel, rc, err);
	return b;
}

/* b holds exactly the members of want (in path order, NULL-terminated),
 * each path's content as given after it. */
static void holds(const struct vmac_bundle *b, const char *const *want, const char *what)
{
	int i;
	for (i = 0; want[2 * i]; i++) {
		ck_assert_msg(i < b->nfiles, "%s: %d members, %s is missing", what, b->nfiles, want[2 * i]);
		ck_assert_msg(strcmp(b->files[i].path, want[2 * i]) == 0, "%s: member %d is %s, not %s", what, i,
		              b->files[i].path, want[2 * i]);
		ck_assert_msg(strcmp(b->files[i].data, want[2 * i + 1]) == 0, "%s: %s holds \"%s\", not \"%s\"", what,
		              want[2 * i], b->files[i].data, want[2 * i + 1]);
	}
	ck_assert_msg(b->nfiles == i, "%s: %d members, not %d (one more is %s)", what, b->nfiles, i,
	              b->nfiles > i ? b->files[i].path : "");
}

static const char *const X_MEMBERS[] = {"cycles/a.lua",
                                        "return 'a'\n",
                                        "cycles/b.lua",
                                        "return 'b'\n",
                                        "plant.lua",
                                        "return 'plant of x'\n",
                                        TESTS "x_more_test.lua",
                                        "-- x's second test\n",
                                        TESTS "x_test.lua",
                                        "-- x's test\n",
                                        "x.lua",
                                        "return { name = 'x' }\n",
                                        NULL};

START_TEST(a_driver_file_takes_its_programmes_plant_and_tests)
{
	struct vmac_bundle *b;
	drivers_folder();
	b = from_folder("D/x.lua", NULL);
	ck_assert_str_eq(b->name, "x");
	ck_assert_msg(!b->version[0] && !b->api[0] && b->counter == 0, "version, api or counter set: %s %s %llu",
	              b->version, b->api, (unsigned long long)b->counter);
	holds(b, X_MEMBERS, "D/x.lua");
	vmac_bundle_free(b);
}
END_TEST

START_TEST(the_folder_of_one_driver_gives_the_same_bundle)
{
	struct vmac_bundle *by_file, *by_folder;
	char err[256] = "", *a, *b;
	size_t alen, blen;
	drivers_folder();
	by_file = from_folder("D/x.lua", NULL);
	by_folder = from_folder("D", NULL);
	holds(by_folder, X_MEMBERS, "D");
	snprintf(by_file->version, sizeof(by_file->version), "1.0");
	snprintf(by_folder->version, sizeof(by_folder->version), "1.0");
	snprintf(by_file->api, sizeof(by_file->api), "0.2");
	snprintf(by_folder->api, sizeof(by_folder->api), "0.2");
	ck_assert_msg(vmac_bundle_write(by_file, &a, &alen, err, sizeof(err)) == 0, "%s", err);
	ck_assert_msg(vmac_bundle_write(by_folder, &b, &blen, err, sizeof(err)) == 0, "%s", err);
	ck_assert_msg(alen == blen && memcmp(a, b, alen) == 0, "D/x.lua and D give different bytes");
	free(a);
	free(b);
	vmac_bundle_free(by_file);
	vmac_bundle_free(by_folder);
}
END_TEST

/* vmac_bundle_from_folder(root/rel) must fail with code (0: any) and a
 * message holding says and also (NULL: nothing more). */
static void folder_refused(const char *rel, int code, const char *says, const char *also)
{
	struct vmac_bundle *b = (struct vmac_bundle *)&b;
	char err[512] = "", path[512];
	int rc = vmac_bundle_from_folder(in_root(rel, path, sizeof(path)), NULL, &b, err, sizeof(err));
	ck_assert_msg(rc < 0, "%s: taken (%d)", rel, rc);
	ck_assert_msg(!code || rc == code, "%s: %d, not %d (%s)", rel, rc, code, err);
	ck_assert_msg(b == NULL, "%s: refused, but *out is not NULL", rel);
	ck_assert_msg(strstr(err, says) != NULL, "%s: the message does not say \"%s\": %s", rel, says, err);
	ck_assert_msg(!also || strstr(err, also) != NULL, "%s: the message does not say \"%s\": %s", rel, also, err);
}

START_TEST(a_folder_of_two_drivers_or_none_is_refused)
{
	put("two/washer.lua", "return {}\n");
	put("two/dryer.lua", "return {}\n");
	put("none/README.txt", "no driver here\n");
	put("empty", NULL);
	put("bad/x.lua", "return {}\n");
	put("bad/cycles/x/wash-hot.lua", "return {}\n");
	folder_refused("two", -ENOENT, "washer.lua", "dryer.lua");
	folder_refused("none", -ENOENT, "holds no driver", NULL);
	folder_refused("empty", -ENOENT, "holds no driver", NULL);
	folder_refused("none/README.txt", -ENOENT, "not a driver file", NULL);
	folder_refused("none/missing.lua", -ENOENT, "missing.lua", NULL);
	folder_refused("nowhere", -ENOENT, "nowhere", NULL);
	folder_refused("bad/x.lua", -VMAC_EBUNDLE, "cycles/wash-hot.lua", NULL);
}
END_TEST

START_TEST(a_driver_named_plant_with_a_plant_model_is_refused)
{
	struct vmac_bundle *b;
	put("D/plant.lua", "return { name = 'plant' }\n");
	b = from_folder("D/plant.lua", NULL);
	ck_assert_str_eq(vmac_bundle_driver(b)->data, "return { name = 'plant' }\n");
	vmac_bundle_free(b);
	/* Its plant model would be plant.lua too, and would replace the driver. */
	put("D/plants/plant.lua", "return 'a plant model'\n");
	folder_refused("D/plant.lua", -VMAC_EBUNDLE, "plants/plant.lua", NULL);
}
END_TEST

START_TEST(programmes_come_from_the_scripts_layout_or_the_folder_given)
{
	static const char *const scripts_layout[] = {"cycles/c.lua", "return 'c'\n", "x.lua", "return {}\n", NULL};
	static const char *const beside[] = {"cycles/a.lua", "return 'a'\n", "x.lua", "return {}\n", NULL};
	static const char *const given[] = {"cycles/m.lua", "return 'm'\n", "x.lua", "return {}\n", NULL};
	struct vmac_bundle *b;
	put("drivers/x.lua", "return {}\n");
	put("cycles/x/c.lua", "return 'c'\n");
	put("mine/m.lua", "return 'm'\n");
	b = from_folder("drivers/x.lua", NULL);
	holds(b, scripts_layout, "drivers/x.lua with cycles/x/ beside drivers/");
	vmac_bundle_free(b);
	put("drivers/cycles/x/a.lua", "return 'a'\n");
	b = from_folder("drivers", NULL);
	holds(b, beside, "drivers/ with drivers/cycles/x/ (the other cycles/x/ not read)");
	vmac_bundle_free(b);
	b = from_folder("drivers/x.lua", "mine");
	holds(b, given, "drivers/x.lua with the programmes of mine/");
	vmac_bundle_free(b);
}
END_TEST

/* ---- the trusted comment ---- */

static struct vmac_bundle *washer(uint64_t counter)
{
	struct vmac_bundle *b;
	char err[256] = "";
	ck_assert_msg(vmac_bundle_new("washer", &b, err, sizeof(err)) == 0, "%s", err);
	snprintf(b->version, sizeof(b->version), "1.2.0");
	b->counter = counter;
	return b;
}

START_TEST(the_trusted_comment_names_the_bundle_and_holds_for_it)
{
	static const char *const good[] = {
	    "vmac-bundle name=washer version=1.2.0 counter=3",
	    "counter=3 version=1.2.0 name=washer",
	    "  name=washer\tcounter=3   version=1.2.0  ",
	    "timestamp:1700000000\tfile:washer-1.2.0.vbundle\thashed vmac-bundle name=washer version=1.2.0 counter=3",
	    "vmac-bundle name=washer version=1.2.0 counter=3 signed-by=ci names=dryer xname=dryer version2=9",
	};
	struct vmac_bundle *b = washer(3), *big = washer(9223372036854775807ull);
	char comment[256], err[512];
	size_t i;
	vmac_bundle_comment(b, comment, sizeof(comment));
	ck_assert_str_eq(comment, "vmac-bundle name=washer version=1.2.0 counter=3");
	for (i = 0; i < sizeof(good) / sizeof(good[0]); i++) {
		err[0] = 0;
		ck_assert_msg(vmac_bundle_comment_check(b, good[i], err, sizeof(err)) == 0, "\"%s\" refused: %s",
		              good[i], err);
	}
	vmac_bundle_comment(big, comment, sizeof(comment));
	ck_assert_str_eq(comment, "vmac-bundle name=washer version=1.2.0 counter=9223372036854775807");
	ck_assert_msg(vmac_bundle_comment_check(big, comment, err, sizeof(err)) == 0, "%s", err);
	vmac_bundle_free(b);
	vmac_bundle_free(big);
}
END_TEST

START_TEST(each_word_that_disagrees_is_named)
{
	/* A comment, and what the refusal must say. */
	static const char *const bad[][2] = {
	    {"vmac-bundle name=dryer version=1.2.0 counter=3", "made for name=dryer, but the bundle says name=washer"},
	    {"vmac-bundle name=washe version=1.2.0 counter=3", "made for name=washe,"},
	    {"vmac-bundle name=washer2 version=1.2.0 counter=3", "made for name=washer2,"},
	    {"vmac-bundle version=1.2.0 counter=3", "made for name=(none), but the bundle says name=washer"},
	    {"vmac-bundle xname=washer version=1.2.0 counter=3", "made for name=(none)"},
	    {"vmac-bundle name= washer version=1.2.0 counter=3", "made for name=(none)"},
	    {"vmac-bundle name=washer version=1.2.1 counter=3",
	     "made for version=1.2.1, but the bundle says version=1.2.0"},
	    {"vmac-bundle name=washer counter=3", "made for version=(none)"},
	    {"vmac-bundle name=washer version=1.2.0 counter=4", "made for counter=4, but the bundle says counter=3"},
	    {"vmac-bundle name=washer version=1.2.0 counter=03", "made for counter=03,"},
	    {"vmac-bundle name=washer version=1.2.0", "made for counter=(none)"},
	    {"", "made for name=(none)"},
	};
	struct vmac_bundle *b = washer(3);
	char err[512];
	size_t i;
	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		err[0] = 0;
		ck_assert_msg(vmac_bundle_comment_check(b, bad[i][0], err, sizeof(err)) == -VMAC_ESIGMETA,
		              "\"%s\" was not refused with -VMAC_ESIGMETA", bad[i][0]);
		ck_assert_msg(strstr(err, bad[i][1]) != NULL, "\"%s\": the message does not say \"%s\": %s", bad[i][0],
		              bad[i][1], err);
		ck_assert_msg(strstr(err, "vmac-bundle name=washer version=1.2.0 counter=3") != NULL,
		              "\"%s\": the message does not give the comment to sign with: %s", bad[i][0], err);
	}
	vmac_bundle_free(b);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("bundle_folder");
	TCase *f = tcase_create("folder"), *c = tcase_create("comment");
	tcase_add_checked_fixture(f, setup, teardown);
	tcase_add_test(f, a_driver_file_takes_its_programmes_plant_and_tests);
	tcase_add_test(f, the_folder_of_one_driver_gives_the_same_bundle);
	tcase_add_test(f, a_folder_of_two_drivers_or_none_is_refused);
	tcase_add_test(f, a_driver_named_plant_with_a_plant_model_is_refused);
	tcase_add_test(f, programmes_come_from_the_scripts_layout_or_the_folder_given);
	tcase_add_test(c, the_trusted_comment_names_the_bundle_and_holds_for_it);
	tcase_add_test(c, each_word_that_disagrees_is_named);
	suite_add_tcase(s, f);
	suite_add_tcase(s, c);
	return s;
}
