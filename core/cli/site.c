/* vmac site: connects to the broker (libmosquitto), subscribes to every
 * host's native topics, collects the retained messages for --wait seconds
 * into a site view (core/mqtt/site.h, the one vmacd keeps for GET /api/site)
 * and prints it. Needs no vmacd and no token: only the broker. */
#include "site.h"

#include <getopt.h>
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

/* Exit codes (docs/CLI.md). */
enum { SITE_OK = 0, SITE_BROKER = 1, SITE_USAGE = 2, SITE_EMPTY = 3 };

static const char help[] =
    "usage: vmac site --mqtt URL [--prefix P] [--json] [--wait S] [--user U --password-file F] [--cafile F]\n"
    "Every vmac host on an MQTT broker, its devices (online/offline) and their last values, from the\n"
    "broker's retained messages alone (no vmacd HTTP, no token).\n"
    "  --mqtt URL          the broker: mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (default $VMAC_MQTT)\n"
    "  --prefix P          the hosts' mqtt_prefix (default vmac)\n"
    "  --json              print the site as JSON (as GET /api/site answers)\n"
    "  --wait S            wait S seconds for the retained messages, 0.1..60 (default 2)\n"
    "  --user U            user name for the broker\n"
    "  --password-file F   the password: F's first line\n"
    "  --cafile F          mqtts: the CA of the broker's certificate (default: the system's)\n"
    "Exit codes: 0 the site printed, 1 the broker unreachable or refusing, 2 wrong usage,\n"
    "3 no vmac host under the prefix.\n";

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

int vmac_site_main(int argc, char **argv)
{
	static const struct option opts[] = {{"mqtt", required_argument, 0, 'm'},
	                                     {"prefix", required_argument, 0, 'p'},
	                                     {"json", no_argument, 0, 'j'},
	                                     {"wait", required_argument, 0, 'w'},
	                                     {"user", required_argument, 0, 'u'},
	                                     {"password-file", required_argument, 0, 'P'},
	                                     {"cafile", required_argument, 0, 'c'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {0, 0, 0, 0}};
	const char *url = getenv("VMAC_MQTT"), *prefix = NULL, *user = NULL, *password_file = NULL, *cafile = NULL;
	struct vmac_mqtt_settings s;
	struct session k = {NULL, NULL, -1};
	double wait_s = 2.0;
	char broker[300], *end;
	int json = 0, opt, rc;
	json_t *view;
	optind = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		switch (opt) {
		case 'm': url = optarg; break;
		case 'p': prefix = optarg; break;
		case 'j': json = 1; break;
		case 'u': user = optarg; break;
		case 'P': password_file = optarg; break;
		case 'c': cafile = optarg; break;
		case 'w':
			wait_s = strtod(optarg, &end);
			if (!*optarg || *end || !(wait_s >= 0.1 && wait_s <= 60)) {
				fprintf(stderr, "vmac site: --wait '%s': expected seconds, 0.1..60\n", optarg);
				return SITE_USAGE;
			}
			break;
		case 'h': printf("%s", help); return SITE_OK;
		default: return SITE_USAGE;
		}
	}
	if (optind < argc) {
		fprintf(stderr, "vmac site: unexpected argument '%s' (see --help)\n", argv[optind]);
		return SITE_USAGE;
	}
	if (!url || !url[0]) {
		fprintf(stderr, "vmac site: --mqtt URL is needed (or $VMAC_MQTT), e.g. --mqtt mqtt://127.0.0.1:1883\n");
		return SITE_USAGE;
	}
	if (settings(url, prefix, user, password_file, cafile, &s) != 0)
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
	if (json) {
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
