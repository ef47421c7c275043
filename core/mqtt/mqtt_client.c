/* The MQTT connection and the publisher thread. libmosquitto's own network
 * thread (mosquitto_loop_start) connects, reconnects with exponential
 * backoff (1 s to 30 s) and keeps the session alive; its callbacks only set
 * flags and queue received messages. The publisher thread reads the bus's
 * status copy every MQTT_POLL_MS, publishes what changed, and handles the
 * received messages (commands into the bus's request slots). Neither ever
 * touches the bus thread except through vmac_bus_status and
 * vmac_bus_request_input, which never make it wait. */
#include "mqtt_internal.h"

#include <errno.h>
#include <mosquitto.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const struct mqtt_profile *const profiles[] = {&mqtt_native_profile, &mqtt_ha_profile};
#define NPROFILES (int)(sizeof(profiles) / sizeof(profiles[0]))

double mqtt_now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

void mqtt_event(struct vmac_mqtt *m, const char *device, const char *fmt, ...)
{
	char text[VMAC_EVENT_TEXT];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(text, sizeof(text), fmt, ap);
	va_end(ap);
	vmac_event_log_add(m->log, "mqtt", device, text);
}

int mqtt_publish(struct vmac_mqtt *m, const char *topic, const char *payload, int len, int qos, int retain)
{
	int rc;
	if (!atomic_load(&m->connected))
		return -1;
	if (len < 0)
		len = (int)strlen(payload);
	atomic_fetch_add(&m->outstanding, 1);
	rc = mosquitto_publish(m->mosq, NULL, topic, len, payload, qos, retain != 0);
	if (rc != MOSQ_ERR_SUCCESS) {
		atomic_fetch_sub(&m->outstanding, 1);
		return -1;
	}
	return 0;
}

int mqtt_subscribe(struct vmac_mqtt *m, const char *pattern, int qos)
{
	return mosquitto_subscribe(m->mosq, NULL, pattern, qos) == MOSQ_ERR_SUCCESS ? 0 : -1;
}

int mqtt_can_publish_values(struct vmac_mqtt *m)
{
	return atomic_load(&m->connected) && atomic_load(&m->outstanding) < MQTT_MAX_OUTSTANDING;
}

/* ---- libmosquitto's network thread: flags and the queue only ---- */

static void on_connect(struct mosquitto *mosq, void *obj, int rc)
{
	struct vmac_mqtt *m = obj;
	(void)mosq;
	if (rc != 0) { /* refused: bad credentials, not authorised; libmosquitto tries again */
		mqtt_event(m, "", "the broker %s:%d refused the connection: %s", m->s.host, m->s.port,
		           mosquitto_connack_string(rc));
		return;
	}
	atomic_store(&m->outstanding, 0);
	atomic_store(&m->connected, 1);
	atomic_store(&m->need_births, 1);
	pthread_mutex_lock(&m->lock);
	pthread_cond_signal(&m->wake);
	pthread_mutex_unlock(&m->lock);
}

static void on_disconnect(struct mosquitto *mosq, void *obj, int rc)
{
	struct vmac_mqtt *m = obj;
	(void)mosq;
	atomic_store(&m->connected, 0);
	if (rc != 0 && !atomic_load(&m->stopping) && atomic_exchange(&m->was_connected, 0))
		mqtt_event(m, "", "lost the broker %s:%d (%s); reconnecting with backoff, control goes on", m->s.host,
		           m->s.port, mosquitto_strerror(rc));
}

static void on_publish(struct mosquitto *mosq, void *obj, int mid)
{
	struct vmac_mqtt *m = obj;
	(void)mosq;
	(void)mid;
	if (atomic_load(&m->outstanding) > 0)
		atomic_fetch_sub(&m->outstanding, 1);
}

static void on_message(struct mosquitto *mosq, void *obj, const struct mosquitto_message *msg)
{
	struct vmac_mqtt *m = obj;
	struct mqtt_message *q;
	(void)mosq;
	if (!msg->topic || strlen(msg->topic) >= sizeof(q->topic) || msg->retain)
		return; /* a retained command is an old one: never acted on */
	pthread_mutex_lock(&m->lock);
	if (m->nqueue == MQTT_QUEUE) {
		m->dropped++;
	} else {
		q = &m->queue[m->nqueue++];
		snprintf(q->topic, sizeof(q->topic), "%s", msg->topic);
		q->len = msg->payloadlen > MQTT_PAYLOAD_MAX ? -1 : msg->payloadlen;
		if (msg->payloadlen > 0) /* an empty payload may come as NULL */
			memcpy(q->payload, msg->payload, q->len < 0 ? MQTT_PAYLOAD_MAX : (size_t)q->len);
		q->payload[q->len < 0 ? MQTT_PAYLOAD_MAX : q->len] = 0;
		pthread_cond_signal(&m->wake);
	}
	pthread_mutex_unlock(&m->lock);
}

/* ---- the publisher thread ---- */

static void handle_messages(struct vmac_mqtt *m)
{
	struct mqtt_message batch[MQTT_QUEUE];
	unsigned long dropped;
	int n, i, p;
	pthread_mutex_lock(&m->lock);
	n = m->nqueue;
	memcpy(batch, m->queue, (size_t)n * sizeof(batch[0]));
	m->nqueue = 0;
	dropped = m->dropped;
	m->dropped = 0;
	pthread_mutex_unlock(&m->lock);
	if (dropped)
		mqtt_event(m, "",
		           "%lu messages from the broker came faster than they could be handled and were dropped",
		           dropped);
	for (i = 0; i < n; i++)
		for (p = 0; p < NPROFILES; p++)
			if (profiles[p]->message && profiles[p]->message(m, &batch[i]))
				break;
}

void mqtt_profiles_device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->device_up)
			profiles[p]->device_up(m, d, st);
}

void mqtt_profiles_device_down(struct vmac_mqtt *m, struct mqtt_device *d)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->device_down)
			profiles[p]->device_down(m, d);
}

void mqtt_profiles_values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                          struct mqtt_value *const *changed, int n)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->values)
			profiles[p]->values(m, d, st, changed, n);
}

void mqtt_profiles_stopping(struct vmac_mqtt *m)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->stopping)
			profiles[p]->stopping(m);
}

static void *publisher(void *arg)
{
	struct vmac_mqtt *m = arg;
	double next_poll = mqtt_now_s();
	while (!atomic_load(&m->stopping)) {
		struct timespec until;
		double now = mqtt_now_s(), left;
		int p;
		if (atomic_exchange(&m->need_births, 0)) {
			mqtt_event(m, "", "connected to the broker %s:%d as %s", m->s.host, m->s.port, m->s.client_id);
			atomic_store(&m->was_connected, 1);
			for (p = 0; p < NPROFILES; p++)
				if (profiles[p]->connected)
					profiles[p]->connected(m);
			mqtt_devices_republish(m);
		}
		handle_messages(m);
		if (now >= next_poll) {
			mqtt_devices_poll(m);
			next_poll += MQTT_POLL_MS / 1000.0;
			if (next_poll < now)
				next_poll = now + MQTT_POLL_MS / 1000.0;
		}
		left = next_poll - mqtt_now_s();
		if (left <= 0)
			continue;
		clock_gettime(CLOCK_MONOTONIC, &until);
		until.tv_sec += (time_t)left;
		until.tv_nsec += (long)((left - (double)(time_t)left) * 1e9);
		if (until.tv_nsec >= 1000000000L) {
			until.tv_sec++;
			until.tv_nsec -= 1000000000L;
		}
		pthread_mutex_lock(&m->lock);
		if (m->nqueue == 0 && !atomic_load(&m->need_births) && !atomic_load(&m->stopping))
			pthread_cond_timedwait(&m->wake, &m->lock, &until);
		pthread_mutex_unlock(&m->lock);
	}
	return NULL;
}

static int tls_setup(struct vmac_mqtt *m, char *err, size_t errlen)
{
	int rc;
	if (!m->s.tls)
		return 0;
	if (m->s.cafile[0])
		rc = mosquitto_tls_set(m->mosq, m->s.cafile, NULL, m->s.certfile[0] ? m->s.certfile : NULL,
		                       m->s.keyfile[0] ? m->s.keyfile : NULL, NULL);
	else
		rc = mosquitto_tls_set(m->mosq, NULL, "/etc/ssl/certs", m->s.certfile[0] ? m->s.certfile : NULL,
		                       m->s.keyfile[0] ? m->s.keyfile : NULL, NULL);
	if (rc != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "mqtts: the TLS files were refused: %s", mosquitto_strerror(rc));
		return -1;
	}
	return 0;
}

struct vmac_mqtt *vmac_mqtt_start(const struct vmac_mqtt_settings *s, const struct vmac_config *cfg,
                                  struct vmac_bus *bus, struct vmac_event_log *log, char *err, size_t errlen)
{
	struct vmac_mqtt *m = calloc(1, sizeof(*m));
	char will[512];
	int rc;
	if (!m) {
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	m->s = *s;
	m->bus = bus;
	m->log = log;
	m->status.devices = calloc(cfg->max_devices, sizeof(*m->status.devices));
	m->status.slot_load = calloc((size_t)1 << cfg->max_level, sizeof(*m->status.slot_load));
	pthread_mutex_init(&m->lock, NULL);
	{
		pthread_condattr_t attr;
		pthread_condattr_init(&attr);
		pthread_condattr_setclock(&attr, CLOCK_MONOTONIC);
		pthread_cond_init(&m->wake, &attr);
		pthread_condattr_destroy(&attr);
	}
	mosquitto_lib_init();
	m->mosq = mosquitto_new(s->client_id, true, m);
	if (!m->status.devices || !m->status.slot_load || !m->mosq) {
		snprintf(err, errlen, "cannot make the MQTT client: %s", m->mosq ? "out of memory" : strerror(errno));
		goto fail;
	}
	mosquitto_int_option(m->mosq, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
	mosquitto_reconnect_delay_set(m->mosq, 1, 30, true);
	mosquitto_connect_callback_set(m->mosq, on_connect);
	mosquitto_disconnect_callback_set(m->mosq, on_disconnect);
	mosquitto_publish_callback_set(m->mosq, on_publish);
	mosquitto_message_callback_set(m->mosq, on_message);
	if (s->user[0] &&
	    mosquitto_username_pw_set(m->mosq, s->user, s->has_password ? s->password : NULL) != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "mqtt_user: refused by libmosquitto");
		goto fail;
	}
	/* A host that dies (SIGKILL, power) is said offline by the broker. */
	mqtt_topic(m, will, sizeof(will), "status");
	if (mosquitto_will_set(m->mosq, will, 7, "offline", 1, true) != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "mqtt: cannot set the last will on %s", will);
		goto fail;
	}
	if (tls_setup(m, err, errlen) != 0)
		goto fail;
	rc = mosquitto_connect_async(m->mosq, s->host, s->port, (int)s->keepalive_s);
	if (rc != MOSQ_ERR_SUCCESS) /* the broker down is no error: the network thread keeps trying */
		mqtt_event(m, "", "the broker %s:%d is not reachable yet (%s); trying again with backoff", s->host,
		           s->port, rc == MOSQ_ERR_ERRNO ? strerror(errno) : mosquitto_strerror(rc));
	if ((rc = mosquitto_loop_start(m->mosq)) != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "cannot start the MQTT network thread: %s", mosquitto_strerror(rc));
		goto fail;
	}
	if ((rc = pthread_create(&m->thread, NULL, publisher, m)) != 0) {
		snprintf(err, errlen, "cannot start the MQTT publisher thread: %s", strerror(rc));
		atomic_store(&m->stopping, 1);
		mosquitto_disconnect(m->mosq);
		mosquitto_loop_stop(m->mosq, true);
		goto fail;
	}
	pthread_setname_np(m->thread, "vmac-mqtt");
	return m;
fail:
	if (m->mosq)
		mosquitto_destroy(m->mosq);
	mosquitto_lib_cleanup();
	free(m->status.devices);
	free(m->status.slot_load);
	free(m);
	return NULL;
}

void vmac_mqtt_stop(struct vmac_mqtt *m)
{
	double deadline;
	if (!m)
		return;
	atomic_store(&m->stopping, 1);
	pthread_mutex_lock(&m->lock);
	pthread_cond_signal(&m->wake);
	pthread_mutex_unlock(&m->lock);
	pthread_join(m->thread, NULL);
	/* Last words, then wait (at most a second) for them to be written. */
	mqtt_devices_stopping(m);
	deadline = mqtt_now_s() + 1.0;
	while (atomic_load(&m->connected) && atomic_load(&m->outstanding) > 0 && mqtt_now_s() < deadline) {
		struct timespec ts = {0, 10 * 1000 * 1000};
		nanosleep(&ts, NULL);
	}
	mosquitto_disconnect(m->mosq);
	mosquitto_loop_stop(m->mosq, false);
	mosquitto_destroy(m->mosq);
	mosquitto_lib_cleanup();
	mqtt_devices_free(m);
	free(m->status.devices);
	free(m->status.slot_load);
	pthread_mutex_destroy(&m->lock);
	pthread_cond_destroy(&m->wake);
	free(m);
}
