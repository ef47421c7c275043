/* Unit tests for the CYCLIC frame of protocol version 2 in the wire codec
 * (core/proto): vmac_proto_cyclic_begin, _put and _record, the decoder's
 * checks of a CYCLIC, and vmac_proto_frame_length for transports that pad.
 * The v2 device ops and versions are in test_proto_v2.c, the board's side in
 * test_board_v2.c and test_board_cyclic.c. docs/PROTOCOL.md, "Version 2", is
 * the contract checked. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "check_main.h"
#include "proto_helpers.h"

/* ---- CYCLIC frames ---------------------------------------------------- */

/* vmac_proto_cyclic_record's answer in words. */
static const char *record_rc_name(int rc)
{
	static char text[96];
	if (rc == 0)
		return "0 (a valid record)";
	if (rc == 1)
		return "1 (no record at that offset)";
	snprintf(text, sizeof(text), "%s", errname(rc));
	return text;
}

/* Read the record at offset; on rc 0 check every field. */
static void expect_record(const struct vmac_msg *m, uint16_t offset, uint16_t tag, uint8_t flags, uint8_t digital,
                          int16_t pwm)
{
	struct vmac_cyclic_record r;
	int rc;
	memset(&r, 0xA5, sizeof(r));
	rc = vmac_proto_cyclic_record(m, offset, &r);
	ck_assert_msg(rc == 0, "record at offset %u: read returned %s, want 0", offset, record_rc_name(rc));
	ck_assert_msg(r.tag == tag && r.flags == flags && r.outputs.digital == digital && r.outputs.pwm == pwm,
	              "record at offset %u read as tag %u flags 0x%02x outputs 0x%02x/%d, want tag %u flags 0x%02x "
	              "outputs 0x%02x/%d",
	              offset, r.tag, r.flags, r.outputs.digital, r.outputs.pwm, tag, flags, digital, pwm);
}

static void expect_record_rc(const struct vmac_msg *m, uint16_t offset, int want, const char *what)
{
	struct vmac_cyclic_record r;
	int rc = vmac_proto_cyclic_record(m, offset, &r);
	char got[96];
	snprintf(got, sizeof(got), "%s", record_rc_name(rc));
	ck_assert_msg(rc == want, "record at offset %u (%s): read returned %s, want %s", offset, what, got,
	              record_rc_name(want));
}

START_TEST(cyclic_begin_with_one_record_has_pinned_bytes)
{
	static const uint8_t want[] = {
	    'V',  'M',  0x02, 0x00,             /* magic, version 2, flags */
	    0x01, 0x02,                         /* seq */
	    0x00, 0x00, 0x00, 0x00,             /* device id: none on the system channel */
	    0xFF, 0x04, 0x01,                   /* system channel, CYCLIC, 1 record */
	    0x00, 0x25,                         /* first: offset 37 */
	    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, /* an empty record */
	};
	uint8_t buf[64], *copy;
	struct vmac_msg m;
	int n, rc;

	memset(buf, 0xA5, sizeof(buf));
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 0x0102, 37, 1);
	expect_bytes(buf, n, want, (int)sizeof(want), "CYCLIC of 1 record from offset 37");
	ck_assert_msg(buf[sizeof(want)] == 0xA5, "cyclic_begin wrote byte %zu, past its %zu-byte frame", sizeof(want),
	              sizeof(want));

	copy = heap_copy(buf, (size_t)n);
	rc = vmac_proto_decode(copy, (size_t)n, &m);
	ck_assert_msg(rc == 0, "decode of a 1-record CYCLIC returned %s", errname(rc));
	ck_assert_msg(
	    m.version == 2 && m.channel == VMAC_CH_SYSTEM && m.op == VMAC_SYS_CYCLIC && m.seq == 0x0102 &&
	        m.device_id == 0 && m.flags == 0,
	    "1-record CYCLIC decoded as version %u channel 0x%02x op 0x%02x seq 0x%04x id 0x%08x flags 0x%02x",
	    m.version, m.channel, m.op, m.seq, (unsigned)m.device_id, m.flags);
	ck_assert_msg(m.u.cyclic.first == 37 && m.u.cyclic.count == 1, "1-record CYCLIC decoded as first %u count %u",
	              m.u.cyclic.first, m.u.cyclic.count);
	expect_record(&m, 37, 0, 0, 0, 0);
	free(copy);
}
END_TEST

/* The byte example of docs/PROTOCOL.md: seq 0x0102, offsets 0 and 1, only
 * offset 1 (device 0x00030001) due, outputs 0x05 and pwm -250. */
START_TEST(cyclic_example_of_protocol_md_has_pinned_bytes)
{
	static const uint8_t want[] = {
	    0x56, 0x4D, 0x02, 0x00, 0x01, 0x02, 0x00, 0x00, 0x00, 0x00, 0xFF, 0x04, 0x02, /* header */
	    0x00, 0x00,                                                                   /* first 0 */
	    0x00, 0x00, 0x00, 0x00, 0x00, 0x00,                                           /* offset 0: empty */
	    0x00, 0x03, 0x01, 0x05, 0xFF, 0x06, /* offset 1: tag 3, DUE, 0x05, -250 */
	};
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	int n = vmac_proto_cyclic_begin(buf, sizeof(buf), 0x0102, 0, 2);

	put_record(buf, 1, 3, VMAC_CYCLIC_DUE, 0x05, -250);
	expect_bytes(buf, n, want, (int)sizeof(want), "CYCLIC example of PROTOCOL.md");
}
END_TEST

START_TEST(cyclic_of_240_records_is_the_largest_frame)
{
	uint8_t buf[VMAC_PACKET_MAX], *copy;
	struct vmac_msg m;
	int n, rc;

	ck_assert_msg(VMAC_CYCLIC_FRAME_MAX == 1471,
	              "VMAC_CYCLIC_FRAME_MAX is %d, want 15 + 16 + 6 * 240 = 1471 (TIMED)", VMAC_CYCLIC_FRAME_MAX);
	ck_assert_msg(VMAC_CYCLIC_FRAME_MAX <= VMAC_PACKET_MAX, "largest CYCLIC (%d) exceeds one Ethernet payload (%d)",
	              VMAC_CYCLIC_FRAME_MAX, VMAC_PACKET_MAX);
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 9, 240, VMAC_CYCLIC_RECORDS_MAX);
	ck_assert_msg(n == 15 + 6 * 240, "cyclic_begin of 240 records returned %s, want %d", errname(n),
	              VMAC_CYCLIC_FRAME_MAX);
	ck_assert_msg(buf[12] == 240, "len byte of a 240-record CYCLIC is %u, want 240", buf[12]);
	put_record(buf, 0, 1, VMAC_CYCLIC_DUE, 0x01, 1);
	put_record(buf, 239, 0xFFFF, VMAC_CYCLIC_DUE, 0x7F, -1000);

	copy = heap_copy(buf, (size_t)n);
	rc = vmac_proto_decode(copy, (size_t)n, &m);
	ck_assert_msg(rc == 0, "decode of the 1455-byte CYCLIC returned %s", errname(rc));
	ck_assert_msg(m.u.cyclic.first == 240 && m.u.cyclic.count == 240,
	              "240-record CYCLIC decoded as first %u count %u", m.u.cyclic.first, m.u.cyclic.count);
	expect_record(&m, 240, 1, VMAC_CYCLIC_DUE, 0x01, 1);
	expect_record(&m, 479, 0xFFFF, VMAC_CYCLIC_DUE, 0x7F, -1000);
	expect_record_rc(&m, 480, 1, "one past the last of 240");
	free(copy);
}
END_TEST

START_TEST(cyclic_begin_refuses_bad_counts_offsets_and_small_buffers)
{
	static const struct {
		uint16_t first;
		unsigned count;
		size_t cap;
		int want;
		const char *what;
	} cases[] = {
	    {0, 0, VMAC_PACKET_MAX, VMAC_EPROTO_VALUE, "0 records"},
	    {0, 241, VMAC_PACKET_MAX, VMAC_EPROTO_VALUE, "241 records"},
	    {0, 1000, VMAC_PACKET_MAX, VMAC_EPROTO_VALUE, "1000 records"},
	    {0xFFFF - 240 + 1, 240, VMAC_PACKET_MAX, VMAC_EPROTO_VALUE, "first 65296 + 240 records > 0xFFFF"},
	    {0xFFFF, 1, VMAC_PACKET_MAX, VMAC_EPROTO_VALUE, "first 0xFFFF (VMAC_OFFSET_NONE)"},
	    {0, 1, 20, VMAC_EPROTO_SPACE, "1 record (21 bytes) into 20"},
	    {0, 240, 1454, VMAC_EPROTO_SPACE, "240 records (1455 bytes) into 1454"},
	    {0, 2, 0, VMAC_EPROTO_SPACE, "2 records into 0 bytes"},
	};
	uint8_t buf[VMAC_PACKET_MAX + 16];
	char got[96];
	size_t i, j;
	int n;

	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		memset(buf, 0xA5, sizeof(buf));
		n = vmac_proto_cyclic_begin(buf, cases[i].cap, 1, cases[i].first, cases[i].count);
		snprintf(got, sizeof(got), "%s", errname(n));
		ck_assert_msg(n == cases[i].want, "cyclic_begin of %s: got %s, want %s", cases[i].what, got,
		              errname(cases[i].want));
		for (j = 0; j < sizeof(buf); j++)
			ck_assert_msg(buf[j] == 0xA5, "refused cyclic_begin of %s wrote byte %zu", cases[i].what, j);
	}

	/* The edges that are allowed. */
	n = vmac_proto_cyclic_begin(buf, VMAC_PACKET_MAX, 1, 0xFFFF - 240, 240);
	ck_assert_msg(n == 15 + 6 * 240, "cyclic_begin of 240 records from 65295 (last 65534): got %s", errname(n));
	n = vmac_proto_cyclic_begin(buf, 21, 1, 0xFFFE, 1);
	ck_assert_msg(n == 21, "cyclic_begin of 1 record at 65534 into exactly 21 bytes: got %s", errname(n));
}
END_TEST

START_TEST(cyclic_records_read_back_at_their_offsets)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX], *copy;
	struct vmac_msg m;
	int n = vmac_proto_cyclic_begin(buf, sizeof(buf), 0xBEEF, 100, 40), rc;

	ck_assert_msg(n == 15 + 6 * 40, "cyclic_begin of 40 records returned %s, want 255 bytes", errname(n));
	put_record(buf, 0, 1, VMAC_CYCLIC_DUE, 0x7F, 1000);
	put_record(buf, 17, 0x1234, 0, 0x00, -1000);
	put_record(buf, 39, 0xFFFF, VMAC_CYCLIC_DUE, 0x55, -250);

	copy = heap_copy(buf, (size_t)n);
	rc = vmac_proto_decode(copy, (size_t)n, &m);
	ck_assert_msg(rc == 0, "decode of a 40-record CYCLIC returned %s", errname(rc));
	ck_assert_msg(m.seq == 0xBEEF && m.u.cyclic.first == 100 && m.u.cyclic.count == 40,
	              "40-record CYCLIC decoded as seq 0x%04x first %u count %u, want 0xbeef 100 40", m.seq,
	              m.u.cyclic.first, m.u.cyclic.count);
	expect_record(&m, 100, 1, VMAC_CYCLIC_DUE, 0x7F, 1000);
	expect_record(&m, 117, 0x1234, 0, 0x00, -1000);
	expect_record(&m, 139, 0xFFFF, VMAC_CYCLIC_DUE, 0x55, -250);
	expect_record(&m, 105, 0, 0, 0, 0); /* never put: empty */

	expect_record_rc(&m, 99, 1, "one before first");
	expect_record_rc(&m, 140, 1, "first + count");
	expect_record_rc(&m, 0, 1, "offset 0");
	expect_record_rc(&m, 0xFFFF, 1, "VMAC_OFFSET_NONE");
	free(copy);
}
END_TEST

START_TEST(cyclic_record_refuses_reserved_flags_and_outputs_out_of_range)
{
	static const struct {
		uint8_t flags, digital;
		int16_t pwm;
		int want;
		const char *what;
	} cases[] = {
	    {0x02, 0x00, 0, VMAC_EPROTO_VALUE, "flag bit 1"},
	    {VMAC_CYCLIC_DUE | 0x80, 0x00, 0, VMAC_EPROTO_VALUE, "DUE and flag bit 7"},
	    {0xFF, 0x00, 0, VMAC_EPROTO_VALUE, "flags 0xff"},
	    {VMAC_CYCLIC_DUE, 0x80, 0, VMAC_EPROTO_VALUE, "digital bit 7"},
	    {VMAC_CYCLIC_DUE, 0x00, 1001, VMAC_EPROTO_VALUE, "pwm 1001"},
	    {VMAC_CYCLIC_DUE, 0x00, -1001, VMAC_EPROTO_VALUE, "pwm -1001"},
	    {VMAC_CYCLIC_DUE, 0x00, INT16_MIN, VMAC_EPROTO_VALUE, "pwm -32768"},
	    {VMAC_CYCLIC_DUE, 0x7F, 1000, 0, "0x7f and pwm 1000 (in range)"},
	    {0, 0x00, -1000, 0, "pwm -1000, not due (in range)"},
	};
	enum { N = sizeof(cases) / sizeof(cases[0]) };
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX], *copy;
	struct vmac_msg m;
	unsigned i;
	int n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 50, N), rc;

	for (i = 0; i < N; i++)
		put_record(buf, i, 7, cases[i].flags, cases[i].digital, cases[i].pwm);
	copy = heap_copy(buf, (size_t)n);
	rc = vmac_proto_decode(copy, (size_t)n, &m);
	ck_assert_msg(rc == 0, "decode of a CYCLIC with bad records returned %s, want 0: records are checked when read",
	              errname(rc));
	for (i = 0; i < N; i++)
		expect_record_rc(&m, (uint16_t)(50 + i), cases[i].want, cases[i].what);
	free(copy);
}
END_TEST

START_TEST(cyclic_length_must_match_its_record_count)
{
	uint8_t buf[VMAC_PACKET_MAX + 8];
	int n;

	memset(buf, 0, sizeof(buf));
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0, 3);
	ck_assert_msg(n == 33, "cyclic_begin of 3 records returned %s, want 33 bytes", errname(n));
	expect_decode_err(buf, 32, VMAC_EPROTO_LENGTH, "3-record CYCLIC one byte short");
	expect_decode_err(buf, 34, VMAC_EPROTO_LENGTH, "3-record CYCLIC one byte long");
	expect_decode_err(buf, 15, VMAC_EPROTO_LENGTH, "3-record CYCLIC cut after first");
	expect_decode_err(buf, 14, VMAC_EPROTO_LENGTH, "3-record CYCLIC cut inside first");
	buf[12] = 2;
	expect_decode_err(buf, 33, VMAC_EPROTO_LENGTH, "33-byte CYCLIC whose len says 2 records");
	buf[12] = 4;
	expect_decode_err(buf, 33, VMAC_EPROTO_LENGTH, "33-byte CYCLIC whose len says 4 records");
	buf[12] = 33 - VMAC_HDR_LEN;
	expect_decode_err(buf, 33, VMAC_EPROTO_LENGTH, "33-byte CYCLIC whose len counts bytes, as version 1");

	buf[12] = 0;
	expect_decode_err(buf, 15, VMAC_EPROTO_LENGTH, "CYCLIC of 0 records with its first");
	expect_decode_err(buf, VMAC_HDR_LEN, VMAC_EPROTO_LENGTH, "CYCLIC of 0 records, header only");

	/* 241 records would fit the bytes of 1461 but not the protocol. */
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0, 240);
	memset(buf + n, 0, 6);
	buf[12] = 241;
	expect_decode_err(buf, (size_t)n + 6, VMAC_EPROTO_LENGTH, "CYCLIC of 241 records (1461 bytes)");
}
END_TEST

START_TEST(cyclic_from_a_board_or_for_a_device_is_refused)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	int n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0, 2);

	buf[3] = VMAC_FLAG_REPLY;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "CYCLIC with the REPLY flag");
	buf[3] = 0x08;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "CYCLIC with flag bit 3");
	buf[3] = 0;
	buf[8] = 0x00;
	buf[9] = 0x25;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "CYCLIC with device id 0x00000025");
	buf[6] = 0x80;
	buf[9] = 0;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "CYCLIC with device id 0x80000000");
}
END_TEST

START_TEST(cyclic_reaching_offset_0xffff_is_refused_by_decode)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	struct vmac_msg m;
	int n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0xFFFF - 240, 240), rc;

	rc = decode_exact(buf, (size_t)n, &m);
	ck_assert_msg(rc == 0, "CYCLIC of offsets 65295..65534: decode returned %s, want 0", errname(rc));
	buf[VMAC_HDR_LEN + 1] = (uint8_t)(0xFFFF - 240 + 1); /* first 65296: the last record would be 0xFFFF */
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "CYCLIC of offsets 65296..65535");
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0, 1);
	buf[VMAC_HDR_LEN] = 0xFF;
	buf[VMAC_HDR_LEN + 1] = 0xFF;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "CYCLIC of 1 record at 0xFFFF");
}
END_TEST

/* ---- frame length (for transports that pad) --------------------------- */

START_TEST(frame_length_of_version_1_and_cyclic_frames)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_msg m = msg(1, 0, VMAC_CH_DEVICE, VMAC_OP_UPDATE, 0x00010002u, 1);
	int n, got;
	unsigned count;

	m.u.outputs.pwm = -250;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	got = vmac_proto_frame_length(buf, (size_t)n);
	ck_assert_msg(got == 16, "frame_length of a version-1 UPDATE request returned %s, want 16", errname(got));
	m = msg(1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	got = vmac_proto_frame_length(buf, (size_t)n);
	ck_assert_msg(got == VMAC_HDR_LEN, "frame_length of a DISCOVER returned %s, want 13", errname(got));

	for (count = 1; count <= VMAC_CYCLIC_RECORDS_MAX; count += count < 3 ? 1 : 237) {
		n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0, count);
		got = vmac_proto_frame_length(buf, (size_t)n);
		ck_assert_msg(got == n && got == 15 + 6 * (int)count,
		              "frame_length of a %u-record CYCLIC returned %s, want %d", count, errname(got),
		              15 + 6 * (int)count);
	}

	/* Op 0x04 on the system channel of a version-1 frame is no CYCLIC: len counts bytes. */
	raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_CYCLIC, NULL, 0);
	buf[12] = 8;
	got = vmac_proto_frame_length(buf, VMAC_HDR_LEN + 8);
	ck_assert_msg(got == VMAC_HDR_LEN + 8,
	              "frame_length of a version-1 frame of op 0x04, len 8, returned %s, want 21", errname(got));
}
END_TEST

START_TEST(frame_length_gives_the_true_length_of_a_padded_frame)
{
	uint8_t buf[46], *copy;
	struct vmac_msg m = msg(1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	int n, got, rc;

	memset(buf, 0, sizeof(buf));
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	got = vmac_proto_frame_length(buf, sizeof(buf));
	ck_assert_msg(got == n, "frame_length of a DISCOVER padded to 46 bytes returned %s, want %d", errname(got), n);
	rc = decode_exact(buf, sizeof(buf), &m);
	ck_assert_msg(rc == VMAC_EPROTO_LENGTH, "decode of a DISCOVER with its padding returned %s, want LENGTH",
	              errname(rc));

	memset(buf, 0, sizeof(buf));
	m = msg(2, VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_OFFSET, DOC_DEVICE, 1);
	m.u.offset = 37;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	got = vmac_proto_frame_length(buf, sizeof(buf));
	ck_assert_msg(got == 15, "frame_length of an OFFSET reply padded to 46 bytes returned %s, want 15",
	              errname(got));

	memset(buf, 0, sizeof(buf));
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 37, 1);
	put_record(buf, 0, 5, VMAC_CYCLIC_DUE, 0x05, -250);
	got = vmac_proto_frame_length(buf, sizeof(buf));
	ck_assert_msg(got == 21 && n == 21, "frame_length of a 1-record CYCLIC padded to 46 bytes returned %s, want 21",
	              errname(got));
	copy = heap_copy(buf, (size_t)got);
	rc = vmac_proto_decode(copy, (size_t)got, &m);
	ck_assert_msg(rc == 0, "decode of the first frame_length bytes of a padded CYCLIC returned %s", errname(rc));
	expect_record(&m, 37, 5, VMAC_CYCLIC_DUE, 0x05, -250);
	free(copy);
}
END_TEST

START_TEST(frame_length_refuses_garbage_and_short_buffers)
{
	static const uint8_t garbage[46] = {'X', 'M', 2, 0, 0, 1, 0, 0, 0, 0, 0xFF, 0x04, 1};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t len, n;
	int got;

	got = vmac_proto_frame_length(garbage, sizeof(garbage));
	ck_assert_msg(got == VMAC_EPROTO_MAGIC, "frame_length of a frame with magic 'X' 'M' returned %s, want MAGIC",
	              errname(got));
	n = raw_frame(buf, 2, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
	buf[1] = 0x00;
	got = vmac_proto_frame_length(buf, n);
	ck_assert_msg(got == VMAC_EPROTO_MAGIC, "frame_length with magic 'V' 0x00 returned %s, want MAGIC",
	              errname(got));

	n = (size_t)vmac_proto_cyclic_begin(buf, sizeof(buf), 1, 0, 1);
	for (len = 0; len < VMAC_HDR_LEN; len++) {
		uint8_t *copy = heap_copy(buf, len);
		got = vmac_proto_frame_length(copy, len);
		free(copy);
		ck_assert_msg(got == VMAC_EPROTO_SHORT, "frame_length of %zu bytes of a CYCLIC returned %s, want SHORT",
		              len, errname(got));
	}
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("cyclic");
	TCase *tc;

	tc = tcase_create("cyclic_frame");
	tcase_add_test(tc, cyclic_begin_with_one_record_has_pinned_bytes);
	tcase_add_test(tc, cyclic_example_of_protocol_md_has_pinned_bytes);
	tcase_add_test(tc, cyclic_of_240_records_is_the_largest_frame);
	tcase_add_test(tc, cyclic_begin_refuses_bad_counts_offsets_and_small_buffers);
	tcase_add_test(tc, cyclic_records_read_back_at_their_offsets);
	tcase_add_test(tc, cyclic_record_refuses_reserved_flags_and_outputs_out_of_range);
	tcase_add_test(tc, cyclic_length_must_match_its_record_count);
	tcase_add_test(tc, cyclic_from_a_board_or_for_a_device_is_refused);
	tcase_add_test(tc, cyclic_reaching_offset_0xffff_is_refused_by_decode);
	suite_add_tcase(s, tc);

	tc = tcase_create("frame_length");
	tcase_add_test(tc, frame_length_of_version_1_and_cyclic_frames);
	tcase_add_test(tc, frame_length_gives_the_true_length_of_a_padded_frame);
	tcase_add_test(tc, frame_length_refuses_garbage_and_short_buffers);
	suite_add_tcase(s, tc);

	return s;
}
