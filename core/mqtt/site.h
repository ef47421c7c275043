/* The site view: every vmac host on one broker, its devices and their last
 * values, as vmac's native topics tell them (docs/MQTT.md, "Several hosts,
 * one site"). Pure: topics and payloads in, JSON out; no libmosquitto. vmacd
 * feeds it from its MQTT network thread and serves it as GET /api/site;
 * `vmac site` feeds it from a connection of its own. Bounded (VMAC_SITE_*):
 * what does not fit is dropped and counted, never a crash. Thread-safe: one
 * lock inside, held only while a message is applied or the JSON is made. */
#ifndef VMAC_MQTT_SITE_H
#define VMAC_MQTT_SITE_H

#include <jansson.h>
#include <stddef.h>

#define VMAC_SITE_HOSTS 64             /* hosts kept; then the longest-silent offline one makes room */
#define VMAC_SITE_DEVICES_PER_HOST 256 /* devices of one host */
#define VMAC_SITE_DEVICES 1024         /* devices of all hosts together */
#define VMAC_SITE_VALUES 64            /* values of one device */
#define VMAC_SITE_TEXT_MAX 63          /* a value's payload in bytes (a driver's string is at most 63) */
#define VMAC_SITE_PATTERNS 2           /* subscriptions: PREFIX/+/status, PREFIX/+/+/+ */

struct vmac_site; /* opaque */

/* A site view of the hosts under prefix (mqtt_prefix); self: the host id of
 * the host that keeps it (marked "self" in the JSON), or NULL. NULL when out
 * of memory. */
struct vmac_site *vmac_site_new(const char *prefix, const char *self);
void vmac_site_free(struct vmac_site *s);

/* The i-th topic filter to subscribe to (0 <= i < VMAC_SITE_PATTERNS). */
void vmac_site_pattern(const struct vmac_site *s, int i, char *out, size_t outlen);

/* A message (retained or not) on topic: 1 when it is a site topic (applied,
 * or counted as malformed and ignored), 0 when it is not one (a command
 * topic, another prefix): the caller handles it. payload: len bytes, any
 * bytes; NULL when len is 0. */
int vmac_site_feed(struct vmac_site *s, const char *topic, const void *payload, int len);

/* Whether the connection that feeds it is up (shown as "connected"). */
void vmac_site_set_connected(struct vmac_site *s, int connected);

/* The view as GET /api/site answers (docs/API.md): {"enabled": true,
 * "connected", "prefix", "self", "hosts": [...], "dropped": {...},
 * "malformed"}; hosts, devices and values sorted by name. NULL when out of
 * memory. */
json_t *vmac_site_json(struct vmac_site *s);

#endif
