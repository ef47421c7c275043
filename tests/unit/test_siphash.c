/* SipHash-2-4 as the board firmware computes it (core/proto/siphash.c)
 * against libsodium's, the host's reference: every length from 0 to 200
 * bytes across word boundaries, random keys, both output widths. */
#include <check.h>
#include <sodium.h>
#include <string.h>

#include "../../core/proto/siphash.h"
#include "check_main.h"

START_TEST(the_64_bit_hash_is_libsodiums)
{
	uint8_t key[VMAC_SIPHASH_KEY_LEN], msg[200], ours[8], theirs[crypto_shorthash_siphash24_BYTES];
	size_t len;
	int round;
	ck_assert_int_ge(sodium_init(), 0);
	for (round = 0; round < 20; round++)
		for (len = 0; len <= sizeof(msg); len++) {
			randombytes_buf(key, sizeof(key));
			randombytes_buf(msg, len);
			vmac_siphash24(key, msg, len, ours);
			crypto_shorthash_siphash24(theirs, msg, len, key);
			ck_assert_msg(memcmp(ours, theirs, 8) == 0, "SipHash-2-4 of %zu bytes differs from libsodium's",
			              len);
		}
}
END_TEST

START_TEST(the_128_bit_hash_is_libsodiums)
{
	uint8_t key[VMAC_SIPHASH_KEY_LEN], msg[200], ours[16], theirs[crypto_shorthash_siphashx24_BYTES];
	size_t len;
	int round;
	ck_assert_int_ge(sodium_init(), 0);
	for (round = 0; round < 20; round++)
		for (len = 0; len <= sizeof(msg); len++) {
			randombytes_buf(key, sizeof(key));
			randombytes_buf(msg, len);
			vmac_siphash24_128(key, msg, len, ours);
			crypto_shorthash_siphashx24(theirs, msg, len, key);
			ck_assert_msg(memcmp(ours, theirs, 16) == 0,
			              "SipHash-2-4-128 of %zu bytes differs from libsodium's", len);
		}
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

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("siphash");
	TCase *tc = tcase_create("siphash");
	tcase_add_test(tc, the_64_bit_hash_is_libsodiums);
	tcase_add_test(tc, the_128_bit_hash_is_libsodiums);
	tcase_add_test(tc, the_papers_test_vector);
	suite_add_tcase(s, tc);
	return s;
}
