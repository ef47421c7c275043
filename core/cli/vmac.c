/* vmac: the command line for vmac hosts. Its commands, in one table here
 * (each declared beside its code, parsed by command.c); `vmac status`
 * (GET /api/status for people) and `vmac bench` live in this file.
 * Commands and options: docs/CLI.md. */
#include <curl/curl.h>
#include <errno.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../common/paths.h"
#include "../common/version.h"
#include "../vtest/vtest.h"
#include "board.h"
#include "bundle.h"
#include "client.h"
#include "command.h"
#include "console.h"
#include "events.h"
#include "lint.h"
#include "recordings.h"
#include "reload.h"
#include "schedule.h"
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

static int status_run(const struct vmac_cmd_args *a)
{
	char url[256];
	struct vmac_buffer b = {NULL, 0};
	json_t *s;
	json_error_t jerr;
	int rc;

	vmac_client_url(url, sizeof(url), a->opt[VMAC_CMD_HTTP], "/api/status");
	curl_global_init(CURL_GLOBAL_DEFAULT);
	rc = http_get(url, &b);
	curl_global_cleanup();
	if (rc) {
		free(b.data);
		return 1;
	}
	if (a->opt[VMAC_CMD_JSON]) {
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

static const struct vmac_cmd status_cmd = {
    .name = "status",
    .summary = "devices, tick lateness, counters and events of a running vmacd",
    .about = "Show the devices, tick lateness, counters and recent events of a running vmacd (the JSON\n"
             "of GET /api/status with --json). Needs a token of scope read or more.\n"
             "Exit 0 done, 1 the host unreachable, the token refused or an unusable answer, 2 wrong usage.\n",
    .common = VMAC_CMD_API,
    .run = status_run};

/* vmac bench's options: handed to tests/bench/bench.py as they are. */
static const struct vmac_cmd_option bench_options[] = {
    {"seconds", NULL, 0, "N", NULL, NULL, "length of each measurement (default 60)"},
    {"only", NULL, 0, "LIST", NULL, NULL,
     "the figures to take, of lateness,cost,capacity,vtest,reload,ui,fieldbus,qemu,recorder,ethring,mqtt,"
     "workers,auth,metrics,minisign,bundle (default all)"},
    {"max-boards", NULL, 0, "N", NULL, NULL,
     "most boards a capacity search tries (default 2000; fieldbus: 4088, max_devices' range)"},
    {"cpu-awake", NULL, 0, "true|false", NULL, NULL,
     "vmacd's cpu_awake where lateness is compared with cyclictest (default true: like for like)"},
    {"out", NULL, 0, "FILE", NULL, NULL, "where the results go as JSON (default build/bench/results.json)"},
    {"base-bin", NULL, 0, "DIR", NULL, NULL,
     "workers: a folder with a vmacd of the code that ran drivers on its bus thread"},
    {"bisect", NULL, 0, "N", NULL, NULL, "bisection steps per capacity search (default 3)"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

/* vmac bench: the timing benchmark (tests/bench/bench.py) against the
 * programs beside this vmac. */
static int bench_run(const struct vmac_cmd_args *a)
{
	static char python[] = "python3", bin_flag[] = "--bin", bare_flag[] = "--bare";
	char root[1024], script[1100], bindir[1100], bare[1200], self[1024], flags[VMAC_CMD_OPT_MAX][32];
	char *args[2 * VMAC_CMD_OPT_MAX + 8];
	ssize_t len;
	int i, n = 0;
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
	args[n++] = python;
	args[n++] = script;
	args[n++] = bin_flag;
	args[n++] = bindir;
	args[n++] = bare_flag;
	args[n++] = bare;
	for (i = 0; bench_options[i].name; i++) {
		if (!a->opt[VMAC_CMD_OWN + i])
			continue;
		snprintf(flags[i], sizeof(flags[i]), "--%s", bench_options[i].name);
		args[n++] = flags[i];
		args[n++] = (char *)a->opt[VMAC_CMD_OWN + i];
	}
	args[n] = NULL;
	execvp("python3", args);
	fprintf(stderr, "vmac bench: cannot run python3 (%s)\n", strerror(errno));
	return 2;
}

static const struct vmac_cmd bench_cmd = {
    .name = "bench",
    .summary = "timing figures as ratios to baselines (cyclictest, a bare loop)",
    .about = "Measure tick lateness (next to cyclictest), capacity at 1 kHz, 100 Hz and 10 Hz, host CPU\n"
             "per device per tick (next to a bare sendmmsg loop), the speed of vmac test (wall time of a\n"
             "virtual hour of washing), hot reload (misses and latency of 1,000 reloads, next to the\n"
             "same window without), tick lateness with 50 web UI clients (next to none), the fieldbus\n"
             "modes, the firmware in QEMU, the flight recorder and checkpoints, raw Ethernet's receive\n"
             "ring, MQTT through Mosquitto, a bundle's signature check (next to its hash) and a bundle's\n"
             "upload to switched (next to a driver's text) (each next to its own baseline). Figures are ratios to\n"
             "baselines run in the same run on the same machine. Needs cyclictest (Debian rt-tests) and\n"
             "the bare loop built by 'make bench' (build/bench/bare_loop). See docs/PERFORMANCE.md.\n",
    .own = bench_options,
    .run = bench_run};

/* vmac test's options (docs/TESTING.md), in the order of test_run's opt[]. */
enum { T_DRIVERS, T_REPLAY, T_FILTER, T_SEED, T_LIST, T_TAP, T_JUNIT, T_TRACE, T_TIME_LIMIT, T_TIMEOUT, T_HISTORY };
static const struct vmac_cmd_option test_options[] = {
    {"drivers", NULL, 0, "DIR", NULL, NULL,
     "look for NAME.lua and its programmes (cycles/NAME/) in DIR before the shipped scripts/"},
    {"replay", NULL, 0, "FILE", NULL, NULL,
     "replay a flight recording (vmac recording get ID > FILE) against the driver it recorded, or with "
     "--drivers against DIR's version; say where an output first differs (docs/RECORDING.md)"},
    {"filter", NULL, 0, "PATTERN", NULL, NULL, "run only tests whose \"file: name\" contains PATTERN (plain text)"},
    {"seed", NULL, 0, "N", NULL, "1", "seed of the fault injector; a run is a function of it"},
    {"list", NULL, 0, NULL, NULL, NULL, "list the tests and exit"},
    {"tap", NULL, 0, NULL, NULL, NULL, "TAP version 13 on standard output instead of the human report"},
    {"junit", NULL, 0, "FILE", NULL, NULL, "also write JUnit XML to FILE"},
    {"trace", NULL, 0, "FILE", NULL, NULL, "write every board service as CSV (test,time_s,board,io,value)"},
    {"time-limit", NULL, 0, "S", NULL, "21600", "virtual seconds a test may run (6 h)"},
    {"timeout", NULL, 0, "S", NULL, "120",
     "wall-clock seconds a test or a file's top level may take: catches endless loops"},
    {"history", NULL, 0, "N", NULL, "8", "services per board shown when a test fails"},
    {NULL, NULL, 0, NULL, NULL, NULL, NULL}};

/* A number option of vmac test: at least lo (whole when whole). */
static int test_number(const struct vmac_cmd_args *a, int which, double lo, int whole, double *out)
{
	const char *v = a->opt[VMAC_CMD_OWN + which];
	char *end;
	errno = 0;
	*out = strtod(v, &end);
	if (errno || end == v || *end || *out < lo || (whole && *out != (double)(long)*out))
		return vmac_cmd_usage_error(a, "--%s takes a %s >= %g, got '%s'", test_options[which].name,
		                            whole ? "whole number" : "number", lo, v);
	return 0;
}

static int test_run(const struct vmac_cmd_args *a)
{
	struct vmac_test_options o;
	double seed, history;
	const char *const *opt = a->opt + VMAC_CMD_OWN;
	memset(&o, 0, sizeof(o));
	if (test_number(a, T_SEED, 0, 1, &seed) || test_number(a, T_HISTORY, 0, 1, &history) ||
	    test_number(a, T_TIME_LIMIT, 0.001, 0, &o.time_limit_s) ||
	    test_number(a, T_TIMEOUT, 0.001, 0, &o.timeout_s))
		return VMAC_CMD_USAGE;
	o.seed = (long)seed;
	o.history = (long)history;
	o.drivers = opt[T_DRIVERS];
	o.replay = opt[T_REPLAY];
	o.filter = opt[T_FILTER];
	o.junit = opt[T_JUNIT];
	o.trace = opt[T_TRACE];
	o.list = opt[T_LIST] != NULL;
	o.tap = opt[T_TAP] != NULL;
	o.paths = a->arg;
	o.npaths = a->nargs;
	return vmac_test_run(&o);
}

static const struct vmac_cmd test_cmd = {
    .name = "test",
    .args = "[PATH ...]",
    .min_args = 0,
    .max_args = -1,
    .summary = "run driver tests against mock boards in virtual time",
    .about = "Run driver tests (*_test.lua) against the real host core and board firmware with\n"
             "simulated plants, in virtual time: no sockets, no sleeping, no hardware, no root.\n"
             "With no PATH: the project's own tests under tests/ and scripts/. Exit status: 0 every\n"
             "test passed, 1 a test failed, 2 bad usage. See docs/TESTING.md.\n",
    .own = test_options,
    .run = test_run};

static const struct vmac_cmd *const commands[] = {&status_cmd,
                                                  &vmac_lint_cmd,
                                                  &test_cmd,
                                                  &vmac_token_cmd,
                                                  &vmac_board_cmd,
                                                  &vmac_console_cmd,
                                                  &vmac_get_cmd,
                                                  &vmac_set_cmd,
                                                  &vmac_events_cmd,
                                                  &vmac_logs_cmd,
                                                  &vmac_site_cmd,
                                                  &vmac_bundle_cmd,
                                                  &vmac_reload_cmd,
                                                  &vmac_rollback_cmd,
                                                  &vmac_drivers_cmd,
                                                  &vmac_activate_cmd,
                                                  &vmac_recordings_cmd,
                                                  &vmac_recording_cmd,
                                                  &vmac_record_cmd,
                                                  &vmac_schedule_cmd,
                                                  &bench_cmd,
                                                  NULL};

static const struct vmac_cmd vmac = {
    .name = "vmac", .args = "COMMAND", .about = "The command line for vmac hosts (docs/CLI.md).\n", .sub = commands};

int main(int argc, char **argv)
{
	if (argc >= 2 && strcmp(argv[1], "--version") == 0) {
		printf("vmac %s\n", VMAC_VERSION_STRING);
		return 0;
	}
	if (argc >= 2 && strcmp(argv[1], "help") == 0) {
		vmac_cmd_help(&vmac, NULL, stdout);
		return 0;
	}
	return vmac_cmd_main(&vmac, NULL, argc, argv);
}
