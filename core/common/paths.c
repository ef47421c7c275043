/* vmac_root_dir: where the shipped scripts and stdlib are (paths.h). */
#include "paths.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#ifndef VMAC_FALLBACK_ROOT
#define VMAC_FALLBACK_ROOT "/usr/local/share/vmac"
#endif

#define ROOT_MARK "scripts/drivers" /* what a root holds, in either layout */
#define TREE_LEVELS 5               /* build/asan/bin is three below the tree */
#define PATH_CAP 4096

/* Whether folder/ROOT_MARK is a folder. */
static int holds_mark(const char *folder)
{
	char probe[PATH_CAP + sizeof(ROOT_MARK) + 1];
	struct stat st;
	if (snprintf(probe, sizeof(probe), "%s/" ROOT_MARK, folder) >= (int)sizeof(probe))
		return 0;
	return stat(probe, &st) == 0 && S_ISDIR(st.st_mode);
}

/* Cuts path at its last '/', unless that is its first character (the
 * file system's root has no parent here). 0, or -1 when nothing is left. */
static int up_one(char *path)
{
	char *slash = strrchr(path, '/');
	if (!slash || slash == path)
		return -1;
	*slash = '\0';
	return 0;
}

static int found(char *out, size_t len, const char *root)
{
	return snprintf(out, len, "%s", root) >= (int)len ? -ENAMETOOLONG : 0;
}

int vmac_root_dir_of(const char *exe, char *out, size_t len)
{
	char dir[PATH_CAP], share[PATH_CAP + sizeof("/share/vmac")];
	int level;
	if (snprintf(dir, sizeof(dir), "%s", exe) >= (int)sizeof(dir) || up_one(dir) != 0)
		return -ENOENT;
	/* dir is the binary's folder: PREFIX/bin when installed. */
	snprintf(share, sizeof(share), "%s", dir);
	if (up_one(share) == 0) {
		strcat(share, "/share/vmac");
		if (holds_mark(share))
			return found(out, len, share);
	}
	for (level = 0; level < TREE_LEVELS; level++) {
		if (holds_mark(dir))
			return found(out, len, dir);
		if (up_one(dir) != 0)
			break;
	}
	return -ENOENT;
}

void vmac_root_dir(char *out, size_t len)
{
	char exe[PATH_CAP];
	ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
	if (n > 0) {
		exe[n] = '\0';
		if (vmac_root_dir_of(exe, out, len) == 0)
			return;
	}
	snprintf(out, len, "%s", VMAC_FALLBACK_ROOT);
}
