/* `vmac test`: run driver tests in virtual time (docs/TESTING.md). */
#ifndef VMAC_VTEST_H
#define VMAC_VTEST_H

/* The options of a run, as vmac's option table parsed them
 * (core/cli/vmac.c); NULL or 0: not given. */
struct vmac_test_options {
	const char *drivers, *replay, *filter, *junit, *trace;
	long seed, history;
	double time_limit_s, timeout_s;
	int list, tap;
	char **paths; /* the test files and folders; none: the project's own */
	int npaths;
};

/* Returns the process exit code (0 all passed, 1 a test failed, 2 a
 * setup error: a folder or file that is not there). */
int vmac_test_run(const struct vmac_test_options *o);

#endif
