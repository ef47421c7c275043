/* The plots' short history (docs/API.md "GET /api/devices/NAME/history"):
 * a thread of the HTTP side copies the status every HISTORY_PERIOD_MS and
 * keeps, per running machine, the last HISTORY_SAMPLES values of the
 * variables its manifest plots (ui.plots), so a page opened now draws the
 * last two minutes at once. The bus thread does nothing for it.
 *
 * BOUNDS
 *
 * A machine keeps at most HISTORY_SERIES plotted variables, each a ring of
 * HISTORY_SAMPLES floats, and the ring's times: sizeof(struct
 * history_machine), about 9.7 KB, allocated when the machine is first seen
 * and freed when it goes. At most max_devices machines (a machine is at
 * least one device): 1024 by default, about 10 MB at worst.
 *
 * FORGETTING
 *
 * A machine's history goes when it is not in a sample's status (it left,
 * or no driver runs it) and when its driver version changes (other
 * variables may be plotted). Which variables are plotted is read from the
 * manifest of the version it runs, once. */
#include "http_internal.h"

#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/monotime.h"
#include "../loader/loader.h"

struct history_machine {
	char name[VMAC_NAME_MAX + 1];
	char driver[VMAC_NAME_MAX + 1];
	char version[VMAC_DRIVER_VERSION_MAX + 1];
	int plots_read; /* series below are the manifest's (0: its manifest was not there yet) */
	int seen;       /* in the sample being taken */
	int nseries;
	char series[HISTORY_SERIES][VMAC_DRIVER_NAME_MAX + 1];
	unsigned next, count;                         /* the ring: the next sample's index, samples held */
	double time_s[HISTORY_SAMPLES];               /* the host's wall clock (Unix seconds) */
	float value[HISTORY_SERIES][HISTORY_SAMPLES]; /* NaN: not a number or boolean then */
};

static double wall_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* The plotted variables of m's manifest into m->series (at most
 * HISTORY_SERIES, each once, in the order of ui.plots). */
static void read_plots(struct history_machine *m)
{
	char *text = vmac_loaded_manifest(m->driver, m->version);
	json_t *manifest = text ? http_manifest_json(text) : NULL;
	json_t *groups = json_object_get(json_object_get(manifest, "ui"), "plots"), *group, *name;
	size_t i, j;
	int s;
	free(text);
	if (!manifest)
		return;
	m->plots_read = 1;
	json_array_foreach(groups, i, group) json_array_foreach(group, j, name)
	{
		const char *n = json_string_value(name);
		if (!n || strlen(n) > VMAC_DRIVER_NAME_MAX || m->nseries == HISTORY_SERIES)
			continue;
		for (s = 0; s < m->nseries && strcmp(m->series[s], n) != 0; s++)
			;
		if (s == m->nseries)
			snprintf(m->series[m->nseries++], sizeof(m->series[0]), "%s", n);
	}
	json_decref(manifest);
}

/* d's value of variable name: a number, a boolean as 0 or 1, else NaN. */
static float variable_value(const struct vmac_device_status *d, const char *name)
{
	int i;
	for (i = 0; i < d->nvars; i++)
		if (strcmp(d->vars[i].name, name) == 0) {
			const struct vmac_value *v = &d->vars[i].value;
			if (v->type == VMAC_VALUE_NUMBER)
				return (float)v->number;
			if (v->type == VMAC_VALUE_BOOL)
				return v->number != 0 ? 1.0f : 0.0f;
			break;
		}
	return NAN;
}

static struct history_machine *find(struct http_history *hist, const char *name)
{
	unsigned i;
	for (i = 0; i < hist->cap; i++)
		if (hist->machines[i] && strcmp(hist->machines[i]->name, name) == 0)
			return hist->machines[i];
	return NULL;
}

/* d's machine, new when it was not kept or ran another version; NULL when
 * out of memory or every entry is taken. */
static struct history_machine *machine_of(struct http_history *hist, const struct vmac_device_status *d)
{
	struct history_machine *m = find(hist, d->name);
	unsigned i;
	if (m && strcmp(m->driver, d->driver) == 0 && strcmp(m->version, d->driver_version) == 0)
		return m;
	if (m) { /* another version: forgotten, and made again */
		memset(m, 0, sizeof(*m));
	} else {
		for (i = 0; i < hist->cap && hist->machines[i]; i++)
			;
		if (i == hist->cap || !(m = hist->machines[i] = calloc(1, sizeof(*m))))
			return NULL;
	}
	snprintf(m->name, sizeof(m->name), "%s", d->name);
	snprintf(m->driver, sizeof(m->driver), "%s", d->driver);
	snprintf(m->version, sizeof(m->version), "%s", d->driver_version);
	return m;
}

/* One sample of s, taken at now_s (hist->lock held). */
static void sample(struct http_history *hist, const struct vmac_status *s, double now_s)
{
	unsigned i;
	int j, k;
	for (i = 0; i < hist->cap; i++)
		if (hist->machines[i])
			hist->machines[i]->seen = 0;
	for (j = 0; j < s->ndevices; j++) {
		const struct vmac_device_status *d = &s->devices[j];
		struct history_machine *m;
		if (!d->driver_version[0] || strcmp(d->machine, d->name) != 0 || strcmp(d->state, "running") != 0)
			continue; /* a machine's primary board running its driver: the one with its variables */
		if (!(m = machine_of(hist, d)))
			continue;
		m->seen = 1;
		if (!m->plots_read)
			read_plots(m);
		m->time_s[m->next] = now_s;
		for (k = 0; k < m->nseries; k++)
			m->value[k][m->next] = variable_value(d, m->series[k]);
		m->next = (m->next + 1) % HISTORY_SAMPLES;
		if (m->count < HISTORY_SAMPLES)
			m->count++;
	}
	for (i = 0; i < hist->cap; i++)
		if (hist->machines[i] && !hist->machines[i]->seen) {
			free(hist->machines[i]);
			hist->machines[i] = NULL;
		}
}

static void *sampler(void *arg)
{
	struct vmac_http *h = arg;
	struct http_history *hist = &h->history;
	struct timespec next;
	pthread_mutex_lock(&hist->lock);
	while (!hist->stop) {
		pthread_mutex_unlock(&hist->lock);
		/* The status copy the API's other readers share, and its lock. */
		pthread_mutex_lock(&h->status_lock);
		vmac_bus_status(h->bus, &h->status);
		pthread_mutex_lock(&hist->lock);
		sample(hist, &h->status, wall_s());
		pthread_mutex_unlock(&h->status_lock);
		/* A period from this sample: one held up skips, never bursts. */
		next = vmac_mono_after_ns(HISTORY_PERIOD_MS * 1000000L);
		while (!hist->stop && pthread_cond_timedwait(&hist->wake, &hist->lock, &next) != ETIMEDOUT)
			;
	}
	pthread_mutex_unlock(&hist->lock);
	return NULL;
}

int http_history_start(struct vmac_http *h)
{
	struct http_history *hist = &h->history;
	pthread_condattr_t attr;
	int rc;
	hist->cap = h->cfg.max_devices;
	hist->machines = calloc(hist->cap, sizeof(*hist->machines));
	if (!hist->machines)
		return -ENOMEM;
	pthread_mutex_init(&hist->lock, NULL);
	pthread_condattr_init(&attr);
	pthread_condattr_setclock(&attr, CLOCK_MONOTONIC);
	pthread_cond_init(&hist->wake, &attr);
	pthread_condattr_destroy(&attr);
	hist->inited = 1;
	rc = pthread_create(&hist->thread, NULL, sampler, h);
	hist->running = rc == 0;
	return -rc;
}

void http_history_stop(struct vmac_http *h)
{
	struct http_history *hist = &h->history;
	unsigned i;
	if (hist->running) {
		pthread_mutex_lock(&hist->lock);
		hist->stop = 1;
		pthread_cond_signal(&hist->wake);
		pthread_mutex_unlock(&hist->lock);
		pthread_join(hist->thread, NULL);
		hist->running = 0;
	}
	if (hist->inited) {
		pthread_cond_destroy(&hist->wake);
		pthread_mutex_destroy(&hist->lock);
		hist->inited = 0;
	}
	for (i = 0; hist->machines && i < hist->cap; i++)
		free(hist->machines[i]);
	free(hist->machines);
	hist->machines = NULL;
}

/* A number of the answer: milliseconds are enough (and keep it short). */
static json_t *rounded(double x, double scale)
{
	return isnan(x) ? json_null() : json_real(round(x * scale) / scale);
}

/* GET /api/devices/NAME/history: machine NAME's kept samples, oldest first. */
enum MHD_Result http_device_history(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct http_history *hist = &h->history;
	struct history_machine *m;
	json_t *times, *series, *body;
	unsigned i, at;
	int s;
	pthread_mutex_lock(&hist->lock);
	if (!(m = find(hist, k->route.name))) {
		pthread_mutex_unlock(&hist->lock);
		return http_reply(c, MHD_HTTP_NOT_FOUND, http_error_body("no history: no machine of that name runs"));
	}
	times = json_array();
	series = json_object();
	for (i = 0; i < m->count; i++)
		json_array_append_new(
		    times, rounded(m->time_s[(m->next + HISTORY_SAMPLES - m->count + i) % HISTORY_SAMPLES], 1e3));
	for (s = 0; s < m->nseries; s++) {
		json_t *values = json_array();
		for (i = 0; i < m->count; i++) {
			at = (m->next + HISTORY_SAMPLES - m->count + i) % HISTORY_SAMPLES;
			json_array_append_new(values, rounded((double)m->value[s][at], 1e4));
		}
		json_object_set_new(series, m->series[s], values);
	}
	body = json_pack("{s:s, s:s, s:f, s:i, s:f, s:o, s:o}", "machine", m->name, "driver_version", m->version,
	                 "period_s", HISTORY_PERIOD_MS / 1000.0, "samples_max", HISTORY_SAMPLES, "now", wall_s(), "t",
	                 times, "series", series);
	pthread_mutex_unlock(&hist->lock);
	return http_reply(c, MHD_HTTP_OK, body);
}
