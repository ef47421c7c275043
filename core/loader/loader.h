/* Finding and loading a device's driver the way the host does: NAME.lua in
 * the --drivers folder DIR first, then the shipped scripts/drivers/; its
 * programmes in DIR/cycles/NAME/ when DIR holds that folder, else in the
 * shipped scripts/cycles/NAME/ (docs/DRIVERS.md, "Cycles as scripts"); the
 * limits and driver.NAME.* settings of the configuration. Used wherever a
 * driver is loaded or described: vmacd's main thread, a deploy, the HTTP
 * API, MQTT and `vmac test`. Slow: reads files and compiles; never on the
 * bus thread. */
#ifndef VMAC_LOADER_H
#define VMAC_LOADER_H

#include <stddef.h>

#include "../config/config.h"
#include "../driver/driver.h"

/* Load driver `driver` for board `device`. Returns 0 and *out; or -ENOENT
 * (no such file) or another negative errno, with text saying why in words a
 * person can act on ("no driver 'washer' for washer-1 (looked in ...)"). */
int vmac_load_driver(const struct vmac_config *cfg, const char *driver, const char *device, struct vmac_driver **out,
                     char *text, size_t textlen);

/* The same from a text in memory (a version uploaded for hot reload); its
 * messages call it DRIVER.lua. */
int vmac_load_driver_source(const struct vmac_config *cfg, const char *driver, const char *device, const char *src,
                            size_t len, struct vmac_driver **out, char *text, size_t textlen);

/* The declarations (vmac_driver_describe) of every driver version this
 * process has loaded, for user interfaces: a malloc'd copy of the JSON
 * text of driver `driver` version `version`, or NULL when none was loaded.
 * Any thread. */
char *vmac_loaded_manifest(const char *driver, const char *version);

/* The file vmac_load_driver would load for `driver`: 0, or -ENOENT. */
int vmac_driver_path(const struct vmac_config *cfg, const char *driver, char *path, size_t len);

#endif
