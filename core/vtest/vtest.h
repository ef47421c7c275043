/* `vmac test`: run driver tests in virtual time (docs/TESTING.md). */
#ifndef VMAC_VTEST_H
#define VMAC_VTEST_H

/* argv[0] is "test"; returns the process exit code (0 all passed, 1 a test
 * failed, 2 usage or setup error). */
int vmac_test_main(int argc, char **argv);

#endif
