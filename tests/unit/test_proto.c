/* Unit tests for the wire codec (core/proto), protocol version 1: round
 * trips of every message, the pinned byte layout, and the texts of errors and
 * ops. Every rejection is in test_proto_reject.c; the helpers both use are in
 * proto_helpers.h. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "check_main.h"
#include "proto_helpers.h"

/* ---- helpers ---------------------------------------------------------- */

/* Encode, then decode what was encoded; both must succeed and the header
 * fields must survive. The decoded message is returned through out. */
static void roundtrip(const struct vmac_msg *in, struct vmac_msg *out, const char *what)
{
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(in, buf, sizeof(buf));
	int rc;

	ck_assert_msg(n >= VMAC_HDR_LEN, "%s: encode returned %s, want a frame of >= %d bytes", what, errname(n),
	              VMAC_HDR_LEN);
	ck_assert_msg(buf[12] == n - VMAC_HDR_LEN, "%s: len byte %u but frame has %d data bytes", what, buf[12],
	              n - VMAC_HDR_LEN);
	rc = vmac_proto_decode(buf, (size_t)n, out);
	ck_assert_msg(rc == 0, "%s: decode of own %d-byte frame returned %s", what, n, errname(rc));
	ck_assert_msg(out->flags == in->flags, "%s: flags 0x%02x came back as 0x%02x", what, in->flags, out->flags);
	ck_assert_msg(out->seq == in->seq, "%s: seq %u came back as %u", what, in->seq, out->seq);
	ck_assert_msg(out->device_id == in->device_id, "%s: device_id 0x%08x came back as 0x%08x", what,
	              (unsigned)in->device_id, (unsigned)out->device_id);
	ck_assert_msg(out->channel == in->channel, "%s: channel 0x%02x came back as 0x%02x", what, in->channel,
	              out->channel);
	ck_assert_msg(out->op == in->op, "%s: op 0x%02x came back as 0x%02x", what, in->op, out->op);
}

/* ---- round trips ------------------------------------------------------ */

START_TEST(discover_request_roundtrips)
{
	struct vmac_msg in = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 0xBEEF), out;
	roundtrip(&in, &out, "DISCOVER request");
}
END_TEST

START_TEST(announce_reply_with_longest_names_roundtrips)
{
	struct vmac_msg in = sample_announce(), out;
	memset(in.u.announce.driver, 'd', VMAC_NAME_MAX);
	in.u.announce.driver[0] = 'A';
	in.u.announce.driver[VMAC_NAME_MAX - 1] = '9';
	in.u.announce.driver[VMAC_NAME_MAX] = '\0';
	memset(in.u.announce.board, 'b', VMAC_NAME_MAX);
	in.u.announce.board[1] = '_';
	in.u.announce.board[2] = '-';
	in.u.announce.board[VMAC_NAME_MAX] = '\0';
	in.u.announce.major = 0xFFFFFFFEu;
	in.u.announce.minor = 0x80000001u;
	in.u.announce.firmware_major = 250;
	in.u.announce.firmware_minor = 3;

	roundtrip(&in, &out, "ANNOUNCE with 31-byte names");
	ck_assert_msg(strcmp(out.u.announce.driver, in.u.announce.driver) == 0, "driver \"%s\" came back as \"%s\"",
	              in.u.announce.driver, out.u.announce.driver);
	ck_assert_msg(strcmp(out.u.announce.board, in.u.announce.board) == 0, "board \"%s\" came back as \"%s\"",
	              in.u.announce.board, out.u.announce.board);
	ck_assert_msg(out.u.announce.major == in.u.announce.major && out.u.announce.minor == in.u.announce.minor,
	              "major/minor 0x%08x/0x%08x came back as 0x%08x/0x%08x", (unsigned)in.u.announce.major,
	              (unsigned)in.u.announce.minor, (unsigned)out.u.announce.major, (unsigned)out.u.announce.minor);
	ck_assert_msg(out.u.announce.firmware_major == 250 && out.u.announce.firmware_minor == 3,
	              "firmware 250.3 came back as %u.%u", out.u.announce.firmware_major,
	              out.u.announce.firmware_minor);
	ck_assert_msg(memcmp(&out.u.announce.caps, &in.u.announce.caps, sizeof(in.u.announce.caps)) == 0,
	              "caps 8/7/2/1/1 came back as %u/%u/%u/%u/%u", out.u.announce.caps.digital_inputs,
	              out.u.announce.caps.digital_outputs, out.u.announce.caps.analog_inputs,
	              out.u.announce.caps.pwm_outputs, out.u.announce.caps.encoders);
}
END_TEST

START_TEST(register_request_roundtrips)
{
	struct vmac_msg in = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, 0xCAFEF00Du, 1), out;
	in.u.reg.major = 0x01020304u;
	in.u.reg.minor = 0xA0B0C0D0u;
	in.u.reg.watchdog_ms = 60000;
	roundtrip(&in, &out, "REGISTER request");
	ck_assert_msg(
	    out.u.reg.major == in.u.reg.major && out.u.reg.minor == in.u.reg.minor && out.u.reg.watchdog_ms == 60000,
	    "REGISTER 0x%08x/0x%08x/60000 ms came back as 0x%08x/0x%08x/%u ms", (unsigned)in.u.reg.major,
	    (unsigned)in.u.reg.minor, (unsigned)out.u.reg.major, (unsigned)out.u.reg.minor, out.u.reg.watchdog_ms);

	in.u.reg.watchdog_ms = 1;
	roundtrip(&in, &out, "REGISTER request, 1 ms watchdog");
	ck_assert_msg(out.u.reg.watchdog_ms == 1, "watchdog 1 ms came back as %u", out.u.reg.watchdog_ms);
}
END_TEST

START_TEST(register_ack_roundtrips)
{
	struct vmac_msg in = reply(VMAC_CH_DEVICE, VMAC_OP_REGISTER, 0xCAFEF00Du, 1), out;
	roundtrip(&in, &out, "REGISTER ack");
}
END_TEST

START_TEST(shutdown_request_and_ack_roundtrip)
{
	struct vmac_msg in = request(VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, 9, 3), out;
	in.u.shutdown_reason = VMAC_SHUT_DRIVER;
	roundtrip(&in, &out, "SHUTDOWN request");
	ck_assert_msg(out.u.shutdown_reason == VMAC_SHUT_DRIVER, "shutdown reason %d came back as %u", VMAC_SHUT_DRIVER,
	              out.u.shutdown_reason);

	in = reply(VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, 9, 3);
	roundtrip(&in, &out, "SHUTDOWN ack");
}
END_TEST

START_TEST(update_request_with_negative_pwm_roundtrips)
{
	static const int16_t pwms[] = {-VMAC_PWM_MAX, -1, 0, 1, VMAC_PWM_MAX};
	size_t i;
	for (i = 0; i < sizeof(pwms) / sizeof(pwms[0]); i++) {
		struct vmac_msg in = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, 77, (uint16_t)i), out;
		in.u.outputs.digital = 0x7F;
		in.u.outputs.pwm = pwms[i];
		roundtrip(&in, &out, "UPDATE request");
		ck_assert_msg(out.u.outputs.digital == 0x7F && out.u.outputs.pwm == pwms[i],
		              "UPDATE outputs 0x7f/%d came back as 0x%02x/%d", pwms[i], out.u.outputs.digital,
		              out.u.outputs.pwm);
	}
}
END_TEST

static void check_inputs_reply_roundtrips(uint8_t op, const char *what)
{
	struct vmac_msg in = sample_inputs_reply(op), out;
	roundtrip(&in, &out, what);
	ck_assert_msg(out.u.inputs.digital == 0xA5, "%s: digital 0xa5 came back as 0x%02x", what, out.u.inputs.digital);
	ck_assert_msg(out.u.inputs.analog[0] == 0 && out.u.inputs.analog[1] == VMAC_ANALOG_MAX,
	              "%s: analog 0/4095 came back as %u/%u", what, out.u.inputs.analog[0], out.u.inputs.analog[1]);
	ck_assert_msg(out.u.inputs.encoder == -123456789, "%s: encoder -123456789 came back as %ld", what,
	              (long)out.u.inputs.encoder);
	ck_assert_msg(out.u.inputs.applied.digital == 0x7F && out.u.inputs.applied.pwm == -VMAC_PWM_MAX,
	              "%s: applied 0x7f/-1000 came back as 0x%02x/%d", what, out.u.inputs.applied.digital,
	              out.u.inputs.applied.pwm);
}

START_TEST(update_reply_with_negative_pwm_and_encoder_roundtrips)
{
	struct vmac_msg in = sample_inputs_reply(VMAC_OP_UPDATE), out;
	check_inputs_reply_roundtrips(VMAC_OP_UPDATE, "UPDATE reply");

	in.u.inputs.encoder = INT32_MIN;
	roundtrip(&in, &out, "UPDATE reply, INT32_MIN encoder");
	ck_assert_msg(out.u.inputs.encoder == INT32_MIN, "encoder INT32_MIN came back as %ld",
	              (long)out.u.inputs.encoder);
}
END_TEST

START_TEST(idle_request_and_reply_roundtrip)
{
	struct vmac_msg in = request(VMAC_CH_DEVICE, VMAC_OP_IDLE, 5, 6), out;
	roundtrip(&in, &out, "IDLE request");
	check_inputs_reply_roundtrips(VMAC_OP_IDLE, "IDLE reply");
}
END_TEST

START_TEST(error_reply_roundtrips_for_every_code)
{
	static const uint8_t codes[] = {VMAC_BERR_NOT_REGISTERED, VMAC_BERR_BAD_REQUEST, VMAC_BERR_IDENTITY};
	size_t i;
	for (i = 0; i < sizeof(codes); i++) {
		struct vmac_msg in = reply(VMAC_CH_DEVICE, VMAC_OP_ERROR, 0x10, 0xFFFF), out;
		in.u.error.code = codes[i];
		in.u.error.op = VMAC_OP_WATCHDOG;
		roundtrip(&in, &out, "ERROR reply");
		ck_assert_msg(out.u.error.code == codes[i] && out.u.error.op == VMAC_OP_WATCHDOG,
		              "ERROR code %u op %u came back as code %u op %u", codes[i], VMAC_OP_WATCHDOG,
		              out.u.error.code, out.u.error.op);
	}
}
END_TEST

START_TEST(sleep_request_and_ack_roundtrip)
{
	static const uint16_t secs[] = {1, 3600};
	size_t i;
	struct vmac_msg in, out;
	for (i = 0; i < 2; i++) {
		in = request(VMAC_CH_DEVICE, VMAC_OP_SLEEP, 8, 1);
		in.u.sleep_s = secs[i];
		roundtrip(&in, &out, "SLEEP request");
		ck_assert_msg(out.u.sleep_s == secs[i], "sleep %u s came back as %u s", secs[i], out.u.sleep_s);
	}
	in = reply(VMAC_CH_DEVICE, VMAC_OP_SLEEP, 8, 1);
	roundtrip(&in, &out, "SLEEP ack");
}
END_TEST

START_TEST(watchdog_request_and_ack_roundtrip)
{
	static const uint16_t periods[] = {1, 60000};
	size_t i;
	struct vmac_msg in, out;
	for (i = 0; i < 2; i++) {
		in = request(VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, 8, 1);
		in.u.watchdog_ms = periods[i];
		roundtrip(&in, &out, "WATCHDOG request");
		ck_assert_msg(out.u.watchdog_ms == periods[i], "watchdog %u ms came back as %u ms", periods[i],
		              out.u.watchdog_ms);
	}
	in = reply(VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, 8, 1);
	roundtrip(&in, &out, "WATCHDOG ack");
}
END_TEST

/* ---- the wire format, byte for byte ----------------------------------- */

START_TEST(update_request_has_pinned_wire_bytes)
{
	static const uint8_t want[] = {
	    'V',  'M',  1,    0x00, /* magic, version, flags */
	    0x12, 0x34,             /* seq, big-endian */
	    0xA1, 0xB2, 0xC3, 0xD4, /* device id, big-endian */
	    0x00, 0x02, 0x03,       /* device channel, UPDATE, 3 data bytes */
	    0x55, 0xFF, 0x06,       /* digital, pwm -250 big-endian */
	};
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, 0xA1B2C3D4u, 0x1234), back;
	uint8_t buf[VMAC_FRAME_MAX];
	int n, rc;

	m.u.outputs.digital = 0x55;
	m.u.outputs.pwm = -250;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	expect_bytes(buf, n, want, (int)sizeof(want), "UPDATE request");

	rc = vmac_proto_decode(want, sizeof(want), &back);
	ck_assert_msg(rc == 0, "decode of the pinned UPDATE bytes returned %s", errname(rc));
	ck_assert_msg(back.seq == 0x1234 && back.device_id == 0xA1B2C3D4u && back.u.outputs.digital == 0x55 &&
	                  back.u.outputs.pwm == -250,
	              "pinned UPDATE decoded as seq 0x%04x id 0x%08x digital 0x%02x pwm %d", back.seq,
	              (unsigned)back.device_id, back.u.outputs.digital, back.u.outputs.pwm);
}
END_TEST

START_TEST(discover_request_has_pinned_wire_bytes)
{
	static const uint8_t want[] = {
	    'V',  'M',  1,    0x00, /* magic, version, flags */
	    0xBE, 0xEF,             /* seq */
	    0,    0,    0,    0,    /* device id: none on the system channel */
	    0xFF, 0x01, 0x00,       /* system channel, DISCOVER, no data */
	};
	struct vmac_msg m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 0xBEEF), back;
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(&m, buf, sizeof(buf)), rc;

	expect_bytes(buf, n, want, (int)sizeof(want), "DISCOVER request");
	rc = vmac_proto_decode(want, sizeof(want), &back);
	ck_assert_msg(rc == 0 && back.seq == 0xBEEF && back.channel == VMAC_CH_SYSTEM && back.op == VMAC_SYS_DISCOVER,
	              "pinned DISCOVER decoded as rc %d seq 0x%04x channel 0x%02x op 0x%02x", rc, back.seq,
	              back.channel, back.op);
}
END_TEST
/* ---- texts ------------------------------------------------------------ */

START_TEST(strerror_has_text_for_every_error)
{
	static const int errs[] = {VMAC_EPROTO_SHORT,  VMAC_EPROTO_MAGIC, VMAC_EPROTO_VERSION,
	                           VMAC_EPROTO_LENGTH, VMAC_EPROTO_OP,    VMAC_EPROTO_PAYLOAD,
	                           VMAC_EPROTO_NAME,   VMAC_EPROTO_VALUE, VMAC_EPROTO_SPACE};
	const char *unknown = vmac_proto_strerror(-1000);
	size_t i, j;

	ck_assert_msg(unknown != NULL && unknown[0] != '\0', "strerror(-1000) gave no text");
	ck_assert_msg(vmac_proto_strerror(1) != NULL, "strerror(1) returned NULL");
	for (i = 0; i < sizeof(errs) / sizeof(errs[0]); i++) {
		const char *text = vmac_proto_strerror(errs[i]);
		ck_assert_msg(text != NULL && text[0] != '\0', "strerror(%d) gave no text", errs[i]);
		ck_assert_msg(strcmp(text, unknown) != 0, "strerror(%d) gave the unknown-error text \"%s\"", errs[i],
		              text);
		for (j = 0; j < i; j++)
			ck_assert_msg(strcmp(text, vmac_proto_strerror(errs[j])) != 0,
			              "strerror(%d) and strerror(%d) share the text \"%s\"", errs[i], errs[j], text);
	}
}
END_TEST

START_TEST(opname_names_every_op)
{
	static const struct {
		uint8_t channel, op;
		const char *name;
	} ops[] = {
	    {VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, "DISCOVER"}, {VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, "ANNOUNCE"},
	    {VMAC_CH_DEVICE, VMAC_OP_REGISTER, "REGISTER"},  {VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, "SHUTDOWN"},
	    {VMAC_CH_DEVICE, VMAC_OP_UPDATE, "UPDATE"},      {VMAC_CH_DEVICE, VMAC_OP_ERROR, "ERROR"},
	    {VMAC_CH_DEVICE, VMAC_OP_IDLE, "IDLE"},          {VMAC_CH_DEVICE, VMAC_OP_SLEEP, "SLEEP"},
	    {VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, "WATCHDOG"},  {VMAC_CH_DEVICE, VMAC_OP_SIZE, "SIZE"},
	    {VMAC_CH_DEVICE, VMAC_OP_OFFSET, "OFFSET"},      {VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, "OFFSET_GET"},
	    {VMAC_CH_SYSTEM, VMAC_SYS_CYCLIC, "CYCLIC"},     {VMAC_CH_DEVICE, 0x0A, "?"},
	    {VMAC_CH_SYSTEM, VMAC_OP_UPDATE, "?"},           {0x01, VMAC_OP_UPDATE, "?"},
	};
	size_t i;
	for (i = 0; i < sizeof(ops) / sizeof(ops[0]); i++) {
		const char *got = vmac_proto_opname(ops[i].channel, ops[i].op);
		ck_assert_msg(strcmp(got, ops[i].name) == 0, "opname(0x%02x, 0x%02x) is \"%s\", want \"%s\"",
		              ops[i].channel, ops[i].op, got, ops[i].name);
	}
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("proto");
	TCase *tc;

	tc = tcase_create("roundtrip");
	tcase_add_test(tc, discover_request_roundtrips);
	tcase_add_test(tc, announce_reply_with_longest_names_roundtrips);
	tcase_add_test(tc, register_request_roundtrips);
	tcase_add_test(tc, register_ack_roundtrips);
	tcase_add_test(tc, shutdown_request_and_ack_roundtrip);
	tcase_add_test(tc, update_request_with_negative_pwm_roundtrips);
	tcase_add_test(tc, update_reply_with_negative_pwm_and_encoder_roundtrips);
	tcase_add_test(tc, idle_request_and_reply_roundtrip);
	tcase_add_test(tc, error_reply_roundtrips_for_every_code);
	tcase_add_test(tc, sleep_request_and_ack_roundtrip);
	tcase_add_test(tc, watchdog_request_and_ack_roundtrip);
	suite_add_tcase(s, tc);

	tc = tcase_create("wire");
	tcase_add_test(tc, update_request_has_pinned_wire_bytes);
	tcase_add_test(tc, discover_request_has_pinned_wire_bytes);
	suite_add_tcase(s, tc);

	tc = tcase_create("text");
	tcase_add_test(tc, strerror_has_text_for_every_error);
	tcase_add_test(tc, opname_names_every_op);
	suite_add_tcase(s, tc);

	return s;
}
