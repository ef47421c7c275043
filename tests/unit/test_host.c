/* Unit tests of the host's own modules: configuration, the lateness
 * histogram, the SPSC ring, the error codes the bus answers other
 * threads with, and the bus's table of board keys (white-box: bus_internal.h). The driver module has its own tests
 * (test_driver.c). */
#include <arpa/inet.h>
#include <check.h>
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../core/common/errors.h"
#include "../../core/common/hist.h"
#include "../../core/common/ring.h"
#include "../../core/config/config.h"
#include "../../core/driver/driver.h"
#include "../../core/host/bus.h"
#include "../../core/host/bus_internal.h"
#include "check_main.h"

/* ---- config ---- */

static char *write_temp(const char *text)
{
	static char path[64];
	int fd;
	snprintf(path, sizeof(path), "/tmp/vmac-test-XXXXXX");
	fd = mkstemp(path);
	ck_assert_msg(fd >= 0, "cannot create a temporary file");
	ck_assert_int_eq(write(fd, text, strlen(text)), (ssize_t)strlen(text));
	close(fd);
	return path;
}

START_TEST(config_defaults_are_valid)
{
	struct vmac_config c;
	char err[256] = "";
	vmac_config_defaults(&c);
	ck_assert_msg(vmac_config_check(&c, err, sizeof(err)) == 0, "defaults rejected: %s", err);
	ck_assert_str_eq(c.http, "127.0.0.1:8080");
	ck_assert_uint_eq(c.miss_limit, 1);
}
END_TEST

START_TEST(config_file_sets_keys)
{
	struct vmac_config c;
	char err[256] = "";
	char *path =
	    write_temp("slice_us = 2000\nreply_deadline_us = 5000\nrealtime = false\nbus = \"239.1.2.3:999\"\n");
	vmac_config_defaults(&c);
	ck_assert_msg(vmac_config_load(&c, path, err, sizeof(err)) == 0, "load failed: %s", err);
	unlink(path);
	ck_assert_uint_eq(c.slice_us, 2000);
	ck_assert_uint_eq(vmac_config_slot_us(&c), 20000);
	ck_assert_uint_eq(c.reply_deadline_us, 5000);
	ck_assert_int_eq(c.realtime, 0);
	ck_assert_str_eq(c.bus, "239.1.2.3:999");
}
END_TEST

START_TEST(config_file_errors_name_the_problem)
{
	struct vmac_config c;
	char err[256] = "";
	char *path = write_temp("slice_us = 2000\nslice_uss = 5\n");
	vmac_config_defaults(&c);
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "slice_uss") != NULL, "error does not name the unknown key: %s", err);
	unlink(path);

	path = write_temp("slice_us = = 3\n");
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, ":1:") != NULL, "syntax error without a line number: %s", err);
	unlink(path);

	path = write_temp("os.exit(1)\n"); /* no library reachable from a config file */
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	unlink(path);

	path = write_temp("slice_us = 2000\nwhile true do end\n"); /* an endless file: an error, not a hang */
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, path) != NULL && strstr(err, "instructions") != NULL,
	              "an endless config file: '%s' does not name the file and the limit", err);
	unlink(path);

	path = write_temp("error(setmetatable({}, { __tostring = function() while true do end end }))\n");
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	unlink(path);

	/* A greedy file: an error at the state's cap, not all the machine's
	 * memory (found by tests/fuzz/fuzz_config.c). */
	path = write_temp("s = 'x' for i = 1, 40 do s = s .. s end\n");
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, path) != NULL && strstr(err, "1 MiB") != NULL,
	              "a greedy config file: '%s' does not name the file and the cap", err);
	unlink(path);

	/* A churning file: a few KiB in use at a time, but gigabytes copied
	 * within its instructions; refused at 4 MiB allocated in all (found
	 * by tests/fuzz/fuzz_config.c). */
	path = write_temp("s = 'x' for r = 1, 1e90 do s = 2 .. s end\n");
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, path) != NULL && strstr(err, "4 MiB in all") != NULL,
	              "a churning config file: '%s' does not name the file and the bound", err);
	unlink(path);

	/* Nearly 64 KiB of settings, a driver table of 40 drivers: within
	 * every bound (it allocates under 2 MiB in all). */
	{
		char *big = malloc(64 * 1024), *q = big;
		int i;
		ck_assert_ptr_nonnull(big);
		q += sprintf(q, "driver = {\n");
		for (i = 0; q - big < 60000; i++)
			q += sprintf(q, "  d%d = { key_%d = \"value %d xxxxxxxxxxxxxxxxxxxxxxxx\" },\n", i % 40, i, i);
		sprintf(q, "}\n");
		path = write_temp(big);
		free(big);
		ck_assert_msg(vmac_config_load(&c, path, err, sizeof(err)) == 0, "60 KB of driver settings: %s", err);
		unlink(path);
	}

	/* A file over 64 KiB is refused before it runs; one that is not there
	 * says so. */
	{
		char *big = malloc(65 * 1024 + 1);
		ck_assert_ptr_nonnull(big);
		memset(big, ' ', 65 * 1024);
		big[65 * 1024] = 0;
		memcpy(big, "slice_us = 2000\n", 16);
		path = write_temp(big);
		free(big);
		ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
		ck_assert_msg(strstr(err, path) != NULL && strstr(err, "64 KiB") != NULL,
		              "a config file over 64 KiB: '%s' does not name the file and the bound", err);
		unlink(path);
	}
	ck_assert_int_ne(vmac_config_load(&c, "/nonexistent/vmac.lua", err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "/nonexistent/vmac.lua") != NULL && strstr(err, "cannot open") != NULL,
	              "a missing config file: '%s'", err);
}
END_TEST

START_TEST(config_set_rejects_bad_values)
{
	struct vmac_config c;
	char err[256];
	vmac_config_defaults(&c);
	ck_assert_int_ne(vmac_config_set(&c, "slice_us", "abc", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "slice_us", "-5", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "slice_us", "99999999999", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "realtime", "maybe", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "nonsense", "1", err, sizeof(err)), 0);
	ck_assert_uint_eq(c.slice_us, 100);
	ck_assert_int_eq(vmac_config_set(&c, "default_level", "11", err, sizeof(err)), 0);
	ck_assert_msg(vmac_config_check(&c, err, sizeof(err)) != 0, "default_level above max_level accepted");
	ck_assert_msg(strstr(err, "default_level") != NULL, "error does not name default_level: %s", err);
	vmac_config_defaults(&c);
	ck_assert_int_eq(vmac_config_set(&c, "slice_us", "100000", err, sizeof(err)), 0);
	ck_assert_msg(vmac_config_check(&c, err, sizeof(err)) != 0, "watchdog shorter than two slots accepted");
	ck_assert_msg(strstr(err, "watchdog_ms") != NULL, "error does not name watchdog_ms: %s", err);
}
END_TEST

START_TEST(config_driver_settings)
{
	struct vmac_config c;
	struct vmac_driver_setting got[8];
	char err[256] = "";
	char *path = write_temp("driver = { washer = { memory_kib = 8192, param = { time_scale = 0.01 } } }\n");
	int n;
	vmac_config_defaults(&c);
	ck_assert_msg(vmac_config_load(&c, path, err, sizeof(err)) == 0, "nested driver table refused: %s", err);
	unlink(path);
	ck_assert_int_eq(vmac_config_set(&c, "driver.washer.param.time_scale", "0.5", err, sizeof(err)), 0);
	ck_assert_int_eq(vmac_config_set(&c, "driver.lights.budget_us", "300", err, sizeof(err)), 0);
	n = vmac_config_driver_settings(&c, "washer", got, 8);
	ck_assert_msg(n == 2, "washer has %d settings, expected 2 (a later --set replaces, not adds)", n);
	ck_assert_msg((strcmp(got[0].key, "param.time_scale") == 0 && strcmp(got[0].value, "0.5") == 0) ||
	                  (strcmp(got[1].key, "param.time_scale") == 0 && strcmp(got[1].value, "0.5") == 0),
	              "param.time_scale not overridden to 0.5");
	ck_assert_int_eq(vmac_config_driver_settings(&c, "lights", got, 8), 1);
	ck_assert_int_eq(vmac_config_driver_settings(&c, "dishwasher", got, 8), 0);
	ck_assert_msg(vmac_config_set(&c, "driver.washer", "1", err, sizeof(err)) != 0,
	              "driver.NAME without KEY accepted");
	ck_assert_msg(strstr(err, "driver.NAME.KEY") != NULL, "unclear message: %s", err);
}
END_TEST

/* A config file of LuaJIT bytecode is refused, never run: the bytecode
 * loader trusts its input, and this damaged file (found by
 * tests/fuzz/fuzz_config.c, kept as a seed of tests/fuzz/corpus-config/)
 * made the host read address 0. */
START_TEST(config_file_refuses_bytecode)
{
	static const unsigned char damaged[] = {
	    0x1b, 0x4c, 0x4a, 0x02, 0x0a, 0xc8, 0x01, 0x02, 0x00, 0x03, 0x00, 0x0c, 0x00, 0x0f, 0x27, 0x00, 0x00, 0x00,
	    0x37, 0x00, 0x01, 0x00, 0x27, 0x00, 0x02, 0x00, 0x37, 0x00, 0x03, 0x00, 0x29, 0x00, 0xe8, 0x03, 0x37, 0x00,
	    0x04, 0x00, 0x29, 0x00, 0xa0, 0x0f, 0x37, 0x00, 0x05, 0x00, 0x35, 0x00, 0x09, 0x00, 0x35, 0x01, 0x06, 0x00,
	    0x35, 0x02, 0x07, 0x00, 0x3d, 0x02, 0x08, 0x01, 0x3d, 0x01, 0x0a, 0x00, 0x37, 0x00, 0x0b, 0x00, 0x4b, 0x00,
	    0x01, 0x00, 0x0b, 0x64, 0x72, 0x69, 0x76, 0x65, 0x72, 0x0b, 0x77, 0x61, 0x73, 0x68, 0x65, 0x72, 0x01, 0x00,
	    0x00, 0x0a, 0x70, 0x61, 0x72, 0x61, 0x6d, 0x01, 0x00, 0x01, 0x0f, 0x74, 0x69, 0x6d, 0x65, 0x5f, 0x73, 0x63,
	    0x61, 0x6c, 0x65, 0x04, 0x9a, 0xb3, 0xe6, 0xcc, 0x09, 0x99, 0xb3, 0xe6, 0x01, 0x03, 0xfd, 0x0f, 0x01, 0x00,
	    0x6d, 0x65, 0x6d, 0x6f, 0x72, 0x79, 0x5f, 0x6b, 0x69, 0x62, 0x03, 0x80, 0x40, 0x16, 0x72, 0x65, 0x70, 0x6c,
	    0x79, 0x5f, 0x64, 0x65, 0x61, 0x64, 0x6c, 0x69, 0x6e, 0x65, 0x5f, 0x75, 0x73, 0x0d, 0x73, 0x6c, 0x69, 0x63,
	    0x65, 0x5f, 0x75, 0x73, 0x09, 0x68, 0x74, 0x74, 0x70, 0x11, 0x30, 0x2e, 0x30, 0x2e, 0x30, 0x2e, 0x30, 0x3a,
	    0x38, 0x30, 0x38, 0x30, 0x08, 0x62, 0x75, 0x73, 0x17, 0x32, 0x33, 0x39, 0x2e, 0x32, 0x35, 0x35, 0x2e, 0x38,
	    0x36, 0x2e, 0x37, 0x37, 0x3a, 0x35, 0x38, 0x37, 0x30, 0x00,
	};
	struct vmac_config c;
	char err[256] = "", path[] = "/tmp/vmac-test-XXXXXX";
	int fd = mkstemp(path);
	ck_assert_msg(fd >= 0, "cannot create a temporary file");
	ck_assert_int_eq(write(fd, damaged, sizeof(damaged)), (ssize_t)sizeof(damaged));
	close(fd);
	vmac_config_defaults(&c);
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, path) != NULL && strstr(err, "wrong mode") != NULL,
	              "a bytecode config file: '%s' does not name the file and LuaJIT's reason", err);
	unlink(path);
}
END_TEST

/* ---- histogram ---- */

START_TEST(hist_quantiles)
{
	static struct vmac_hist h;
	int i;
	memset(&h, 0, sizeof(h));
	ck_assert_int_eq(vmac_hist_quantile(&h, 0.5), 0);
	for (i = 1; i <= 100; i++)
		vmac_hist_add(&h, i);
	ck_assert_msg(vmac_hist_quantile(&h, 0.5) == 51, "p50 of 1..100 is %lld",
	              (long long)vmac_hist_quantile(&h, 0.5));
	ck_assert_int_eq(vmac_hist_quantile(&h, 0.99), 100);
	ck_assert_int_eq(h.max_us, 100);
	vmac_hist_add(&h, 5000);
	vmac_hist_add(&h, 10000000); /* overflow bucket keeps the true max */
	ck_assert_int_eq(h.max_us, 10000000);
	ck_assert_int_eq(vmac_hist_quantile(&h, 1.0), 10000000);
	vmac_hist_add(&h, -3); /* clock oddities count as 0, never index out */
	ck_assert_uint_eq(h.bucket[0], 1);
}
END_TEST

/* GET /metrics's buckets: exact counts below each bucket bound, and the sum. */
START_TEST(hist_counts_below_bounds)
{
	static struct vmac_hist h;
	const int64_t samples[] = {0, 4, 5, 999, 1000, 1099, 1100, 2500, 99999, 100000, 5000000};
	size_t i;
	uint64_t sum = 0;
	memset(&h, 0, sizeof(h));
	for (i = 0; i < sizeof(samples) / sizeof(samples[0]); i++) {
		vmac_hist_add(&h, samples[i]);
		sum += (uint64_t)samples[i];
	}
	ck_assert_uint_eq(h.sum_us, sum);
	ck_assert_uint_eq(vmac_hist_below(&h, 0), 0);
	ck_assert_uint_eq(vmac_hist_below(&h, 5), 2);       /* 0 and 4: a sample of 5 us is not below 5 */
	ck_assert_uint_eq(vmac_hist_below(&h, 1000), 4);    /* ... and 5, 999 */
	ck_assert_uint_eq(vmac_hist_below(&h, 1100), 6);    /* + 1000, 1099 (the coarse bucket [1000, 1100)) */
	ck_assert_uint_eq(vmac_hist_below(&h, 2500), 7);    /* + 1100 */
	ck_assert_uint_eq(vmac_hist_below(&h, 2600), 8);    /* + 2500 */
	ck_assert_uint_eq(vmac_hist_below(&h, 100000), 9);  /* + 99999; not 100000 itself */
	ck_assert_uint_eq(vmac_hist_below(&h, 1 << 30), 9); /* the overflow bucket has no bound below +Inf */
	ck_assert_uint_eq(h.count, 11);
}
END_TEST

/* ---- ring ---- */

/* A bus whose thread never runs: every request times out and is left for
 * the bus thread to free, so the slots run out; neither side waits for the
 * other beyond the caller's timeout. */
START_TEST(input_requests_time_out_and_run_out_without_a_bus_thread)
{
	struct vmac_config c;
	struct vmac_bus *bus;
	struct vmac_bus_input_request r;
	char err[256] = "";
	int i;
	vmac_config_defaults(&c);
	ck_assert_int_eq(vmac_config_set(&c, "bus", "239.255.77.1:47123", err, sizeof(err)), 0);
	c.realtime = 0;
	bus = vmac_bus_new(&c, err, sizeof(err));
	ck_assert_msg(bus != NULL, "vmac_bus_new: %s", err);
	for (i = 0; i <= VMAC_BUS_REQUESTS; i++) {
		memset(&r, 0, sizeof(r));
		snprintf(r.device, sizeof(r.device), "lights-1");
		snprintf(r.name, sizeof(r.name), "kitchen");
		ck_assert_int_eq(vmac_bus_request_input(bus, &r, 20), -VMAC_EBUSY);
		if (i < VMAC_BUS_REQUESTS)
			ck_assert_msg(strstr(r.reply, "did not take the request within 20 ms") != NULL,
			              "request %d: %s", i, r.reply);
		else
			ck_assert_msg(strstr(r.reply, "busy") != NULL, "request past the slots: %s", r.reply);
	}
	vmac_bus_free(bus);
}
END_TEST

/* ---- what the bus answers, as codes (core/common/errors.h) ---- */

static void send_nowhere(void *ctx, const struct vmac_packet *pkts, int n)
{
	(void)ctx;
	(void)pkts;
	(void)n;
}

/* A bus in virtual mode with no board at all. */
static struct vmac_bus *empty_bus(void)
{
	struct vmac_config c;
	struct vmac_bus_link link = {send_nowhere, NULL};
	struct vmac_addr group;
	struct sockaddr_in *sin = (struct sockaddr_in *)&group.ss;
	struct vmac_bus *bus;
	char err[256] = "";
	vmac_config_defaults(&c);
	c.realtime = 0;
	memset(&group, 0, sizeof(group));
	sin->sin_family = AF_INET;
	sin->sin_port = htons(5870);
	sin->sin_addr.s_addr = htonl(0xEFFF564Du);
	group.len = sizeof(*sin);
	bus = vmac_bus_new_virtual(&c, &link, &group, err, sizeof(err));
	ck_assert_msg(bus != NULL, "vmac_bus_new_virtual: %s", err);
	return bus;
}

/* The bus thread's part, for requests made from another thread: what a
 * virtual bus does when its caller handles commands. */
struct pump {
	struct vmac_bus *bus;
	atomic_int stop;
};

static void *pump_requests(void *arg)
{
	struct pump *p = arg;
	while (!atomic_load(&p->stop)) {
		vmac_bus_virtual_commands(p->bus);
		usleep(1000);
	}
	return NULL;
}

START_TEST(the_bus_answers_with_codes)
{
	struct vmac_bus *bus = empty_bus();
	struct vmac_value v = {.type = VMAC_VALUE_BOOL, .number = 1};
	struct vmac_bus_input_request r;
	struct pump p = {bus, 0};
	pthread_t th;
	char reply[VMAC_EVENT_TEXT] = "", names[4][VMAC_NAME_MAX + 1];
	int rc = 99, n;

	n = vmac_bus_input(bus, "nosuch-1", "relay", &v, reply, sizeof(reply));
	ck_assert_msg(n == -VMAC_ENOTRUNNING && strstr(reply, "nosuch-1 is not running"),
	              "input to a device that is not there: %d %s", n, reply);
	ck_assert_str_eq(vmac_strerror(n), "not running");

	ck_assert_int_eq(pthread_create(&th, NULL, pump_requests, &p), 0);
	memset(&r, 0, sizeof(r));
	snprintf(r.device, sizeof(r.device), "nosuch-1");
	snprintf(r.name, sizeof(r.name), "relay");
	r.value = v;
	ck_assert_int_eq(vmac_bus_request_input(bus, &r, 2000), 0);
	ck_assert_msg(r.rc == -VMAC_ENOTRUNNING, "input through a request: %d %s", r.rc, r.reply);
	/* The swap is refused before the new instance is looked at: none is needed. */
	n = vmac_bus_request_swap(bus, "nosuch-1", NULL, 0, 2000, &rc, reply, sizeof(reply));
	ck_assert_msg(n == 0 && rc == -VMAC_ENOTRUNNING && strstr(reply, "is not running"),
	              "a swap for a device that is not there: %d %d %s", n, rc, reply);
	n = vmac_bus_request_machines(bus, "counter", names, 4, 2000, reply, sizeof(reply));
	ck_assert_msg(n == 0, "machines of a driver nothing runs: %d %s", n, reply);
	atomic_store(&p.stop, 1);
	pthread_join(th, NULL);

	/* No one takes requests now: busy, as a code. */
	n = vmac_bus_request_swap(bus, "nosuch-1", NULL, 0, 20, &rc, reply, sizeof(reply));
	ck_assert_msg(n == -VMAC_EBUSY && rc == -VMAC_EBUSY, "a swap no one takes: %d %d %s", n, rc, reply);
	vmac_bus_free(bus);
}
END_TEST

START_TEST(ring_fifo_and_full)
{
	struct vmac_ring r;
	int i, v;
	ck_assert_int_eq(vmac_ring_init(&r, sizeof(int), 5), 0); /* rounds up to 8 */
	for (i = 0; i < 8; i++)
		ck_assert_msg(vmac_ring_push(&r, &i) == 0, "push %d failed below capacity", i);
	ck_assert_msg(vmac_ring_push(&r, &i) != 0, "push into a full ring succeeded");
	for (i = 0; i < 8; i++) {
		ck_assert_int_eq(vmac_ring_pop(&r, &v), 1);
		ck_assert_msg(v == i, "popped %d, expected %d", v, i);
	}
	ck_assert_int_eq(vmac_ring_pop(&r, &v), 0);
	vmac_ring_fini(&r);
}
END_TEST

/* core/common/errors.h: a VMAC_E* code, an errno, a codec error and a
 * refusal never share a value, and each has a name. */
START_TEST(error_codes_have_ranges_of_their_own)
{
	static const int errnos[] = {EPERM, ENOENT, EIO, EAGAIN, ENOMEM, EACCES, ENAMETOOLONG, ENOSPC};
	int code;
	size_t i;
	for (code = VMAC_EFAIL; code < VMAC_ERR_END_; code++) {
		ck_assert_msg(code > 4095, "VMAC_E code %d is in errno's range", code);
		ck_assert_msg(strcmp(vmac_strerror(-code), "unknown error") != 0, "VMAC_E code %d has no text", code);
		ck_assert_msg(-code > VMAC_EPROTO_SHORT, "VMAC_E code %d reaches the codec's range", code);
	}
	ck_assert_msg(VMAC_ERR_END_ - VMAC_ERR_BASE < 100, "more VMAC_E codes than their range holds");
	for (i = 0; i < sizeof(errnos) / sizeof(errnos[0]); i++)
		ck_assert_msg(strcmp(vmac_strerror(-errnos[i]), strerror(errnos[i])) == 0,
		              "errno %d is named '%s', not strerror's", errnos[i], vmac_strerror(-errnos[i]));
	ck_assert_msg(VMAC_EPROTO_SHORT <= -20001 && VMAC_EPROTO_AUTH >= -20099, "codec errors outside -20001..-20099");
	ck_assert_msg(VMAC_REFUSED_BY_DRIVER >= 1 && VMAC_REFUSED_NOT_PERSIST < 100, "refusals outside 1..99");
}
END_TEST

/* ---- the bus's table of board keys (keys.c) ---- */

START_TEST(board_key_table_finds_every_name_and_only_those)
{
	struct vmac_bus_keys *k = vmac_bus_keys_new(1000);
	struct vmac_bus *bus = calloc(1, sizeof(*bus));
	uint8_t key[16];
	char name[32];
	int i;
	ck_assert_ptr_nonnull(k);
	ck_assert_ptr_nonnull(bus);
	for (i = 0; i < 1000; i++) {
		snprintf(name, sizeof(name), "board-%d", i);
		memset(key, i & 0xff, sizeof(key));
		ck_assert_int_eq(vmac_bus_keys_add(k, name, key), 0);
	}
	/* A name added again takes its last key, and takes no room. */
	memset(key, 0xee, sizeof(key));
	ck_assert_int_eq(vmac_bus_keys_add(k, "board-7", key), 0);
	ck_assert_int_eq(vmac_bus_keys_add(k, "", key), -EINVAL);
	bus->keys = k;
	ck_assert_uint_eq(bus_keys_count(bus), 1000);
	for (i = 0; i < 1000; i++) {
		const uint8_t *got;
		snprintf(name, sizeof(name), "board-%d", i);
		got = bus_key_of(bus, name);
		ck_assert_msg(got != NULL, "%s not found", name);
		ck_assert_int_eq(got[0], i == 7 ? 0xee : (i & 0xff));
	}
	ck_assert_ptr_null(bus_key_of(bus, "board-1000"));
	ck_assert_ptr_null(bus_key_of(bus, "board"));
	/* Full: at most half the slots, so every probe ends. */
	for (i = 1000; vmac_bus_keys_add(k, (snprintf(name, sizeof(name), "more-%d", i), name), key) == 0; i++)
		ck_assert_int_lt(i, 100000);
	ck_assert_ptr_null(bus_key_of(bus, "nobody"));
	bus->keys = NULL;
	vmac_bus_keys_free(k);
	free(bus);
}
END_TEST

/* A TIMED reply's latch time becomes the inputs' instant only when it is
 * plausible; any 64 bits a forger on an open bus sends are not (2^63 and
 * above once wrapped into a time long before the reply, passing the check). */
START_TEST(a_timed_reply_latch_time_is_taken_only_when_plausible)
{
	static struct device d;
	struct vmac_msg m;
	const int64_t rx = 5000000000LL;
	const uint64_t odd[] = {0x8000000000000001ULL, UINT64_MAX, (uint64_t)rx + 2000000,
	                        (uint64_t)rx - 2000000000ULL};
	size_t i;
	memset(&m, 0, sizeof(m));
	m.flags = VMAC_FLAG_REPLY | VMAC_FLAG_TIMED;
	d.sent_timed = 1;
	m.latch.latched_at = (uint64_t)rx - 300000;
	bus_timed_reply(NULL, &d, &m, rx);
	ck_assert_msg(d.sample_ns == rx - 300000, "a latch 300 us before the reply not taken: %lld",
	              (long long)d.sample_ns);
	for (i = 0; i < sizeof(odd) / sizeof(odd[0]); i++) {
		m.latch.latched_at = odd[i];
		bus_timed_reply(NULL, &d, &m, rx);
		ck_assert_msg(d.sample_ns == rx,
		              "latched_at 0x%016llx taken as the inputs' instant (%lld), not the reply's",
		              (unsigned long long)odd[i], (long long)d.sample_ns);
	}
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("host");
	TCase *tc = tcase_create("host");
	tcase_set_timeout(tc, 30);
	tcase_add_test(tc, error_codes_have_ranges_of_their_own);
	tcase_add_test(tc, config_defaults_are_valid);
	tcase_add_test(tc, config_file_sets_keys);
	tcase_add_test(tc, config_file_errors_name_the_problem);
	tcase_add_test(tc, config_set_rejects_bad_values);
	tcase_add_test(tc, config_driver_settings);
	tcase_add_test(tc, config_file_refuses_bytecode);
	tcase_add_test(tc, hist_quantiles);
	tcase_add_test(tc, hist_counts_below_bounds);
	tcase_add_test(tc, ring_fifo_and_full);
	tcase_add_test(tc, input_requests_time_out_and_run_out_without_a_bus_thread);
	tcase_add_test(tc, the_bus_answers_with_codes);
	tcase_add_test(tc, board_key_table_finds_every_name_and_only_those);
	tcase_add_test(tc, a_timed_reply_latch_time_is_taken_only_when_plausible);
	suite_add_tcase(s, tc);
	return s;
}
