/* vmac_root_dir: see paths.h. */
#include "paths.h"

#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define INSTALLED_ROOT "/usr/local/share/vmac"

void vmac_root_dir(char *out, size_t len)
{
	char exe[1024], probe[1100];
	ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
	struct stat st;
	char *slash;
	int up;
	if (n > 0) {
		exe[n] = '\0';
		for (up = 0; up < 5 && (slash = strrchr(exe, '/')) && slash != exe; up++) {
			*slash = '\0';
			snprintf(probe, sizeof(probe), "%s/scripts/drivers", exe);
			if (stat(probe, &st) == 0 && S_ISDIR(st.st_mode)) {
				snprintf(out, len, "%s", exe);
				return;
			}
		}
	}
	snprintf(out, len, "%s", INSTALLED_ROOT);
}
