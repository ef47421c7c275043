/* The machines as the MQTT client sees them: every MQTT_POLL_MS the bus's
 * status copy (vmac_bus_status: what the bus thread published at most
 * 100 ms ago, with a trylock, so reading it never holds the bus back) is
 * compared with what was published. A machine that starts running, or runs
 * a new driver version, is "up"; one that stops running is "down"; values
 * that changed go out, the newest only (a value that changed five times
 * while the broker was away is published once, as it is now). A variable
 * declared with update = "timer:N" goes out at most every N s; a number
 * declared with a precision goes out when it changes at that precision. */
#include "mqtt_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../loader/loader.h"

struct mqtt_device *mqtt_device_find(struct vmac_mqtt *m, const char *name)
{
	int i;
	for (i = 0; i < m->ndevices; i++)
		if (strcmp(m->devices[i].name, name) == 0)
			return &m->devices[i];
	return NULL;
}

static struct mqtt_device *device_add(struct vmac_mqtt *m, const char *name)
{
	struct mqtt_device *d;
	if (m->ndevices == m->cap) {
		int cap = m->cap ? 2 * m->cap : 16;
		struct mqtt_device *more = realloc(m->devices, (size_t)cap * sizeof(*more));
		if (!more)
			return NULL;
		m->devices = more;
		m->cap = cap;
	}
	d = &m->devices[m->ndevices++];
	memset(d, 0, sizeof(*d));
	snprintf(d->name, sizeof(d->name), "%s", name);
	return d;
}

/* The declaration of variable or param name in the manifest (NULL: none). */
static json_t *declaration(json_t *manifest, const char *name)
{
	json_t *decl = json_object_get(json_object_get(manifest, "variables"), name);
	return decl ? decl : json_object_get(json_object_get(manifest, "params"), name);
}

/* timer:N of variable name in the manifest: N, else 0. */
static double timer_period(json_t *manifest, const char *name)
{
	json_t *var = json_object_get(json_object_get(manifest, "variables"), name);
	const char *update = json_string_value(json_object_get(var, "update"));
	double n;
	if (update && sscanf(update, "timer:%lf", &n) == 1 && n > 0)
		return n;
	return 0;
}

static struct mqtt_value *value_slot(struct mqtt_device *d, const char *name)
{
	struct mqtt_value *v;
	int i;
	for (i = 0; i < d->nvalues; i++)
		if (strcmp(d->values[i].name, name) == 0)
			return &d->values[i];
	if (d->nvalues == MQTT_VALUES)
		return NULL;
	v = &d->values[d->nvalues++];
	memset(v, 0, sizeof(*v));
	snprintf(v->name, sizeof(v->name), "%s", name);
	v->period_s = timer_period(d->manifest, name);
	v->precision = mqtt_declared_precision(declaration(d->manifest, name));
	return v;
}

/* The values of st that changed since they were published (all with
 * force), published: variables then params. */
static void publish_values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st, int force)
{
	struct mqtt_value *changed[MQTT_VALUES];
	double now = mqtt_now_s();
	int n = 0, i;
	if (!mqtt_can_publish_values(m)) {
		m->skipped_rounds++; /* they stay unsent: the newest goes out when there is room */
		return;
	}
	for (i = 0; i < st->nvars + st->nparams; i++) {
		const struct vmac_variable *var = i < st->nvars ? &st->vars[i] : &st->params[i - st->nvars];
		struct mqtt_value *v = value_slot(d, var->name);
		char text[MQTT_TEXT_MAX];
		if (!v)
			continue;
		mqtt_value_text_at(&var->value, v->precision, text, sizeof(text)); /* a change that shows */
		if (!force && v->sent && strcmp(v->text, text) == 0)
			continue;
		if (!force && v->sent && now < v->next_s)
			continue; /* timer:N: not yet; the newest goes out when due */
		snprintf(v->text, sizeof(v->text), "%s", text);
		v->sent = 1;
		v->next_s = now + v->period_s;
		changed[n++] = v;
	}
	if (n)
		mqtt_profiles_values(m, d, st, changed, n);
}

/* The manifest of the version d runs now; 0, or -1 when not known yet. */
static int load_manifest(struct mqtt_device *d, const struct vmac_device_status *st)
{
	char *text = vmac_loaded_manifest(st->driver, st->driver_version);
	json_t *j = text ? json_loads(text, 0, NULL) : NULL;
	free(text);
	if (!j)
		return -1;
	json_decref(d->manifest);
	d->manifest = j;
	snprintf(d->driver, sizeof(d->driver), "%s", st->driver);
	snprintf(d->version, sizeof(d->version), "%s", st->driver_version);
	d->nvalues = 0; /* periods and names from this version's manifest */
	return 0;
}

static void go_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	if ((!d->manifest || strcmp(d->driver, st->driver) != 0 || strcmp(d->version, st->driver_version) != 0) &&
	    load_manifest(d, st) != 0)
		return; /* not known yet: next round */
	if (!mqtt_conn_is_up(&m->conns[MQTT_CONN_MAIN]))
		return; /* said when the connection is back (mqtt_devices_republish) */
	d->online = 1;
	mqtt_profiles_device_up(m, d, st);
	publish_values(m, d, st, 1);
}

/* A machine is its primary board: the others carry no variables. */
static int is_machine(const struct vmac_device_status *st)
{
	return strcmp(st->state, "running") == 0 && st->driver_version[0] &&
	       (!st->machine[0] || strcmp(st->machine, st->name) == 0);
}

void mqtt_devices_poll(struct vmac_mqtt *m)
{
	int i;
	vmac_bus_status(m->bus, &m->status);
	for (i = 0; i < m->ndevices; i++)
		m->devices[i].seen = 0;
	for (i = 0; i < m->status.ndevices; i++) {
		const struct vmac_device_status *st = &m->status.devices[i];
		struct mqtt_device *d;
		if (!is_machine(st))
			continue;
		d = mqtt_device_find(m, st->name);
		if (!d && !(d = device_add(m, st->name)))
			continue;
		d->seen = 1;
		if (!d->online || strcmp(d->driver, st->driver) != 0 || strcmp(d->version, st->driver_version) != 0)
			go_up(m, d, st); /* new, back, or a hot reload */
		else
			publish_values(m, d, st, 0);
	}
	for (i = 0; i < m->ndevices; i++) {
		struct mqtt_device *d = &m->devices[i];
		if (!d->seen && d->online && mqtt_conn_is_up(&m->conns[MQTT_CONN_MAIN])) {
			d->online = 0;
			mqtt_profiles_device_down(m, d);
		}
	}
}

void mqtt_devices_republish(struct vmac_mqtt *m)
{
	int i;
	for (i = 0; i < m->ndevices; i++) {
		struct mqtt_device *d = &m->devices[i];
		int k;
		for (k = 0; k < d->nvalues; k++)
			d->values[k].sent = 0;
		d->online = 0; /* up again, with every value, at this poll */
	}
	mqtt_devices_poll(m);
	/* The others are said offline again: dropped while the broker was away,
	 * or a broker that lost its retained messages. */
	for (i = 0; i < m->ndevices; i++)
		if (!m->devices[i].online && mqtt_conn_is_up(&m->conns[MQTT_CONN_MAIN]))
			mqtt_profiles_device_down(m, &m->devices[i]);
}

void mqtt_devices_stopping(struct vmac_mqtt *m)
{
	int i;
	for (i = 0; i < m->ndevices; i++)
		if (m->devices[i].online) {
			m->devices[i].online = 0;
			mqtt_profiles_device_down(m, &m->devices[i]);
		}
	mqtt_profiles_stopping(m);
}

const struct vmac_value *mqtt_status_value(const struct vmac_device_status *st, const char *name)
{
	int i;
	for (i = 0; st && i < st->nvars; i++)
		if (strcmp(st->vars[i].name, name) == 0)
			return &st->vars[i].value;
	for (i = 0; st && i < st->nparams; i++)
		if (strcmp(st->params[i].name, name) == 0)
			return &st->params[i].value;
	return NULL;
}

void mqtt_devices_free(struct vmac_mqtt *m)
{
	int i, k;
	for (i = 0; i < m->ndevices; i++) {
		json_decref(m->devices[i].manifest);
		for (k = 0; k < m->devices[i].nconfigs; k++)
			free(m->devices[i].configs[k]);
		free(m->devices[i].configs);
		free(m->devices[i].spb_metrics);
	}
	free(m->devices);
	m->devices = NULL;
	m->ndevices = m->cap = 0;
}
