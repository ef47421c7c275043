/* Hot reload on a running host (docs/API.md "Drivers"): a bundle (docs/
 * DRIVERS.md "Bundles") is checked (accept.c: its signature against the
 * trusted keys, its security counter, its version against the kept ones),
 * compiled in a fresh sandbox, kept in the store, and handed to every
 * running machine of that driver, each switching at a slot boundary
 * (vmac_bus_request_swap); a rollback does the same with the version
 * before. Runs on the HTTP server's threads, never the bus thread; one
 * deploy or rollback at a time, and a new machine's driver is loaded
 * (vmac_deploy_load) only between them. */
#ifndef VMAC_DEPLOY_H
#define VMAC_DEPLOY_H

#include <stddef.h>
#include <stdint.h>

#include "../bundle/minisign.h"
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
	int status;                  /* HTTP status: 200; 400 not a bundle; 403 signature; 409 refused (the counter,
	                                the version, a machine); 500/507 store; 503 busy */
	int code;                    /* when status is not 200: the error's code (core/common/errors.h) */
	char error[VMAC_EVENT_TEXT]; /* when status is not 200 */
	int64_t id;                  /* the version now active */
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	char hash[65];
	uint64_t counter;
	char signer[17];            /* the key id that signed it; "" unsigned */
	int unchanged;              /* 1: that content was active already: nothing was done */
	char note[VMAC_EVENT_TEXT]; /* what --force replaced, or "" */
	int nmachines;
	struct vmac_deploy_machine machines[VMAC_DEPLOY_MACHINES];
};

/* Whose signatures a deploy accepts (docs/SECURITY.md "Signed bundles"):
 * the keys of deploy_keys, and whether an upload must be signed by one. */
struct vmac_deploy_trust {
	struct vmac_minisign_key keys[VMAC_MINISIGN_KEYS];
	int nkeys;
	int require;
};

/* The trust of cfg: deploy_keys read (none when unset), and
 * deploy_require_signature (auto: on when a key is configured). 0, or < 0
 * with err (a keys file that cannot be read or holds no key). */
int vmac_deploy_trust_load(const struct vmac_config *cfg, struct vmac_deploy_trust *t, char *err, size_t errlen);

struct vmac_deploy_ctx {
	struct vmac_bus *bus;
	struct vmac_store *store;
	const struct vmac_config *cfg;
	const struct vmac_deploy_trust *trust; /* NULL: no keys, nothing required */
};

/* An upload: a bundle's bytes (or a driver's Lua text alone, a bundle of
 * that one file), its minisign signature (NULL: none), --force (the same
 * version number with other content replaces it), the deploying token's
 * id, the probation (0: none). */
struct vmac_deploy_upload {
	const char *data;
	size_t len;
	const char *sig;
	size_t siglen;
	int force;
	const char *by;
	unsigned probation_ms;
};

/* Check, store and activate an upload for driver `driver`: its bundle must
 * name driver. */
void vmac_deploy(const struct vmac_deploy_ctx *x, const char *driver, const struct vmac_deploy_upload *u,
                 struct vmac_deploy_result *out);

/* A version kept in the store (vmac_store_driver_get) made active again:
 * its bundle is deployed as an upload would be (a new entry, the same
 * hash; its signature was checked when it came). 404 when driver has no
 * version id; 409 when its counter is below one accepted since (vmac
 * rollback is the way back). */
void vmac_deploy_activate(const struct vmac_deploy_ctx *x, const char *driver, int64_t id, const char *by,
                          unsigned probation_ms, struct vmac_deploy_result *out);

/* Back to the version that was active before the active one, on every
 * running machine of driver, whatever its counter. */
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
 * loads, tagged with its version id: the store's active version; or, when
 * none is active or the active one came from the drivers folder and the
 * folder has changed since (looked at once per driver while the process
 * runs), what the folder holds (vmac_folder_bundle), stored as a version
 * of origin "folder" and made active. vmacd's main thread, on VMAC_MSG_LOAD. A deploy or
 * rollback under way is waited for. hand_over(ctx, rc, drv, text) gets the
 * result (rc as vmac_load_driver returns it, -EIO when the store cannot be
 * read; drv NULL unless rc is 0, then the callee's; text says why not) and
 * must hand drv to the bus thread (vmac_bus_send_cmd) before it returns: no
 * deploy begins until it has, so a deploy finds the machine with it. */
void vmac_deploy_load(struct vmac_store *store, const struct vmac_config *cfg, const char *driver, const char *device,
                      void (*hand_over)(void *ctx, int rc, struct vmac_driver *drv, const char *text), void *ctx);

#endif
