/* Profile "health": what Home Assistant's diagnostic sensors and event
 * entities read (docs/MQTT.md, "Home Assistant"; mqtt_ha.c configures
 * them). It publishes, on the main connection:
 *
 *   PREFIX/HOST/DEVICE/_health  retained JSON {"misses", "misses_host",
 *       "served", "driver_late", "driver_memory_kb"}: the machine's primary
 *       board, from the bus's status copy
 *   PREFIX/HOST/_health         retained JSON {"misses", "drops",
 *       "malformed_frames", "lateness_p99_ms", "lateness_max_ms",
 *       "devices"}: the bus
 *   PREFIX/HOST/DEVICE/_event   not retained, {"event_type": T} as HA's
 *       event platform reads it (event.py), T one of
 *       mqtt_health_event_types
 *
 * Health goes out when it changed, at most every HEALTH_PERIOD_S per topic,
 * and at once when a machine comes up; it is looked at whenever the
 * publisher hands a profile a machine's changed values (every status copy
 * that changed one) or a machine going up or down. A machine whose values
 * never change does not bring its health out again: a profile has no hook
 * that runs on every status copy (docs/MQTT.md says so).
 *
 * EVENTS
 *
 * A programme's start, end, cancel and error are read from the stdlib
 * appliance's published variables (stdlib/appliance.lua publish():
 * "state", the cycle's state, and "error"), the only place a driver says
 * them (the cycle's states, stdlib/cycle.lua: idle, running, paused,
 * cancelling, done, failed, cancelled); a driver declaring both variables
 * is taken to be an appliance:
 *   state becomes "running" from anything but "paused" -> programme_started
 *   state becomes "done"                                -> programme_finished
 *   state becomes "cancelled"                           -> programme_cancelled
 *   state becomes "failed" (the error variable says why) -> programme_error
 * The first value after a machine comes up says no event (it is where the
 * programme was, not a change). Every machine has "dropped": it stopped
 * running while the host did not stop (its availability says offline). */
#include "mqtt_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/hist.h"

#define HEALTH_PERIOD_S 10.0

/* What was said of one machine (by name) on this publisher thread. */
struct seen {
	char name[VMAC_NAME_MAX + 1];
	int up;         /* device_up seen, device_down not since */
	int have_state; /* state holds the value before this one */
	char state[MQTT_TEXT_MAX];
	char health[200];     /* the _health text published last */
	double next_health_s; /* monotonic: not before this */
};

/* The publisher thread's own: one MQTT client per process (vmacd's). */
static struct seen *seen;
static int nseen, seen_cap;
static char host_health[300];
static double next_host_health_s;

static struct seen *seen_of(const char *name)
{
	int i;
	for (i = 0; i < nseen; i++)
		if (strcmp(seen[i].name, name) == 0)
			return &seen[i];
	if (nseen == seen_cap) {
		int cap = seen_cap ? seen_cap * 2 : 16;
		struct seen *more = realloc(seen, (size_t)cap * sizeof(*seen));
		if (!more)
			return NULL;
		seen = more;
		seen_cap = cap;
	}
	memset(&seen[nseen], 0, sizeof(seen[0]));
	snprintf(seen[nseen].name, sizeof(seen[0].name), "%s", name);
	return &seen[nseen++];
}

static int is_appliance(json_t *manifest)
{
	json_t *vars = json_object_get(manifest, "variables");
	return json_object_get(vars, "state") && json_object_get(vars, "error");
}

json_t *mqtt_health_event_types(json_t *manifest)
{
	if (is_appliance(manifest))
		return json_pack("[s, s, s, s, s]", "programme_started", "programme_finished", "programme_cancelled",
		                 "programme_error", "dropped");
	return json_pack("[s]", "dropped");
}

static void publish_event(struct vmac_mqtt *m, const char *device, const char *type)
{
	char topic[300], body[120];
	mqtt_topic(m, topic, sizeof(topic), "%s/_event", device);
	snprintf(body, sizeof(body), "{\"event_type\":\"%s\"}", type);
	mqtt_publish(m, topic, body, -1, 1, 0);
}

/* The bus's health, if it changed and its period is over (force: now). */
static void host_health_out(struct vmac_mqtt *m, int force)
{
	const struct vmac_status *st = &m->status;
	char text[sizeof(host_health)], topic[300];
	double now = mqtt_now_s();
	if (!force && now < next_host_health_s)
		return;
	snprintf(text, sizeof(text),
	         "{\"misses\":%llu,\"drops\":%llu,\"malformed_frames\":%llu,\"lateness_p99_ms\":%.3f,"
	         "\"lateness_max_ms\":%.3f,\"devices\":%d}",
	         (unsigned long long)st->counters.misses, (unsigned long long)st->counters.drops,
	         (unsigned long long)st->counters.malformed_frames,
	         (double)vmac_hist_quantile(&st->lateness, 0.99) / 1000.0, (double)st->lateness.max_us / 1000.0,
	         st->ndevices);
	if (!force && strcmp(text, host_health) == 0)
		return;
	mqtt_topic(m, topic, sizeof(topic), "_health");
	if (mqtt_publish(m, topic, text, -1, 1, 1) == 0) {
		memcpy(host_health, text, sizeof(text));
		next_host_health_s = now + HEALTH_PERIOD_S;
	}
}

static void device_health_out(struct vmac_mqtt *m, struct seen *s, const struct vmac_device_status *st, int force)
{
	char text[sizeof(s->health)], topic[300];
	double now = mqtt_now_s();
	if (!force && now < s->next_health_s)
		return;
	snprintf(
	    text, sizeof(text),
	    "{\"misses\":%llu,\"misses_host\":%llu,\"served\":%llu,\"driver_late\":%llu,\"driver_memory_kb\":%.1f}",
	    (unsigned long long)st->misses, (unsigned long long)st->misses_host, (unsigned long long)st->served,
	    (unsigned long long)st->driver_late, (double)st->driver_memory / 1024.0);
	if (!force && strcmp(text, s->health) == 0)
		return;
	mqtt_topic(m, topic, sizeof(topic), "%s/_health", s->name);
	if (mqtt_publish(m, topic, text, -1, 1, 1) == 0) {
		memcpy(s->health, text, sizeof(text));
		s->next_health_s = now + HEALTH_PERIOD_S;
	}
}

static void connected(struct vmac_mqtt *m)
{
	host_health_out(m, 1);
}

static void device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	struct seen *s = seen_of(d->name);
	if (!s)
		return;
	s->up = 1;
	s->have_state = 0; /* the first state is where it is, not a change */
	device_health_out(m, s, st, 1);
	host_health_out(m, 0);
}

static void device_down(struct vmac_mqtt *m, struct mqtt_device *d)
{
	struct seen *s = seen_of(d->name);
	if (!s || !s->up)
		return;
	s->up = 0;
	if (!atomic_load(&m->stopping))
		publish_event(m, d->name, "dropped");
	host_health_out(m, 0);
}

/* The event a change of the appliance's state says, or NULL. */
static const char *state_event(const char *before, const char *now)
{
	if (strcmp(now, "running") == 0 && strcmp(before, "paused") != 0 && strcmp(before, "running") != 0)
		return "programme_started";
	if (strcmp(now, "done") == 0 && strcmp(before, "done") != 0)
		return "programme_finished";
	if (strcmp(now, "cancelled") == 0 && strcmp(before, "cancelled") != 0)
		return "programme_cancelled";
	if (strcmp(now, "failed") == 0 && strcmp(before, "failed") != 0)
		return "programme_error";
	return NULL;
}

static void values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                   struct mqtt_value *const *changed, int n)
{
	struct seen *s = seen_of(d->name);
	int i, appliance = is_appliance(d->manifest);
	if (!s)
		return;
	for (i = 0; appliance && i < n; i++) {
		const char *event = NULL;
		if (strcmp(changed[i]->name, "state") != 0)
			continue;
		if (s->have_state)
			event = state_event(s->state, changed[i]->text);
		snprintf(s->state, sizeof(s->state), "%s", changed[i]->text);
		s->have_state = 1;
		if (event)
			publish_event(m, d->name, event);
	}
	device_health_out(m, s, st, 0);
	host_health_out(m, 0);
}

static void stopping(struct vmac_mqtt *m)
{
	(void)m;
	free(seen);
	seen = NULL;
	nseen = seen_cap = 0;
	host_health[0] = 0;
}

const struct mqtt_profile mqtt_health_profile = {
    .name = "health",
    .conn = MQTT_CONN_MAIN,
    .connected = connected,
    .device_up = device_up,
    .device_down = device_down,
    .values = values,
    .stopping = stopping,
};
