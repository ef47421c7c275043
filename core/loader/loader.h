/* Finding and loading a device's driver the way the host does: from a
 * bundle (docs/DRIVERS.md "Bundles"), or from the folders: NAME.lua in
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
#include <stdint.h>

#include "../bundle/bundle.h"
#include "../config/config.h"
#include "../driver/driver.h"

/* The bundle of driver `driver` as the folders hold it (DRIVERS.md
 * "Bundles"): DIR/NAME.lua of the --drivers folder DIR, else the shipped
 * scripts/drivers/NAME.lua; the programmes as above; its plant and tests
 * when the folder has them; version and api from the driver's manifest
 * (it is compiled: the instance, loaded for device, goes to *drv when drv
 * is not NULL), counter 0. 0 and *out; -ENOENT (no such file) or
 * another negative errno, with text saying why in words a person can act
 * on ("no driver 'washer' for washer-1 (looked in ...)"). */
int vmac_folder_bundle(const struct vmac_config *cfg, const char *driver, const char *device, struct vmac_bundle **out,
                       struct vmac_driver **drv, char *text, size_t textlen);

/* Load the driver of bundle b for board device: its NAME.lua, with the
 * bundle's programmes and nothing from the host's folders (but the
 * stdlib). The manifest must name b's driver and version, and b's api
 * must be one this host has. 0 and *out, or < 0 with text. */
int vmac_load_driver_bundle(const struct vmac_config *cfg, const struct vmac_bundle *b, const char *device,
                            struct vmac_driver **out, char *text, size_t textlen);

/* The bundle of data, as an upload, a stored version or a recording holds
 * it: an archive (read and checked, it must be driver's; not compiled), or
 * a driver's Lua text alone (a bundle of that one file, without
 * programmes: versions stored before bundles), compiled to learn its
 * version. 0, or -VMAC_EBUNDLE (not a bundle of driver) or -VMAC_EFAIL (a
 * Lua text that does not compile) with err. */
int vmac_bundle_of_data(const struct vmac_config *cfg, const char *driver, const char *data, size_t len,
                        struct vmac_bundle **out, char *err, size_t errlen);

/* A bundle of what a folder holds for one driver (vmac_bundle_from_folder:
 * path is D/NAME.lua or a folder D with one driver), its version and api
 * from the driver's manifest (it is compiled, with its programmes, and
 * must load), with security counter counter: `vmac bundle`, `vmac reload
 * DIR`. 0, or < 0 with err. */
int vmac_bundle_make(const struct vmac_config *cfg, const char *path, uint64_t counter, struct vmac_bundle **out,
                     char *err, size_t errlen);

/* Load driver `driver` for board `device` from the folders: the two
 * above. Returns as vmac_folder_bundle. */
int vmac_load_driver(const struct vmac_config *cfg, const char *driver, const char *device, struct vmac_driver **out,
                     char *text, size_t textlen);

/* The declarations (vmac_driver_describe) of every driver version this
 * process has loaded, for user interfaces: a malloc'd copy of the JSON
 * text of driver `driver` version `version`, or NULL when none was loaded.
 * Any thread. */
char *vmac_loaded_manifest(const char *driver, const char *version);

/* The file vmac_load_driver would load for `driver`: 0, or -ENOENT. */
int vmac_driver_path(const struct vmac_config *cfg, const char *driver, char *path, size_t len);

#endif
