/* Unit tests for protocol version 2, the cyclic frame: the codec's new ops and
 * its version handling (core/proto), and the board's v2 registration and
 * CYCLIC service (firmware/board), driven through a fake HAL as in
 * test_board.c. docs/PROTOCOL.md, "Version 2", is the contract checked. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "../../firmware/board.h"

/* ---- codec helpers ---------------------------------------------------- */

/* Device 0x00030025 (generation 3, slot 37), as in docs/PROTOCOL.md. */
#define DOC_DEVICE 0x00030025u

static struct vmac_msg msg(uint8_t version, uint8_t flags, uint8_t channel, uint8_t op, uint32_t device_id,
                           uint16_t seq)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.version = version;
	m.flags = flags;
	m.seq = seq;
	m.device_id = device_id;
	m.channel = channel;
	m.op = op;
	return m;
}

static const char *errname(int err)
{
	static char text[96];
	if (err > 0)
		snprintf(text, sizeof(text), "%d (a %d-byte frame)", err, err);
	else
		snprintf(text, sizeof(text), "%d (%s)", err, vmac_proto_strerror(err));
	return text;
}

static void expect_bytes(const uint8_t *got, int got_len, const uint8_t *want, int want_len, const char *what)
{
	int i;
	ck_assert_msg(got_len == want_len, "%s: encoded %s, want %d bytes", what, errname(got_len), want_len);
	for (i = 0; i < want_len; i++)
		ck_assert_msg(got[i] == want[i], "%s: byte %d is 0x%02x, want 0x%02x", what, i, got[i], want[i]);
}

/* A heap copy of exactly len bytes, so a sanitizer sees any read past the
 * end of the datagram. A decoded CYCLIC points into it: free it after. */
static uint8_t *heap_copy(const uint8_t *frame, size_t len)
{
	uint8_t *copy = malloc(len ? len : 1);
	ck_assert_msg(copy != NULL, "malloc(%zu) failed", len);
	if (len)
		memcpy(copy, frame, len);
	return copy;
}

static int decode_exact(const uint8_t *frame, size_t len, struct vmac_msg *m)
{
	uint8_t *copy = heap_copy(frame, len);
	int rc = vmac_proto_decode(copy, len, m);
	free(copy);
	return rc;
}

static void expect_decode_err(const uint8_t *frame, size_t len, int want, const char *what)
{
	struct vmac_msg m;
	int rc = decode_exact(frame, len, &m);
	char got[96];
	snprintf(got, sizeof(got), "%s", errname(rc));
	ck_assert_msg(rc == want, "decode %s (%zu bytes): got %s, want %s", what, len, got, errname(want));
}

static void expect_encode_err(const struct vmac_msg *m, int want, const char *what)
{
	uint8_t buf[VMAC_FRAME_MAX];
	int rc = vmac_proto_encode(m, buf, sizeof(buf));
	char got[96];
	snprintf(got, sizeof(got), "%s", errname(rc));
	ck_assert_msg(rc == want, "encode %s: got %s, want %s", what, got, errname(want));
}

/* A frame byte by byte, any version, bypassing the encoder's checks. */
static size_t raw_frame(uint8_t *buf, uint8_t version, uint8_t flags, uint16_t seq, uint32_t device_id, uint8_t channel,
                        uint8_t op, const uint8_t *data, size_t data_len)
{
	buf[0] = VMAC_MAGIC0;
	buf[1] = VMAC_MAGIC1;
	buf[2] = version;
	buf[3] = flags;
	buf[4] = (uint8_t)(seq >> 8);
	buf[5] = (uint8_t)seq;
	buf[6] = (uint8_t)(device_id >> 24);
	buf[7] = (uint8_t)(device_id >> 16);
	buf[8] = (uint8_t)(device_id >> 8);
	buf[9] = (uint8_t)device_id;
	buf[10] = channel;
	buf[11] = op;
	buf[12] = (uint8_t)data_len;
	if (data_len)
		memcpy(buf + VMAC_HDR_LEN, data, data_len);
	return VMAC_HDR_LEN + data_len;
}

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

/* ---- CYCLIC frames ---------------------------------------------------- */

static void put_record(uint8_t *frame, unsigned index, uint16_t tag, uint8_t flags, uint8_t digital, int16_t pwm)
{
	struct vmac_outputs out;
	out.digital = digital;
	out.pwm = pwm;
	vmac_proto_cyclic_put(frame, index, tag, flags, &out);
}

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

	ck_assert_msg(VMAC_CYCLIC_FRAME_MAX == 1455, "VMAC_CYCLIC_FRAME_MAX is %d, want 15 + 6 * 240 = 1455",
	              VMAC_CYCLIC_FRAME_MAX);
	ck_assert_msg(VMAC_CYCLIC_FRAME_MAX <= VMAC_PACKET_MAX, "largest CYCLIC (%d) exceeds one Ethernet payload (%d)",
	              VMAC_CYCLIC_FRAME_MAX, VMAC_PACKET_MAX);
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 9, 240, VMAC_CYCLIC_RECORDS_MAX);
	ck_assert_msg(n == VMAC_CYCLIC_FRAME_MAX, "cyclic_begin of 240 records returned %s, want %d", errname(n),
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
	ck_assert_msg(n == VMAC_CYCLIC_FRAME_MAX, "cyclic_begin of 240 records from 65295 (last 65534): got %s",
	              errname(n));
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
	buf[3] = 0x02;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "CYCLIC with flag bit 1");
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

/* ---- the board: fake HAL ---------------------------------------------- */

#define MAX_WRITES 64

struct fake_io {
	struct vmac_outputs writes[MAX_WRITES]; /* every write_outputs call, in order */
	int n_writes;
	struct vmac_inputs inputs; /* what read_inputs returns, always */
};

static void fake_read_inputs(void *ctx, struct vmac_inputs *in)
{
	struct fake_io *io = ctx;
	*in = io->inputs;
	/* Junk in `applied`: the board must overwrite it with what it drives. */
	in->applied.digital = 0x33;
	in->applied.pwm = 333;
}

static void fake_write_outputs(void *ctx, const struct vmac_outputs *out)
{
	struct fake_io *io = ctx;
	ck_assert_msg(io->n_writes < MAX_WRITES, "more than %d write_outputs calls", MAX_WRITES);
	io->writes[io->n_writes++] = *out;
}

static const struct vmac_board_io fake_hal = {fake_read_inputs, fake_write_outputs};

/* ---- the bench: a board, its HAL and its last reply ------------------- */

#define BOARD_MAJOR 3
#define BOARD_MINOR 7
#define RIVAL_MINOR 8
#define SESSION_ID 0x00050025u     /* generation 5, slot 37 */
#define SESSION_TAG 5              /* SESSION_ID >> 16 */
#define NEW_SESSION_ID 0x00060025u /* generation 6 of slot 37: the offset's next holder */
#define OTHER_ID 0x00BADBADu
#define SLOT 37 /* the offset the host gives */
#define SPAN 40 /* records in the test's CYCLIC frames: offsets 0..39 */
#define START_MS 1000

struct bench {
	struct vmac_board board;
	struct fake_io io;
	uint8_t reply[VMAC_FRAME_MAX];
	int reply_len;
	struct vmac_msg answer; /* reply_len > 0: the decoded reply */
	const char *name;
};

static struct bench rig;   /* the board under test */
static struct bench rival; /* a second board on the same bus */
static uint64_t now_ms;

static void bench_init(struct bench *b, const char *name, uint32_t minor, uint8_t protocol)
{
	struct vmac_board_identity id;
	memset(b, 0, sizeof(*b));
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "test_motor");
	strcpy(id.board, name);
	id.major = BOARD_MAJOR;
	id.minor = minor;
	id.caps.digital_inputs = 8;
	id.caps.digital_outputs = 7;
	id.caps.analog_inputs = 2;
	id.caps.pwm_outputs = 1;
	id.caps.encoders = 1;
	id.protocol = protocol;
	b->name = name;
	b->io.inputs.digital = 0xC3;
	b->io.inputs.analog[0] = 1234;
	b->io.inputs.analog[1] = VMAC_ANALOG_MAX;
	b->io.inputs.encoder = -98765;
	vmac_board_init(&b->board, &id, &fake_hal, &b->io, now_ms);
}

static void setup(void)
{
	now_ms = START_MS;
	bench_init(&rig, "bench-1", BOARD_MINOR, 0);
	bench_init(&rival, "bench-2", RIVAL_MINOR, 0);
}

/* Deliver raw bytes at now_ms; decode any reply into b->answer. */
static int deliver(struct bench *b, const uint8_t *frame, size_t len)
{
	uint8_t *copy = heap_copy(frame, len);
	int rc;
	memset(b->reply, 0, sizeof(b->reply));
	memset(&b->answer, 0, sizeof(b->answer));
	b->reply_len = vmac_board_receive(&b->board, copy, len, now_ms, b->reply, sizeof(b->reply));
	free(copy);
	ck_assert_msg(b->reply_len >= 0 && b->reply_len <= VMAC_FRAME_MAX, "%s: reply length %d outside 0..%d", b->name,
	              b->reply_len, VMAC_FRAME_MAX);
	if (b->reply_len > 0) {
		rc = vmac_proto_decode(b->reply, (size_t)b->reply_len, &b->answer);
		ck_assert_msg(rc == 0, "%s: its %d-byte reply does not decode: %s", b->name, b->reply_len, errname(rc));
		ck_assert_msg(b->answer.flags & VMAC_FLAG_REPLY, "%s: its reply lacks the reply flag (flags 0x%02x)",
		              b->name, b->answer.flags);
	}
	return b->reply_len;
}

static int send_msg(struct bench *b, const struct vmac_msg *m)
{
	uint8_t frame[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(m, frame, sizeof(frame));
	ck_assert_msg(n > 0, "test bug: cannot encode request op 0x%02x: %s", m->op, errname(n));
	return deliver(b, frame, (size_t)n);
}

static int send_op(struct bench *b, uint8_t version, uint8_t op, uint32_t device_id, uint16_t seq)
{
	struct vmac_msg m = msg(version, 0, VMAC_CH_DEVICE, op, device_id, seq);
	return send_msg(b, &m);
}

static int send_discover(struct bench *b, uint16_t seq)
{
	struct vmac_msg m = msg(1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, seq); /* always sent as version 1 */
	return send_msg(b, &m);
}

static int send_register(struct bench *b, uint8_t version, uint32_t device_id, uint16_t watchdog_ms, uint16_t seq)
{
	struct vmac_msg m = msg(version, 0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, device_id, seq);
	m.u.reg.major = b->board.id.major;
	m.u.reg.minor = b->board.id.minor;
	m.u.reg.watchdog_ms = watchdog_ms;
	return send_msg(b, &m);
}

static int send_offset(struct bench *b, uint32_t device_id, uint16_t offset, uint16_t seq)
{
	struct vmac_msg m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, device_id, seq);
	m.u.offset = offset;
	return send_msg(b, &m);
}

static void expect_state(struct bench *b, enum vmac_board_state want, const char *when)
{
	ck_assert_msg(b->board.state == want, "%s, %s: board is %s, want %s", b->name, when,
	              vmac_board_state_name(b->board.state), vmac_board_state_name(want));
}

static void expect_silent(struct bench *b, const char *when)
{
	ck_assert_msg(b->reply_len == 0, "%s, %s: answered with %d bytes (channel 0x%02x op 0x%02x), want silence",
	              b->name, when, b->reply_len, b->answer.channel, b->answer.op);
}

static void expect_reply(struct bench *b, uint8_t op, uint16_t seq, uint32_t device_id, const char *when)
{
	ck_assert_msg(b->reply_len > 0, "%s, %s: no reply, want %s", b->name, when,
	              vmac_proto_opname(VMAC_CH_DEVICE, op));
	ck_assert_msg(b->answer.channel == VMAC_CH_DEVICE && b->answer.op == op,
	              "%s, %s: reply is channel 0x%02x %s, want the device channel's %s", b->name, when,
	              b->answer.channel, vmac_proto_opname(b->answer.channel, b->answer.op),
	              vmac_proto_opname(VMAC_CH_DEVICE, op));
	ck_assert_msg(b->reply[2] == 2 && b->answer.version == 2, "%s, %s: reply of version %u, want 2", b->name, when,
	              b->reply[2]);
	ck_assert_msg(b->answer.seq == seq, "%s, %s: reply seq %u, want %u", b->name, when, b->answer.seq, seq);
	ck_assert_msg(b->answer.device_id == device_id, "%s, %s: reply device id 0x%08x, want 0x%08x", b->name, when,
	              (unsigned)b->answer.device_id, (unsigned)device_id);
}

static void expect_offset(struct bench *b, uint16_t want, const char *when)
{
	ck_assert_msg(b->board.offset == want, "%s, %s: board holds offset %u, want %u", b->name, when, b->board.offset,
	              want);
}

static void expect_driving(struct bench *b, uint8_t digital, int16_t pwm, const char *when)
{
	const struct vmac_outputs *w;
	ck_assert_msg(b->io.n_writes > 0, "%s, %s: write_outputs was never called", b->name, when);
	w = &b->io.writes[b->io.n_writes - 1];
	ck_assert_msg(w->digital == digital && w->pwm == pwm,
	              "%s, %s: last write_outputs was 0x%02x/%d, want 0x%02x/%d", b->name, when, w->digital, w->pwm,
	              digital, pwm);
	ck_assert_msg(b->board.outputs.digital == digital && b->board.outputs.pwm == pwm,
	              "%s, %s: board says it drives 0x%02x/%d, want 0x%02x/%d", b->name, when, b->board.outputs.digital,
	              b->board.outputs.pwm, digital, pwm);
}

static void expect_no_write_since(struct bench *b, int n_writes, const char *when)
{
	ck_assert_msg(b->io.n_writes == n_writes,
	              "%s, %s: write_outputs called %d more times (last 0x%02x/%d), want none", b->name, when,
	              b->io.n_writes - n_writes, b->io.writes[b->io.n_writes - 1].digital,
	              b->io.writes[b->io.n_writes - 1].pwm);
}

static void expect_never_drove(struct bench *b, uint8_t digital, int16_t pwm, const char *when)
{
	int i;
	for (i = 0; i < b->io.n_writes; i++)
		ck_assert_msg(!(b->io.writes[i].digital == digital && b->io.writes[i].pwm == pwm),
		              "%s, %s: write %d drove 0x%02x/%d, a record that was not its own", b->name, when, i,
		              digital, pwm);
}

/* REGISTER in version 2 as device_id with the given watchdog; the board must
 * ack in version 2. */
static void register_v2(struct bench *b, uint32_t device_id, uint16_t watchdog_ms)
{
	send_register(b, 2, device_id, watchdog_ms, 100);
	expect_reply(b, VMAC_OP_REGISTER, 100, device_id, "REGISTER of version 2");
	expect_state(b, VMAC_BOARD_KNOWN, "after REGISTER");
}

/* REGISTER and OFFSET: the board is served by the cyclic frame at offset. */
static void join(struct bench *b, uint32_t device_id, uint16_t offset, uint16_t watchdog_ms)
{
	register_v2(b, device_id, watchdog_ms);
	send_offset(b, device_id, offset, 101);
	expect_reply(b, VMAC_OP_OFFSET, 101, device_id, "OFFSET");
	ck_assert_msg(b->answer.u.offset == offset, "%s: OFFSET %u echoed as %u", b->name, offset, b->answer.u.offset);
	expect_offset(b, offset, "after OFFSET");
}

/* A CYCLIC frame of offsets first..first+count-1, every record empty. */
struct cyclic_frame {
	uint8_t bytes[VMAC_CYCLIC_FRAME_MAX];
	int len;
	uint16_t first, seq;
};

static void cyclic_new(struct cyclic_frame *f, uint16_t seq, uint16_t first, unsigned count)
{
	f->len = vmac_proto_cyclic_begin(f->bytes, sizeof(f->bytes), seq, first, count);
	ck_assert_msg(f->len > 0, "test bug: cyclic_begin(first %u, count %u) returned %s", first, count,
	              errname(f->len));
	f->first = first;
	f->seq = seq;
}

static void cyclic_set(struct cyclic_frame *f, uint16_t offset, uint16_t tag, uint8_t flags, uint8_t digital,
                       int16_t pwm)
{
	put_record(f->bytes, (unsigned)(offset - f->first), tag, flags, digital, pwm);
}

static int send_cyclic(struct bench *b, const struct cyclic_frame *f)
{
	return deliver(b, f->bytes, (size_t)f->len);
}

/* Frame [0, SPAN) with one record at SLOT, sent to b. */
static int send_record(struct bench *b, uint16_t seq, uint16_t tag, uint8_t flags, uint8_t digital, int16_t pwm)
{
	struct cyclic_frame f;
	cyclic_new(&f, seq, 0, SPAN);
	cyclic_set(&f, SLOT, tag, flags, digital, pwm);
	return send_cyclic(b, &f);
}

static void expect_update_reply(struct bench *b, uint16_t seq, uint32_t device_id, uint8_t digital, int16_t pwm,
                                const char *when)
{
	const struct vmac_inputs *in = &b->answer.u.inputs;
	expect_reply(b, VMAC_OP_UPDATE, seq, device_id, when);
	ck_assert_msg(b->reply_len == VMAC_HDR_LEN + 12, "%s, %s: UPDATE reply of %d bytes, want 25", b->name, when,
	              b->reply_len);
	ck_assert_msg(in->digital == 0xC3 && in->analog[0] == 1234 && in->analog[1] == VMAC_ANALOG_MAX &&
	                  in->encoder == -98765,
	              "%s, %s: reply inputs 0x%02x/%u/%u/%ld, want the HAL's 0xc3/1234/4095/-98765", b->name, when,
	              in->digital, in->analog[0], in->analog[1], (long)in->encoder);
	ck_assert_msg(in->applied.digital == digital && in->applied.pwm == pwm,
	              "%s, %s: reply applied 0x%02x/%d, want the 0x%02x/%d just driven", b->name, when,
	              in->applied.digital, in->applied.pwm, digital, pwm);
}

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

static Suite *cyclic_suite(void)
{
	Suite *s = suite_create("cyclic");
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

	tc = tcase_create("board_takeover");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, stale_board_never_drives_the_new_holder_of_its_offset);
	tcase_add_test(tc, empty_record_never_feeds_a_session_of_generation_0);
	suite_add_tcase(s, tc);

	return s;
}

int main(void)
{
	SRunner *runner = srunner_create(cyclic_suite());
	int failed;

	srunner_run_all(runner, CK_NORMAL);
	failed = srunner_ntests_failed(runner);
	srunner_free(runner);
	return failed == 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}
