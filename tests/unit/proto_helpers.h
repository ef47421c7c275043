/* The codec's checks shared by the unit tests that decode and encode
 * (core/proto, both protocol versions): error names, decoding from an
 * exact-length heap copy, the expected encode and decode errors, pinned
 * bytes. The frames themselves come from frames.h, included here. All
 * static inline, each test program using what it needs. Used by
 * test_proto.c, test_proto_reject.c, test_proto_v2.c, test_cyclic.c,
 * test_board.c, test_transport.c and, through board_v2_bench.h,
 * test_board_v2.c and test_board_cyclic.c. */
#ifndef VMAC_TESTS_PROTO_HELPERS_H
#define VMAC_TESTS_PROTO_HELPERS_H

#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "frames.h"

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

static inline void expect_bytes(const uint8_t *got, int got_len, const uint8_t *want, int want_len, const char *what)
{
	int i;
	ck_assert_msg(got_len == want_len, "%s: encoded %s, want %d bytes", what, errname(got_len), want_len);
	for (i = 0; i < want_len; i++)
		ck_assert_msg(got[i] == want[i], "%s: byte %d is 0x%02x, want 0x%02x", what, i, got[i], want[i]);
}

#endif
