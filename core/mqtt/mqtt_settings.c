/* The mqtt_* settings (docs/HOST.md, docs/MQTT.md) checked at start, with
 * their defaults filled in: the broker's URL, the client id and host id,
 * the credentials (the password file read here, once), the TLS files and
 * the topic prefixes. No libmosquitto: pure checks and file reads. */
#include "mqtt.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* A host name or IPv4 address: letters, digits, '.', '-'. */
static int host_ok(const char *s, size_t len)
{
	size_t i;
	if (len == 0 || len > 253)
		return 0;
	for (i = 0; i < len; i++)
		if (!isalnum((unsigned char)s[i]) && s[i] != '.' && s[i] != '-')
			return 0;
	return 1;
}

/* mqtt://HOST[:PORT] or mqtts://HOST[:PORT]. */
static int parse_url(const char *url, struct vmac_mqtt_settings *s, char *err, size_t errlen)
{
	const char *rest, *colon;
	size_t hostlen;
	if (strncmp(url, "mqtt://", 7) == 0) {
		rest = url + 7;
		s->tls = 0;
		s->port = 1883;
	} else if (strncmp(url, "mqtts://", 8) == 0) {
		rest = url + 8;
		s->tls = 1;
		s->port = 8883;
	} else {
		snprintf(err, errlen, "mqtt_url '%s': expected mqtt://HOST:PORT or mqtts://HOST:PORT", url);
		return -EINVAL;
	}
	colon = strchr(rest, ':');
	hostlen = colon ? (size_t)(colon - rest) : strlen(rest);
	if (!host_ok(rest, hostlen) || hostlen >= sizeof(s->host)) {
		snprintf(err, errlen, "mqtt_url '%s': expected a host name or IPv4 address after %s", url,
		         s->tls ? "mqtts://" : "mqtt://");
		return -EINVAL;
	}
	memcpy(s->host, rest, hostlen);
	s->host[hostlen] = 0;
	if (colon) {
		char *end;
		long port;
		errno = 0;
		port = strtol(colon + 1, &end, 10);
		if (errno || end == colon + 1 || *end || port < 1 || port > 65535) {
			snprintf(err, errlen, "mqtt_url '%s': the port must be 1..65535", url);
			return -EINVAL;
		}
		s->port = (int)port;
	}
	return 0;
}

/* A topic prefix: one or more levels of printable characters, no
 * wildcard, no empty level. */
static int prefix_ok(const char *p)
{
	size_t i, n = strlen(p);
	if (n == 0 || p[0] == '/' || p[n - 1] == '/' || strstr(p, "//"))
		return 0;
	for (i = 0; i < n; i++)
		if (p[i] == '+' || p[i] == '#' || (unsigned char)p[i] < 0x21 || p[i] == 0x7f)
			return 0;
	return 1;
}

/* [A-Za-z0-9_-]+: one topic level, and a Home Assistant node id. */
static int id_ok(const char *p)
{
	size_t i, n = strlen(p);
	if (n == 0)
		return 0;
	for (i = 0; i < n; i++)
		if (!isalnum((unsigned char)p[i]) && p[i] != '_' && p[i] != '-')
			return 0;
	return 1;
}

static int readable(const char *key, const char *path, char *err, size_t errlen)
{
	if (path[0] && access(path, R_OK) != 0) {
		int e = errno;
		snprintf(err, errlen, "%s '%s': cannot be read (%s)", key, path, strerror(e));
		return -e;
	}
	return 0;
}

/* The first line of the password file, without its line end. */
static int read_password(const char *path, struct vmac_mqtt_settings *s, char *err, size_t errlen)
{
	FILE *f = fopen(path, "r");
	size_t n;
	if (!f) {
		int e = errno;
		snprintf(err, errlen, "mqtt_password_file '%s': %s", path, strerror(e));
		return -e;
	}
	if (!fgets(s->password, sizeof(s->password), f))
		s->password[0] = 0;
	fclose(f);
	n = strcspn(s->password, "\r\n");
	s->password[n] = 0;
	if (n == 0) {
		snprintf(err, errlen, "mqtt_password_file '%s': the file is empty", path);
		return -EINVAL;
	}
	s->has_password = 1;
	return 0;
}

/* The web UI's address as a browser on another machine reaches it:
 * ui_url, else http(s)://ADDR:PORT/ from the http setting (the machine's
 * host name when it listens on every address); none for port 0. 0, or -1
 * with err. */
static int ui_url(const struct vmac_config *cfg, const char *hostname, struct vmac_mqtt_settings *s, char *err,
                  size_t errlen)
{
	const char *colon = strrchr(cfg->http, ':');
	size_t i;
	if (cfg->ui_url[0]) {
		if (strncmp(cfg->ui_url, "http://", 7) != 0 && strncmp(cfg->ui_url, "https://", 8) != 0) {
			snprintf(err, errlen, "ui_url '%s': expected http://HOST[:PORT]/... or https://...",
			         cfg->ui_url);
			return -EINVAL;
		}
		for (i = 0; cfg->ui_url[i]; i++)
			if ((unsigned char)cfg->ui_url[i] <= 0x20 || cfg->ui_url[i] == 0x7f || cfg->ui_url[i] == '"') {
				snprintf(err, errlen, "ui_url '%s': no spaces, quotes or control characters",
				         cfg->ui_url);
				return -EINVAL;
			}
		snprintf(s->ui_url, sizeof(s->ui_url), "%s", cfg->ui_url);
		return 0;
	}
	if (!colon || strcmp(colon, ":0") == 0)
		return 0; /* a port the kernel chooses: not known here, so none */
	if (strncmp(cfg->http, "0.0.0.0:", 8) == 0)
		snprintf(s->ui_url, sizeof(s->ui_url), "%s://%s%s/", cfg->tls_cert[0] ? "https" : "http", hostname,
		         colon);
	else
		snprintf(s->ui_url, sizeof(s->ui_url), "%s://%s/", cfg->tls_cert[0] ? "https" : "http", cfg->http);
	return 0;
}

/* mqtt_discovery_mode: Home Assistant's single component discovery (one
 * config per entity, the default) or its device-based discovery (one per
 * machine, HA 2024.11 and later). */
static int discovery_mode(const struct vmac_config *cfg, struct vmac_mqtt_settings *s, char *err, size_t errlen)
{
	if (strcmp(cfg->mqtt_discovery_mode, "device") != 0 && strcmp(cfg->mqtt_discovery_mode, "component") != 0) {
		snprintf(err, errlen, "mqtt_discovery_mode '%s': expected component or device",
		         cfg->mqtt_discovery_mode);
		return -EINVAL;
	}
	s->ha_device = strcmp(cfg->mqtt_discovery_mode, "device") == 0;
	return 0;
}

/* mqtt_sparkplug_group and mqtt_sparkplug_primary_host: one topic level each. */
static int sparkplug_ids(const struct vmac_config *cfg, struct vmac_mqtt_settings *s, char *err, size_t errlen)
{
	size_t i;
	/* A Sparkplug group id is one topic level; '.' allowed (names such as plant.hall2). */
	for (i = 0; cfg->mqtt_sparkplug_group[i]; i++)
		if (!isalnum((unsigned char)cfg->mqtt_sparkplug_group[i]) &&
		    !strchr("_-.", cfg->mqtt_sparkplug_group[i]))
			break;
	if (!cfg->mqtt_sparkplug_group[0] || cfg->mqtt_sparkplug_group[i] ||
	    strlen(cfg->mqtt_sparkplug_group) >= sizeof(s->sparkplug_group)) {
		snprintf(err, errlen, "mqtt_sparkplug_group '%s': expected letters, digits, '_', '-' and '.' only",
		         cfg->mqtt_sparkplug_group);
		return -EINVAL;
	}
	snprintf(s->sparkplug_group, sizeof(s->sparkplug_group), "%s", cfg->mqtt_sparkplug_group);
	/* The Primary Host Application's id: one topic level of spBv1.0/STATE/ID. */
	for (i = 0; cfg->mqtt_sparkplug_primary_host[i]; i++)
		if (!isalnum((unsigned char)cfg->mqtt_sparkplug_primary_host[i]) &&
		    !strchr("_-.", cfg->mqtt_sparkplug_primary_host[i]))
			break;
	if (cfg->mqtt_sparkplug_primary_host[i] ||
	    strlen(cfg->mqtt_sparkplug_primary_host) >= sizeof(s->sparkplug_primary_host)) {
		snprintf(err, errlen,
		         "mqtt_sparkplug_primary_host '%s': expected a host application id of letters, digits, '_', "
		         "'-' and '.' (at most 63)",
		         cfg->mqtt_sparkplug_primary_host);
		return -EINVAL;
	}
	snprintf(s->sparkplug_primary_host, sizeof(s->sparkplug_primary_host), "%s", cfg->mqtt_sparkplug_primary_host);
	return 0;
}

int vmac_mqtt_settings_parse(const struct vmac_config *cfg, struct vmac_mqtt_settings *out, char *err, size_t errlen)
{
	struct vmac_mqtt_settings *s = out;
	char hostname[64];
	int rc;
	size_t i;
	memset(s, 0, sizeof(*s));
	if (!cfg->mqtt_url[0])
		return 0; /* off: the other keys are not looked at */
	s->enabled = 1;
	if ((rc = parse_url(cfg->mqtt_url, s, err, errlen)) != 0)
		return rc;
	if (gethostname(hostname, sizeof(hostname)) != 0)
		snprintf(hostname, sizeof(hostname), "vmac");
	hostname[sizeof(hostname) - 1] = 0;
	if ((rc = ui_url(cfg, hostname, s, err, errlen)) != 0)
		return rc;
	for (i = 0; hostname[i]; i++) /* a topic level and an HA id: [A-Za-z0-9_-] */
		if (!isalnum((unsigned char)hostname[i]) && hostname[i] != '-')
			hostname[i] = '_';
	snprintf(s->host_id, sizeof(s->host_id), "%s", cfg->mqtt_host_id[0] ? cfg->mqtt_host_id : hostname);
	if (!id_ok(s->host_id)) {
		snprintf(err, errlen, "mqtt_host_id '%s': expected letters, digits, '_' and '-' only", s->host_id);
		return -EINVAL;
	}
	if (cfg->mqtt_client_id[0])
		snprintf(s->client_id, sizeof(s->client_id), "%s", cfg->mqtt_client_id);
	else
		snprintf(s->client_id, sizeof(s->client_id), "vmac-%s", hostname);
	for (i = 0; s->client_id[i]; i++)
		if ((unsigned char)s->client_id[i] < 0x21 || s->client_id[i] == 0x7f) {
			snprintf(err, errlen, "mqtt_client_id '%s': no spaces or control characters", s->client_id);
			return -EINVAL;
		}
	snprintf(s->user, sizeof(s->user), "%s", cfg->mqtt_user);
	if (cfg->mqtt_password[0] && cfg->mqtt_password_file[0]) {
		snprintf(err, errlen, "mqtt_password and mqtt_password_file: give one or the other");
		return -EINVAL;
	}
	if (cfg->mqtt_password[0]) {
		snprintf(s->password, sizeof(s->password), "%s", cfg->mqtt_password);
		s->has_password = 1;
	} else if (cfg->mqtt_password_file[0] && (rc = read_password(cfg->mqtt_password_file, s, err, errlen)) != 0) {
		return rc;
	}
	if (s->has_password && !s->user[0]) {
		snprintf(err, errlen, "a password for the broker needs mqtt_user too");
		return -EINVAL;
	}
	if (!s->tls && (cfg->mqtt_cafile[0] || cfg->mqtt_certfile[0] || cfg->mqtt_keyfile[0])) {
		snprintf(err, errlen, "mqtt_cafile, mqtt_certfile and mqtt_keyfile need an mqtts:// mqtt_url");
		return -EINVAL;
	}
	if (!cfg->mqtt_certfile[0] != !cfg->mqtt_keyfile[0]) {
		snprintf(err, errlen, "a client certificate needs both mqtt_certfile and mqtt_keyfile");
		return -EINVAL;
	}
	if (readable("mqtt_cafile", cfg->mqtt_cafile, err, errlen) ||
	    readable("mqtt_certfile", cfg->mqtt_certfile, err, errlen) ||
	    readable("mqtt_keyfile", cfg->mqtt_keyfile, err, errlen))
		return -EACCES;
	snprintf(s->cafile, sizeof(s->cafile), "%s", cfg->mqtt_cafile);
	snprintf(s->certfile, sizeof(s->certfile), "%s", cfg->mqtt_certfile);
	snprintf(s->keyfile, sizeof(s->keyfile), "%s", cfg->mqtt_keyfile);
	if (!prefix_ok(cfg->mqtt_prefix) || strlen(cfg->mqtt_prefix) >= sizeof(s->prefix)) {
		snprintf(err, errlen,
		         "mqtt_prefix '%s': expected topic levels such as vmac or site/vmac (no +, #, "
		         "spaces or empty levels)",
		         cfg->mqtt_prefix);
		return -EINVAL;
	}
	if (!prefix_ok(cfg->mqtt_discovery_prefix) || strlen(cfg->mqtt_discovery_prefix) >= sizeof(s->prefix)) {
		snprintf(err, errlen,
		         "mqtt_discovery_prefix '%s': expected topic levels such as homeassistant (no +, #, spaces or "
		         "empty levels)",
		         cfg->mqtt_discovery_prefix);
		return -EINVAL;
	}
	snprintf(s->prefix, sizeof(s->prefix), "%s", cfg->mqtt_prefix);
	snprintf(s->discovery_prefix, sizeof(s->discovery_prefix), "%s", cfg->mqtt_discovery_prefix);
	if ((rc = discovery_mode(cfg, s, err, errlen)) != 0 || (rc = sparkplug_ids(cfg, s, err, errlen)) != 0)
		return rc;
	s->sparkplug = cfg->mqtt_sparkplug;
	s->commands = cfg->mqtt_commands;
	s->keepalive_s = cfg->mqtt_keepalive_s;
	return 0;
}
