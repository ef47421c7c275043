/* Unit tests for the sealed SYNC (docs/PROTOCOL.md, "Authenticated frames";
 * docs/TIME.md, "Trust"): its bytes in the codec (core/proto: one MAC per
 * offset, pinned against libsodium's SipHash-2-4), and a keyed board
 * (firmware/board.c) feeding its clock only from a sealed SYNC whose MAC at
 * its offset opens under its session's to_board key with a fresh counter.
 * A forged MAC, a replayed counter, another offset's MAC, an unsealed SYNC
 * to a keyed board and a sealed one to an unkeyed board are each ignored
 * and counted, the clock untouched. The host's side is the codec itself. */
#include <check.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../firmware/board.h"
#include "check_main.h"
#include "frames.h"
#include "proto_helpers.h"

#define SESSION 0x00030001u /* generation 3, slot (offset) 1 */
#define HOST_NS 0x123456789ABCull
#define PREV_TX_NS 0x123456779AC5ull /* the previous SYNC left 1 ms less 9 us before */

/* The byte example's to_board key: 00 01 .. 0F. */
static const uint8_t doc_key[VMAC_KEY_LEN] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
static const uint8_t key[VMAC_KEY_LEN] = {9, 8, 7, 6, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6};
static const uint8_t nonce[VMAC_NONCE_LEN] = {1, 2, 3, 4, 5, 6, 7, 8};

/* The byte example of docs/PROTOCOL.md: seq 0x0102, host time
 * 0x123456789ABC ns, the previous SYNC's transmit time 0x123456779AC5 ns,
 * counter 9, offsets 0 (empty) and 1 (a keyed board
 * whose to_board key is doc_key). The MAC is libsodium's
 * crypto_shorthash_siphash24 of the head and offset 00 01, computed apart
 * (PyNaCl), not by this code. */
static const uint8_t doc_frame[] = {
    0x56, 0x4D, 0x02, 0x02, 0x01, 0x02, 0x00, 0x00, 0x00, 0x00, 0xFF, 0x05, 0x02, /* header: AUTH, 2 MACs */
    0x00, 0x00, 0x12, 0x34, 0x56, 0x78, 0x9A, 0xBC,                               /* host_ns */
    0x00, 0x00, 0x12, 0x34, 0x56, 0x77, 0x9A, 0xC5,                               /* prev_tx_ns */
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x09,                               /* counter */
    0x00, 0x00,                                                                   /* first */
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,                               /* offset 0: no board */
    0x0C, 0x35, 0x75, 0xDE, 0xC9, 0xBF, 0x00, 0x11,                               /* offset 1's MAC */
};

/* A sealed SYNC for offsets first..first+count-1 at host_ns with counter,
 * MAC'd for offset `keyed_at` under k (no MAC when keyed_at is outside). */
static int sealed_sync(uint8_t *buf, size_t cap, uint16_t seq, uint64_t host_ns, uint64_t counter, uint16_t first,
                       unsigned count, unsigned keyed_at, const uint8_t *k)
{
	int n = vmac_proto_sync_begin_auth(buf, cap, seq, counter, first, count);
	ck_assert_int_gt(n, 0);
	vmac_proto_sync_stamp(buf, host_ns);
	vmac_proto_sync_set_prev(buf, seq == 0x0102 ? PREV_TX_NS : 0); /* the byte example's: one-step elsewhere */
	if (keyed_at >= first && keyed_at < first + count)
		vmac_proto_sync_seal(buf, keyed_at - first, k);
	return n;
}

START_TEST(sealed_sync_has_pinned_wire_bytes_and_round_trips)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_msg m;
	int n = sealed_sync(buf, sizeof(buf), 0x0102, HOST_NS, 9, 0, 2, 1, doc_key), rc;

	expect_bytes(buf, n, doc_frame, (int)sizeof(doc_frame), "sealed SYNC");
	ck_assert_int_eq(vmac_proto_frame_length(doc_frame, sizeof(doc_frame)), (int)sizeof(doc_frame));
	rc = decode_exact(doc_frame, sizeof(doc_frame), &m);
	ck_assert_msg(rc == 0, "decode of the pinned sealed SYNC returned %s", errname(rc));
	ck_assert_msg(m.op == VMAC_SYS_SYNC && m.flags == VMAC_FLAG_AUTH && m.seq == 0x0102 &&
	                  m.u.sync.host_ns == HOST_NS && m.u.sync.prev_tx_ns == PREV_TX_NS && m.counter == 9 &&
	                  m.u.sync.first == 0 && m.u.sync.count == 2,
	              "decoded op 0x%02x flags 0x%02x seq 0x%04x host %llx counter %u first %u count %u", m.op, m.flags,
	              m.seq, (unsigned long long)m.u.sync.host_ns, (unsigned)m.counter, (unsigned)m.u.sync.first,
	              (unsigned)m.u.sync.count);
	/* decode_exact's copy is gone: open against the frame's own bytes */
	ck_assert_int_eq(vmac_proto_decode(doc_frame, sizeof(doc_frame), &m), 0);
	ck_assert_int_eq(vmac_proto_sync_open(&m, 1, doc_key), 0);
	ck_assert_int_eq(vmac_proto_sync_open(&m, 1, key), VMAC_EPROTO_AUTH);
	ck_assert_int_eq(vmac_proto_sync_open(&m, 0, doc_key), 1); /* zeros: no board there */
	ck_assert_int_eq(vmac_proto_sync_open(&m, 2, doc_key), 1); /* outside the frame */
	/* the largest: 100 MACs, 839 bytes, one Ethernet payload */
	ck_assert_int_eq(vmac_proto_sync_begin_auth(buf, sizeof(buf), 1, 1, 0, VMAC_SYNC_AUTH_MACS_MAX), 839);
	ck_assert_int_eq(vmac_proto_sync_begin_auth(buf, sizeof(buf), 1, 1, 0, VMAC_SYNC_AUTH_MACS_MAX + 1),
	                 VMAC_EPROTO_VALUE);
	ck_assert_int_eq(vmac_proto_sync_begin_auth(buf, sizeof(buf), 1, 1, 0, 0), VMAC_EPROTO_VALUE);
	ck_assert_int_eq(vmac_proto_sync_begin_auth(buf, 50, 1, 1, 0, 2), VMAC_EPROTO_SPACE);
}
END_TEST

START_TEST(sealed_sync_is_refused_at_a_wrong_length_count_or_flag)
{
	uint8_t buf[VMAC_PACKET_MAX];
	int n = sealed_sync(buf, sizeof(buf), 1, HOST_NS, 1, 0, 2, 1, doc_key);

	expect_decode_err(buf, (size_t)n - 1, VMAC_EPROTO_LENGTH, "sealed SYNC a byte short");
	buf[n] = 0;
	expect_decode_err(buf, (size_t)n + 1, VMAC_EPROTO_LENGTH, "sealed SYNC a byte long");
	buf[12] = 0;
	expect_decode_err(buf, VMAC_SYNC_AUTH_HEAD_LEN, VMAC_EPROTO_LENGTH, "sealed SYNC of no MAC");
	buf[12] = VMAC_SYNC_AUTH_MACS_MAX + 1;
	expect_decode_err(buf, VMAC_SYNC_AUTH_HEAD_LEN + 8 * (VMAC_SYNC_AUTH_MACS_MAX + 1), VMAC_EPROTO_LENGTH,
	                  "sealed SYNC of 101 MACs");
	buf[12] = 2;
	buf[3] = VMAC_FLAG_AUTH | VMAC_FLAG_TIMED;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_OP, "sealed SYNC with TIMED");
	buf[3] = VMAC_FLAG_AUTH;
	buf[9] = 1;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "sealed SYNC with a device id");
	buf[9] = 0;
	buf[37] = 0xFF; /* first 0xFFFF: its second MAC past the last offset */
	buf[38] = 0xFF;
	expect_decode_err(buf, (size_t)n, VMAC_EPROTO_VALUE, "sealed SYNC past offset 0xFFFE");
}
END_TEST

/* ---- the board ---------------------------------------------------------- */

static void quiet_read(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
}

static void quiet_write(void *ctx, const struct vmac_outputs *out)
{
	(void)ctx;
	(void)out;
}

static const struct vmac_board_io hal = {quiet_read, quiet_write};

static struct {
	struct vmac_board board;
	uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
	uint32_t host_counter;
} rig;

static void start(int keyed)
{
	struct vmac_board_identity id;
	memset(&rig, 0, sizeof(rig));
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "washer");
	strcpy(id.board, "washer-1");
	id.major = 3;
	id.protocol = 2;
	id.keyed = (uint8_t)keyed;
	memcpy(id.key, key, sizeof(key));
	vmac_board_init(&rig.board, &id, &hal, NULL, 0);
	vmac_proto_session_keys(key, nonce, SESSION, rig.to_board, rig.to_host);
}

static int send_msg(struct vmac_msg *m, int sealed)
{
	uint8_t buf[VMAC_PACKET_MAX], reply[VMAC_BOARD_REPLY_MAX];
	int n = vmac_proto_encode(m, buf, sizeof(buf));
	ck_assert_int_gt(n, 0);
	if (sealed)
		n = vmac_proto_seal(buf, (size_t)n, sizeof(buf), ++rig.host_counter, rig.to_board, NULL, 0);
	return vmac_board_receive(&rig.board, buf, (size_t)n, 10, reply, sizeof(reply));
}

/* A session at offset 1: DISCOVER with the nonce, REGISTER and OFFSET,
 * sealed as the host seals them when keyed. */
static void session(int keyed)
{
	struct vmac_msg m = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	m.u.discover.has_nonce = 1;
	memcpy(m.u.discover.nonce, nonce, sizeof(nonce));
	ck_assert_int_gt(send_msg(&m, 0), 0);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION, 2);
	m.u.reg.major = 3;
	m.u.reg.watchdog_ms = 60000;
	ck_assert_int_gt(send_msg(&m, keyed), 0);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION, 3);
	m.u.offset = 1;
	ck_assert_int_gt(send_msg(&m, keyed), 0);
	ck_assert_int_eq(rig.board.state, VMAC_BOARD_KNOWN);
	ck_assert_int_eq(rig.board.offset, 1);
}

static void give(const uint8_t *frame, int n, uint64_t rx_local_ns)
{
	uint8_t reply[VMAC_BOARD_REPLY_MAX];
	ck_assert_int_eq(vmac_board_receive_at(&rig.board, frame, (size_t)n, 10, rx_local_ns, reply, sizeof(reply)), 0);
}

/* The clock's samples taken, and the board's SYNC counters, as they must be. */
static void expect_counts(uint32_t accepted, uint32_t ignored, uint32_t failed, const char *what)
{
	const struct vmac_board *b = &rig.board;
	ck_assert_msg(b->clock.counters.accepted + b->clock.counters.rejected == accepted &&
	                  b->counters.sync_ignored == ignored && b->counters.auth_failed == failed &&
	                  b->counters.frames_malformed == 0,
	              "%s: clock samples %u, sync_ignored %u, auth_failed %u, malformed %u; want %u, %u, %u, 0", what,
	              (unsigned)(b->clock.counters.accepted + b->clock.counters.rejected),
	              (unsigned)b->counters.sync_ignored, (unsigned)b->counters.auth_failed,
	              (unsigned)b->counters.frames_malformed, (unsigned)accepted, (unsigned)ignored, (unsigned)failed);
}

START_TEST(a_keyed_board_feeds_its_clock_from_its_own_mac_only)
{
	uint8_t f[VMAC_PACKET_MAX];
	struct vmac_msg plain = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_SYNC, 0, 1);
	int n;

	start(1);
	/* before a session: nothing to check a sealed SYNC with */
	n = sealed_sync(f, sizeof(f), 1, HOST_NS, 1, 0, 2, 1, rig.to_board);
	give(f, n, 1000);
	expect_counts(0, 1, 0, "a sealed SYNC before the session");
	session(1);
	n = sealed_sync(f, sizeof(f), 2, HOST_NS, 2, 0, 2, 1, rig.to_board);
	give(f, n, 2000);
	expect_counts(1, 1, 0, "a good sealed SYNC");
	give(f, n, 3000); /* the same again: its counter is not above the last */
	expect_counts(1, 1, 1, "a replayed sealed SYNC");
	n = sealed_sync(f, sizeof(f), 3, HOST_NS + 1000000, 3, 0, 2, 1, rig.to_board);
	f[VMAC_SYNC_AUTH_HEAD_LEN + 8 + 3] ^= 0x40; /* offset 1's MAC, one bit */
	give(f, n, 4000);
	expect_counts(1, 1, 2, "a forged MAC");
	n = sealed_sync(f, sizeof(f), 3, HOST_NS + 1000000, 3, 0, 2, 1, rig.to_board);
	f[VMAC_HDR_LEN + 7] ^= 0x01; /* host_ns moved 1 ns after sealing */
	give(f, n, 4000);
	expect_counts(1, 1, 3, "a moved host time");
	/* our key's MAC at offset 0 (another board's place), none at ours */
	n = sealed_sync(f, sizeof(f), 3, HOST_NS + 1000000, 3, 0, 2, 0, rig.to_board);
	memcpy(f + VMAC_SYNC_AUTH_HEAD_LEN + 8, f + VMAC_SYNC_AUTH_HEAD_LEN, 8);
	give(f, n, 4000);
	expect_counts(1, 1, 4, "another offset's MAC at ours");
	n = sealed_sync(f, sizeof(f), 3, HOST_NS + 1000000, 3, 100, 100, 150, rig.to_board);
	give(f, n, 4000); /* another chunk's frame: not ours to judge */
	expect_counts(1, 2, 4, "another chunk's sealed SYNC");
	plain.u.sync.host_ns = HOST_NS + 2000000;
	n = vmac_proto_encode(&plain, f, sizeof(f));
	give(f, n, 5000);
	expect_counts(1, 3, 4, "an unsealed SYNC");
	n = sealed_sync(f, sizeof(f), 4, HOST_NS + 3000000, 7, 0, 2, 1, rig.to_board);
	give(f, n, 6000);
	expect_counts(2, 3, 4, "the next good sealed SYNC");
	ck_assert_uint_eq(rig.board.rx_sync_counter, 7);
	ck_assert_int_eq(rig.board.counters.frames_ok, 2); /* REGISTER, OFFSET: SYNC is never a frame served */
}
END_TEST

START_TEST(a_new_session_starts_the_sync_counter_again)
{
	uint8_t f[VMAC_PACKET_MAX];
	int n;

	start(1);
	session(1);
	n = sealed_sync(f, sizeof(f), 1, HOST_NS, 50, 0, 2, 1, rig.to_board);
	give(f, n, 1000);
	expect_counts(1, 0, 0, "counter 50");
	vmac_board_safe(&rig.board); /* the host restarted: a new session, its SYNC counter from 1 */
	session(1);
	n = sealed_sync(f, sizeof(f), 1, HOST_NS + 1000000, 1, 0, 2, 1, rig.to_board);
	give(f, n, 2000);
	expect_counts(2, 0, 0, "counter 1 in the new session");
}
END_TEST

START_TEST(an_unkeyed_board_takes_plain_sync_and_ignores_sealed)
{
	uint8_t f[VMAC_PACKET_MAX];
	struct vmac_msg plain = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_SYNC, 0, 1);
	int n;

	start(0);
	session(0);
	n = sealed_sync(f, sizeof(f), 1, HOST_NS, 1, 0, 2, 1, rig.to_board);
	give(f, n, 1000);
	expect_counts(0, 1, 0, "a sealed SYNC to an unkeyed board");
	ck_assert_int_eq(rig.board.clock.state, VMAC_CLOCK_UNSYNCED);
	plain.u.sync.host_ns = HOST_NS;
	n = vmac_proto_encode(&plain, f, sizeof(f));
	give(f, n, 2000);
	expect_counts(1, 1, 0, "a plain SYNC to an unkeyed board");
}
END_TEST

/* The clock locks from sealed SYNC alone, at 1 kHz, as from plain ones. */
START_TEST(a_keyed_board_locks_from_sealed_sync)
{
	uint8_t f[VMAC_PACKET_MAX];
	uint32_t k;

	start(1);
	session(1);
	for (k = 1; k <= 1500; k++) {
		uint64_t host_ns = 5000000000ull + (uint64_t)k * 1000000u;
		int n = sealed_sync(f, sizeof(f), (uint16_t)k, host_ns, k, 0, 2, 1, rig.to_board);
		give(f, n, host_ns + 7000000000ull); /* the board's counter 7 s ahead */
	}
	ck_assert_msg(rig.board.clock.state == VMAC_CLOCK_LOCKED, "after 1.5 s of sealed SYNC the clock is %s",
	              vmac_clock_state_name(rig.board.clock.state));
	/* seq 0x0102 names a transmit time (sealed_sync: the byte example's),
	 * so the board takes the host for one that stamps: it holds that sample
	 * and drops it and the next 15, all unnamed, then goes back to one-step
	 * (VMAC_BOARD_UNNAMED_MAX) */
	expect_counts(1500 - VMAC_BOARD_UNNAMED_MAX, 0, 0, "1500 sealed SYNC");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("sync_auth");
	TCase *tc = tcase_create("core");
	tcase_add_test(tc, sealed_sync_has_pinned_wire_bytes_and_round_trips);
	tcase_add_test(tc, sealed_sync_is_refused_at_a_wrong_length_count_or_flag);
	tcase_add_test(tc, a_keyed_board_feeds_its_clock_from_its_own_mac_only);
	tcase_add_test(tc, a_new_session_starts_the_sync_counter_again);
	tcase_add_test(tc, an_unkeyed_board_takes_plain_sync_and_ignores_sealed);
	tcase_add_test(tc, a_keyed_board_locks_from_sealed_sync);
	suite_add_tcase(s, tc);
	return s;
}
