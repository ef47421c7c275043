/* See loader.h. */
#include "loader.h"

#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

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
                       struct vmac_driver_setting *settings, char *cycles, size_t cycleslen)
{
	memset(limits, 0, sizeof(*limits));
	limits->memory_bytes = (size_t)cfg->driver_memory_kib * 1024;
	limits->instructions = cfg->driver_instructions;
	limits->budget_us = cfg->driver_budget_us;
	limits->default_level = cfg->default_level;
	limits->max_level = cfg->max_level;
	limits->allow_jit = cfg->allow_jit;
	limits->stdlib_dir = cfg->stdlib_dir;
	cycles_path(cfg, driver, cycles, cycleslen);
	limits->cycles_dir = cycles;
	limits->expect_name = driver;
	limits->settings = settings;
	limits->nsettings = vmac_config_driver_settings(cfg, driver, settings, VMAC_CONFIG_DRIVER_SETTINGS);
}

int vmac_load_driver(const struct vmac_config *cfg, const char *driver, const char *device, struct vmac_driver **out,
                     char *text, size_t textlen)
{
	struct vmac_driver_limits limits;
	struct vmac_driver_setting settings[VMAC_CONFIG_DRIVER_SETTINGS];
	char path[VMAC_PATH_MAX + 64], cycles[VMAC_PATH_MAX + 64], err[VMAC_DRIVER_ERR_MAX];
	int rc;

	*out = NULL;
	limits_for(cfg, driver, &limits, settings, cycles, sizeof(cycles));
	if (vmac_driver_path(cfg, driver, path, sizeof(path)) != 0) {
		snprintf(text, textlen, "no driver '%s' for %s (looked in %s%s%s/drivers)", driver, device,
		         cfg->drivers_dir, cfg->drivers_dir[0] ? " and " : "", cfg->scripts_dir);
		return -ENOENT;
	}
	rc = vmac_driver_load(path, &limits, out, err, sizeof(err));
	if (rc != 0) {
		snprintf(text, textlen, "driver '%s' for %s failed to load: %s", driver, device, err);
		return rc < 0 ? rc : -EINVAL;
	}
	remember(*out);
	return 0;
}

int vmac_load_driver_source(const struct vmac_config *cfg, const char *driver, const char *device, const char *src,
                            size_t len, struct vmac_driver **out, char *text, size_t textlen)
{
	struct vmac_driver_limits limits;
	struct vmac_driver_setting settings[VMAC_CONFIG_DRIVER_SETTINGS];
	char file[VMAC_NAME_MAX + 8], cycles[VMAC_PATH_MAX + 64], err[VMAC_DRIVER_ERR_MAX];
	int rc;

	*out = NULL;
	limits_for(cfg, driver, &limits, settings, cycles, sizeof(cycles));
	snprintf(file, sizeof(file), "%s.lua", driver);
	rc = vmac_driver_load_source(file, src, len, &limits, out, err, sizeof(err));
	if (rc != 0) {
		snprintf(text, textlen, "driver '%s' for %s failed to load: %s", driver, device, err);
		return rc < 0 ? rc : -EINVAL;
	}
	remember(*out);
	return 0;
}
