/* The MQTT client of vmacd (docs/MQTT.md): the settings it is started with,
 * and start/stop. It runs on threads of its own (a network thread per
 * connection and a publisher thread), reads the bus's published status copy
 * (vmac_bus_status) and hands operator input in through the bus's request
 * slots (vmac_bus_request_input), exactly as the HTTP API does: the bus
 * thread never waits for it. */
#ifndef VMAC_MQTT_H
#define VMAC_MQTT_H

#include <stddef.h>
#include <stdint.h>

#include "../config/config.h"
#include "../host/bus.h"
#include "../host/events.h"

#define VMAC_MQTT_TOPIC_MAX 128 /* a prefix, or a host id */

/* The mqtt_* settings of the configuration, checked, with defaults filled
 * in and the password file read (vmac_mqtt_settings_parse). */
struct vmac_mqtt_settings {
	int enabled; /* mqtt_url given */
	int tls;     /* mqtts:// */
	char host[256];
	int port;
	char client_id[128];
	char host_id[64]; /* this host in topics: PREFIX/HOST_ID/... */
	char user[128];
	char password[256]; /* never printed */
	int has_password;
	char cafile[VMAC_PATH_MAX], certfile[VMAC_PATH_MAX], keyfile[VMAC_PATH_MAX];
	char prefix[VMAC_MQTT_TOPIC_MAX];
	char discovery_prefix[VMAC_MQTT_TOPIC_MAX];
	int ha_device; /* mqtt_discovery_mode = device: Home Assistant's device-based discovery */
	int commands;  /* subscribe to the command topics */
	int sparkplug; /* also a Sparkplug B Edge Node, on a connection of its own */
	char sparkplug_group[VMAC_MQTT_TOPIC_MAX];
	char ui_url[256];                /* the web UI's address for Home Assistant's configuration_url */
	char sparkplug_primary_host[64]; /* "": none; else births wait for spBv1.0/STATE/ID online */
	unsigned keepalive_s;
};

/* The configuration's mqtt_* keys into *out. Returns 0, or -1 with err
 * naming the setting and what is wrong (the host then does not start).
 * Reads mqtt_password_file and checks that the TLS files can be read. */
int vmac_mqtt_settings_parse(const struct vmac_config *cfg, struct vmac_mqtt_settings *out, char *err, size_t errlen);

struct vmac_mqtt; /* opaque */
struct vmac_site; /* site.h */

/* Start the client (enabled settings only): it connects in the background
 * and keeps trying; a broker that is down is never an error here. log gets
 * its events (kind "mqtt"). Returns NULL with err set only when the client
 * cannot be made at all (out of memory, a TLS file libmosquitto refuses).
 * site (NULL: none): the site view it keeps, from every host's native topics
 * on the broker; the caller owns it and frees it after vmac_mqtt_stop. */
struct vmac_mqtt *vmac_mqtt_start(const struct vmac_mqtt_settings *s, const struct vmac_config *cfg,
                                  struct vmac_bus *bus, struct vmac_event_log *log, struct vmac_site *site, char *err,
                                  size_t errlen);
/* Publish the host and its devices offline (waiting at most about a
 * second for the broker), disconnect, join the threads, free. NULL: nothing. */
void vmac_mqtt_stop(struct vmac_mqtt *m);

/* The client's figures for GET /metrics (mqtt_stats.c), since the process
 * started: all 0 while no client runs. Connection 0 is the main one,
 * 1 Sparkplug's (used only with mqtt_sparkplug). Any thread. */
#define VMAC_MQTT_CONNECTIONS 2
struct vmac_mqtt_stats {
	int running;      /* a client runs (mqtt_url set) */
	uint64_t dropped; /* messages received and dropped: they came faster than they were handled */
	struct {
		int used, connected;     /* the connection is made; its CONNACK came and it has not closed since */
		uint64_t connects;       /* CONNACKs accepted */
		uint64_t published;      /* messages handed to libmosquitto to send */
		uint64_t publish_failed; /* ... refused by it (not connected meanwhile, out of memory) */
		uint64_t received;       /* messages that came from the broker, every topic */
	} conn[VMAC_MQTT_CONNECTIONS];
};
void vmac_mqtt_stats(struct vmac_mqtt_stats *out);

#endif
