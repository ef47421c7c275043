/* What mqtt_sparkplug.c and mqtt_spb_dcmd.c share: Sparkplug B's payload
 * types (protoc-c's, from sparkplug_b.proto) and the names both use. */
#ifndef VMAC_MQTT_SPB_H
#define VMAC_MQTT_SPB_H

#include "mqtt_internal.h"
#include "sparkplug_b.pb-c.h"

typedef SparkplugB__Payload Payload;
typedef SparkplugB__Payload__Metric Metric;

#define COMMANDS "Commands/" /* a driver's command as a Boolean metric: write true to run it */

/* A received payload, or NULL with why (malformed, too long). Free with
 * sparkplug_b__payload__free_unpacked. */
Payload *mqtt_spb_unpack(const struct mqtt_message *msg, const char **why);

/* A DCMD for device (the topic's last level): every metric into the bus. */
void mqtt_spb_dcmd(struct vmac_mqtt *m, const struct mqtt_message *msg, const char *device);

#endif
