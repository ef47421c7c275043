/* Unit tests of the Prometheus text writer behind GET /metrics
 * (core/api/prom_text.c; docs/API.md, "Metrics"): label values and help
 * texts escaped as the exposition format says (backslash, double quote,
 * newline), empty labels left out, values as Prometheus reads them, and
 * a text far larger than its first buffer. */
#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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
	suite_add_tcase(s, tc);
	return s;
}
