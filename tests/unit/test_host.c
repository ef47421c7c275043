/* Unit tests of the host's own modules: configuration, the lateness
 * histogram, the SPSC ring, and the driver sandbox's guarded call. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../core/driver/driver.h"
#include "../../core/host/config.h"
#include "../../core/host/hist.h"
#include "../../core/host/ring.h"

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
	char *path = write_temp("period_us = 20000\nreply_deadline_us = 5000\nrealtime = false\nbus = \"239.1.2.3:999\"\n");
	vmac_config_defaults(&c);
	ck_assert_msg(vmac_config_load(&c, path, err, sizeof(err)) == 0, "load failed: %s", err);
	unlink(path);
	ck_assert_uint_eq(c.period_us, 20000);
	ck_assert_uint_eq(c.reply_deadline_us, 5000);
	ck_assert_int_eq(c.realtime, 0);
	ck_assert_str_eq(c.bus, "239.1.2.3:999");
}
END_TEST

START_TEST(config_file_errors_name_the_problem)
{
	struct vmac_config c;
	char err[256] = "";
	char *path = write_temp("period_us = 20000\nperiod_uss = 5\n");
	vmac_config_defaults(&c);
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "period_uss") != NULL, "error does not name the unknown key: %s", err);
	unlink(path);

	path = write_temp("period_us = = 3\n");
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, ":1:") != NULL, "syntax error without a line number: %s", err);
	unlink(path);

	path = write_temp("os.exit(1)\n"); /* no library reachable from a config file */
	ck_assert_int_ne(vmac_config_load(&c, path, err, sizeof(err)), 0);
	unlink(path);
}
END_TEST

START_TEST(config_set_rejects_bad_values)
{
	struct vmac_config c;
	char err[256];
	vmac_config_defaults(&c);
	ck_assert_int_ne(vmac_config_set(&c, "period_us", "abc", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "period_us", "-5", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "period_us", "99999999999", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "realtime", "maybe", err, sizeof(err)), 0);
	ck_assert_int_ne(vmac_config_set(&c, "nonsense", "1", err, sizeof(err)), 0);
	ck_assert_uint_eq(c.period_us, 10000);
	ck_assert_int_eq(vmac_config_set(&c, "reply_deadline_us", "20000", err, sizeof(err)), 0);
	ck_assert_msg(vmac_config_check(&c, err, sizeof(err)) != 0, "deadline longer than the period accepted");
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
	ck_assert_msg(vmac_hist_quantile(&h, 0.5) == 51, "p50 of 1..100 is %lld", (long long)vmac_hist_quantile(&h, 0.5));
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

/* ---- ring ---- */

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

/* ---- driver sandbox ---- */

static struct vmac_driver_limits limits = {1 << 20, 200000, "/tmp/vmac-test-stdlib"};

static int load_text(const char *text, struct vmac_driver **d, char *err, size_t errlen)
{
	char *path = write_temp(text);
	int rc = vmac_driver_load(path, &limits, d, err, errlen);
	unlink(path);
	return rc;
}

static int tick_once(struct vmac_driver *d, struct vmac_outputs *out, char *err, size_t errlen)
{
	struct vmac_inputs in;
	memset(&in, 0, sizeof(in));
	in.digital = 0x03;
	in.analog[0] = 1234;
	in.encoder = -7;
	return vmac_driver_tick(d, 1.5, &in, out, err, errlen);
}

START_TEST(driver_tick_maps_io)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load_text("return { tick = function(i)\n"
	                        "  assert(i.digital[1] and i.digital[2] and not i.digital[3])\n"
	                        "  assert(i.analog[1] == 1234 and i.encoder == -7 and i.time == 1.5)\n"
	                        "  return { digital = { true, false, true }, pwm = -250 } end }\n",
	                        &d, err, sizeof(err)) == 0,
	              "load failed: %s", err);
	ck_assert_msg(tick_once(d, &out, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_msg(out.digital == 0x05, "digital outputs 0x%02x, expected 0x05", out.digital);
	ck_assert_int_eq(out.pwm, -250);
	vmac_driver_free(d);
}
END_TEST

START_TEST(driver_errors_carry_file_and_line)
{
	struct vmac_driver *d = NULL;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_int_ne(load_text("return { tick = function( end }\n", &d, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, ":1:") != NULL, "syntax error without line: %s", err);
	ck_assert_int_ne(load_text("return 42\n", &d, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "table") != NULL, "wrong-type error unclear: %s", err);
	ck_assert_int_eq(load_text("return { tick = function()\n\n  error('boom')\nend }\n", &d, err, sizeof(err)), 0);
	ck_assert_int_ne(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, ":3: boom") != NULL, "runtime error lacks file:line: %s", err);
	ck_assert_msg(strstr(err, "traceback") != NULL, "runtime error lacks a traceback: %s", err);
	vmac_driver_free(d);
}
END_TEST

START_TEST(driver_budget_cannot_be_swallowed)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_int_eq(load_text("return { tick = function()\n"
	                           "  while true do pcall(function() while true do end end) end\n"
	                           "end }\n",
	                           &d, err, sizeof(err)),
	                 0);
	ck_assert_int_ne(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "time budget") != NULL, "runaway loop not stopped by budget: %s", err);
	vmac_driver_free(d);
}
END_TEST

START_TEST(driver_memory_cap)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_int_eq(load_text("local t = {}\nreturn { tick = function()\n"
	                           "  for i = 1, 1e6 do t[i] = {i} end end }\n",
	                           &d, err, sizeof(err)),
	                 0);
	ck_assert_int_ne(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "memory") != NULL || strstr(err, "budget") != NULL,
	              "allocation beyond the cap did not fail cleanly: %s", err);
	ck_assert_msg(vmac_driver_memory(d) <= limits.memory_bytes, "heap %zu over cap %zu", vmac_driver_memory(d),
	              limits.memory_bytes);
	vmac_driver_free(d);
}
END_TEST

START_TEST(driver_sandbox_offers_its_libraries)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(load_text("return { tick = function()\n"
	                        "  assert(string.format('%d', 7) == '7' and ('ab'):upper() == 'AB')\n"
	                        "  assert(table.concat({1, 2}, ',') == '1,2' and math.floor(2.5) == 2)\n"
	                        "  assert(bit.band(6, 3) == 2 and string.rep('x', 3) == 'xxx')\n"
	                        "  assert(type(coroutine.create) == 'function' and select('#', 1, 2) == 2)\n"
	                        "  assert(string.dump == nil and ('').dump == nil)\n"
	                        "end }\n",
	                        &d, err, sizeof(err)) == 0,
	              "load failed: %s", err);
	ck_assert_msg(tick_once(d, &out, err, sizeof(err)) == 0, "allowed library missing: %s", err);
	vmac_driver_free(d);
}
END_TEST

START_TEST(driver_sandbox_hides_host)
{
	static const char *const escapes[] = {
	    "io.open('/etc/passwd')", "os.execute('true')", "require('ffi')", "debug.getregistry()",
	    "loadstring('return 1')()", "load('return 1')()", "dofile('/etc/passwd')", "getfenv(0)",
	    "string.dump(print)", "(''):dump()", "collectgarbage()", "jit.on()", "package.loadlib('x','y')",
	    "newproxy(true)", "setfenv(1, {})", "string.rep('x', 1e9)",
	    "getmetatable('').__index.rep('x', 1e9)", "setmetatable('', {})"};
	size_t i;
	for (i = 0; i < sizeof(escapes) / sizeof(escapes[0]); i++) {
		struct vmac_driver *d;
		struct vmac_outputs out;
		char src[256], err[VMAC_DRIVER_ERR_MAX] = "";
		snprintf(src, sizeof(src), "return { tick = function() %s end }\n", escapes[i]);
		ck_assert_msg(load_text(src, &d, err, sizeof(err)) == 0, "load of '%s' failed: %s", escapes[i], err);
		ck_assert_msg(tick_once(d, &out, err, sizeof(err)) != 0, "sandbox escape succeeded: %s", escapes[i]);
		vmac_driver_free(d);
	}
}
END_TEST

START_TEST(driver_rejects_bad_outputs)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_int_eq(load_text("return { tick = function() return { pwm = 5000 } end }\n", &d, err, sizeof(err)), 0);
	ck_assert_int_ne(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "pwm") != NULL, "out-of-range pwm not named: %s", err);
	vmac_driver_free(d);
	/* A driver that clobbers its inputs table is served again next tick. */
	ck_assert_int_eq(load_text("return { tick = function(i) i.digital = 5; i.analog = nil end }\n", &d, err,
	                           sizeof(err)),
	                 0);
	ck_assert_int_eq(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_msg(tick_once(d, &out, err, sizeof(err)) == 0, "second tick after clobbered inputs failed: %s", err);
	ck_assert_int_eq(out.digital, 0);
	vmac_driver_free(d);
}
END_TEST

static void write_file(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	ck_assert_msg(f != NULL, "cannot write %s", path);
	fputs(text, f);
	fclose(f);
}

START_TEST(driver_require_loads_stdlib_at_load_time_only)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	mkdir("/tmp/vmac-test-stdlib", 0755);
	write_file("/tmp/vmac-test-stdlib/twice.lua", "return { f = function(x) return 2 * x end }\n");
	ck_assert_msg(load_text("local t = require 'twice'\nassert(require('twice') == t)\n"
	                        "return { tick = function() return { pwm = t.f(21) } end }\n",
	                        &d, err, sizeof(err)) == 0,
	              "require at load failed: %s", err);
	ck_assert_msg(tick_once(d, &out, err, sizeof(err)) == 0, "tick failed: %s", err);
	ck_assert_int_eq(out.pwm, 42);
	vmac_driver_free(d);

	ck_assert_int_eq(load_text("return { tick = function() require 'twice' end }\n", &d, err, sizeof(err)), 0);
	ck_assert_msg(tick_once(d, &out, err, sizeof(err)) != 0, "require inside tick (file I/O on the bus) allowed");
	ck_assert_msg(strstr(err, "when the driver loads") != NULL, "unclear message: %s", err);
	vmac_driver_free(d);

	ck_assert_int_ne(load_text("require '../../etc/passwd'\nreturn {tick=function() end}\n", &d, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "not a stdlib module name") != NULL, "path in require not refused: %s", err);
	ck_assert_int_ne(load_text("require 'nosuch'\nreturn {tick=function() end}\n", &d, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "no such stdlib module") != NULL, "missing module unclear: %s", err);
}
END_TEST

START_TEST(driver_coroutines_keep_the_budget)
{
	struct vmac_driver *d;
	struct vmac_outputs out;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_int_eq(load_text("local co = coroutine.wrap(function() for i = 1, 3 do coroutine.yield(i) end end)\n"
	                           "return { tick = function() return { pwm = co() } end }\n",
	                           &d, err, sizeof(err)),
	                 0);
	ck_assert_msg(tick_once(d, &out, err, sizeof(err)) == 0, "coroutine tick failed: %s", err);
	ck_assert_int_eq(out.pwm, 1);
	ck_assert_int_eq(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_int_eq(out.pwm, 2);
	vmac_driver_free(d);

	ck_assert_int_eq(load_text("return { tick = function()\n"
	                           "  while true do coroutine.resume(coroutine.create(function() while true do end end)) end\n"
	                           "end }\n",
	                           &d, err, sizeof(err)),
	                 0);
	ck_assert_int_ne(tick_once(d, &out, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "time budget") != NULL, "resume swallowed the budget: %s", err);
	vmac_driver_free(d);
}
END_TEST

int main(void)
{
	Suite *s = suite_create("host");
	TCase *tc = tcase_create("host");
	SRunner *sr;
	int failed;
	tcase_set_timeout(tc, 30);
	tcase_add_test(tc, config_defaults_are_valid);
	tcase_add_test(tc, config_file_sets_keys);
	tcase_add_test(tc, config_file_errors_name_the_problem);
	tcase_add_test(tc, config_set_rejects_bad_values);
	tcase_add_test(tc, hist_quantiles);
	tcase_add_test(tc, ring_fifo_and_full);
	tcase_add_test(tc, driver_tick_maps_io);
	tcase_add_test(tc, driver_errors_carry_file_and_line);
	tcase_add_test(tc, driver_budget_cannot_be_swallowed);
	tcase_add_test(tc, driver_memory_cap);
	tcase_add_test(tc, driver_sandbox_offers_its_libraries);
	tcase_add_test(tc, driver_sandbox_hides_host);
	tcase_add_test(tc, driver_rejects_bad_outputs);
	tcase_add_test(tc, driver_require_loads_stdlib_at_load_time_only);
	tcase_add_test(tc, driver_coroutines_keep_the_budget);
	suite_add_tcase(s, tc);
	sr = srunner_create(s);
	srunner_run_all(sr, CK_NORMAL);
	failed = srunner_ntests_failed(sr);
	srunner_free(sr);
	return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
