/* Unit tests for the SYNC frame (docs/PROTOCOL.md, "SYNC"): its bytes in
 * the codec (core/proto), and a board (firmware/board.c) feeding its clock
 * from SYNC frames with the receive times its caller passes in: the clock
 * locks onto a host whose counter differs by an offset and a drift, a SYNC
 * is never answered, never drives, never feeds the watchdog, and the boards
 * that cannot use it (version 1, no receive time, sealed to an unkeyed
 * board) ignore it without counting it malformed, as every board now
 * ignores a system op of a later protocol. The clock's filter itself is test_clock.c's. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../core/proto/proto.h"
#include "../../firmware/board.h"
#include "../../firmware/report.h"
#include "check_main.h"
#include "proto_helpers.h"

#define SESSION 0x00050025u
#define HOST_START_NS 5000000000ull /* the host's clock at the first SYNC */

/* ---- the codec --------------------------------------------------------- */

static struct vmac_msg sync_msg(uint16_t seq, uint64_t host_ns)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_SYNC;
	m.seq = seq;
	m.u.sync.host_ns = host_ns;
	return m;
}

START_TEST(sync_has_pinned_wire_bytes_and_round_trips)
{
	static const uint8_t want[] = {
	    'V',  'M',  0x02, 0x00,                         /* magic, version 2, flags */
	    0x01, 0x02,                                     /* seq: the sync sequence number */
	    0x00, 0x00, 0x00, 0x00,                         /* device 0: the system channel */
	    0xFF, 0x05, 0x08,                               /* system channel, SYNC, 8 bytes */
	    0x00, 0x00, 0x12, 0x34, 0x56, 0x78, 0x9A, 0xBC, /* host time, ns */
	};
	struct vmac_msg m = sync_msg(0x0102, 0x123456789ABCull), back;
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(&m, buf, sizeof(buf)), rc;

	expect_bytes(buf, n, want, (int)sizeof(want), "SYNC");
	rc = decode_exact(want, sizeof(want), &back);
	ck_assert_msg(rc == 0, "decode of the pinned SYNC returned %s", errname(rc));
	ck_assert_msg(back.op == VMAC_SYS_SYNC && back.channel == VMAC_CH_SYSTEM && back.seq == 0x0102 &&
	                  back.u.sync.host_ns == 0x123456789ABCull,
	              "pinned SYNC decoded as op 0x%02x seq 0x%04x host %llx", back.op, back.seq,
	              (unsigned long long)back.u.sync.host_ns);
	vmac_proto_sync_stamp(buf, 0xFEDCBA9876543210ull);
	rc = decode_exact(buf, (size_t)n, &back);
	ck_assert_msg(rc == 0 && back.u.sync.host_ns == 0xFEDCBA9876543210ull,
	              "a stamped SYNC decoded as %s, host %llx, want the stamp", errname(rc),
	              (unsigned long long)back.u.sync.host_ns);
	ck_assert_str_eq(vmac_proto_opname(VMAC_CH_SYSTEM, VMAC_SYS_SYNC), "SYNC");
}
END_TEST

START_TEST(sync_is_refused_in_version_1_as_a_reply_and_at_other_lengths)
{
	struct vmac_msg m = sync_msg(1, 42);
	uint8_t buf[VMAC_FRAME_MAX + 4];
	int n;

	m.version = 1;
	expect_encode_err(&m, VMAC_EPROTO_OP, "SYNC of version 1");
	m = sync_msg(1, 42);
	m.flags = VMAC_FLAG_REPLY;
	expect_encode_err(&m, VMAC_EPROTO_OP, "SYNC as a reply");
	m = sync_msg(1, 42);
	m.device_id = SESSION;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "SYNC with a device id");

	m = sync_msg(1, 42);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_int_eq(n, VMAC_HDR_LEN + VMAC_SYNC_LEN);
	buf[2] = 1; /* the same bytes as version 1 */
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "SYNC of version 1");
	buf[2] = 2;
	buf[3] = VMAC_FLAG_REPLY;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "SYNC as a reply");
	buf[3] = 0;
	buf[12] = 7; /* seven bytes of time */
	expect_decode_err(buf, (size_t)n - 1, VMAC_EPROTO_PAYLOAD, "SYNC of 7 data bytes");
	buf[12] = 9;
	buf[n] = 0;
	expect_decode_err(buf, (size_t)n + 1, VMAC_EPROTO_PAYLOAD, "SYNC of 9 data bytes");
	buf[12] = 8;
	buf[9] = 1; /* device id 1 on the system channel */
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "SYNC with a device id");
}
END_TEST

/* ---- the board ---------------------------------------------------------- */

struct fake_io {
	int writes;
};

static void fake_read(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
}

static void fake_write(void *ctx, const struct vmac_outputs *out)
{
	(void)out;
	((struct fake_io *)ctx)->writes++;
}

static const struct vmac_board_io fake_hal = {fake_read, fake_write};

static void board_start(struct vmac_board *b, struct fake_io *io, uint8_t protocol)
{
	struct vmac_board_identity id;
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "motor");
	strcpy(id.board, "sync-1");
	id.major = 3;
	id.minor = 7;
	id.protocol = protocol;
	memset(io, 0, sizeof(*io));
	vmac_board_init(b, &id, &fake_hal, io, 0);
}

/* The board's counter at host time host_ns: offset_ns ahead, drift_ppb fast
 * from the first SYNC on. */
static uint64_t board_counter(uint64_t host_ns, int64_t offset_ns, int64_t drift_ppb)
{
	int64_t since = (int64_t)(host_ns - HOST_START_NS);
	return (uint64_t)((int64_t)host_ns + offset_ns + since / 1000000000 * drift_ppb +
	                  since % 1000000000 * drift_ppb / 1000000000);
}

/* n SYNC frames at 1 kHz from host time HOST_START_NS + first_ms ms, each
 * received 3 us after it left (a fixed path: the clock reads it as part of
 * host time). Returns the board's replies' total length (always 0). */
static int feed(struct vmac_board *b, int first_ms, int n, int64_t offset_ns, int64_t drift_ppb, int with_stamp)
{
	int k, replied = 0;
	for (k = 0; k < n; k++) {
		uint64_t host_ns = HOST_START_NS + (uint64_t)(first_ms + k) * 1000000u;
		struct vmac_msg m = sync_msg((uint16_t)(first_ms + k), host_ns);
		uint8_t frame[VMAC_FRAME_MAX], reply[VMAC_BOARD_REPLY_MAX];
		int len = vmac_proto_encode(&m, frame, sizeof(frame));
		uint64_t rx = board_counter(host_ns + 3000, offset_ns, drift_ppb);
		ck_assert_int_gt(len, 0);
		if (with_stamp)
			replied += vmac_board_receive_at(b, frame, (size_t)len, (uint64_t)(first_ms + k), rx, reply,
			                                 sizeof(reply));
		else
			replied +=
			    vmac_board_receive(b, frame, (size_t)len, (uint64_t)(first_ms + k), reply, sizeof(reply));
	}
	return replied;
}

START_TEST(board_clock_locks_onto_the_host_from_sync_frames)
{
	const int64_t offset_ns = -2500000000LL, drift_ppb = 150000; /* 2.5 s behind, 150 ppm fast */
	struct vmac_board b;
	struct fake_io io;
	int64_t offset, want;
	uint64_t bound, local;
	int replied;

	board_start(&b, &io, 2);
	replied = feed(&b, 0, 1500, offset_ns, drift_ppb, 1);
	ck_assert_msg(replied == 0, "the board answered SYNC frames with %d bytes, want silence", replied);
	ck_assert_msg(b.clock.state == VMAC_CLOCK_LOCKED, "after 1.5 s of SYNC at 1 kHz the clock is %s, want locked",
	              vmac_clock_state_name(b.clock.state));
	local = board_counter(HOST_START_NS + 1500000000ull, offset_ns, drift_ppb);
	ck_assert_int_eq(vmac_board_clock_offset(&b, local, &offset, &bound), 0);
	/* the board takes the host's send time for the arrival: the path's 3 us
	 * is in the offset (docs/TIME.md, "The clock model") */
	want = offset_ns + 1500 * drift_ppb / 1000 + 3000;
	ck_assert_msg(offset - want < 2000 && offset - want > -2000, "offset %lld ns, want %lld within 2 us",
	              (long long)offset, (long long)want);
	ck_assert_msg(bound <= VMAC_CLOCK_LOCK_NS, "bound %llu ns when locked", (unsigned long long)bound);
	ck_assert_msg(b.state == VMAC_BOARD_UNKNOWN && io.writes == 1 && b.counters.frames_ok == 0,
	              "SYNC changed the board: state %s, %d writes (1 at init), frames_ok %u",
	              vmac_board_state_name(b.state), io.writes, (unsigned)b.counters.frames_ok);
	ck_assert_msg(
	    b.counters.frames_malformed == 0 && b.counters.sync_ignored == 0 && b.clock.counters.accepted == 1500,
	    "malformed %u, sync_ignored %u, accepted %u: want 0, 0, 1500", (unsigned)b.counters.frames_malformed,
	    (unsigned)b.counters.sync_ignored, (unsigned)b.clock.counters.accepted);
}
END_TEST

START_TEST(sync_does_not_feed_the_watchdog_of_a_session)
{
	struct vmac_board b;
	struct fake_io io;
	struct vmac_msg reg;
	uint8_t frame[VMAC_FRAME_MAX], reply[VMAC_BOARD_REPLY_MAX];
	int len;

	board_start(&b, &io, 2);
	memset(&reg, 0, sizeof(reg));
	reg.version = 2;
	reg.device_id = SESSION;
	reg.op = VMAC_OP_REGISTER;
	reg.u.reg.major = 3;
	reg.u.reg.minor = 7;
	reg.u.reg.watchdog_ms = 100;
	len = vmac_proto_encode(&reg, frame, sizeof(frame));
	ck_assert_int_gt(vmac_board_receive(&b, frame, (size_t)len, 0, reply, sizeof(reply)), 0);
	ck_assert_int_eq(b.state, VMAC_BOARD_KNOWN);
	feed(&b, 1, 150, 0, 0, 1); /* 150 ms of SYNC and nothing else */
	ck_assert_msg(b.state == VMAC_BOARD_UNKNOWN && b.counters.watchdog_trips == 1,
	              "150 ms of SYNC alone: state %s, %u watchdog trips; want the 100 ms watchdog tripped",
	              vmac_board_state_name(b.state), (unsigned)b.counters.watchdog_trips);
}
END_TEST

START_TEST(boards_that_cannot_use_sync_ignore_it_without_counting_it_malformed)
{
	struct vmac_board b;
	struct fake_io io;
	struct vmac_msg m = sync_msg(9, HOST_START_NS);
	uint8_t frame[VMAC_SYNC_AUTH_HEAD_LEN + VMAC_AUTH_MAC_LEN], reply[VMAC_BOARD_REPLY_MAX];
	int len;

	board_start(&b, &io, 1); /* a board of version 1 */
	ck_assert_int_eq(feed(&b, 0, 20, 0, 0, 1), 0);
	ck_assert_msg(b.counters.frames_malformed == 0 && b.counters.sync_ignored == 20 &&
	                  b.clock.state == VMAC_CLOCK_UNSYNCED,
	              "version-1 board: malformed %u, sync_ignored %u, clock %s; want 0, 20, unsynced",
	              (unsigned)b.counters.frames_malformed, (unsigned)b.counters.sync_ignored,
	              vmac_clock_state_name(b.clock.state));

	board_start(&b, &io, 2); /* no receive time: vmac_board_receive */
	ck_assert_int_eq(feed(&b, 0, 20, 0, 0, 0), 0);
	ck_assert_msg(b.counters.frames_malformed == 0 && b.counters.sync_ignored == 20 &&
	                  b.clock.state == VMAC_CLOCK_UNSYNCED,
	              "without receive times: malformed %u, sync_ignored %u, clock %s; want 0, 20, unsynced",
	              (unsigned)b.counters.frames_malformed, (unsigned)b.counters.sync_ignored,
	              vmac_clock_state_name(b.clock.state));

	board_start(&b, &io, 2); /* a sealed SYNC to an unkeyed board: not its (test_sync_auth.c) */
	len = vmac_proto_sync_begin_auth(frame, sizeof(frame), 9, 1, 0, 1);
	ck_assert_int_gt(len, 0);
	vmac_proto_sync_stamp(frame, m.u.sync.host_ns);
	vmac_proto_sync_seal(frame, 0, (const uint8_t *)"0123456789abcdef");
	ck_assert_int_eq(vmac_board_receive_at(&b, frame, (size_t)len, 0, 1000, reply, sizeof(reply)), 0);
	ck_assert_msg(b.counters.frames_malformed == 0 && b.counters.sync_ignored == 1 &&
	                  b.clock.state == VMAC_CLOCK_UNSYNCED,
	              "sealed SYNC: malformed %u, sync_ignored %u, clock %s; want 0, 1, unsynced",
	              (unsigned)b.counters.frames_malformed, (unsigned)b.counters.sync_ignored,
	              vmac_clock_state_name(b.clock.state));
}
END_TEST

START_TEST(a_later_system_op_is_ignored_not_malformed)
{
	/* What SYNC is to firmware built before it: a host frame of the system
	 * channel with an op it does not know (here 0x06, 4 bytes of data). */
	uint8_t frame[] = {'V', 'M', 0x02, 0x00, 0x00, 0x07, 0, 0, 0, 0, 0xFF, 0x06, 0x04, 1, 2, 3, 4};
	uint8_t reply[VMAC_BOARD_REPLY_MAX];
	struct vmac_board b;
	struct fake_io io;

	board_start(&b, &io, 2);
	ck_assert_int_eq(vmac_board_receive_at(&b, frame, sizeof(frame), 0, 1000, reply, sizeof(reply)), 0);
	ck_assert_msg(b.counters.frames_ignored == 1 && b.counters.frames_malformed == 0,
	              "system op 0x06: ignored %u, malformed %u; want 1, 0", (unsigned)b.counters.frames_ignored,
	              (unsigned)b.counters.frames_malformed);
	frame[3] = VMAC_FLAG_REPLY; /* no board's reply has an op of later protocols */
	vmac_board_receive_at(&b, frame, sizeof(frame), 0, 1000, reply, sizeof(reply));
	frame[3] = 0;
	frame[9] = 1; /* a device id on the system channel */
	vmac_board_receive_at(&b, frame, sizeof(frame), 0, 1000, reply, sizeof(reply));
	frame[9] = 0;
	vmac_board_receive_at(&b, frame, sizeof(frame) - 1, 0, 1000, reply, sizeof(reply)); /* cut short */
	frame[11] = VMAC_SYS_ANNOUNCE; /* a known op, not as a request */
	vmac_board_receive_at(&b, frame, sizeof(frame), 0, 1000, reply, sizeof(reply));
	ck_assert_msg(b.counters.frames_ignored == 1 && b.counters.frames_malformed == 4,
	              "reply, device id, short, ANNOUNCE request: ignored %u, malformed %u; want 1, 4",
	              (unsigned)b.counters.frames_ignored, (unsigned)b.counters.frames_malformed);
}
END_TEST

static uint32_t no_episodes(const void *ctx)
{
	(void)ctx;
	return 0;
}

static size_t no_text(const void *ctx, const char *board, char *line, size_t len)
{
	(void)ctx;
	(void)board;
	(void)line;
	(void)len;
	return 0;
}

START_TEST(the_report_says_when_the_clock_locks_and_is_lost)
{
	struct vmac_plant_safety safety = {no_episodes, no_text, NULL};
	struct vmac_board b;
	struct vmac_report r, quiet;
	struct fake_io io;
	char line[VMAC_REPORT_LINE];
	uint64_t local;

	board_start(&b, &io, 2);
	vmac_report_init(&r, &b, &safety, 0);
	vmac_report_init(&quiet, &b, &safety, 1);
	feed(&b, 0, 1500, 1000000000LL, -100000, 1); /* 1 s ahead, 100 ppm slow */
	ck_assert_int_eq(vmac_report_next(&r, &b, &safety, line, sizeof(line)), 1);
	ck_assert_msg(strncmp(line, "sync-1: clock locked, offset +0.99", 34) == 0 && strstr(line, " drift -") &&
	                  strstr(line, " ppm, bound ") && strstr(line, " us"),
	              "the locked line reads '%s'", line);
	ck_assert_msg(vmac_report_next(&quiet, &b, &safety, line, sizeof(line)) == 0,
	              "--quiet said '%s' of a clock that locked", line);
	/* a minute without SYNC: holdover, then lost */
	local = board_counter(HOST_START_NS + 60000000000ull, 1000000000LL, -100000);
	ck_assert_int_eq(vmac_board_clock_poll(&b, local), VMAC_CLOCK_LOST);
	ck_assert_int_eq(vmac_report_next(&quiet, &b, &safety, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "sync-1: clock lost, acting on arrival");
	vmac_report_clock(&b, 1, line, sizeof(line));
	ck_assert_str_eq(line, "sync-1: clock lost, acting on arrival; sync accepted 1500, rejected 0, ignored 0");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("sync");
	TCase *tc = tcase_create("codec");
	tcase_add_test(tc, sync_has_pinned_wire_bytes_and_round_trips);
	tcase_add_test(tc, sync_is_refused_in_version_1_as_a_reply_and_at_other_lengths);
	suite_add_tcase(s, tc);
	tc = tcase_create("board");
	tcase_add_test(tc, board_clock_locks_onto_the_host_from_sync_frames);
	tcase_add_test(tc, sync_does_not_feed_the_watchdog_of_a_session);
	tcase_add_test(tc, boards_that_cannot_use_sync_ignore_it_without_counting_it_malformed);
	tcase_add_test(tc, a_later_system_op_is_ignored_not_malformed);
	tcase_add_test(tc, the_report_says_when_the_clock_locks_and_is_lost);
	suite_add_tcase(s, tc);
	return s;
}
