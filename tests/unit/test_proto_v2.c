/* Unit tests for protocol version 2 in the wire codec (core/proto): the
 * device ops SIZE, OFFSET and OFFSET_GET on the wire, and the codec's version
 * handling (what it decodes, what it writes, the v2 ops in a v1 frame).
 * The CYCLIC frame is in test_cyclic.c, the board's side of version 2 in
 * test_board_v2.c and test_board_cyclic.c. docs/PROTOCOL.md, "Version 2", is
 * the contract checked. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "check_main.h"
#include "proto_helpers.h"

/* ---- codec helpers ---------------------------------------------------- */

/* Encode m, compare with the pinned bytes, then decode the pinned bytes and
 * check the header came back; the decoded message is returned through back. */
static void expect_pinned(const struct vmac_msg *m, const uint8_t *want, int want_len, struct vmac_msg *back,
                          const char *what)
{
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(m, buf, sizeof(buf)), rc;

	expect_bytes(buf, n, want, want_len, what);
	rc = decode_exact(want, (size_t)want_len, back);
	ck_assert_msg(rc == 0, "%s: decode of the pinned bytes returned %s", what, errname(rc));
	ck_assert_msg(back->version == 2, "%s: pinned bytes decoded as version %u, want 2", what, back->version);
	ck_assert_msg(back->flags == m->flags && back->seq == m->seq && back->device_id == m->device_id &&
	                  back->channel == m->channel && back->op == m->op,
	              "%s: pinned bytes decoded as flags 0x%02x seq %u id 0x%08x channel 0x%02x op 0x%02x", what,
	              back->flags, back->seq, (unsigned)back->device_id, back->channel, back->op);
}

/* Encode, decode what was encoded; both must succeed and the header,
 * version included, survive. */
static void roundtrip(const struct vmac_msg *in, struct vmac_msg *out, const char *what)
{
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(in, buf, sizeof(buf)), rc;

	ck_assert_msg(n >= VMAC_HDR_LEN, "%s: encode returned %s, want a frame", what, errname(n));
	rc = decode_exact(buf, (size_t)n, out);
	ck_assert_msg(rc == 0, "%s: decode of own %d-byte frame returned %s", what, n, errname(rc));
	ck_assert_msg(out->version == in->version, "%s: came back as version %u, want %u", what, out->version,
	              in->version);
	ck_assert_msg(out->flags == in->flags && out->seq == in->seq && out->device_id == in->device_id &&
	                  out->channel == in->channel && out->op == in->op,
	              "%s: header came back as flags 0x%02x seq %u id 0x%08x channel 0x%02x op 0x%02x", what,
	              out->flags, out->seq, (unsigned)out->device_id, out->channel, out->op);
}

/* ---- v2 device ops on the wire ---------------------------------------- */

START_TEST(size_request_and_reply_have_pinned_wire_bytes)
{
	static const uint8_t want_request[] = {
	    'V',  'M',  0x02, 0x00, /* magic, version 2, flags */
	    0x00, 0x09,             /* seq */
	    0x00, 0x03, 0x00, 0x25, /* device 0x00030025 */
	    0x00, 0x07, 0x00,       /* device channel, SIZE, no data */
	};
	static const uint8_t want_reply[] = {
	    'V', 'M', 0x02, 0x01, 0x00, 0x09, 0x00, 0x03, 0x00, 0x25, 0x00, 0x07, 0x01, 0x06, /* record size 6 */
	};
	struct vmac_msg m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_SIZE, DOC_DEVICE, 9), back;

	expect_pinned(&m, want_request, (int)sizeof(want_request), &back, "SIZE request");
	m = msg(2, VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_SIZE, DOC_DEVICE, 9);
	m.u.record_size = VMAC_CYCLIC_RECORD_LEN;
	expect_pinned(&m, want_reply, (int)sizeof(want_reply), &back, "SIZE reply");
	ck_assert_msg(back.u.record_size == 6, "pinned SIZE reply decoded as record size %u, want 6",
	              back.u.record_size);
}
END_TEST

START_TEST(offset_request_and_reply_have_pinned_wire_bytes)
{
	static const uint8_t want_request[] = {
	    'V',  'M',  0x02, 0x00, 0x00, 0x0A, 0x00, 0x03, 0x00, 0x25, 0x00, 0x08, 0x02, /* OFFSET, 2 data bytes */
	    0x00, 0x25,                                                                   /* offset 37 */
	};
	static const uint8_t want_reply[] = {
	    'V', 'M', 0x02, 0x01, 0x00, 0x0A, 0x00, 0x03, 0x00, 0x25, 0x00, 0x08, 0x02, 0x00, 0x25, /* echoed */
	};
	struct vmac_msg m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, DOC_DEVICE, 10), back;

	m.u.offset = 37;
	expect_pinned(&m, want_request, (int)sizeof(want_request), &back, "OFFSET request");
	ck_assert_msg(back.u.offset == 37, "pinned OFFSET request decoded as offset %u, want 37", back.u.offset);
	m.flags = VMAC_FLAG_REPLY;
	expect_pinned(&m, want_reply, (int)sizeof(want_reply), &back, "OFFSET reply");
	ck_assert_msg(back.u.offset == 37, "pinned OFFSET reply decoded as offset %u, want 37", back.u.offset);
}
END_TEST

START_TEST(offset_get_request_and_reply_have_pinned_wire_bytes)
{
	static const uint8_t want_request[] = {
	    'V', 'M', 0x02, 0x00, 0x00, 0x0B, 0x00, 0x03, 0x00, 0x25, 0x00, 0x09, 0x00, /* OFFSET_GET, no data */
	};
	static const uint8_t want_reply[] = {
	    'V', 'M', 0x02, 0x01, 0x00, 0x0B, 0x00, 0x03, 0x00, 0x25, 0x00, 0x09, 0x02, 0x00, 0x25, /* offset 37 */
	};
	static const uint8_t want_none[] = {
	    'V', 'M', 0x02, 0x01, 0x00, 0x0B, 0x00, 0x03, 0x00, 0x25, 0x00, 0x09, 0x02, 0xFF, 0xFF, /* none */
	};
	struct vmac_msg m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, DOC_DEVICE, 11), back;

	expect_pinned(&m, want_request, (int)sizeof(want_request), &back, "OFFSET_GET request");
	m = msg(2, VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, DOC_DEVICE, 11);
	m.u.offset = 37;
	expect_pinned(&m, want_reply, (int)sizeof(want_reply), &back, "OFFSET_GET reply");
	ck_assert_msg(back.u.offset == 37, "pinned OFFSET_GET reply decoded as offset %u, want 37", back.u.offset);
	m.u.offset = VMAC_OFFSET_NONE;
	expect_pinned(&m, want_none, (int)sizeof(want_none), &back, "OFFSET_GET reply of a board without offset");
	ck_assert_msg(back.u.offset == VMAC_OFFSET_NONE, "pinned OFFSET_GET 0xffff decoded as offset %u, want 65535",
	              back.u.offset);
}
END_TEST

START_TEST(size_offset_and_offset_get_roundtrip)
{
	static const uint8_t sizes[] = {1, 6, 255};
	static const uint16_t offsets[] = {0, 37, 239, 240, 0xFFFE, VMAC_OFFSET_NONE};
	struct vmac_msg m, back;
	size_t i;
	char what[80];

	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_SIZE, 0x00010002u, 1);
	roundtrip(&m, &back, "SIZE request");
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, 0x00010002u, 2);
	roundtrip(&m, &back, "OFFSET_GET request");
	for (i = 0; i < sizeof(sizes); i++) {
		m = msg(2, VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_SIZE, 0xFFFF0001u, (uint16_t)(100 + i));
		m.u.record_size = sizes[i];
		snprintf(what, sizeof(what), "SIZE reply of %u bytes", sizes[i]);
		roundtrip(&m, &back, what);
		ck_assert_msg(back.u.record_size == sizes[i], "%s: came back as %u", what, back.u.record_size);
	}
	for (i = 0; i < sizeof(offsets) / sizeof(offsets[0]); i++) {
		m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, 0x00010002u, (uint16_t)(200 + i));
		m.u.offset = offsets[i];
		snprintf(what, sizeof(what), "OFFSET request of %u", offsets[i]);
		roundtrip(&m, &back, what);
		ck_assert_msg(back.u.offset == offsets[i], "%s: came back as %u", what, back.u.offset);

		m.flags = VMAC_FLAG_REPLY;
		snprintf(what, sizeof(what), "OFFSET reply of %u", offsets[i]);
		roundtrip(&m, &back, what);
		ck_assert_msg(back.u.offset == offsets[i], "%s: came back as %u", what, back.u.offset);

		m.op = VMAC_OP_OFFSET_GET;
		snprintf(what, sizeof(what), "OFFSET_GET reply of %u", offsets[i]);
		roundtrip(&m, &back, what);
		ck_assert_msg(back.u.offset == offsets[i], "%s: came back as %u", what, back.u.offset);
	}
}
END_TEST

START_TEST(size_reply_of_zero_bytes_is_refused)
{
	static const uint8_t zero[] = {0};
	uint8_t buf[VMAC_FRAME_MAX];
	struct vmac_msg m = msg(2, VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_SIZE, DOC_DEVICE, 1);
	size_t n;

	expect_encode_err(&m, VMAC_EPROTO_VALUE, "SIZE reply with record size 0");
	n = raw_frame(buf, 2, VMAC_FLAG_REPLY, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_SIZE, zero, 1);
	expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "SIZE reply with record size 0");
}
END_TEST

START_TEST(v2_ops_with_wrong_data_size_are_payload_errors)
{
	static const uint8_t data[3] = {0, 0x25, 0};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n;

	n = raw_frame(buf, 2, 0, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_SIZE, data, 1);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "SIZE request with 1 data byte");
	n = raw_frame(buf, 2, VMAC_FLAG_REPLY, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_SIZE, data, 2);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "SIZE reply with 2 data bytes");
	n = raw_frame(buf, 2, 0, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_OFFSET, data, 1);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "OFFSET request with 1 data byte");
	n = raw_frame(buf, 2, VMAC_FLAG_REPLY, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_OFFSET, data, 3);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "OFFSET reply with 3 data bytes");
	n = raw_frame(buf, 2, 0, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, data, 2);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "OFFSET_GET request with 2 data bytes");
	n = raw_frame(buf, 2, VMAC_FLAG_REPLY, 1, DOC_DEVICE, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, data, 0);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "OFFSET_GET reply with no data");
}
END_TEST

/* ---- versions --------------------------------------------------------- */

START_TEST(decode_accepts_versions_1_and_2_and_reports_them)
{
	static const uint8_t outputs[3] = {0x05, 0xFF, 0x06};
	uint8_t buf[VMAC_FRAME_MAX];
	struct vmac_msg m;
	uint8_t version;
	size_t n;
	int rc;

	for (version = 1; version <= 2; version++) {
		n = raw_frame(buf, version, 0, 7, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
		rc = decode_exact(buf, n, &m);
		ck_assert_msg(rc == 0, "DISCOVER of version %u: decode returned %s", version, errname(rc));
		ck_assert_msg(m.version == version, "DISCOVER of version %u decoded as version %u", version, m.version);

		n = raw_frame(buf, version, 0, 8, 0x00010002u, VMAC_CH_DEVICE, VMAC_OP_UPDATE, outputs, 3);
		rc = decode_exact(buf, n, &m);
		ck_assert_msg(rc == 0, "UPDATE of version %u: decode returned %s", version, errname(rc));
		ck_assert_msg(m.version == version, "UPDATE of version %u decoded as version %u", version, m.version);
		ck_assert_msg(m.u.outputs.digital == 0x05 && m.u.outputs.pwm == -250,
		              "UPDATE of version %u decoded as outputs 0x%02x/%d, want 0x05/-250", version,
		              m.u.outputs.digital, m.u.outputs.pwm);
	}
}
END_TEST

START_TEST(decode_refuses_versions_0_and_3)
{
	static const uint8_t versions[] = {0, 3};
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	char what[64];
	size_t i, n;
	int len;

	for (i = 0; i < sizeof(versions); i++) {
		n = raw_frame(buf, versions[i], 0, 7, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
		snprintf(what, sizeof(what), "DISCOVER of version %u", versions[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VERSION, what);

		len = vmac_proto_cyclic_begin(buf, sizeof(buf), 7, 0, 2);
		ck_assert_msg(len > 0, "test bug: cyclic_begin returned %s", errname(len));
		buf[2] = versions[i];
		snprintf(what, sizeof(what), "CYCLIC of version %u", versions[i]);
		expect_decode_err(buf, (size_t)len, VMAC_EPROTO_VERSION, what);
	}
}
END_TEST

/* proto.h: "encode: 0 means 1, the version every board speaks". A v2 frame
 * is only ever written when version 2 is asked for. */
START_TEST(encode_writes_the_version_asked_and_1_for_version_0)
{
	uint8_t buf[VMAC_FRAME_MAX];
	struct vmac_msg m = msg(0, 0, VMAC_CH_DEVICE, VMAC_OP_UPDATE, 0x00010002u, 1);
	int n;

	m.u.outputs.digital = 0x05;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == 16 && buf[2] == 1,
	              "UPDATE with version 0: encode returned %s, version byte %u, want 1 (proto.h: 0 means 1)",
	              errname(n), buf[2]);
	m.version = 1;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == 16 && buf[2] == 1, "UPDATE with version 1: encode returned %s, version byte %u, want 1",
	              errname(n), buf[2]);
	m.version = 2;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == 16 && buf[2] == 2, "UPDATE with version 2: encode returned %s, version byte %u, want 2",
	              errname(n), buf[2]);

	m = msg(0, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == VMAC_HDR_LEN && buf[2] == 1,
	              "DISCOVER with version 0: encode returned %s, version byte %u, want 1", errname(n), buf[2]);

	/* Version 0 is version 1, where the v2 ops do not exist. */
	m = msg(0, 0, VMAC_CH_DEVICE, VMAC_OP_SIZE, 0x00010002u, 1);
	expect_encode_err(&m, VMAC_EPROTO_OP, "SIZE with version 0 (means 1)");
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_SIZE, 0x00010002u, 1);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(n == VMAC_HDR_LEN && buf[2] == 2, "SIZE with version 2: encode returned %s, version byte %u",
	              errname(n), buf[2]);

	m.version = 3;
	expect_encode_err(&m, VMAC_EPROTO_VERSION, "SIZE with version 3");
	m = msg(3, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	expect_encode_err(&m, VMAC_EPROTO_VERSION, "DISCOVER with version 3");
	m.version = 0xFF;
	expect_encode_err(&m, VMAC_EPROTO_VERSION, "DISCOVER with version 255");
}
END_TEST

START_TEST(v2_ops_inside_a_version_1_frame_are_unknown_ops)
{
	static const uint8_t data[8] = {0x06, 0x25, 0x00, 0x05, 0x01, 0x05, 0xFF, 0x06};
	static const struct {
		uint8_t flags, channel, op;
		size_t data_len;
		const char *what;
	} cases[] = {
	    {0, VMAC_CH_DEVICE, VMAC_OP_SIZE, 0, "SIZE request"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_SIZE, 1, "SIZE reply"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, 2, "OFFSET request"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_OFFSET, 2, "OFFSET reply"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, 0, "OFFSET_GET request"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, 2, "OFFSET_GET reply"},
	    /* len counts bytes in version 1: 8 data bytes, one record's worth */
	    {0, VMAC_CH_SYSTEM, VMAC_SYS_CYCLIC, 8, "CYCLIC"},
	};
	uint8_t buf[VMAC_FRAME_MAX];
	struct vmac_msg m;
	char what[80];
	size_t i, n;

	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		uint32_t id = cases[i].channel == VMAC_CH_SYSTEM ? 0 : DOC_DEVICE;
		n = raw_frame(buf, 1, cases[i].flags, 1, id, cases[i].channel, cases[i].op, data, cases[i].data_len);
		snprintf(what, sizeof(what), "%s in a version-1 frame", cases[i].what);
		expect_decode_err(buf, n, VMAC_EPROTO_OP, what);

		buf[2] = 2; /* the same bytes are fine in version 2 (CYCLIC aside: its len counts records) */
		if (cases[i].op != VMAC_SYS_CYCLIC || cases[i].channel != VMAC_CH_SYSTEM) {
			int rc = decode_exact(buf, n, &m);
			ck_assert_msg(rc == 0, "%s in a version-2 frame: decode returned %s", cases[i].what,
			              errname(rc));
		}

		m = msg(1, cases[i].flags, cases[i].channel, cases[i].op, id, 1);
		m.u.record_size = 6; /* a valid SIZE reply in version 2 */
		snprintf(what, sizeof(what), "%s of version 1", cases[i].what);
		expect_encode_err(&m, VMAC_EPROTO_OP, what);
	}
}
END_TEST

START_TEST(encode_refuses_to_build_a_cyclic)
{
	static const uint8_t versions[] = {0, 1, 2};
	struct vmac_msg m;
	char what[64];
	size_t i;

	for (i = 0; i < sizeof(versions); i++) {
		m = msg(versions[i], 0, VMAC_CH_SYSTEM, VMAC_SYS_CYCLIC, 0, 1);
		m.u.cyclic.count = 1;
		snprintf(what, sizeof(what), "CYCLIC through vmac_proto_encode, version %u", versions[i]);
		expect_encode_err(&m, VMAC_EPROTO_OP, what);
	}
	m = msg(2, VMAC_FLAG_REPLY, VMAC_CH_SYSTEM, VMAC_SYS_CYCLIC, 0, 1);
	expect_encode_err(&m, VMAC_EPROTO_OP, "CYCLIC reply through vmac_proto_encode");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("proto_v2");
	TCase *tc;

	tc = tcase_create("v2_ops");
	tcase_add_test(tc, size_request_and_reply_have_pinned_wire_bytes);
	tcase_add_test(tc, offset_request_and_reply_have_pinned_wire_bytes);
	tcase_add_test(tc, offset_get_request_and_reply_have_pinned_wire_bytes);
	tcase_add_test(tc, size_offset_and_offset_get_roundtrip);
	tcase_add_test(tc, size_reply_of_zero_bytes_is_refused);
	tcase_add_test(tc, v2_ops_with_wrong_data_size_are_payload_errors);
	suite_add_tcase(s, tc);

	tc = tcase_create("versions");
	tcase_add_test(tc, decode_accepts_versions_1_and_2_and_reports_them);
	tcase_add_test(tc, decode_refuses_versions_0_and_3);
	tcase_add_test(tc, encode_writes_the_version_asked_and_1_for_version_0);
	tcase_add_test(tc, v2_ops_inside_a_version_1_frame_are_unknown_ops);
	tcase_add_test(tc, encode_refuses_to_build_a_cyclic);
	suite_add_tcase(s, tc);

	return s;
}
