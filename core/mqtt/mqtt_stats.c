/* What the MQTT client has done, for GET /metrics (docs/API.md): its
 * connections' state and messages, kept as process-wide atomic counters.
 * Process-wide because vmacd runs at most one client and the HTTP server is
 * given no handle on it (core/vmacd/main.c starts both, each knowing only
 * the bus); the client's threads write them (mqtt_client.c), any thread
 * reads them (vmac_mqtt_stats), and nothing waits. */
#include "mqtt_internal.h"

#include <string.h>

struct mqtt_stats mqtt_stats;

void vmac_mqtt_stats(struct vmac_mqtt_stats *out)
{
	int k;
	memset(out, 0, sizeof(*out));
	out->running = atomic_load(&mqtt_stats.running);
	out->dropped = atomic_load(&mqtt_stats.dropped);
	for (k = 0; k < MQTT_CONNS && k < VMAC_MQTT_CONNECTIONS; k++) {
		out->conn[k].used = atomic_load(&mqtt_stats.conn[k].used);
		out->conn[k].connected = atomic_load(&mqtt_stats.conn[k].connected);
		out->conn[k].connects = atomic_load(&mqtt_stats.conn[k].connects);
		out->conn[k].published = atomic_load(&mqtt_stats.conn[k].published);
		out->conn[k].publish_failed = atomic_load(&mqtt_stats.conn[k].publish_failed);
		out->conn[k].received = atomic_load(&mqtt_stats.conn[k].received);
	}
}
