/* The machines as the MQTT client sees them: every MQTT_POLL_MS the bus's
 * status copy (vmac_bus_status: what the bus thread published at most
 * 100 ms ago, with a trylock, so reading it never holds the bus back) is
 * compared with what was published, on each connection separately (each
 * has its own table: Sparkplug's births and deaths go on while the main
 * connection is away, and a main-only reconnect says nothing on Sparkplug's). A machine that starts running, or runs
 * a new driver version, is "up"; one that stops running is "down"; values
 * that changed go out, the newest only (a value that changed five times
 * while the broker was away is published once, as it is now). A variable
 * declared with update = "timer:N" goes out at most every N s; a number
 * declared with a precision goes out when it has moved a whole step of that
 * precision from what was published (mqtt_value_moved). */
#include "mqtt_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../driver/hints.h"
#include "../loader/loader.h"

/* From after the last find on, round the table: the poll, HA's configs and
 * Sparkplug's births ask in the status's order, which is the table's (the
 * table grows in that order and keeps a machine that left), so a lookup is
 * one compare, not a walk over every machine before it. */
struct mqtt_device *mqtt_conn_device_find(struct mqtt_conn *c, const char *name)
{
	int k;
	for (k = 0; k < c->ndevices; k++) {
		int i = (c->find_next + k) % c->ndevices;
		if (strcmp(c->devices[i].name, name) == 0) {
			c->find_next = i + 1;
			return &c->devices[i];
		}
	}
	return NULL;
}

struct mqtt_device *mqtt_device_find(struct vmac_mqtt *m, const char *name)
{
	return mqtt_conn_device_find(&m->conns[MQTT_CONN_MAIN], name);
}

static struct mqtt_device *device_add(struct mqtt_conn *c, const char *name)
{
	struct mqtt_device *d;
	if (c->ndevices == c->cap) {
		int cap = c->cap ? 2 * c->cap : 16;
		struct mqtt_device *more = realloc(c->devices, (size_t)cap * sizeof(*more));
		if (!more)
			return NULL;
		c->devices = more;
		c->cap = cap;
	}
	d = &c->devices[c->ndevices++];
	memset(d, 0, sizeof(*d));
	snprintf(d->name, sizeof(d->name), "%s", name);
	d->conn = c->index;
	return d;
}

/* The declaration of variable or param name in the manifest (NULL: none). */
static json_t *declaration(json_t *manifest, const char *name)
{
	json_t *decl = json_object_get(json_object_get(manifest, "variables"), name);
	return decl ? decl : json_object_get(json_object_get(manifest, "params"), name);
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
	v->precision = mqtt_declared_precision(declaration(d->manifest, name));
	v->kind = vmac_hints_kind(declaration(d->manifest, name));
	return v;
}

/* The values of st that changed since they were published (all with
 * force), published: variables then params. A variable declared
 * update = "timer:N" changes in the status copy at most every N s (the
 * driver's instance publishes it so, core/driver/instance.c): no second
 * clock here, which drifting against that one would lose its steps. */
static void publish_values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st, int force)
{
	struct mqtt_value *changed[MQTT_VALUES];
	int n = 0, i;
	if (!mqtt_conn_can_publish(&m->conns[d->conn])) {
		m->skipped_rounds++; /* they stay unsent: the newest goes out when there is room */
		return;
	}
	for (i = 0; i < st->nvars + st->nparams; i++) {
		const struct vmac_variable *var = i < st->nvars ? &st->vars[i] : &st->params[i - st->nvars];
		struct mqtt_value *v = value_slot(d, var->name);
		struct vmac_value shown;
		char text[MQTT_TEXT_MAX];
		if (!v)
			continue;
		shown = var->value;
		if (shown.type != VMAC_VALUE_NONE && ((v->kind == 'n' && shown.type != VMAC_VALUE_NUMBER) ||
		                                      (v->kind == 'b' && shown.type != VMAC_VALUE_BOOL)))
			shown.type = VMAC_VALUE_NONE; /* not what its entity reads: unknown, not an error in HA's log */
		mqtt_value_text_at(&shown, v->precision, text, sizeof(text));
		if (!force && v->sent && !mqtt_value_moved(&shown, v->precision, text, v->text))
			continue; /* no change, or one under a step of its precision */
		snprintf(v->text, sizeof(v->text), "%s", text);
		v->sent = 1;
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
	if (!mqtt_conn_is_up(&m->conns[d->conn]))
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

/* The status copy m->status against connection c's table. */
static void poll_conn(struct vmac_mqtt *m, struct mqtt_conn *c)
{
	int i;
	for (i = 0; i < c->ndevices; i++)
		c->devices[i].seen = 0;
	for (i = 0; i < m->status.ndevices; i++) {
		const struct vmac_device_status *st = &m->status.devices[i];
		struct mqtt_device *d;
		if (!is_machine(st))
			continue;
		d = mqtt_conn_device_find(c, st->name);
		if (!d && !(d = device_add(c, st->name)))
			continue;
		d->seen = 1;
		if (!d->online || strcmp(d->driver, st->driver) != 0 || strcmp(d->version, st->driver_version) != 0)
			go_up(m, d, st); /* new, back, or a hot reload */
		else
			publish_values(m, d, st, 0);
		if (d->online)
			mqtt_profiles_tick(m, d, st);
	}
	for (i = 0; i < c->ndevices; i++) {
		struct mqtt_device *d = &c->devices[i];
		if (!d->seen && d->online && mqtt_conn_is_up(c)) {
			d->online = 0;
			mqtt_profiles_device_down(m, d);
		}
	}
}

void mqtt_devices_poll(struct vmac_mqtt *m)
{
	int k;
	vmac_bus_status(m->bus, &m->status);
	for (k = 0; k < MQTT_CONNS; k++)
		if (m->conns[k].mosq)
			poll_conn(m, &m->conns[k]);
}

void mqtt_devices_republish(struct vmac_mqtt *m, struct mqtt_conn *c)
{
	int i;
	for (i = 0; i < c->ndevices; i++) {
		struct mqtt_device *d = &c->devices[i];
		int k;
		for (k = 0; k < d->nvalues; k++)
			d->values[k].sent = 0;
		d->online = 0; /* up again, with every value, at this poll */
	}
	vmac_bus_status(m->bus, &m->status);
	poll_conn(m, c);
	/* The others are said offline again: dropped while the broker was away,
	 * or a broker that lost its retained messages. */
	for (i = 0; i < c->ndevices; i++)
		if (!c->devices[i].online && mqtt_conn_is_up(c))
			mqtt_profiles_device_down(m, &c->devices[i]);
}

void mqtt_devices_stopping(struct vmac_mqtt *m)
{
	int i, k;
	for (k = 0; k < MQTT_CONNS; k++)
		for (i = 0; i < m->conns[k].ndevices; i++) {
			struct mqtt_device *d = &m->conns[k].devices[i];
			if (d->online) {
				d->online = 0;
				mqtt_profiles_device_down(m, d);
			}
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
	int i, k, c;
	for (c = 0; c < MQTT_CONNS; c++) {
		struct mqtt_conn *conn = &m->conns[c];
		for (i = 0; i < conn->ndevices; i++) {
			struct mqtt_device *d = &conn->devices[i];
			json_decref(d->manifest);
			for (k = 0; k < d->nconfigs; k++)
				free(d->configs[k]);
			free(d->configs);
			free(d->spb_metrics);
			mqtt_ha_left_free(&d->ha_left);
		}
		free(conn->devices);
		conn->devices = NULL;
		conn->ndevices = conn->cap = 0;
	}
	mqtt_ha_left_free(&m->ha_host_left);
}
