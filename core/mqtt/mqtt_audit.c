/* The audit trail over MQTT (docs/MQTT.md, "Audit"). Both ways:
 *
 * - A command that came over MQTT (a native set or cmd topic, a Sparkplug
 *   DCMD metric) is a state-changing request like POST .../input, and is
 *   audited in the same format (core/host/audit.h). MQTT carries no
 *   token and no sender: WHO is this host's own connection to the broker
 *   (its client id and user), which the broker's ACL let the command
 *   through to; WHERE the broker; WHAT the topic and the input as the
 *   console writes it; RESULT ok or the code published on _error.
 *
 * - Profile "audit": every audit event of the host's log (HTTP, MQTT,
 *   vmac token) is published on PREFIX/HOST/audit, not retained, as Home
 *   Assistant's event entity reads it: {"event_type": TYPE, "seq", "time",
 *   "device", "text"} (mqtt_ha.c declares the entity). The log is read
 *   from where it was at start, after every read of the status copy while
 *   the connection is up; what the log's ring dropped meanwhile is lost to
 *   MQTT (the event log keeps it). Publisher thread. */
#include "mqtt_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../host/audit.h"

#define AUDIT_BATCH 16

/* s into out as one word: a blank, a quote, '%' and every byte that is
 * not printable ASCII as %XX, at most max bytes of out. */
static void one_word(const char *s, char *out, size_t max)
{
	size_t i, n = 0;
	for (i = 0; s[i] && n + 4 < max; i++) {
		unsigned char ch = (unsigned char)s[i];
		if (ch <= 0x20 || ch >= 0x7f || ch == '%' || ch == '"' || ch == '\\')
			n += (size_t)snprintf(out + n, max - n, "%%%02X", ch);
		else
			out[n++] = (char)ch;
	}
	out[n] = 0;
}

void mqtt_audit_command(struct vmac_mqtt *m, int conn, const char *topic, const char *device,
                        const struct vmac_bus_input_request *req, const char *code, const char *why)
{
	char who[400], where[320], what[VMAC_EVENT_TEXT], input[VMAC_EVENT_TEXT / 2], client[160], user[160];
	struct vmac_audit a;
	size_t n;
	one_word(m->conns[conn].client_id, client, sizeof(client));
	one_word(m->s.user, user, sizeof(user));
	snprintf(who, sizeof(who), "mqtt client \"%s\"%s%s%s", client, user[0] ? " user \"" : "", user,
	         user[0] ? "\"" : "");
	snprintf(where, sizeof(where), "%s://%s:%d", m->s.tls ? "mqtts" : "mqtt", m->s.host, m->s.port);
	one_word(topic, what, sizeof(what) / 2); /* a topic of any bytes, said in one word */
	n = strlen(what);
	if (req) {
		vmac_audit_input(req, input, sizeof(input));
		snprintf(what + n, sizeof(what) - n, " %s", input);
	}
	memset(&a, 0, sizeof(a));
	a.type = "input";
	a.who = who;
	a.where = where;
	a.what = what;
	a.result = code;
	a.device = device ? device : "";
	if (strcmp(code, "ok") != 0) {
		a.key = "mqtt";
		a.why = why;
	}
	vmac_audit_add(m->log, &a);
}

/* The audit events since the last look, each on PREFIX/HOST/audit. */
static void poll(struct vmac_mqtt *m)
{
	struct vmac_event ev[AUDIT_BATCH];
	char topic[300], type[16];
	uint64_t lost;
	int n, i;
	mqtt_topic(m, topic, sizeof(topic), "audit");
	do {
		n = vmac_event_log_since(m->log, m->audit_after, ev, AUDIT_BATCH, 0, &lost);
		for (i = 0; i < n; i++) {
			json_t *o;
			char *body;
			m->audit_after = ev[i].seq;
			if (strcmp(ev[i].kind, "audit") != 0 || vmac_audit_type_of(ev[i].text, type, sizeof(type)) != 0)
				continue;
			o = json_pack("{s:s, s:I, s:f, s:s, s:s}", "event_type", type, "seq", (json_int_t)ev[i].seq,
			              "time", (double)ev[i].time_ns / 1e9, "device", ev[i].device, "text", ev[i].text);
			body = o ? json_dumps(o, JSON_COMPACT) : NULL;
			if (body)
				mqtt_publish(m, topic, body, -1, 1, 0);
			free(body);
			json_decref(o);
		}
	} while (n == AUDIT_BATCH);
}

json_t *mqtt_audit_event_types(void)
{
	json_t *types = json_array();
	int i;
	for (i = 0; i < VMAC_AUDIT_TYPE_COUNT; i++)
		json_array_append_new(types, json_string(vmac_audit_types[i]));
	return types;
}

const struct mqtt_profile mqtt_audit_profile = {
    .name = "audit",
    .conn = MQTT_CONN_MAIN,
    .poll = poll,
};
