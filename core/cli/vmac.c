/* vmac: the command line for a running host. `vmac status` fetches
 * GET /api/status (libcurl) and prints it for people, or raw with --json.
 * Subcommands and flags: docs/CLI.md. */
#include <curl/curl.h>
#include <errno.h>
#include <getopt.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../common/paths.h"
#include "../vtest/vtest.h"
#include "client.h"
#include "console.h"
#include "events.h"
#include "lint.h"
#include "recordings.h"
#include "reload.h"
#include "site.h"
#include "token.h"

/* GET url into *out. Returns 0, or prints why and returns 1. */
static int http_get(const char *url, struct vmac_buffer *out)
{
	char err[512];
	long code;
	if (vmac_client_call("GET", url, NULL, out, &code, err, sizeof(err)) != 0) {
		fprintf(stderr, "vmac: %s\n", err);
		return 1;
	}
	if (code == 401 || code == 403) {
		fprintf(stderr, "vmac: %s answered HTTP %ld: %s\n%s\n", url, code, out->data ? out->data : "",
		        vmac_client_auth_hint());
		return 1;
	}
	if (code != 200) {
		fprintf(stderr, "vmac: %s answered HTTP %ld: %s\n", url, code, out->data ? out->data : "");
		return 1;
	}
	return 0;
}

static void bits(json_t *array, char *out)
{
	size_t i;
	json_t *v;
	json_array_foreach(array, i, v) out[i] = json_is_true(v) ? '1' : '0';
	out[json_array_size(array)] = '\0';
}

static void print_status(json_t *s)
{
	json_t *bus = json_object_get(s, "bus"), *tick = json_object_get(s, "tick"),
	       *lat = json_object_get(tick, "lateness_us"), *cnt = json_object_get(s, "counters"),
	       *devices = json_object_get(s, "devices"), *events = json_object_get(s, "events"), *d, *e;
	size_t i;

	json_t *sched = json_object_get(s, "schedule"), *load = json_object_get(sched, "slot_load"), *x;
	long long lo = -1, hi = 0;
	json_array_foreach(load, i, x)
	{
		long long n = json_integer_value(x);
		lo = lo < 0 || n < lo ? n : lo;
		hi = n > hi ? n : hi;
	}
	printf("vmacd %s, up %.1f s, bus %s from %s, slot %lld us, reply deadline %lld us%s\n",
	       json_string_value(json_object_get(s, "version")), json_real_value(json_object_get(s, "uptime_s")),
	       json_string_value(json_object_get(bus, "group")), json_string_value(json_object_get(bus, "host_addr")),
	       json_integer_value(json_object_get(bus, "slot_us")),
	       json_integer_value(json_object_get(bus, "reply_deadline_us")),
	       json_is_true(json_object_get(bus, "realtime")) ? ", real-time" : "");
	printf("schedule: %lld slices of %lld us per slot, %lld slots per block, %lld of %lld slice-slots used, "
	       "devices per slot %lld..%lld\n",
	       json_integer_value(json_object_get(sched, "slices_per_slot")),
	       json_integer_value(json_object_get(sched, "slice_us")),
	       json_integer_value(json_object_get(sched, "slots_per_block")),
	       json_integer_value(json_object_get(sched, "capacity_used")),
	       json_integer_value(json_object_get(sched, "capacity_total")), lo < 0 ? 0 : lo, hi);
	printf("tick lateness: p50 %lld us, p99 %lld us, max %lld us over %lld ticks\n",
	       json_integer_value(json_object_get(lat, "p50")), json_integer_value(json_object_get(lat, "p99")),
	       json_integer_value(json_object_get(lat, "max")), json_integer_value(json_object_get(tick, "count")));
	printf("malformed frames %lld, late replies %lld, misses %lld, drops %lld\n\n",
	       json_integer_value(json_object_get(cnt, "malformed_frames")),
	       json_integer_value(json_object_get(cnt, "late_replies")),
	       json_integer_value(json_object_get(cnt, "misses")), json_integer_value(json_object_get(cnt, "drops")));
	if (json_array_size(devices) == 0)
		printf("no devices (start a board: vmac-board --plant lights)\n");
	else
		printf("%-16s %-18s %-10s %-10s %7s %9s  %-8s %-11s %-8s  %-7s %s\n", "DEVICE", "DRIVER", "STATE",
		       "LEVEL/SLOT", "MISSES", "SERVED", "DIN", "ANALOG", "ENCODER", "DOUT", "PWM");
	json_array_foreach(devices, i, d)
	{
		json_t *in = json_object_get(d, "inputs"), *out = json_object_get(d, "outputs"),
		       *an = json_object_get(in, "analog");
		char din[16], dout[16], analog[24], drv[64], where[32];
		const char *ver = json_string_value(json_object_get(d, "driver_version")), *key;
		json_t *vars = json_object_get(d, "variables"), *v;
		bits(json_object_get(in, "digital"), din);
		bits(json_object_get(out, "digital"), dout);
		snprintf(analog, sizeof(analog), "%lld/%lld", json_integer_value(json_array_get(an, 0)),
		         json_integer_value(json_array_get(an, 1)));
		snprintf(drv, sizeof(drv), "%s%s%s", json_string_value(json_object_get(d, "driver")),
		         ver && ver[0] ? " " : "", ver ? ver : "");
		if (json_is_integer(json_object_get(d, "slot")))
			snprintf(where, sizeof(where), "%lld/%lld.%lld",
			         json_integer_value(json_object_get(d, "level")),
			         json_integer_value(json_object_get(d, "slot")),
			         json_integer_value(json_object_get(d, "slice")));
		else
			snprintf(where, sizeof(where), "-");
		printf("%-16s %-18s %-10s %-10s %7lld %9lld  %-8s %-11s %-8lld  %-7s %lld\n",
		       json_string_value(json_object_get(d, "name")), drv,
		       json_string_value(json_object_get(d, "state")), where,
		       json_integer_value(json_object_get(d, "misses")),
		       json_integer_value(json_object_get(d, "served")), din, analog,
		       json_integer_value(json_object_get(in, "encoder")), dout,
		       json_integer_value(json_object_get(out, "pwm")));
		if (json_is_string(json_object_get(d, "note")))
			printf("    %s\n", json_string_value(json_object_get(d, "note")));
		if (json_object_size(vars) > 0) {
			printf("   ");
			json_object_foreach(vars, key, v)
			{
				if (json_is_string(v))
					printf(" %s=%s", key, json_string_value(v));
				else if (json_is_boolean(v))
					printf(" %s=%s", key, json_is_true(v) ? "true" : "false");
				else if (json_is_number(v))
					printf(" %s=%.4g", key, json_number_value(v));
				else
					printf(" %s=-", key);
			}
			printf("\n");
		}
	}
	if (json_array_size(events) > 0)
		printf("\nrecent events:\n");
	json_array_foreach(events, i, e)
	{
		time_t t = (time_t)json_real_value(json_object_get(e, "time"));
		char when[16];
		strftime(when, sizeof(when), "%H:%M:%S", localtime(&t));
		printf("  %s %-14s %s\n", when, json_string_value(json_object_get(e, "kind")),
		       json_string_value(json_object_get(e, "text")));
	}
}

static int cmd_status(int argc, char **argv)
{
	static const struct option opts[] = {{"http", required_argument, 0, 'H'},
	                                     {"host", required_argument, 0, 'H'},
	                                     {"json", no_argument, 0, 'j'},
	                                     {"token", required_argument, 0, 't'},
	                                     {"token-file", required_argument, 0, 'f'},
	                                     {"help", no_argument, 0, 'h'},
	                                     {0, 0, 0, 0}};
	const char *http = getenv("VMAC_HTTP") ? getenv("VMAC_HTTP") : "127.0.0.1:8080", *token = NULL,
	           *token_file = NULL;
	int raw = 0, opt, rc;
	char url[256];
	struct vmac_buffer b = {NULL, 0};
	json_t *s;
	json_error_t jerr;

	optind = 1;
	while ((opt = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
		switch (opt) {
		case 'H': http = optarg; break;
		case 'j': raw = 1; break;
		case 't': token = optarg; break;
		case 'f': token_file = optarg; break;
		case 'h':
			printf("usage: vmac status [--http ADDR:PORT] [--json] [--token T | --token-file F]\n"
			       "Show the devices, tick lateness, counters and recent events of a running vmacd.\n"
			       "  --http ADDR:PORT   the host's HTTP address (default $VMAC_HTTP or 127.0.0.1:8080)\n"
			       "  --json             print the raw JSON of GET /api/status\n"
			       "  --token T          a token of scope read or more (default $VMAC_TOKEN)\n"
			       "  --token-file F     read the token from F's first line (default $VMAC_TOKEN_FILE)\n");
			return 0;
		default: return 2;
		}
	}
	if (optind < argc) {
		fprintf(stderr, "vmac status: unexpected argument '%s'\n", argv[optind]);
		return 2;
	}
	if (vmac_client_token(token, token_file) != 0)
		return 2;
	vmac_client_url(url, sizeof(url), http, "/api/status");
	curl_global_init(CURL_GLOBAL_DEFAULT);
	rc = http_get(url, &b);
	curl_global_cleanup();
	if (rc) {
		free(b.data);
		return 1;
	}
	if (raw) {
		printf("%s\n", b.data);
		free(b.data);
		return 0;
	}
	s = json_loads(b.data, 0, &jerr);
	free(b.data);
	if (!s) {
		fprintf(stderr, "vmac: the host's answer is not JSON (%s)\n", jerr.text);
		return 1;
	}
	print_status(s);
	json_decref(s);
	return 0;
}

/* vmac bench [bench.py options]: the timing benchmark (tests/bench/bench.py)
 * against the programs beside this vmac. */
static int cmd_bench(int argc, char **argv)
{
	static char python[] = "python3", bin_flag[] = "--bin", bare_flag[] = "--bare";
	char root[1024], script[1100], bindir[1100], bare[1200], self[1024];
	char **args;
	ssize_t len;
	int i, n = 0;
	if (argc >= 2 && (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0)) {
		printf("usage: vmac bench [--seconds N] [--max-boards N] [--cpu-awake true|false] [--out FILE]\n"
		       "                  [--only "
		       "lateness,cost,capacity,vtest,reload,ui,fieldbus,qemu,recorder,ethring,mqtt]\n"
		       "Measure tick lateness (next to cyclictest), capacity at 1 kHz, 100 Hz and 10 Hz, host CPU\n"
		       "per device per tick (next to a bare sendmmsg loop), the speed of vmac test (wall time of a\n"
		       "virtual hour of washing), hot reload (misses and latency of 1,000 reloads, next to the\n"
		       "same window without), tick lateness with 50 web UI clients (next to none), the fieldbus\n"
		       "modes, the firmware in QEMU, the flight recorder and checkpoints, raw Ethernet's receive\n"
		       "ring, and MQTT through Mosquitto (each next to its own baseline). Figures are ratios "
		       "to baselines run in the same run on the same\n"
		       "machine. Needs cyclictest (Debian rt-tests) and the bare loop built by 'make bench'\n"
		       "(build/bench/bare_loop). See docs/PERFORMANCE.md.\n");
		return 0;
	}
	vmac_root_dir(root, sizeof(root));
	snprintf(script, sizeof(script), "%s/tests/bench/bench.py", root);
	len = readlink("/proc/self/exe", self, sizeof(self) - 1);
	if (len <= 0 || access(script, R_OK) != 0) {
		fprintf(stderr, "vmac bench: cannot find %s (run it from a source tree, or use make bench)\n", script);
		return 2;
	}
	self[len] = 0;
	*strrchr(self, '/') = 0;
	snprintf(bindir, sizeof(bindir), "%s", self);
	snprintf(bare, sizeof(bare), "%s/../bench/bare_loop", self);
	args = calloc((size_t)argc + 8, sizeof(*args));
	if (!args)
		return 2;
	args[n++] = python;
	args[n++] = script;
	args[n++] = bin_flag;
	args[n++] = bindir;
	args[n++] = bare_flag;
	args[n++] = bare;
	for (i = 1; i < argc; i++)
		args[n++] = argv[i];
	execvp("python3", args);
	fprintf(stderr, "vmac bench: cannot run python3 (%s)\n", strerror(errno));
	free(args);
	return 2;
}

static void usage(FILE *f)
{
	fprintf(f, "usage: vmac COMMAND [options]\n"
	           "The command line for vmac hosts.\n\n"
	           "  status    devices, tick lateness, counters and events of a running vmacd\n"
	           "  lint      check driver scripts with luacheck and the sandbox's globals\n"
	           "  test      run driver tests against mock boards in virtual time\n"
	           "  token     create, list and revoke the host's access tokens\n"
	           "  console   the line console: DEVICE.NAME?  DEVICE.NAME:VALUE  DEVICE.NAME!\n"
	           "  get       print published variables (DEVICE.NAME...)\n"
	           "  set       operator input (DEVICE.NAME:VALUE, DEVICE.NAME!)\n"
	           "  events    follow the host's events as they happen\n"
	           "  site      every host on an MQTT broker, its devices and values (the broker alone)\n"
	           "  reload    upload a new version of a driver; machines switch at a slot boundary\n"
	           "  rollback  go back to a driver's previous version\n"
	           "  drivers   list the driver versions the host keeps\n"
	           "  activate  make a kept driver version the active one again\n"
	           "  recordings  list the flight recordings the host keeps (drops, driver failures)\n"
	           "  recording get ID > FILE, recording to-test FILE: fetch one, make it a test\n"
	           "  record    capture a running machine's flight recorder now\n"
	           "  bench     timing figures as ratios to baselines (cyclictest, a bare loop)\n\n"
	           "Run 'vmac COMMAND --help' for a command's options.\n");
}

int main(int argc, char **argv)
{
	if (argc < 2) {
		usage(stderr);
		return 2;
	}
	if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0 || strcmp(argv[1], "help") == 0) {
		usage(stdout);
		return 0;
	}
	if (strcmp(argv[1], "--version") == 0) {
		printf("vmac 0.1.0\n");
		return 0;
	}
	if (strcmp(argv[1], "status") == 0)
		return cmd_status(argc - 1, argv + 1);
	if (strcmp(argv[1], "lint") == 0)
		return vmac_lint_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "test") == 0)
		return vmac_test_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "bench") == 0)
		return cmd_bench(argc - 1, argv + 1);
	if (strcmp(argv[1], "token") == 0)
		return vmac_token_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "site") == 0)
		return vmac_site_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "events") == 0)
		return vmac_events_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "console") == 0)
		return vmac_console_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "get") == 0)
		return vmac_get_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "set") == 0)
		return vmac_set_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "reload") == 0)
		return vmac_reload_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "rollback") == 0)
		return vmac_rollback_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "drivers") == 0)
		return vmac_drivers_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "activate") == 0)
		return vmac_activate_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "recordings") == 0)
		return vmac_recordings_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "recording") == 0)
		return vmac_recording_main(argc - 1, argv + 1);
	if (strcmp(argv[1], "record") == 0)
		return vmac_record_main(argc - 1, argv + 1);
	fprintf(stderr, "vmac: unknown command '%s'\n", argv[1]);
	usage(stderr);
	return 2;
}
