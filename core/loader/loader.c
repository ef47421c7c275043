/* See loader.h. */
#include "loader.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "../common/errors.h"

int vmac_driver_path(const struct vmac_config *cfg, const char *driver, char *path, size_t len)
{
	struct stat st;
	if (cfg->drivers_dir[0]) {
		snprintf(path, len, "%s/%s.lua", cfg->drivers_dir, driver);
		if (stat(path, &st) == 0)
			return 0;
	}
	snprintf(path, len, "%s/drivers/%s.lua", cfg->scripts_dir, driver);
	return stat(path, &st) == 0 ? 0 : -ENOENT;
}

static int is_dir(const char *path)
{
	struct stat st;
	return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

/* The folder of driver NAME's programmes: DIR/cycles/NAME/, inside the
 * --drivers folder DIR, when there is one and it holds that folder; else the
 * shipped scripts/cycles/NAME/. When neither exists, DIR's: the error of a
 * driver that finds no programmes then names the folder to make. */
static void cycles_path(const struct vmac_config *cfg, const char *name, char *path, size_t len)
{
	char shipped[VMAC_PATH_MAX + 64];
	snprintf(shipped, sizeof(shipped), "%s/cycles/%s", cfg->scripts_dir, name);
	if (cfg->drivers_dir[0]) {
		snprintf(path, len, "%s/cycles/%s", cfg->drivers_dir, name);
		if (is_dir(path) || !is_dir(shipped))
			return;
	}
	snprintf(path, len, "%s", shipped);
}

/* The declarations of the driver versions loaded so far, newest first: a
 * few dozen at most in practice; the oldest go past MANIFESTS. */
#define MANIFESTS 128

static struct manifest {
	char driver[VMAC_NAME_MAX + 1];
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	char *json;
} manifests[MANIFESTS];
static pthread_mutex_t manifests_lock = PTHREAD_MUTEX_INITIALIZER;

static void remember(const struct vmac_driver *d)
{
	struct manifest keep;
	int i;
	pthread_mutex_lock(&manifests_lock);
	for (i = 0; i < MANIFESTS && manifests[i].json; i++)
		if (strcmp(manifests[i].driver, vmac_driver_name(d)) == 0 &&
		    strcmp(manifests[i].version, vmac_driver_version(d)) == 0)
			break;
	if (i == MANIFESTS) { /* full: the oldest goes */
		i = MANIFESTS - 1;
		free(manifests[i].json);
		manifests[i].json = NULL;
	}
	keep = manifests[i];
	if (!keep.json || strcmp(keep.json, vmac_driver_describe(d)) != 0) {
		free(keep.json);
		snprintf(keep.driver, sizeof(keep.driver), "%s", vmac_driver_name(d));
		snprintf(keep.version, sizeof(keep.version), "%s", vmac_driver_version(d));
		keep.json = strdup(vmac_driver_describe(d));
	}
	memmove(&manifests[1], &manifests[0], (size_t)i * sizeof(manifests[0])); /* to the front */
	manifests[0] = keep;
	pthread_mutex_unlock(&manifests_lock);
}

char *vmac_loaded_manifest(const char *driver, const char *version)
{
	char *json = NULL;
	int i;
	pthread_mutex_lock(&manifests_lock);
	for (i = 0; i < MANIFESTS && manifests[i].json && !json; i++)
		if (strcmp(manifests[i].driver, driver) == 0 && strcmp(manifests[i].version, version) == 0)
			json = strdup(manifests[i].json);
	pthread_mutex_unlock(&manifests_lock);
	return json;
}

/* The limits and settings the configuration gives driver `driver`. */
static void limits_for(const struct vmac_config *cfg, const char *driver, struct vmac_driver_limits *limits,
                       struct vmac_driver_setting *settings)
{
	memset(limits, 0, sizeof(*limits));
	limits->memory_bytes = (size_t)cfg->driver_memory_kib * 1024;
	limits->instructions = cfg->driver_instructions;
	limits->budget_us = cfg->driver_budget_us;
	limits->default_level = cfg->default_level;
	limits->max_level = cfg->max_level;
	limits->slot_us = vmac_config_slot_us(cfg);
	limits->timed_lead_us = vmac_timing_lead_us(cfg->timed_lead_us, vmac_config_slot_us(cfg));
	limits->allow_jit = cfg->allow_jit;
	limits->stdlib_dir = cfg->stdlib_dir;
	limits->expect_name = driver;
	limits->settings = settings;
	limits->nsettings = vmac_config_driver_settings(cfg, driver, settings, VMAC_CONFIG_DRIVER_SETTINGS);
}

/* Whether this host runs drivers of API api: the same major, a minor not
 * above the host's (VMAC_DRIVER_API). */
static int api_ok(const char *api)
{
	unsigned hmaj = 0, hmin = 0, maj = 0, min = 0;
	char end;
	if (sscanf(VMAC_DRIVER_API, "%u.%u", &hmaj, &hmin) != 2 || sscanf(api, "%u.%u%c", &maj, &min, &end) != 2)
		return 0;
	return maj == hmaj && min <= hmin;
}

/* The bundle's programmes as the driver takes them: pointers into b;
 * from: where they were read (a folder), or NULL: the bundle. */
static void programmes_of(const struct vmac_bundle *b, const char *from, struct vmac_driver_programmes *p)
{
	int i;
	memset(p, 0, sizeof(*p));
	snprintf(p->from, sizeof(p->from), "%s", from ? from : "the bundle's cycles");
	for (i = 0; i < b->nfiles && p->n < VMAC_DRIVER_PROGRAMMES; i++) {
		const struct vmac_bundle_file *f = &b->files[i];
		size_t n = strlen(f->path);
		if (strncmp(f->path, "cycles/", 7) != 0 || n - 11 >= sizeof(p->p[0].name))
			continue;
		snprintf(p->p[p->n].name, sizeof(p->p[0].name), "%.*s", (int)(n - 11), f->path + 7);
		p->p[p->n].src = f->data;
		p->p[p->n].len = f->len;
		p->n++;
	}
}

/* Load b's driver (version: the one it must declare, or NULL; from: the
 * folder its programmes were read from, or NULL). */
static int load_bundle(const struct vmac_config *cfg, const struct vmac_bundle *b, const char *device,
                       const char *version, const char *from, struct vmac_driver **out, char *text, size_t textlen)
{
	struct vmac_driver_limits limits;
	struct vmac_driver_setting settings[VMAC_CONFIG_DRIVER_SETTINGS];
	struct vmac_driver_programmes programmes;
	const struct vmac_bundle_file *f = vmac_bundle_driver(b);
	char file[VMAC_NAME_MAX + 8], err[VMAC_DRIVER_ERR_MAX];
	int rc;

	*out = NULL;
	if (!f) {
		snprintf(text, textlen, "the bundle of %s holds no %s.lua", b->name, b->name);
		return -VMAC_EBUNDLE;
	}
	limits_for(cfg, b->name, &limits, settings);
	programmes_of(b, from, &programmes);
	limits.programmes = &programmes;
	snprintf(file, sizeof(file), "%s.lua", b->name);
	rc = vmac_driver_load_source(file, f->data, f->len, &limits, out, err, sizeof(err));
	if (rc != 0) {
		snprintf(text, textlen, "driver '%s' for %s failed to load: %s", b->name, device, err);
		return rc < 0 ? rc : -EINVAL;
	}
	if (version && version[0] && strcmp(version, vmac_driver_version(*out)) != 0) {
		snprintf(text, textlen, "the bundle says %s %s, but %s.lua's manifest says version %s", b->name,
		         version, b->name, vmac_driver_version(*out));
		vmac_driver_free(*out);
		*out = NULL;
		return -VMAC_EBUNDLE;
	}
	remember(*out);
	return 0;
}

int vmac_load_driver_bundle(const struct vmac_config *cfg, const struct vmac_bundle *b, const char *device,
                            struct vmac_driver **out, char *text, size_t textlen)
{
	*out = NULL;
	if (!api_ok(b->api)) {
		snprintf(text, textlen, "the bundle of %s %s needs driver API %s; this host has %s", b->name,
		         b->version, b->api, VMAC_DRIVER_API);
		return -VMAC_EBUNDLE;
	}
	return load_bundle(cfg, b, device, b->version, NULL, out, text, textlen);
}

int vmac_folder_bundle(const struct vmac_config *cfg, const char *driver, const char *device, struct vmac_bundle **out,
                       struct vmac_driver **drv, char *text, size_t textlen)
{
	char path[VMAC_PATH_MAX + 64], cycles[VMAC_PATH_MAX + 64], err[VMAC_DRIVER_ERR_MAX];
	struct vmac_driver *d;
	int rc;

	*out = NULL;
	if (vmac_driver_path(cfg, driver, path, sizeof(path)) != 0) {
		snprintf(text, textlen, "no driver '%s' for %s (looked in %s%s%s/drivers)", driver, device,
		         cfg->drivers_dir, cfg->drivers_dir[0] ? " and " : "", cfg->scripts_dir);
		return -ENOENT;
	}
	cycles_path(cfg, driver, cycles, sizeof(cycles));
	if ((rc = vmac_bundle_from_folder(path, cycles, out, err, sizeof(err))) != 0) {
		snprintf(text, textlen, "driver '%s' for %s failed to load: %s", driver, device, err);
		return rc;
	}
	snprintf((*out)->api, sizeof((*out)->api), "%s", VMAC_DRIVER_API);
	if ((rc = load_bundle(cfg, *out, device, NULL, cycles, &d, text, textlen)) != 0) {
		vmac_bundle_free(*out);
		*out = NULL;
		return rc;
	}
	snprintf((*out)->version, sizeof((*out)->version), "%s", vmac_driver_version(d));
	if (drv)
		*drv = d;
	else
		vmac_driver_free(d);
	return 0;
}

int vmac_load_driver(const struct vmac_config *cfg, const char *driver, const char *device, struct vmac_driver **out,
                     char *text, size_t textlen)
{
	struct vmac_bundle *b;
	int rc = vmac_folder_bundle(cfg, driver, device, &b, out, text, textlen);
	if (rc == 0)
		vmac_bundle_free(b);
	else
		*out = NULL;
	return rc;
}

int vmac_bundle_of_data(const struct vmac_config *cfg, const char *driver, const char *data, size_t len,
                        struct vmac_bundle **out, char *err, size_t errlen)
{
	struct vmac_driver *check = NULL;
	char file[VMAC_BUNDLE_NAME_MAX + 8];
	int rc;
	*out = NULL;
	if (vmac_bundle_is_archive(data, len)) {
		if ((rc = vmac_bundle_read(data, len, out, err, errlen)) != 0)
			return rc;
		if (strcmp((*out)->name, driver) != 0) {
			snprintf(err, errlen, "the bundle is of driver %s, not %s", (*out)->name, driver);
			vmac_bundle_free(*out);
			*out = NULL;
			return -VMAC_EBUNDLE;
		}
		return 0; /* compiled by whoever loads it: after its signature is checked */
	} else {
		/* A driver's Lua text alone: a bundle of that one file, without
		 * programmes (older versions in the store, `curl --data-binary`). */
		snprintf(file, sizeof(file), "%s.lua", driver);
		if ((rc = vmac_bundle_new(driver, out, err, errlen)) != 0 ||
		    (rc = vmac_bundle_add(*out, file, data, len, err, errlen)) != 0) {
			vmac_bundle_free(*out);
			*out = NULL;
			return rc;
		}
		snprintf((*out)->api, sizeof((*out)->api), "%s", VMAC_DRIVER_API);
		if ((rc = vmac_load_driver_bundle(cfg, *out, "(upload)", &check, err, errlen)) == 0)
			snprintf((*out)->version, sizeof((*out)->version), "%s", vmac_driver_version(check));
	}
	vmac_driver_free(check);
	if (rc != 0) {
		vmac_bundle_free(*out);
		*out = NULL;
		return rc == -VMAC_EBUNDLE ? rc : -VMAC_EFAIL;
	}
	return 0;
}

int vmac_bundle_make(const struct vmac_config *cfg, const char *path, uint64_t counter, struct vmac_bundle **out,
                     char *err, size_t errlen)
{
	struct vmac_driver *d;
	int rc = vmac_bundle_from_folder(path, NULL, out, err, errlen);
	if (rc != 0)
		return rc;
	snprintf((*out)->api, sizeof((*out)->api), "%s", VMAC_DRIVER_API);
	(*out)->counter = counter;
	if ((rc = load_bundle(cfg, *out, "(bundle)", NULL, NULL, &d, err, errlen)) != 0) {
		vmac_bundle_free(*out);
		*out = NULL;
		return rc;
	}
	snprintf((*out)->version, sizeof((*out)->version), "%s", vmac_driver_version(d));
	vmac_driver_free(d);
	return 0;
}
