/* vmac's version: what vmacd --version, vmac --version, GET /api/health
 * and the MQTT discovery configs (origin, the host's sw_version) say. */
#ifndef VMAC_VERSION_H
#define VMAC_VERSION_H

#define VMAC_VERSION_STRING "0.1.0"

#endif
