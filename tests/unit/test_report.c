/* The board's log lines (firmware/report.c), word for word as the tests
 * and docs/BOARD.md read them, from the one place vmac-board and the
 * Cortex-M3 firmware both make them. */
#include <check.h>
#include <string.h>

#include "../../firmware/report.h"
#include "check_main.h"

static void io_read(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
}

static void io_write(void *ctx, const struct vmac_outputs *out)
{
	(void)ctx;
	(void)out;
}

static const struct vmac_board_io io = {io_read, io_write};

static void make(struct vmac_board *b, struct vmac_plant *p)
{
	struct vmac_board_identity id;
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "washer");
	strcpy(id.board, "washer-1");
	vmac_plant_init(p, VMAC_PLANT_WASHER);
	vmac_board_init(b, &id, &io, NULL, 0);
}

START_TEST(a_change_is_said_once_in_the_words_the_tests_read)
{
	struct vmac_board b;
	struct vmac_plant p;
	struct vmac_plant_safety s;
	struct vmac_report r;
	char line[VMAC_REPORT_LINE];
	make(&b, &p);
	s = vmac_plant_safety_of(&p);
	vmac_report_init(&r, &b, &s, 0);
	ck_assert_int_eq(vmac_report_next(&r, &b, &s, line, sizeof(line)), 0);
	b.state = VMAC_BOARD_KNOWN;
	b.device_id = 0x00030025u;
	b.watchdog_ms = 500;
	b.outputs.digital = 0x05;
	b.outputs.pwm = -250;
	ck_assert_int_eq(vmac_report_next(&r, &b, &s, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "washer-1: state known device 0x00030025 watchdog 500 ms");
	ck_assert_int_eq(vmac_report_next(&r, &b, &s, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "washer-1: outputs digital=0x05 pwm=-250");
	ck_assert_int_eq(vmac_report_next(&r, &b, &s, line, sizeof(line)), 0);
	vmac_report_watchdog(&b, line, sizeof(line));
	ck_assert_str_eq(line, "washer-1: watchdog: no frame for 500 ms, outputs off");
}
END_TEST

START_TEST(quiet_says_only_leaving_a_session)
{
	struct vmac_board b;
	struct vmac_plant p;
	struct vmac_plant_safety s;
	struct vmac_report r;
	char line[VMAC_REPORT_LINE];
	make(&b, &p);
	s = vmac_plant_safety_of(&p);
	vmac_report_init(&r, &b, &s, 1);
	b.state = VMAC_BOARD_KNOWN;
	b.outputs.digital = 1;
	ck_assert_msg(vmac_report_next(&r, &b, &s, line, sizeof(line)) == 0, "quiet said: %s", line);
	b.state = VMAC_BOARD_UNKNOWN;
	b.outputs.digital = 0;
	ck_assert_int_eq(vmac_report_next(&r, &b, &s, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "washer-1: state unknown device 0x00000000 watchdog 500 ms");
	ck_assert_int_eq(vmac_report_next(&r, &b, &s, line, sizeof(line)), 0);
}
END_TEST

START_TEST(a_short_buffer_is_cut_not_overrun)
{
	struct vmac_board b;
	struct vmac_plant p;
	char line[12];
	make(&b, &p);
	memset(line, 'x', sizeof(line));
	vmac_report_watchdog(&b, line, 10);
	ck_assert_str_eq(line, "washer-1:");
	ck_assert_int_eq(line[10], 'x');
}
END_TEST

START_TEST(the_counters_line_names_auth_failed)
{
	struct vmac_board b;
	struct vmac_plant p;
	char line[VMAC_REPORT_LINE];
	make(&b, &p);
	b.counters.frames_ok = 4294967295u;
	b.counters.frames_malformed = 2;
	b.counters.frames_ignored = 3;
	b.counters.watchdog_trips = 4;
	b.counters.auth_failed = 17;
	vmac_report_counters(&b, line, sizeof(line));
	ck_assert_str_eq(line, "washer-1: frames ok 4294967295, malformed 2, ignored 3, watchdog trips 4, "
	                       "auth_failed 17");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("report");
	TCase *tc = tcase_create("report");
	tcase_add_test(tc, a_change_is_said_once_in_the_words_the_tests_read);
	tcase_add_test(tc, quiet_says_only_leaving_a_session);
	tcase_add_test(tc, a_short_buffer_is_cut_not_overrun);
	tcase_add_test(tc, the_counters_line_names_auth_failed);
	suite_add_tcase(s, tc);
	return s;
}
