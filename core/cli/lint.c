/* vmac lint FILE...: luacheck over driver scripts and stdlib modules with
 * exactly the globals the driver sandbox has. The globals are not written
 * down here nor in a luacheck file: they come from the sandbox's own
 * allow-list (vmac_driver_allowed, core/driver/sandbox.c), written as the
 * luacheck std "vmac" into a temporary configuration, followed by the
 * other settings of scripts/luacheckrc (line length, the driver tests' std).
 * So anything a driver cannot reach (os.execute, io, load, string.dump) is
 * an unknown global to luacheck too. */
#include "lint.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../common/paths.h"
#include "../driver/driver.h"

static void write_names(FILE *f, const char *const *names, const char *indent)
{
	for (; *names; names++)
		fprintf(f, "%s\"%s\",\n", indent, *names);
}

/* The luacheck configuration: std "vmac" from the allow-list, then the text
 * of settings (scripts/luacheckrc). 0, or -1 with errno set. */
static int write_config(FILE *out, FILE *settings)
{
	const struct vmac_driver_lib *lib;
	char buf[4096];
	size_t n;
	fprintf(out, "-- Written by vmac lint: the driver sandbox's allow-list (core/driver/sandbox.c,\n"
	             "-- vmac_driver_allowed), then scripts/luacheckrc.\n"
	             "stds.vmac = { read_globals = {\n");
	for (lib = vmac_driver_allowed; lib->copied; lib++) {
		if (!lib->lib) {
			write_names(out, lib->copied, "\t");
			write_names(out, lib->own, "\t");
			continue;
		}
		fprintf(out, "\t%s = { fields = {\n", lib->lib);
		write_names(out, lib->copied, "\t\t");
		write_names(out, lib->own, "\t\t");
		fprintf(out, "\t} },\n");
	}
	fprintf(out, "} }\nstd = \"vmac\"\n\n");
	while ((n = fread(buf, 1, sizeof(buf), settings)) > 0)
		fwrite(buf, 1, n, out);
	return ferror(settings) || fflush(out) != 0 || ferror(out) ? -1 : 0;
}

static int lint_run(const struct vmac_cmd_args *a)
{
	static char luacheck[] = "luacheck", config_flag[] = "--config", no_color[] = "--no-color";
	const char *tmpdir = getenv("TMPDIR");
	char root[1024], settings_path[1100], config_path[1100];
	FILE *settings, *out;
	char **args;
	int i, n = 0, fd, status;
	pid_t pid;

	vmac_root_dir(root, sizeof(root));
	snprintf(settings_path, sizeof(settings_path), "%s/scripts/luacheckrc", root);
	if (!(settings = fopen(settings_path, "r"))) {
		fprintf(stderr, "vmac lint: cannot read %s: %s\n", settings_path, strerror(errno));
		return 2;
	}
	snprintf(config_path, sizeof(config_path), "%s/vmac-lint-XXXXXX", tmpdir && tmpdir[0] ? tmpdir : "/tmp");
	if ((fd = mkstemp(config_path)) < 0 || !(out = fdopen(fd, "w"))) {
		fprintf(stderr, "vmac lint: cannot write a configuration in %s: %s\n", config_path, strerror(errno));
		if (fd >= 0) {
			close(fd);
			unlink(config_path);
		}
		fclose(settings);
		return 2;
	}
	i = write_config(out, settings);
	fclose(settings);
	if (fclose(out) != 0 || i != 0) {
		fprintf(stderr, "vmac lint: cannot write %s: %s\n", config_path, strerror(errno));
		unlink(config_path);
		return 2;
	}

	args = calloc((size_t)a->nargs + 6, sizeof(*args));
	if (!args) {
		unlink(config_path);
		return 2;
	}
	args[n++] = luacheck;
	args[n++] = config_flag;
	args[n++] = config_path;
	if (!isatty(STDOUT_FILENO))
		args[n++] = no_color;
	for (i = 0; i < a->nargs; i++)
		args[n++] = a->arg[i];
	fflush(stdout);
	pid = fork();
	if (pid == 0) {
		execvp("luacheck", args);
		fprintf(stderr, "vmac lint: cannot run luacheck (%s); install Debian's lua-check (make deps)\n",
		        strerror(errno));
		_exit(2);
	}
	free(args);
	if (pid < 0) {
		fprintf(stderr, "vmac lint: cannot start luacheck: %s\n", strerror(errno));
		unlink(config_path);
		return 2;
	}
	while (waitpid(pid, &status, 0) < 0)
		if (errno != EINTR) {
			status = 2 << 8;
			break;
		}
	unlink(config_path);
	return WIFEXITED(status) ? WEXITSTATUS(status) : 2;
}

const struct vmac_cmd vmac_lint_cmd = {
    .name = "lint",
    .args = "FILE.lua...",
    .min_args = 1,
    .max_args = -1,
    .summary = "check driver scripts with luacheck and the sandbox's globals",
    .about = "Check driver and stdlib scripts with luacheck, knowing exactly the globals the driver\n"
             "sandbox provides: anything else (os, io, debug, load, ...) is reported.\n"
             "Exit 0 when clean, 1 on warnings or errors, 2 wrong usage or luacheck missing.\n",
    .run = lint_run};
