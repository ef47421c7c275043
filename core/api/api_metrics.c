/* GET /metrics (docs/API.md, "Metrics"): the host's figures in Prometheus's
 * text format (prom_text.h), made afresh at every scrape from the bus's
 * published status copy (the one GET /api/status reads, on this HTTP
 * thread; the bus thread only ever publishes it), so a board that left the
 * status has left the metrics too: nothing here remembers a series. Beside
 * the status: the event log's counts by kind, the store's size and
 * failures, the MQTT client's connections and messages, and this server's
 * own answers by status code and deploys by outcome. Also the listener
 * without a token on metrics_http (HOST.md), which serves this and nothing
 * else.
 *
 * Names and labels follow Prometheus's naming guide: the vmac_ prefix,
 * base units (seconds, bytes), _total for counters, _info for a gauge of
 * metadata; a board's series are labelled machine, board and driver, a
 * machine's (its driver's) machine and driver. A board's clock, when it
 * has sent a TIMED reply: prom_clock.c. */
#include "http_internal.h"

#include <arpa/inet.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../common/addr.h"
#include "../mqtt/mqtt.h"
#include "prom_clock.h"
#include "prom_text.h"

/* The lateness histogram's buckets, in us: each a bound of the bus's own
 * histogram (core/common/hist.h: 1 us wide to 1 ms, 100 us wide to
 * 100 ms), so each cumulative count is exact (vmac_hist_below), none
 * interpolated; chosen to keep the scrape small (the bus's has 1,991). */
static const int64_t lateness_le_us[] = {5,   10,   20,   30,   50,   75,   100,  150,   200,   300,   500,
                                         750, 1000, 1500, 2000, 3000, 5000, 7500, 10000, 20000, 50000, 100000};

/* Every state GET /api/status gives a device (vmac_devices counts each). */
static const char *const device_states[] = {"attaching", "running", "sleeping", "errant", "waiting"};

static const char *const deploy_actions[HTTP_DEPLOY_ACTIONS] = {"upload", "activate", "rollback"};
static const char *const deploy_results[HTTP_DEPLOY_RESULTS] = {"ok", "refused", "failed"};

static double now_s(clockid_t clock)
{
	struct timespec ts;
	clock_gettime(clock, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* One counter family of a single sample. */
static void counter(struct http_prom *p, const char *name, const char *help, uint64_t value)
{
	http_prom_family(p, name, "counter", help);
	http_prom_u64(p, name, value, NULL);
}

static void gauge(struct http_prom *p, const char *name, const char *help, double value)
{
	http_prom_family(p, name, "gauge", help);
	http_prom_f64(p, name, value, NULL);
}

/* "0.000005" for 5 us: a bucket's le, in seconds, without trailing zeros. */
static void le_text(int64_t us, char *out, size_t len)
{
	size_t n;
	snprintf(out, len, "%.6f", (double)us / 1e6);
	n = strlen(out);
	while (n > 1 && out[n - 1] == '0')
		out[--n] = 0;
	if (n > 1 && out[n - 1] == '.')
		out[--n] = 0;
}

static void lateness(struct http_prom *p, const struct vmac_hist *h)
{
	char le[32];
	size_t i;
	http_prom_family(p, "vmac_tick_lateness_seconds", "histogram",
	                 "How late the bus thread handled its ticks (handled minus due), since the host started");
	for (i = 0; i < sizeof(lateness_le_us) / sizeof(lateness_le_us[0]); i++) {
		le_text(lateness_le_us[i], le, sizeof(le));
		http_prom_u64(p, "vmac_tick_lateness_seconds_bucket", vmac_hist_below(h, lateness_le_us[i]), "le", le,
		              NULL);
	}
	http_prom_u64(p, "vmac_tick_lateness_seconds_bucket", h->count, "le", "+Inf", NULL);
	http_prom_f64(p, "vmac_tick_lateness_seconds_sum", (double)h->sum_us / 1e6, NULL);
	http_prom_u64(p, "vmac_tick_lateness_seconds_count", h->count, NULL);
}

/* The host's own figures: the status's counters and schedule. */
static void host_series(struct http_prom *p, const struct vmac_status *s)
{
	const struct vmac_bus_counters *c = &s->counters;
	double started = now_s(CLOCK_REALTIME) - (now_s(CLOCK_MONOTONIC) - (double)s->started_ns / 1e9);
	const struct {
		const char *name, *help;
		uint64_t value;
	} counters[] = {
	    {"vmac_ticks_total", "Ticks of the bus thread (one a slot)", c->ticks},
	    {"vmac_ticks_skipped_total", "Whole slots the bus thread was not scheduled for (served late)",
	     c->ticks_skipped},
	    {"vmac_late_replies_total", "Replies of the right sequence that came after the deadline (each a miss)",
	     c->late_replies},
	    {"vmac_drops_total", "Devices dropped (a miss, a late reply, an ERROR reply or a driver failure)",
	     c->drops},
	    {"vmac_discoveries_total", "DISCOVER frames sent", c->discoveries},
	    {"vmac_announces_total", "Announcements of boards taken", c->announces},
	    {"vmac_announces_waiting_total", "Announcements of boards without a key held back for approval",
	     c->waiting},
	    {"vmac_events_lost_total",
	     "Events lost: the ring of the bus thread or of a driver worker to the main thread was full",
	     c->events_lost},
	    {"vmac_table_full_total", "Announcements of new boards ignored: the device table was full", c->table_full},
	    {"vmac_attach_refused_total", "Announcements not let attach (attach_max or attach_rate reached)",
	     c->attach_refused},
	    {"vmac_schedule_full_total", "Devices refused by admission control (schedule full)", c->schedule_full},
	    {"vmac_auth_failed_total", "Frames that did not prove a key they had to", c->auth_failed},
	    {"vmac_takeover_refused_total", "Announcements of a known board's identity that did not prove its key",
	     c->takeover_refused},
	    {"vmac_checkpoints_total", "Machine checkpoints handed to the main thread to store", c->checkpoints},
	    {"vmac_checkpoints_deferred_total", "Checkpoints put off a tick: their ring was full",
	     c->checkpoints_deferred},
	};
	size_t i;
	int counts[sizeof(device_states) / sizeof(device_states[0])] = {0}, d;

	http_prom_family(p, "vmac_build_info", "gauge", "The vmacd build: its version");
	http_prom_u64(p, "vmac_build_info", 1, "version", VMAC_VERSION_STRING, NULL);
	gauge(p, "vmac_start_time_seconds", "When the bus started, in Unix time", s->started_ns ? started : 0);
	gauge(p, "vmac_realtime", "1 when the bus thread got real-time scheduling (SCHED_FIFO)", s->realtime ? 1 : 0);
	gauge(p, "vmac_board_keys", "Enrolled boards' keys the bus holds", s->board_keys);
	gauge(p, "vmac_slot_seconds", "One slot of the schedule", (double)s->slot_us / 1e6);
	gauge(p, "vmac_schedule_slice_slots_used", "Slice-slots per block taken by admitted devices", s->capacity_used);
	gauge(p, "vmac_schedule_slice_slots", "Slice-slots per block (slices per slot x slots per block)",
	      s->capacity_total);
	lateness(p, &s->lateness);
	for (i = 0; i < sizeof(counters) / sizeof(counters[0]); i++)
		counter(p, counters[i].name, counters[i].help, counters[i].value);
	http_prom_family(p, "vmac_misses_total", "counter",
	                 "Deadlines missed by all devices, by whose fault: the host's (its request never left) or "
	                 "the board's and the wire's");
	http_prom_u64(p, "vmac_misses_total", c->misses_host, "cause", "host", NULL);
	http_prom_u64(p, "vmac_misses_total", c->misses - c->misses_host, "cause", "board", NULL);
	http_prom_family(p, "vmac_malformed_frames_total", "counter", "Datagrams dropped as unusable, by reason");
	for (i = 0; i < VMAC_BAD_REASONS; i++)
		http_prom_u64(p, "vmac_malformed_frames_total", c->malformed_by_reason[i], "reason",
		              vmac_malformed_reason_names[i], NULL);
	for (d = 0; d < s->ndevices; d++)
		for (i = 0; i < sizeof(device_states) / sizeof(device_states[0]); i++)
			if (strcmp(s->devices[d].state, device_states[i]) == 0)
				counts[i]++;
	http_prom_family(p, "vmac_devices", "gauge", "Devices (boards) the host knows, by state");
	for (i = 0; i < sizeof(device_states) / sizeof(device_states[0]); i++)
		http_prom_u64(p, "vmac_devices", (uint64_t)counts[i], "state", device_states[i], NULL);
}

/* Every board's series, then every machine's (its primary board's, while a
 * driver runs it): each family's samples together, as the format wants. */
static void device_series(struct http_prom *p, const struct vmac_status *s)
{
	const struct vmac_device_status *d;
	int i;
#define EACH_DEVICE for (i = 0, d = s->devices; i < s->ndevices; i++, d = &s->devices[i])
#define DEVICE_LABELS "machine", d->last_machine, "board", d->name, "driver", d->driver
#define EACH_MACHINE EACH_DEVICE if (d->machine[0] && strcmp(d->machine, d->name) == 0 && d->driver_version[0])
#define MACHINE_LABELS "machine", d->machine, "driver", d->driver
	http_prom_family(p, "vmac_device_state", "gauge",
	                 "1 for each board, labelled with its state (attaching, running, sleeping, errant, waiting)");
	EACH_DEVICE http_prom_u64(p, "vmac_device_state", 1, DEVICE_LABELS, "state", d->state, NULL);
	http_prom_family(p, "vmac_device_served_total", "counter", "Replies of the board received in time");
	EACH_DEVICE http_prom_u64(p, "vmac_device_served_total", d->served, DEVICE_LABELS, NULL);
	http_prom_family(p, "vmac_device_misses_total", "counter",
	                 "Deadlines the board missed, by whose fault: the host's or the board's and the wire's");
	EACH_DEVICE
	{
		http_prom_u64(p, "vmac_device_misses_total", d->misses_host, DEVICE_LABELS, "cause", "host", NULL);
		http_prom_u64(p, "vmac_device_misses_total", d->misses - d->misses_host, DEVICE_LABELS, "cause",
		              "board", NULL);
	}
	http_prom_family(p, "vmac_device_drops_total", "counter",
	                 "Times the host dropped the board (a miss, an error, or a board of its machine dropped)");
	EACH_DEVICE http_prom_u64(p, "vmac_device_drops_total", d->drops, DEVICE_LABELS, NULL);
	http_prom_board_clocks(p, s); /* the clocks of boards that sent a TIMED reply (prom_clock.c) */
	http_prom_family(p, "vmac_driver_info", "gauge", "1 for each machine a driver runs, with the driver's version");
	EACH_MACHINE http_prom_u64(p, "vmac_driver_info", 1, MACHINE_LABELS, "version", d->driver_version, NULL);
	http_prom_family(p, "vmac_driver_memory_bytes", "gauge", "Bytes in the machine's driver's Lua heap");
	EACH_MACHINE http_prom_u64(p, "vmac_driver_memory_bytes", d->driver_memory, MACHINE_LABELS, NULL);
	http_prom_family(p, "vmac_driver_memory_limit_bytes", "gauge",
	                 "The cap of the machine's driver's Lua heap (driver_memory_kib)");
	EACH_MACHINE http_prom_u64(p, "vmac_driver_memory_limit_bytes", d->driver_memory_cap, MACHINE_LABELS, NULL);
	http_prom_family(p, "vmac_driver_instructions_total", "counter",
	                 "Lua VM instructions the machine's driver ran, as its budget counts them (in steps of 1000)");
	EACH_MACHINE http_prom_u64(p, "vmac_driver_instructions_total", d->driver_instructions, MACHINE_LABELS, NULL);
	http_prom_family(p, "vmac_driver_call_seconds_total", "counter",
	                 "Wall-clock time the machine's driver's calls took (its tick, input, attach, ...)");
	EACH_MACHINE http_prom_f64(p, "vmac_driver_call_seconds_total", (double)d->driver_call_ns / 1e9, MACHINE_LABELS,
	                           NULL);
	http_prom_family(p, "vmac_driver_call_instructions_limit", "gauge",
	                 "The instruction budget of one call of the machine's driver (driver_instructions)");
	EACH_MACHINE http_prom_u64(p, "vmac_driver_call_instructions_limit", d->driver_instruction_budget,
	                           MACHINE_LABELS, NULL);
	http_prom_family(p, "vmac_driver_late_ticks_total", "counter",
	                 "Ticks of the machine's driver whose outputs were ready only after its next service");
	EACH_MACHINE http_prom_u64(p, "vmac_driver_late_ticks_total", d->driver_late, MACHINE_LABELS, NULL);
#undef EACH_DEVICE
#undef DEVICE_LABELS
#undef EACH_MACHINE
#undef MACHINE_LABELS
}

static void event_series(struct http_prom *p, struct vmac_event_log *log)
{
	struct vmac_event_count kinds[VMAC_EVENT_KINDS];
	int i, n = vmac_event_log_counts(log, kinds);
	http_prom_family(p, "vmac_events_total", "counter",
	                 "Events the host recorded, by kind (reloaded: a machine switched to another driver version; "
	                 "rolled_back: a version failed its probation)");
	for (i = 0; i < n; i++)
		http_prom_u64(p, "vmac_events_total", kinds[i].count, "kind", kinds[i].kind, NULL);
}

static void store_series(struct http_prom *p, struct vmac_store *store)
{
	struct vmac_store_stats st;
	vmac_store_stats(store, &st);
	http_prom_family(p, "vmac_store_size_bytes", "gauge",
	                 "The store's files: the database and its write-ahead log");
	http_prom_u64(p, "vmac_store_size_bytes", st.database_bytes, "file", "database", NULL);
	http_prom_u64(p, "vmac_store_size_bytes", st.wal_bytes, "file", "wal", NULL);
	http_prom_family(p, "vmac_store_failures_total", "counter",
	                 "Calls into the store that failed: the disk was full, the file was removed or replaced "
	                 "under the host, or another error");
	http_prom_u64(p, "vmac_store_failures_total", st.failures[VMAC_STORE_FAILED_FULL], "reason", "disk_full", NULL);
	http_prom_u64(p, "vmac_store_failures_total", st.failures[VMAC_STORE_FAILED_REPLACED], "reason", "replaced",
	              NULL);
	http_prom_u64(p, "vmac_store_failures_total", st.failures[VMAC_STORE_FAILED_OTHER], "reason", "error", NULL);
}

/* The MQTT client's, while one runs (mqtt_url set); none without. */
static void mqtt_series(struct http_prom *p)
{
	static const char *const names[VMAC_MQTT_CONNECTIONS] = {"main", "sparkplug"};
	struct vmac_mqtt_stats m;
	int k;
	vmac_mqtt_stats(&m);
	if (!m.running)
		return;
#define EACH_CONNECTION                                                                                                \
	for (k = 0; k < VMAC_MQTT_CONNECTIONS; k++)                                                                    \
		if (m.conn[k].used)
	http_prom_family(p, "vmac_mqtt_connected", "gauge", "1 while the connection to the MQTT broker is up");
	EACH_CONNECTION http_prom_u64(p, "vmac_mqtt_connected", (uint64_t)m.conn[k].connected, "connection", names[k],
	                              NULL);
	http_prom_family(p, "vmac_mqtt_connects_total", "counter", "Connections the broker accepted (CONNACK)");
	EACH_CONNECTION http_prom_u64(p, "vmac_mqtt_connects_total", m.conn[k].connects, "connection", names[k], NULL);
	http_prom_family(p, "vmac_mqtt_messages_published_total", "counter", "Messages handed to the client to send");
	EACH_CONNECTION http_prom_u64(p, "vmac_mqtt_messages_published_total", m.conn[k].published, "connection",
	                              names[k], NULL);
	http_prom_family(p, "vmac_mqtt_publish_failures_total", "counter", "Messages the client refused to send");
	EACH_CONNECTION http_prom_u64(p, "vmac_mqtt_publish_failures_total", m.conn[k].publish_failed, "connection",
	                              names[k], NULL);
	http_prom_family(p, "vmac_mqtt_messages_received_total", "counter", "Messages that came from the broker");
	EACH_CONNECTION http_prom_u64(p, "vmac_mqtt_messages_received_total", m.conn[k].received, "connection",
	                              names[k], NULL);
#undef EACH_CONNECTION
	counter(p, "vmac_mqtt_messages_dropped_total",
	        "Messages received and dropped: they came faster than the host handled them", m.dropped);
}

/* This server's own: answers by status code, deploys by outcome. */
static void http_series(struct http_prom *p, struct vmac_http *h)
{
	char code[8];
	int i, j;
	http_prom_family(p, "vmac_http_requests_total", "counter",
	                 "Requests the HTTP API answered (counted when the answer ended), by status code");
	for (i = 0; i < HTTP_CODES; i++) {
		uint64_t n = atomic_load(&h->answered[i]);
		if (!n)
			continue;
		snprintf(code, sizeof(code), "%d", HTTP_CODE_FIRST + i);
		http_prom_u64(p, "vmac_http_requests_total", n, "code", code, NULL);
	}
	http_prom_family(p, "vmac_driver_deploys_total", "counter",
	                 "Driver uploads, activations and rollbacks by hand through the API, by outcome (ok; refused: "
	                 "4xx, nothing changed; failed: 5xx)");
	for (i = 0; i < HTTP_DEPLOY_ACTIONS; i++)
		for (j = 0; j < HTTP_DEPLOY_RESULTS; j++)
			http_prom_u64(p, "vmac_driver_deploys_total", atomic_load(&h->deploys[i][j]), "action",
			              deploy_actions[i], "result", deploy_results[j], NULL);
}

char *http_metrics_text(struct vmac_http *h, size_t *len)
{
	struct vmac_status *s = &h->status;
	struct http_prom p;
	pthread_mutex_lock(&h->status_lock);
	vmac_bus_status(h->bus, s);
	/* About 1 KiB a board (10 series of it and its machine), and the rest. */
	http_prom_init(&p, 32768 + (size_t)s->ndevices * 1024);
	host_series(&p, s);
	device_series(&p, s);
	pthread_mutex_unlock(&h->status_lock);
	event_series(&p, h->log);
	store_series(&p, h->store);
	mqtt_series(&p);
	http_series(&p, h);
	return http_prom_take(&p, len);
}

/* The text as the answer, or 500 when it could not be made. */
static enum MHD_Result reply_metrics(struct vmac_http *h, struct MHD_Connection *c)
{
	size_t len;
	char *text = http_metrics_text(h, &len);
	struct MHD_Response *r;
	enum MHD_Result ret;
	if (!text)
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body("out of memory"));
	r = MHD_create_response_from_buffer(len, text, MHD_RESPMEM_MUST_FREE);
	if (!r) {
		free(text);
		return MHD_NO;
	}
	MHD_add_response_header(r, "Content-Type", HTTP_PROM_CONTENT_TYPE);
	MHD_add_response_header(r, "Cache-Control", "no-store");
	ret = MHD_queue_response(c, MHD_HTTP_OK, r);
	MHD_destroy_response(r);
	return ret;
}

/* GET /metrics */
enum MHD_Result http_metrics(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	(void)k;
	return reply_metrics(h, c);
}

/* ---- metrics_http: GET /metrics without a token, on its own address ---- */

static enum MHD_Result on_metrics_request(void *cls, struct MHD_Connection *c, const char *url, const char *method,
                                          const char *version, const char *upload_data, size_t *upload_size,
                                          void **con_cls)
{
	struct vmac_http *h = cls;
	(void)version;
	(void)upload_data;
	if (!*con_cls) { /* first call: headers only */
		*con_cls = c;
		return MHD_YES;
	}
	if (*upload_size) { /* a body is not read */
		*upload_size = 0;
		return MHD_YES;
	}
	if (strcmp(method, "GET") != 0 && strcmp(method, "HEAD") != 0)
		return http_reply(c, MHD_HTTP_METHOD_NOT_ALLOWED, http_error_body("only GET /metrics is served here"));
	if (strcmp(url, "/metrics") != 0)
		return http_reply(c, MHD_HTTP_NOT_FOUND,
		                  http_error_body("only GET /metrics is served here (metrics_http; docs/API.md)"));
	return reply_metrics(h, c);
}

static void on_metrics_completed(void *cls, struct MHD_Connection *c, void **con_cls,
                                 enum MHD_RequestTerminationCode why)
{
	(void)why;
	http_count_answer(cls, c);
	*con_cls = NULL;
}

int http_metrics_listen(struct vmac_http *h, const char *listen, char *err, size_t errlen)
{
	struct sockaddr_in sin;
	uint16_t port;
	const union MHD_DaemonInfo *info;
	char text[200], addr[INET_ADDRSTRLEN];
	memset(&sin, 0, sizeof(sin));
	sin.sin_family = AF_INET;
	if (vmac_addr_parse(listen, &sin.sin_addr, &port) != 0) {
		snprintf(err, errlen, "metrics_http '%s': expected IPv4ADDR:PORT, e.g. 127.0.0.1:9108", listen);
		return -1;
	}
	sin.sin_port = htons(port);
	/* One polling thread: a scrape is answered in milliseconds and a slow
	 * client only holds its own connection; a few connections at most. */
	h->metrics_daemon = MHD_start_daemon(
	    MHD_USE_INTERNAL_POLLING_THREAD | MHD_USE_AUTO | MHD_USE_ERROR_LOG, 0, NULL, NULL, on_metrics_request, h,
	    MHD_OPTION_NOTIFY_COMPLETED, on_metrics_completed, h, MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&sin,
	    MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)HTTP_METRICS_TIMEOUT_S, MHD_OPTION_CONNECTION_LIMIT,
	    (unsigned)HTTP_METRICS_CONNECTIONS, MHD_OPTION_PER_IP_CONNECTION_LIMIT, (unsigned)HTTP_METRICS_PER_ADDRESS,
	    MHD_OPTION_END);
	if (!h->metrics_daemon) {
		snprintf(err, errlen,
		         "metrics_http: cannot listen on %s (address in use, or not an address of this machine)",
		         listen);
		return -1;
	}
	info = MHD_get_daemon_info(h->metrics_daemon, MHD_DAEMON_INFO_BIND_PORT);
	h->metrics_port = info ? info->port : (unsigned)port;
	snprintf(text, sizeof(text),
	         "metrics at http://%s:%u/metrics without a token (metrics_http): anyone who reaches that address "
	         "reads them",
	         inet_ntop(AF_INET, &sin.sin_addr, addr, sizeof(addr)) ? addr : "?", h->metrics_port);
	vmac_event_log_add(h->log, "http", "", text);
	return 0;
}
