/* Unit tests for the board's side of protocol version 2 (firmware/board.c),
 * driven through the fake HAL of board_v2_bench.h: the version it announces
 * and speaks, registration with SIZE, OFFSET and OFFSET_GET, and the stale
 * session (the tag keeps a dropped board off its offset's next holder). The
 * CYCLIC service and its watchdog are in test_board_cyclic.c.
 * docs/PROTOCOL.md, "Version 2", is the contract checked. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "../../firmware/board.h"
#include "board_v2_bench.h"
#include "check_main.h"

/* ---- board: versions -------------------------------------------------- */

START_TEST(v2_board_announces_version_2_to_a_version_1_discover)
{
	send_discover(&rig, 0x4242);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.channel == VMAC_CH_SYSTEM && rig.answer.op == VMAC_SYS_ANNOUNCE,
	              "DISCOVER of version 1 got %d bytes, channel 0x%02x op 0x%02x, want an ANNOUNCE", rig.reply_len,
	              rig.answer.channel, rig.answer.op);
	ck_assert_msg(rig.reply[2] == 2 && rig.answer.version == 2,
	              "a version-2 board announced version %u, want its highest, 2", rig.reply[2]);
	ck_assert_msg(rig.answer.seq == 0x4242, "ANNOUNCE seq 0x%04x, want the DISCOVER's 0x4242", rig.answer.seq);
	ck_assert_msg(rig.board.id.protocol == 2, "identity.protocol 0 became %u, want 2 (VMAC_PROTO_VERSION)",
	              rig.board.id.protocol);
}
END_TEST

START_TEST(v1_board_announces_version_1_and_treats_version_2_as_malformed)
{
	int writes_before;
	struct vmac_msg m;

	bench_init(&rig, "bench-1", BOARD_MINOR, 1);
	send_discover(&rig, 1);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_SYS_ANNOUNCE,
	              "version-1 board: DISCOVER got %d bytes op 0x%02x, want an ANNOUNCE", rig.reply_len,
	              rig.answer.op);
	ck_assert_msg(rig.reply[2] == 1 && rig.answer.version == 1, "a version-1 board announced version %u, want 1",
	              rig.reply[2]);

	send_register(&rig, 2, SESSION_ID, 500, 2);
	expect_silent(&rig, "version-1 board, REGISTER of version 2");
	expect_state(&rig, VMAC_BOARD_UNKNOWN, "version-1 board after a REGISTER of version 2");
	ck_assert_msg(rig.board.counters.frames_malformed == 1, "REGISTER of version 2: frames_malformed %u, want 1",
	              (unsigned)rig.board.counters.frames_malformed);

	m = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 3);
	send_msg(&rig, &m);
	expect_silent(&rig, "version-1 board, DISCOVER of version 2");

	send_register(&rig, 1, SESSION_ID, 500, 4);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_REGISTER && rig.answer.version == 1,
	              "version-1 board: REGISTER of version 1 got %d bytes op 0x%02x version %u, want a version-1 ack",
	              rig.reply_len, rig.answer.op, rig.answer.version);
	expect_state(&rig, VMAC_BOARD_KNOWN, "version-1 board after REGISTER of version 1");
	writes_before = rig.io.n_writes;

	send_op(&rig, 2, VMAC_OP_SIZE, SESSION_ID, 5);
	expect_silent(&rig, "version-1 board, SIZE");
	send_offset(&rig, SESSION_ID, SLOT, 6);
	expect_silent(&rig, "version-1 board, OFFSET");
	expect_offset(&rig, VMAC_OFFSET_NONE, "version-1 board after an OFFSET of version 2");
	send_record(&rig, 7, SESSION_TAG, VMAC_CYCLIC_DUE, 0x05, -250);
	expect_silent(&rig, "version-1 board, CYCLIC");
	expect_no_write_since(&rig, writes_before, "version-1 board, CYCLIC");
	ck_assert_msg(rig.board.counters.frames_malformed == 5,
	              "version-1 board: frames_malformed %u after five version-2 frames, want 5",
	              (unsigned)rig.board.counters.frames_malformed);
}
END_TEST

/* ---- board: registration of version 2 --------------------------------- */

START_TEST(v2_registration_size_offset_and_offset_get)
{
	send_register(&rig, 2, SESSION_ID, 500, 100);
	expect_reply(&rig, VMAC_OP_REGISTER, 100, SESSION_ID, "REGISTER of version 2");
	expect_offset(&rig, VMAC_OFFSET_NONE, "after REGISTER");

	send_op(&rig, 2, VMAC_OP_SIZE, SESSION_ID, 101);
	expect_reply(&rig, VMAC_OP_SIZE, 101, SESSION_ID, "SIZE");
	ck_assert_msg(rig.answer.u.record_size == VMAC_CYCLIC_RECORD_LEN, "SIZE answered %u bytes per record, want 6",
	              rig.answer.u.record_size);

	send_op(&rig, 2, VMAC_OP_OFFSET_GET, SESSION_ID, 102);
	expect_reply(&rig, VMAC_OP_OFFSET_GET, 102, SESSION_ID, "OFFSET_GET before OFFSET");
	ck_assert_msg(rig.answer.u.offset == VMAC_OFFSET_NONE, "OFFSET_GET before any OFFSET answered %u, want 0xffff",
	              rig.answer.u.offset);

	send_offset(&rig, SESSION_ID, SLOT, 103);
	expect_reply(&rig, VMAC_OP_OFFSET, 103, SESSION_ID, "OFFSET 37");
	ck_assert_msg(rig.answer.u.offset == SLOT, "OFFSET 37 echoed as %u", rig.answer.u.offset);
	expect_offset(&rig, SLOT, "after OFFSET 37");

	send_op(&rig, 2, VMAC_OP_OFFSET_GET, SESSION_ID, 104);
	expect_reply(&rig, VMAC_OP_OFFSET_GET, 104, SESSION_ID, "OFFSET_GET after OFFSET 37");
	ck_assert_msg(rig.answer.u.offset == SLOT, "OFFSET_GET after OFFSET 37 answered %u", rig.answer.u.offset);
	expect_offset(&rig, SLOT, "after OFFSET_GET");
	expect_state(&rig, VMAC_BOARD_KNOWN, "after registration");
}
END_TEST

START_TEST(new_register_forgets_the_offset)
{
	join(&rig, SESSION_ID, SLOT, 500);
	register_v2(&rig, NEW_SESSION_ID, 500);
	expect_offset(&rig, VMAC_OFFSET_NONE, "after a new REGISTER");
	send_op(&rig, 2, VMAC_OP_OFFSET_GET, NEW_SESSION_ID, 7);
	expect_reply(&rig, VMAC_OP_OFFSET_GET, 7, NEW_SESSION_ID, "OFFSET_GET after a new REGISTER");
	ck_assert_msg(rig.answer.u.offset == VMAC_OFFSET_NONE,
	              "OFFSET_GET after a new REGISTER answered %u, want 0xffff", rig.answer.u.offset);
}
END_TEST

START_TEST(shutdown_sleep_and_watchdog_trip_forget_the_offset)
{
	struct vmac_msg m;

	join(&rig, SESSION_ID, SLOT, 500);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, SESSION_ID, 8);
	send_msg(&rig, &m);
	expect_reply(&rig, VMAC_OP_SHUTDOWN, 8, SESSION_ID, "SHUTDOWN");
	expect_offset(&rig, VMAC_OFFSET_NONE, "after SHUTDOWN");
	register_v2(&rig, SESSION_ID, 500);
	send_op(&rig, 2, VMAC_OP_OFFSET_GET, SESSION_ID, 9);
	ck_assert_msg(rig.answer.u.offset == VMAC_OFFSET_NONE,
	              "OFFSET_GET after SHUTDOWN and REGISTER answered %u, want 0xffff", rig.answer.u.offset);

	join(&rig, SESSION_ID, SLOT, 500);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_SLEEP, SESSION_ID, 10);
	m.u.sleep_s = 1;
	send_msg(&rig, &m);
	expect_reply(&rig, VMAC_OP_SLEEP, 10, SESSION_ID, "SLEEP");
	expect_offset(&rig, VMAC_OFFSET_NONE, "after SLEEP");

	now_ms += 1000;
	vmac_board_poll(&rig.board, now_ms);
	join(&rig, SESSION_ID, SLOT, 100);
	now_ms += 100;
	ck_assert_msg(vmac_board_poll(&rig.board, now_ms) == 1, "no watchdog trip 100 ms after the last frame");
	expect_offset(&rig, VMAC_OFFSET_NONE, "after a watchdog trip");
}
END_TEST

START_TEST(offset_from_another_session_is_refused)
{
	join(&rig, SESSION_ID, SLOT, 500);
	send_offset(&rig, OTHER_ID, 99, 12);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_ERROR &&
	                  rig.answer.u.error.code == VMAC_BERR_NOT_REGISTERED,
	              "OFFSET of another session got %d bytes op 0x%02x code %u, want ERROR 1", rig.reply_len,
	              rig.answer.op, rig.answer.u.error.code);
	expect_offset(&rig, SLOT, "after an OFFSET of another session");
}
END_TEST

/* ---- board: the tag protects the offset's next holder ----------------- */

START_TEST(stale_board_never_drives_the_new_holder_of_its_offset)
{
	int stale_writes;
	unsigned tick;
	char when[80];

	/* rig: the stale board, generation 5 of slot 37; the host dropped it
	 * (it never heard) and gave offset 37 to rival, generation 6. */
	join(&rig, SESSION_ID, SLOT, 500);
	join(&rival, NEW_SESSION_ID, SLOT, 500);
	send_record(&rig, 1, SESSION_TAG, 0, 0x5A, -750);
	expect_driving(&rig, 0x5A, -750, "stale board before the takeover");
	stale_writes = rig.io.n_writes;

	for (tick = 0; tick < 8; tick++) {
		struct cyclic_frame f;
		now_ms = START_MS + 100 * (tick + 1);
		cyclic_new(&f, (uint16_t)(200 + tick), 0, SPAN);
		cyclic_set(&f, SLOT, SESSION_TAG + 1, VMAC_CYCLIC_DUE, 0x7F, (int16_t)(1000 - tick));

		snprintf(when, sizeof(when), "tick %u, record tagged 6", tick);
		send_cyclic(&rival, &f);
		expect_update_reply(&rival, (uint16_t)(200 + tick), NEW_SESSION_ID, 0x7F, (int16_t)(1000 - tick), when);
		expect_driving(&rival, 0x7F, (int16_t)(1000 - tick), when);

		send_cyclic(&rig, &f);
		expect_silent(&rig, when);
		expect_never_drove(&rig, 0x7F, (int16_t)(1000 - tick), when);
	}
	/* The stale board went safe when its own 500 ms ran out, and only that. */
	ck_assert_msg(rig.io.n_writes == stale_writes + 1, "stale board wrote its outputs %d times, want once (off)",
	              rig.io.n_writes - stale_writes);
	expect_driving(&rig, 0, 0, "stale board after its watchdog");
	expect_state(&rig, VMAC_BOARD_UNKNOWN, "stale board after its watchdog");
	ck_assert_msg(rig.board.counters.watchdog_trips == 1, "stale board: watchdog_trips %u, want 1",
	              (unsigned)rig.board.counters.watchdog_trips);
	expect_state(&rival, VMAC_BOARD_KNOWN, "new holder");

	/* And the other way: a late record of generation 5 never reaches the new holder. */
	stale_writes = rival.io.n_writes;
	send_record(&rival, 300, SESSION_TAG, VMAC_CYCLIC_DUE, 0x01, -1);
	expect_silent(&rival, "new holder, record tagged 5");
	expect_no_write_since(&rival, stale_writes, "new holder, record tagged 5");
}
END_TEST

/* A record of tag 0 is an empty record (PROTOCOL.md), what cyclic_begin
 * fills every unused offset with. A session whose generation is 0
 * (device_id < 0x10000) must not take empty records for its own: they would
 * feed its watchdog, and drive it off, whatever the host thinks of it. */
START_TEST(empty_record_never_feeds_a_session_of_generation_0)
{
	struct cyclic_frame f;
	uint32_t ok_before;
	int writes_before;

	join(&rig, 0x00000025u, SLOT, 100); /* at 1000 ms */
	send_record(&rig, 1, 0, 0, 0x5A, -750);
	writes_before = rig.io.n_writes;
	ok_before = rig.board.counters.frames_ok;

	now_ms = START_MS + 50;
	cyclic_new(&f, 2, 0, SPAN); /* every record empty */
	send_cyclic(&rig, &f);
	expect_silent(&rig, "empty record at our offset");
	ck_assert_msg(rig.io.n_writes == writes_before && rig.board.counters.frames_ok == ok_before &&
	                  rig.board.last_valid_ms == START_MS,
	              "an empty record (tag 0) was taken as the record of session 0x00000025: %d writes, frames_ok "
	              "+%u, last_valid_ms %llu (want no write, +0, 1000)",
	              rig.io.n_writes - writes_before, (unsigned)(rig.board.counters.frames_ok - ok_before),
	              (unsigned long long)rig.board.last_valid_ms);
	ck_assert_msg(vmac_board_poll(&rig.board, START_MS + 100) == 1,
	              "watchdog did not trip at 1100 ms: an empty record at 1050 ms fed it");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("board_v2");
	TCase *tc;

	tc = tcase_create("board_versions");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, v2_board_announces_version_2_to_a_version_1_discover);
	tcase_add_test(tc, v1_board_announces_version_1_and_treats_version_2_as_malformed);
	suite_add_tcase(s, tc);

	tc = tcase_create("board_registration");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, v2_registration_size_offset_and_offset_get);
	tcase_add_test(tc, new_register_forgets_the_offset);
	tcase_add_test(tc, shutdown_sleep_and_watchdog_trip_forget_the_offset);
	tcase_add_test(tc, offset_from_another_session_is_refused);
	suite_add_tcase(s, tc);

	tc = tcase_create("board_takeover");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, stale_board_never_drives_the_new_holder_of_its_offset);
	tcase_add_test(tc, empty_record_never_feeds_a_session_of_generation_0);
	suite_add_tcase(s, tc);

	return s;
}
