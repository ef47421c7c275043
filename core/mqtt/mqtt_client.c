/* The MQTT connections and the publisher thread. Each connection has a
 * network thread of ours (net_thread: libmosquitto's loop) that connects,
 * reconnects with exponential backoff (1 s to 30 s) after any failure, TLS
 * ones included, says why once per reason, and keeps the session alive; its
 * callbacks only set flags and queue received messages. The publisher thread reads the bus's
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

#include "../common/monotime.h"
#include "site.h"

static const struct mqtt_profile *const profiles[] = {&mqtt_native_profile,    &mqtt_ha_profile,   &mqtt_health_profile,
                                                      &mqtt_sparkplug_profile, &mqtt_site_profile, &mqtt_audit_profile};
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

int mqtt_conn_publish(struct mqtt_conn *c, const char *topic, const void *payload, int len, int qos, int retain)
{
	int rc;
	if (!c->mosq || !atomic_load(&c->connected))
		return -1;
	if (len < 0)
		len = (int)strlen(payload);
	atomic_fetch_add(&c->outstanding, 1);
	rc = mosquitto_publish(c->mosq, NULL, topic, len, payload, qos, retain != 0);
	if (rc != MOSQ_ERR_SUCCESS) {
		atomic_fetch_sub(&c->outstanding, 1);
		atomic_fetch_add(&mqtt_stats.conn[c->index].publish_failed, 1);
		return -1;
	}
	atomic_fetch_add(&mqtt_stats.conn[c->index].published, 1);
	return 0;
}

int mqtt_conn_subscribe(struct mqtt_conn *c, const char *pattern, int qos)
{
	return c->mosq && mosquitto_subscribe(c->mosq, NULL, pattern, qos) == MOSQ_ERR_SUCCESS ? 0 : -1;
}

int mqtt_conn_is_up(struct mqtt_conn *c)
{
	return c->mosq && atomic_load(&c->connected);
}

int mqtt_conn_can_publish(struct mqtt_conn *c)
{
	return mqtt_conn_is_up(c) && atomic_load(&c->outstanding) < MQTT_MAX_OUTSTANDING;
}

int mqtt_publish(struct vmac_mqtt *m, const char *topic, const char *payload, int len, int qos, int retain)
{
	return mqtt_conn_publish(&m->conns[MQTT_CONN_MAIN], topic, payload, len, qos, retain);
}

int mqtt_subscribe(struct vmac_mqtt *m, const char *pattern, int qos)
{
	return mqtt_conn_subscribe(&m->conns[MQTT_CONN_MAIN], pattern, qos);
}

int mqtt_can_publish_values(struct vmac_mqtt *m)
{
	return mqtt_conn_can_publish(&m->conns[MQTT_CONN_MAIN]);
}

/* ---- libmosquitto's network thread: flags and the queue only ---- */

static const char *conn_what(const struct mqtt_conn *c)
{
	return c->index == MQTT_CONN_SPARKPLUG ? " (Sparkplug)" : "";
}

/* Sparkplug, before every CONNECT (network thread, the one that sends
 * it): the will is the NDEATH with the next bdSeq, one more than the last
 * CONNECT's whether or not that one was accepted (the specification counts
 * CONNECT packets), persisted, so a restart goes on counting. A CONNACK
 * makes it this connection's bdSeq (on_connect). 0, or -1 (out of memory:
 * this attempt is not made). */
static int spb_arm_will(struct mqtt_conn *c)
{
	struct vmac_mqtt *m = c->m;
	char topic[300];
	void *ndeath;
	int len, rc;
	snprintf(topic, sizeof(topic), "spBv1.0/%s/NDEATH/%s", m->s.sparkplug_group, m->s.host_id);
	if (!(ndeath = mqtt_spb_ndeath((unsigned)m->spb.bdseq_next, &len)))
		return -1;
	rc = mosquitto_will_set(c->mosq, topic, len, ndeath, 1, false); /* QoS 1, not retained */
	free(ndeath);
	if (rc != MOSQ_ERR_SUCCESS)
		return -1;
	m->spb.bdseq_connect = m->spb.bdseq_next;
	m->spb.bdseq_next = (m->spb.bdseq_next + 1) % 256;
	mqtt_spb_bdseq_store(m->spb.path, m->spb.bdseq_next);
	return 0;
}

/* A failure to connect or a lost connection, in an event: once per reason
 * (c->reported), so a broker that stays away for a day says so once, and
 * again only when the reason changes or after it was reached. Network thread. */
static void say_failure(struct mqtt_conn *c, int rc)
{
	struct vmac_mqtt *m = c->m;
	char why[sizeof(c->reported)];
	snprintf(why, sizeof(why), "%s%s%s", rc == MOSQ_ERR_ERRNO ? strerror(errno) : mosquitto_strerror(rc),
	         c->last_error[0] ? ": " : "", c->last_error);
	if (atomic_exchange(&c->was_connected, 0))
		mqtt_event(m, "", "lost the broker %s:%d%s (%s); reconnecting with backoff, control goes on", m->s.host,
		           m->s.port, conn_what(c), why);
	else if (strcmp(why, c->reported) != 0)
		mqtt_event(m, "",
		           "cannot connect to the broker %s:%d%s (%s); trying again with backoff, control goes on",
		           m->s.host, m->s.port, conn_what(c), why);
	snprintf(c->reported, sizeof(c->reported), "%s", why);
}

/* c is connected (a CONNACK accepted) or no longer; GET /metrics sees it too. */
static void conn_set_connected(struct mqtt_conn *c, int connected)
{
	atomic_store(&c->connected, connected);
	atomic_store(&mqtt_stats.conn[c->index].connected, connected);
}

static void on_connect(struct mosquitto *mosq, void *obj, int rc)
{
	struct mqtt_conn *c = obj;
	struct vmac_mqtt *m = c->m;
	(void)mosq;
	if (rc != 0) { /* refused (bad credentials, not authorised): said by on_disconnect, which follows */
		snprintf(c->last_error, sizeof(c->last_error), "%s", mosquitto_connack_string(rc));
		return;
	}
	if (c->index == MQTT_CONN_SPARKPLUG)
		atomic_store(&m->spb.bdseq, m->spb.bdseq_connect);
	c->reported[0] = 0; /* the next failure is news again */
	c->last_error[0] = 0;
	atomic_fetch_add(&c->connacks, 1);
	atomic_store(&c->outstanding, 0);
	conn_set_connected(c, 1);
	atomic_fetch_add(&mqtt_stats.conn[c->index].connects, 1);
	if (c->index == MQTT_CONN_MAIN && m->site)
		vmac_site_set_connected(m->site, 1);
	atomic_store(&c->need_births, 1);
	pthread_mutex_lock(&m->lock);
	pthread_cond_signal(&m->wake);
	pthread_mutex_unlock(&m->lock);
}

/* libmosquitto's own error lines (network thread): kept, for the event
 * that says why a connection failed (a TLS handshake's reason is only here). */
static void on_log(struct mosquitto *mosq, void *obj, int level, const char *text)
{
	struct mqtt_conn *c = obj;
	(void)mosq;
	if ((level & MOSQ_LOG_ERR) && text)
		snprintf(c->last_error, sizeof(c->last_error), "%s", text);
}

static void on_disconnect(struct mosquitto *mosq, void *obj, int rc)
{
	struct mqtt_conn *c = obj;
	struct vmac_mqtt *m = c->m;
	(void)mosq;
	conn_set_connected(c, 0);
	if (c->index == MQTT_CONN_MAIN && m->site)
		vmac_site_set_connected(m->site, 0);
	if (rc != 0 && !atomic_load(&m->stopping))
		say_failure(c, rc);
}

static void on_publish(struct mosquitto *mosq, void *obj, int mid)
{
	struct mqtt_conn *c = obj;
	(void)mosq;
	(void)mid;
	if (atomic_load(&c->outstanding) > 0)
		atomic_fetch_sub(&c->outstanding, 1);
}

static void on_message(struct mosquitto *mosq, void *obj, const struct mosquitto_message *msg)
{
	struct mqtt_conn *c = obj;
	struct vmac_mqtt *m = c->m;
	struct mqtt_message *q;
	(void)mosq;
	atomic_fetch_add(&mqtt_stats.conn[c->index].received, 1);
	if (c->index == MQTT_CONN_MAIN && mqtt_site_message(m, msg))
		return; /* the site view's, applied here (mqtt_site.c) */
	if (!msg->topic || strlen(msg->topic) >= sizeof(q->topic))
		return;
	if (c->index == MQTT_CONN_SPARKPLUG && mqtt_spb_ids_foreign(m, msg->topic))
		return; /* another node's birth: nothing to check (mqtt_spb_ids.c) */
	if (msg->retain && !(c->index == MQTT_CONN_SPARKPLUG && strncmp(msg->topic, "spBv1.0/STATE/", 14) == 0) &&
	    !(c->index == MQTT_CONN_MAIN && mqtt_ha_takes_retained(m, msg->topic)))
		return; /* a retained command is an old one: never acted on (a host application's STATE is news, and
		           so is a discovery config left by another mode: mqtt_ha_device.c) */
	pthread_mutex_lock(&m->lock);
	if (m->nqueue == MQTT_QUEUE) {
		m->dropped++;
		atomic_fetch_add(&mqtt_stats.dropped, 1);
	} else {
		q = &m->queue[m->nqueue++];
		snprintf(q->topic, sizeof(q->topic), "%s", msg->topic);
		q->conn = c->index;
		q->retained = msg->retain;
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
		if (profiles[p]->conn == d->conn && profiles[p]->device_up)
			profiles[p]->device_up(m, d, st);
}

void mqtt_profiles_device_down(struct vmac_mqtt *m, struct mqtt_device *d)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->conn == d->conn && profiles[p]->device_down)
			profiles[p]->device_down(m, d);
}

void mqtt_profiles_values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                          struct mqtt_value *const *changed, int n)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->conn == d->conn && profiles[p]->values)
			profiles[p]->values(m, d, st, changed, n);
}

void mqtt_profiles_tick(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->conn == d->conn && profiles[p]->tick)
			profiles[p]->tick(m, d, st);
}

void mqtt_profiles_poll(struct vmac_mqtt *m)
{
	int p;
	for (p = 0; p < NPROFILES; p++)
		if (profiles[p]->poll && mqtt_conn_is_up(&m->conns[profiles[p]->conn]))
			profiles[p]->poll(m);
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
		int p, k;
		for (k = 0; k < MQTT_CONNS; k++) {
			struct mqtt_conn *c = &m->conns[k];
			if (!c->mosq || !atomic_exchange(&c->need_births, 0))
				continue;
			mqtt_event(m, "", "connected to the broker %s:%d as %s%s", m->s.host, m->s.port, c->client_id,
			           conn_what(c));
			atomic_store(&c->was_connected, 1);
			for (p = 0; p < NPROFILES; p++)
				if (profiles[p]->conn == k && profiles[p]->connected)
					profiles[p]->connected(m);
			mqtt_devices_republish(m, c);
		}
		handle_messages(m);
		if (now >= next_poll) {
			mqtt_devices_poll(m);
			mqtt_profiles_poll(m);
			next_poll += MQTT_POLL_MS / 1000.0;
			if (next_poll < now)
				next_poll = now + MQTT_POLL_MS / 1000.0;
		}
		left = next_poll - mqtt_now_s();
		if (left <= 0)
			continue;
		until = vmac_mono_after_ns((int64_t)(left * 1e9));
		pthread_mutex_lock(&m->lock);
		if (m->nqueue == 0 && !atomic_load(&m->conns[MQTT_CONN_MAIN].need_births) &&
		    !atomic_load(&m->conns[MQTT_CONN_SPARKPLUG].need_births) && !atomic_load(&m->stopping))
			pthread_cond_timedwait(&m->wake, &m->lock, &until);
		pthread_mutex_unlock(&m->lock);
	}
	return NULL;
}

static int tls_setup(struct vmac_mqtt *m, struct mosquitto *mosq, char *err, size_t errlen)
{
	int rc;
	if (!m->s.tls)
		return 0;
	if (m->s.cafile[0])
		rc = mosquitto_tls_set(mosq, m->s.cafile, NULL, m->s.certfile[0] ? m->s.certfile : NULL,
		                       m->s.keyfile[0] ? m->s.keyfile : NULL, NULL);
	else
		rc = mosquitto_tls_set(mosq, NULL, "/etc/ssl/certs", m->s.certfile[0] ? m->s.certfile : NULL,
		                       m->s.keyfile[0] ? m->s.keyfile : NULL, NULL);
	if (rc != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "mqtts: the TLS files were refused: %s", mosquitto_strerror(rc));
		return -1;
	}
	return 0;
}

/* The will of the main connection: PREFIX/HOST/status "offline"
 * (retained). Sparkplug's (the NDEATH) is made before each CONNECT, with
 * that CONNECT's bdSeq (spb_arm_will). */
static int set_will(struct mqtt_conn *c, char *err, size_t errlen)
{
	struct vmac_mqtt *m = c->m;
	char topic[512];
	int rc;
	if (c->index != MQTT_CONN_MAIN)
		return 0;
	/* A host that dies (SIGKILL, power) is said offline by the broker. */
	mqtt_topic(m, topic, sizeof(topic), "status");
	rc = mosquitto_will_set(c->mosq, topic, 7, "offline", 1, true);
	if (rc != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "mqtt: cannot set the last will on %s", topic);
		return -1;
	}
	return 0;
}

/* Waits seconds, or less when a stop comes (network thread). */
static void net_pause(struct vmac_mqtt *m, int seconds)
{
	struct timespec until;
	clock_gettime(CLOCK_MONOTONIC, &until);
	until.tv_sec += seconds;
	pthread_mutex_lock(&m->lock);
	while (!atomic_load(&m->stopping) && pthread_cond_timedwait(&m->net_wake, &m->lock, &until) != ETIMEDOUT)
		;
	pthread_mutex_unlock(&m->lock);
}

/* A connection's network thread: connect, run libmosquitto's loop, and after
 * any failure say why (once per reason) and try again with backoff (1 s,
 * doubling to 30 s; from 1 s again after a connection was made). Not
 * mosquitto_loop_start's thread: that one gives up for good on what
 * libmosquitto takes for fatal (a TLS handshake refused, the broker's
 * certificate not trusted), silently, so a broker mended later would never be
 * reached again. */
static void *net_thread(void *arg)
{
	struct mqtt_conn *c = arg;
	struct vmac_mqtt *m = c->m;
	int backoff_s = 1, rc, connacks, first = 1;
	for (;;) {
		atomic_store(&c->in_connect, 1); /* before the check: a stop sees one or the other */
		if (atomic_load(&m->stopping))
			break;
		c->last_error[0] = 0;
		if (c->index == MQTT_CONN_SPARKPLUG && spb_arm_will(c) != 0) {
			atomic_store(&c->in_connect, 0);
			net_pause(m, backoff_s);
			continue;
		}
		rc = first ? mosquitto_connect(c->mosq, m->s.host, m->s.port, (int)m->s.keepalive_s)
		           : mosquitto_reconnect(c->mosq);
		first = 0;
		atomic_store(&c->in_connect, 0);
		if (rc != MOSQ_ERR_SUCCESS && c->index == MQTT_CONN_SPARKPLUG) {
			/* No CONNECT packet went out (the TCP connection or the TLS
			 * handshake failed): its bdSeq is the next one's. */
			m->spb.bdseq_next = m->spb.bdseq_connect;
			mqtt_spb_bdseq_store(m->spb.path, m->spb.bdseq_next);
		}
		connacks = atomic_load(&c->connacks);
		/* Until the connection fails; at a stop, until the DISCONNECT is out
		 * (at most a second). */
		while (rc == MOSQ_ERR_SUCCESS) {
			if (atomic_load(&c->closing) &&
			    (!mosquitto_want_write(c->mosq) || mqtt_now_s() > c->m->close_by))
				break;
			rc = mosquitto_loop(c->mosq, 250, 1);
		}
		if (atomic_load(&c->closing) || atomic_load(&m->stopping))
			break;
		if (atomic_load(&c->connacks) != connacks)
			backoff_s = 1;
		if (atomic_exchange(&c->redial, 0)) { /* asked for, and said by who asked */
			atomic_store(&c->was_connected, 0);
			backoff_s = 1;
		} else {
			say_failure(c, rc);
		}
		net_pause(m, backoff_s);
		backoff_s = backoff_s >= 16 ? 30 : backoff_s * 2;
	}
	atomic_store(&c->in_connect, 0);
	return NULL;
}

/* Connection c made and started (its network thread connecting in the
 * background); 0, or -1 with err. */
static int conn_start(struct vmac_mqtt *m, int index, char *err, size_t errlen)
{
	struct mqtt_conn *c = &m->conns[index];
	const struct vmac_mqtt_settings *s = &m->s;
	int rc;
	c->m = m;
	c->index = index;
	snprintf(c->client_id, sizeof(c->client_id), "%s%s", s->client_id, index == MQTT_CONN_SPARKPLUG ? "-spb" : "");
	c->mosq = mosquitto_new(c->client_id, true, c);
	if (!c->mosq) {
		snprintf(err, errlen, "cannot make the MQTT client: %s", strerror(errno));
		return -1;
	}
	mosquitto_threaded_set(c->mosq, true); /* our network thread, and publishes from the publisher thread */
	mosquitto_int_option(c->mosq, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
	mosquitto_connect_callback_set(c->mosq, on_connect);
	mosquitto_disconnect_callback_set(c->mosq, on_disconnect);
	mosquitto_log_callback_set(c->mosq, on_log);
	mosquitto_publish_callback_set(c->mosq, on_publish);
	mosquitto_message_callback_set(c->mosq, on_message);
	if (s->user[0] &&
	    mosquitto_username_pw_set(c->mosq, s->user, s->has_password ? s->password : NULL) != MOSQ_ERR_SUCCESS) {
		snprintf(err, errlen, "mqtt_user: refused by libmosquitto");
		return -1;
	}
	if (set_will(c, err, errlen) != 0 || tls_setup(m, c->mosq, err, errlen) != 0)
		return -1;
	if ((rc = pthread_create(&c->net, NULL, net_thread, c)) != 0) {
		snprintf(err, errlen, "cannot start the MQTT network thread: %s", strerror(rc));
		return -1;
	}
	pthread_setname_np(c->net, index == MQTT_CONN_SPARKPLUG ? "vmac-mqtt-spb" : "vmac-mqtt-net");
	c->net_started = 1;
	atomic_store(&mqtt_stats.conn[index].used, 1);
	return 0;
}

void mqtt_conn_redial(struct mqtt_conn *c)
{
	if (!c->mosq)
		return;
	atomic_store(&c->redial, 1);
	conn_set_connected(c, 0);
	mosquitto_disconnect(c->mosq); /* queued after what was published; the network thread writes it */
}

static void conn_stop(struct mqtt_conn *c)
{
	struct vmac_mqtt *m = c->m;
	if (!c->mosq)
		return;
	if (c->net_started) {
		m->close_by = mqtt_now_s() + 1.0;
		mosquitto_disconnect(c->mosq); /* queued; the network thread writes it */
		atomic_store(&c->closing, 1);
		pthread_mutex_lock(&m->lock);
		pthread_cond_broadcast(&m->net_wake);
		pthread_mutex_unlock(&m->lock);
		/* A connect to a broker that does not answer can block for minutes
		 * (the kernel's SYN retries): not worth waiting for at a stop. */
		if (atomic_load(&c->in_connect))
			pthread_cancel(c->net);
		pthread_join(c->net, NULL);
		c->net_started = 0;
	}
	mosquitto_destroy(c->mosq);
	c->mosq = NULL;
	conn_set_connected(c, 0);
	atomic_store(&mqtt_stats.conn[c->index].used, 0);
}

/* The connections closed and everything of m freed (a start that failed
 * half-way, or a stop). */
static void mqtt_free(struct vmac_mqtt *m)
{
	int k;
	atomic_store(&mqtt_stats.running, 0);
	for (k = 0; k < MQTT_CONNS; k++)
		conn_stop(&m->conns[k]);
	mosquitto_lib_cleanup();
	mqtt_devices_free(m);
	free(m->status.devices);
	free(m->status.slot_load);
	pthread_mutex_destroy(&m->lock);
	pthread_cond_destroy(&m->wake);
	pthread_cond_destroy(&m->net_wake);
	free(m);
}

struct vmac_mqtt *vmac_mqtt_start(const struct vmac_mqtt_settings *s, const struct vmac_config *cfg,
                                  struct vmac_bus *bus, struct vmac_event_log *log, struct vmac_site *site, char *err,
                                  size_t errlen)
{
	struct vmac_mqtt *m = calloc(1, sizeof(*m));
	int rc, k;
	if (!m) {
		snprintf(err, errlen, "out of memory");
		return NULL;
	}
	m->s = *s;
	m->bus = bus;
	m->log = log;
	m->audit_after = vmac_event_log_next_seq(log) - 1; /* audit events from now on go out (mqtt_audit.c) */
	m->site = site;
	m->status.devices = calloc(cfg->max_devices, sizeof(*m->status.devices));
	m->status.slot_load = calloc((size_t)1 << cfg->max_level, sizeof(*m->status.slot_load));
	pthread_mutex_init(&m->lock, NULL);
	{
		pthread_condattr_t attr;
		pthread_condattr_init(&attr);
		pthread_condattr_setclock(&attr, CLOCK_MONOTONIC);
		pthread_cond_init(&m->wake, &attr);
		pthread_cond_init(&m->net_wake, &attr);
		pthread_condattr_destroy(&attr);
	}
	mosquitto_lib_init();
	if (!m->status.devices || !m->status.slot_load) {
		snprintf(err, errlen, "cannot make the MQTT client: out of memory");
		goto fail;
	}
	if (s->sparkplug) {
		snprintf(m->spb.path, sizeof(m->spb.path), "%s/sparkplug-bdseq", cfg->state_dir);
		m->spb.bdseq_next = mqtt_spb_bdseq_load(m->spb.path);
	}
	for (k = 0; k < MQTT_CONNS; k++)
		if ((k == MQTT_CONN_MAIN || s->sparkplug) && conn_start(m, k, err, errlen) != 0)
			goto fail;
	if ((rc = pthread_create(&m->thread, NULL, publisher, m)) != 0) {
		snprintf(err, errlen, "cannot start the MQTT publisher thread: %s", strerror(rc));
		goto fail;
	}
	pthread_setname_np(m->thread, "vmac-mqtt");
	atomic_store(&mqtt_stats.running, 1);
	return m;
fail:
	atomic_store(&m->stopping, 1);
	mqtt_free(m);
	return NULL;
}

static int waiting(struct vmac_mqtt *m)
{
	int k;
	for (k = 0; k < MQTT_CONNS; k++)
		if (mqtt_conn_is_up(&m->conns[k]) && atomic_load(&m->conns[k].outstanding) > 0)
			return 1;
	return 0;
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
	while (waiting(m) && mqtt_now_s() < deadline) {
		struct timespec ts = {0, 10 * 1000 * 1000};
		nanosleep(&ts, NULL);
	}
	mqtt_free(m);
}
