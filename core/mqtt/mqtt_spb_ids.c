/* Sparkplug ids that clash (docs/MQTT.md, "Sparkplug B"): an Edge Node
 * Descriptor (GROUP/EDGE) MUST be unique, and ids SHOULD NOT differ only in
 * case. Neither can be refused by one node, but it can see a clash and say
 * it in the host's events (kind mqtt): the NBIRTHs of its group (spBv1.0/
 * GROUP/NBIRTH/+, subscribed by mqtt_sparkplug.c) tell of another node with
 * its own descriptor (an NBIRTH it did not send) or one whose edge id is its
 * own in another case, and its own machines of names that differ only in
 * case are said when they come up. */
#include "mqtt_internal.h"

#include <stdio.h>
#include <string.h>
#include <strings.h>

/* spBv1.0/GROUP/NBIRTH/ then the edge id: the edge id, else NULL. */
static const char *nbirth_edge(const struct vmac_mqtt *m, const char *topic)
{
	char head[VMAC_MQTT_TOPIC_MAX + 32];
	size_t n = (size_t)snprintf(head, sizeof(head), "spBv1.0/%s/NBIRTH/", m->s.sparkplug_group);
	return strncmp(topic, head, n) == 0 && !strchr(topic + n, '/') ? topic + n : NULL;
}

int mqtt_spb_ids_foreign(const struct vmac_mqtt *m, const char *topic)
{
	const char *edge = nbirth_edge(m, topic);
	return edge && strcasecmp(edge, m->s.host_id) != 0;
}

void mqtt_spb_ids_nbirth_sent(struct vmac_mqtt *m, uint64_t timestamp, int bdseq)
{
	struct mqtt_spb *s = &m->spb;
	s->sent_ts[s->nsent % MQTT_SPB_SENT_BIRTHS] = timestamp;
	s->sent_bdseq[s->nsent % MQTT_SPB_SENT_BIRTHS] = bdseq;
	s->nsent++;
}

/* Whether an NBIRTH on this node's own topic is one it sent (its payload
 * timestamp and bdSeq among the last few it sent): MQTT 3.1.1 brings a
 * client's own messages back to its subscriptions. */
static int own_birth(const struct vmac_mqtt *m, uint64_t timestamp, int64_t bdseq)
{
	const struct mqtt_spb *s = &m->spb;
	unsigned i;
	for (i = 0; i < MQTT_SPB_SENT_BIRTHS && i < s->nsent; i++)
		if (timestamp == s->sent_ts[i] && bdseq == s->sent_bdseq[i])
			return 1;
	return 0;
}

const char *mqtt_spb_ids_nbirth_edge(const struct vmac_mqtt *m, const char *topic)
{
	return nbirth_edge(m, topic);
}

void mqtt_spb_ids_nbirth(struct vmac_mqtt *m, const char *edge, uint64_t timestamp, int64_t bdseq)
{
	if (strcmp(edge, m->s.host_id) != 0)
		mqtt_event(m, "",
		           "Sparkplug: another Edge Node of group %s, %s, has an id that differs from this one's (%s) "
		           "only in case: the specification says SHOULD NOT (a host application may take them for one)",
		           m->s.sparkplug_group, edge, m->s.host_id);
	else if (!own_birth(m, timestamp, bdseq))
		mqtt_event(
		    m, "",
		    "Sparkplug: another Edge Node publishes as %s/%s (an NBIRTH this host did not send): an Edge "
		    "Node Descriptor MUST be unique; give each host its own mqtt_host_id",
		    m->s.sparkplug_group, m->s.host_id);
}

void mqtt_spb_ids_device_up(struct vmac_mqtt *m, const struct mqtt_device *d)
{
	const struct mqtt_conn *c = &m->conns[MQTT_CONN_SPARKPLUG];
	int i;
	for (i = 0; i < c->ndevices; i++) {
		const struct mqtt_device *other = &c->devices[i];
		if (other != d && other->online && strcasecmp(other->name, d->name) == 0 &&
		    strcmp(other->name, d->name) != 0)
			mqtt_event(
			    m, d->name,
			    "Sparkplug: device ids %s and %s of this Edge Node differ only in case: the specification "
			    "says SHOULD NOT (a host application may take them for one); rename a board",
			    other->name, d->name);
	}
}
