/* Home Assistant's two discovery modes (docs/MQTT.md, "Home Assistant"):
 * single component discovery, one retained config per entity on
 * DISCOVERY/COMPONENT/NODE/OBJECT/config (the default, read by every HA
 * since 2019), and device-based discovery (mqtt_discovery_mode = device,
 * HA 2024.11 and later), one retained config per HA device on
 * DISCOVERY/device/NODE/config: {"device", "origin", "components":
 * {OBJECT: entity config + "platform"}}, as homeassistant/components/mqtt/
 * discovery.py reads it (the components inherit device and origin). A
 * component dropped by a new driver version is sent once with its platform
 * alone, HA's removal of it, then left out.
 *
 * Moving from one mode to the other is HA's documented migration: the
 * retained configs of the other mode that a vmacd left on the broker for
 * one of this host's HA devices are found (a subscription per device), HA
 * is told {"migrate_discovery": true} on each (it unloads the entity and
 * keeps its registry entry), the device's configs go out again in this
 * mode (HA makes the entities again, the same ids), and the leftovers are
 * cleared with an empty retained payload. */
#include "mqtt_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MIGRATE "{\"migrate_discovery\": true}"

/* DISCOVERY/COMPONENT/NODE/OBJECT/config into its parts; 0, or -1. */
static int split(const struct vmac_mqtt *m, const char *topic, char *component, char *node, char *object, size_t n)
{
	size_t dl = strlen(m->s.discovery_prefix);
	char rest[300], *c, *nd, *ob, *cfg;
	if (strncmp(topic, m->s.discovery_prefix, dl) != 0 || topic[dl] != '/' || strlen(topic + dl) >= sizeof(rest))
		return -1;
	snprintf(rest, sizeof(rest), "%s", topic + dl + 1);
	c = rest;
	if (!(nd = strchr(c, '/')))
		return -1;
	*nd++ = 0;
	if (!(ob = strchr(nd, '/')))
		return -1;
	*ob++ = 0;
	if (!(cfg = strchr(ob, '/')) || strcmp(cfg, "/config") != 0)
		return -1;
	*cfg = 0;
	snprintf(component, n, "%s", c);
	snprintf(node, n, "%s", nd);
	snprintf(object, n, "%s", ob);
	return 0;
}

static void publish_json(struct vmac_mqtt *m, const char *topic, json_t *o)
{
	char *body = o ? json_dumps(o, JSON_COMPACT) : NULL;
	if (body)
		mqtt_publish(m, topic, body, -1, 1, 1);
	free(body);
}

/* The device config of configs (all of one node), the entities of
 * before[] it lacks as platform-only components when stubs is set; its
 * topic into topic. NULL when configs is empty or not vmac's. */
static json_t *device_config(struct vmac_mqtt *m, json_t *configs, char *const *before, int nbefore, int stubs,
                             char *topic, size_t topiclen)
{
	json_t *out = NULL, *components = json_object(), *c;
	const char *key;
	char component[100], node[100] = "", object[100];
	int i;
	json_object_foreach(configs, key, c)
	{
		json_t *comp;
		if (split(m, key, component, node, object, sizeof(component)) != 0)
			continue;
		if (!out)
			out = json_pack("{s:O, s:O}", "device", json_object_get(c, "device"), "origin",
			                json_object_get(c, "origin"));
		comp = json_deep_copy(c);
		json_object_del(comp, "device");
		json_object_del(comp, "origin");
		json_object_set_new(comp, "platform", json_string(component));
		json_object_set_new(components, object, comp);
	}
	for (i = 0; stubs && i < nbefore; i++)
		if (!json_object_get(configs, before[i]) &&
		    split(m, before[i], component, node, object, sizeof(node)) == 0 &&
		    !json_object_get(components, object))
			json_object_set_new(components, object, json_pack("{s:s}", "platform", component));
	if (!out) {
		json_decref(components);
		return NULL;
	}
	json_object_set_new(out, "components", components);
	snprintf(topic, topiclen, "%s/device/%s/config", m->s.discovery_prefix, node);
	return out;
}

void mqtt_ha_publish(struct vmac_mqtt *m, json_t *o, char *const *before, int nbefore)
{
	json_t *c, *dev;
	const char *topic;
	char dtopic[300];
	int i, removed = 0;
	if (!o)
		return;
	for (i = 0; i < nbefore; i++)
		removed += !json_object_get(o, before[i]);
	if (!m->s.ha_device) {
		for (i = 0; i < nbefore; i++)
			if (!json_object_get(o, before[i]))
				mqtt_publish(m, before[i], "", 0, 1, 1);
		json_object_foreach(o, topic, c) publish_json(m, topic, c);
	} else {
		if (removed && (dev = device_config(m, o, before, nbefore, 1, dtopic, sizeof(dtopic))) != NULL) {
			publish_json(m, dtopic, dev);
			json_decref(dev);
		}
		if ((dev = device_config(m, o, NULL, 0, 0, dtopic, sizeof(dtopic))) != NULL) {
			publish_json(m, dtopic, dev);
			json_decref(dev);
		}
	}
	json_decref(o);
}

void mqtt_ha_watch(struct vmac_mqtt *m, const char *node)
{
	char filter[300];
	if (m->s.ha_device)
		snprintf(filter, sizeof(filter), "%s/+/%s/+/config", m->s.discovery_prefix, node);
	else
		snprintf(filter, sizeof(filter), "%s/device/%s/config", m->s.discovery_prefix, node);
	mqtt_subscribe(m, filter, 1);
}

int mqtt_ha_takes_retained(const struct vmac_mqtt *m, const char *topic)
{
	size_t dl = strlen(m->s.discovery_prefix), n = strlen(topic);
	return strncmp(topic, m->s.discovery_prefix, dl) == 0 && topic[dl] == '/' && n > 7 &&
	       strcmp(topic + n - 7, "/config") == 0;
}

/* DISCOVERY/device/NODE/config: NODE into node; 0, or -1. */
static int device_topic(const struct vmac_mqtt *m, const char *topic, char *node, size_t n)
{
	size_t dl = strlen(m->s.discovery_prefix), tl = strlen(topic);
	if (strncmp(topic, m->s.discovery_prefix, dl) != 0 || strncmp(topic + dl, "/device/", 8) != 0 || tl < dl + 16 ||
	    strcmp(topic + tl - 7, "/config") != 0 || tl - 7 - (dl + 8) >= n)
		return -1;
	memcpy(node, topic + dl + 8, tl - 7 - (dl + 8));
	node[tl - 7 - (dl + 8)] = 0;
	return strchr(node, '/') ? -1 : 0;
}

int mqtt_ha_leftover(struct vmac_mqtt *m, const struct mqtt_message *msg, const char *node, struct mqtt_ha_left *left)
{
	char component[100], theirs[100], object[100];
	char **more;
	int other_mode;
	if (m->s.ha_device)
		other_mode = split(m, msg->topic, component, theirs, object, sizeof(theirs)) == 0 &&
		             strcmp(component, "device") != 0 && strcmp(theirs, node) == 0;
	else
		other_mode = device_topic(m, msg->topic, theirs, sizeof(theirs)) == 0 && strcmp(theirs, node) == 0;
	if (!other_mode)
		return 0;
	if (!msg->retained || msg->len == 0)
		return 1; /* live: this host's own clearing, or HA's business */
	if (msg->len != (int)strlen(MIGRATE) || memcmp(msg->payload, MIGRATE, (size_t)msg->len) != 0)
		mqtt_publish(m, msg->topic, MIGRATE, -1, 1, 0);
	if (!(more = realloc(left->topics, (size_t)(left->n + 1) * sizeof(*more))))
		return 1;
	left->topics = more;
	if ((left->topics[left->n] = strdup(msg->topic)) != NULL)
		left->n++;
	return 1;
}

void mqtt_ha_left_clear(struct vmac_mqtt *m, struct mqtt_ha_left *left, const char *device)
{
	int i;
	if (!left->n)
		return;
	for (i = 0; i < left->n; i++)
		mqtt_publish(m, left->topics[i], "", 0, 1, 1);
	mqtt_event(m, device,
	           "Home Assistant: %d discovery config%s of %s found and migrated to %s discovery (HA's "
	           "migrate_discovery, then cleared)",
	           left->n, left->n == 1 ? "" : "s", m->s.ha_device ? "single components" : "a device",
	           m->s.ha_device ? "device-based" : "single component");
	mqtt_ha_left_free(left);
}

void mqtt_ha_left_free(struct mqtt_ha_left *left)
{
	int i;
	for (i = 0; i < left->n; i++)
		free(left->topics[i]);
	free(left->topics);
	left->topics = NULL;
	left->n = 0;
}
