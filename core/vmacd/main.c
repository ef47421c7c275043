/* vmacd: the vmac host. The main thread parses the configuration, starts
 * the bus thread and the HTTP server, loads and unloads drivers when the bus
 * thread asks, records events, and on SIGINT/SIGTERM has every board put in
 * its safe state before exiting 0. */
#include <errno.h>
#include <ev.h>
#include <getopt.h>
#include <limits.h>
#include <malloc.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../api/http.h"
#include "../common/file.h"
#include "../common/paths.h"
#include "../config/config.h"
#include "../host/bus.h"
#include "../host/events.h"
#include "../loader/loader.h"
#include "../mqtt/mqtt.h"
#include "../mqtt/site.h"
#include "../recorder/recording.h"
#include "../reload/deploy.h"
#include "../store/store.h"

struct host {
	struct vmac_config cfg;
	struct vmac_bus *bus;
	struct vmac_http *http;
	struct vmac_mqtt_settings mqtt_settings; /* checked at start; mqtt NULL when off */
	struct vmac_mqtt *mqtt;
	struct vmac_site *site; /* the other hosts on the broker (GET /api/site); NULL when MQTT is off */
	struct vmac_store *store;
	struct vmac_event_log log;
	uint64_t stored_seq; /* events up to this one are in the store */
	int store_failing;   /* the last copy failed: said once, retried */
	struct ev_loop *loop;
	ev_async wake_w;
	ev_signal int_w, term_w;
	int stopping;
	int exit_code;
	double started;          /* Unix time this run began: older checkpoints are from before a restart */
	int checkpoints_failing; /* the last save failed: said once, retried */
	/* Versions that stalled a driver worker: not loaded again until a new
	 * version arrives (a reload gives a new version id). The newest 32. */
	struct stalled {
		char driver[VMAC_NAME_MAX + 1];
		char version[VMAC_DRIVER_VERSION_MAX + 1];
		int64_t id;
	} stalled[32];
	unsigned nstalled;
};

static void usage(FILE *f)
{
	fprintf(f,
	        "usage: vmacd [options]\n"
	        "The vmac host: finds vmac boards on the bus, runs a Lua driver for each, serves\n"
	        "GET /api/status. Runs on built-in defaults with no options at all.\n\n"
	        "  --config FILE      Lua file of settings (docs/HOST.md lists every key)\n"
	        "  --bus GROUP:PORT   UDP: discovery multicast group and port (default 239.255.86.77:5870)\n"
	        "  --bus eth:IFACE    raw Ethernet (EtherType 0x88B5) on network interface IFACE;\n"
	        "                     needs CAP_NET_RAW (root, or setcap cap_net_raw+ep vmacd)\n"
	        "  --iface ADDR       UDP: local interface address for the bus (default 127.0.0.1)\n"
	        "  --http ADDR:PORT   status/API server (default 127.0.0.1:8080; port 0 = any free)\n"
	        "  --drivers DIR      look for NAME.lua here before the shipped scripts/drivers/\n"
	        "  --scripts DIR      the shipped scripts folder (default: found beside the binary)\n"
	        "  --state DIR        persistent state: the store with the access tokens (default /var/lib/vmac)\n"
	        "  --set KEY=VALUE    any config key, e.g. --set slice_us=200 (repeatable);\n"
	        "                     driver.NAME.KEY for one driver, e.g. --set driver.washer.param.time_scale=0.01\n"
	        "  --help, --version\n\n"
	        "SIGINT or SIGTERM: every board is commanded to its safe state, then exit 0.\n");
}

static void wakeup(void *ctx)
{
	struct host *h = ctx;
	ev_async_send(h->loop, &h->wake_w);
}

struct restore {
	struct host *h;
	struct vmac_driver *drv;
	const char *device;
};

static void restore_one(void *ctx, const char *name, const struct vmac_value *v)
{
	struct restore *r = ctx;
	char why[200], text[300];
	if (vmac_driver_restore_param(r->drv, name, v, why, sizeof(why)) != 0) {
		snprintf(text, sizeof(text), "%s: persisted param not restored: %s", r->device, why);
		vmac_event_log_add(&r->h->log, "warning", r->device, text);
	}
}

/* The params persisted for the machine whose primary is device go back
 * into its freshly loaded driver (before it runs). */
static void restore_params(struct host *h, struct vmac_driver *drv, const char *device)
{
	struct restore r = {h, drv, device};
	char err[512];
	if (vmac_store_param_list(h->store, device, restore_one, &r, err, sizeof(err)) < 0)
		vmac_event_log_add(&h->log, "warning", device, err);
}

static double unix_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

/* The checkpoints the bus thread has handed over go to the store, in one
 * transaction (a batch at most the ring's size; the store keeps the newest
 * of each machine). A failure (a full disk) is said once; those checkpoints
 * are lost, newer ones follow. */
static void store_checkpoints(struct host *h)
{
	enum { BATCH = 16 };
	struct vmac_checkpoint cp[BATCH];
	struct vmac_bus_checkpoint head[BATCH]; /* names and time, copied out of the ring */
	uint8_t *data[BATCH];
	const struct vmac_bus_checkpoint *c;
	double mono_to_unix = unix_now() - (double)vmac_now_ns() / 1e9;
	char err[512], text[600];
	int n, i;
	do {
		for (n = 0; n < BATCH && (c = vmac_bus_checkpoint_peek(h->bus)) != NULL; n++) {
			/* Copied out so that the slot goes back to the bus thread at once. */
			memcpy(&head[n], c, sizeof(head[n]));
			data[n] = malloc(c->len ? c->len : 1);
			if (data[n])
				memcpy(data[n], c->data, c->len);
			vmac_bus_checkpoint_release(h->bus);
			if (!data[n]) {
				n--; /* out of memory: this one is lost, a newer one follows */
				continue;
			}
			cp[n].machine = head[n].machine;
			cp[n].driver = head[n].driver;
			cp[n].version = head[n].version;
			cp[n].time = mono_to_unix + (double)head[n].time_ns / 1e9;
			cp[n].data = data[n];
			cp[n].len = head[n].len;
		}
		if (n == 0)
			return;
		if (vmac_store_checkpoints_put(h->store, cp, n, err, sizeof(err)) != 0) {
			if (!h->checkpoints_failing) {
				snprintf(text, sizeof(text), "checkpoints are not being saved: %s", err);
				vmac_event_log_add(&h->log, "warning", "", text);
			}
			h->checkpoints_failing = 1;
		} else {
			h->checkpoints_failing = 0;
		}
		for (i = 0; i < n; i++)
			free(data[i]);
	} while (n == BATCH);
}

/* The checkpoint of machine `device`, if the store has one of this driver,
 * offered to its freshly loaded instance (for recover, after attach). */
static void offer_checkpoint(struct host *h, struct vmac_driver *drv, const char *device)
{
	struct vmac_checkpoint_info info;
	char driver[VMAC_NAME_MAX + 1], version[VMAC_DRIVER_VERSION_MAX + 1], err[512], text[700];
	uint8_t *data;
	size_t len;
	double time;
	int rc = vmac_store_checkpoint_get(h->store, device, &data, &len, driver, sizeof(driver), version,
	                                   sizeof(version), &time, err, sizeof(err));
	if (rc < 0)
		vmac_event_log_add(&h->log, "warning", device, err);
	if (rc != 1)
		return;
	if (strcmp(driver, vmac_driver_name(drv)) == 0) {
		info.time = time;
		info.age_s = unix_now() - time;
		if (info.age_s < 0)
			info.age_s = 0; /* the clock was set back */
		info.version = version;
		info.restarted = time < h->started;
		if (vmac_driver_offer_checkpoint(drv, data, len, &info, err, sizeof(err)) != 0) {
			snprintf(text, sizeof(text), "%s: checkpoint not offered: %s", device, err);
			vmac_event_log_add(&h->log, "warning", device, text);
		}
	}
	free(data);
}

/* The source of the driver version a recording ran: the store's version,
 * or the driver's file as it is now (malloc'd; NULL when neither). */
static char *recorded_source(struct host *h, const struct vmac_recorder *r, size_t *len)
{
	struct vmac_driver_version v;
	char path[VMAC_PATH_MAX + 64], err[VMAC_PATH_MAX + 128], *src = NULL;
	int code = 0;
	*len = 0;
	if (r->version_id > 0)
		return vmac_store_driver_get(h->store, r->version_id, &v, &src, len, err, sizeof(err)) == 1 ? src
		                                                                                            : NULL;
	if (vmac_driver_path(&h->cfg, r->driver, path, sizeof(path)) != 0)
		return NULL;
	return vmac_read_file(path, VMAC_DRIVER_FILE_MAX, len, err, sizeof(err), &code);
}

/* A machine's flight recorder, captured (a drop, a driver failure), goes
 * to the store as a recording file (docs/RECORDING.md); an event says
 * where to find it. */
static void store_recording(struct host *h, const struct vmac_bus_msg *m)
{
	struct vmac_recorder *r = m->rec;
	struct vmac_recording_info info;
	char err[512], text[700], *file, *src;
	size_t len, srclen;
	int64_t id;
	memset(&info, 0, sizeof(info));
	snprintf(info.machine, sizeof(info.machine), "%s", r->machine);
	snprintf(info.driver, sizeof(info.driver), "%s", r->driver);
	snprintf(info.version, sizeof(info.version), "%s", r->version);
	snprintf(info.reason, sizeof(info.reason), "%s", r->reason);
	info.time = unix_now() - (double)(vmac_now_ns() - r->when_ns) / 1e9;
	src = recorded_source(h, r, &srclen);
	file = vmac_recording_write(r, src, srclen, info.time, &len);
	free(src);
	if (m->replace) { /* the machine runs on: a new recorder takes the place of this one */
		struct vmac_host_cmd c;
		memset(&c, 0, sizeof(c));
		c.kind = VMAC_CMD_RECORDER;
		c.slot = m->slot;
		c.generation = m->generation;
		c.rec = vmac_recorder_new(h->cfg.recorder_s, r->period_s);
		if (c.rec && vmac_bus_send_cmd(h->bus, &c) != 0)
			vmac_recorder_free(c.rec);
	}
	vmac_recorder_free(r);
	if (!file) {
		vmac_event_log_add(&h->log, "warning", info.machine, "recording lost: out of memory");
		return;
	}
	if (vmac_store_recording_add(h->store, &info, file, len, (int)h->cfg.recordings_max, &id, err, sizeof(err)) !=
	    0) {
		snprintf(text, sizeof(text), "%s: recording lost: %s", info.machine, err);
		vmac_event_log_add(&h->log, "warning", info.machine, text);
	} else {
		snprintf(text, sizeof(text), "%s: recording %lld kept (%zu bytes): %s; vmac recording get %lld",
		         info.machine, (long long)id, len, info.reason, (long long)id);
		vmac_event_log_add(&h->log, "recording", info.machine, text);
	}
	free(file);
}

struct load {
	struct host *h;
	const struct vmac_bus_msg *m;
};

static int has_stalled(const struct host *h, const struct vmac_driver *drv)
{
	unsigned i;
	for (i = 0; i < h->nstalled && i < 32; i++)
		if (h->stalled[i].id == vmac_driver_tag(drv) &&
		    strcmp(h->stalled[i].driver, vmac_driver_name(drv)) == 0 &&
		    strcmp(h->stalled[i].version, vmac_driver_version(drv)) == 0)
			return 1;
	return 0;
}

/* vmac_deploy_load's result goes to the bus thread, with the machine's
 * persisted params in the driver; a version that stalled a worker is
 * refused. */
static void hand_over(void *ctx, int rc, struct vmac_driver *drv, const char *text)
{
	struct load *l = ctx;
	char why[VMAC_EVENT_TEXT];
	if (drv && has_stalled(l->h, drv)) {
		snprintf(why, sizeof(why),
		         "driver %s %s stalled a driver worker on this host; it is not loaded again until a new "
		         "version arrives (vmac reload)",
		         vmac_driver_name(drv), vmac_driver_version(drv));
		vmac_driver_free(drv);
		drv = NULL;
		rc = -EPERM;
		text = why;
	}
	if (drv) {
		restore_params(l->h, drv, l->m->device);
		offer_checkpoint(l->h, drv, l->m->device);
	}
	if (vmac_bus_loaded(l->h->bus, l->m, rc, drv, text) != 0)
		vmac_event_log_add(&l->h->log, "warning", l->m->device,
		                   "command ring full; device will retry on discovery");
}

static void load_driver(struct host *h, const struct vmac_bus_msg *m)
{
	struct load l = {h, m};
	store_checkpoints(h); /* one taken before this load is found by it */
	vmac_deploy_load(h->store, &h->cfg, m->driver, m->device, hand_over, &l);
}

/* A version on probation failed and its machines went back: the store
 * says so too, so that boards attaching later load the version before
 * (under the deploy lock: never in the middle of a deploy). */
static void roll_back_version(struct host *h, const struct vmac_bus_msg *m)
{
	char err[512];
	if (vmac_deploy_rolled_back(h->store, m->driver, m->version_id, m->text, err, sizeof(err)) < 0)
		vmac_event_log_add(&h->log, "warning", m->device, err);
}

/* The events not yet in the store go there, in one transaction. An event
 * the in-memory log has already dropped (over 100 in one go) is counted. */
static void store_events(struct host *h)
{
	struct vmac_event ev[VMAC_EVENT_LOG_SIZE];
	struct vmac_stored_event st[VMAC_EVENT_LOG_SIZE];
	char err[512], text[600];
	uint64_t lost;
	int n, i;
	for (;;) {
		n = vmac_event_log_since(&h->log, h->stored_seq, ev, VMAC_EVENT_LOG_SIZE, 0, &lost);
		if (n == 0)
			return;
		for (i = 0; i < n; i++) {
			st[i].seq = ev[i].seq;
			st[i].time = (double)ev[i].time_ns / 1e9;
			st[i].kind = ev[i].kind;
			st[i].device = ev[i].device;
			st[i].text = ev[i].text;
		}
		if (vmac_store_events_add(h->store, st, n, err, sizeof(err)) != 0) {
			if (!h->store_failing) { /* this warning is not stored either: it would fail the same way */
				h->store_failing = 1;
				snprintf(text, sizeof(text), "events are not being stored: %s", err);
				vmac_event_log_add(&h->log, "warning", "", text);
			}
			return;
		}
		h->store_failing = 0;
		h->stored_seq = ev[n - 1].seq;
		if (lost) {
			snprintf(text, sizeof(text), "%llu events came too fast to be stored",
			         (unsigned long long)lost);
			vmac_event_log_add(&h->log, "warning", "", text);
		}
	}
}

static void on_wake(struct ev_loop *loop, ev_async *w, int revents)
{
	struct host *h = w->data;
	struct vmac_bus_msg m;
	(void)revents;
	while (vmac_bus_poll_msg(h->bus, &m)) {
		switch (m.kind) {
		case VMAC_MSG_EVENT:
			vmac_event_log_add(&h->log, m.event_kind, m.device, m.text);
			if (m.code == VMAC_EVENT_ROLLED_BACK && m.version_id)
				roll_back_version(h, &m);
			if (m.code == VMAC_EVENT_STALLED) {
				struct stalled *x = &h->stalled[h->nstalled++ % 32];
				memcpy(x->driver, m.driver, sizeof(x->driver));
				memcpy(x->version, m.version, sizeof(x->version));
				x->id = m.version_id;
			}
			break;
		case VMAC_MSG_LOAD: load_driver(h, &m); break;
		case VMAC_MSG_UNLOAD:
			vmac_driver_free(m.drv);
			vmac_recorder_free(m.rec);
			free(m.buf);
			break;
		case VMAC_MSG_RECORDING: store_recording(h, &m); break;
		case VMAC_MSG_STOPPED: ev_break(loop, EVBREAK_ALL); break;
		}
	}
	vmac_bus_workers_service(h->bus);
	store_checkpoints(h);
	store_events(h);
}

static void on_signal(struct ev_loop *loop, ev_signal *w, int revents)
{
	struct host *h = w->data;
	struct vmac_host_cmd c;
	(void)loop;
	(void)revents;
	if (h->stopping) {
		fprintf(stderr, "vmacd: second signal, exiting now (boards go safe on their watchdog)\n");
		_exit(1);
	}
	h->stopping = 1;
	fprintf(stderr, "vmacd: signal %d: putting every board in its safe state\n", w->signum);
	memset(&c, 0, sizeof(c));
	c.kind = VMAC_CMD_STOP;
	while (vmac_bus_send_cmd(h->bus, &c) != 0)
		usleep(1000);
}

static int parse_args(struct host *h, int argc, char **argv)
{
	static const struct option opts[] = {{"config", required_argument, 0, 'c'},
	                                     {"bus", required_argument, 0, 'b'},
	                                     {"iface", required_argument, 0, 'i'},
	                                     {"http", required_argument, 0, 'H'},
	                                     {"drivers", required_argument, 0, 'd'},
	                                     {"scripts", required_argument, 0, 'S'},
	                                     {"state", required_argument, 0, 's'},
	                                     {"set", required_argument, 0, 'o'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {"version", no_argument, 0, 'V'},
	                                     {0, 0, 0, 0}};
	char err[VMAC_PATH_MAX + 256], root[VMAC_PATH_MAX];
	int opt, i;

	vmac_config_defaults(&h->cfg);
	vmac_root_dir(root, sizeof(root));
	snprintf(h->cfg.scripts_dir, sizeof(h->cfg.scripts_dir), "%.900s/scripts", root);
	snprintf(h->cfg.stdlib_dir, sizeof(h->cfg.stdlib_dir), "%.900s/stdlib", root);
	/* The config file first, so flags given on the command line win. */
	for (i = 1; i < argc; i++) {
		const char *file = NULL;
		if (strcmp(argv[i], "--config") == 0 && i + 1 < argc)
			file = argv[i + 1];
		else if (strncmp(argv[i], "--config=", 9) == 0)
			file = argv[i] + 9;
		if (file && vmac_config_load(&h->cfg, file, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmacd: config: %s\n", err);
			return 2;
		}
	}
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		const char *key = NULL;
		char kv[VMAC_PATH_MAX + 64], *eq;
		switch (opt) {
		case 'c': continue;
		case 'b': key = "bus"; break;
		case 'i': key = "iface"; break;
		case 'H': key = "http"; break;
		case 'd': key = "drivers_dir"; break;
		case 'S': key = "scripts_dir"; break;
		case 's': key = "state_dir"; break;
		case 'o':
			snprintf(kv, sizeof(kv), "%s", optarg);
			eq = strchr(kv, '=');
			if (!eq) {
				fprintf(stderr, "vmacd: --set wants KEY=VALUE, got '%s'\n", optarg);
				return 2;
			}
			*eq = '\0';
			if (vmac_config_set(&h->cfg, kv, eq + 1, err, sizeof(err)) != 0) {
				fprintf(stderr, "vmacd: --set: %s\n", err);
				return 2;
			}
			continue;
		case 'h': usage(stdout); return 1;
		case 'V': printf("vmacd 0.1.0\n"); return 1;
		default: usage(stderr); return 2;
		}
		if (vmac_config_set(&h->cfg, key, optarg, err, sizeof(err)) != 0) {
			fprintf(stderr, "vmacd: %s\n", err);
			return 2;
		}
	}
	if (optind < argc) {
		fprintf(stderr, "vmacd: unexpected argument '%s' (see --help)\n", argv[optind]);
		return 2;
	}
	if (vmac_config_check(&h->cfg, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmacd: %s\n", err);
		return 2;
	}
	if (vmac_mqtt_settings_parse(&h->cfg, &h->mqtt_settings, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmacd: %s\n", err);
		return 2;
	}
	return 0;
}

int main(int argc, char **argv)
{
	static struct host host;
	struct host *h = &host;
	char err[512];
	int rc = parse_args(h, argc, argv);

	if (rc)
		return rc == 1 ? 0 : rc;
	signal(SIGPIPE, SIG_IGN);
	/* A host runs for months: large buffers (recordings, status bodies,
	 * uploads) are mapped and given back whole when freed, instead of
	 * glibc's threshold growing until they fragment the heap, and the HTTP
	 * server's many short threads share a few arenas instead of each
	 * keeping its own (the soak's RSS: docs/RELIABILITY.md). */
	mallopt(M_MMAP_THRESHOLD, 64 * 1024);
	mallopt(M_ARENA_MAX, 4);
	setvbuf(stderr, NULL, _IOLBF, 0);
	vmac_event_log_init(&h->log);
	h->started = unix_now();
	h->loop = EV_DEFAULT;
	h->bus = vmac_bus_new(&h->cfg, err, sizeof(err));
	if (!h->bus) {
		fprintf(stderr, "vmacd: bus: %s\n", err);
		return 1;
	}
	if (vmac_store_open(h->cfg.state_dir, &h->store, err, sizeof(err)) != 0 ||
	    vmac_store_events_last(h->store, &h->stored_seq, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmacd: %s\n", err);
		vmac_store_close(h->store);
		vmac_bus_free(h->bus);
		return 1;
	}
	vmac_event_log_start_at(&h->log, h->stored_seq + 1); /* seq goes on across restarts */
	h->http = vmac_http_start(h->cfg.http, h->bus, &h->log, h->store, &h->cfg, err, sizeof(err));
	if (!h->http) {
		fprintf(stderr, "vmacd: http: %s\n", err);
		vmac_store_close(h->store);
		vmac_bus_free(h->bus);
		return 1;
	}
	ev_async_init(&h->wake_w, on_wake);
	h->wake_w.data = h;
	ev_async_start(h->loop, &h->wake_w);
	ev_signal_init(&h->int_w, on_signal, SIGINT);
	h->int_w.data = h;
	ev_signal_start(h->loop, &h->int_w);
	ev_signal_init(&h->term_w, on_signal, SIGTERM);
	h->term_w.data = h;
	ev_signal_start(h->loop, &h->term_w);
	vmac_bus_set_wakeup(h->bus, wakeup, h);

	/* Block the stop signals in the bus thread: libev delivers them here. */
	{
		sigset_t set, old;
		sigemptyset(&set);
		sigaddset(&set, SIGINT);
		sigaddset(&set, SIGTERM);
		pthread_sigmask(SIG_BLOCK, &set, &old);
		rc = vmac_bus_start(h->bus);
		pthread_sigmask(SIG_SETMASK, &old, NULL);
	}
	if (rc != 0) {
		fprintf(stderr, "vmacd: cannot start the bus thread: %s\n", strerror(-rc));
		return 1;
	}
	if (h->mqtt_settings.enabled) { /* its threads too leave the stop signals to the main thread */
		sigset_t set, old;
		sigemptyset(&set);
		sigaddset(&set, SIGINT);
		sigaddset(&set, SIGTERM);
		pthread_sigmask(SIG_BLOCK, &set, &old);
		h->site = vmac_site_new(h->mqtt_settings.prefix, h->mqtt_settings.host_id);
		h->mqtt = h->site
		              ? vmac_mqtt_start(&h->mqtt_settings, &h->cfg, h->bus, &h->log, h->site, err, sizeof(err))
		              : NULL;
		pthread_sigmask(SIG_SETMASK, &old, NULL);
		if (!h->site)
			snprintf(err, sizeof(err), "out of memory");
		if (!h->mqtt) {
			fprintf(stderr, "vmacd: mqtt: %s\n", err);
			return 1;
		}
		fprintf(stderr, "vmacd: mqtt to %s://%s:%d as %s, topics %s/%s/...%s\n",
		        h->mqtt_settings.tls ? "mqtts" : "mqtt", h->mqtt_settings.host, h->mqtt_settings.port,
		        h->mqtt_settings.client_id, h->mqtt_settings.prefix, h->mqtt_settings.host_id,
		        h->mqtt_settings.commands ? ", commands accepted" : ", commands off");
		vmac_http_set_site(h->http, h->site);
	}
	fprintf(stderr,
	        "vmacd: bus %s from %s, slot %u us (%u slices of %u us), %u slots per block, reply deadline %u us\n"
	        "vmacd: drivers from %s%s%s/drivers\n"
	        "vmacd: status at %s://%.*s:%u/api/status\n",
	        h->cfg.bus, vmac_bus_host_addr(h->bus), vmac_config_slot_us(&h->cfg), h->cfg.slices_per_slot,
	        h->cfg.slice_us, 1u << h->cfg.max_level, h->cfg.reply_deadline_us, h->cfg.drivers_dir,
	        h->cfg.drivers_dir[0] ? " then " : "", h->cfg.scripts_dir, vmac_http_tls(h->http) ? "https" : "http",
	        (int)(strrchr(h->cfg.http, ':') - h->cfg.http), h->cfg.http, vmac_http_port(h->http));
	ev_run(h->loop, 0);
	vmac_mqtt_stop(h->mqtt); /* devices and host offline, while the broker can still be told */
	vmac_bus_join(h->bus);
	on_wake(h->loop, &h->wake_w, 0); /* the last events */
	vmac_http_stop(h->http);
	vmac_site_free(h->site); /* after the server: a request may have been reading it */
	vmac_store_close(h->store);
	vmac_bus_free(h->bus);
	fprintf(stderr, "vmacd: stopped; every board was told to go safe\n");
	return 0;
}
