/* vmac frames for the tests, laid out in one place (docs/PROTOCOL.md,
 * "Frame layout"): messages for the codec to encode (msg, request, reply,
 * the samples) and frames written byte by byte (raw_frame,
 * raw_announce_data, put_record). A raw frame bypasses the encoder's
 * checks, so a test can show the decoder and the board what the encoder
 * would refuse: build the frame right, then corrupt the one byte under
 * test, so the corruption is what the reader sees. C99, no heap and no
 * Check: the unit tests use it through proto_helpers.h, and
 * tests/fuzz/make_corpus.c directly. The Python tests' twin is
 * tests/integration/frames.py. */
#ifndef VMAC_TESTS_FRAMES_H
#define VMAC_TESTS_FRAMES_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "../../core/proto/proto.h"

/* Device 0x00030025 (generation 3, slot 37), as in docs/PROTOCOL.md. */
#define DOC_DEVICE 0x00030025u

/* ---- messages, for the encoder ---------------------------------------- */

/* A message with every payload field 0. version 0 is version 1 to the
 * encoder (proto.h). */
static inline struct vmac_msg msg(uint8_t version, uint8_t flags, uint8_t channel, uint8_t op, uint32_t device_id,
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

/* A host's request and a board's reply, of version 1. */
static inline struct vmac_msg request(uint8_t channel, uint8_t op, uint32_t device_id, uint16_t seq)
{
	return msg(0, 0, channel, op, device_id, seq);
}

static inline struct vmac_msg reply(uint8_t channel, uint8_t op, uint32_t device_id, uint16_t seq)
{
	return msg(0, VMAC_FLAG_REPLY, channel, op, device_id, seq);
}

/* An ANNOUNCE with every capability at its maximum. */
static inline struct vmac_msg sample_announce(void)
{
	struct vmac_msg m = reply(VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, 0, 7);
	strcpy(m.u.announce.driver, "motor_x");
	strcpy(m.u.announce.board, "bench-1");
	m.u.announce.major = 2;
	m.u.announce.minor = 5;
	m.u.announce.firmware_major = 1;
	m.u.announce.firmware_minor = 0;
	m.u.announce.caps.digital_inputs = 8;
	m.u.announce.caps.digital_outputs = 7;
	m.u.announce.caps.analog_inputs = 2;
	m.u.announce.caps.pwm_outputs = 1;
	m.u.announce.caps.encoders = 1;
	return m;
}

/* An UPDATE or IDLE reply (op) with inputs at the edges of their ranges. */
static inline struct vmac_msg sample_inputs_reply(uint8_t op)
{
	struct vmac_msg m = reply(VMAC_CH_DEVICE, op, 0x01020304u, 99);
	m.u.inputs.digital = 0xA5;
	m.u.inputs.analog[0] = 0;
	m.u.inputs.analog[1] = VMAC_ANALOG_MAX;
	m.u.inputs.encoder = -123456789;
	m.u.inputs.applied.digital = 0x7F;
	m.u.inputs.applied.pwm = -VMAC_PWM_MAX;
	return m;
}

/* ---- frames, byte by byte --------------------------------------------- */

/* The 13-byte header and data_len bytes of data into buf (at least
 * VMAC_HDR_LEN + data_len bytes), any version, flags or op: nothing is
 * checked. The len byte is data_len (for a CYCLIC of version 2 the caller
 * sets the record count). Returns the frame's length. */
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

/* ANNOUNCE data with any name bytes (major 2, minor 5, firmware 1.0, every
 * capability at its maximum) into d (at least 19 + driver_len + board_len
 * bytes). Returns its length. */
static inline size_t raw_announce_data(uint8_t *d, const uint8_t *driver, size_t driver_len, const uint8_t *board,
                                       size_t board_len)
{
	size_t n = 0;
	d[n++] = (uint8_t)driver_len;
	memcpy(d + n, driver, driver_len);
	n += driver_len;
	memset(d + n, 0, 8); /* major, minor */
	d[n + 3] = 2;
	d[n + 7] = 5;
	n += 8;
	d[n++] = (uint8_t)board_len;
	memcpy(d + n, board, board_len);
	n += board_len;
	d[n++] = 1; /* firmware major */
	d[n++] = 0; /* firmware minor */
	d[n++] = 8;
	d[n++] = 7;
	d[n++] = 2;
	d[n++] = 1;
	d[n++] = 1;
	return n;
}

/* Record index of a CYCLIC frame begun with vmac_proto_cyclic_begin. */
static inline void put_record(uint8_t *frame, unsigned index, uint16_t tag, uint8_t flags, uint8_t digital, int16_t pwm)
{
	struct vmac_outputs out;
	out.digital = digital;
	out.pwm = pwm;
	vmac_proto_cyclic_put(frame, index, tag, flags, &out);
}

#endif
