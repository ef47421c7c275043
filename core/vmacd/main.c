/* vmacd: the vmac host. The main thread parses the configuration, starts
 * the bus thread, the HTTP server and MQTT, runs the main loop
 * (core/mainloop/: drivers loaded and unloaded when the bus thread asks,
 * events and checkpoints stored) on each wake-up, tells systemd it is ready
 * and alive (service.c), and on SIGINT/SIGTERM has every board put in its
 * safe state before exiting 0. */
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
#include "../common/version.h"
#include "../config/config.h"
#include "../host/bus.h"
#include "../host/events.h"
#include "../mainloop/mainloop.h"
#include "../mqtt/mqtt.h"
#include "../mqtt/site.h"
#include "../store/store.h"
#include "service.h"

struct host {
	struct vmac_config cfg;
	struct vmac_bus *bus;
	struct vmac_http *http;
	struct vmac_mqtt_settings mqtt_settings; /* checked at start; mqtt NULL when off */
	struct vmac_mqtt *mqtt;
	struct vmac_site *site; /* the other hosts on the broker (GET /api/site); NULL when MQTT is off */
	struct vmac_store *store;
	struct vmac_event_log log;
	struct vmac_mainloop *main; /* the bus's messages answered, the store kept (core/mainloop/) */
	struct ev_loop *loop;
	ev_async wake_w;
	ev_timer every_w; /* the main loop's own looks (the store's board keys) when nothing wakes it */
	ev_signal int_w, term_w;
	struct vmacd_notify notify; /* systemd: READY=1, WATCHDOG=1 (service.h) */
	int stopping;
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
	        "  --drivers DIR      look for NAME.lua, and its programmes in cycles/NAME/, here before the\n"
	        "                     shipped scripts/\n"
	        "  --scripts DIR      the shipped scripts folder (default: found beside the binary)\n"
	        "  --state DIR        persistent state: the store with the access tokens (default /var/lib/vmac)\n"
	        "  --set KEY=VALUE    any config key, e.g. --set slice_us=200 (repeatable);\n"
	        "                     driver.NAME.KEY for one driver, e.g. --set driver.washer.param.time_scale=0.01\n"
	        "  --help, --version\n\n"
	        "SIGINT or SIGTERM: every board is commanded to its safe state, then exit 0.");
}

static void wakeup(void *ctx)
{
	struct host *h = ctx;
	ev_async_send(h->loop, &h->wake_w);
}

static int64_t wall_ns(void *ctx)
{
	struct timespec ts;
	(void)ctx;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int64_t bus_ns(void *ctx)
{
	(void)ctx;
	return vmac_now_ns();
}

static void stopped(void *ctx)
{
	struct host *h = ctx;
	ev_break(h->loop, EVBREAK_ALL);
}

/* A service that left messages comes again once the loop has seen to
 * whatever else waits (a stop signal among them). */
static void service(struct host *h)
{
	if (vmac_mainloop_service(h->main))
		ev_async_send(h->loop, &h->wake_w);
}

static void on_wake(struct ev_loop *loop, ev_async *w, int revents)
{
	(void)loop;
	(void)revents;
	service(w->data);
}

static void on_timer(struct ev_loop *loop, ev_timer *w, int revents)
{
	(void)loop;
	(void)revents;
	service(w->data);
}

static void on_signal(struct ev_loop *loop, ev_signal *w, int revents)
{
	struct host *h = w->data;
	struct vmac_host_cmd c;
	(void)loop;
	(void)revents;
	if (h->stopping) {
		vmacd_log(LOG_ERR, "second signal, exiting now (boards go safe on their watchdog)");
		_exit(1);
	}
	h->stopping = 1;
	vmacd_notify_stopping();
	vmacd_log(LOG_NOTICE, "signal %d: putting every board in its safe state", w->signum);
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
	char err[VMAC_PATH_MAX + 256];
	int opt, i;

	vmac_config_defaults(&h->cfg);
	vmac_config_shipped_dirs(&h->cfg);
	/* The config file first, so flags given on the command line win. */
	for (i = 1; i < argc; i++) {
		const char *file = NULL;
		if (strcmp(argv[i], "--config") == 0 && i + 1 < argc)
			file = argv[i + 1];
		else if (strncmp(argv[i], "--config=", 9) == 0)
			file = argv[i] + 9;
		if (file && vmac_config_load(&h->cfg, file, err, sizeof(err)) != 0) {
			vmacd_log(LOG_ERR, "config: %s", err);
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
				vmacd_log(LOG_ERR, "--set wants KEY=VALUE, got '%s'", optarg);
				return 2;
			}
			*eq = '\0';
			if (vmac_config_set(&h->cfg, kv, eq + 1, err, sizeof(err)) != 0) {
				vmacd_log(LOG_ERR, "--set: %s", err);
				return 2;
			}
			continue;
		case 'h': usage(stdout); return 1;
		case 'V': printf("vmacd %s", VMAC_VERSION_STRING); return 1;
		default: usage(stderr); return 2;
		}
		if (vmac_config_set(&h->cfg, key, optarg, err, sizeof(err)) != 0) {
			vmacd_log(LOG_ERR, "%s", err);
			return 2;
		}
	}
	if (optind < argc) {
		vmacd_log(LOG_ERR, "unexpected argument '%s' (see --help)", argv[optind]);
		return 2;
	}
	if (vmac_config_check(&h->cfg, err, sizeof(err)) != 0) {
		vmacd_log(LOG_ERR, "%s", err);
		return 2;
	}
	if (vmac_mqtt_settings_parse(&h->cfg, &h->mqtt_settings, err, sizeof(err)) != 0) {
		vmacd_log(LOG_ERR, "%s", err);
		return 2;
	}
	return 0;
}

/* The bus, the store, the main loop and the HTTP server: 0, or 1 said. */
static int open_parts(struct host *h)
{
	const struct vmac_mainloop_hooks hooks = {.ctx = h, .wall_ns = wall_ns, .bus_ns = bus_ns, .stopped = stopped};
	char err[512];
	h->bus = vmac_bus_new(&h->cfg, err, sizeof(err));
	if (!h->bus) {
		vmacd_log(LOG_ERR, "bus: %s", err);
		return 1;
	}
	if (vmac_store_open(h->cfg.state_dir, &h->store, err, sizeof(err)) != 0 ||
	    !(h->main = vmac_mainloop_new(&h->cfg, h->bus, h->store, &h->log, &hooks, err, sizeof(err)))) {
		vmacd_log(LOG_ERR, "%s", err);
		vmac_store_close(h->store);
		vmac_bus_free(h->bus);
		return 1;
	}
	h->http = vmac_http_start(h->cfg.http, h->bus, &h->log, h->store, &h->cfg, err, sizeof(err));
	if (!h->http) {
		vmacd_log(LOG_ERR, "http: %s", err);
		vmac_store_close(h->store);
		vmac_bus_free(h->bus);
		return 1;
	}
	return 0;
}

/* The main loop's watchers: the bus's wake-ups, its own timer, the stop signals. */
static void watch(struct host *h)
{
	ev_async_init(&h->wake_w, on_wake);
	h->wake_w.data = h;
	ev_async_start(h->loop, &h->wake_w);
	ev_timer_init(&h->every_w, on_timer, 0.05, 0.05);
	h->every_w.data = h;
	ev_timer_start(h->loop, &h->every_w);
	ev_signal_init(&h->int_w, on_signal, SIGINT);
	h->int_w.data = h;
	ev_signal_start(h->loop, &h->int_w);
	ev_signal_init(&h->term_w, on_signal, SIGTERM);
	h->term_w.data = h;
	ev_signal_start(h->loop, &h->term_w);
	vmac_bus_set_wakeup(h->bus, wakeup, h);
}

/* Block (or, with old, restore) the stop signals around starting threads:
 * libev delivers them to the main thread. */
static void block_stop_signals(sigset_t *old)
{
	sigset_t set;
	sigemptyset(&set);
	sigaddset(&set, SIGINT);
	sigaddset(&set, SIGTERM);
	pthread_sigmask(SIG_BLOCK, &set, old);
}

/* The bus thread, then MQTT's when it is on: 0, or 1 said. */
static int start_threads(struct host *h)
{
	char err[512];
	sigset_t old;
	int rc;
	block_stop_signals(&old);
	rc = vmac_bus_start(h->bus);
	pthread_sigmask(SIG_SETMASK, &old, NULL);
	if (rc != 0) {
		vmacd_log(LOG_ERR, "cannot start the bus thread: %s", vmac_strerror(rc));
		return 1;
	}
	if (!h->mqtt_settings.enabled)
		return 0;
	block_stop_signals(&old);
	h->site = vmac_site_new(h->mqtt_settings.prefix, h->mqtt_settings.host_id);
	h->mqtt =
	    h->site ? vmac_mqtt_start(&h->mqtt_settings, &h->cfg, h->bus, &h->log, h->site, err, sizeof(err)) : NULL;
	pthread_sigmask(SIG_SETMASK, &old, NULL);
	if (!h->site)
		snprintf(err, sizeof(err), "out of memory");
	if (!h->mqtt) {
		vmacd_log(LOG_ERR, "mqtt: %s", err);
		return 1;
	}
	vmacd_log(LOG_NOTICE, "mqtt to %s://%s:%d as %s, topics %s/%s/...%s", h->mqtt_settings.tls ? "mqtts" : "mqtt",
	          h->mqtt_settings.host, h->mqtt_settings.port, h->mqtt_settings.client_id, h->mqtt_settings.prefix,
	          h->mqtt_settings.host_id, h->mqtt_settings.commands ? ", commands accepted" : ", commands off");
	vmac_http_set_site(h->http, h->site);
	return 0;
}

/* Where everything is, in the log; systemd is told once the bus ticks. */
static void announce(struct host *h)
{
	char status[256];
	int hostlen = (int)(strrchr(h->cfg.http, ':') - h->cfg.http);
	const char *scheme = vmac_http_tls(h->http) ? "https" : "http";
	vmacd_log(LOG_NOTICE,
	          "bus %s from %s, slot %u us (%u slices of %u us), %u slots per block, reply deadline %u us",
	          h->cfg.bus, vmac_bus_host_addr(h->bus), vmac_config_slot_us(&h->cfg), h->cfg.slices_per_slot,
	          h->cfg.slice_us, 1u << h->cfg.max_level, h->cfg.reply_deadline_us);
	vmacd_log(LOG_NOTICE, "drivers from %s%s%s/drivers", h->cfg.drivers_dir, h->cfg.drivers_dir[0] ? " then " : "",
	          h->cfg.scripts_dir);
	vmacd_log(LOG_NOTICE, "status at %s://%.*s:%u/api/status", scheme, hostlen, h->cfg.http,
	          vmac_http_port(h->http));
	snprintf(status, sizeof(status), "bus %s, API at %s://%.*s:%u", h->cfg.bus, scheme, hostlen, h->cfg.http,
	         vmac_http_port(h->http));
	vmacd_notify_start(&h->notify, h->loop, h->bus, status);
}

/* After the loop: MQTT said offline, the bus's last events kept, all freed. */
static void shut_down(struct host *h)
{
	vmac_mqtt_stop(h->mqtt); /* devices and host offline, while the broker can still be told */
	vmac_bus_join(h->bus);
	while (vmac_mainloop_service(h->main)) /* the last events */
		;
	vmac_http_stop(h->http);
	vmac_site_free(h->site); /* after the server: a request may have been reading it */
	vmac_mainloop_free(h->main);
	vmac_store_close(h->store);
	vmac_bus_free(h->bus);
	vmacd_log(LOG_NOTICE, "stopped; every board was told to go safe");
}

int main(int argc, char **argv)
{
	static struct host host;
	struct host *h = &host;
	int rc;

	vmacd_log_init();
	rc = parse_args(h, argc, argv);
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
	h->log.echo = vmacd_echo_event;
	h->loop = EV_DEFAULT;
	if (open_parts(h) != 0)
		return 1;
	watch(h);
	if (start_threads(h) != 0)
		return 1;
	announce(h);
	ev_run(h->loop, 0);
	shut_down(h);
	return 0;
}
