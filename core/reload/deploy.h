/* Hot reload on a running host (docs/API.md "Drivers"): a new version of a
 * driver is compiled in a fresh sandbox, kept in the store, and handed to
 * every running machine of that driver, each switching at a slot boundary
 * (vmac_bus_request_swap); a rollback does the same with the version
 * before. Runs on the HTTP server's threads, never the bus thread; one
 * deploy or rollback at a time, and a new machine's driver is loaded
 * (vmac_deploy_load) only between them. */
#ifndef VMAC_DEPLOY_H
#define VMAC_DEPLOY_H

#include <stddef.h>
#include <stdint.h>

#include "../config/config.h"
#include "../host/bus.h"
#include "../store/store.h"

#define VMAC_DEPLOY_MACHINES 64 /* machines reported one by one */

struct vmac_deploy_machine {
	char device[VMAC_NAME_MAX + 1];
	int ok;
	char text[VMAC_EVENT_TEXT];
};

struct vmac_deploy_result {
	int status;                  /* HTTP status: 200, 400 bad source, 409 refused, 500/507 store, 503 busy */
	char error[VMAC_EVENT_TEXT]; /* when status is not 200 */
	int64_t id;                  /* the version now active (0: the driver's file) */
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	char hash[65];
	int nmachines;
	struct vmac_deploy_machine machines[VMAC_DEPLOY_MACHINES];
};

struct vmac_deploy_ctx {
	struct vmac_bus *bus;
	struct vmac_store *store;
	const struct vmac_config *cfg;
};

/* Upload and activate: src (len bytes) must compile, and its manifest must
 * name driver. by: the deploying token's id. probation_ms: 0 for none. */
void vmac_deploy(const struct vmac_deploy_ctx *x, const char *driver, const char *src, size_t len, const char *by,
                 unsigned probation_ms, struct vmac_deploy_result *out);

/* A version kept in the store (vmac_store_driver_get) made active again:
 * its source is deployed as an upload would be (a new entry, the same
 * hash). 404 when driver has no version id. */
void vmac_deploy_activate(const struct vmac_deploy_ctx *x, const char *driver, int64_t id, const char *by,
                          unsigned probation_ms, struct vmac_deploy_result *out);

/* Back to the version that was active before the active one (or to the
 * driver's file), on every running machine of driver. */
void vmac_deploy_rollback(const struct vmac_deploy_ctx *x, const char *driver, const char *by,
                          struct vmac_deploy_result *out);

/* A version on probation failed and the bus thread put its machines back
 * on the instance before (event rolled_back carrying version id): the
 * store says so too (vmac_store_driver_roll_back), so that boards attaching
 * later load the version before. Under the deploy lock: it waits for a
 * deploy or rollback under way, and none interleaves with it. vmacd's main
 * thread. 0, 1 (id was no longer the active version: nothing changed), or
 * -1 with err. */
int vmac_deploy_rolled_back(struct vmac_store *store, const char *driver, int64_t id, const char *why, char *err,
                            size_t errlen);

/* The driver a new machine of driver `driver` (primary board `device`)
 * loads: the store's active version (tagged with its id) or else the file
 * (vmac_load_driver). vmacd's main thread, on VMAC_MSG_LOAD. A deploy or
 * rollback under way is waited for. hand_over(ctx, rc, drv, text) gets the
 * result (rc as vmac_load_driver returns it, -EIO when the store cannot be
 * read; drv NULL unless rc is 0, then the callee's; text says why not) and
 * must hand drv to the bus thread (vmac_bus_send_cmd) before it returns: no
 * deploy begins until it has, so a deploy finds the machine with it. */
void vmac_deploy_load(struct vmac_store *store, const struct vmac_config *cfg, const char *driver, const char *device,
                      void (*hand_over)(void *ctx, int rc, struct vmac_driver *drv, const char *text), void *ctx);

#endif
