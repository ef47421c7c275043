/* Authenticated frames (core/proto/auth.c, docs/PROTOCOL.md "Authenticated
 * frames"): SipHash-2-4 as the board firmware computes it against
 * libsodium's, the host's reference (every length from 0 to 200 bytes,
 * random keys, both output widths); sealed frames that open, and that do
 * not once any bit, the key, the nonce or the record changes. */
#include <check.h>
#include <sodium.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../core/proto/siphash.h"
#include "check_main.h"
#include "frames.h"

/* Ours (64 or 128 bits: width bytes) against libsodium's, for every
 * length from 0 to 200 bytes, random keys and messages, 20 rounds. */
static void against_libsodium(size_t width)
{
	uint8_t key[VMAC_SIPHASH_KEY_LEN], msg[200], ours[16], theirs[16];
	size_t len;
	int round;
	ck_assert_int_ge(sodium_init(), 0);
	for (round = 0; round < 20; round++)
		for (len = 0; len <= sizeof(msg); len++) {
			randombytes_buf(key, sizeof(key));
			randombytes_buf(msg, len);
			if (width == 8) {
				vmac_siphash24(key, msg, len, ours);
				crypto_shorthash_siphash24(theirs, msg, len, key);
			} else {
				vmac_siphash24_128(key, msg, len, ours);
				crypto_shorthash_siphashx24(theirs, msg, len, key);
			}
			ck_assert_msg(memcmp(ours, theirs, width) == 0,
			              "SipHash-2-4 (%zu bytes out) of %zu bytes differs "
			              "from libsodium's",
			              width, len);
		}
}

START_TEST(the_64_bit_hash_is_libsodiums)
{
	against_libsodium(crypto_shorthash_siphash24_BYTES);
}
END_TEST

START_TEST(the_128_bit_hash_is_libsodiums)
{
	against_libsodium(crypto_shorthash_siphashx24_BYTES);
}
END_TEST

/* The paper's own vector (Appendix A): key 00..0f, message 00..0e, hash
 * 0xa129ca6149be45e5, little-endian on the wire. */
START_TEST(the_papers_test_vector)
{
	static const uint8_t want[8] = {0xe5, 0x45, 0xbe, 0x49, 0x61, 0xca, 0x29, 0xa1};
	uint8_t key[16], msg[15], out[8];
	int i;
	for (i = 0; i < 16; i++)
		key[i] = (uint8_t)i;
	for (i = 0; i < 15; i++)
		msg[i] = (uint8_t)i;
	vmac_siphash24(key, msg, sizeof(msg), out);
	ck_assert_msg(memcmp(out, want, 8) == 0, "the paper's test vector: got %02x%02x%02x%02x%02x%02x%02x%02x",
	              out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7]);
}
END_TEST

static const uint8_t key_a[VMAC_KEY_LEN] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
static const uint8_t key_b[VMAC_KEY_LEN] = {16, 15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1};
static const uint8_t nonce_a[VMAC_NONCE_LEN] = {0xde, 0xad, 0xbe, 0xef, 0, 1, 2, 3};

/* A sealed UPDATE request of device 42, counter 7 under key_a; its length. */
static int sealed_update(uint8_t *buf, size_t cap)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, 42, 9);
	int n;
	m.u.outputs.digital = 0x05;
	m.u.outputs.pwm = -250;
	n = vmac_proto_encode(&m, buf, cap);
	ck_assert_int_gt(n, 0);
	return vmac_proto_seal(buf, (size_t)n, cap, 7, key_a, NULL, 0);
}

START_TEST(a_sealed_frame_decodes_and_opens)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_msg m;
	int n = sealed_update(buf, sizeof(buf));
	ck_assert_int_eq(n, VMAC_HDR_LEN + 3 + VMAC_AUTH_TRAILER_LEN);
	ck_assert_int_eq(vmac_proto_frame_length(buf, (size_t)n), n);
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &m), 0);
	ck_assert_msg(m.flags & VMAC_FLAG_AUTH, "the AUTH flag is not set in the decoded frame");
	ck_assert_uint_eq(m.counter, 7);
	ck_assert_uint_eq(m.u.outputs.digital, 0x05);
	ck_assert_int_eq(m.u.outputs.pwm, -250);
	ck_assert_int_eq(vmac_proto_open(buf, (size_t)n, key_a, NULL, 0), 0);
	ck_assert_int_eq(vmac_proto_open(buf, (size_t)n, key_b, NULL, 0), VMAC_EPROTO_AUTH);
}
END_TEST

START_TEST(no_bit_of_a_sealed_frame_can_change)
{
	uint8_t buf[VMAC_PACKET_MAX], bad[VMAC_PACKET_MAX];
	struct vmac_msg m;
	int n = sealed_update(buf, sizeof(buf)), i, bit;
	for (i = 0; i < n; i++)
		for (bit = 0; bit < 8; bit++) {
			memcpy(bad, buf, (size_t)n);
			bad[i] ^= (uint8_t)(1u << bit);
			ck_assert_msg(vmac_proto_decode(bad, (size_t)n, &m) != 0 ||
			                  vmac_proto_open(bad, (size_t)n, key_a, NULL, 0) == VMAC_EPROTO_AUTH ||
			                  !(m.flags & VMAC_FLAG_AUTH),
			              "byte %d bit %d flipped: the frame still opens", i, bit);
		}
}
END_TEST

START_TEST(an_announce_is_bound_to_the_discovery_it_answers)
{
	uint8_t buf[VMAC_PACKET_MAX], other[VMAC_NONCE_LEN];
	struct vmac_msg m = sample_announce();
	int n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_int_gt(n, 0);
	n = vmac_proto_seal(buf, (size_t)n, sizeof(buf), 0, key_a, nonce_a, VMAC_NONCE_LEN);
	ck_assert_int_gt(n, 0);
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &m), 0);
	ck_assert_str_eq(m.u.announce.board, "bench-1");
	ck_assert_int_eq(vmac_proto_open(buf, (size_t)n, key_a, nonce_a, VMAC_NONCE_LEN), 0);
	memcpy(other, nonce_a, sizeof(other));
	other[7] ^= 1;
	ck_assert_msg(vmac_proto_open(buf, (size_t)n, key_a, other, VMAC_NONCE_LEN) == VMAC_EPROTO_AUTH,
	              "an ANNOUNCE opened against another discovery's nonce (a replay)");
}
END_TEST

START_TEST(sealing_needs_room_and_opening_a_seal)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_IDLE, 42, 1);
	int n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_int_eq(vmac_proto_open(buf, (size_t)n, key_a, NULL, 0), VMAC_EPROTO_OP);
	ck_assert_int_eq(vmac_proto_seal(buf, (size_t)n, (size_t)n + VMAC_AUTH_TRAILER_LEN - 1, 1, key_a, NULL, 0),
	                 VMAC_EPROTO_SPACE);
	/* A trailer the len byte does not account for: not a frame. */
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n + 1, &m), VMAC_EPROTO_LENGTH);
}
END_TEST

START_TEST(session_keys_differ_by_nonce_device_and_direction)
{
	uint8_t b1[VMAC_KEY_LEN], h1[VMAC_KEY_LEN], b2[VMAC_KEY_LEN], h2[VMAC_KEY_LEN], n2[VMAC_NONCE_LEN];
	vmac_proto_session_keys(key_a, nonce_a, 0x00010002u, b1, h1);
	ck_assert_msg(memcmp(b1, h1, VMAC_KEY_LEN) != 0, "both directions got one key");
	vmac_proto_session_keys(key_a, nonce_a, 0x00020002u, b2, h2);
	ck_assert_msg(memcmp(b1, b2, VMAC_KEY_LEN) != 0 && memcmp(h1, h2, VMAC_KEY_LEN) != 0,
	              "another session of the slot got the same keys");
	memcpy(n2, nonce_a, sizeof(n2));
	n2[0] ^= 0x80;
	vmac_proto_session_keys(key_a, n2, 0x00010002u, b2, h2);
	ck_assert_msg(memcmp(b1, b2, VMAC_KEY_LEN) != 0, "another discovery's nonce gave the same key");
	vmac_proto_session_keys(key_b, nonce_a, 0x00010002u, b2, h2);
	ck_assert_msg(memcmp(b1, b2, VMAC_KEY_LEN) != 0, "another board's key gave the same session key");
}
END_TEST

START_TEST(a_discover_carries_the_hosts_nonce)
{
	uint8_t buf[VMAC_FRAME_MAX];
	struct vmac_msg m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 3), d;
	int n;
	m.u.discover.has_nonce = 1;
	memcpy(m.u.discover.nonce, nonce_a, VMAC_NONCE_LEN);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_int_eq(n, VMAC_HDR_LEN + VMAC_NONCE_LEN);
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &d), 0);
	ck_assert_msg(d.u.discover.has_nonce && memcmp(d.u.discover.nonce, nonce_a, VMAC_NONCE_LEN) == 0,
	              "the nonce did not come back");
	n = (int)raw_frame(buf, 1, 0, 3, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, nonce_a, 4);
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &d), VMAC_EPROTO_PAYLOAD);
	n = (int)raw_frame(buf, 1, 0, 3, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, NULL, 0);
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &d), 0);
	ck_assert_msg(!d.u.discover.has_nonce, "a plain DISCOVER decoded with a nonce");
}
END_TEST

START_TEST(each_cyclic_record_opens_for_its_board_alone)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_outputs out = {0x05, -250};
	struct vmac_cyclic_record rec;
	struct vmac_msg m;
	int n = vmac_proto_cyclic_begin_auth(buf, sizeof(buf), 0x0102, 10, 2, 1234);
	ck_assert_int_eq(n, VMAC_HDR_LEN + 2 + 8 + 2 * VMAC_CYCLIC_AUTH_RECORD_LEN);
	vmac_proto_cyclic_put(buf, 0, 3, VMAC_CYCLIC_DUE, &out);
	vmac_proto_cyclic_seal_record(buf, 0, key_a);
	vmac_proto_cyclic_put(buf, 1, 4, 0, &out);
	vmac_proto_cyclic_seal_record(buf, 1, key_b);
	ck_assert_int_eq(vmac_proto_frame_length(buf, (size_t)n), n);
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &m), 0);
	ck_assert_uint_eq(m.counter, 1234);
	ck_assert_int_eq(vmac_proto_cyclic_record(&m, 10, &rec), 0);
	ck_assert_uint_eq(rec.tag, 3);
	ck_assert_int_eq(rec.outputs.pwm, -250);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 10, key_a), 0);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 11, key_b), 0);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 10, key_b), VMAC_EPROTO_AUTH);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 12, key_a), 1);
	/* Another record's bytes, or the frame's counter, change: it no longer opens. */
	vmac_proto_cyclic_slot(buf, 1)[3] ^= 1;
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &m), 0);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 10, key_a), 0);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 11, key_b), VMAC_EPROTO_AUTH);
	buf[VMAC_HDR_LEN + 5] ^= 1;
	ck_assert_int_eq(vmac_proto_decode(buf, (size_t)n, &m), 0);
	ck_assert_int_eq(vmac_proto_cyclic_open_record(&m, 10, key_a), VMAC_EPROTO_AUTH);
	ck_assert_int_eq(vmac_proto_cyclic_begin_auth(buf, sizeof(buf), 1, 0, VMAC_CYCLIC_AUTH_RECORDS_MAX + 1, 1),
	                 VMAC_EPROTO_VALUE);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("auth");
	TCase *tc = tcase_create("siphash");
	TCase *frames = tcase_create("frames");
	tcase_add_test(tc, the_64_bit_hash_is_libsodiums);
	tcase_add_test(tc, the_128_bit_hash_is_libsodiums);
	tcase_add_test(tc, the_papers_test_vector);
	suite_add_tcase(s, tc);
	tcase_add_test(frames, a_sealed_frame_decodes_and_opens);
	tcase_add_test(frames, no_bit_of_a_sealed_frame_can_change);
	tcase_add_test(frames, an_announce_is_bound_to_the_discovery_it_answers);
	tcase_add_test(frames, sealing_needs_room_and_opening_a_seal);
	tcase_add_test(frames, session_keys_differ_by_nonce_device_and_direction);
	tcase_add_test(frames, a_discover_carries_the_hosts_nonce);
	tcase_add_test(frames, each_cyclic_record_opens_for_its_board_alone);
	suite_add_tcase(s, frames);
	return s;
}
