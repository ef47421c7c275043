/* Profile "health": what Home Assistant's diagnostic sensors and event
 * entities read (docs/MQTT.md, "Home Assistant"; mqtt_ha.c configures
 * them). It publishes, on the main connection:
 *
 *   PREFIX/HOST/DEVICE/_health  retained JSON {"misses", "misses_host",
 *       "served", "driver_late", "driver_memory_kb", "clock_state",
 *       "clock_bound_us", "clock_on_arrival"}: the machine's primary
 *       board, from the bus's status copy (its clock's three null until it
 *       sends a TIMED reply, docs/TIME.md)
 *   PREFIX/HOST/_health         retained JSON {"misses", "drops",
 *       "malformed_frames", "lateness_p99_ms", "lateness_max_ms",
 *       "devices"}: the bus
 *   PREFIX/HOST/DEVICE/_event   not retained, {"event_type": T} as HA's
 *       event platform reads it (event.py), T one of
 *       mqtt_health_event_types
 *
 * Health is looked at on every status copy (the tick and poll hooks). It
 * goes out when it changed, at most every HEALTH_PERIOD_S per topic, at
 * once when a machine comes up, and every HEALTH_HEARTBEAT_S when it did
 * not change: a heartbeat, so that Home Assistant's expire_after
 * (HEALTH_EXPIRE_S, mqtt_ha.c) shows a host whose publisher stopped while
 * its connection lives on as unknown.
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
#include <string.h>

#include "../common/hist.h"

#define HEALTH_PERIOD_S 10.0
#define HEALTH_HEARTBEAT_S ((double)MQTT_HEALTH_HEARTBEAT_S)

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

/* The bus's health, if it changed (or its heartbeat is due) and its
 * period is over (force: now). */
static void host_health_out(struct vmac_mqtt *m, int force)
{
	const struct vmac_status *st = &m->status;
	char text[sizeof(m->host_health)], topic[300];
	double now = mqtt_now_s();
	if (!force && now < m->host_health_next_s)
		return;
	snprintf(text, sizeof(text),
	         "{\"misses\":%llu,\"drops\":%llu,\"malformed_frames\":%llu,\"lateness_p99_ms\":%.3f,"
	         "\"lateness_max_ms\":%.3f,\"devices\":%d}",
	         (unsigned long long)st->counters.misses, (unsigned long long)st->counters.drops,
	         (unsigned long long)st->counters.malformed_frames,
	         (double)vmac_hist_quantile(&st->lateness, 0.99) / 1000.0, (double)st->lateness.max_us / 1000.0,
	         st->ndevices);
	if (!force && strcmp(text, m->host_health) == 0 && now < m->host_health_sent_s + HEALTH_HEARTBEAT_S)
		return;
	mqtt_topic(m, topic, sizeof(topic), "_health");
	if (mqtt_publish(m, topic, text, -1, 1, 1) == 0) {
		memcpy(m->host_health, text, sizeof(text));
		m->host_health_sent_s = now;
		m->host_health_next_s = now + HEALTH_PERIOD_S;
	}
}

const char *const mqtt_clock_states[] = {"unsynced", "locking", "locked", "holdover", "lost", NULL};
#define CLOCK_STATES 5

/* The primary board's clock as the health's JSON fields (null while it
 * has sent no TIMED reply; the bound null while the board does not know
 * it): ,"clock_state":..,"clock_bound_us":..,"clock_on_arrival":.. */
void mqtt_health_clock_fields(const struct vmac_board_clock_status *c, char *out, size_t outlen)
{
	char bound[32] = "null";
	if (!c->known || c->state >= CLOCK_STATES) {
		snprintf(out, outlen, ",\"clock_state\":null,\"clock_bound_us\":null,\"clock_on_arrival\":null");
		return;
	}
	if (c->bound_ns != 0xFFFFFFFFu)
		snprintf(bound, sizeof(bound), "%.1f", (double)c->bound_ns / 1000.0);
	snprintf(out, outlen, ",\"clock_state\":\"%s\",\"clock_bound_us\":%s,\"clock_on_arrival\":%s",
	         mqtt_clock_states[c->state], bound, c->on_arrival ? "true" : "false");
}

static void device_health_out(struct vmac_mqtt *m, struct mqtt_device *s, const struct vmac_device_status *st,
                              int force)
{
	char text[sizeof(s->health)], topic[300], clock[120];
	double now = mqtt_now_s();
	if (!force && now < s->health_next_s)
		return;
	mqtt_health_clock_fields(&st->clock, clock, sizeof(clock));
	snprintf(
	    text, sizeof(text),
	    "{\"misses\":%llu,\"misses_host\":%llu,\"served\":%llu,\"driver_late\":%llu,\"driver_memory_kb\":%.1f%s}",
	    (unsigned long long)st->misses, (unsigned long long)st->misses_host, (unsigned long long)st->served,
	    (unsigned long long)st->driver_late, (double)st->driver_memory / 1024.0, clock);
	if (!force && strcmp(text, s->health) == 0 && now < s->health_sent_s + HEALTH_HEARTBEAT_S)
		return;
	mqtt_topic(m, topic, sizeof(topic), "%s/_health", s->name);
	if (mqtt_publish(m, topic, text, -1, 1, 1) == 0) {
		memcpy(s->health, text, sizeof(text));
		s->health_sent_s = now;
		s->health_next_s = now + HEALTH_PERIOD_S;
	}
}

static void connected(struct vmac_mqtt *m)
{
	host_health_out(m, 1);
}

static void device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	d->have_state = 0; /* the first state is where it is, not a change */
	d->told_up = 1;
	device_health_out(m, d, st, 1);
}

/* A machine that stops running: "dropped", once (after a reconnect the
 * machines that are not up are said down again). */
static void device_down(struct vmac_mqtt *m, struct mqtt_device *d)
{
	if (d->told_up && !atomic_load(&m->stopping))
		publish_event(m, d->name, "dropped");
	d->told_up = 0;
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
	int i, appliance = is_appliance(d->manifest);
	(void)st;
	for (i = 0; appliance && i < n; i++) {
		const char *event = NULL;
		if (strcmp(changed[i]->name, "state") != 0)
			continue;
		if (d->have_state)
			event = state_event(d->state, changed[i]->text);
		snprintf(d->state, sizeof(d->state), "%s", changed[i]->text);
		d->have_state = 1;
		if (event)
			publish_event(m, d->name, event);
	}
}

static void tick(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	device_health_out(m, d, st, 0);
}

static void poll(struct vmac_mqtt *m)
{
	host_health_out(m, 0);
}

const struct mqtt_profile mqtt_health_profile = {
    .name = "health",
    .conn = MQTT_CONN_MAIN,
    .connected = connected,
    .device_up = device_up,
    .device_down = device_down,
    .values = values,
    .tick = tick,
    .poll = poll,
};
