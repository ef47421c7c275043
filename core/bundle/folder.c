/* A bundle from what a drivers folder holds for one driver
 * (vmac_bundle_from_folder, bundle.h): which files of the folder belong to
 * the driver, read into memory. */
#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../common/errors.h"
#include "../common/file.h"
#include "bundle.h"

#define DIR_MAX 1024

static int is_dir(const char *path)
{
	struct stat st;
	return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

static int ends_with(const char *s, const char *tail)
{
	size_t n = strlen(s), t = strlen(tail);
	return n >= t && strcmp(s + n - t, tail) == 0;
}

/* Add file dir/file as member path: 0, or < 0 with err. */
static int add_file(struct vmac_bundle *b, const char *dir, const char *file, const char *path, char *err,
                    size_t errlen)
{
	char full[DIR_MAX + 256];
	size_t len;
	int code = 0, rc;
	char *data;
	snprintf(full, sizeof(full), "%s/%s", dir, file);
	if (!(data = vmac_read_file(full, VMAC_BUNDLE_FILE_MAX, &len, err, errlen, &code)))
		return code ? code : -VMAC_EFAIL;
	rc = vmac_bundle_add(b, path, data, len, err, errlen);
	free(data);
	return rc;
}

/* The driver's name and folder from path (D/NAME.lua, or D holding one
 * NAME.lua). */
static int driver_of(const char *path, char *dir, char *name, char *err, size_t errlen)
{
	const char *slash = strrchr(path, '/');
	DIR *d;
	struct dirent *e;
	int n = 0;
	if (!is_dir(path)) {
		const char *base = slash ? slash + 1 : path;
		if (!ends_with(base, ".lua") || strlen(base) - 4 > VMAC_BUNDLE_NAME_MAX) {
			snprintf(err, errlen, "%s: not a driver file (NAME.lua) nor a folder", path);
			return -ENOENT;
		}
		snprintf(dir, DIR_MAX, "%.*s", slash ? (int)(slash - path) : 1, slash ? path : ".");
		snprintf(name, VMAC_BUNDLE_NAME_MAX + 1, "%.*s", (int)(strlen(base) - 4), base);
		return 0;
	}
	snprintf(dir, DIR_MAX, "%s", path);
	if (!(d = opendir(path))) {
		snprintf(err, errlen, "%s: cannot read the folder: %s", path, strerror(errno));
		return -errno;
	}
	while ((e = readdir(d)))
		if (ends_with(e->d_name, ".lua") && strlen(e->d_name) - 4 <= VMAC_BUNDLE_NAME_MAX &&
		    e->d_name[0] != '.') {
			if (n++ == 0)
				snprintf(name, VMAC_BUNDLE_NAME_MAX + 1, "%.*s", (int)(strlen(e->d_name) - 4),
				         e->d_name);
			else if (n == 2)
				snprintf(err, errlen,
				         "%s holds several drivers (%s.lua, %s, ...): name one, %s/NAME.lua", path,
				         name, e->d_name, path);
		}
	closedir(d);
	if (n == 1)
		return 0;
	if (n == 0)
		snprintf(err, errlen, "%s holds no driver (NAME.lua)", path);
	return -ENOENT;
}

/* Every NAME.lua of folder dir whose NAME passes keep(name, len, ctx) as
 * PREFIX/NAME.lua (sorted by the bundle). */
static int add_folder(struct vmac_bundle *b, const char *dir, const char *prefix,
                      int (*keep)(const char *file, const void *ctx), const void *ctx, char *err, size_t errlen)
{
	DIR *d = opendir(dir);
	struct dirent *e;
	int rc = 0;
	if (!d)
		return 0; /* no such folder: nothing of that kind */
	while (rc == 0 && (e = readdir(d))) {
		char path[VMAC_BUNDLE_PATH_MAX + 64];
		if (e->d_name[0] == '.' || !ends_with(e->d_name, ".lua") || !keep(e->d_name, ctx))
			continue;
		snprintf(path, sizeof(path), "%s/%s", prefix, e->d_name);
		rc = add_file(b, dir, e->d_name, path, err, errlen);
	}
	closedir(d);
	return rc;
}

static int any_file(const char *file, const void *ctx)
{
	(void)file;
	(void)ctx;
	return 1;
}

/* NAME_test.lua and NAME_*_test.lua of driver ctx. */
static int test_of(const char *file, const void *ctx)
{
	const char *name = ctx;
	size_t n = strlen(name);
	return strncmp(file, name, n) == 0 && file[n] == '_' && ends_with(file, "_test.lua");
}

int vmac_bundle_from_folder(const char *path, const char *cycles_dir, struct vmac_bundle **out, char *err,
                            size_t errlen)
{
	char dir[DIR_MAX], name[VMAC_BUNDLE_NAME_MAX + 1], file[VMAC_BUNDLE_NAME_MAX + 8], sub[DIR_MAX + 128];
	struct stat st;
	struct vmac_bundle *b;
	int rc;
	*out = NULL;
	if ((rc = driver_of(path, dir, name, err, errlen)) != 0 || (rc = vmac_bundle_new(name, &b, err, errlen)) != 0)
		return rc;
	snprintf(file, sizeof(file), "%s.lua", name);
	rc = add_file(b, dir, file, file, err, errlen);
	if (rc == 0 && !cycles_dir) {
		snprintf(sub, sizeof(sub), "%s/cycles/%s", dir, name);
		if (!is_dir(sub))
			snprintf(sub, sizeof(sub), "%s/../cycles/%s", dir, name);
		cycles_dir = sub;
	}
	if (rc == 0)
		rc = add_folder(b, cycles_dir, "cycles", any_file, NULL, err, errlen);
	if (rc == 0) {
		snprintf(sub, sizeof(sub), "%s/plants/%s", dir, file);
		if (stat(sub, &st) == 0 && strcmp(file, "plant.lua") == 0) {
			/* the driver is plant.lua already: its model would replace it */
			snprintf(err, errlen, "%s: a driver named plant cannot have a plant model (both are plant.lua)",
			         sub);
			rc = -VMAC_EBUNDLE;
		} else if (stat(sub, &st) == 0) {
			snprintf(sub, sizeof(sub), "%s/plants", dir);
			rc = add_file(b, sub, file, "plant.lua", err, errlen);
		}
	}
	if (rc == 0) {
		snprintf(sub, sizeof(sub), "%s/tests", dir);
		rc = add_folder(b, sub, "tests", test_of, name, err, errlen);
	}
	if (rc != 0) {
		vmac_bundle_free(b);
		return rc;
	}
	*out = b;
	return 0;
}
