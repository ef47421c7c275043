/* GET /api/schedule: the 2^n schedule as seed 002's static time manager's
 * table (docs/SCHEDULER.md, "The static time manager"): per slot of the
 * longest period in use that serves a device, its devices, the instants
 * their inputs are latched and their outputs released, and whether their
 * driver runs on that reply. Made from a status copy, never from the bus. */
#include "http_internal.h"

#include <jansson.h>
#include <microhttpd.h>
#include <stdlib.h>
#include <string.h>

/* The slot a machine's instants count from (docs/TIME.md, "The
 * patterns"): the latest of its boards' slots in the period. */
static unsigned anchor_of(const struct vmac_status *s, const struct vmac_device_status *d)
{
	unsigned anchor = d->slot;
	int j;
	for (j = 0; j < s->ndevices && d->machine[0]; j++) {
		const struct vmac_device_status *o = &s->devices[j];
		if (o->scheduled && o->level == d->level && o->slot > anchor && strcmp(o->machine, d->machine) == 0)
			anchor = o->slot;
	}
	return anchor;
}

/* The seed's deadline violation vector for one service: each kind of
 * deadline it has missed (as the status counts them), and the last. */
static json_t *violations_json(const struct vmac_status *s, const struct vmac_device_status *d)
{
	json_t *last = json_null();
	if (d->violation)
		last = json_pack("{s:s, s:f}", "kind", vmac_violation_name(d->violation), "ago_s",
		                 (double)(s->time_ns - d->violation_ns) / 1e9);
	return json_pack("{s:I, s:I, s:I, s:o}", "misses", (json_int_t)(d->misses - d->misses_host), "misses_host",
	                 (json_int_t)d->misses_host, "driver_late", (json_int_t)d->driver_late, "last", last);
}

static json_t *entry_json(const struct vmac_status *s, const struct vmac_device_status *d, unsigned row,
                          unsigned anchor)
{
	json_int_t base = (json_int_t)(row - d->slot + anchor) * s->slot_us;
	int timed = d->timing.timed;
	return json_pack("{s:s, s:s?, s:i, s:i, s:s, s:o, s:o, s:b, s:o}", "name", d->name, "machine",
	                 d->machine[0] ? d->machine : NULL, "slice", (int)d->slice, "level", (int)d->level, "pattern",
	                 vmac_timing_name(d->timing.pattern), "latch_us",
	                 timed ? json_integer(base + d->timing.in_us) : json_null(), "release_us",
	                 timed ? json_integer(base + d->timing.out_us) : json_null(), "driver",
	                 d->machine[0] && strcmp(d->machine, d->name) == 0, "violations", violations_json(s, d));
}

static int by_latest(const void *a, const void *b)
{
	const struct vmac_device_status *x = *(const struct vmac_device_status *const *)a;
	const struct vmac_device_status *y = *(const struct vmac_device_status *const *)b;
	return (x->violation_ns < y->violation_ns) - (x->violation_ns > y->violation_ns);
}

/* Every scheduled device that has violated a deadline, the latest first:
 * the vector as one list. */
static json_t *violated_json(const struct vmac_status *s)
{
	const struct vmac_device_status **v = calloc((size_t)s->ndevices + 1, sizeof(*v));
	json_t *out = json_array();
	int i, n = 0;
	if (!v)
		return out;
	for (i = 0; i < s->ndevices; i++)
		if (s->devices[i].scheduled && s->devices[i].violation)
			v[n++] = &s->devices[i];
	qsort(v, (size_t)n, sizeof(*v), by_latest);
	for (i = 0; i < n; i++)
		json_array_append_new(out, json_pack("{s:s, s:i, s:s, s:f}", "name", v[i]->name, "slot",
		                                     (int)v[i]->slot, "kind", vmac_violation_name(v[i]->violation),
		                                     "ago_s", (double)(s->time_ns - v[i]->violation_ns) / 1e9));
	free(v);
	return out;
}

static json_t *schedule_json(const struct vmac_status *s)
{
	unsigned *anchor = calloc((size_t)s->ndevices + 1, sizeof(*anchor));
	unsigned top = 0, rows, r;
	json_t *timeline = json_array();
	int i;
	if (!anchor) {
		json_decref(timeline);
		return NULL;
	}
	for (i = 0; i < s->ndevices; i++) {
		anchor[i] = s->devices[i].scheduled ? anchor_of(s, &s->devices[i]) : 0;
		if (s->devices[i].scheduled && s->devices[i].level > top)
			top = s->devices[i].level;
	}
	rows = 1u << top;
	if (rows > s->slots_per_block)
		rows = s->slots_per_block;
	for (r = 0; r < rows; r++) {
		json_t *devs = NULL;
		for (i = 0; i < s->ndevices; i++) {
			const struct vmac_device_status *d = &s->devices[i];
			if (!d->scheduled || r % (1u << d->level) != d->slot)
				continue;
			if (!devs)
				devs = json_array();
			json_array_append_new(devs, entry_json(s, d, r, anchor[i]));
		}
		if (devs)
			json_array_append_new(timeline, json_pack("{s:i, s:I, s:o}", "slot", (int)r, "offset_us",
			                                          (json_int_t)r * s->slot_us, "devices", devs));
	}
	free(anchor);
	return json_pack("{s:i, s:i, s:o, s:o}", "slot_us", (int)s->slot_us, "slots", (int)rows, "timeline", timeline,
	                 "violated", violated_json(s));
}

/* GET /api/schedule */
enum MHD_Result http_schedule(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	json_t *body;
	(void)k;
	pthread_mutex_lock(&h->status_lock);
	vmac_bus_status(h->bus, &h->status);
	body = schedule_json(&h->status);
	pthread_mutex_unlock(&h->status_lock);
	return http_reply(c, MHD_HTTP_OK, body);
}
