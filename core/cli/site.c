/* vmac site: connects to the broker (libmosquitto), subscribes to every
 * host's native topics, collects the retained messages for --wait seconds
 * into a site view (core/mqtt/site.h, the one vmacd keeps for GET /api/site)
 * and prints it. Needs no vmacd and no token: only the broker. */
#include "site.h"

#include <jansson.h>
#include <mosquitto.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../config/config.h"
#include "../mqtt/mqtt.h"
#include "../mqtt/site.h"
#include "command.h"

/* Exit codes (docs/CLI.md). */
enum { SITE_OK = 0, SITE_BROKER = 1, SITE_USAGE = VMAC_CMD_USAGE, SITE_EMPTY = 3 };

struct session {
	struct mosquitto *mosq;
	struct vmac_site *site;
	int connack; /* -1: none yet; else the CONNACK's code (0: accepted) */
};

static void on_connect(struct mosquitto *mosq, void *obj, int rc)
{
	struct session *k = obj;
	char pattern[VMAC_MQTT_TOPIC_MAX + 16];
	int i;
	k->connack = rc;
	if (rc != 0)
		return;
	vmac_site_set_connected(k->site, 1);
	for (i = 0; i < VMAC_SITE_PATTERNS; i++) {
		vmac_site_pattern(k->site, i, pattern, sizeof(pattern));
		mosquitto_subscribe(mosq, NULL, pattern, 1);
	}
}

static void on_message(struct mosquitto *mosq, void *obj, const struct mosquitto_message *msg)
{
	struct session *k = obj;
	(void)mosq;
	vmac_site_feed(k->site, msg->topic, msg->payload, msg->payloadlen);
}

static double mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* A value as the console prints it: strings as they are, others as JSON. */
static void print_value(const char *name, json_t *v)
{
	char *text = json_is_string(v) ? NULL : json_dumps(v, JSON_ENCODE_ANY | JSON_COMPACT);
	printf(" %s=%s", name, text ? text : json_string_value(v));
	free(text);
}

static void print_site(json_t *site, const char *broker)
{
	json_t *hosts = json_object_get(site, "hosts"), *h, *d, *dropped = json_object_get(site, "dropped");
	size_t i, k, online = 0;
	json_array_foreach(hosts, i, h) online += strcmp(json_string_value(json_object_get(h, "state")), "online") == 0;
	printf("site %s on %s: %zu host%s, %zu online\n", json_string_value(json_object_get(site, "prefix")), broker,
	       json_array_size(hosts), json_array_size(hosts) == 1 ? "" : "s", online);
	json_array_foreach(hosts, i, h)
	{
		json_t *devices = json_object_get(h, "devices");
		printf("\n%-20s %s\n", json_string_value(json_object_get(h, "host")),
		       json_string_value(json_object_get(h, "state")));
		json_array_foreach(devices, k, d)
		{
			const char *name;
			json_t *v;
			printf("  %-18s %-8s", json_string_value(json_object_get(d, "device")),
			       json_string_value(json_object_get(d, "state")));
			json_object_foreach(json_object_get(d, "values"), name, v) print_value(name, v);
			printf("\n");
		}
	}
	if (json_integer_value(json_object_get(dropped, "hosts")) ||
	    json_integer_value(json_object_get(dropped, "devices")) ||
	    json_integer_value(json_object_get(dropped, "values")) ||
	    json_integer_value(json_object_get(site, "malformed")))
		printf("\nnot shown: %lld hosts, %lld devices, %lld values over the bounds; %lld malformed messages\n",
		       (long long)json_integer_value(json_object_get(dropped, "hosts")),
		       (long long)json_integer_value(json_object_get(dropped, "devices")),
		       (long long)json_integer_value(json_object_get(dropped, "values")),
		       (long long)json_integer_value(json_object_get(site, "malformed")));
}

/* The broker's settings from the options, checked as vmacd checks its own. */
static int settings(const char *url, const char *prefix, const char *user, const char *password_file,
                    const char *cafile, struct vmac_mqtt_settings *s)
{
	static struct vmac_config cfg;
	char err[512], client_id[64];
	vmac_config_defaults(&cfg);
	snprintf(client_id, sizeof(client_id), "vmac-site-%ld", (long)getpid());
	if (vmac_config_set(&cfg, "mqtt_url", url, err, sizeof(err)) != 0 ||
	    vmac_config_set(&cfg, "mqtt_client_id", client_id, err, sizeof(err)) != 0 ||
	    (prefix && vmac_config_set(&cfg, "mqtt_prefix", prefix, err, sizeof(err)) != 0) ||
	    (user && vmac_config_set(&cfg, "mqtt_user", user, err, sizeof(err)) != 0) ||
	    (password_file && vmac_config_set(&cfg, "mqtt_password_file", password_file, err, sizeof(err)) != 0) ||
	    (cafile && vmac_config_set(&cfg, "mqtt_cafile", cafile, err, sizeof(err)) != 0) ||
	    vmac_mqtt_settings_parse(&cfg, s, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac site: %s\n", err);
		return -1;
	}
	return 0;
}

/* Connect, collect for wait_s, and leave the view in k->site: SITE_OK or
 * SITE_BROKER (said why). */
static int collect(struct session *k, const struct vmac_mqtt_settings *s, double wait_s)
{
	double deadline;
	int rc;
	k->mosq = mosquitto_new(s->client_id, true, k);
	if (!k->mosq) {
		fprintf(stderr, "vmac site: cannot make an MQTT client\n");
		return SITE_BROKER;
	}
	mosquitto_int_option(k->mosq, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
	mosquitto_connect_callback_set(k->mosq, on_connect);
	mosquitto_message_callback_set(k->mosq, on_message);
	if (s->user[0] && mosquitto_username_pw_set(k->mosq, s->user, s->has_password ? s->password : NULL) != 0) {
		fprintf(stderr, "vmac site: --user refused by libmosquitto\n");
		return SITE_BROKER;
	}
	if (s->tls && mosquitto_tls_set(k->mosq, s->cafile[0] ? s->cafile : NULL,
	                                s->cafile[0] ? NULL : "/etc/ssl/certs", NULL, NULL, NULL) != MOSQ_ERR_SUCCESS) {
		fprintf(stderr, "vmac site: the TLS files were refused\n");
		return SITE_BROKER;
	}
	if ((rc = mosquitto_connect(k->mosq, s->host, s->port, 10)) != MOSQ_ERR_SUCCESS) {
		fprintf(stderr, "vmac site: cannot reach the broker %s:%d: %s\n", s->host, s->port,
		        rc == MOSQ_ERR_ERRNO ? "connection refused or unreachable" : mosquitto_strerror(rc));
		return SITE_BROKER;
	}
	deadline = mono_s() + wait_s;
	while (mono_s() < deadline) {
		int left_ms = (int)((deadline - mono_s()) * 1000) + 1;
		if ((rc = mosquitto_loop(k->mosq, left_ms < 100 ? left_ms : 100, 1)) != MOSQ_ERR_SUCCESS) {
			fprintf(stderr, "vmac site: lost the broker %s:%d: %s\n", s->host, s->port,
			        mosquitto_strerror(rc));
			return SITE_BROKER;
		}
		if (k->connack > 0) {
			fprintf(stderr, "vmac site: the broker %s:%d refused the connection: %s\n", s->host, s->port,
			        mosquitto_connack_string(k->connack));
			return SITE_BROKER;
		}
	}
	if (k->connack != 0) {
		fprintf(stderr, "vmac site: the broker %s:%d did not answer within %g s\n", s->host, s->port, wait_s);
		return SITE_BROKER;
	}
	mosquitto_disconnect(k->mosq);
	return SITE_OK;
}

enum { SITE_MQTT = VMAC_CMD_OWN, SITE_PREFIX, SITE_WAIT, SITE_USER, SITE_PASSWORD_FILE, SITE_CAFILE };

static const struct vmac_cmd_option site_options[] = {
    [SITE_MQTT - VMAC_CMD_OWN] = {"mqtt", NULL, 0, "URL", "VMAC_MQTT", NULL,
                                  "the broker: mqtt://HOST[:PORT] or mqtts://HOST[:PORT]"},
    [SITE_PREFIX - VMAC_CMD_OWN] = {"prefix", NULL, 0, "P", NULL, NULL, "the hosts' mqtt_prefix (default vmac)"},
    [SITE_WAIT - VMAC_CMD_OWN] = {"wait", NULL, 0, "S", NULL, NULL,
                                  "wait S seconds for the retained messages, 0.1..60 (default 2)"},
    [SITE_USER - VMAC_CMD_OWN] = {"user", NULL, 0, "U", NULL, NULL, "user name for the broker"},
    [SITE_PASSWORD_FILE - VMAC_CMD_OWN] = {"password-file", NULL, 0, "F", NULL, NULL, "the password: F's first line"},
    [SITE_CAFILE - VMAC_CMD_OWN] = {"cafile", NULL, 0, "F", NULL, NULL,
                                    "mqtts: the CA of the broker's certificate (default: the system's)"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

static int site_run(const struct vmac_cmd_args *a)
{
	const char *url = a->opt[SITE_MQTT];
	struct vmac_mqtt_settings s;
	struct session k = {NULL, NULL, -1};
	double wait_s = 2.0;
	char broker[300], *end;
	int rc;
	json_t *view;
	if (a->opt[SITE_WAIT]) {
		wait_s = strtod(a->opt[SITE_WAIT], &end);
		if (!*a->opt[SITE_WAIT] || *end || !(wait_s >= 0.1 && wait_s <= 60)) {
			fprintf(stderr, "vmac site: --wait '%s': expected seconds, 0.1..60\n", a->opt[SITE_WAIT]);
			return SITE_USAGE;
		}
	}
	if (!url || !url[0]) {
		fprintf(stderr, "vmac site: --mqtt URL is needed (or $VMAC_MQTT), e.g. --mqtt mqtt://127.0.0.1:1883\n");
		return SITE_USAGE;
	}
	if (settings(url, a->opt[SITE_PREFIX], a->opt[SITE_USER], a->opt[SITE_PASSWORD_FILE], a->opt[SITE_CAFILE],
	             &s) != 0)
		return SITE_USAGE;
	if (!(k.site = vmac_site_new(s.prefix, NULL))) {
		fprintf(stderr, "vmac site: out of memory\n");
		return SITE_BROKER;
	}
	mosquitto_lib_init();
	rc = collect(&k, &s, wait_s);
	mosquitto_destroy(k.mosq);
	mosquitto_lib_cleanup();
	view = rc == SITE_OK ? vmac_site_json(k.site) : NULL;
	vmac_site_free(k.site);
	if (rc != SITE_OK)
		return rc;
	if (!view) {
		fprintf(stderr, "vmac site: out of memory\n");
		return SITE_BROKER;
	}
	if (a->opt[VMAC_CMD_JSON]) {
		char *text = json_dumps(view, JSON_COMPACT);
		printf("%s\n", text ? text : "{}");
		free(text);
	} else {
		snprintf(broker, sizeof(broker), "%s://%s:%d", s.tls ? "mqtts" : "mqtt", s.host, s.port);
		print_site(view, broker);
	}
	rc = json_array_size(json_object_get(view, "hosts")) > 0 ? SITE_OK : SITE_EMPTY;
	if (rc == SITE_EMPTY)
		fprintf(stderr, "vmac site: no vmac host under %s/ on this broker\n", s.prefix);
	json_decref(view);
	return rc;
}

const struct vmac_cmd vmac_site_cmd = {
    .name = "site",
    .summary = "every host on an MQTT broker, its devices and values (the broker alone)",
    .about = "Every vmac host on an MQTT broker, its devices (online/offline) and their last values, from the\n"
             "broker's retained messages alone (no vmacd HTTP, no token); with --json as GET /api/site\n"
             "answers it.\n"
             "Exit codes: 0 the site printed, 1 the broker unreachable or refusing, 2 wrong usage,\n"
             "3 no vmac host under the prefix.\n",
    .common = VMAC_CMD_TAKES(VMAC_CMD_JSON),
    .own = site_options,
    .run = site_run};
