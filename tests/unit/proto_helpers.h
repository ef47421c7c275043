/* Helpers shared by the wire codec's unit tests (core/proto), both protocol
 * versions: error names, decoding from an exact-length heap copy, the
 * expected encode and decode errors, and the version-1 message builders.
 * All static inline, each test program using what it needs. Used by
 * test_proto.c, test_proto_reject.c, test_proto_v2.c, test_cyclic.c and,
 * through board_v2_bench.h, test_board_v2.c and test_board_cyclic.c. */
#ifndef VMAC_TESTS_PROTO_HELPERS_H
#define VMAC_TESTS_PROTO_HELPERS_H

#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"

static inline const char *errname(int err)
{
	static char text[96];
	if (err > 0)
		snprintf(text, sizeof(text), "%d (a %d-byte frame)", err, err);
	else
		snprintf(text, sizeof(text), "%d (%s)", err, vmac_proto_strerror(err));
	return text;
}

/* A heap copy of exactly len bytes, so a sanitizer sees any read past the
 * end of the datagram. A decoded CYCLIC points into it: free it after. */
static inline uint8_t *heap_copy(const uint8_t *frame, size_t len)
{
	uint8_t *copy = malloc(len ? len : 1);
	ck_assert_msg(copy != NULL, "malloc(%zu) failed", len);
	if (len)
		memcpy(copy, frame, len);
	return copy;
}

static inline int decode_exact(const uint8_t *frame, size_t len, struct vmac_msg *m)
{
	uint8_t *copy = heap_copy(frame, len);
	int rc = vmac_proto_decode(copy, len, m);
	free(copy);
	return rc;
}

static inline void expect_decode_err(const uint8_t *frame, size_t len, int want, const char *what)
{
	struct vmac_msg m;
	int rc = decode_exact(frame, len, &m);
	char got[96];
	snprintf(got, sizeof(got), "%s", errname(rc));
	ck_assert_msg(rc == want, "decode %s (%zu bytes): got %s, want %s", what, len, got, errname(want));
}

static inline void expect_encode_err(const struct vmac_msg *m, int want, const char *what)
{
	uint8_t buf[VMAC_FRAME_MAX];
	int rc = vmac_proto_encode(m, buf, sizeof(buf));
	char got[96];
	snprintf(got, sizeof(got), "%s", errname(rc));
	ck_assert_msg(rc == want, "encode %s: got %s, want %s", what, got, errname(want));
}

/* ---- version-1 messages ---------------------------------------------- */

static inline struct vmac_msg request(uint8_t channel, uint8_t op, uint32_t device_id, uint16_t seq)
{
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.seq = seq;
	m.device_id = device_id;
	m.channel = channel;
	m.op = op;
	return m;
}

static inline struct vmac_msg reply(uint8_t channel, uint8_t op, uint32_t device_id, uint16_t seq)
{
	struct vmac_msg m = request(channel, op, device_id, seq);
	m.flags = VMAC_FLAG_REPLY;
	return m;
}

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

#endif
