/* Profile "vmac": vmac's own topics (docs/MQTT.md, "Topics"). The host's
 * birth and will on PREFIX/HOST/status, each machine's availability and
 * values (retained), and the command topics PREFIX/HOST/DEVICE/set/NAME
 * and .../cmd/NAME handed to the bus exactly as POST
 * /api/devices/NAME/input hands them (the driver validates; a refusal is
 * published back on PREFIX/HOST/DEVICE/_error, never more than that;
 * each command, carried out or not, is in the audit trail).
 * The host's own per-device topics begin with '_', which no name of a
 * driver's can ([a-z][a-z0-9_]*): a variable named error or availability
 * has its state topic like any other. */
#include "mqtt_internal.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/errors.h"
#include "../driver/hints.h"

void mqtt_topic(const struct vmac_mqtt *m, char *out, size_t outlen, const char *fmt, ...)
{
	va_list ap;
	int n = snprintf(out, outlen, "%s/%s/", m->s.prefix, m->s.host_id);
	if (n < 0 || (size_t)n >= outlen)
		return;
	va_start(ap, fmt);
	vsnprintf(out + n, outlen - (size_t)n, fmt, ap);
	va_end(ap);
}

/* "None" is Home Assistant's PAYLOAD_NONE: every MQTT entity reads it as
 * unknown, where an empty payload is ignored (the stale value stays) and
 * "null" is refused by a sensor with a unit. A number that is not finite
 * (NaN, inf) is no measurement: unknown too. */
void mqtt_value_text(const struct vmac_value *v, char *out, size_t outlen)
{
	switch (v->type) {
	case VMAC_VALUE_NUMBER:
		if (isfinite(v->number))
			snprintf(out, outlen, "%.15g", v->number);
		else
			snprintf(out, outlen, "%s", MQTT_PAYLOAD_NONE);
		break;
	case VMAC_VALUE_BOOL: snprintf(out, outlen, "%s", v->number != 0 ? "true" : "false"); break;
	case VMAC_VALUE_STRING: snprintf(out, outlen, "%s", v->str); break;
	default: snprintf(out, outlen, "%s", MQTT_PAYLOAD_NONE); break;
	}
}

void mqtt_value_text_at(const struct vmac_value *v, int precision, char *out, size_t outlen)
{
	double rounded;
	if (precision < 0 || precision > 6 || v->type != VMAC_VALUE_NUMBER || !isfinite(v->number)) {
		mqtt_value_text(v, out, outlen);
		return;
	}
	snprintf(out, outlen, "%.*f", precision, v->number);
	rounded = strtod(out, NULL);
	if (rounded == 0) /* -0.04 at one decimal is 0.0, not -0.0 */
		snprintf(out, outlen, "%.*f", precision, 0.0);
}

/* A whole step less this share of one still counts as one: the texts read
 * back are binary approximations (37.5 - 37.4 is 0.1000000000000014, and
 * another pair of texts gives 0.0999999999999996). */
#define STEP_TOLERANCE 1e-9

int mqtt_value_moved(const struct vmac_value *v, int precision, const char *text, const char *sent)
{
	double shown;
	char *end;
	if (strcmp(text, sent) == 0)
		return 0;
	if (precision < 0 || precision > 6 || v->type != VMAC_VALUE_NUMBER || !isfinite(v->number))
		return 1;
	shown = strtod(sent, &end);
	if (end == sent || *end || !isfinite(shown))
		return 1; /* None, or not a number before: a change of kind */
	return fabs(v->number - shown) >= pow(10.0, -precision) * (1.0 - STEP_TOLERANCE);
}

int mqtt_declared_precision(json_t *decl)
{
	json_t *p = json_object_get(decl, "precision");
	double x = json_number_value(p);
	if (!json_is_number(p) || json_object_get(decl, "values") || x != floor(x) || x < 0 || x > 6)
		return -1;
	return (int)x;
}

static int equals_ci(const char *a, const char *b)
{
	return strcasecmp(a, b) == 0;
}

int mqtt_payload_value(const char *payload, int len, struct vmac_value *v, const char **why)
{
	char text[MQTT_PAYLOAD_MAX + 1], *end;
	size_t n, i;
	memset(v, 0, sizeof(*v));
	if (len < 0) {
		*why = "the payload is over 256 bytes";
		return -1;
	}
	memcpy(text, payload, (size_t)len);
	text[len] = 0;
	if (strlen(text) != (size_t)len) {
		*why = "the payload holds a NUL byte";
		return -1;
	}
	for (i = 0; i < (size_t)len; i++)
		if ((unsigned char)text[i] < 0x20 && text[i] != '\t' && text[i] != '\n' && text[i] != '\r') {
			*why = "the payload holds control characters";
			return -1;
		}
	/* Trim blanks around it. */
	for (n = strlen(text); n > 0 && isspace((unsigned char)text[n - 1]); n--)
		text[n - 1] = 0;
	for (i = 0; isspace((unsigned char)text[i]); i++)
		;
	memmove(text, text + i, strlen(text + i) + 1);
	n = strlen(text);
	if (n == 0 || strcmp(text, "null") == 0 || strcmp(text, "PRESS") == 0) {
		v->type = VMAC_VALUE_NONE; /* a command without a value */
		return 0;
	}
	if (equals_ci(text, "true") || equals_ci(text, "on")) {
		v->type = VMAC_VALUE_BOOL;
		v->number = 1;
		return 0;
	}
	if (equals_ci(text, "false") || equals_ci(text, "off")) {
		v->type = VMAC_VALUE_BOOL;
		return 0;
	}
	errno = 0;
	v->number = strtod(text, &end);
	if (!*end && errno == 0 && isfinite(v->number) && !isalpha((unsigned char)text[0])) {
		v->type = VMAC_VALUE_NUMBER;
		return 0;
	}
	v->number = 0;
	if (n >= 2 && text[0] == '"' && text[n - 1] == '"') { /* a JSON string: "12" stays a string */
		json_t *s = json_loads(text, JSON_DECODE_ANY, NULL);
		const char *str = json_string_value(s);
		if (!str || strlen(str) > VMAC_DRIVER_STR_MAX) {
			json_decref(s);
			*why = "expected a JSON string of at most 63 bytes";
			return -1;
		}
		v->type = VMAC_VALUE_STRING;
		snprintf(v->str, sizeof(v->str), "%s", str);
		json_decref(s);
		return 0;
	}
	if (text[0] == '{' || text[0] == '[') {
		*why = "expected true/false/ON/OFF, a number, a string (at most 63 bytes) or nothing, not JSON "
		       "structures";
		return -1;
	}
	if (n > VMAC_DRIVER_STR_MAX) {
		*why = "a string value is at most 63 bytes";
		return -1;
	}
	v->type = VMAC_VALUE_STRING;
	snprintf(v->str, sizeof(v->str), "%s", text);
	return 0;
}

/* What a declaration says a value is: 's' a string (a select of strings,
 * or a string default), 'v' one of numeric values, 'n' a number, 'b' a
 * boolean, 0 nothing or a mixed list (the value's own text decides). The
 * kind is Home Assistant's and Sparkplug's too (vmac_hints_kind). */
static char declared_kind(json_t *decl)
{
	json_t *values = json_object_get(decl, "values"), *x;
	size_t i, strings = 0, numbers = 0;
	char kind;
	if (json_is_array(values)) {
		json_array_foreach(values, i, x)
		{
			strings += json_is_string(x);
			numbers += json_is_number(x);
		}
		return strings > 0 && strings == json_array_size(values)   ? 's'
		       : numbers > 0 && numbers == json_array_size(values) ? 'v'
		                                                           : 0;
	}
	kind = vmac_hints_kind(decl);
	return kind == '?' ? 0 : kind;
}

int mqtt_payload_typed(const char *payload, int len, json_t *decl, struct vmac_value *v, const char **why)
{
	char kind = declared_kind(decl);
	size_t i, n;
	if (kind == 's' && len >= 0) { /* the text as it came: "1", "on", "null" are options like any other */
		memset(v, 0, sizeof(*v));
		for (i = 0, n = 0; i < (size_t)len; i++) {
			if (payload[i] == 0 || (unsigned char)payload[i] < 0x20 || payload[i] == 0x7f) {
				*why = payload[i] == 0 ? "the payload holds a NUL byte"
				                       : "the payload holds control characters";
				return -1;
			}
			n += payload[i] != ' ';
		}
		if (n == 0)
			return 0; /* nothing: no value */
		if (len > VMAC_DRIVER_STR_MAX) {
			*why = "a string value is at most 63 bytes";
			return -1;
		}
		v->type = VMAC_VALUE_STRING;
		memcpy(v->str, payload, (size_t)len);
		v->str[len] = 0;
		return 0;
	}
	if (mqtt_payload_value(payload, len, v, why) != 0)
		return -1;
	if (v->type == VMAC_VALUE_NONE || !kind || kind == 'v')
		return 0; /* 'v': a number when it reads as one, else the driver says it is not among the values */
	if (kind == 'n' && v->type != VMAC_VALUE_NUMBER) {
		*why = "expected a number";
		return -1;
	}
	if (kind == 'b' && v->type != VMAC_VALUE_BOOL) {
		*why = "expected true/false/ON/OFF";
		return -1;
	}
	return 0;
}

/* [A-Za-z0-9._-]{1,max} (a device), or [a-z][a-z0-9_]{0,max-1} (a name). */
static int device_ok(const char *s)
{
	size_t i, n = strlen(s);
	if (n == 0 || n > VMAC_NAME_MAX)
		return 0;
	for (i = 0; i < n; i++)
		if (!isalnum((unsigned char)s[i]) && s[i] != '.' && s[i] != '_' && s[i] != '-')
			return 0;
	return 1;
}

static int name_ok(const char *s)
{
	size_t i, n = strlen(s);
	if (n == 0 || n > VMAC_DRIVER_NAME_MAX || !islower((unsigned char)s[0]))
		return 0;
	for (i = 0; i < n; i++)
		if (!islower((unsigned char)s[i]) && !isdigit((unsigned char)s[i]) && s[i] != '_')
			return 0;
	return 1;
}

/* Not retained. */
void mqtt_publish_error(struct vmac_mqtt *m, const char *device, const char *topic, const char *name, const char *code,
                        const char *text)
{
	char where[512];
	json_t *o =
	    json_pack("{s:s, s:s, s:s, s:s}", "topic", topic, "name", name ? name : "", "code", code, "error", text);
	char *body = o ? json_dumps(o, JSON_COMPACT) : NULL;
	if (device)
		mqtt_topic(m, where, sizeof(where), "%s/_error", device);
	else
		mqtt_topic(m, where, sizeof(where), "error");
	if (body)
		mqtt_publish(m, where, body, -1, 0, 0);
	free(body);
	json_decref(o);
}

/* Empty, blanks or PRESS: a button's payload. */
static int is_press(const char *payload, int len)
{
	int start, end;
	if (len < 0)
		return 0;
	for (start = 0; start < len && isspace((unsigned char)payload[start]); start++)
		;
	for (end = len; end > start && isspace((unsigned char)payload[end - 1]); end--)
		;
	return end == start || (end - start == 5 && memcmp(payload + start, "PRESS", 5) == 0);
}

/* The declaration that types the payload of .../set/NAME (the variable or
 * param NAME) or .../cmd/NAME (the param its arg names), from the manifest
 * of the version that runs; NULL when there is none (the value's own text
 * decides). */
static json_t *declaration(struct vmac_mqtt *m, const char *device, const char *kind, const char *name)
{
	struct mqtt_device *d = mqtt_device_find(m, device);
	json_t *decl;
	if (!d || !d->manifest)
		return NULL;
	if (strcmp(kind, "cmd") == 0) {
		const char *arg = json_string_value(
		    json_object_get(json_object_get(json_object_get(d->manifest, "commands"), name), "arg"));
		return arg ? json_object_get(json_object_get(d->manifest, "params"), arg) : NULL;
	}
	decl = json_object_get(json_object_get(d->manifest, "variables"), name);
	return decl ? decl : json_object_get(json_object_get(d->manifest, "params"), name);
}

/* A command not carried out: the error published back on _error (device
 * NULL: the host's error topic) and in the audit trail, with the input
 * when it parsed. */
static void refuse(struct vmac_mqtt *m, const char *device, const struct mqtt_message *msg, const char *name,
                   const struct vmac_bus_input_request *req, const char *code, const char *why)
{
	mqtt_publish_error(m, device, msg->topic, name, code, why);
	mqtt_audit_command(m, msg->conn, msg->topic, device, req, code, why);
}

/* PREFIX/HOST/DEVICE/set/NAME or .../cmd/NAME: operator input, as POST
 * /api/devices/DEVICE/input {"name": NAME, "value": payload} does it; each
 * one, carried out or not, is in the audit trail (mqtt_audit.c). */
static void command(struct vmac_mqtt *m, const struct mqtt_message *msg, const char *rest)
{
	struct vmac_bus_input_request req;
	char device[VMAC_NAME_MAX + 2], kind[8], name[VMAC_DRIVER_NAME_MAX + 2];
	const char *slash1 = strchr(rest, '/'), *slash2 = slash1 ? strchr(slash1 + 1, '/') : NULL, *why;
	size_t dn = slash1 ? (size_t)(slash1 - rest) : 0, kn = slash2 ? (size_t)(slash2 - slash1 - 1) : 0;
	if (!slash2 || dn >= sizeof(device) || kn >= sizeof(kind) || strlen(slash2 + 1) >= sizeof(name) ||
	    strchr(slash2 + 1, '/')) {
		refuse(m, NULL, msg, NULL, NULL, "malformed", "expected PREFIX/HOST/DEVICE/set/NAME or .../cmd/NAME");
		return;
	}
	memcpy(device, rest, dn);
	device[dn] = 0;
	memcpy(kind, slash1 + 1, kn);
	kind[kn] = 0;
	snprintf(name, sizeof(name), "%s", slash2 + 1);
	if (!device_ok(device)) {
		refuse(m, NULL, msg, name, NULL, "malformed", "no such device");
		return;
	}
	if ((strcmp(kind, "set") != 0 && strcmp(kind, "cmd") != 0) || !name_ok(name)) {
		refuse(m, device, msg, name, NULL, "malformed",
		       "expected .../set/NAME or .../cmd/NAME, NAME a variable, param or command of the driver");
		return;
	}
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	snprintf(req.name, sizeof(req.name), "%s", name);
	if (strcmp(kind, "cmd") == 0 && is_press(msg->payload, msg->len)) {
		req.value.type = VMAC_VALUE_NONE; /* a button: the command without an argument */
	} else if (mqtt_payload_typed(msg->payload, msg->len > MQTT_TEXT_PAYLOAD_MAX ? -1 : msg->len,
	                              declaration(m, device, kind, name), &req.value, &why) != 0) {
		refuse(m, device, msg, name, NULL, "malformed", why);
		return;
	}
	if (strcmp(kind, "set") == 0 && req.value.type == VMAC_VALUE_NONE) {
		refuse(m, device, msg, name, &req, "malformed", "set needs a value");
		return;
	}
	if (vmac_bus_request_input(m->bus, &req, MQTT_INPUT_TIMEOUT_MS) != 0) {
		refuse(m, device, msg, name, &req, "busy", req.reply);
		return;
	}
	if (req.rc == 0) { /* the new value is published from the next status copy */
		mqtt_audit_command(m, msg->conn, msg->topic, device, &req, "ok", NULL);
		return;
	}
	refuse(m, device, msg, name, &req,
	       req.rc > 0                    ? "refused"
	       : req.rc == -VMAC_ENOTRUNNING ? "not_running"
	                                     : "driver_failed",
	       req.reply);
}

static void connected(struct vmac_mqtt *m)
{
	char topic[512];
	mqtt_topic(m, topic, sizeof(topic), "status");
	mqtt_publish(m, topic, "online", -1, 1, 1);
	if (m->s.commands) {
		mqtt_topic(m, topic, sizeof(topic), "+/set/+");
		mqtt_subscribe(m, topic, 1);
		mqtt_topic(m, topic, sizeof(topic), "+/cmd/+");
		mqtt_subscribe(m, topic, 1);
	}
}

static void availability(struct vmac_mqtt *m, struct mqtt_device *d, const char *what)
{
	char topic[512];
	mqtt_topic(m, topic, sizeof(topic), "%s/_availability", d->name);
	mqtt_publish(m, topic, what, -1, 1, 1);
}

static void device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	(void)st;
	availability(m, d, "online");
}

static void device_down(struct vmac_mqtt *m, struct mqtt_device *d)
{
	availability(m, d, "offline");
}

static void values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                   struct mqtt_value *const *changed, int n)
{
	char topic[512];
	int i;
	(void)st;
	for (i = 0; i < n; i++) {
		mqtt_topic(m, topic, sizeof(topic), "%s/%s", d->name, changed[i]->name);
		mqtt_publish(m, topic, changed[i]->text, -1, 0, 1);
	}
}

static int message(struct vmac_mqtt *m, const struct mqtt_message *msg)
{
	char mine[512];
	size_t n;
	mqtt_topic(m, mine, sizeof(mine), "%s", "");
	n = strlen(mine);
	if (msg->conn != MQTT_CONN_MAIN || strncmp(msg->topic, mine, n) != 0)
		return 0;
	{ /* only the command topics' shape (DEVICE/set/NAME): the site view takes the others */
		const char *p = msg->topic + n, *slash = strchr(p, '/');
		if (!slash || !(slash = strchr(slash + 1, '/')) || strchr(slash + 1, '/'))
			return 0;
	}
	if (m->s.commands && !msg->retained) /* a retained command is an old one (a discovery prefix like this one) */
		command(m, msg, msg->topic + n);
	return 1;
}

static void stopping(struct vmac_mqtt *m)
{
	char topic[512];
	mqtt_topic(m, topic, sizeof(topic), "status");
	mqtt_publish(m, topic, "offline", -1, 1, 1);
}

const struct mqtt_profile mqtt_native_profile = {
    .name = "vmac",
    .conn = MQTT_CONN_MAIN,
    .connected = connected,
    .device_up = device_up,
    .device_down = device_down,
    .values = values,
    .message = message,
    .stopping = stopping,
};
