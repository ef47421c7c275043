/* Profile "ha": Home Assistant MQTT discovery (docs/MQTT.md, "Home
 * Assistant"). One HA device per machine, its entities made from the
 * driver's manifest (vmac_driver_describe's JSON) and published retained
 * under DISCOVERY/COMPONENT/NODE/OBJECT/config; the host is a device too
 * (every machine's via_device). Entities read and write vmac's own topics
 * (mqtt_native.c). Configs are published again when HA says it is online
 * on DISCOVERY/status, and a config of the previous driver version that the
 * new one no longer has is removed (an empty retained payload). An entity
 * whose kind only its value tells (no default, no unit) and that had no
 * value yet is configured as a string, and configured again when a value
 * says it is a boolean or a number (device_up comes with the first status
 * copy that shows the machine running: before its driver's first tick).
 * What HA accepts of each config (device classes, units, state classes,
 * categories) is docs/MQTT.md's "Conformance: Home Assistant"; the
 * driver's hints (core/driver/hints.c) are checked against it at load, and
 * a class is put only on the platform that takes it. Beside the values,
 * every machine has diagnostic sensors of its health and an event entity
 * (mqtt_health.c publishes both), and so does the host. mqtt_ha_device.c
 * publishes them per entity or, with mqtt_discovery_mode = device, one per
 * HA device, and migrates what the other mode left on the broker. */
#include "mqtt_internal.h"

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/version.h"
#include "../driver/hints.h"

/* s with every character outside [A-Za-z0-9_-] made '_' (HA's ids). */
static void ha_id(char *out, size_t outlen, const char *s)
{
	size_t i;
	for (i = 0; s[i] && i + 1 < outlen; i++)
		out[i] = isalnum((unsigned char)s[i]) || s[i] == '-' || s[i] == '_' ? s[i] : '_';
	out[i] = 0;
}

static const char *ha_unit(const char *unit)
{
	return vmac_hints_ha_unit(unit);
}

/* Who made the configs, for HA's logs (discovery.py, MQTT_ORIGIN_INFO_SCHEMA). */
static json_t *origin(void)
{
	return json_pack("{s:s, s:s}", "name", "vmac", "sw_version", VMAC_VERSION_STRING);
}

struct ha {
	const struct vmac_mqtt_settings *s;
	const char *device;
	char topic_base[300]; /* PREFIX/HOST/DEVICE */
	char node[160];       /* HOST_DEVICE */
	char dev_id[180];     /* vmac_HOST_DEVICE */
	json_t *device_obj;
	json_t *out;
};

static json_t *entity(struct ha *h, const char *name, json_t *decl)
{
	char uid[240], topic[400], host_status[300];
	const char *label = json_string_value(json_object_get(decl, "label"));
	const char *category = json_string_value(json_object_get(decl, "entity_category"));
	json_t *e;
	snprintf(uid, sizeof(uid), "%s_%s", h->dev_id, name);
	snprintf(topic, sizeof(topic), "%s/_availability", h->topic_base);
	snprintf(host_status, sizeof(host_status), "%s/%s/status", h->s->prefix, h->s->host_id);
	/* Available only while both the host and the machine say online. */
	e = json_pack("{s:s, s:s, s:[{s:s}, {s:s}], s:s, s:O, s:o}", "name", label ? label : name, "unique_id", uid,
	              "availability", "topic", host_status, "topic", topic, "availability_mode", "all", "device",
	              h->device_obj, "origin", origin());
	if (e && category && strcmp(category, "diagnostic") == 0)
		json_object_set_new(e, "entity_category", json_string("diagnostic"));
	if (e && json_is_false(json_object_get(decl, "enabled_by_default")))
		json_object_set_new(e, "enabled_by_default", json_false());
	return e;
}

/* The declaration's device_class, where component takes it with its unit. */
static void device_class(json_t *e, json_t *decl, const char *component)
{
	const char *dc = json_string_value(json_object_get(decl, "device_class"));
	if (dc && vmac_hints_fits(component, dc, json_string_value(json_object_get(decl, "unit"))))
		json_object_set_new(e, "device_class", json_string(dc));
}

/* Whether values can be HA's options: a non-empty array of strings,
 * numbers or booleans (option_texts makes them the texts published). */
static int string_options(json_t *values)
{
	size_t i;
	json_t *v;
	if (!json_is_array(values) || json_array_size(values) == 0)
		return 0;
	json_array_foreach(values, i, v) if (!json_is_string(v) && !json_is_number(v) && !json_is_boolean(v)) return 0;
	return 1;
}

static void add(struct ha *h, const char *component, const char *name, json_t *config)
{
	char topic[512], object[64];
	if (!config)
		return;
	ha_id(object, sizeof(object), name);
	snprintf(topic, sizeof(topic), "%s/%s/%s/%s/config", h->s->discovery_prefix, component, h->node, object);
	json_object_set_new(h->out, topic, config);
}

/* The kind of a declared value: 'n' number, 'b' boolean, 's' string, from
 * its declaration, else from its value now; '?' when neither says (no value
 * yet), configured as a string. */
static char kind_of(json_t *decl, const struct vmac_value *now)
{
	char kind = vmac_hints_kind(decl);
	if (kind != '?')
		return kind;
	if (now && now->type == VMAC_VALUE_BOOL)
		return 'b';
	if (now && now->type == VMAC_VALUE_STRING)
		return 's';
	return now && now->type == VMAC_VALUE_NUMBER ? 'n' : '?';
}

static int whole(json_t *v)
{
	double x = json_number_value(v);
	return !v || (json_is_number(v) && floor(x) == x);
}

/* A select's options as the texts its state topic carries (HA compares the
 * state with them as strings): a number as mqtt_value_text writes it (2, not
 * 2.0), a boolean true/false. */
static json_t *option_texts(json_t *values)
{
	json_t *out = json_array(), *x;
	size_t i;
	json_array_foreach(values, i, x)
	{
		struct vmac_value v;
		char text[MQTT_TEXT_MAX];
		if (json_is_string(x)) {
			json_array_append(out, x);
			continue;
		}
		memset(&v, 0, sizeof(v));
		v.type = json_is_boolean(x) ? VMAC_VALUE_BOOL : VMAC_VALUE_NUMBER;
		v.number = json_is_boolean(x) ? json_is_true(x) : json_number_value(x);
		mqtt_value_text(&v, text, sizeof(text));
		json_array_append_new(out, json_string(text));
	}
	return out;
}

/* A read-only view: sensor (with its unit, class and precision; an enum
 * when its values are strings) or binary_sensor. A "config" category is
 * left out: HA refuses it on a sensor (SensorEntity's
 * async_internal_added_to_hass). */
static void add_reader(struct ha *h, const char *name, json_t *decl, char kind)
{
	json_t *e = entity(h, name, decl), *values = json_object_get(decl, "values"), *v;
	const char *unit = json_string_value(json_object_get(decl, "unit"));
	char state[400];
	snprintf(state, sizeof(state), "%s/%s", h->topic_base, name);
	json_object_set_new(e, "state_topic", json_string(state));
	if (kind == 'b') {
		json_object_set_new(e, "payload_on", json_string("true"));
		json_object_set_new(e, "payload_off", json_string("false"));
		device_class(e, decl, "binary_sensor");
		add(h, "binary_sensor", name, e);
		return;
	}
	if (kind == 's' && string_options(values)) {
		json_object_set_new(e, "device_class", json_string("enum"));
		json_object_set_new(e, "options", option_texts(values));
	} else if (kind == 'n') {
		const char *dc = json_string_value(json_object_get(decl, "device_class"));
		if (unit)
			json_object_set_new(e, "unit_of_measurement", json_string(ha_unit(unit)));
		device_class(e, decl, "sensor");
		if ((v = json_object_get(decl, "state_class")) != NULL && (!dc || json_object_get(e, "device_class")))
			json_object_set(e, "state_class", v);
		if (json_is_number(v = json_object_get(decl, "precision")))
			json_object_set_new(e, "suggested_display_precision",
			                    json_integer((json_int_t)json_number_value(v)));
	} else if (kind == 's') {
		device_class(e, decl, "sensor"); /* timestamp, date */
	}
	add(h, "sensor", name, e);
}

/* A settable value: switch, number, select or text. */
static void add_writer(struct ha *h, const char *name, json_t *decl, char kind, int config)
{
	json_t *e = entity(h, name, decl), *values = json_object_get(decl, "values");
	const char *unit = json_string_value(json_object_get(decl, "unit"));
	const char *component;
	char t[400];
	snprintf(t, sizeof(t), "%s/%s", h->topic_base, name);
	json_object_set_new(e, "state_topic", json_string(t));
	snprintf(t, sizeof(t), "%s/set/%s", h->topic_base, name);
	json_object_set_new(e, "command_topic", json_string(t));
	/* The declaration's category wins; else a param is a setting. */
	if (json_is_string(json_object_get(decl, "entity_category")))
		json_object_set(e, "entity_category", json_object_get(decl, "entity_category"));
	else if (config)
		json_object_set_new(e, "entity_category", json_string("config"));
	if (kind == 'b') {
		component = "switch";
		device_class(e, decl, component);
		json_object_set_new(e, "payload_on", json_string("true"));
		json_object_set_new(e, "payload_off", json_string("false"));
		json_object_set_new(e, "state_on", json_string("true"));
		json_object_set_new(e, "state_off", json_string("false"));
	} else if (kind == 'n') {
		json_t *min = json_object_get(decl, "min"), *max = json_object_get(decl, "max"),
		       *step = json_object_get(decl, "step");
		component = "number";
		json_object_set_new(e, "min", json_real(json_is_number(min) ? json_number_value(min) : -1e9));
		json_object_set_new(e, "max", json_real(json_is_number(max) ? json_number_value(max) : 1e9));
		json_object_set_new(e, "step",
		                    json_real(json_is_number(step) ? json_number_value(step)
		                              : whole(min) && whole(max) && whole(json_object_get(decl, "default"))
		                                  ? 1
		                                  : 0.001));
		json_object_set_new(e, "mode", json_string("box"));
		if (unit)
			json_object_set_new(e, "unit_of_measurement", json_string(ha_unit(unit)));
		device_class(e, decl, component);
	} else if (string_options(values)) {
		component = "select";
		json_object_set_new(e, "options", option_texts(values));
	} else {
		component = "text";
		json_object_set_new(e, "max", json_integer(VMAC_DRIVER_STR_MAX));
	}
	add(h, component, name, e);
}

/* Whether name is the argument of a command (a cycle's programme). */
static int is_command_arg(json_t *commands, const char *name)
{
	const char *key;
	json_t *c;
	json_object_foreach(commands, key, c)
	{
		const char *arg = json_string_value(json_object_get(c, "arg"));
		if (arg && strcmp(arg, name) == 0)
			return 1;
	}
	return 0;
}

/* The kind of every variable, then every param, of the manifest (kind_of's
 * letters) into out: what decides each entity's component. */
static void kinds_of(json_t *manifest, const struct vmac_device_status *st, char *out, size_t outlen)
{
	static const char *const tables[] = {"variables", "params"};
	const char *name;
	json_t *decl;
	size_t n = 0, t;
	for (t = 0; t < 2; t++)
		json_object_foreach(json_object_get(manifest, tables[t]), name, decl)
		{
			if (n + 1 < outlen)
				out[n++] = kind_of(decl, mqtt_status_value(st, name));
		}
	out[n] = 0;
}

/* Whether two kinds_of make the same configs ('?' is configured as 's'). */
static int same_components(const char *a, const char *b)
{
	for (; *a && *b; a++, b++)
		if ((*a == '?' ? 's' : *a) != (*b == '?' ? 's' : *b))
			return 0;
	return *a == *b;
}

/* A diagnostic sensor reading one field of a JSON health topic. */
static json_t *health_sensor(json_t *common, const char *uid, const char *label, const char *state_topic,
                             const char *field, const char *unit, const char *dc, const char *state_class, int enabled)
{
	char tpl[120];
	json_t *e = json_deep_copy(common);
	snprintf(tpl, sizeof(tpl), "{{ value_json.%s }}", field);
	json_object_set_new(e, "name", json_string(label));
	json_object_set_new(e, "unique_id", json_string(uid));
	json_object_set_new(e, "state_topic", json_string(state_topic));
	json_object_set_new(e, "value_template", json_string(tpl));
	json_object_set_new(e, "entity_category", json_string("diagnostic"));
	if (state_class)
		json_object_set_new(e, "state_class", json_string(state_class));
	/* A heartbeat comes every MQTT_HEALTH_HEARTBEAT_S: none for this long
	 * (the publisher stopped, the connection lives on) shows unknown. */
	json_object_set_new(e, "expire_after", json_integer(MQTT_HEALTH_EXPIRE_S));
	if (unit)
		json_object_set_new(e, "unit_of_measurement", json_string(unit));
	if (dc)
		json_object_set_new(e, "device_class", json_string(dc));
	if (!enabled)
		json_object_set_new(e, "enabled_by_default", json_false());
	return e;
}

/* The machine's health (PREFIX/HOST/DEVICE/_health, mqtt_health.c) as
 * diagnostic sensors, and its events (_event) as an event entity that
 * only the host's status makes unavailable, so that a drop is seen. */
static void add_health(struct ha *h, json_t *manifest)
{
	static const struct {
		const char *field, *label, *unit, *dc, *state_class;
		int enabled;
	} fields[] = {
	    {"misses", "Misses", NULL, NULL, "total_increasing", 1},
	    {"driver_late", "Late ticks", NULL, NULL, "total_increasing", 0},
	    {"driver_memory_kb", "Driver memory", "kB", "data_size", "measurement", 0},
	    /* The primary board's clock (docs/TIME.md): null, unknown to HA,
	     * until it sends a TIMED reply. An enum takes no state class. */
	    {"clock_state", "Clock", NULL, "enum", NULL, 1},
	    {"clock_bound_us", "Clock error bound", "µs", NULL, "measurement", 0},
	};
	char state[400], uid[300], host_status[300], object[64];
	json_t *none = json_object(), *common = entity(h, "_health", none), *e, *types;
	size_t i;
	snprintf(state, sizeof(state), "%s/_health", h->topic_base);
	for (i = 0; common && i < sizeof(fields) / sizeof(fields[0]); i++) {
		snprintf(uid, sizeof(uid), "%s__health_%s", h->dev_id, fields[i].field);
		snprintf(object, sizeof(object), "_health_%s", fields[i].field);
		e = health_sensor(common, uid, fields[i].label, state, fields[i].field, fields[i].unit, fields[i].dc,
		                  fields[i].state_class, fields[i].enabled);
		if (e && fields[i].dc && strcmp(fields[i].dc, "enum") == 0) {
			json_t *options = json_array();
			int k;
			for (k = 0; mqtt_clock_states[k]; k++)
				json_array_append_new(options, json_string(mqtt_clock_states[k]));
			json_object_set_new(e, "options", options);
		}
		add(h, "sensor", object, e);
	}
	json_decref(common);
	json_decref(none);
	snprintf(uid, sizeof(uid), "%s__event", h->dev_id);
	snprintf(state, sizeof(state), "%s/_event", h->topic_base);
	snprintf(host_status, sizeof(host_status), "%s/%s/status", h->s->prefix, h->s->host_id);
	types = mqtt_health_event_types(manifest);
	e = json_pack("{s:s, s:s, s:s, s:o, s:[{s:s}], s:O, s:o}", "name", "Events", "unique_id", uid, "state_topic",
	              state, "event_types", types, "availability", "topic", host_status, "device", h->device_obj,
	              "origin", origin());
	add(h, "event", "_event", e);
}

json_t *mqtt_ha_configs(const struct vmac_mqtt_settings *s, const char *device, const char *driver, const char *version,
                        json_t *manifest, const struct vmac_device_status *st)
{
	struct ha h;
	char host_id[80], dev[80], model[100], via[100];
	json_t *commands = json_object_get(manifest, "commands"), *decl;
	const char *name;
	memset(&h, 0, sizeof(h));
	h.s = s;
	h.device = device;
	h.out = json_object();
	ha_id(host_id, sizeof(host_id), s->host_id);
	ha_id(dev, sizeof(dev), device);
	snprintf(h.topic_base, sizeof(h.topic_base), "%s/%s/%s", s->prefix, s->host_id, device);
	snprintf(h.node, sizeof(h.node), "%s_%s", host_id, dev);
	snprintf(h.dev_id, sizeof(h.dev_id), "vmac_%s_%s", host_id, dev);
	snprintf(model, sizeof(model), "%s %s", driver, version);
	snprintf(via, sizeof(via), "vmac_%s", host_id);
	h.device_obj = json_pack("{s:[s], s:s, s:s, s:s, s:s, s:s}", "identifiers", h.dev_id, "name", device, "model",
	                         model, "manufacturer", "vmac", "sw_version", version, "via_device", via);
	if (h.device_obj && s->ui_url[0]) { /* HA's "Visit": the web UI's machines */
		char url[sizeof(s->ui_url) + 16];
		snprintf(url, sizeof(url), "%s#devices", s->ui_url);
		json_object_set_new(h.device_obj, "configuration_url", json_string(url));
	}
	json_object_foreach(json_object_get(manifest, "variables"), name, decl)
	{
		char kind = kind_of(decl, mqtt_status_value(st, name));
		if (json_is_true(json_object_get(decl, "set")) && s->commands)
			add_writer(&h, name, decl, kind, 0);
		else
			add_reader(&h, name, decl, kind);
	}
	json_object_foreach(json_object_get(manifest, "params"), name, decl)
	{
		char kind = kind_of(decl, mqtt_status_value(st, name));
		if (s->commands)
			add_writer(&h, name, decl, kind, !is_command_arg(commands, name));
		else
			add_reader(&h, name, decl, kind);
	}
	if (s->commands)
		json_object_foreach(commands, name, decl)
		{
			json_t *e = entity(&h, name, decl);
			char t[400];
			snprintf(t, sizeof(t), "%s/cmd/%s", h.topic_base, name);
			json_object_set_new(e, "command_topic", json_string(t));
			json_object_set_new(e, "payload_press", json_string("PRESS"));
			add(&h, "button", name, e);
		}
	add_health(&h, manifest);
	json_decref(h.device_obj);
	return h.out;
}

/* A config into the host's configs (o is taken). */
static void publish_config(json_t *configs, const char *topic, json_t *o)
{
	if (o)
		json_object_set_new(configs, topic, o);
}

/* The node of a machine's configs: HOST_DEVICE (ha_id of each). */
static void node_of(const struct vmac_mqtt *m, const char *device, char *out, size_t outlen)
{
	char host_id[80], dev[80];
	ha_id(host_id, sizeof(host_id), m->s.host_id);
	ha_id(dev, sizeof(dev), device);
	snprintf(out, outlen, "%s_%s", host_id, dev);
}

/* The host itself: a device with its connection, its health
 * (PREFIX/HOST/_health, mqtt_health.c) and its audit trail
 * (PREFIX/HOST/audit, mqtt_audit.c), all diagnostic. */
static void publish_host(struct vmac_mqtt *m)
{
	static const struct {
		const char *field, *label, *unit, *dc, *state_class;
		int enabled;
	} fields[] = {
	    {"misses", "Misses", NULL, NULL, "total_increasing", 1},
	    {"drops", "Drops", NULL, NULL, "total_increasing", 1},
	    {"malformed_frames", "Malformed frames", NULL, NULL, "total_increasing", 0},
	    {"lateness_p99_ms", "Lateness (99th percentile)", "ms", "duration", "measurement", 1},
	    {"lateness_max_ms", "Lateness (most)", "ms", "duration", "measurement", 0},
	};
	char host_id[80], topic[512], uid[160], state[300], name[100], via[100], host_status[300];
	json_t *o, *device, *configs = json_object();
	size_t i;
	ha_id(host_id, sizeof(host_id), m->s.host_id);
	snprintf(uid, sizeof(uid), "vmac_%s_status", host_id);
	snprintf(state, sizeof(state), "%s/%s/status", m->s.prefix, m->s.host_id);
	snprintf(name, sizeof(name), "vmac %s", m->s.host_id);
	snprintf(via, sizeof(via), "vmac_%s", host_id);
	device = json_pack("{s:[s], s:s, s:s, s:s, s:s}", "identifiers", via, "name", name, "model", "vmacd",
	                   "manufacturer", "vmac", "sw_version", VMAC_VERSION_STRING);
	if (device && m->s.ui_url[0])
		json_object_set_new(device, "configuration_url", json_string(m->s.ui_url));
	o = json_pack("{s:s, s:s, s:s, s:s, s:s, s:s, s:s, s:O, s:o}", "name", "Connected", "unique_id", uid,
	              "state_topic", state, "payload_on", "online", "payload_off", "offline", "device_class",
	              "connectivity", "entity_category", "diagnostic", "device", device, "origin", origin());
	snprintf(topic, sizeof(topic), "%s/binary_sensor/%s/status/config", m->s.discovery_prefix, host_id);
	publish_config(configs, topic, o);
	snprintf(state, sizeof(state), "%s/%s/_health", m->s.prefix, m->s.host_id);
	snprintf(host_status, sizeof(host_status), "%s/%s/status", m->s.prefix, m->s.host_id);
	o = json_pack("{s:[{s:s}], s:O, s:o}", "availability", "topic", host_status, "device", device, "origin",
	              origin());
	for (i = 0; o && i < sizeof(fields) / sizeof(fields[0]); i++) {
		snprintf(uid, sizeof(uid), "vmac_%s__health_%s", host_id, fields[i].field);
		snprintf(topic, sizeof(topic), "%s/sensor/%s/_health_%s/config", m->s.discovery_prefix, host_id,
		         fields[i].field);
		publish_config(configs, topic,
		               health_sensor(o, uid, fields[i].label, state, fields[i].field, fields[i].unit,
		                             fields[i].dc, fields[i].state_class, fields[i].enabled));
	}
	json_decref(o);
	/* The audit trail (mqtt_audit.c): an event entity whose event_type is
	 * the audit event's type, and whose attributes are the rest. */
	snprintf(uid, sizeof(uid), "vmac_%s_audit", host_id);
	snprintf(state, sizeof(state), "%s/%s/audit", m->s.prefix, m->s.host_id);
	snprintf(topic, sizeof(topic), "%s/event/%s/audit/config", m->s.discovery_prefix, host_id);
	publish_config(configs, topic,
	               json_pack("{s:s, s:s, s:s, s:o, s:s, s:[{s:s}], s:O, s:o}", "name", "Audit", "unique_id", uid,
	                         "state_topic", state, "event_types", mqtt_audit_event_types(), "entity_category",
	                         "diagnostic", "availability", "topic", host_status, "device", device, "origin",
	                         origin()));
	json_decref(device);
	mqtt_ha_publish(m, configs, NULL, 0);
}

static void free_configs(struct mqtt_device *d)
{
	int i;
	for (i = 0; i < d->nconfigs; i++)
		free(d->configs[i]);
	free(d->configs);
	d->configs = NULL;
	d->nconfigs = 0;
}

static void device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	json_t *configs = mqtt_ha_configs(&m->s, d->name, d->driver, d->version, d->manifest, st), *c;
	const char *topic;
	char **kept;
	int n = 0;
	if (!configs)
		return;
	kinds_of(d->manifest, st, d->kinds, sizeof(d->kinds));
	kept = calloc(json_object_size(configs) + 1, sizeof(*kept));
	json_object_foreach(configs, topic, c)
	{
		if (kept && (kept[n] = strdup(topic)) != NULL)
			n++;
	}
	/* Entities of the version before (or of a kind guessed before) that these
	 * configs do not have: removed. */
	mqtt_ha_publish(m, configs, d->configs, d->nconfigs);
	free_configs(d);
	d->configs = kept;
	d->nconfigs = kept ? n : 0;
	if (!d->ha_watched) { /* configs of the other mode left on the broker: migrated (mqtt_ha_device.c) */
		char node[200];
		node_of(m, d->name, node, sizeof(node));
		mqtt_ha_watch(m, node);
		d->ha_watched = 1;
	}
}

/* An entity configured before its kind was known ('?') whose value now says
 * it is a boolean or a number: every config of d again, the guessed one
 * removed (its topic names the component). */
static void values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                   struct mqtt_value *const *changed, int n)
{
	char now[sizeof(d->kinds)];
	(void)changed;
	(void)n;
	if (!strchr(d->kinds, '?'))
		return;
	kinds_of(d->manifest, st, now, sizeof(now));
	if (same_components(d->kinds, now))
		memcpy(d->kinds, now, sizeof(now)); /* a string after all, or still no value */
	else
		device_up(m, d, st);
}

static void connected(struct vmac_mqtt *m)
{
	struct mqtt_conn *c = &m->conns[MQTT_CONN_MAIN];
	char topic[300], host_id[80];
	int i;
	snprintf(topic, sizeof(topic), "%s/status", m->s.discovery_prefix);
	mqtt_subscribe(m, topic, 1);
	publish_host(m);
	ha_id(host_id, sizeof(host_id), m->s.host_id);
	mqtt_ha_watch(m, host_id);
	for (i = 0; i < c->ndevices; i++) /* a new session: subscriptions again as they come up */
		c->devices[i].ha_watched = 0;
}

/* A discovery config of the other mode for the host or one of its
 * machines (mqtt_ha_device.c): 1 when msg was one of theirs. */
static int leftover(struct vmac_mqtt *m, const struct mqtt_message *msg)
{
	struct mqtt_conn *c = &m->conns[MQTT_CONN_MAIN];
	char node[200];
	int i;
	if (!mqtt_ha_takes_retained(m, msg->topic))
		return 0;
	ha_id(node, sizeof(node), m->s.host_id);
	if (mqtt_ha_leftover(m, msg, node, &m->ha_host_left))
		return 1;
	for (i = 0; i < c->ndevices; i++) {
		node_of(m, c->devices[i].name, node, sizeof(node));
		if (mqtt_ha_leftover(m, msg, node, &c->devices[i].ha_left))
			return 1;
	}
	return 0;
}

/* Leftovers of the other mode found since the last read: the configs again
 * in this mode, then the leftovers cleared. */
static void tick(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	if (!d->ha_left.n)
		return;
	device_up(m, d, st);
	mqtt_ha_left_clear(m, &d->ha_left, d->name);
}

static void poll(struct vmac_mqtt *m)
{
	if (!m->ha_host_left.n)
		return;
	publish_host(m);
	mqtt_ha_left_clear(m, &m->ha_host_left, "");
}

/* HA (re)started: it has forgotten what it was told; tell it again. */
static int message(struct vmac_mqtt *m, const struct mqtt_message *msg)
{
	char topic[300];
	int i;
	snprintf(topic, sizeof(topic), "%s/status", m->s.discovery_prefix);
	if (msg->conn != MQTT_CONN_MAIN)
		return 0;
	if (strcmp(msg->topic, topic) != 0)
		return leftover(m, msg);
	if (msg->len == 6 && memcmp(msg->payload, "online", 6) == 0) {
		mqtt_event(m, "", "Home Assistant is online: discovery configs published again");
		publish_host(m);
		for (i = 0; i < m->status.ndevices; i++) {
			struct mqtt_device *d = mqtt_device_find(m, m->status.devices[i].name);
			if (d && d->online)
				device_up(m, d, &m->status.devices[i]);
		}
	}
	return 1;
}

const struct mqtt_profile mqtt_ha_profile = {
    .name = "ha",
    .conn = MQTT_CONN_MAIN,
    .connected = connected,
    .device_up = device_up,
    .values = values,
    .tick = tick,
    .poll = poll,
    .message = message,
};
