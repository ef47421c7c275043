/* The main() of every unit test program: runs the suite its test file
 * gives (vmac_test_suite, check_main.h) and exits 0 only if every check
 * passed. Check reads its settings from the environment: CK_FORK (make
 * test-unit sets yes: each test in a child, so a crash fails that test
 * only), CK_RUN_SUITE and CK_RUN_CASE (one test case), CK_VERBOSITY
 * (verbose: every test's name and result; default normal). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check_main.h"

static const char *program = "unit test"; /* argv[0]'s last part, for the skip file */

void vmac_test_cannot_run(const char *what, const char *reason)
{
	const char *ci = getenv("CI"), *skip_file = getenv("VMAC_SKIP_FILE");
	ck_assert_msg(!ci || strcmp(ci, "true") != 0, "%s: %s cannot run, and CI=true makes that a failure: %s",
	              program, what, reason);
	fprintf(stderr,
	        "################################################################################\n"
	        "## SKIPPED: %s: %s: %s\n"
	        "################################################################################\n",
	        program, what, reason);
	if (skip_file) {
		FILE *f = fopen(skip_file, "a");
		if (f) {
			fprintf(f, "%s: %s: %s\n", program, what, reason);
			fclose(f);
		}
	}
}

int main(int argc, char **argv)
{
	SRunner *runner;
	int failed;

	if (argc > 0 && argv[0]) {
		const char *slash = strrchr(argv[0], '/');
		program = slash ? slash + 1 : argv[0];
	}
	runner = srunner_create(vmac_test_suite());
	srunner_run_all(runner, CK_ENV);
	failed = srunner_ntests_failed(runner);
	srunner_free(runner);
	return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
