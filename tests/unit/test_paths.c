/* Where a program finds its shipped scripts and stdlib (core/common/paths.c):
 * installed under a prefix, in a source tree's build folders, and neither,
 * each laid out in a fresh temporary folder. */
#include <check.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../core/common/paths.h"
#include "check_main.h"

static char top[256]; /* this test's temporary folder */

/* Every folder of top/rel made, like mkdir -p. */
static void make_dirs(const char *rel)
{
	char path[1024];
	size_t i, n = (size_t)snprintf(path, sizeof(path), "%s/%s", top, rel);
	for (i = strlen(top) + 1; i <= n; i++) {
		if (path[i] != '/' && path[i] != '\0')
			continue;
		path[i] = '\0';
		ck_assert_msg(mkdir(path, 0700) == 0 || errno == EEXIST, "cannot make %s: %s", path, strerror(errno));
		if (i < n)
			path[i] = '/';
	}
}

static void setup(void)
{
	snprintf(top, sizeof(top), "%s/vmac-paths-XXXXXX", getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
	ck_assert_msg(mkdtemp(top) != NULL, "cannot make a temporary folder: %s", strerror(errno));
}

static void teardown(void)
{
	char cmd[512];
	snprintf(cmd, sizeof(cmd), "rm -rf '%s'", top);
	if (system(cmd) != 0)
		fprintf(stderr, "test_paths: could not remove %s\n", top);
}

/* The root vmac_root_dir_of finds for the binary top/exe_rel: 0 and
 * top/want_rel, or the code it returned. */
static void expect_root(const char *exe_rel, const char *want_rel)
{
	char exe[1024], want[1024], got[1024] = "";
	int rc;
	snprintf(exe, sizeof(exe), "%s/%s", top, exe_rel);
	snprintf(want, sizeof(want), "%s/%s", top, want_rel);
	rc = vmac_root_dir_of(exe, got, sizeof(got));
	ck_assert_msg(rc == 0, "%s: no root found (%d), want %s", exe_rel, rc, want_rel);
	ck_assert_msg(strcmp(got, want) == 0, "%s: root %s, want %s", exe_rel, got, want);
}

START_TEST(an_installed_binary_finds_its_prefix_share_folder)
{
	make_dirs("usr/bin");
	make_dirs("usr/share/vmac/scripts/drivers");
	expect_root("usr/bin/vmacd", "usr/share/vmac");
	make_dirs("opt/vmac/bin");
	make_dirs("opt/vmac/share/vmac/scripts/drivers");
	expect_root("opt/vmac/bin/vmac", "opt/vmac/share/vmac");
}
END_TEST

START_TEST(a_binary_in_a_source_tree_finds_the_tree)
{
	make_dirs("src/scripts/drivers");
	make_dirs("src/build/bin");
	make_dirs("src/build/asan/bin");
	expect_root("src/build/bin/vmacd", "src");
	expect_root("src/build/asan/bin/vmac", "src");
	expect_root("src/debian/build/bin/vmacd", "src");
}
END_TEST

START_TEST(the_install_layout_wins_over_a_tree_above)
{
	/* A prefix inside a folder that also looks like a tree (make install
	 * DESTDIR=build/dest in a clone): the installed copy is the binary's own. */
	make_dirs("clone/scripts/drivers");
	make_dirs("clone/build/dest/usr/share/vmac/scripts/drivers");
	expect_root("clone/build/dest/usr/bin/vmacd", "clone/build/dest/usr/share/vmac");
}
END_TEST

START_TEST(neither_layout_is_said)
{
	char got[1024] = "unchanged", exe[1024];
	make_dirs("usr/bin");
	make_dirs("usr/share/vmac/stdlib"); /* no scripts/drivers: not a root */
	snprintf(exe, sizeof(exe), "%s/usr/bin/vmacd", top);
	ck_assert_int_eq(vmac_root_dir_of(exe, got, sizeof(got)), -ENOENT);
	ck_assert_int_eq(vmac_root_dir_of("/vmacd", got, sizeof(got)), -ENOENT);
	ck_assert_int_eq(vmac_root_dir_of("vmacd", got, sizeof(got)), -ENOENT);
	ck_assert_str_eq(got, "unchanged");
}
END_TEST

START_TEST(a_root_that_does_not_fit_is_refused)
{
	char exe[1024], small[8];
	make_dirs("usr/share/vmac/scripts/drivers");
	snprintf(exe, sizeof(exe), "%s/usr/bin/vmacd", top);
	ck_assert_int_eq(vmac_root_dir_of(exe, small, sizeof(small)), -ENAMETOOLONG);
}
END_TEST

START_TEST(the_running_program_gets_a_root_from_anywhere)
{
	/* This test program is in build/tests/ of a tree: the tree's root, the
	 * same whatever the working folder. */
	char root[1024], probe[1100];
	struct stat st;
	ck_assert_msg(chdir("/") == 0, "cannot change to /: %s", strerror(errno));
	vmac_root_dir(root, sizeof(root));
	snprintf(probe, sizeof(probe), "%s/stdlib", root);
	ck_assert_msg(stat(probe, &st) == 0 && S_ISDIR(st.st_mode), "root %s has no stdlib/", root);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("paths");
	TCase *tc = tcase_create("root");
	tcase_add_checked_fixture(tc, setup, teardown);
	tcase_add_test(tc, an_installed_binary_finds_its_prefix_share_folder);
	tcase_add_test(tc, a_binary_in_a_source_tree_finds_the_tree);
	tcase_add_test(tc, the_install_layout_wins_over_a_tree_above);
	tcase_add_test(tc, neither_layout_is_said);
	tcase_add_test(tc, a_root_that_does_not_fit_is_refused);
	tcase_add_test(tc, the_running_program_gets_a_root_from_anywhere);
	suite_add_tcase(s, tc);
	return s;
}
