/* Profile "sparkplug": Sparkplug B 3.0 (docs/MQTT.md, "Sparkplug B"). vmacd
 * is an Edge Node (spBv1.0/GROUP/NBIRTH/HOST), each machine a Device
 * (spBv1.0/GROUP/DBIRTH/HOST/DEVICE ...), on a connection of its own whose
 * will is the NDEATH (mqtt_client.c sets it, with the bdSeq counted here
 * and kept in STATE_DIR/sparkplug-bdseq). Payloads are sparkplug_b.proto
 * through protobuf-c. A DCMD is operator input through the bus's request
 * slots, with the checks and the refusals of the native profile
 * (mqtt_native.c: refusals on PREFIX/HOST/DEVICE/_error); an NCMD "Node
 * Control/Rebirth" brings the NBIRTH and every DBIRTH again. Publisher
 * thread, except where a function says otherwise. */
#include "mqtt_spb.h"

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/errors.h"
#include "../driver/hints.h"

#define DT_INT64 SPARKPLUG_B__DATA_TYPE__Int64
#define DT_DOUBLE SPARKPLUG_B__DATA_TYPE__Double
#define DT_BOOLEAN SPARKPLUG_B__DATA_TYPE__Boolean
#define DT_STRING SPARKPLUG_B__DATA_TYPE__String
#define REBIRTH "Node Control/Rebirth"
#define SPB_COMMANDS_MAX 32 /* commands of one driver in a DBIRTH */
#define SPB_METRICS (MQTT_VALUES + SPB_COMMANDS_MAX + 2)
#define SPB_NAME_MAX (sizeof(COMMANDS) + VMAC_DRIVER_NAME_MAX)

/* ms since the epoch, UTC (the specification's timestamps). */
static uint64_t now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}

/* spBv1.0/GROUP/TYPE/HOST[/DEVICE] */
static void spb_topic(const struct vmac_mqtt *m, char *out, size_t outlen, const char *type, const char *device)
{
	snprintf(out, outlen, "spBv1.0/%s/%s/%s%s%s", m->s.sparkplug_group, type, m->s.host_id, device ? "/" : "",
	         device ? device : "");
}

/* A payload being made: at most SPB_METRICS metrics, their names here. */
struct spb_out {
	Payload payload;
	Metric *list[SPB_METRICS];
	Metric metrics[SPB_METRICS];
	char names[SPB_METRICS][SPB_NAME_MAX];
	char texts[SPB_METRICS][MQTT_TEXT_MAX]; /* a value written as a String metric's text */
	uint64_t ts;
	int no_datatypes; /* DDATA: a host knows them from the birth (the specification: SHOULD NOT) */
};

static void out_init(struct spb_out *o)
{
	Payload init = SPARKPLUG_B__PAYLOAD__INIT;
	o->payload = init;
	o->payload.metrics = o->list;
	o->ts = now_ms();
}

/* A metric with name, datatype and timestamp, no value yet; NULL when full. */
static Metric *out_metric(struct spb_out *o, const char *name, unsigned datatype)
{
	Metric init = SPARKPLUG_B__PAYLOAD__METRIC__INIT, *mt;
	size_t i = o->payload.n_metrics;
	if (i == SPB_METRICS)
		return NULL;
	mt = &o->metrics[i];
	*mt = init;
	snprintf(o->names[i], sizeof(o->names[i]), "%s", name);
	mt->name = o->names[i];
	mt->has_datatype = !o->no_datatypes;
	mt->datatype = datatype;
	mt->has_timestamp = 1;
	mt->timestamp = o->ts;
	o->list[i] = mt;
	o->payload.n_metrics++;
	return mt;
}

/* v as metric mt (of o) of datatype t. A value of another type than t
 * (a driver's declaration said one kind, its value is another): a String
 * metric takes its text, a Boolean or number metric is null rather than a
 * value it does not say. The string stays v's or o's until the packing. */
static void out_value(struct spb_out *o, Metric *mt, unsigned t, const struct vmac_value *v)
{
	int fits = t == DT_STRING || (t == DT_BOOLEAN ? v->type == VMAC_VALUE_BOOL : v->type == VMAC_VALUE_NUMBER);
	if (v->type == VMAC_VALUE_NONE || (v->type == VMAC_VALUE_NUMBER && !isfinite(v->number)) || !fits) {
		mt->has_is_null = 1;
		mt->is_null = 1;
		return;
	}
	switch (t) {
	case DT_BOOLEAN:
		mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_BOOLEAN_VALUE;
		mt->boolean_value = v->number != 0;
		break;
	case DT_INT64:
		mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_LONG_VALUE;
		mt->long_value = (uint64_t)(int64_t)llround(v->number); /* two's complement, as the spec says */
		break;
	case DT_DOUBLE:
		mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_DOUBLE_VALUE;
		mt->double_value = v->number;
		break;
	default:
		mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_STRING_VALUE;
		if (v->type == VMAC_VALUE_STRING) {
			mt->string_value = (char *)(uintptr_t)v->str; /* read only: packing copies it */
		} else {
			char *text = o->texts[mt - o->metrics];
			mqtt_value_text(v, text, sizeof(o->texts[0]));
			mt->string_value = text;
		}
		break;
	}
}

/* Pack and publish (QoS 0, not retained, as the specification says for
 * everything but the NDEATH); with_seq: the node's next seq. 0, or -1. */
static int out_send(struct vmac_mqtt *m, const char *topic, struct spb_out *o, int with_seq)
{
	size_t len;
	uint8_t *buf;
	int rc;
	o->payload.has_timestamp = 1;
	o->payload.timestamp = o->ts;
	if (with_seq) {
		o->payload.has_seq = 1;
		o->payload.seq = m->spb.seq;
	}
	len = sparkplug_b__payload__get_packed_size(&o->payload);
	if (!(buf = malloc(len ? len : 1)))
		return -1;
	sparkplug_b__payload__pack(&o->payload, buf);
	rc = mqtt_conn_publish(&m->conns[MQTT_CONN_SPARKPLUG], topic, buf, (int)len, 0, 0);
	free(buf);
	if (rc == 0 && with_seq)
		m->spb.seq = (m->spb.seq + 1) % 256;
	return rc;
}

void *mqtt_spb_ndeath(unsigned bdseq, int *len)
{
	Payload p = SPARKPLUG_B__PAYLOAD__INIT;
	Metric mt = SPARKPLUG_B__PAYLOAD__METRIC__INIT, *list[1] = {&mt};
	uint8_t *buf;
	size_t n;
	p.has_timestamp = 1;
	p.timestamp = now_ms();
	p.n_metrics = 1;
	p.metrics = list;
	mt.name = (char *)(uintptr_t) "bdSeq";
	mt.has_datatype = 1;
	mt.datatype = DT_INT64; /* the normative text (its own NDEATH example says UInt64) */
	mt.has_timestamp = 1;
	mt.timestamp = p.timestamp;
	mt.value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_LONG_VALUE;
	mt.long_value = bdseq;
	n = sparkplug_b__payload__get_packed_size(&p);
	if (!(buf = malloc(n)))
		return NULL;
	sparkplug_b__payload__pack(&p, buf);
	*len = (int)n;
	return buf;
}

int mqtt_spb_bdseq_load(const char *path)
{
	FILE *f = fopen(path, "r");
	int n = 0;
	if (!f)
		return 0;
	if (fscanf(f, "%d", &n) != 1 || n < 0 || n > 255)
		n = 0;
	fclose(f);
	return n;
}

void mqtt_spb_bdseq_store(const char *path, int bdseq)
{
	char tmp[VMAC_PATH_MAX + 48];
	FILE *f;
	snprintf(tmp, sizeof(tmp), "%s.tmp", path);
	if (!(f = fopen(tmp, "w")))
		return;
	fprintf(f, "%d\n", bdseq);
	if (fclose(f) == 0)
		rename(tmp, path);
}

/* ---- datatypes from the manifest ---- */

static int whole(json_t *v)
{
	double x = json_number_value(v);
	return !v || (json_is_number(v) && floor(x) == x);
}

/* Whether values (a declaration's list) are all numbers; *whole: all whole. */
static int numeric_values(json_t *values, int *whole_out)
{
	size_t i;
	json_t *v;
	*whole_out = 1;
	if (!json_is_array(values) || json_array_size(values) == 0)
		return 0;
	json_array_foreach(values, i, v)
	{
		if (!json_is_number(v))
			return 0;
		if (!whole(v))
			*whole_out = 0;
	}
	return 1;
}

/* The Sparkplug datatype of a declared value: Int64 or Double for values
 * that are all numbers (whole or not); else by its kind as Home Assistant's
 * configs take it (vmac_hints_kind: default, values, min, max, unit, a
 * device class): String, Boolean, or for a number Int64 when it is a param
 * or a variable without a unit, declared with whole min/max/default/step,
 * no decimals (precision) and whole now, else Double (a measurement);
 * where the declaration says no kind, from its value now, and String with
 * none yet (null, and a DBIRTH again once its value says otherwise). */
static unsigned datatype_of(json_t *decl, int is_param, const struct vmac_value *now)
{
	json_t *min = json_object_get(decl, "min"), *max = json_object_get(decl, "max");
	int now_whole = !now || now->type != VMAC_VALUE_NUMBER || floor(now->number) == now->number, all_whole;
	if (numeric_values(json_object_get(decl, "values"), &all_whole))
		return all_whole && now_whole ? DT_INT64 : DT_DOUBLE;
	switch (vmac_hints_kind(decl)) {
	case 's': return DT_STRING;
	case 'b': return DT_BOOLEAN;
	case 'n':
		return (is_param || !json_object_get(decl, "unit")) && whole(json_object_get(decl, "default")) &&
		               whole(min) && whole(max) && whole(json_object_get(decl, "step")) &&
		               json_integer_value(json_object_get(decl, "precision")) == 0 && now_whole
		           ? DT_INT64
		           : DT_DOUBLE;
	default: break;
	}
	if (now && now->type == VMAC_VALUE_BOOL)
		return DT_BOOLEAN;
	if (now && now->type == VMAC_VALUE_NUMBER)
		return DT_DOUBLE;
	return DT_STRING;
}

/* The declaration of a variable or (*is_param set) a param. */
static json_t *decl_of(json_t *manifest, const char *name, int *is_param)
{
	json_t *d = json_object_get(json_object_get(manifest, "variables"), name);
	*is_param = !d;
	return d ? d : json_object_get(json_object_get(manifest, "params"), name);
}

static const struct vmac_device_status *status_of(struct vmac_mqtt *m, const char *name)
{
	int i;
	for (i = 0; i < m->status.ndevices; i++)
		if (strcmp(m->status.devices[i].name, name) == 0)
			return &m->status.devices[i];
	return NULL;
}

/* ---- births, deaths, data ---- */

/* NBIRTH on this connection done, and no CONNACK since. */
static int live(struct vmac_mqtt *m)
{
	return m->s.sparkplug && mqtt_conn_is_up(&m->conns[MQTT_CONN_SPARKPLUG]) &&
	       m->spb.born == atomic_load(&m->spb.bdseq) + 1;
}

/* DBIRTH of d: every variable and param of its manifest with its datatype
 * and its value in st (null when it has none yet), its commands as Boolean
 * metrics (with mqtt_commands), its driver; the datatypes remembered for
 * its DDATA. */
static void dbirth(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	static const struct vmac_value none;
	static const char *const tables[] = {"variables", "params"};
	struct spb_out *o = calloc(1, sizeof(*o));
	struct mqtt_spb_metric *types = calloc(MQTT_VALUES, sizeof(*types));
	char topic[300], model[VMAC_NAME_MAX + VMAC_DRIVER_VERSION_MAX + 2];
	struct vmac_value driver;
	const char *name;
	json_t *decl;
	int ntypes = 0, t;
	if (!o || !types)
		goto done;
	out_init(o);
	for (t = 0; t < 2; t++)
		json_object_foreach(json_object_get(d->manifest, tables[t]), name, decl)
		{
			const struct vmac_value *v = mqtt_status_value(st, name);
			unsigned dt = datatype_of(decl, t == 1, v);
			Metric *mt;
			if (ntypes == MQTT_VALUES || !(mt = out_metric(o, name, dt)))
				break;
			out_value(o, mt, dt, v ? v : &none);
			snprintf(types[ntypes].name, sizeof(types[ntypes].name), "%s", name);
			types[ntypes++].datatype = dt;
		}
	if (m->s.commands) {
		int n = 0;
		json_object_foreach(json_object_get(d->manifest, "commands"), name, decl)
		{
			char metric[SPB_NAME_MAX];
			Metric *mt;
			snprintf(metric, sizeof(metric), COMMANDS "%s", name);
			if (n++ == SPB_COMMANDS_MAX || !(mt = out_metric(o, metric, DT_BOOLEAN)))
				break;
			mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_BOOLEAN_VALUE;
			mt->boolean_value = 0;
		}
	}
	memset(&driver, 0, sizeof(driver));
	driver.type = VMAC_VALUE_STRING;
	snprintf(model, sizeof(model), "%s %s", d->driver, d->version);
	snprintf(driver.str, sizeof(driver.str), "%s", model);
	out_value(o, out_metric(o, "Properties/Driver", DT_STRING), DT_STRING, &driver);
	spb_topic(m, topic, sizeof(topic), "DBIRTH", d->name);
	if (out_send(m, topic, o, 1) != 0)
		goto done;
	free(d->spb_metrics);
	d->spb_metrics = types;
	d->nspb_metrics = ntypes;
	types = NULL;
	d->spb_born = 1;
done:
	free(types);
	free(o);
}

/* A DDEATH of d (born in this session), before it is born again or when
 * it stops running. */
static void ddeath(struct vmac_mqtt *m, struct mqtt_device *d)
{
	struct spb_out *o;
	char topic[300];
	if (!d->spb_born || !live(m))
		return;
	d->spb_born = 0;
	if (!(o = calloc(1, sizeof(*o))))
		return;
	out_init(o);
	spb_topic(m, topic, sizeof(topic), "DDEATH", d->name);
	out_send(m, topic, o, 1);
	free(o);
}

/* d born again in this session (a new driver version, a value whose
 * datatype its DBIRTH did not say): its DDEATH first, so that a host
 * application never sees a second birth of a device it holds as alive. */
static void reborn(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	ddeath(m, d);
	dbirth(m, d, st);
}

/* NBIRTH: seq 0, this connection's bdSeq, Node Control/Rebirth false. The
 * node is live once it is out (not before: a failed one leaves it not). */
static void nbirth(struct vmac_mqtt *m)
{
	struct spb_out *o = calloc(1, sizeof(*o));
	char topic[300];
	int bdseq = atomic_load(&m->spb.bdseq);
	Metric *mt;
	m->spb.born = 0;
	if (!o)
		return;
	out_init(o);
	mt = out_metric(o, "bdSeq", DT_INT64);
	mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_LONG_VALUE;
	mt->long_value = (uint64_t)bdseq;
	mt = out_metric(o, REBIRTH, DT_BOOLEAN);
	mt->value_case = SPARKPLUG_B__PAYLOAD__METRIC__VALUE_BOOLEAN_VALUE;
	mt->boolean_value = 0;
	m->spb.seq = 0;
	spb_topic(m, topic, sizeof(topic), "NBIRTH", NULL);
	mqtt_spb_ids_nbirth_sent(m, o->ts, bdseq); /* before it can come back */
	if (out_send(m, topic, o, 1) == 0)
		m->spb.born = bdseq + 1;
	free(o);
}

/* The NBIRTH, then a DBIRTH for every machine up on this connection: when
 * the primary host application comes online, and for a Rebirth. (After a
 * CONNACK only the NBIRTH: mqtt_devices_republish brings each machine up,
 * and its DBIRTH, right after.) */
static void births(struct vmac_mqtt *m)
{
	struct mqtt_conn *c = &m->conns[MQTT_CONN_SPARKPLUG];
	int i;
	nbirth(m);
	for (i = 0; i < c->ndevices; i++) {
		struct mqtt_device *d = &c->devices[i];
		d->spb_born = 0;
		if (d->online && d->manifest && live(m))
			dbirth(m, d, status_of(m, d->name));
	}
}

/* Subscriptions before the NBIRTH (NCMD, DCMD, the primary host's STATE);
 * the machines follow from mqtt_devices_republish, whose DBIRTHs wait for
 * the NBIRTH. */
static void connected(struct vmac_mqtt *m)
{
	struct mqtt_conn *c = &m->conns[MQTT_CONN_SPARKPLUG];
	char topic[300];
	int i;
	m->spb.born = 0;
	m->spb.host_online = 0; /* host_ts stays: an older STATE is still older */
	for (i = 0; i < c->ndevices; i++)
		c->devices[i].spb_born = 0; /* a new session */
	spb_topic(m, topic, sizeof(topic), "NCMD", NULL);
	mqtt_conn_subscribe(c, topic, 1);
	snprintf(topic, sizeof(topic), "spBv1.0/%s/NBIRTH/+", m->s.sparkplug_group); /* ids that clash */
	mqtt_conn_subscribe(c, topic, 0);
	if (m->s.commands) {
		spb_topic(m, topic, sizeof(topic), "DCMD", "+");
		mqtt_conn_subscribe(c, topic, 1);
	}
	if (m->s.sparkplug_primary_host[0]) {
		snprintf(topic, sizeof(topic), "spBv1.0/STATE/%s", m->s.sparkplug_primary_host);
		mqtt_conn_subscribe(c, topic, 1);
		return; /* births when it says online */
	}
	nbirth(m);
}

/* Its DBIRTH goes out with its values (the values hook right after); born
 * before in this session (a new driver version): its DDEATH first. A driver
 * without variables or params is born now. */
static void device_up(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st)
{
	mqtt_spb_ids_device_up(m, d);
	ddeath(m, d);
	if (live(m) && json_object_size(json_object_get(d->manifest, "variables")) == 0 &&
	    json_object_size(json_object_get(d->manifest, "params")) == 0)
		dbirth(m, d, st);
}

static void device_down(struct vmac_mqtt *m, struct mqtt_device *d)
{
	ddeath(m, d);
}

static const struct mqtt_spb_metric *born_metric(const struct mqtt_device *d, const char *name)
{
	int i;
	for (i = 0; i < d->nspb_metrics; i++)
		if (strcmp(d->spb_metrics[i].name, name) == 0)
			return &d->spb_metrics[i];
	return NULL;
}

/* DDATA with the values that changed (report by exception: mqtt_devices.c
 * passes only those, timer:N honoured). A value whose datatype is not the
 * one its DBIRTH said (a first value of an undeclared kind, a fraction in
 * an Int64) brings a new DBIRTH instead: a Sparkplug host takes a metric's
 * datatype from the birth only. */
static void values(struct vmac_mqtt *m, struct mqtt_device *d, const struct vmac_device_status *st,
                   struct mqtt_value *const *changed, int n)
{
	struct spb_out *o;
	char topic[300];
	int i;
	if (!live(m))
		return;
	if (!d->spb_born) {
		dbirth(m, d, st);
		return;
	}
	if (!(o = calloc(1, sizeof(*o))))
		return;
	out_init(o);
	o->no_datatypes = 1;
	for (i = 0; i < n; i++) {
		const struct vmac_value *v = mqtt_status_value(st, changed[i]->name);
		const struct mqtt_spb_metric *born = born_metric(d, changed[i]->name);
		unsigned dt;
		int is_param;
		json_t *decl;
		Metric *mt;
		if (!v)
			continue;
		if (!born) {
			free(o);
			reborn(m, d, st);
			return;
		}
		decl = decl_of(d->manifest, born->name, &is_param);
		dt = v->type == VMAC_VALUE_NONE ? born->datatype : datatype_of(decl, is_param, v);
		if (born->datatype == DT_DOUBLE && dt == DT_INT64)
			dt = DT_DOUBLE; /* a whole number now, a fraction before */
		if (dt != born->datatype) {
			free(o);
			reborn(m, d, st);
			return;
		}
		if ((mt = out_metric(o, born->name, dt)) != NULL)
			out_value(o, mt, dt, v);
	}
	if (o->payload.n_metrics) {
		spb_topic(m, topic, sizeof(topic), "DDATA", d->name);
		out_send(m, topic, o, 1);
	}
	free(o);
}

/* ---- commands (DCMDs: mqtt_spb_dcmd.c) ---- */

/* NCMD: Node Control/Rebirth true brings every birth again; anything else
 * is said in the host's events. */
static void ncmd(struct vmac_mqtt *m, const struct mqtt_message *msg)
{
	const char *why;
	Payload *p = mqtt_spb_unpack(msg, &why);
	int rebirth = 0;
	size_t i;
	if (!p) {
		mqtt_event(m, "", "Sparkplug: an NCMD refused: %s", why);
		return;
	}
	for (i = 0; i < p->n_metrics; i++) {
		const Metric *mt = p->metrics[i];
		if (mt->name && strcmp(mt->name, REBIRTH) == 0 &&
		    mt->value_case == SPARKPLUG_B__PAYLOAD__METRIC__VALUE_BOOLEAN_VALUE && mt->boolean_value)
			rebirth = 1;
		else
			mqtt_event(m, "", "Sparkplug: an NCMD metric refused: %s", mt->name ? mt->name : "(no name)");
	}
	sparkplug_b__payload__free_unpacked(p, NULL);
	if (rebirth && m->s.sparkplug_primary_host[0] && !m->spb.host_online)
		mqtt_event(m, "", "Sparkplug: Rebirth asked for while the primary host %s is not online: not yet",
		           m->s.sparkplug_primary_host);
	else if (rebirth && mqtt_conn_is_up(&m->conns[MQTT_CONN_SPARKPLUG])) {
		mqtt_event(m, "", "Sparkplug: Rebirth asked for: NBIRTH and every DBIRTH again");
		births(m);
	}
}

/* The NDEATH of this connection's bdSeq, published (QoS 1, not retained)
 * as the will would say it. */
static void publish_ndeath(struct vmac_mqtt *m)
{
	char topic[300];
	void *ndeath;
	int len;
	if (!(ndeath = mqtt_spb_ndeath((unsigned)atomic_load(&m->spb.bdseq), &len)))
		return;
	spb_topic(m, topic, sizeof(topic), "NDEATH", NULL);
	mqtt_conn_publish(&m->conns[MQTT_CONN_SPARKPLUG], topic, ndeath, len, 1, 0);
	free(ndeath);
}

/* spBv1.0/STATE/ID of mqtt_sparkplug_primary_host: {"online": bool,
 * "timestamp": ms}. Online: the births, if not yet. Offline (not older than
 * the online it follows): the session ends, NDEATH and a disconnect, and a
 * new connection waits for online again. A malformed one is said and
 * ignored. */
static void host_state(struct vmac_mqtt *m, const struct mqtt_message *msg)
{
	json_t *j = msg->len > 0 ? json_loadb(msg->payload, (size_t)msg->len, 0, NULL) : NULL;
	json_t *online = json_object_get(j, "online"), *ts = json_object_get(j, "timestamp");
	double x = json_number_value(ts); /* an integer, or a real that is whole (1.7e12) */
	int64_t t = json_is_integer(ts)                                         ? (int64_t)json_integer_value(ts)
	            : json_is_real(ts) && x >= 0 && x < 9.2e18 && floor(x) == x ? (int64_t)x
	                                                                        : -1;
	int is_online = json_is_true(online);
	if (!json_is_boolean(online) || t < 0) {
		mqtt_event(m, "",
		           "Sparkplug: a STATE of the primary host %s ignored: expected {\"online\": true|false, "
		           "\"timestamp\": ms}",
		           m->s.sparkplug_primary_host);
		json_decref(j);
		return;
	}
	json_decref(j);
	if (t < m->spb.host_ts)
		return; /* older than the last one: a stale retained message */
	m->spb.host_ts = t;
	m->spb.host_online = is_online;
	if (is_online && !live(m)) {
		mqtt_event(m, "", "Sparkplug: the primary host %s is online: NBIRTH and every DBIRTH",
		           m->s.sparkplug_primary_host);
		births(m);
	} else if (!is_online && live(m)) {
		mqtt_event(m, "",
		           "Sparkplug: the primary host %s is offline: NDEATH, and connecting again to wait "
		           "for it",
		           m->s.sparkplug_primary_host);
		publish_ndeath(m);
		m->spb.born = 0;
		mqtt_conn_redial(&m->conns[MQTT_CONN_SPARKPLUG]);
	} else if (!is_online) {
		mqtt_event(m, "", "Sparkplug: waiting for the primary host %s to be online before the NBIRTH",
		           m->s.sparkplug_primary_host);
	}
}

/* An NBIRTH of the group (this node's own edge id in some case: the
 * others are dropped on the network thread), for mqtt_spb_ids.c: its
 * payload timestamp and bdSeq. One that does not unpack (over 1024 bytes,
 * not protobuf) is no NBIRTH of this node's. */
static void nbirth_seen(struct vmac_mqtt *m, const struct mqtt_message *msg, const char *edge)
{
	const char *why;
	Payload *p = mqtt_spb_unpack(msg, &why);
	uint64_t ts = p && p->has_timestamp ? p->timestamp : 0;
	int64_t bdseq = -1;
	size_t i;
	for (i = 0; p && i < p->n_metrics; i++)
		if (p->metrics[i]->name && strcmp(p->metrics[i]->name, "bdSeq") == 0 &&
		    p->metrics[i]->value_case == SPARKPLUG_B__PAYLOAD__METRIC__VALUE_LONG_VALUE)
			bdseq = (int64_t)p->metrics[i]->long_value;
	if (p)
		sparkplug_b__payload__free_unpacked(p, NULL);
	mqtt_spb_ids_nbirth(m, edge, ts, bdseq);
}

static int message(struct vmac_mqtt *m, const struct mqtt_message *msg)
{
	char mine[300];
	const char *edge;
	size_t n;
	if (msg->conn != MQTT_CONN_SPARKPLUG)
		return 0;
	if (m->s.sparkplug_primary_host[0]) {
		snprintf(mine, sizeof(mine), "spBv1.0/STATE/%s", m->s.sparkplug_primary_host);
		if (strcmp(msg->topic, mine) == 0) {
			host_state(m, msg);
			return 1;
		}
	}
	spb_topic(m, mine, sizeof(mine), "NCMD", NULL);
	if (strcmp(msg->topic, mine) == 0) {
		ncmd(m, msg);
		return 1;
	}
	if ((edge = mqtt_spb_ids_nbirth_edge(m, msg->topic)) != NULL) {
		nbirth_seen(m, msg, edge);
		return 1;
	}
	spb_topic(m, mine, sizeof(mine), "DCMD", "");
	n = strlen(mine);
	if (m->s.commands && strncmp(msg->topic, mine, n) == 0)
		mqtt_spb_dcmd(m, msg, msg->topic + n);
	return 1;
}

/* An orderly stop: the DDEATHs went out (device_down); the NDEATH now, as
 * the will would say it (QoS 1, not retained). */
static void stopping(struct vmac_mqtt *m)
{
	if (m->s.sparkplug)
		publish_ndeath(m);
}

const struct mqtt_profile mqtt_sparkplug_profile = {
    .name = "sparkplug",
    .conn = MQTT_CONN_SPARKPLUG,
    .connected = connected,
    .device_up = device_up,
    .device_down = device_down,
    .values = values,
    .message = message,
    .stopping = stopping,
};
