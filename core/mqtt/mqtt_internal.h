/* What the files of core/mqtt/ share. Who owns what:
 *   mqtt_settings.c  the mqtt_* settings, checked at start
 *   mqtt_client.c    the connections (libmosquitto, a network thread each, reconnect with backoff, the last
 *                    will), the publisher thread and its loop, publishing with a bound on what waits
 *   mqtt_devices.c   the bus's status copy read every 250 ms: which machines are up or down, which values
 *                    changed (newest wins), handed to every profile
 *   mqtt_native.c    profile "vmac": the host's and devices' availability, state topics, the command
 *                    topics into the bus's request slots, errors published back
 *   mqtt_ha.c        profile "ha": Home Assistant discovery configs from each driver's manifest
 *   mqtt_ha_device.c those configs as one per HA device (mqtt_discovery_mode = device), and the move
 *                    from one mode to the other
 *   mqtt_health.c    profile "health": each machine's and the host's health (_health) and events (_event)
 *   mqtt_sparkplug.c profile "sparkplug": Sparkplug B 3.0 (vmacd an Edge Node, each machine a Device), on a
 *                    connection of its own (its will is the NDEATH), payloads in sparkplug_b.proto
 *   mqtt_spb_dcmd.c  its DCMDs into the bus's request slots (mqtt_spb.h is what these share)
 *   mqtt_spb_ids.c   its ids checked against the group's: another node with this descriptor, ids that
 *                    differ only in case
 *   mqtt_site.c      profile "site": every host's native topics into the site view (site.h) that GET
 *                    /api/site serves, on the network thread
 *   mqtt_audit.c     commands audited (core/host/audit.h), and profile "audit": the host's audit events
 *                    published for Home Assistant's event entity
 *   mqtt_stats.c     the client's connections and messages counted for GET /metrics (process-wide)
 * A profile is one way of speaking MQTT over a connection and the same device table (docs/MQTT.md,
 * "Adding a profile"). Everything here runs on the publisher thread unless it says otherwise. */
#ifndef VMAC_MQTT_INTERNAL_H
#define VMAC_MQTT_INTERNAL_H

#include <jansson.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>

#include "mqtt.h"

#define MQTT_POLL_MS 250           /* the status copy is read this often */
#define MQTT_INPUT_TIMEOUT_MS 2000 /* as the HTTP API waits for the bus thread */
#define MQTT_MAX_OUTSTANDING 5000  /* messages handed to libmosquitto and not yet written: values wait */
#define MQTT_QUEUE 64              /* messages received and not yet handled; more are dropped, counted */
#define MQTT_PAYLOAD_MAX 1024      /* a received payload; longer is kept as len -1 and refused */
#define MQTT_TEXT_PAYLOAD_MAX 256  /* a command's text payload (mqtt_native.c); longer is refused */
#define MQTT_VALUES (VMAC_DRIVER_MAX_VARS + VMAC_DRIVER_MAX_PARAMS)
#define MQTT_TEXT_MAX 96           /* a value as text */
#define MQTT_HEALTH_HEARTBEAT_S 60 /* _health goes out at least this often (mqtt_health.c) */
#define MQTT_HEALTH_EXPIRE_S 150   /* HA's expire_after of the health sensors (mqtt_ha.c) */
#define MQTT_PAYLOAD_NONE "None"   /* no value (nil, NaN, inf): Home Assistant's PAYLOAD_NONE */
#define MQTT_SPB_SENT_BIRTHS 4     /* NBIRTHs remembered to know this node's own when they come back */

/* A value as published: its text at its precision. */
struct mqtt_value {
	char name[VMAC_DRIVER_NAME_MAX + 1];
	char text[MQTT_TEXT_MAX];
	int sent;      /* text went out on this connection */
	int precision; /* a number's decimals as published (the declaration's precision), -1: all */
	char kind;     /* vmac_hints_kind of its declaration: a value of another kind goes out as None */
};

/* sparkplug: a metric of a DBIRTH and its Sparkplug datatype. */
struct mqtt_spb_metric {
	char name[VMAC_DRIVER_NAME_MAX + 1];
	unsigned datatype;
};

/* ha: retained discovery configs of the other mode (mqtt_ha_device.c)
 * found for one HA device, to be cleared once its configs are out again. */
struct mqtt_ha_left {
	char **topics;
	int n;
};

/* A machine as one connection's profiles know it (by its primary board's
 * name): each connection has a table of its own, so what one connection
 * said (up, down, which values) is independent of the other's outages. */
struct mqtt_device {
	char name[VMAC_NAME_MAX + 1];
	int conn; /* the connection whose table holds it (MQTT_CONN_*) */
	char driver[VMAC_NAME_MAX + 1];
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	int online;       /* running, and said so on its connection */
	int seen;         /* in the status this round */
	json_t *manifest; /* the running version's declarations (vmac_loaded_manifest), NULL until known */
	char **configs;   /* ha: the discovery config topics published for this version */
	int nconfigs;
	/* ha: the kind of each variable, then each param, in those configs ('n', 'b', 's'; '?' where neither
	 * the declaration nor a value said it yet, configured as a string until a value says otherwise). */
	char kinds[MQTT_VALUES + 1];
	int ha_watched;              /* ha: its configs of the other mode looked for on this connection */
	struct mqtt_ha_left ha_left; /* ha: ... and those found, to clear */
	/* sparkplug: DBIRTH sent in this Sparkplug session, and the datatype of each variable and param in it
	 * (a value of another type brings a new DBIRTH). */
	int spb_born;
	struct mqtt_spb_metric *spb_metrics;
	int nspb_metrics;
	/* health: the appliance's state before this one (its events), the
	 * _health text published last, when, and when it may go out again. */
	int told_up; /* device_up said, device_down not since: a drop is an event once */
	int have_state;
	char state[MQTT_TEXT_MAX];
	char health[300];
	double health_sent_s, health_next_s;
	struct mqtt_value values[MQTT_VALUES];
	int nvalues;
};

struct mqtt_message {
	char topic[256];
	char payload[MQTT_PAYLOAD_MAX + 1]; /* NUL after len bytes; binary payloads (Sparkplug) use len */
	int len;                            /* -1: longer than MQTT_PAYLOAD_MAX (payload holds its start) */
	int conn;                           /* the connection it came on (MQTT_CONN_*) */
	int retained;                       /* the broker's retained message (only discovery configs and STATE) */
};

/* The connections: the main one (profiles vmac and ha; its will PREFIX/HOST/status offline), and
 * Sparkplug's own (client id + "-spb"; its will the NDEATH), made only with mqtt_sparkplug = true. MQTT
 * gives a connection one will, and each of them needs its own. */
enum { MQTT_CONN_MAIN, MQTT_CONN_SPARKPLUG, MQTT_CONNS };

struct mqtt_conn {
	struct vmac_mqtt *m;
	int index;              /* MQTT_CONN_* */
	struct mosquitto *mosq; /* NULL: this connection is not used */
	char client_id[160];
	atomic_int connected;     /* CONNACK accepted, not yet disconnected (network thread sets it) */
	atomic_int need_births;   /* a new connection: its profiles say everything again */
	atomic_int outstanding;   /* published, not yet written (QoS 0) or acknowledged (QoS 1) */
	atomic_int was_connected; /* said once per outage */
	atomic_int connacks;      /* CONNACKs accepted so far */
	/* The network thread (mqtt_client.c, net_thread). */
	pthread_t net;
	int net_started;
	atomic_int in_connect; /* in mosquitto_connect: a stop cancels it rather than wait minutes */
	atomic_int closing;    /* conn_stop: write what is queued (the DISCONNECT), then end */
	atomic_int redial;     /* a disconnect asked for (Sparkplug's primary host offline): connect again */
	/* The publisher thread's: the machines as this connection's profiles
	 * were told of them (mqtt_devices.c). */
	struct mqtt_device *devices;
	int ndevices, cap;
	int find_next; /* where mqtt_conn_device_find looks first: after its last find */
	/* Network thread only: libmosquitto's last error line (its log callback:
	 * the OpenSSL reason of a refused handshake, or the broker's CONNACK) and
	 * the failure last reported, so that a broker that stays unreachable is
	 * said once per reason, not once per retry. */
	char last_error[160];
	char reported[200];
};

struct vmac_mqtt;

/* Every hook is optional. Publisher thread. */
struct mqtt_profile {
	const char *name;
	int conn; /* the connection it speaks on (MQTT_CONN_*) */
	/* After every CONNACK on its connection: subscriptions, and what the broker
	 * needs (the host's birth); on the main connection devices follow with
	 * device_up/down. */
	void (*connected)(struct vmac_mqtt *m);
	/* A machine running: new, back after a drop, a new driver version, or
	 * everything again after a reconnect. st: its status now. */
	void (*device_up)(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st);
	/* A machine no longer running (dropped, asleep, gone). */
	void (*device_down)(struct vmac_mqtt *m, struct mqtt_device *d);
	/* Values of one machine that changed (or all, after device_up), from one
	 * status copy (st): a group's variables come together. */
	void (*values)(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
	               struct mqtt_value *const *changed, int n);
	/* After every read of the status copy, for every machine up on its
	 * connection (st its status now): what is due by time, not by change. */
	void (*tick)(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st);
	/* After every read of the status copy while its connection is up. */
	void (*poll)(struct vmac_mqtt *m);
	/* A message on a subscribed topic: 1 handled, 0 not this profile's. */
	int (*message)(struct vmac_mqtt *m, const struct mqtt_message *msg);
	/* The host stopping in order: last words (the will covers a crash). */
	void (*stopping)(struct vmac_mqtt *m);
};

extern const struct mqtt_profile mqtt_native_profile, mqtt_ha_profile, mqtt_sparkplug_profile, mqtt_site_profile,
    mqtt_health_profile, mqtt_audit_profile;

/* Sparkplug's session (mqtt_sparkplug.c). Before every CONNECT the
 * network thread registers the NDEATH with bdseq_next as the will, makes it
 * bdseq_connect and counts bdseq_next on (persisted); a CONNACK makes
 * bdseq_connect this connection's bdseq. */
struct mqtt_spb {
	char path[VMAC_PATH_MAX + 32]; /* STATE_DIR/sparkplug-bdseq: the next CONNECT's bdSeq */
	atomic_int bdseq;              /* this connection's bdSeq (its NBIRTH's and its will's) */
	int bdseq_next;                /* network thread: the next CONNECT's */
	int bdseq_connect;             /* network thread: the CONNECT in flight's */
	unsigned seq;                  /* the next message's seq, 0..255 */
	int born;                      /* bdseq + 1 of the connection the NBIRTH went out on; 0: none yet */
	/* mqtt_sparkplug_primary_host: its last STATE on this connection (the
	 * retained one comes right after the SUBSCRIBE) and that STATE's
	 * timestamp; an older one than what was seen is ignored. */
	int host_online;
	int64_t host_ts;
	/* The last NBIRTHs sent (mqtt_spb_ids.c): their payload timestamps and
	 * bdSeqs, to tell this node's own from another's with its descriptor. */
	uint64_t sent_ts[MQTT_SPB_SENT_BIRTHS];
	int sent_bdseq[MQTT_SPB_SENT_BIRTHS];
	unsigned nsent;
};

struct vmac_mqtt {
	struct vmac_mqtt_settings s;
	struct vmac_bus *bus;
	struct vmac_event_log *log;
	struct mqtt_conn conns[MQTT_CONNS];
	pthread_t thread;
	atomic_int stopping;
	pthread_mutex_t lock; /* queue, nqueue, dropped; wake; net_wake */
	pthread_cond_t wake;
	pthread_cond_t net_wake; /* the network threads' backoff, cut short by a stop */
	double close_by;         /* a stop: the network threads write what is queued until then */
	struct mqtt_message queue[MQTT_QUEUE];
	int nqueue;
	unsigned long dropped;
	/* The publisher thread's own. */
	struct vmac_status status;
	unsigned long skipped_rounds; /* values held back: too much waiting to be written */
	char host_health[300];        /* health (mqtt_health.c): the host's _health published last, when */
	double host_health_sent_s, host_health_next_s;
	struct mqtt_spb spb;
	struct vmac_site *site; /* the site view (vmacd's; NULL: none), fed on the network thread */
	uint64_t audit_after;   /* audit (mqtt_audit.c): the events of the log up to this seq were looked at */
	struct mqtt_ha_left ha_host_left; /* ha: the host's own configs of the other mode, to clear */
};

/* The process's client counted (mqtt_stats.c: vmac_mqtt_stats reads it);
 * written by mqtt_client.c on whichever thread sees the thing counted. */
struct mqtt_stats {
	atomic_int running;
	_Atomic uint64_t dropped;
	struct {
		atomic_int used, connected;
		_Atomic uint64_t connects, published, publish_failed, received;
	} conn[MQTT_CONNS];
};
extern struct mqtt_stats mqtt_stats;

/* Publish (retained or not) at QoS 0 or 1 on the main connection; len -1:
 * strlen(payload). 0, or -1 when not connected (nothing queued). Any thread. */
int mqtt_publish(struct vmac_mqtt *m, const char *topic, const char *payload, int len, int qos, int retain);
int mqtt_subscribe(struct vmac_mqtt *m, const char *pattern, int qos);
/* The same on connection c (MQTT_CONN_*). */
int mqtt_conn_publish(struct mqtt_conn *c, const char *topic, const void *payload, int len, int qos, int retain);
int mqtt_conn_subscribe(struct mqtt_conn *c, const char *pattern, int qos);
int mqtt_conn_is_up(struct mqtt_conn *c);
/* Whether values may be published now on the main connection (connected,
 * not too much waiting); mqtt_conn_can_publish: on c. */
int mqtt_can_publish_values(struct vmac_mqtt *m);
int mqtt_conn_can_publish(struct mqtt_conn *c);
void mqtt_event(struct vmac_mqtt *m, const char *device, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
double mqtt_now_s(void);

/* mqtt_client.c: the hook of every profile on d's connection, in order. */
void mqtt_profiles_device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st);
void mqtt_profiles_device_down(struct vmac_mqtt *m, struct mqtt_device *d);
void mqtt_profiles_values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                          struct mqtt_value *const *changed, int n);
void mqtt_profiles_stopping(struct vmac_mqtt *m);
void mqtt_profiles_tick(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st);
void mqtt_profiles_poll(struct vmac_mqtt *m);

/* mqtt_devices.c */
void mqtt_devices_poll(struct vmac_mqtt *m); /* read the status copy, tell every connection's profiles */
/* After a CONNACK on c: every device again to c's profiles. */
void mqtt_devices_republish(struct vmac_mqtt *m, struct mqtt_conn *c);
void mqtt_devices_stopping(struct vmac_mqtt *m); /* every device down, then the profiles' last words */
void mqtt_devices_free(struct vmac_mqtt *m);
/* The value of a variable or param named name in a machine's status (NULL: none). */
const struct vmac_value *mqtt_status_value(const struct vmac_device_status *st, const char *name);
/* A machine in connection c's table (mqtt_device_find: the main one's). */
struct mqtt_device *mqtt_conn_device_find(struct mqtt_conn *c, const char *name);
struct mqtt_device *mqtt_device_find(struct vmac_mqtt *m, const char *name);

/* mqtt_spb_ids.c: Sparkplug ids that clash. An NBIRTH of another Edge
 * Node of the group whose id is not this node's in any case is dropped on
 * the network thread before it takes a place in the queue that commands
 * use: 1 for such a topic. Any thread. */
int mqtt_spb_ids_foreign(const struct vmac_mqtt *m, const char *topic);
/* An NBIRTH this node published (its payload timestamp and bdSeq), so that
 * its own, back from the broker, does not read as a twin's. */
void mqtt_spb_ids_nbirth_sent(struct vmac_mqtt *m, uint64_t timestamp, int bdseq);
/* The edge id of a topic spBv1.0/GROUP/NBIRTH/EDGE of this node's group,
 * else NULL. */
const char *mqtt_spb_ids_nbirth_edge(const struct vmac_mqtt *m, const char *topic);
/* An NBIRTH of the group seen (timestamp and bdSeq from its payload; 0 and
 * -1 when it had none or was not one): another node with this node's
 * descriptor, or this node's edge id in another case, said in the events. */
void mqtt_spb_ids_nbirth(struct vmac_mqtt *m, const char *edge, uint64_t timestamp, int64_t bdseq);
/* d up on Sparkplug's connection: a machine up whose name differs from d's
 * only in case is said. */
void mqtt_spb_ids_device_up(struct vmac_mqtt *m, const struct mqtt_device *d);

/* mqtt_site.c: a message on the main connection, on libmosquitto's network
 * thread: 1 when it was one of the site view's topics (applied or counted
 * as malformed), 0 when it is for the queue. */
struct mosquitto_message;
int mqtt_site_message(struct vmac_mqtt *m, const struct mosquitto_message *msg);

/* mqtt_native.c: values as text and back (pure; docs/MQTT.md "Payloads"). */
void mqtt_value_text(const struct vmac_value *v, char *out, size_t outlen);
/* The same with a number rounded to precision decimals (0..6; -1: as it is),
 * -0 written 0: a value is published when this text changes. */
void mqtt_value_text_at(const struct vmac_value *v, int precision, char *out, size_t outlen);
/* The precision throttle with its hysteresis: whether a value whose text
 * at its precision is text goes out, sent being the text published last.
 * A number with a precision (0..6) goes out when it is a whole step
 * (10^-precision) or more from the number sent, not when it merely rounds
 * to a neighbour: noise at a rounding boundary does not flip it back and
 * forth, and the number shown is always less than a step from the value
 * now. Anything else (no precision, None, another kind) when its text
 * changes. */
int mqtt_value_moved(const struct vmac_value *v, int precision, const char *text, const char *sent);
/* The precision a declaration gives its numbers: "precision" 0..6, not for
 * a choice of values (its state is the option's text); else -1. */
int mqtt_declared_precision(json_t *decl);
/* A command's payload (len bytes, -1: too long) into v: 0, or -1 with why. */
int mqtt_payload_value(const char *payload, int len, struct vmac_value *v, const char **why);
/* The same, typed by decl (a variable's or param's declaration from the
 * manifest; NULL: as mqtt_payload_value): a string (values of strings, a
 * string default) as it came, a number, a boolean (true/false/ON/OFF), or
 * for numeric values a number when it reads as one; a payload that is not
 * what the declaration says is refused with why. */
int mqtt_payload_typed(const char *payload, int len, json_t *decl, struct vmac_value *v, const char **why);
/* {"topic", "name", "code", "error"} on PREFIX/HOST/DEVICE/_error (device
 * NULL: PREFIX/HOST/error); docs/MQTT.md "Payloads". */
void mqtt_publish_error(struct vmac_mqtt *m, const char *device, const char *topic, const char *name, const char *code,
                        const char *text);
/* Topic helpers: PREFIX/HOST/rest into out. */
void mqtt_topic(const struct vmac_mqtt *m, char *out, size_t outlen, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

/* mqtt_ha.c: the discovery configs of one machine (pure): a JSON object
 * {config topic: config payload object} from its manifest and status. */
json_t *mqtt_ha_configs(const struct vmac_mqtt_settings *s, const char *device, const char *driver, const char *version,
                        json_t *manifest, const struct vmac_device_status *st);

/* mqtt_ha_device.c: Home Assistant's two discovery modes. Publish the
 * configs of one HA device ({config topic: config}, as mqtt_ha_configs
 * makes them, o is taken): per entity (an empty retained payload first on
 * each topic of before[] that configs lack), or with mqtt_discovery_mode =
 * device as one config on DISCOVERY/device/NODE/config, the entities of
 * before[] it lacks sent once with their platform alone (HA's removal of a
 * component) before it. */
void mqtt_ha_publish(struct vmac_mqtt *m, json_t *o, char *const *before, int nbefore);
/* Look, on the main connection, for the retained configs of HA device node
 * in the other mode (left by a vmacd that ran in it). */
void mqtt_ha_watch(struct vmac_mqtt *m, const char *node);
/* Whether a retained message on topic may be handed to the profiles: a
 * discovery config (a leftover of the other mode). Network thread. */
int mqtt_ha_takes_retained(const struct vmac_mqtt *m, const char *topic);
/* A message on a discovery config topic: a retained leftover of the other
 * mode for node (the host's, or one of the machines') is told to HA to
 * migrate (its documented {"migrate_discovery": true}) and kept in *left.
 * 1 when msg was a config topic of node, else 0. */
int mqtt_ha_leftover(struct vmac_mqtt *m, const struct mqtt_message *msg, const char *node, struct mqtt_ha_left *left);
/* After the configs of left's HA device went out again: its leftovers
 * cleared (an empty retained payload each), left emptied. */
void mqtt_ha_left_clear(struct vmac_mqtt *m, struct mqtt_ha_left *left, const char *device);
void mqtt_ha_left_free(struct mqtt_ha_left *left);

/* Disconnect c (after what is queued) and connect again, with the
 * reconnect's backoff from 1 s; said by the caller. Publisher thread. */
void mqtt_conn_redial(struct mqtt_conn *c);

/* mqtt_health.c: the event types a machine of this manifest publishes on
 * PREFIX/HOST/DEVICE/_event (a new JSON array of strings). */
json_t *mqtt_health_event_types(json_t *manifest);
/* A board's clock states by vmac_board_clock_status.state (docs/TIME.md),
 * NULL after the last: the _health's clock_state, HA's Clock options. */
extern const char *const mqtt_clock_states[];
/* A board's clock as the fields that end a machine's _health JSON:
 * ,"clock_state":S,"clock_bound_us":B,"clock_on_arrival":A (each null
 * until it sends a TIMED reply; B null while it does not know its bound). */
void mqtt_health_clock_fields(const struct vmac_board_clock_status *c, char *out, size_t outlen);

/* mqtt_audit.c: a command that came on connection conn (MQTT_CONN_*)
 * in the audit trail: its topic, its device (NULL: none), the input it
 * made (NULL: it did not parse), and code: "ok" or what was published on
 * _error (refused, malformed, ...) with why. */
void mqtt_audit_command(struct vmac_mqtt *m, int conn, const char *topic, const char *device,
                        const struct vmac_bus_input_request *req, const char *code, const char *why);
/* The event_types of the host's audit event entity (a new JSON array). */
json_t *mqtt_audit_event_types(void);

/* mqtt_sparkplug.c: the NDEATH payload with bdSeq (malloc'd, *len its size;
 * NULL when out of memory), for the will of a connection. Any thread. */
void *mqtt_spb_ndeath(unsigned bdseq, int *len);
/* STATE_DIR/sparkplug-bdseq: the bdSeq of the next connection (0 when
 * missing or unreadable), and storing it (best effort). Any thread. */
int mqtt_spb_bdseq_load(const char *path);
void mqtt_spb_bdseq_store(const char *path, int bdseq);

#endif
