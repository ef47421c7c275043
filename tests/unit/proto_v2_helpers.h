/* Helpers shared by the unit tests of protocol version 2: a message of any
 * version, a raw frame of any version, the pinned-bytes check and a CYCLIC
 * record put in place. Used by test_proto_v2.c, test_cyclic.c and, through
 * board_v2_bench.h, test_board_v2.c and test_board_cyclic.c. */
#ifndef VMAC_TESTS_PROTO_V2_HELPERS_H
#define VMAC_TESTS_PROTO_V2_HELPERS_H

#include "proto_helpers.h"

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

static inline void expect_bytes(const uint8_t *got, int got_len, const uint8_t *want, int want_len, const char *what)
{
	int i;
	ck_assert_msg(got_len == want_len, "%s: encoded %s, want %d bytes", what, errname(got_len), want_len);
	for (i = 0; i < want_len; i++)
		ck_assert_msg(got[i] == want[i], "%s: byte %d is 0x%02x, want 0x%02x", what, i, got[i], want[i]);
}

/* A frame byte by byte, any version, bypassing the encoder's checks. */
static inline size_t raw_frame(uint8_t *buf, uint8_t version, uint8_t flags, uint16_t seq, uint32_t device_id,
                               uint8_t channel, uint8_t op, const uint8_t *data, size_t data_len)
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

static inline void put_record(uint8_t *frame, unsigned index, uint16_t tag, uint8_t flags, uint8_t digital, int16_t pwm)
{
	struct vmac_outputs out;
	out.digital = digital;
	out.pwm = pwm;
	vmac_proto_cyclic_put(frame, index, tag, flags, &out);
}

#endif
