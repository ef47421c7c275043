/* The host's HTTP server (libmicrohttpd, its own threads): the API (every
 * endpoint is in docs/API.md) and the web UI (docs/UI.md). It reads the
 * bus's published status and the event log, never the bus thread's live
 * tables; what must reach a driver (input, a hot reload) goes through the
 * bus's request slots. Every request but the health check and the UI's
 * files needs a bearer token of the store with the endpoint's scope;
 * failed attempts are rate-limited per client address. */
#ifndef VMAC_HTTP_H
#define VMAC_HTTP_H

#include <stddef.h>

#include "../host/bus.h"
#include "../host/events.h"
#include "../store/store.h"

struct vmac_http; /* opaque */

/* Listen on "ADDR:PORT" (port 0: the kernel picks; see vmac_http_port).
 * Returns NULL with err set. */
struct vmac_http *vmac_http_start(const char *listen, struct vmac_bus *bus, struct vmac_event_log *log,
                                  struct vmac_store *store, const struct vmac_config *cfg, char *err, size_t errlen);
unsigned vmac_http_port(const struct vmac_http *h);
/* Whether it serves HTTPS (settings tls_cert and tls_key). */
int vmac_http_tls(const struct vmac_http *h);
/* GET /api/site serves this site view (core/mqtt/site.h) from now on;
 * NULL (the default): MQTT is off, {"enabled": false}. The view must outlive
 * the server (vmac_http_stop first). */
struct vmac_site;
void vmac_http_set_site(struct vmac_http *h, struct vmac_site *site);
void vmac_http_stop(struct vmac_http *h);

#endif
