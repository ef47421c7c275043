/* Sparkplug B's DCMD (docs/MQTT.md, "Sparkplug B"): each metric of a
 * spBv1.0/GROUP/DCMD/EDGE/DEVICE payload is operator input through the
 * bus's request slots, with the native profile's checks and refusals
 * (refusals on PREFIX/HOST/DEVICE/_error), each one in the audit trail; and
 * the unpacking of received payloads that mqtt_sparkplug.c's NCMD shares.
 * Publisher thread. */
#include "mqtt_spb.h"

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../common/errors.h"

/* A DCMD metric's value as operator input; 0, or -1 with why. */
static int metric_input(const Metric *mt, struct vmac_value *v, const char **why)
{
	memset(v, 0, sizeof(*v));
	if (mt->has_datatype && (mt->datatype == SPARKPLUG_B__DATA_TYPE__Unknown || mt->datatype > 34)) {
		*why = "unknown datatype";
		return -1;
	}
	if (mt->has_is_null && mt->is_null) {
		v->type = VMAC_VALUE_NONE;
		return 0;
	}
	switch (mt->value_case) {
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE_BOOLEAN_VALUE:
		v->type = VMAC_VALUE_BOOL;
		v->number = mt->boolean_value ? 1 : 0;
		return 0;
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE_INT_VALUE: /* Int8..Int32 travel as two's complement */
		v->type = VMAC_VALUE_NUMBER;
		v->number = mt->has_datatype && mt->datatype >= SPARKPLUG_B__DATA_TYPE__Int8 &&
		                    mt->datatype <= SPARKPLUG_B__DATA_TYPE__Int32
		                ? (double)(int32_t)mt->int_value
		                : (double)mt->int_value;
		return 0;
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE_LONG_VALUE:
		v->type = VMAC_VALUE_NUMBER;
		v->number = mt->has_datatype && mt->datatype == SPARKPLUG_B__DATA_TYPE__Int64
		                ? (double)(int64_t)mt->long_value
		                : (double)mt->long_value;
		return 0;
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE_FLOAT_VALUE:
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE_DOUBLE_VALUE:
		v->type = VMAC_VALUE_NUMBER;
		v->number = mt->value_case == SPARKPLUG_B__PAYLOAD__METRIC__VALUE_FLOAT_VALUE ? (double)mt->float_value
		                                                                              : mt->double_value;
		if (!isfinite(v->number)) {
			*why = "not a finite number";
			return -1;
		}
		return 0;
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE_STRING_VALUE:
		if (strlen(mt->string_value) > VMAC_DRIVER_STR_MAX) {
			*why = "a string value is at most 63 bytes";
			return -1;
		}
		v->type = VMAC_VALUE_STRING;
		snprintf(v->str, sizeof(v->str), "%s", mt->string_value);
		return 0;
	case SPARKPLUG_B__PAYLOAD__METRIC__VALUE__NOT_SET:
		*why = "a metric without a value (and not is_null)";
		return -1;
	default: *why = "only Boolean, integer, Float, Double and String values are taken"; return -1;
	}
}

/* A DCMD not carried out: the error answered on PREFIX/HOST/DEVICE/_error
 * (the native profile's), and in the audit trail (mqtt_audit.c), so that
 * what the broker's clients asked and were refused is on record. */
static void dcmd_refused(struct vmac_mqtt *m, const char *device, const char *topic, const char *name,
                         const struct vmac_bus_input_request *req, const char *code, const char *text)
{
	char why[VMAC_EVENT_TEXT];
	mqtt_publish_error(m, device, topic, name, code, text);
	snprintf(why, sizeof(why), "%s%s%s%s", name ? "metric " : "", name ? name : "", name ? ": " : "", text);
	mqtt_audit_command(m, MQTT_CONN_SPARKPLUG, topic, device, req, code, why);
}

/* One DCMD metric into the bus, as the native profile's set/cmd topics. */
static void dcmd_metric(struct vmac_mqtt *m, const char *device, const char *topic, const Metric *mt)
{
	struct vmac_bus_input_request req;
	const char *why, *name = mt->name;
	int command = 0;
	size_t i;
	if (!name || !name[0]) {
		dcmd_refused(m, device, topic, NULL, NULL, "malformed",
		             "a metric without a name (vmacd uses no aliases)");
		return;
	}
	if (strncmp(name, COMMANDS, strlen(COMMANDS)) == 0) {
		name += strlen(COMMANDS);
		command = 1;
	}
	for (i = 0; name[i]; i++)
		if (!islower((unsigned char)name[i]) && !isdigit((unsigned char)name[i]) && name[i] != '_')
			break;
	if (!name[0] || name[i] || i > VMAC_DRIVER_NAME_MAX || !islower((unsigned char)name[0])) {
		dcmd_refused(m, device, topic, mt->name, NULL, "refused",
		             "no such metric: expected a variable, a param or Commands/NAME of the driver");
		return;
	}
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	snprintf(req.name, sizeof(req.name), "%s", name);
	if (metric_input(mt, &req.value, &why) != 0) {
		dcmd_refused(m, device, topic, mt->name, NULL, "malformed", why);
		return;
	}
	if (command) { /* true runs it; false is no command */
		if (req.value.type != VMAC_VALUE_BOOL) {
			dcmd_refused(m, device, topic, mt->name, NULL, "malformed", "a command metric takes a Boolean");
			return;
		}
		if (req.value.number == 0)
			return;
		req.value.type = VMAC_VALUE_NONE;
		req.value.number = 0;
	} else if (req.value.type == VMAC_VALUE_NONE) {
		dcmd_refused(m, device, topic, mt->name, NULL, "malformed", "set needs a value");
		return;
	}
	if (vmac_bus_request_input(m->bus, &req, MQTT_INPUT_TIMEOUT_MS) != 0) {
		dcmd_refused(m, device, topic, mt->name, &req, "busy", req.reply);
		return;
	}
	if (req.rc != 0)
		dcmd_refused(m, device, topic, mt->name, &req,
		             req.rc > 0                    ? "refused"
		             : req.rc == -VMAC_ENOTRUNNING ? "not_running"
		                                           : "driver_failed",
		             req.reply);
	else
		mqtt_audit_command(m, MQTT_CONN_SPARKPLUG, topic, device, &req, "ok", NULL);
}

/* A received payload, or NULL with why (malformed, too long). */
Payload *mqtt_spb_unpack(const struct mqtt_message *msg, const char **why)
{
	Payload *p;
	if (msg->len < 0) {
		*why = "the payload is over 1024 bytes";
		return NULL;
	}
	if (!(p = sparkplug_b__payload__unpack(NULL, (size_t)msg->len, (const uint8_t *)msg->payload)))
		*why = "not a Sparkplug B payload (protobuf)";
	return p;
}

void mqtt_spb_dcmd(struct vmac_mqtt *m, const struct mqtt_message *msg, const char *device)
{
	const char *why;
	Payload *p;
	size_t i;
	for (i = 0; device[i]; i++)
		if (!isalnum((unsigned char)device[i]) && !strchr("._-", device[i]))
			break;
	if (!device[0] || device[i] || i > VMAC_NAME_MAX) {
		dcmd_refused(m, NULL, msg->topic, NULL, NULL, "malformed", "no such device");
		return;
	}
	if (!(p = mqtt_spb_unpack(msg, &why))) {
		dcmd_refused(m, device, msg->topic, NULL, NULL, "malformed", why);
		return;
	}
	if (p->n_metrics == 0)
		dcmd_refused(m, device, msg->topic, NULL, NULL, "malformed", "a DCMD without metrics");
	for (i = 0; i < p->n_metrics; i++)
		dcmd_metric(m, device, msg->topic, p->metrics[i]);
	sparkplug_b__payload__free_unpacked(p, NULL);
}
