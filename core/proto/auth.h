/* Authenticated frames (docs/PROTOCOL.md, "Authenticated frames"): the
 * keyed half of the codec. Each board has a 16-byte key the host also
 * holds; a session's two keys (host to board, board to host) are derived
 * from it and the host's nonce of the discovery the board answered, and
 * every frame of the session carries a counter that never repeats and a
 * SipHash-2-4 MAC (siphash.h) over the frame and the counter. Portable
 * C99, no heap: the board firmware links it. */
#ifndef VMAC_AUTH_H
#define VMAC_AUTH_H

#include <stddef.h>
#include <stdint.h>

#include "proto.h"
#include "siphash.h"

#define VMAC_KEY_LEN VMAC_SIPHASH_KEY_LEN

/* The keys of the session of device_id that began with the host's nonce
 * (the DISCOVER the board announced to): to_board seals the host's frames,
 * to_host the board's. */
void vmac_proto_session_keys(const uint8_t key[VMAC_KEY_LEN], const uint8_t nonce[VMAC_NONCE_LEN], uint32_t device_id,
                             uint8_t to_board[VMAC_KEY_LEN], uint8_t to_host[VMAC_KEY_LEN]);

/* Seal an encoded frame of len bytes in place: set VMAC_FLAG_AUTH, append
 * counter and the MAC under key of the frame, the counter and `extra`
 * (extralen bytes not sent: an ANNOUNCE's is the DISCOVER's nonce). Returns
 * the new length, or VMAC_EPROTO_SPACE when cap has no room. */
int vmac_proto_seal(uint8_t *frame, size_t len, size_t cap, uint64_t counter, const uint8_t key[VMAC_KEY_LEN],
                    const uint8_t *extra, size_t extralen);

/* Check the MAC of a received, decoded frame of len bytes (trailer
 * included) under key with the same `extra`: 0, VMAC_EPROTO_AUTH when it
 * does not verify, VMAC_EPROTO_OP when the frame is not sealed. */
int vmac_proto_open(const uint8_t *frame, size_t len, const uint8_t key[VMAC_KEY_LEN], const uint8_t *extra,
                    size_t extralen);

/* The MAC of record index of an authenticated CYCLIC frame (written after
 * vmac_proto_cyclic_put), under its board's to_board key. */
void vmac_proto_cyclic_seal_record(uint8_t *frame, unsigned index, const uint8_t key[VMAC_KEY_LEN]);

/* Check the MAC of the record at offset of a decoded authenticated CYCLIC
 * message: 0, 1 when the frame holds no record there, VMAC_EPROTO_AUTH. */
int vmac_proto_cyclic_open_record(const struct vmac_msg *m, uint16_t offset, const uint8_t key[VMAC_KEY_LEN]);

/* A sealed SYNC (vmac_proto_sync_begin_auth, stamped): write MAC index,
 * for the board at offset first + index, under its to_board key: the MAC
 * of the frame's head (header, host_ns, counter, first) and that offset. */
void vmac_proto_sync_seal(uint8_t *frame, unsigned index, const uint8_t key[VMAC_KEY_LEN]);

/* Check the MAC for offset of a decoded sealed SYNC under key: 0; 1 when
 * the frame holds no MAC for that offset (outside it, or all zeros: the
 * host has no keyed board there); VMAC_EPROTO_AUTH when it does not
 * verify; VMAC_EPROTO_OP when the SYNC is not sealed. O(1). */
int vmac_proto_sync_open(const struct vmac_msg *m, uint16_t offset, const uint8_t key[VMAC_KEY_LEN]);

/* Equal in constant time (a MAC compared byte by byte would say how much
 * of a guess was right). */
int vmac_proto_equal(const uint8_t *a, const uint8_t *b, size_t n);

#endif
