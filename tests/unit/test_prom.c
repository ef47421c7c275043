/* Unit tests of the Prometheus text writer behind GET /metrics
 * (core/api/prom_text.c; docs/API.md, "Metrics"): label values and help
 * texts escaped as the exposition format says (backslash, double quote,
 * newline), empty labels left out, values as Prometheus reads them, a
 * text far larger than its first buffer, and the boards' clock series
 * (core/api/prom_clock.c) of a status filled here. */
#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/api/prom_clock.h"
#include "../../core/api/prom_text.h"
#include "check_main.h"

/* The text p holds so far (p stays usable). */
static const char *text(const struct http_prom *p)
{
	ck_assert_msg(!p->failed, "the writer failed (out of memory)");
	return p->text;
}

START_TEST(label_values_are_escaped)
{
	struct http_prom p;
	http_prom_init(&p, 16); /* small: the samples below make it grow */
	http_prom_u64(&p, "vmac_device_state", 1, "board", "a\\b\"c\nd", "state", "running", NULL);
	ck_assert_str_eq(text(&p), "vmac_device_state{board=\"a\\\\b\\\"c\\nd\",state=\"running\"} 1\n");
	http_prom_free(&p);
}
END_TEST

START_TEST(escape_alone_never_cuts_an_escape_in_two)
{
	char out[8];
	http_prom_escape("x\"y\\z\n", out, sizeof(out));
	ck_assert_str_eq(out, "x\\\"y\\\\z"); /* 7 bytes and the NUL: the newline's escape does not fit */
	http_prom_escape("ab\"", out, 4);
	ck_assert_str_eq(out, "ab"); /* not "ab\\" */
	http_prom_escape("plain", out, sizeof(out));
	ck_assert_str_eq(out, "plain");
}
END_TEST

START_TEST(help_text_escapes_backslash_and_newline_but_not_quotes)
{
	struct http_prom p;
	http_prom_init(&p, 0);
	http_prom_family(&p, "vmac_x_total", "counter", "a \"quoted\" word\\ and\na second line");
	ck_assert_str_eq(text(&p), "# HELP vmac_x_total a \"quoted\" word\\\\ and\\na second line\n"
	                           "# TYPE vmac_x_total counter\n");
	http_prom_free(&p);
}
END_TEST

START_TEST(empty_labels_are_left_out_and_no_labels_means_no_braces)
{
	struct http_prom p;
	http_prom_init(&p, 0);
	http_prom_u64(&p, "vmac_device_served_total", 7, "machine", "", "board", "lamp", NULL);
	http_prom_u64(&p, "vmac_ticks_total", 18446744073709551615ull, NULL);
	http_prom_u64(&p, "vmac_drops_total", 0, "machine", "", NULL);
	ck_assert_str_eq(text(&p), "vmac_device_served_total{board=\"lamp\"} 7\n"
	                           "vmac_ticks_total 18446744073709551615\n"
	                           "vmac_drops_total 0\n");
	http_prom_free(&p);
}
END_TEST

START_TEST(float_values_as_prometheus_reads_them)
{
	struct http_prom p;
	http_prom_init(&p, 0);
	http_prom_f64(&p, "a", 0.00625, NULL);
	http_prom_f64(&p, "b", NAN, NULL);
	http_prom_f64(&p, "c", INFINITY, NULL);
	http_prom_f64(&p, "d", -INFINITY, NULL);
	http_prom_f64(&p, "e", 1795750315.91764, NULL);
	ck_assert_str_eq(text(&p), "a 0.00625\nb NaN\nc +Inf\nd -Inf\ne 1795750315.91764\n");
	http_prom_free(&p);
}
END_TEST

START_TEST(a_large_text_is_whole_and_taken_once)
{
	struct http_prom p;
	char name[32], *t;
	size_t len;
	int i;
	http_prom_init(&p, 64);
	for (i = 0; i < 20000; i++) {
		snprintf(name, sizeof(name), "board-%d", i);
		http_prom_u64(&p, "vmac_device_served_total", (uint64_t)i, "board", name, NULL);
	}
	t = http_prom_take(&p, &len);
	ck_assert_ptr_nonnull(t);
	ck_assert_uint_eq(len, strlen(t));
	ck_assert_ptr_nonnull(strstr(t, "vmac_device_served_total{board=\"board-0\"} 0\n"));
	ck_assert_ptr_nonnull(strstr(t, "vmac_device_served_total{board=\"board-19999\"} 19999\n"));
	ck_assert_ptr_null(p.text); /* the caller's now; p is empty */
	free(t);
}
END_TEST

/* A status of three boards: one locked, one acting on arrival in holdover
 * with its bound unknown, one that never sent a TIMED reply. */
static void clock_status(struct vmac_status *s, struct vmac_device_status *devs)
{
	memset(s, 0, sizeof(*s));
	memset(devs, 0, 3 * sizeof(*devs));
	s->ndevices = 3;
	s->devices = devs;
	snprintf(devs[0].name, sizeof(devs[0].name), "washer-1");
	snprintf(devs[0].last_machine, sizeof(devs[0].last_machine), "washer-1");
	snprintf(devs[0].driver, sizeof(devs[0].driver), "washer");
	devs[0].clock.known = 1;
	devs[0].clock.state = 2;
	devs[0].clock.bound_ns = 1500;
	devs[0].clock.offset_ns = -3500000000ll;
	devs[0].clock.services_timed = 120;
	devs[0].clock.services_arrival = 3;
	snprintf(devs[1].name, sizeof(devs[1].name), "washer-io");
	snprintf(devs[1].last_machine, sizeof(devs[1].last_machine), "washer-1");
	snprintf(devs[1].driver, sizeof(devs[1].driver), "io");
	devs[1].clock.known = 1;
	devs[1].clock.state = 3;
	devs[1].clock.on_arrival = 1;
	devs[1].clock.bound_ns = 0xFFFFFFFFu;
	devs[1].clock.offset_ns = 250000;
	devs[1].clock.services_arrival = 7;
	snprintf(devs[2].name, sizeof(devs[2].name), "lamp");
	snprintf(devs[2].driver, sizeof(devs[2].driver), "lights");
}

START_TEST(board_clocks_only_of_boards_that_sent_a_timed_reply)
{
	struct vmac_status s;
	struct vmac_device_status devs[3];
	struct http_prom p;
	const char *t;
#define W "machine=\"washer-1\",board=\"washer-1\",driver=\"washer\""
#define IO "machine=\"washer-1\",board=\"washer-io\",driver=\"io\""
	clock_status(&s, devs);
	http_prom_init(&p, 0);
	http_prom_board_clocks(&p, &s);
	t = text(&p);
	/* One state 1, the others 0: an enum as labels. */
	ck_assert_ptr_nonnull(strstr(t, "# TYPE vmac_board_clock_state gauge\n"
	                                "vmac_board_clock_state{" W ",state=\"unsynced\"} 0\n"
	                                "vmac_board_clock_state{" W ",state=\"locking\"} 0\n"
	                                "vmac_board_clock_state{" W ",state=\"locked\"} 1\n"
	                                "vmac_board_clock_state{" W ",state=\"holdover\"} 0\n"
	                                "vmac_board_clock_state{" W ",state=\"lost\"} 0\n"));
	ck_assert_ptr_nonnull(strstr(t, "vmac_board_clock_state{" IO ",state=\"holdover\"} 1\n"));
	ck_assert_ptr_nonnull(strstr(t, "vmac_board_clock_state{" IO ",state=\"locked\"} 0\n"));
	/* Seconds; an unknown bound has no sample. */
	ck_assert_ptr_nonnull(strstr(t, "# TYPE vmac_board_clock_bound_seconds gauge\n"
	                                "vmac_board_clock_bound_seconds{" W "} 1.5e-06\n"
	                                "# HELP vmac_board_clock_offset_seconds"));
	ck_assert_ptr_nonnull(strstr(t, "vmac_board_clock_offset_seconds{" W "} -3.5\n"));
	ck_assert_ptr_nonnull(strstr(t, "vmac_board_clock_offset_seconds{" IO "} 0.00025\n"));
	ck_assert_ptr_nonnull(strstr(t, "# TYPE vmac_board_services_total counter\n"
	                                "vmac_board_services_total{" W ",timing=\"timed\"} 120\n"
	                                "vmac_board_services_total{" W ",timing=\"arrival\"} 3\n"
	                                "vmac_board_services_total{" IO ",timing=\"timed\"} 0\n"
	                                "vmac_board_services_total{" IO ",timing=\"arrival\"} 7\n"));
	/* The board without a clock has no series at all. */
	ck_assert_ptr_null(strstr(t, "lamp"));
	http_prom_free(&p);
#undef W
#undef IO
}
END_TEST

START_TEST(no_clock_known_means_headers_only)
{
	struct vmac_status s;
	struct vmac_device_status devs[3];
	struct http_prom p;
	const char *t, *line;
	clock_status(&s, devs);
	devs[0].clock.known = devs[1].clock.known = 0;
	http_prom_init(&p, 0);
	http_prom_board_clocks(&p, &s);
	t = text(&p);
	for (line = t; *line; line = strchr(line, '\n') + 1)
		ck_assert_msg(line[0] == '#', "a sample without a known clock: %s", line);
	ck_assert_ptr_nonnull(strstr(t, "# TYPE vmac_board_services_total counter\n"));
	http_prom_free(&p);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("prom");
	TCase *tc = tcase_create("text");
	tcase_add_test(tc, label_values_are_escaped);
	tcase_add_test(tc, escape_alone_never_cuts_an_escape_in_two);
	tcase_add_test(tc, help_text_escapes_backslash_and_newline_but_not_quotes);
	tcase_add_test(tc, empty_labels_are_left_out_and_no_labels_means_no_braces);
	tcase_add_test(tc, float_values_as_prometheus_reads_them);
	tcase_add_test(tc, a_large_text_is_whole_and_taken_once);
	tcase_add_test(tc, board_clocks_only_of_boards_that_sent_a_timed_reply);
	tcase_add_test(tc, no_clock_known_means_headers_only);
	suite_add_tcase(s, tc);
	return s;
}
