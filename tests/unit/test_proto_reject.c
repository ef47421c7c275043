/* Unit tests for the wire codec (core/proto), protocol version 1: every
 * rejection with its exact error code, by the decoder (bad header, bad
 * payload, values out of range, truncation) and by the encoder (values out of
 * range, a buffer too small). Round trips and pinned bytes are in
 * test_proto.c; the helpers both use are in proto_helpers.h. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "check_main.h"
#include "proto_helpers.h"

/* ---- helpers ---------------------------------------------------------- */

/* Frames of device 42, seq 1, built byte by byte (frames.h, raw_frame):
 * each valid but for the value under test. */
static size_t raw_update_request(uint8_t *buf, uint8_t digital, int16_t pwm)
{
	uint8_t d[3] = {digital, (uint8_t)((uint16_t)pwm >> 8), (uint8_t)pwm};
	return raw_frame(buf, 1, 0, 1, 42, VMAC_CH_DEVICE, VMAC_OP_UPDATE, d, sizeof(d));
}

static size_t raw_inputs_reply(uint8_t *buf, uint16_t analog0, uint16_t analog1, uint8_t applied_digital,
                               int16_t applied_pwm)
{
	uint8_t d[12] = {0};
	d[1] = (uint8_t)(analog0 >> 8);
	d[2] = (uint8_t)analog0;
	d[3] = (uint8_t)(analog1 >> 8);
	d[4] = (uint8_t)analog1;
	d[9] = applied_digital;
	d[10] = (uint8_t)((uint16_t)applied_pwm >> 8);
	d[11] = (uint8_t)applied_pwm;
	return raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 42, VMAC_CH_DEVICE, VMAC_OP_UPDATE, d, sizeof(d));
}

static size_t raw_u16_request(uint8_t *buf, uint8_t op, uint16_t value)
{
	uint8_t d[2] = {(uint8_t)(value >> 8), (uint8_t)value};
	return raw_frame(buf, 1, 0, 1, 42, VMAC_CH_DEVICE, op, d, sizeof(d));
}

static size_t raw_register_request(uint8_t *buf, uint16_t watchdog_ms)
{
	uint8_t d[10] = {0, 0, 0, 2, 0, 0, 0, 5, (uint8_t)(watchdog_ms >> 8), (uint8_t)watchdog_ms};
	return raw_frame(buf, 1, 0, 1, 42, VMAC_CH_DEVICE, VMAC_OP_REGISTER, d, sizeof(d));
}

static size_t raw_error_reply(uint8_t *buf, uint8_t code)
{
	uint8_t d[2] = {code, VMAC_OP_UPDATE};
	return raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 42, VMAC_CH_DEVICE, VMAC_OP_ERROR, d, sizeof(d));
}

/* ---- header rejections ------------------------------------------------ */

START_TEST(frame_shorter_than_header_is_short)
{
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0), len;
	ck_assert_msg(n == VMAC_HDR_LEN, "a DISCOVER is %zu bytes, want %d", n, VMAC_HDR_LEN);
	for (len = 0; len < VMAC_HDR_LEN; len++)
		expect_decode_err(buf, len, VMAC_EPROTO_SHORT, "header prefix");
}
END_TEST

START_TEST(bad_magic_is_rejected)
{
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
	buf[0] = 'X';
	expect_decode_err(buf, n, VMAC_EPROTO_MAGIC, "first magic byte 'X'");
	buf[0] = VMAC_MAGIC0;
	buf[1] = 'm';
	expect_decode_err(buf, n, VMAC_EPROTO_MAGIC, "second magic byte 'm'");
	buf[0] = VMAC_MAGIC1;
	buf[1] = VMAC_MAGIC0;
	expect_decode_err(buf, n, VMAC_EPROTO_MAGIC, "magic bytes swapped");
}
END_TEST

START_TEST(wrong_version_is_rejected)
{
	static const uint8_t versions[] = {0, 3, 0xFF};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0), i;
	for (i = 0; i < sizeof(versions); i++) {
		buf[2] = versions[i];
		expect_decode_err(buf, n, VMAC_EPROTO_VERSION, "version byte 0/3/255");
	}
}
END_TEST

START_TEST(length_byte_disagreeing_with_size_is_rejected)
{
	uint8_t buf[VMAC_FRAME_MAX + 8];
	size_t n = raw_update_request(buf, 1, 2);

	buf[12] = 4; /* claims more data than arrived */
	expect_decode_err(buf, n, VMAC_EPROTO_LENGTH, "UPDATE whose len byte says 4 of 3");
	buf[12] = 2; /* claims less data than arrived */
	expect_decode_err(buf, n, VMAC_EPROTO_LENGTH, "UPDATE whose len byte says 2 of 3");
	buf[12] = 3;
	buf[n] = 0;
	expect_decode_err(buf, n + 1, VMAC_EPROTO_LENGTH, "UPDATE with a trailing byte");
	expect_decode_err(buf, n - 1, VMAC_EPROTO_LENGTH, "UPDATE missing its last byte");

	n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
	buf[12] = 0xFF;
	expect_decode_err(buf, n, VMAC_EPROTO_LENGTH, "DISCOVER whose len byte says 255");
	memset(buf + n, 0, VMAC_DATA_MAX + 1);
	buf[12] = VMAC_DATA_MAX + 1;
	expect_decode_err(buf, n + VMAC_DATA_MAX + 1, VMAC_EPROTO_LENGTH, "frame with 97 data bytes, len 97");
}
END_TEST

START_TEST(unknown_op_or_channel_is_rejected)
{
	static const uint8_t device_ops[] = {0x07, 0x10, 0x7F, 0xFF};
	static const uint8_t system_ops[] = {0x00, 0x02, VMAC_OP_UPDATE, 0x11, 0xFF};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n, i;
	struct vmac_msg m;

	for (i = 0; i < sizeof(device_ops); i++) {
		n = raw_frame(buf, 1, 0, 1, 42, VMAC_CH_DEVICE, device_ops[i], NULL, 0);
		expect_decode_err(buf, n, VMAC_EPROTO_OP, "device request with unknown op");
		n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 42, VMAC_CH_DEVICE, device_ops[i], NULL, 0);
		expect_decode_err(buf, n, VMAC_EPROTO_OP, "device reply with unknown op");
		m = request(VMAC_CH_DEVICE, device_ops[i], 42, 1);
		expect_encode_err(&m, VMAC_EPROTO_OP, "device request with unknown op");
	}
	for (i = 0; i < sizeof(system_ops); i++) {
		n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, system_ops[i], NULL, 0);
		expect_decode_err(buf, n, VMAC_EPROTO_OP, "system request with unknown op");
		m = request(VMAC_CH_SYSTEM, system_ops[i], 0, 1);
		expect_encode_err(&m, VMAC_EPROTO_OP, "system request with unknown op");
	}
	n = raw_frame(buf, 1, 0, 1, 42, 0x01, VMAC_OP_IDLE, NULL, 0);
	expect_decode_err(buf, n, VMAC_EPROTO_OP, "IDLE on channel 0x01");
	m = request(0x01, VMAC_OP_IDLE, 42, 1);
	expect_encode_err(&m, VMAC_EPROTO_OP, "IDLE on channel 0x01");
}
END_TEST

START_TEST(op_in_wrong_direction_is_rejected)
{
	uint8_t buf[VMAC_FRAME_MAX], data[VMAC_DATA_MAX];
	size_t n;
	struct vmac_msg m;

	/* Requests sent with the reply flag. */
	n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
	expect_decode_err(buf, n, VMAC_EPROTO_OP, "DISCOVER flagged as a reply");
	m = reply(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	expect_encode_err(&m, VMAC_EPROTO_OP, "DISCOVER flagged as a reply");

	/* Replies sent as requests. */
	n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data,
	              raw_announce_data(data, (const uint8_t *)"drv", 3, (const uint8_t *)"brd", 3));
	expect_decode_err(buf, n, VMAC_EPROTO_OP, "ANNOUNCE without the reply flag");
	m = sample_announce();
	m.flags = 0;
	expect_encode_err(&m, VMAC_EPROTO_OP, "ANNOUNCE without the reply flag");

	data[0] = VMAC_BERR_BAD_REQUEST;
	data[1] = VMAC_OP_UPDATE;
	n = raw_frame(buf, 1, 0, 1, 42, VMAC_CH_DEVICE, VMAC_OP_ERROR, data, 2);
	expect_decode_err(buf, n, VMAC_EPROTO_OP, "ERROR without the reply flag");
	m = request(VMAC_CH_DEVICE, VMAC_OP_ERROR, 42, 1);
	m.u.error.code = VMAC_BERR_BAD_REQUEST;
	expect_encode_err(&m, VMAC_EPROTO_OP, "ERROR without the reply flag");
}
END_TEST

START_TEST(unknown_flag_bits_are_rejected)
{
	static const uint8_t flags[] = {0x04, 0x05, 0x80, 0x81, 0xFC};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n, i;
	struct vmac_msg m;
	for (i = 0; i < sizeof(flags); i++) {
		n = raw_frame(buf, 1, flags[i], 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
		expect_decode_err(buf, n, VMAC_EPROTO_OP, "DISCOVER with unknown flag bits");
		n = raw_frame(buf, 1, flags[i], 1, 42, VMAC_CH_DEVICE, VMAC_OP_IDLE, NULL, 0);
		expect_decode_err(buf, n, VMAC_EPROTO_OP, "IDLE with unknown flag bits");
		m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
		m.flags = flags[i];
		expect_encode_err(&m, VMAC_EPROTO_OP, "DISCOVER with unknown flag bits");
	}
}
END_TEST

START_TEST(device_id_must_match_channel)
{
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n;
	struct vmac_msg m;

	n = raw_frame(buf, 1, 0, 1, 1, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
	expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "DISCOVER with device id 1");
	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0x80000000u, 1);
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "DISCOVER with device id 0x80000000");

	n = raw_frame(buf, 1, 0, 1, 0, VMAC_CH_DEVICE, VMAC_OP_IDLE, NULL, 0);
	expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "IDLE with device id 0");
	m = request(VMAC_CH_DEVICE, VMAC_OP_IDLE, 0, 1);
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "IDLE with device id 0");
}
END_TEST

/* ---- payload rejections ----------------------------------------------- */

START_TEST(payload_size_wrong_for_op_is_rejected)
{
	static const struct {
		uint8_t flags, channel, op;
		size_t bad_len;
		const char *what;
	} cases[] = {
	    {0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 1, "DISCOVER with 1 data byte"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, 9, "REGISTER with 9 data bytes"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, 11, "REGISTER with 11 data bytes"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_REGISTER, 1, "REGISTER ack with 1 data byte"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, 0, "SHUTDOWN with no reason"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_UPDATE, 2, "UPDATE request with 2 data bytes"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_UPDATE, 4, "UPDATE request with 4 data bytes"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_UPDATE, 11, "UPDATE reply with 11 data bytes"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_UPDATE, 13, "UPDATE reply with 13 data bytes"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_IDLE, 1, "IDLE request with 1 data byte"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_IDLE, 3, "IDLE reply with 3 data bytes"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_ERROR, 1, "ERROR reply with 1 data byte"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_SLEEP, 3, "SLEEP with 3 data bytes"},
	    {VMAC_FLAG_REPLY, VMAC_CH_DEVICE, VMAC_OP_SLEEP, 2, "SLEEP ack with 2 data bytes"},
	    {0, VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, 1, "WATCHDOG with 1 data byte"},
	    {VMAC_FLAG_REPLY, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, 16, "ANNOUNCE with 16 data bytes"},
	};
	uint8_t buf[VMAC_FRAME_MAX], data[VMAC_DATA_MAX];
	size_t i, n;

	/* Non-zero data so a value check cannot fire before the size check. */
	memset(data, 0x01, sizeof(data));
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		uint32_t id = cases[i].channel == VMAC_CH_SYSTEM ? 0 : 42;
		n = raw_frame(buf, 1, cases[i].flags, 1, id, cases[i].channel, cases[i].op, data, cases[i].bad_len);
		expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, cases[i].what);
	}
}
END_TEST

START_TEST(announce_with_inconsistent_name_lengths_is_payload_error)
{
	uint8_t buf[VMAC_FRAME_MAX], data[VMAC_DATA_MAX];
	size_t dn = raw_announce_data(data, (const uint8_t *)"drv", 3, (const uint8_t *)"brd", 3), n;

	data[0] = 4; /* driver length one too long: board length lands elsewhere */
	n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data, dn);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "ANNOUNCE whose driver length overshoots");
	data[0] = 0xFF;
	n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data, dn);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "ANNOUNCE whose driver length is 255");
	data[0] = 3;
	data[1 + 3 + 8] = 2; /* board length one too short: a trailing byte left */
	n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data, dn);
	expect_decode_err(buf, n, VMAC_EPROTO_PAYLOAD, "ANNOUNCE whose board length undershoots");
}
END_TEST

/* Each bad name is tried as the driver and as the board field. */
static void expect_bad_name_decode(const uint8_t *name, size_t len, const char *what)
{
	uint8_t buf[VMAC_FRAME_MAX], data[VMAC_DATA_MAX];
	size_t dn, n;
	char label[128];

	dn = raw_announce_data(data, name, len, (const uint8_t *)"board", 5);
	n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data, dn);
	snprintf(label, sizeof(label), "ANNOUNCE with driver name %s", what);
	expect_decode_err(buf, n, VMAC_EPROTO_NAME, label);

	dn = raw_announce_data(data, (const uint8_t *)"driver", 6, name, len);
	n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data, dn);
	snprintf(label, sizeof(label), "ANNOUNCE with board name %s", what);
	expect_decode_err(buf, n, VMAC_EPROTO_NAME, label);
}

static void expect_bad_name_encode(const char *name, const char *what)
{
	struct vmac_msg m = sample_announce();
	char label[128];

	strcpy(m.u.announce.driver, name);
	snprintf(label, sizeof(label), "ANNOUNCE with driver name %s", what);
	expect_encode_err(&m, VMAC_EPROTO_NAME, label);

	m = sample_announce();
	strcpy(m.u.announce.board, name);
	snprintf(label, sizeof(label), "ANNOUNCE with board name %s", what);
	expect_encode_err(&m, VMAC_EPROTO_NAME, label);
}

START_TEST(bad_names_are_rejected)
{
	static const struct {
		const char *name;
		const char *what;
	} bad[] = {
	    {"", "empty"},
	    {"a.b", "containing '.'"},
	    {"a/b", "containing '/'"},
	    {"a b", "containing ' '"},
	    {"a\x80"
	     "b",
	     "containing 0x80"},
	};
	uint8_t long_name[VMAC_NAME_MAX + 1];
	size_t i;

	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		expect_bad_name_decode((const uint8_t *)bad[i].name, strlen(bad[i].name), bad[i].what);
		expect_bad_name_encode(bad[i].name, bad[i].what);
	}
	/* Only the decoder can be shown these: the struct cannot hold them. */
	expect_bad_name_decode((const uint8_t *)"a\0b", 3, "containing 0x00");
	memset(long_name, 'n', sizeof(long_name));
	expect_bad_name_decode(long_name, sizeof(long_name), "of 32 bytes");
}
END_TEST

START_TEST(announce_caps_beyond_the_board_are_rejected)
{
	uint8_t buf[VMAC_FRAME_MAX], data[VMAC_DATA_MAX];
	size_t dn = raw_announce_data(data, (const uint8_t *)"drv", 3, (const uint8_t *)"brd", 3), n, i;
	static const uint8_t too_many[5] = {VMAC_DIGITAL_INPUTS + 1, VMAC_DIGITAL_OUTPUTS + 1, VMAC_ANALOG_INPUTS + 1,
	                                    2, 2};
	for (i = 0; i < 5; i++) {
		uint8_t saved = data[dn - 5 + i];
		data[dn - 5 + i] = too_many[i];
		n = raw_frame(buf, 1, VMAC_FLAG_REPLY, 1, 0, VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, data, dn);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "ANNOUNCE with one capability over its maximum");
		data[dn - 5 + i] = saved;
	}
}
END_TEST

START_TEST(pwm_beyond_full_drive_is_rejected)
{
	static const int16_t bad[] = {VMAC_PWM_MAX + 1, -VMAC_PWM_MAX - 1, INT16_MAX, INT16_MIN};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t i, n;
	struct vmac_msg m;
	char what[64];

	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		snprintf(what, sizeof(what), "UPDATE request with pwm %d", bad[i]);
		n = raw_update_request(buf, 0, bad[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, what);
		m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, 42, 1);
		m.u.outputs.pwm = bad[i];
		expect_encode_err(&m, VMAC_EPROTO_VALUE, what);

		snprintf(what, sizeof(what), "UPDATE reply with applied pwm %d", bad[i]);
		n = raw_inputs_reply(buf, 0, 0, 0, bad[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, what);
		m = sample_inputs_reply(VMAC_OP_UPDATE);
		m.u.inputs.applied.pwm = bad[i];
		expect_encode_err(&m, VMAC_EPROTO_VALUE, what);
	}
}
END_TEST

START_TEST(digital_output_bit_7_is_rejected)
{
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n = raw_update_request(buf, 0x80, 0);
	struct vmac_msg m;

	expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "UPDATE request with digital 0x80");
	m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, 42, 1);
	m.u.outputs.digital = 0xFF;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "UPDATE request with digital 0xff");

	n = raw_inputs_reply(buf, 0, 0, 0x80, 0);
	expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "UPDATE reply with applied digital 0x80");
	m = sample_inputs_reply(VMAC_OP_IDLE);
	m.u.inputs.applied.digital = 0x80;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "IDLE reply with applied digital 0x80");
}
END_TEST

START_TEST(analog_4096_is_rejected)
{
	uint8_t buf[VMAC_FRAME_MAX];
	size_t n;
	int ch;
	struct vmac_msg m;

	for (ch = 0; ch < VMAC_ANALOG_INPUTS; ch++) {
		n = raw_inputs_reply(buf, ch == 0 ? 4096 : 0, ch == 1 ? 4096 : 0, 0, 0);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, "inputs reply with an analog of 4096");
		m = sample_inputs_reply(VMAC_OP_UPDATE);
		m.u.inputs.analog[ch] = VMAC_ANALOG_MAX + 1;
		expect_encode_err(&m, VMAC_EPROTO_VALUE, "inputs reply with an analog of 4096");
	}
}
END_TEST

START_TEST(watchdog_outside_1_to_60000_ms_is_rejected)
{
	static const uint16_t bad[] = {0, 60001, 0xFFFF};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t i, n;
	struct vmac_msg m;
	char what[64];

	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		snprintf(what, sizeof(what), "WATCHDOG %u ms", bad[i]);
		n = raw_u16_request(buf, VMAC_OP_WATCHDOG, bad[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, what);
		m = request(VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, 42, 1);
		m.u.watchdog_ms = bad[i];
		expect_encode_err(&m, VMAC_EPROTO_VALUE, what);

		snprintf(what, sizeof(what), "REGISTER with watchdog %u ms", bad[i]);
		n = raw_register_request(buf, bad[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, what);
		m = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, 42, 1);
		m.u.reg.watchdog_ms = bad[i];
		expect_encode_err(&m, VMAC_EPROTO_VALUE, what);
	}
}
END_TEST

START_TEST(sleep_outside_1_to_3600_s_is_rejected)
{
	static const uint16_t bad[] = {0, 3601, 0xFFFF};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t i, n;
	struct vmac_msg m;
	char what[64];

	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		snprintf(what, sizeof(what), "SLEEP %u s", bad[i]);
		n = raw_u16_request(buf, VMAC_OP_SLEEP, bad[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, what);
		m = request(VMAC_CH_DEVICE, VMAC_OP_SLEEP, 42, 1);
		m.u.sleep_s = bad[i];
		expect_encode_err(&m, VMAC_EPROTO_VALUE, what);
	}
}
END_TEST

START_TEST(error_code_outside_1_to_3_is_rejected_by_decode)
{
	static const uint8_t bad[] = {0, 4, 0xFF};
	uint8_t buf[VMAC_FRAME_MAX];
	size_t i, n;
	char what[64];

	for (i = 0; i < sizeof(bad); i++) {
		snprintf(what, sizeof(what), "ERROR reply with code %u", bad[i]);
		n = raw_error_reply(buf, bad[i]);
		expect_decode_err(buf, n, VMAC_EPROTO_VALUE, what);
	}
}
END_TEST

/* ---- encoder buffer space --------------------------------------------- */

#define CANARY 0xA5

/* For every cap below the frame's size: SPACE, and not one byte written at
 * or past cap. At exactly the frame's size: success. */
static void check_encode_respects_cap(const struct vmac_msg *m, const char *what)
{
	uint8_t full[VMAC_FRAME_MAX], buf[VMAC_FRAME_MAX + 16];
	int n = vmac_proto_encode(m, full, sizeof(full)), rc;
	size_t cap, i;

	ck_assert_msg(n > 0, "%s: encode with room returned %s", what, errname(n));
	for (cap = 0; cap < (size_t)n; cap++) {
		memset(buf, CANARY, sizeof(buf));
		rc = vmac_proto_encode(m, buf, cap);
		ck_assert_msg(rc == VMAC_EPROTO_SPACE, "%s: encode into %zu of %d bytes returned %s, want %d", what,
		              cap, n, errname(rc), VMAC_EPROTO_SPACE);
		for (i = cap; i < sizeof(buf); i++)
			ck_assert_msg(buf[i] == CANARY, "%s: encode with cap %zu wrote 0x%02x at offset %zu", what, cap,
			              buf[i], i);
	}
	memset(buf, CANARY, sizeof(buf));
	rc = vmac_proto_encode(m, buf, (size_t)n);
	ck_assert_msg(rc == n, "%s: encode into exactly %d bytes returned %s", what, n, errname(rc));
	ck_assert_msg(memcmp(buf, full, (size_t)n) == 0, "%s: exact-fit encode differs from roomy encode", what);
	for (i = (size_t)n; i < sizeof(buf); i++)
		ck_assert_msg(buf[i] == CANARY, "%s: exact-fit encode wrote 0x%02x at offset %zu", what, buf[i], i);
}

START_TEST(encode_into_small_buffer_is_space_and_writes_nothing_past_cap)
{
	struct vmac_msg m;
	struct vmac_msg update = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, 42, 1);
	struct vmac_msg reg = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, 42, 1);

	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	check_encode_respects_cap(&m, "DISCOVER");
	m = sample_announce();
	check_encode_respects_cap(&m, "ANNOUNCE");
	reg.u.reg.watchdog_ms = 500;
	check_encode_respects_cap(&reg, "REGISTER request");
	update.u.outputs.pwm = -5;
	check_encode_respects_cap(&update, "UPDATE request");
	m = sample_inputs_reply(VMAC_OP_UPDATE);
	check_encode_respects_cap(&m, "UPDATE reply");
	m = reply(VMAC_CH_DEVICE, VMAC_OP_ERROR, 42, 1);
	m.u.error.code = VMAC_BERR_IDENTITY;
	check_encode_respects_cap(&m, "ERROR reply");
	m = reply(VMAC_CH_DEVICE, VMAC_OP_SLEEP, 42, 1);
	check_encode_respects_cap(&m, "SLEEP ack");
}
END_TEST

/* ---- truncation ------------------------------------------------------- */

START_TEST(every_prefix_of_an_announce_is_rejected)
{
	struct vmac_msg m = sample_announce(), out;
	uint8_t buf[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(&m, buf, sizeof(buf)), rc;
	size_t len;

	ck_assert_msg(n > VMAC_HDR_LEN, "encode ANNOUNCE returned %s", errname(n));
	for (len = 0; len < (size_t)n; len++) {
		rc = decode_exact(buf, len, &out);
		ck_assert_msg(rc < 0, "decode of the first %zu of %d ANNOUNCE bytes returned %d, want an error", len, n,
		              rc);
	}
	rc = decode_exact(buf, (size_t)n, &out);
	ck_assert_msg(rc == 0, "decode of the whole %d-byte ANNOUNCE returned %s", n, errname(rc));
}
END_TEST

/* ---- contract gaps: encode accepts what decode rejects ---------------- */

/* proto.h: "Fields out of range are refused, never clipped." These fields have
 * ranges the decoder enforces; a frame the encoder makes but the decoder
 * refuses is a frame the peer will drop. */

START_TEST(encode_refuses_error_code_outside_1_to_3)
{
	static const uint8_t bad[] = {0, 4};
	size_t i;
	char what[64];
	for (i = 0; i < sizeof(bad); i++) {
		struct vmac_msg m = reply(VMAC_CH_DEVICE, VMAC_OP_ERROR, 42, 1);
		m.u.error.code = bad[i];
		snprintf(what, sizeof(what), "ERROR reply with code %u", bad[i]);
		expect_encode_err(&m, VMAC_EPROTO_VALUE, what);
	}
}
END_TEST

START_TEST(encode_refuses_caps_beyond_the_board)
{
	struct vmac_msg m = sample_announce();
	m.u.announce.caps.digital_inputs = VMAC_DIGITAL_INPUTS + 1;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "ANNOUNCE with 9 digital inputs");
	m = sample_announce();
	m.u.announce.caps.encoders = 2;
	expect_encode_err(&m, VMAC_EPROTO_VALUE, "ANNOUNCE with 2 encoders");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("proto_reject");
	TCase *tc;

	tc = tcase_create("reject");
	tcase_add_test(tc, frame_shorter_than_header_is_short);
	tcase_add_test(tc, bad_magic_is_rejected);
	tcase_add_test(tc, wrong_version_is_rejected);
	tcase_add_test(tc, length_byte_disagreeing_with_size_is_rejected);
	tcase_add_test(tc, unknown_op_or_channel_is_rejected);
	tcase_add_test(tc, op_in_wrong_direction_is_rejected);
	tcase_add_test(tc, unknown_flag_bits_are_rejected);
	tcase_add_test(tc, device_id_must_match_channel);
	tcase_add_test(tc, payload_size_wrong_for_op_is_rejected);
	tcase_add_test(tc, announce_with_inconsistent_name_lengths_is_payload_error);
	tcase_add_test(tc, bad_names_are_rejected);
	tcase_add_test(tc, announce_caps_beyond_the_board_are_rejected);
	tcase_add_test(tc, pwm_beyond_full_drive_is_rejected);
	tcase_add_test(tc, digital_output_bit_7_is_rejected);
	tcase_add_test(tc, analog_4096_is_rejected);
	tcase_add_test(tc, watchdog_outside_1_to_60000_ms_is_rejected);
	tcase_add_test(tc, sleep_outside_1_to_3600_s_is_rejected);
	tcase_add_test(tc, error_code_outside_1_to_3_is_rejected_by_decode);
	tcase_add_test(tc, encode_into_small_buffer_is_space_and_writes_nothing_past_cap);
	tcase_add_test(tc, every_prefix_of_an_announce_is_rejected);
	suite_add_tcase(s, tc);

	/* The encoder refuses what the decoder would reject. */
	tc = tcase_create("encode_contract");
	tcase_add_test(tc, encode_refuses_error_code_outside_1_to_3);
	tcase_add_test(tc, encode_refuses_caps_beyond_the_board);
	suite_add_tcase(s, tc);

	return s;
}
