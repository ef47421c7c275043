/* Unit tests for time-triggered I/O in the wire codec (core/proto): the
 * TIMED CYCLIC frame (vmac_proto_cyclic_begin_timed, its instants and
 * records, plain and sealed), the TIMED UPDATE request (unicast, plain and
 * sealed) and the TIMED UPDATE reply (the latch time and the board's clock). docs/PROTOCOL.md, "Time-triggered I/O", is
 * the contract checked; the board's side is in test_board_timed.c. */
#include <check.h>
#include <stdio.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../core/proto/proto.h"
#include "check_main.h"
#include "proto_helpers.h"

#define T_AT 10000500000ULL /* 10.0005 s: 00 00 00 02 54 13 85 20 */

START_TEST(timed_cyclic_example_of_protocol_md_has_pinned_bytes)
{
	static const uint8_t want[] = {
	    0x56, 0x4D, 0x02, 0x04, 0x01, 0x02, 0x00, 0x00, 0x00, 0x00, 0xFF, 0x04, 0x02, /* header, flags TIMED */
	    0x00, 0x00,                                                                   /* first 0 */
	    0x00, 0x00, 0x00, 0x02, 0x54, 0x13, 0x85, 0x20,                               /* out_at */
	    0x00, 0x00, 0x00, 0x02, 0x54, 0x13, 0x85, 0x20,                               /* in_at */
	    0x00, 0x00, 0x00, 0x00, 0x00, 0x00,                                           /* offset 0: empty */
	    0x00, 0x03, 0x01, 0x05, 0xFF, 0x06, /* offset 1: tag 3, DUE, 0x05, -250 */
	};
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	int n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 0x0102, 0, 2, 0, 0, T_AT, T_AT);
	struct vmac_outputs out = {0x05, -250};
	struct vmac_msg m;
	struct vmac_cyclic_record r;

	vmac_proto_cyclic_put(buf, 1, 3, VMAC_CYCLIC_DUE, &out);
	expect_bytes(buf, n, want, (int)sizeof(want), "TIMED CYCLIC example of PROTOCOL.md");
	ck_assert_msg(vmac_proto_frame_length(buf, (size_t)n) == n, "frame_length of a TIMED CYCLIC: %d, want %d",
	              vmac_proto_frame_length(buf, (size_t)n), n);
	ck_assert_msg(vmac_proto_decode(buf, (size_t)n, &m) == 0, "the TIMED CYCLIC example does not decode");
	ck_assert_msg(m.u.cyclic.out_at == T_AT && m.u.cyclic.in_at == T_AT,
	              "decoded instants %llu and %llu, want %llu both", (unsigned long long)m.u.cyclic.out_at,
	              (unsigned long long)m.u.cyclic.in_at, T_AT);
	ck_assert_msg(vmac_proto_cyclic_record(&m, 1, &r) == 0 && r.tag == 3 && r.flags == VMAC_CYCLIC_DUE &&
	                  r.outputs.digital == 0x05 && r.outputs.pwm == -250,
	              "offset 1 of the TIMED example does not read back as tag 3, DUE, 0x05/-250");
}
END_TEST

START_TEST(timed_cyclic_of_240_records_fits_one_ethernet_payload)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	int n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 1, 0, VMAC_CYCLIC_RECORDS_MAX, 0, 0, 1, 2);
	struct vmac_msg m;
	ck_assert_msg(n == 15 + 16 + 6 * 240 && n <= VMAC_PACKET_MAX, "240 TIMED records: %d bytes, want %d", n,
	              15 + 16 + 6 * 240);
	n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 1, 0, VMAC_CYCLIC_AUTH_RECORDS_MAX, 1, 7, 1, 2);
	ck_assert_msg(n == 23 + 16 + 14 * 100 && n <= VMAC_PACKET_MAX, "100 sealed TIMED records: %d bytes, want %d", n,
	              23 + 16 + 14 * 100);
	ck_assert_msg(decode_exact(buf, (size_t)n, &m) == 0 && m.counter == 7 && m.u.cyclic.out_at == 1 &&
	                  m.u.cyclic.in_at == 2,
	              "a sealed TIMED CYCLIC does not decode with its counter and instants");
	n = vmac_proto_cyclic_begin_timed(buf, 30, 1, 0, 1, 0, 0, 1, 2);
	ck_assert_msg(n == VMAC_EPROTO_SPACE, "a TIMED CYCLIC in 30 bytes: got %s, want SPACE", errname(n));
}
END_TEST

/* A sealed TIMED record's MAC covers the instants: moving one fails it. */
START_TEST(sealed_timed_record_mac_covers_the_instants)
{
	static const uint8_t key[VMAC_KEY_LEN] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	struct vmac_outputs out = {0x01, 0};
	struct vmac_msg m;
	int n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 9, 0x25, 1, 1, 100, T_AT, T_AT - 1000);
	int rc;

	vmac_proto_cyclic_put(buf, 0, 3, VMAC_CYCLIC_DUE, &out);
	vmac_proto_cyclic_seal_record(buf, 0, key);
	/* decoded in place: a decoded CYCLIC points into its frame */
	ck_assert_msg(vmac_proto_decode(buf, (size_t)n, &m) == 0, "sealed TIMED CYCLIC does not decode");
	rc = vmac_proto_cyclic_open_record(&m, 0x25, key);
	ck_assert_msg(rc == 0, "sealed TIMED record does not open under its key: %s", errname(rc));
	buf[VMAC_HDR_LEN + 6 + 7] ^= 0x01; /* out_at's last byte */
	ck_assert_msg(vmac_proto_decode(buf, (size_t)n, &m) == 0, "the moved frame no longer decodes");
	rc = vmac_proto_cyclic_open_record(&m, 0x25, key);
	ck_assert_msg(rc == VMAC_EPROTO_AUTH, "a record whose out_at was moved by 1 ns opened: %s, want AUTH",
	              errname(rc));
}
END_TEST

/* The TIMED reply of PROTOCOL.md's examples: inputs, latched at T_AT by a
 * locked clock of bound 1.5 us, 3.5 s ahead of host time. */
static struct vmac_msg timed_reply(uint16_t seq, uint32_t device_id)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.flags = VMAC_FLAG_REPLY | VMAC_FLAG_TIMED;
	m.seq = seq;
	m.device_id = device_id;
	m.channel = VMAC_CH_DEVICE;
	m.op = VMAC_OP_UPDATE;
	m.u.inputs.digital = 0x01;
	m.u.inputs.analog[0] = 100;
	m.u.inputs.encoder = 7;
	m.u.inputs.applied.digital = 0x05;
	m.u.inputs.applied.pwm = -250;
	m.latch.latched_at = T_AT;
	m.latch.clock = 2;
	m.latch.bound_ns = 1500;
	m.latch.offset_ns = 3500000000LL;
	return m;
}

START_TEST(timed_reply_example_of_protocol_md_round_trips)
{
	static const uint8_t want[] = {
	    0x56, 0x4D, 0x02, 0x05, 0x01, 0x02, 0x00, 0x03, 0x00, 0x01, 0x00, 0x02, 0x21, /* REPLY|TIMED, len 33 */
	    0x01, 0x00, 0x64, 0x00, 0x00, 0x00, 0x00, 0x00, 0x07, 0x05, 0xFF, 0x06,       /* inputs */
	    0x00, 0x00, 0x00, 0x02, 0x54, 0x13, 0x85, 0x20,                               /* latched_at */
	    0x02,                                                                         /* clock: locked */
	    0x00, 0x00, 0x05, 0xDC,                                                       /* bound 1500 ns */
	    0x00, 0x00, 0x00, 0x00, 0xD0, 0x9D, 0xC3, 0x00,                               /* offset 3.5 s */
	};
	struct vmac_msg m, back;
	uint8_t buf[VMAC_FRAME_MAX];
	int n;

	m = timed_reply(0x0102, 0x00030001);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	expect_bytes(buf, n, want, (int)sizeof(want), "TIMED UPDATE reply example of PROTOCOL.md");
	ck_assert_msg(n == 46, "a TIMED reply is %d bytes, want 46 (Ethernet's least payload)", n);
	ck_assert_msg(decode_exact(buf, (size_t)n, &back) == 0, "the TIMED reply example does not decode");
	ck_assert_msg(back.latch.latched_at == T_AT && back.latch.clock == 2 && back.latch.bound_ns == 1500 &&
	                  back.latch.offset_ns == 3500000000LL && back.u.inputs.encoder == 7,
	              "the TIMED reply decodes to other values than were encoded");
	m.latch.clock = VMAC_CLOCK_ARRIVAL | 4;
	m.latch.offset_ns = -2250000000LL;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == 46 && decode_exact(buf, (size_t)n, &back) == 0 &&
	                  back.latch.clock == (VMAC_CLOCK_ARRIVAL | 4) && back.latch.offset_ns == -2250000000LL,
	              "a reply acted on arrival with a lost clock and a negative offset does not round-trip");
}
END_TEST

START_TEST(timed_flag_is_refused_where_it_means_nothing)
{
	struct vmac_msg m;
	uint8_t buf[VMAC_FRAME_MAX];
	int n;

	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.flags = VMAC_FLAG_REPLY | VMAC_FLAG_TIMED;
	m.device_id = 0x00030001;
	m.channel = VMAC_CH_DEVICE;
	m.op = VMAC_OP_IDLE;
	expect_encode_err(&m, VMAC_EPROTO_OP, "a TIMED IDLE reply");
	m.flags = VMAC_FLAG_TIMED;
	expect_encode_err(&m, VMAC_EPROTO_OP, "a TIMED IDLE request");
	m.op = VMAC_OP_SHUTDOWN;
	expect_encode_err(&m, VMAC_EPROTO_OP, "a TIMED SHUTDOWN request");
	m.op = VMAC_OP_UPDATE;
	m.version = 1;
	expect_encode_err(&m, VMAC_EPROTO_OP, "a TIMED UPDATE request of version 1");
	m.flags = VMAC_FLAG_REPLY | VMAC_FLAG_TIMED;
	m.version = 1;
	expect_encode_err(&m, VMAC_EPROTO_OP, "a TIMED reply of version 1");

	/* a plain UPDATE reply with the TIMED bit set: 12 bytes where 33 are due */
	m.version = 2;
	m.flags = VMAC_FLAG_REPLY;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	buf[3] |= VMAC_FLAG_TIMED;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_PAYLOAD, "a TIMED reply of 12 bytes");
	buf[3] = VMAC_FLAG_REPLY;
	buf[2] = 1;
	buf[3] |= VMAC_FLAG_TIMED;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "a TIMED reply of version 1");

	/* the clock byte's reserved bits and states past lost */
	m.flags = VMAC_FLAG_REPLY | VMAC_FLAG_TIMED;
	m.latch.clock = 5;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "a TIMED reply whose clock state is 5");
	m.latch.clock = 2;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	buf[VMAC_HDR_LEN + 20] = 5;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "a TIMED reply whose clock state is 5");
	buf[VMAC_HDR_LEN + 20] = 0x40 | 2;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "a TIMED reply with clock bit 6 set");
}
END_TEST

/* The TIMED UPDATE of PROTOCOL.md's example: seq 0x1234, device
 * 0x00010002, outputs 0x05/-250, both instants at 10.0005 s. */
static struct vmac_msg timed_update(void)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.flags = VMAC_FLAG_TIMED;
	m.seq = 0x1234;
	m.device_id = 0x00010002;
	m.channel = VMAC_CH_DEVICE;
	m.op = VMAC_OP_UPDATE;
	m.out_at = T_AT;
	m.in_at = T_AT;
	m.u.outputs.digital = 0x05;
	m.u.outputs.pwm = -250;
	return m;
}

START_TEST(timed_update_example_of_protocol_md_has_pinned_bytes)
{
	static const uint8_t want[] = {
	    0x56, 0x4D, 0x02, 0x04, 0x12, 0x34, 0x00, 0x01, 0x00, 0x02, 0x00, 0x02, 0x13, /* flags TIMED, len 19 */
	    0x00, 0x00, 0x00, 0x02, 0x54, 0x13, 0x85, 0x20,                               /* out_at */
	    0x00, 0x00, 0x00, 0x02, 0x54, 0x13, 0x85, 0x20,                               /* in_at */
	    0x05, 0xFF, 0x06,                                                             /* outputs 0x05, -250 */
	};
	static const uint8_t reply[] = {
	    0x56, 0x4D, 0x02, 0x05, 0x12, 0x34, 0x00, 0x01, 0x00, 0x02, 0x00, 0x02, 0x21, /* REPLY|TIMED, len 33 */
	    0x01, 0x00, 0x64, 0x00, 0x00, 0x00, 0x00, 0x00, 0x07, 0x05, 0xFF, 0x06,       /* inputs */
	    0x00, 0x00, 0x00, 0x02, 0x54, 0x13, 0x85, 0x20,                               /* latched_at */
	    0x02,                                                                         /* clock: locked */
	    0x00, 0x00, 0x05, 0xDC,                                                       /* bound 1500 ns */
	    0x00, 0x00, 0x00, 0x00, 0xD0, 0x9D, 0xC3, 0x00,                               /* offset 3.5 s */
	};
	struct vmac_msg m = timed_update(), back, r;
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(&m, buf, sizeof(buf));

	expect_bytes(buf, n, want, (int)sizeof(want), "TIMED UPDATE example of PROTOCOL.md");
	ck_assert_msg(vmac_proto_frame_length(buf, (size_t)n) == 32, "frame_length of a TIMED UPDATE: %d, want 32",
	              vmac_proto_frame_length(buf, (size_t)n));
	ck_assert_msg(decode_exact(buf, (size_t)n, &back) == 0, "the TIMED UPDATE example does not decode");
	ck_assert_msg(back.flags == VMAC_FLAG_TIMED && back.out_at == T_AT && back.in_at == T_AT &&
	                  back.u.outputs.digital == 0x05 && back.u.outputs.pwm == -250,
	              "the TIMED UPDATE decodes to flags 0x%02x, instants %llu and %llu, outputs 0x%02x/%d", back.flags,
	              (unsigned long long)back.out_at, (unsigned long long)back.in_at, back.u.outputs.digital,
	              back.u.outputs.pwm);
	m.out_at = 1;
	m.in_at = 0xFFFFFFFFFFFFFFFFULL;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == 32 && decode_exact(buf, (size_t)n, &back) == 0 && back.out_at == 1 &&
	                  back.in_at == 0xFFFFFFFFFFFFFFFFULL,
	              "a TIMED UPDATE's instants do not round-trip as two distinct u64");

	/* its answer: the TIMED reply, the same 46 bytes as to a TIMED CYCLIC */
	r = timed_reply(0x1234, 0x00010002);
	n = vmac_proto_encode(&r, buf, sizeof(buf));
	expect_bytes(buf, n, reply, (int)sizeof(reply), "the answer to the TIMED UPDATE example of PROTOCOL.md");
}
END_TEST

/* A sealed TIMED UPDATE is any sealed request: its trailer's MAC covers
 * the header, the instants and the outputs; moving an instant fails it. */
START_TEST(sealed_timed_update_mac_covers_the_instants)
{
	static const uint8_t key[VMAC_KEY_LEN] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
	struct vmac_msg m = timed_update(), back;
	uint8_t buf[VMAC_FRAME_MAX + VMAC_AUTH_TRAILER_LEN];
	int n = vmac_proto_encode(&m, buf, sizeof(buf)), rc;

	n = vmac_proto_seal(buf, (size_t)n, sizeof(buf), 7, key, NULL, 0);
	ck_assert_msg(n == 48, "a sealed TIMED UPDATE is %d bytes, want 48", n);
	ck_assert_msg(buf[3] == (VMAC_FLAG_AUTH | VMAC_FLAG_TIMED), "sealed flags 0x%02x, want 0x06", buf[3]);
	ck_assert_msg(decode_exact(buf, (size_t)n, &back) == 0 && back.counter == 7 && back.out_at == T_AT &&
	                  back.in_at == T_AT && back.u.outputs.pwm == -250,
	              "the sealed TIMED UPDATE does not decode with its counter, instants and outputs");
	rc = vmac_proto_open(buf, (size_t)n, key, NULL, 0);
	ck_assert_msg(rc == 0, "the sealed TIMED UPDATE does not open under its key: %s", errname(rc));
	buf[VMAC_HDR_LEN + 8 + 7] ^= 0x01; /* in_at's last byte */
	rc = vmac_proto_open(buf, (size_t)n, key, NULL, 0);
	ck_assert_msg(rc == VMAC_EPROTO_AUTH, "a TIMED UPDATE whose in_at was moved by 1 ns opened: %s, want AUTH",
	              errname(rc));
}
END_TEST

START_TEST(timed_update_of_another_length_or_version_is_malformed)
{
	struct vmac_msg m = timed_update();
	uint8_t buf[VMAC_FRAME_MAX];
	int n;

	/* a plain UPDATE (3 bytes) with the TIMED bit set */
	m.flags = 0;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	buf[3] |= VMAC_FLAG_TIMED;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_PAYLOAD, "a TIMED UPDATE of 3 data bytes");
	/* a TIMED UPDATE in version 1 */
	m = timed_update();
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	buf[2] = 1;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "a TIMED UPDATE of version 1");
	/* outputs out of range after the instants */
	buf[2] = 2;
	buf[VMAC_HDR_LEN + 16] = 0x80;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "a TIMED UPDATE driving output 7");
	m.u.outputs.pwm = 1001;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "a TIMED UPDATE of pwm 1001");
	/* the TIMED bit on a reply to it, but 19 bytes: a request's length */
	m = timed_update();
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	buf[3] |= VMAC_FLAG_REPLY;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_PAYLOAD, "a TIMED UPDATE reply of 19 bytes");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("timed");
	TCase *tc = tcase_create("timed_frames");
	tcase_add_test(tc, timed_cyclic_example_of_protocol_md_has_pinned_bytes);
	tcase_add_test(tc, timed_cyclic_of_240_records_fits_one_ethernet_payload);
	tcase_add_test(tc, sealed_timed_record_mac_covers_the_instants);
	tcase_add_test(tc, timed_reply_example_of_protocol_md_round_trips);
	tcase_add_test(tc, timed_flag_is_refused_where_it_means_nothing);
	tcase_add_test(tc, timed_update_example_of_protocol_md_has_pinned_bytes);
	tcase_add_test(tc, sealed_timed_update_mac_covers_the_instants);
	tcase_add_test(tc, timed_update_of_another_length_or_version_is_malformed);
	suite_add_tcase(s, tc);
	return s;
}
