/* SipHash-2-4 (Aumasson and Bernstein, "SipHash: a fast short-input PRF",
 * 2012): the keyed hash of vmac's authenticated frames, written here in
 * portable C99 so that the board firmware computes it without a library;
 * the host's copy is checked against libsodium's crypto_shorthash
 * (tests/unit/test_auth.c). 64-bit output (a frame's MAC) and the
 * paper's 128-bit variant (deriving a session's keys). */
#ifndef VMAC_SIPHASH_H
#define VMAC_SIPHASH_H

#include <stddef.h>
#include <stdint.h>

#define VMAC_SIPHASH_KEY_LEN 16

/* The 64-bit SipHash-2-4 of msg under key, as 8 bytes little-endian (out). */
void vmac_siphash24(const uint8_t key[VMAC_SIPHASH_KEY_LEN], const uint8_t *msg, size_t len, uint8_t out[8]);
/* The 128-bit variant, as 16 bytes (libsodium's crypto_shorthash_siphashx24). */
void vmac_siphash24_128(const uint8_t key[VMAC_SIPHASH_KEY_LEN], const uint8_t *msg, size_t len, uint8_t out[16]);

#endif
