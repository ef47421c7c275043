/* Profile "site": vmacd's view of the other hosts on its broker (site.h,
 * docs/MQTT.md "Several hosts, one site"). It subscribes to every host's
 * native status, availability and value topics on the main connection; the
 * messages are applied to the view on libmosquitto's network thread as they
 * come (mqtt_site_message), past the queue of commands, so that a burst of
 * retained values never crowds a command out. GET /api/site reads the view. */
#include "mqtt_internal.h"

#include <mosquitto.h>

#include "site.h"

int mqtt_site_message(struct vmac_mqtt *m, const struct mosquitto_message *msg)
{
	if (!m->site || !msg->topic)
		return 0;
	return vmac_site_feed(m->site, msg->topic, msg->payload, msg->payloadlen);
}

static void connected(struct vmac_mqtt *m)
{
	char pattern[VMAC_MQTT_TOPIC_MAX + 16];
	int i;
	if (!m->site)
		return;
	for (i = 0; i < VMAC_SITE_PATTERNS; i++) {
		vmac_site_pattern(m->site, i, pattern, sizeof(pattern));
		mqtt_subscribe(m, pattern, 1);
	}
}

const struct mqtt_profile mqtt_site_profile = {
    .name = "site",
    .conn = MQTT_CONN_MAIN,
    .connected = connected,
};
