/* The unit tests' one main() (check_main.c), and what it asks of each test
 * program: every tests/unit/test_NAME.c defines vmac_test_suite() and is
 * linked with check_main.o (tests/unit/unit.mk). */
#ifndef VMAC_TESTS_CHECK_MAIN_H
#define VMAC_TESTS_CHECK_MAIN_H

#include <check.h>

/* The suite of this test program, every test case added: defined once in
 * each test_NAME.c, run by check_main.c's main(). */
Suite *vmac_test_suite(void);

/* A check that cannot run on this machine (what: the check and what it
 * needs; reason: why not here). Under CI=true that is a failure of the
 * calling test; elsewhere it is SKIPPED loudly on stderr and the line
 * "PROGRAM: WHAT: REASON" appended to $VMAC_SKIP_FILE, which make test
 * lists at the end (as tests/ui/run.sh and tests/integration/run.py do).
 * Call it from a test body, then return. */
void vmac_test_cannot_run(const char *what, const char *reason);

#endif
