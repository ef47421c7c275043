/* Lua driver instances: one sandboxed LuaJIT state per device. Every call
 * from C into driver code goes through driver.c's one guarded call (budget,
 * memory cap, traceback); a failure marks the driver, never the host.
 * The driver API is in docs/DRIVERS.md. */
#ifndef VMAC_DRIVER_H
#define VMAC_DRIVER_H

#include <stddef.h>
#include <stdint.h>

#include "../proto/proto.h"

#define VMAC_DRIVER_ERR_MAX 512

struct vmac_driver_limits {
	size_t memory_bytes;        /* cap on the state's heap (default 4 MiB) */
	uint64_t instructions;      /* VM instructions per call (default 2,000,000) */
	const char *stdlib_dir;     /* where the driver's require() looks; NULL: no require */
};

struct vmac_driver; /* opaque */

/* Load the driver file at path into a fresh sandboxed state and check it
 * returns a table with a tick function. Slow (reads a file, compiles): call
 * off the bus thread. Returns 0 and *out, or a negative errno with err set
 * ("washer.lua:12: unexpected symbol near 'x'"). -ENOENT when no file. */
int vmac_driver_load(const char *path, const struct vmac_driver_limits *limits, struct vmac_driver **out,
                     char *err, size_t errlen);

/* One service: hand the board's inputs to tick() and take the outputs for
 * the next service. time_s is bus time in seconds. Returns 0, or -1 with err
 * holding the driver's error, file, line and traceback; after a failure the
 * driver must not be called again. Allocates only inside the driver's own
 * capped heap. */
int vmac_driver_tick(struct vmac_driver *d, double time_s, const struct vmac_inputs *in,
                     struct vmac_outputs *out, char *err, size_t errlen);

/* Bytes the driver's heap holds now. */
size_t vmac_driver_memory(const struct vmac_driver *d);

void vmac_driver_free(struct vmac_driver *d);

#endif
