/* Unit tests for the board's CYCLIC service in protocol version 2
 * (firmware/board.c), driven through the fake HAL of board_v2_bench.h: a due
 * record drives and answers, a record without DUE drives silently, records
 * of other sessions or bad records are never driven, and only a valid record
 * of its own session feeds the watchdog. Versions, registration and the
 * stale session are in test_board_v2.c. docs/PROTOCOL.md, "Version 2", is the
 * contract checked. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "../../firmware/board.h"
#include "board_v2_bench.h"
#include "check_main.h"

/* ---- board: CYCLIC service -------------------------------------------- */

START_TEST(due_record_drives_outputs_and_answers_an_update)
{
	uint32_t ok_before;
	join(&rig, SESSION_ID, SLOT, 500);
	ok_before = rig.board.counters.frames_ok;
	now_ms += 10;

	send_record(&rig, 0x4321, SESSION_TAG, VMAC_CYCLIC_DUE, 0x05, -250);
	expect_driving(&rig, 0x05, -250, "due record 0x05/-250");
	expect_update_reply(&rig, 0x4321, SESSION_ID, 0x05, -250, "due record 0x05/-250");
	ck_assert_msg(rig.board.last_valid_ms == now_ms, "due record at %llu ms left last_valid_ms at %llu",
	              (unsigned long long)now_ms, (unsigned long long)rig.board.last_valid_ms);
	ck_assert_msg(rig.board.counters.frames_ok == ok_before + 1, "due record: frames_ok went %u -> %u, want +1",
	              (unsigned)ok_before, (unsigned)rig.board.counters.frames_ok);
	expect_state(&rig, VMAC_BOARD_KNOWN, "after a due record");
}
END_TEST

/* The byte example of docs/PROTOCOL.md, end to end: the frame in, the
 * board's answer out. */
START_TEST(board_answers_the_cyclic_example_of_protocol_md_byte_for_byte)
{
	static const uint8_t frame[] = {
	    0x56, 0x4D, 0x02, 0x00, 0x01, 0x02, 0x00, 0x00, 0x00, 0x00, 0xFF, 0x04, 0x02, 0x00,
	    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x03, 0x01, 0x05, 0xFF, 0x06,
	};
	static const uint8_t want[] = {
	    0x56, 0x4D, 0x02, 0x01, 0x01, 0x02, 0x00, 0x03, 0x00, 0x01, 0x00, 0x02, 0x0C, /* header */
	    0x01, 0x00, 0x64, 0x00, 0x00, 0x00, 0x00, 0x00, 0x07, 0x05, 0xFF, 0x06,       /* inputs */
	};
	rig.io.inputs.digital = 0x01;
	rig.io.inputs.analog[0] = 100;
	rig.io.inputs.analog[1] = 0;
	rig.io.inputs.encoder = 7;
	join(&rig, 0x00030001u, 1, 500);
	deliver(&rig, frame, sizeof(frame));
	expect_bytes(rig.reply, rig.reply_len, want, (int)sizeof(want), "answer to the CYCLIC example");
}
END_TEST

START_TEST(record_without_due_drives_and_feeds_the_watchdog_silently)
{
	join(&rig, SESSION_ID, SLOT, 100); /* at 1000 ms */
	now_ms = START_MS + 80;
	send_record(&rig, 2, SESSION_TAG, 0, 0x05, -250);
	expect_silent(&rig, "record without DUE");
	expect_driving(&rig, 0x05, -250, "record without DUE");
	ck_assert_msg(rig.board.last_valid_ms == now_ms, "record without DUE at %llu ms left last_valid_ms at %llu",
	              (unsigned long long)now_ms, (unsigned long long)rig.board.last_valid_ms);
	ck_assert_msg(vmac_board_poll(&rig.board, START_MS + 179) == 0,
	              "watchdog tripped at 1179 ms: the record at 1080 ms did not feed it");
	ck_assert_msg(vmac_board_poll(&rig.board, START_MS + 180) == 1, "watchdog did not trip 100 ms after 1080 ms");
}
END_TEST

START_TEST(record_of_another_session_drives_nothing_and_does_not_feed)
{
	int writes_before;
	uint32_t ignored_before;

	join(&rig, SESSION_ID, SLOT, 100); /* at 1000 ms */
	send_record(&rig, 1, SESSION_TAG, 0, 0x5A, -750);
	expect_driving(&rig, 0x5A, -750, "own record 0x5a/-750");
	writes_before = rig.io.n_writes;
	ignored_before = rig.board.counters.frames_ignored;

	now_ms = START_MS + 50;
	send_record(&rig, 2, SESSION_TAG - 1, VMAC_CYCLIC_DUE, 0x7F, 1000);
	expect_silent(&rig, "record tagged 4 (an older session)");
	expect_no_write_since(&rig, writes_before, "record tagged 4");
	ck_assert_msg(rig.board.counters.frames_ignored == ignored_before + 1,
	              "record tagged 4: frames_ignored +%u, want +1",
	              (unsigned)(rig.board.counters.frames_ignored - ignored_before));
	ck_assert_msg(rig.board.last_valid_ms == START_MS, "record tagged 4 moved last_valid_ms to %llu",
	              (unsigned long long)rig.board.last_valid_ms);

	now_ms = START_MS + 100;
	ck_assert_msg(vmac_board_poll(&rig.board, now_ms) == 1,
	              "watchdog did not trip at 1100 ms: the record tagged 4 at 1050 ms fed it");
	expect_state(&rig, VMAC_BOARD_UNKNOWN, "after the watchdog trip");
	expect_driving(&rig, 0, 0, "after the watchdog trip");
}
END_TEST

START_TEST(bad_record_of_our_session_is_malformed_and_never_driven)
{
	static const struct {
		uint8_t flags, digital;
		int16_t pwm;
		const char *what;
	} cases[] = {
	    {0x02, 0x01, 10, "flag bit 1"},
	    {VMAC_CYCLIC_DUE | 0x80, 0x01, 10, "DUE and flag bit 7"},
	    {VMAC_CYCLIC_DUE, 0x81, 10, "digital bit 7"},
	    {VMAC_CYCLIC_DUE, 0x01, 1001, "pwm 1001"},
	    {VMAC_CYCLIC_DUE, 0x01, -1001, "pwm -1001"},
	};
	int writes_before;
	uint32_t malformed_before;
	size_t i;
	char when[80];

	join(&rig, SESSION_ID, SLOT, 100); /* at 1000 ms */
	send_record(&rig, 1, SESSION_TAG, 0, 0x5A, -750);
	writes_before = rig.io.n_writes;
	now_ms = START_MS + 50;
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		malformed_before = rig.board.counters.frames_malformed;
		send_record(&rig, (uint16_t)(10 + i), SESSION_TAG, cases[i].flags, cases[i].digital, cases[i].pwm);
		snprintf(when, sizeof(when), "our record with %s", cases[i].what);
		expect_silent(&rig, when);
		expect_no_write_since(&rig, writes_before, when);
		ck_assert_msg(rig.board.counters.frames_malformed == malformed_before + 1,
		              "%s: frames_malformed +%u, want +1", when,
		              (unsigned)(rig.board.counters.frames_malformed - malformed_before));
	}
	expect_driving(&rig, 0x5A, -750, "after bad records");
	ck_assert_msg(vmac_board_poll(&rig.board, START_MS + 100) == 1, "bad records at 1050 ms fed the watchdog");
}
END_TEST

/* PROTOCOL.md: "tag != id >> 16: not for it"; only "its tag, but flags or
 * outputs out of range" is malformed. Another board's bad record is no
 * fault of this board's link. */
START_TEST(bad_record_of_another_session_is_ignored_not_malformed)
{
	uint32_t malformed_before, ignored_before;
	int writes_before;

	join(&rig, SESSION_ID, SLOT, 500);
	writes_before = rig.io.n_writes;
	malformed_before = rig.board.counters.frames_malformed;
	ignored_before = rig.board.counters.frames_ignored;
	send_record(&rig, 1, SESSION_TAG + 1, VMAC_CYCLIC_DUE, 0x01, 1001);
	send_record(&rig, 2, 0, 0x02, 0, 0);
	expect_silent(&rig, "bad records of other sessions");
	expect_no_write_since(&rig, writes_before, "bad records of other sessions");
	ck_assert_msg(rig.board.counters.frames_malformed == malformed_before &&
	                  rig.board.counters.frames_ignored == ignored_before + 2,
	              "a bad record tagged 6 and an empty record with flag bit 1 at our offset counted %u malformed "
	              "and %u ignored, want 0 malformed and 2 ignored (not our tag: not for us)",
	              (unsigned)(rig.board.counters.frames_malformed - malformed_before),
	              (unsigned)(rig.board.counters.frames_ignored - ignored_before));
}
END_TEST

START_TEST(frame_not_covering_our_offset_is_ignored)
{
	static const struct {
		uint16_t first;
		unsigned count;
		const char *what;
	} frames[] = {
	    {0, SLOT, "offsets 0..36"},
	    {SLOT + 1, 10, "offsets 38..47"},
	    {240, 240, "offsets 240..479"},
	};
	struct cyclic_frame f;
	uint32_t ignored_before;
	int writes_before;
	size_t i;
	unsigned j;

	join(&rig, SESSION_ID, SLOT, 100); /* at 1000 ms */
	writes_before = rig.io.n_writes;
	now_ms = START_MS + 50;
	for (i = 0; i < sizeof(frames) / sizeof(frames[0]); i++) {
		cyclic_new(&f, (uint16_t)(20 + i), frames[i].first, frames[i].count);
		for (j = 0; j < frames[i].count; j++) /* every record ours, but at other offsets */
			cyclic_set(&f, (uint16_t)(frames[i].first + j), SESSION_TAG, VMAC_CYCLIC_DUE, 0x7F, 1000);
		ignored_before = rig.board.counters.frames_ignored;
		send_cyclic(&rig, &f);
		expect_silent(&rig, frames[i].what);
		expect_no_write_since(&rig, writes_before, frames[i].what);
		ck_assert_msg(rig.board.counters.frames_ignored == ignored_before + 1,
		              "CYCLIC of %s: frames_ignored +%u, want +1", frames[i].what,
		              (unsigned)(rig.board.counters.frames_ignored - ignored_before));
	}
	ck_assert_msg(vmac_board_poll(&rig.board, START_MS + 100) == 1,
	              "watchdog did not trip at 1100 ms: a CYCLIC without our offset fed it");
}
END_TEST

START_TEST(record_at_either_edge_of_a_frame_is_read)
{
	struct cyclic_frame f;

	join(&rig, SESSION_ID, SLOT, 500);
	cyclic_new(&f, 30, 0, SLOT + 1); /* our record last */
	cyclic_set(&f, SLOT, SESSION_TAG, VMAC_CYCLIC_DUE, 0x01, 1);
	send_cyclic(&rig, &f);
	expect_update_reply(&rig, 30, SESSION_ID, 0x01, 1, "our record last in the frame");

	cyclic_new(&f, 31, SLOT, VMAC_CYCLIC_RECORDS_MAX); /* our record first */
	cyclic_set(&f, SLOT, SESSION_TAG, VMAC_CYCLIC_DUE, 0x02, -2);
	send_cyclic(&rig, &f);
	expect_update_reply(&rig, 31, SESSION_ID, 0x02, -2, "our record first in a 240-record frame");

	cyclic_new(&f, 32, SLOT, 1); /* our record alone */
	cyclic_set(&f, SLOT, SESSION_TAG, VMAC_CYCLIC_DUE, 0x03, 3);
	send_cyclic(&rig, &f);
	expect_update_reply(&rig, 32, SESSION_ID, 0x03, 3, "our record alone in the frame");
}
END_TEST

START_TEST(board_without_session_or_offset_ignores_cyclic)
{
	int writes_before = rig.io.n_writes;

	expect_offset(&rig, VMAC_OFFSET_NONE, "fresh board");
	send_record(&rig, 1, SESSION_TAG, VMAC_CYCLIC_DUE, 0x05, -250);
	expect_silent(&rig, "unknown board, CYCLIC");
	expect_no_write_since(&rig, writes_before, "unknown board, CYCLIC");
	expect_state(&rig, VMAC_BOARD_UNKNOWN, "unknown board after a CYCLIC");

	register_v2(&rig, SESSION_ID, 100); /* at 1000 ms, no OFFSET */
	writes_before = rig.io.n_writes;
	now_ms = START_MS + 50;
	send_record(&rig, 2, SESSION_TAG, VMAC_CYCLIC_DUE, 0x05, -250);
	expect_silent(&rig, "registered board without offset, CYCLIC");
	expect_no_write_since(&rig, writes_before, "registered board without offset, CYCLIC");
	ck_assert_msg(vmac_board_poll(&rig.board, START_MS + 100) == 1,
	              "watchdog did not trip at 1100 ms: a CYCLIC fed a board that holds no offset");
}
END_TEST

START_TEST(cyclic_queued_after_the_watchdog_ran_out_does_not_revive)
{
	int writes_before;

	join(&rig, SESSION_ID, SLOT, 100); /* at 1000 ms */
	send_record(&rig, 1, SESSION_TAG, 0, 0x5A, -750);

	/* No poll in between: receive must enforce the watchdog itself. */
	now_ms = START_MS + 100;
	send_record(&rig, 2, SESSION_TAG, VMAC_CYCLIC_DUE, 0x7F, 1000);
	expect_silent(&rig, "CYCLIC arriving as the watchdog expires");
	expect_state(&rig, VMAC_BOARD_UNKNOWN, "after a CYCLIC arriving as the watchdog expires");
	expect_driving(&rig, 0, 0, "after a CYCLIC arriving as the watchdog expires");
	ck_assert_msg(rig.board.counters.watchdog_trips == 1, "watchdog_trips %u, want 1",
	              (unsigned)rig.board.counters.watchdog_trips);

	writes_before = rig.io.n_writes;
	now_ms = START_MS + 150;
	send_record(&rig, 3, SESSION_TAG, VMAC_CYCLIC_DUE, 0x7F, 1000);
	expect_silent(&rig, "CYCLIC after the watchdog tripped");
	expect_no_write_since(&rig, writes_before, "CYCLIC after the watchdog tripped");
	expect_never_drove(&rig, 0x7F, 1000, "CYCLIC records queued after the watchdog");
}
END_TEST

START_TEST(cyclic_the_decoder_refuses_is_malformed_to_the_board)
{
	struct cyclic_frame f;
	int writes_before;

	join(&rig, SESSION_ID, SLOT, 500);
	writes_before = rig.io.n_writes;
	cyclic_new(&f, 1, 0, SPAN);
	cyclic_set(&f, SLOT, SESSION_TAG, VMAC_CYCLIC_DUE, 0x7F, 1000);
	deliver(&rig, f.bytes, (size_t)f.len - 1);
	expect_silent(&rig, "CYCLIC one byte short");
	f.bytes[9] = 0x25; /* device id 0x00000025 */
	send_cyclic(&rig, &f);
	expect_silent(&rig, "CYCLIC with a device id");
	f.bytes[9] = 0;
	f.bytes[3] = VMAC_FLAG_REPLY;
	send_cyclic(&rig, &f);
	expect_silent(&rig, "CYCLIC with the REPLY flag");
	expect_no_write_since(&rig, writes_before, "refused CYCLIC frames");
	ck_assert_msg(rig.board.counters.frames_malformed == 3,
	              "frames_malformed %u after three refused CYCLICs, want 3",
	              (unsigned)rig.board.counters.frames_malformed);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("board_cyclic");
	TCase *tc;

	tc = tcase_create("board_cyclic");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, due_record_drives_outputs_and_answers_an_update);
	tcase_add_test(tc, board_answers_the_cyclic_example_of_protocol_md_byte_for_byte);
	tcase_add_test(tc, record_without_due_drives_and_feeds_the_watchdog_silently);
	tcase_add_test(tc, record_of_another_session_drives_nothing_and_does_not_feed);
	tcase_add_test(tc, bad_record_of_our_session_is_malformed_and_never_driven);
	tcase_add_test(tc, bad_record_of_another_session_is_ignored_not_malformed);
	tcase_add_test(tc, frame_not_covering_our_offset_is_ignored);
	tcase_add_test(tc, record_at_either_edge_of_a_frame_is_read);
	tcase_add_test(tc, board_without_session_or_offset_ignores_cyclic);
	tcase_add_test(tc, cyclic_queued_after_the_watchdog_ran_out_does_not_revive);
	tcase_add_test(tc, cyclic_the_decoder_refuses_is_malformed_to_the_board);
	suite_add_tcase(s, tc);

	return s;
}
