/* Authenticated frames: see auth.h. */
#include "auth.h"

#include <string.h>

/* What a MAC is computed over, at most: a frame, its counter and the
 * DISCOVER's nonce an ANNOUNCE answers. */
#define MAC_INPUT_MAX (VMAC_FRAME_MAX + VMAC_AUTH_COUNTER_LEN + VMAC_NONCE_LEN)
/* A CYCLIC record's: the frame's header, first offset and counter, the
 * record's offset and its 6 bytes. */
#define RECORD_INPUT_MAX (VMAC_HDR_LEN + 2 + VMAC_AUTH_COUNTER_LEN + VMAC_CYCLIC_TIMING_LEN + 2 + 6)

static const char to_board_label[] = "vmac-to-board";
static const char to_host_label[] = "vmac-to-host";

static void derive(const uint8_t key[VMAC_KEY_LEN], const char *label, const uint8_t nonce[VMAC_NONCE_LEN],
                   uint32_t device_id, uint8_t out[VMAC_KEY_LEN])
{
	uint8_t in[16 + VMAC_NONCE_LEN + 4];
	size_t n = strlen(label);
	memcpy(in, label, n);
	memcpy(in + n, nonce, VMAC_NONCE_LEN);
	n += VMAC_NONCE_LEN;
	in[n++] = (uint8_t)(device_id >> 24);
	in[n++] = (uint8_t)(device_id >> 16);
	in[n++] = (uint8_t)(device_id >> 8);
	in[n++] = (uint8_t)device_id;
	vmac_siphash24_128(key, in, n, out);
}

void vmac_proto_session_keys(const uint8_t key[VMAC_KEY_LEN], const uint8_t nonce[VMAC_NONCE_LEN], uint32_t device_id,
                             uint8_t to_board[VMAC_KEY_LEN], uint8_t to_host[VMAC_KEY_LEN])
{
	derive(key, to_board_label, nonce, device_id, to_board);
	derive(key, to_host_label, nonce, device_id, to_host);
}

int vmac_proto_equal(const uint8_t *a, const uint8_t *b, size_t n)
{
	uint8_t d = 0;
	size_t i;
	for (i = 0; i < n; i++)
		d |= (uint8_t)(a[i] ^ b[i]);
	return d == 0;
}

/* The MAC of body (len bytes: the frame up to and with its counter) and
 * extra. 0, or -1 when they do not fit MAC_INPUT_MAX. */
static int mac_of(const uint8_t *body, size_t len, const uint8_t *extra, size_t extralen,
                  const uint8_t key[VMAC_KEY_LEN], uint8_t mac[VMAC_AUTH_MAC_LEN])
{
	uint8_t in[MAC_INPUT_MAX];
	if (len + extralen > sizeof(in))
		return -1;
	memcpy(in, body, len);
	if (extralen)
		memcpy(in + len, extra, extralen);
	vmac_siphash24(key, in, len + extralen, mac);
	return 0;
}

int vmac_proto_seal(uint8_t *frame, size_t len, size_t cap, uint64_t counter, const uint8_t key[VMAC_KEY_LEN],
                    const uint8_t *extra, size_t extralen)
{
	uint8_t *t = frame + len;
	int i;
	if (len < VMAC_HDR_LEN || len + VMAC_AUTH_TRAILER_LEN > cap)
		return VMAC_EPROTO_SPACE;
	frame[3] |= VMAC_FLAG_AUTH;
	for (i = 0; i < VMAC_AUTH_COUNTER_LEN; i++) /* big-endian, as every field */
		t[i] = (uint8_t)(counter >> (8 * (VMAC_AUTH_COUNTER_LEN - 1 - i)));
	if (mac_of(frame, len + VMAC_AUTH_COUNTER_LEN, extra, extralen, key, t + VMAC_AUTH_COUNTER_LEN) != 0)
		return VMAC_EPROTO_SPACE;
	return (int)(len + VMAC_AUTH_TRAILER_LEN);
}

int vmac_proto_open(const uint8_t *frame, size_t len, const uint8_t key[VMAC_KEY_LEN], const uint8_t *extra,
                    size_t extralen)
{
	uint8_t mac[VMAC_AUTH_MAC_LEN];
	if (len < VMAC_HDR_LEN + VMAC_AUTH_TRAILER_LEN || !(frame[3] & VMAC_FLAG_AUTH))
		return VMAC_EPROTO_OP;
	if (mac_of(frame, len - VMAC_AUTH_MAC_LEN, extra, extralen, key, mac) != 0)
		return VMAC_EPROTO_AUTH;
	return vmac_proto_equal(mac, frame + len - VMAC_AUTH_MAC_LEN, VMAC_AUTH_MAC_LEN) ? 0 : VMAC_EPROTO_AUTH;
}

/* The MAC of record index (its 6 bytes at r) of frame. */
static void record_mac(const uint8_t *frame, unsigned index, const uint8_t *r, const uint8_t key[VMAC_KEY_LEN],
                       uint8_t mac[VMAC_AUTH_MAC_LEN])
{
	uint8_t in[RECORD_INPUT_MAX];
	size_t head = vmac_proto_cyclic_head_len(frame); /* header, first offset, counter, timing */
	unsigned offset = (unsigned)((frame[VMAC_HDR_LEN] << 8) | frame[VMAC_HDR_LEN + 1]) + index;
	memcpy(in, frame, head);
	in[head] = (uint8_t)(offset >> 8);
	in[head + 1] = (uint8_t)offset;
	memcpy(in + head + 2, r, 6);
	vmac_siphash24(key, in, head + 8, mac);
}

void vmac_proto_cyclic_seal_record(uint8_t *frame, unsigned index, const uint8_t key[VMAC_KEY_LEN])
{
	uint8_t *r = vmac_proto_cyclic_slot(frame, index);
	record_mac(frame, index, r, key, r + 6);
}

int vmac_proto_cyclic_open_record(const struct vmac_msg *m, uint16_t offset, const uint8_t key[VMAC_KEY_LEN])
{
	const uint8_t *r;
	uint8_t mac[VMAC_AUTH_MAC_LEN];
	unsigned index;
	if (!(m->flags & VMAC_FLAG_AUTH))
		return VMAC_EPROTO_OP;
	if (offset < m->u.cyclic.first || offset - m->u.cyclic.first >= m->u.cyclic.count)
		return 1;
	index = (unsigned)(offset - m->u.cyclic.first);
	r = m->u.cyclic.records + (size_t)VMAC_CYCLIC_AUTH_RECORD_LEN * index;
	record_mac(m->u.cyclic.frame, index, r, key, mac);
	return vmac_proto_equal(mac, r + 6, VMAC_AUTH_MAC_LEN) ? 0 : VMAC_EPROTO_AUTH;
}

/* The MAC for offset of a sealed SYNC frame: its head and the offset. */
static void sync_mac(const uint8_t *frame, unsigned offset, const uint8_t key[VMAC_KEY_LEN],
                     uint8_t mac[VMAC_AUTH_MAC_LEN])
{
	uint8_t in[VMAC_SYNC_AUTH_HEAD_LEN + 2];
	memcpy(in, frame, VMAC_SYNC_AUTH_HEAD_LEN);
	in[VMAC_SYNC_AUTH_HEAD_LEN] = (uint8_t)(offset >> 8);
	in[VMAC_SYNC_AUTH_HEAD_LEN + 1] = (uint8_t)offset;
	vmac_siphash24(key, in, sizeof(in), mac);
}

void vmac_proto_sync_seal(uint8_t *frame, unsigned index, const uint8_t key[VMAC_KEY_LEN])
{
	unsigned first = (unsigned)((frame[VMAC_SYNC_AUTH_HEAD_LEN - 2] << 8) | frame[VMAC_SYNC_AUTH_HEAD_LEN - 1]);
	sync_mac(frame, first + index, key, frame + VMAC_SYNC_AUTH_HEAD_LEN + (size_t)VMAC_AUTH_MAC_LEN * index);
}

int vmac_proto_sync_open(const struct vmac_msg *m, uint16_t offset, const uint8_t key[VMAC_KEY_LEN])
{
	static const uint8_t none[VMAC_AUTH_MAC_LEN];
	const uint8_t *mac;
	uint8_t want[VMAC_AUTH_MAC_LEN];
	if (!(m->flags & VMAC_FLAG_AUTH) || m->u.sync.frame == NULL)
		return VMAC_EPROTO_OP;
	if (offset < m->u.sync.first || offset - m->u.sync.first >= m->u.sync.count)
		return 1;
	mac = m->u.sync.frame + VMAC_SYNC_AUTH_HEAD_LEN + (size_t)VMAC_AUTH_MAC_LEN * (offset - m->u.sync.first);
	if (vmac_proto_equal(mac, none, VMAC_AUTH_MAC_LEN))
		return 1; /* no keyed board there, as the host sees it: not for us */
	sync_mac(m->u.sync.frame, offset, key, want);
	return vmac_proto_equal(want, mac, VMAC_AUTH_MAC_LEN) ? 0 : VMAC_EPROTO_AUTH;
}
