/* A keyed board (firmware/board.c; docs/PROTOCOL.md "Authenticated
 * frames"): it announces sealed over the discovery's nonce, takes a session
 * only from a REGISTER sealed with that session's keys, seals every reply,
 * and obeys nothing forged, replayed or unsealed: no outputs, no answer, no
 * watchdog fed. The host's side is played here with the codec itself. */
#include <check.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../firmware/board.h"
#include "check_main.h"
#include "frames.h"

#define SESSION 0x00030025u

static const uint8_t key[VMAC_KEY_LEN] = {9, 8, 7, 6, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6};
static const uint8_t wrong_key[VMAC_KEY_LEN] = {1};
static const uint8_t nonce[VMAC_NONCE_LEN] = {1, 2, 3, 4, 5, 6, 7, 8};

static struct vmac_outputs driven;

static void read_inputs(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
	in->digital = 0x81;
}

static void write_outputs(void *ctx, const struct vmac_outputs *out)
{
	(void)ctx;
	driven = *out;
}

static const struct vmac_board_io hal = {read_inputs, write_outputs};

static struct {
	struct vmac_board board;
	uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
	uint64_t host_counter;
	uint8_t reply[VMAC_BOARD_REPLY_MAX];
	int reply_len;
	struct vmac_msg answer;
} rig;

static void start(int keyed)
{
	struct vmac_board_identity id;
	memset(&rig, 0, sizeof(rig));
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "washer");
	strcpy(id.board, "washer-1");
	id.major = 3;
	id.minor = 0;
	id.caps.digital_outputs = 7;
	id.keyed = (uint8_t)keyed;
	memcpy(id.key, key, sizeof(key));
	vmac_board_init(&rig.board, &id, &hal, NULL, 0);
	vmac_proto_session_keys(key, nonce, SESSION, rig.to_board, rig.to_host);
}

static int send_bytes(const uint8_t *frame, size_t len, uint64_t now_ms)
{
	memset(&rig.answer, 0, sizeof(rig.answer));
	rig.reply_len = vmac_board_receive(&rig.board, frame, len, now_ms, rig.reply, sizeof(rig.reply));
	if (rig.reply_len > 0)
		ck_assert_int_eq(vmac_proto_decode(rig.reply, (size_t)rig.reply_len, &rig.answer), 0);
	return rig.reply_len;
}

/* m from the host, sealed under k with counter (0: not sealed). */
static int send_sealed(struct vmac_msg *m, const uint8_t *k, uint64_t counter, uint64_t now_ms)
{
	uint8_t buf[VMAC_PACKET_MAX];
	int n = vmac_proto_encode(m, buf, sizeof(buf));
	ck_assert_int_gt(n, 0);
	if (counter)
		n = vmac_proto_seal(buf, (size_t)n, sizeof(buf), counter, k, NULL, 0);
	return send_bytes(buf, (size_t)n, now_ms);
}

static int discover(int with_nonce)
{
	struct vmac_msg m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 77);
	m.u.discover.has_nonce = (uint8_t)with_nonce;
	memcpy(m.u.discover.nonce, nonce, sizeof(nonce));
	return send_sealed(&m, NULL, 0, 0);
}

/* Discovery and a REGISTER sealed as the host seals it: a session. */
static void session(void)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION, 1);
	ck_assert_int_gt(discover(1), 0);
	m.u.reg.major = 3;
	m.u.reg.watchdog_ms = 500;
	ck_assert_int_gt(send_sealed(&m, rig.to_board, ++rig.host_counter, 10), 0);
	ck_assert_int_eq(rig.board.state, VMAC_BOARD_KNOWN);
	ck_assert_int_eq(vmac_proto_open(rig.reply, (size_t)rig.reply_len, rig.to_host, NULL, 0), 0);
}

static int update(uint8_t digital, const uint8_t *k, uint64_t counter, uint64_t now_ms)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION, 2);
	m.u.outputs.digital = digital;
	return send_sealed(&m, k, counter, now_ms);
}

START_TEST(a_keyed_board_announces_only_to_a_nonce_and_sealed)
{
	start(1);
	ck_assert_msg(discover(0) == 0, "a keyed board answered a DISCOVER it cannot be authenticated to");
	ck_assert_int_gt(discover(1), 0);
	ck_assert_msg(rig.answer.flags & VMAC_FLAG_AUTH, "the ANNOUNCE is not sealed");
	ck_assert_int_eq(vmac_proto_open(rig.reply, (size_t)rig.reply_len, key, nonce, VMAC_NONCE_LEN), 0);
	ck_assert_int_eq(vmac_proto_open(rig.reply, (size_t)rig.reply_len, wrong_key, nonce, VMAC_NONCE_LEN),
	                 VMAC_EPROTO_AUTH);
}
END_TEST

START_TEST(a_session_is_obeyed_and_every_reply_sealed)
{
	start(1);
	session();
	ck_assert_int_gt(update(0x05, rig.to_board, ++rig.host_counter, 20), 0);
	ck_assert_uint_eq(driven.digital, 0x05);
	ck_assert_uint_eq(rig.answer.u.inputs.digital, 0x81);
	ck_assert_uint_eq(rig.answer.counter, 2); /* the ack of REGISTER was 1 */
	ck_assert_int_eq(vmac_proto_open(rig.reply, (size_t)rig.reply_len, rig.to_host, NULL, 0), 0);
}
END_TEST

START_TEST(forged_replayed_and_unsealed_frames_are_not_obeyed)
{
	uint32_t failed;
	start(1);
	session();
	ck_assert_int_gt(update(0x01, rig.to_board, ++rig.host_counter, 20), 0);
	failed = rig.board.counters.auth_failed;
	ck_assert_msg(update(0x7f, wrong_key, ++rig.host_counter, 30) == 0, "answered a frame sealed with another key");
	ck_assert_msg(update(0x7f, rig.to_board, rig.host_counter - 1, 30) == 0, "answered a replayed counter");
	ck_assert_msg(update(0x7f, NULL, 0, 30) == 0, "answered an unsealed UPDATE");
	ck_assert_msg(driven.digital == 0x01, "a forged, replayed or unsealed frame drove outputs 0x%02x",
	              driven.digital);
	ck_assert_uint_eq(rig.board.counters.auth_failed, failed + 3);
	/* None of them fed the watchdog: it fires as if they never came. */
	ck_assert_int_eq(vmac_board_poll(&rig.board, 20 + 500), 1);
	ck_assert_uint_eq(driven.digital, 0);
}
END_TEST

START_TEST(a_register_of_another_discovery_starts_nothing)
{
	uint8_t other[VMAC_NONCE_LEN], to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION, 1);
	start(1);
	ck_assert_int_gt(discover(1), 0);
	memcpy(other, nonce, sizeof(other));
	other[0] ^= 1;
	vmac_proto_session_keys(key, other, SESSION, to_board, to_host);
	m.u.reg.major = 3;
	m.u.reg.watchdog_ms = 500;
	ck_assert_msg(send_sealed(&m, to_board, 1, 10) == 0, "a REGISTER sealed for another discovery was answered");
	ck_assert_int_eq(rig.board.state, VMAC_BOARD_UNKNOWN);
	ck_assert_msg(send_sealed(&m, NULL, 0, 10) == 0, "an unsealed REGISTER was answered");
	ck_assert_int_eq(rig.board.state, VMAC_BOARD_UNKNOWN);
}
END_TEST

START_TEST(a_cyclic_record_is_obeyed_only_sealed_for_this_session_and_fresh)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_outputs out = {0x03, 0};
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION, 3);
	int n;
	start(1);
	session();
	m.version = 2;
	m.u.offset = 0x25;
	ck_assert_int_gt(send_sealed(&m, rig.to_board, ++rig.host_counter, 20), 0);
	n = vmac_proto_cyclic_begin_auth(buf, sizeof(buf), 9, 0x25, 1, 100);
	vmac_proto_cyclic_put(buf, 0, (uint16_t)(SESSION >> 16), VMAC_CYCLIC_DUE, &out);
	vmac_proto_cyclic_seal_record(buf, 0, wrong_key);
	ck_assert_msg(send_bytes(buf, (size_t)n, 30) == 0 && driven.digital == 0, "a record sealed with another key");
	vmac_proto_cyclic_seal_record(buf, 0, rig.to_board);
	ck_assert_int_gt(send_bytes(buf, (size_t)n, 30), 0);
	ck_assert_uint_eq(driven.digital, 0x03);
	ck_assert_int_eq(vmac_proto_open(rig.reply, (size_t)rig.reply_len, rig.to_host, NULL, 0), 0);
	out.digital = 0x7f; /* the same frame counter again: a replay */
	vmac_proto_cyclic_put(buf, 0, (uint16_t)(SESSION >> 16), VMAC_CYCLIC_DUE, &out);
	vmac_proto_cyclic_seal_record(buf, 0, rig.to_board);
	ck_assert_msg(send_bytes(buf, (size_t)n, 40) == 0 && driven.digital == 0x03, "a replayed cyclic frame");
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 10, 0x25, 1);
	vmac_proto_cyclic_put(buf, 0, (uint16_t)(SESSION >> 16), VMAC_CYCLIC_DUE, &out);
	ck_assert_msg(send_bytes(buf, (size_t)n, 40) == 0 && driven.digital == 0x03, "an unsealed cyclic frame");
}
END_TEST

/* A cyclic record for this board (offset 0x25) in a frame sealed with
 * counter: the length of the board's answer. */
static int cyclic_sealed(uint8_t digital, uint64_t counter, uint64_t now_ms)
{
	uint8_t buf[VMAC_PACKET_MAX];
	struct vmac_outputs out = {digital, 0};
	int n = vmac_proto_cyclic_begin_auth(buf, sizeof(buf), 9, 0x25, 1, counter);
	vmac_proto_cyclic_put(buf, 0, (uint16_t)(SESSION >> 16), VMAC_CYCLIC_DUE, &out);
	vmac_proto_cyclic_seal_record(buf, 0, rig.to_board);
	return send_bytes(buf, (size_t)n, now_ms);
}

/* The counters are 64 bits on the wire: past 2^32 (49.7 days of frames at
 * 1 kHz) a session goes on, and a frame of 2^32 before is still a replay,
 * not taken as new by a counter that wrapped. */
START_TEST(counters_go_on_past_two_to_the_32)
{
	const uint64_t wrap = (uint64_t)1 << 32;
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION, 3);
	start(1);
	session();
	m.version = 2;
	m.u.offset = 0x25;
	ck_assert_int_gt(send_sealed(&m, rig.to_board, ++rig.host_counter, 20), 0);
	ck_assert_int_gt(update(0x01, rig.to_board, wrap - 1, 30), 0);
	ck_assert_msg(update(0x02, rig.to_board, wrap + 1, 40) > 0 && driven.digital == 0x02,
	              "an UPDATE with counter 2^32 + 1 after 2^32 - 1 was not obeyed");
	ck_assert_msg(update(0x04, rig.to_board, 5, 50) == 0 && driven.digital == 0x02,
	              "an UPDATE with counter 5 obeyed after 2^32 + 1 (a counter that wrapped)");
	ck_assert_msg(cyclic_sealed(0x03, wrap - 1, 60) > 0 && driven.digital == 0x03,
	              "a sealed CYCLIC with counter 2^32 - 1 was not obeyed");
	ck_assert_msg(cyclic_sealed(0x05, wrap + 2, 70) > 0 && driven.digital == 0x05,
	              "a sealed CYCLIC with counter 2^32 + 2 after 2^32 - 1 was not obeyed");
	ck_assert_msg(cyclic_sealed(0x06, 2, 80) == 0 && driven.digital == 0x05,
	              "a sealed CYCLIC with counter 2 obeyed after 2^32 + 2 (a counter that wrapped)");
}
END_TEST

START_TEST(an_unkeyed_board_ignores_sealed_frames)
{
	start(0);
	ck_assert_int_gt(discover(1), 0);
	ck_assert_msg(!(rig.answer.flags & VMAC_FLAG_AUTH), "an unkeyed board sealed its ANNOUNCE");
	ck_assert_msg(update(0x05, rig.to_board, 1, 10) == 0, "an unkeyed board answered a sealed frame");
}
END_TEST

START_TEST(shutdown_is_acknowledged_sealed_then_the_session_is_gone)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, SESSION, 4);
	start(1);
	session();
	ck_assert_int_gt(update(0x05, rig.to_board, ++rig.host_counter, 20), 0);
	ck_assert_int_gt(send_sealed(&m, rig.to_board, ++rig.host_counter, 30), 0);
	ck_assert_int_eq(vmac_proto_open(rig.reply, (size_t)rig.reply_len, rig.to_host, NULL, 0), 0);
	ck_assert_int_eq(rig.board.state, VMAC_BOARD_UNKNOWN);
	ck_assert_uint_eq(driven.digital, 0);
	ck_assert_msg(update(0x05, rig.to_board, ++rig.host_counter, 40) == 0, "obeyed after SHUTDOWN");
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("board_auth");
	TCase *tc = tcase_create("keyed board");
	tcase_add_test(tc, a_keyed_board_announces_only_to_a_nonce_and_sealed);
	tcase_add_test(tc, a_session_is_obeyed_and_every_reply_sealed);
	tcase_add_test(tc, forged_replayed_and_unsealed_frames_are_not_obeyed);
	tcase_add_test(tc, a_register_of_another_discovery_starts_nothing);
	tcase_add_test(tc, a_cyclic_record_is_obeyed_only_sealed_for_this_session_and_fresh);
	tcase_add_test(tc, counters_go_on_past_two_to_the_32);
	tcase_add_test(tc, an_unkeyed_board_ignores_sealed_frames);
	tcase_add_test(tc, shutdown_is_acknowledged_sealed_then_the_session_is_gone);
	suite_add_tcase(s, tc);
	return s;
}
