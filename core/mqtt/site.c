/* See site.h: the site view. Topics are vmac's native ones (docs/MQTT.md,
 * "Topics"): PREFIX/HOST/status, PREFIX/HOST/DEVICE/_availability and
 * PREFIX/HOST/DEVICE/NAME (a value); the host's other per-device topics
 * (PREFIX/HOST/DEVICE/_NAME: _error ...) are no values and are ignored. Hosts, devices and values are kept in
 * arrays sorted by name, grown on demand up to the bounds of site.h. */
#include "site.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define ID_MAX 63     /* a host id (mqtt_host_id) */
#define DEVICE_MAX 31 /* VMAC_NAME_MAX */
#define NAME_MAX_ 31  /* VMAC_DRIVER_NAME_MAX */

enum { UNKNOWN = -1, OFFLINE = 0, ONLINE = 1 };

struct site_value {
	char name[NAME_MAX_ + 1];
	char text[VMAC_SITE_TEXT_MAX + 1];
};

struct site_device {
	char name[DEVICE_MAX + 1];
	int availability; /* UNKNOWN, OFFLINE, ONLINE */
	struct site_value *values;
	int nvalues, cap;
	unsigned long values_dropped;
};

struct site_host {
	char id[ID_MAX + 1];
	int status;       /* UNKNOWN, OFFLINE, ONLINE */
	double last_seen; /* unix seconds of its last message */
	struct site_device **devices;
	int ndevices, cap;
	unsigned long devices_dropped;
};

struct vmac_site {
	pthread_mutex_t lock;
	char prefix[128];
	char self[ID_MAX + 1];
	atomic_int connected;
	struct site_host *hosts[VMAC_SITE_HOSTS];
	int nhosts;
	int ndevices; /* of all hosts */
	unsigned long hosts_dropped, devices_dropped, values_dropped, malformed;
};

static double unix_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

struct vmac_site *vmac_site_new(const char *prefix, const char *self)
{
	struct vmac_site *s = calloc(1, sizeof(*s));
	if (!s)
		return NULL;
	pthread_mutex_init(&s->lock, NULL);
	snprintf(s->prefix, sizeof(s->prefix), "%s", prefix);
	snprintf(s->self, sizeof(s->self), "%s", self ? self : "");
	return s;
}

static void device_free(struct site_device *d)
{
	free(d->values);
	free(d);
}

static void host_free(struct site_host *h)
{
	int i;
	for (i = 0; i < h->ndevices; i++)
		device_free(h->devices[i]);
	free(h->devices);
	free(h);
}

void vmac_site_free(struct vmac_site *s)
{
	int i;
	if (!s)
		return;
	for (i = 0; i < s->nhosts; i++)
		host_free(s->hosts[i]);
	pthread_mutex_destroy(&s->lock);
	free(s);
}

void vmac_site_pattern(const struct vmac_site *s, int i, char *out, size_t outlen)
{
	snprintf(out, outlen, "%s/%s", s->prefix, i == 0 ? "+/status" : "+/+/+");
}

void vmac_site_set_connected(struct vmac_site *s, int connected)
{
	atomic_store(&s->connected, connected != 0);
}

/* ---- checks: what vmacd publishes, nothing else ---- */

/* [A-Za-z0-9_-]{1,ID_MAX}: mqtt_host_id. */
static int host_id_ok(const char *p, size_t n)
{
	size_t i;
	if (n == 0 || n > ID_MAX)
		return 0;
	for (i = 0; i < n; i++)
		if (!isalnum((unsigned char)p[i]) && p[i] != '_' && p[i] != '-')
			return 0;
	return 1;
}

/* [A-Za-z0-9._-]{1,DEVICE_MAX}: a device (its primary board's name). */
static int device_ok(const char *p, size_t n)
{
	size_t i;
	if (n == 0 || n > DEVICE_MAX)
		return 0;
	for (i = 0; i < n; i++)
		if (!isalnum((unsigned char)p[i]) && p[i] != '.' && p[i] != '_' && p[i] != '-')
			return 0;
	return 1;
}

/* [a-z][a-z0-9_]{0,NAME_MAX_-1}: a variable or param. */
static int name_ok(const char *p, size_t n)
{
	size_t i;
	if (n == 0 || n > NAME_MAX_ || !islower((unsigned char)p[0]))
		return 0;
	for (i = 0; i < n; i++)
		if (!islower((unsigned char)p[i]) && !isdigit((unsigned char)p[i]) && p[i] != '_')
			return 0;
	return 1;
}

/* Well-formed UTF-8 without control characters (JSON and a terminal take it). */
static int text_ok(const unsigned char *p, size_t n)
{
	size_t i = 0, k, more;
	while (i < n) {
		unsigned long cp;
		if (p[i] < 0x20 || p[i] == 0x7f)
			return 0;
		if (p[i] < 0x80) {
			i++;
			continue;
		}
		more = (p[i] & 0xE0) == 0xC0 ? 1 : (p[i] & 0xF0) == 0xE0 ? 2 : (p[i] & 0xF8) == 0xF0 ? 3 : 0;
		if (!more || i + more >= n) /* not a lead byte, or cut short */
			return 0;
		cp = p[i] & (0x3Fu >> more);
		for (k = 1; k <= more; k++) {
			if ((p[i + k] & 0xC0) != 0x80)
				return 0;
			cp = cp << 6 | (p[i + k] & 0x3F);
		}
		if ((more == 1 && cp < 0x80) || (more == 2 && cp < 0x800) ||
		    (more == 3 && (cp < 0x10000 || cp > 0x10FFFF)) || (cp >= 0xD800 && cp <= 0xDFFF))
			return 0;
		i += more + 1;
	}
	return 1;
}

/* "online" or "offline" (len bytes); an empty payload (a retained message
 * cleared) is UNKNOWN; anything else -2. */
static int state_of(const char *payload, int len)
{
	if (len == 0)
		return UNKNOWN;
	if (len == 6 && memcmp(payload, "online", 6) == 0)
		return ONLINE;
	if (len == 7 && memcmp(payload, "offline", 7) == 0)
		return OFFLINE;
	return -2;
}

/* "None": no value (the driver's nil, or a number that was not finite), as
 * vmacd publishes it and Home Assistant reads it (docs/MQTT.md, "Payloads");
 * the view holds no value for it, as for an empty payload (a retained value
 * cleared). */
static int is_none(const char *payload, int len)
{
	return len == 4 && memcmp(payload, "None", 4) == 0;
}

/* ---- the tables (lock held) ---- */

/* The host of that id, made when new (NULL: no room, counted). */
static struct site_host *host_get(struct vmac_site *s, const char *id)
{
	struct site_host *h;
	int i, lo = 0, hi = s->nhosts, victim = -1;
	while (lo < hi) {
		int mid = (lo + hi) / 2, c = strcmp(s->hosts[mid]->id, id);
		if (c == 0)
			return s->hosts[mid];
		if (c < 0)
			lo = mid + 1;
		else
			hi = mid;
	}
	if (s->nhosts == VMAC_SITE_HOSTS) { /* room from the offline host silent the longest, if any */
		for (i = 0; i < s->nhosts; i++)
			if (s->hosts[i]->status != ONLINE && strcmp(s->hosts[i]->id, s->self) != 0 &&
			    (victim < 0 || s->hosts[i]->last_seen < s->hosts[victim]->last_seen))
				victim = i;
		if (victim < 0) {
			s->hosts_dropped++;
			return NULL;
		}
		s->ndevices -= s->hosts[victim]->ndevices;
		host_free(s->hosts[victim]);
		memmove(&s->hosts[victim], &s->hosts[victim + 1],
		        (size_t)(s->nhosts - victim - 1) * sizeof(s->hosts[0]));
		s->nhosts--;
		s->hosts_dropped++;
		if (victim < lo)
			lo--;
	}
	if (!(h = calloc(1, sizeof(*h)))) {
		s->hosts_dropped++;
		return NULL;
	}
	snprintf(h->id, sizeof(h->id), "%s", id);
	h->status = UNKNOWN;
	memmove(&s->hosts[lo + 1], &s->hosts[lo], (size_t)(s->nhosts - lo) * sizeof(s->hosts[0]));
	s->hosts[lo] = h;
	s->nhosts++;
	return h;
}

/* The device of that name on h, made when new (NULL: no room, counted). */
static struct site_device *device_get(struct vmac_site *s, struct site_host *h, const char *name)
{
	struct site_device *d;
	int lo = 0, hi = h->ndevices;
	while (lo < hi) {
		int mid = (lo + hi) / 2, c = strcmp(h->devices[mid]->name, name);
		if (c == 0)
			return h->devices[mid];
		if (c < 0)
			lo = mid + 1;
		else
			hi = mid;
	}
	if (h->ndevices == VMAC_SITE_DEVICES_PER_HOST || s->ndevices >= VMAC_SITE_DEVICES) {
		h->devices_dropped++;
		s->devices_dropped++;
		return NULL;
	}
	if (h->ndevices == h->cap) {
		int cap = h->cap ? h->cap * 2 : 8;
		struct site_device **grown = realloc(h->devices, (size_t)cap * sizeof(*grown));
		if (!grown) {
			s->devices_dropped++;
			return NULL;
		}
		h->devices = grown;
		h->cap = cap;
	}
	if (!(d = calloc(1, sizeof(*d)))) {
		s->devices_dropped++;
		return NULL;
	}
	snprintf(d->name, sizeof(d->name), "%s", name);
	d->availability = UNKNOWN;
	memmove(&h->devices[lo + 1], &h->devices[lo], (size_t)(h->ndevices - lo) * sizeof(h->devices[0]));
	h->devices[lo] = d;
	h->ndevices++;
	s->ndevices++;
	return d;
}

/* The value name of d set to text (len bytes), or removed when len is 0
 * (no value: None, or the retained value cleared). */
static void value_set(struct vmac_site *s, struct site_device *d, const char *name, const char *text, int len)
{
	int lo = 0, hi = d->nvalues;
	while (lo < hi) {
		int mid = (lo + hi) / 2, c = strcmp(d->values[mid].name, name);
		if (c == 0) {
			lo = mid;
			break;
		}
		if (c < 0)
			lo = mid + 1;
		else
			hi = mid;
	}
	if (lo < d->nvalues && strcmp(d->values[lo].name, name) == 0) {
		if (len == 0) {
			memmove(&d->values[lo], &d->values[lo + 1],
			        (size_t)(d->nvalues - lo - 1) * sizeof(d->values[0]));
			d->nvalues--;
		} else {
			memcpy(d->values[lo].text, text, (size_t)len);
			d->values[lo].text[len] = 0;
		}
		return;
	}
	if (len == 0)
		return;
	if (d->nvalues == VMAC_SITE_VALUES) {
		d->values_dropped++;
		s->values_dropped++;
		return;
	}
	if (d->nvalues == d->cap) {
		int cap = d->cap ? d->cap * 2 : 8;
		struct site_value *grown = realloc(d->values, (size_t)cap * sizeof(*grown));
		if (!grown) {
			s->values_dropped++;
			return;
		}
		d->values = grown;
		d->cap = cap;
	}
	memmove(&d->values[lo + 1], &d->values[lo], (size_t)(d->nvalues - lo) * sizeof(d->values[0]));
	snprintf(d->values[lo].name, sizeof(d->values[lo].name), "%s", name);
	memcpy(d->values[lo].text, text, (size_t)len);
	d->values[lo].text[len] = 0;
	d->nvalues++;
}

/* ---- a message ---- */

/* rest (after PREFIX/) split at '/' into at most 4 levels; the number of
 * levels, or 4 for 4 and more. */
static int split(const char *rest, const char *level[4], size_t len[4])
{
	int n = 0;
	const char *p = rest;
	for (;;) {
		const char *slash = strchr(p, '/');
		if (n == 4)
			return 4;
		level[n] = p;
		len[n] = slash ? (size_t)(slash - p) : strlen(p);
		n++;
		if (!slash)
			return n;
		p = slash + 1;
	}
}

int vmac_site_feed(struct vmac_site *s, const char *topic, const void *payload, int len)
{
	const char *level[4], *text = payload ? payload : "";
	size_t levlen[4], np = strlen(s->prefix);
	char host[ID_MAX + 1], device[DEVICE_MAX + 1], name[NAME_MAX_ + 1];
	struct site_host *h;
	struct site_device *d;
	int n, state = 0, kind; /* kind: 0 status, 1 availability, 2 a value */
	if (!topic || strncmp(topic, s->prefix, np) != 0 || topic[np] != '/')
		return 0;
	n = split(topic + np + 1, level, levlen);
	if (n == 2 && levlen[1] == 6 && memcmp(level[1], "status", 6) == 0)
		kind = 0;
	else if (n == 3 && levlen[2] == 13 && memcmp(level[2], "_availability", 13) == 0)
		kind = 1;
	else if (n == 3 && levlen[2] > 0 && level[2][0] == '_')
		return 1; /* the host's own (_error, _health ...): not a value, not part of the view */
	else if (n == 3)
		kind = 2;
	else
		return 0; /* PREFIX/HOST/error, the command topics: not the view's */
	pthread_mutex_lock(&s->lock);
	if (len < 0 || !host_id_ok(level[0], levlen[0]) || (kind > 0 && !device_ok(level[1], levlen[1])) ||
	    (kind == 2 && !name_ok(level[2], levlen[2])) || (kind < 2 && (state = state_of(text, len)) == -2) ||
	    (kind == 2 && (len > VMAC_SITE_TEXT_MAX || !text_ok((const unsigned char *)text, (size_t)len)))) {
		s->malformed++;
		pthread_mutex_unlock(&s->lock);
		return 1;
	}
	memcpy(host, level[0], levlen[0]);
	host[levlen[0]] = 0;
	if ((h = host_get(s, host)) != NULL) {
		h->last_seen = unix_now();
		if (kind == 0) {
			h->status = state;
		} else {
			memcpy(device, level[1], levlen[1]);
			device[levlen[1]] = 0;
			if ((d = device_get(s, h, device)) != NULL) {
				if (kind == 1) {
					d->availability = state;
				} else {
					memcpy(name, level[2], levlen[2]);
					name[levlen[2]] = 0;
					value_set(s, d, name, text, is_none(text, len) ? 0 : len);
				}
			}
		}
	}
	pthread_mutex_unlock(&s->lock);
	return 1;
}

/* ---- the JSON ---- */

static const char *state_name(int state)
{
	return state == ONLINE ? "online" : state == OFFLINE ? "offline" : "unknown";
}

/* A value's text as JSON: true/false, a number, "null" (a number that was
 * not finite, as vmacd published it before "None"), else a string
 * (docs/MQTT.md, "Payloads"). */
static json_t *value_json(const char *text)
{
	char *end;
	double x;
	if (strcmp(text, "true") == 0)
		return json_true();
	if (strcmp(text, "false") == 0)
		return json_false();
	if (strcmp(text, "null") == 0)
		return json_null();
	errno = 0;
	x = strtod(text, &end);
	if (!*end && errno == 0 && isfinite(x) && !isspace((unsigned char)text[0]) &&
	    !isalpha((unsigned char)text[0]) && !strpbrk(text, "xX")) /* vmacd writes numbers with %.15g: no hex */
		return fabs(x) < 9e15 && x == (double)(json_int_t)x ? json_integer((json_int_t)x) : json_real(x);
	return json_string(text);
}

static json_t *device_json(const struct site_host *h, const struct site_device *d)
{
	json_t *values = json_object(), *o;
	int i;
	/* A device's availability means something only while its host is up (docs/MQTT.md, "Topics"). */
	int state = h->status == OFFLINE || d->availability == OFFLINE ? OFFLINE
	            : h->status == ONLINE && d->availability == ONLINE ? ONLINE
	                                                               : UNKNOWN;
	for (i = 0; i < d->nvalues; i++)
		json_object_set_new(values, d->values[i].name, value_json(d->values[i].text));
	o = json_pack("{s:s, s:s, s:s, s:o, s:I}", "device", d->name, "state", state_name(state), "availability",
	              state_name(d->availability), "values", values, "values_dropped", (json_int_t)d->values_dropped);
	return o;
}

json_t *vmac_site_json(struct vmac_site *s)
{
	json_t *hosts = json_array(), *root;
	int i, k;
	pthread_mutex_lock(&s->lock);
	for (i = 0; i < s->nhosts; i++) {
		const struct site_host *h = s->hosts[i];
		json_t *devices = json_array();
		for (k = 0; k < h->ndevices; k++)
			json_array_append_new(devices, device_json(h, h->devices[k]));
		json_array_append_new(hosts, json_pack("{s:s, s:b, s:s, s:f, s:o, s:I}", "host", h->id, "self",
		                                       strcmp(h->id, s->self) == 0, "state", state_name(h->status),
		                                       "last_seen", h->last_seen, "devices", devices, "devices_dropped",
		                                       (json_int_t)h->devices_dropped));
	}
	root = json_pack("{s:b, s:b, s:s, s:o, s:o, s:{s:I, s:I, s:I}, s:I}", "enabled", 1, "connected",
	                 atomic_load(&s->connected), "prefix", s->prefix, "self",
	                 s->self[0] ? json_string(s->self) : json_null(), "hosts", hosts, "dropped", "hosts",
	                 (json_int_t)s->hosts_dropped, "devices", (json_int_t)s->devices_dropped, "values",
	                 (json_int_t)s->values_dropped, "malformed", (json_int_t)s->malformed);
	pthread_mutex_unlock(&s->lock);
	return root;
}
