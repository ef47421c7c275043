/* Writes the seed corpus for fuzz_proto.c: one file per message kind, plus
 * session inputs (fuzz_session.h) that register, drive and lose the watchdog.
 * Run once after a wire-format change:
 *   cc -std=c99 tests/fuzz/make_corpus.c core/proto/proto.c core/proto/auth.c core/proto/siphash.c \
 *     -o /tmp/make_corpus
 *   /tmp/make_corpus tests/fuzz/corpus-proto
 * Fuzz (new finds go to the first directory, not the committed seeds):
 *   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz_proto.c \
 *     core/proto/proto.c core/proto/auth.c core/proto/siphash.c firmware/board.c firmware/clock.c \
 *     firmware/timed.c -o /tmp/fuzz_proto
 *   mkdir -p /tmp/fuzz_work && /tmp/fuzz_proto -max_total_time=30 /tmp/fuzz_work tests/fuzz/corpus-proto */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../core/proto/proto.h"
#include "../unit/frames.h"
#include "fuzz_session.h"

#define SESSION_ID 0x00000101u
#define SESSION_V2 0x00030005u /* generation 3, offset 5 */

static const char *out_dir;

static void write_file(const char *name, const uint8_t *bytes, size_t len)
{
	char path[512];
	FILE *f;
	snprintf(path, sizeof(path), "%s/%s", out_dir, name);
	f = fopen(path, "wb");
	if (!f || fwrite(bytes, 1, len, f) != len || fclose(f) != 0) {
		perror(path);
		exit(1);
	}
}

static int encode(const struct vmac_msg *m, uint8_t *buf)
{
	int n = vmac_proto_encode(m, buf, VMAC_FRAME_MAX);
	if (n <= 0) {
		fprintf(stderr, "cannot encode op 0x%02x: %s\n", m->op, vmac_proto_strerror(n));
		exit(1);
	}
	return n;
}

static void seed(const char *name, const struct vmac_msg *m)
{
	uint8_t buf[VMAC_FRAME_MAX];
	write_file(name, buf, (size_t)encode(m, buf));
}

/* Session builder: appends [step][len][frame]. */
struct session {
	uint8_t bytes[1024];
	size_t len;
};

static void append(struct session *s, uint8_t step, const struct vmac_msg *m)
{
	uint8_t buf[VMAC_FRAME_MAX];
	int n = encode(m, buf);
	if (s->len + 2 + (size_t)n > sizeof(s->bytes))
		exit(1);
	s->bytes[s->len++] = step;
	s->bytes[s->len++] = (uint8_t)n;
	memcpy(s->bytes + s->len, buf, (size_t)n);
	s->len += (size_t)n;
}

int main(int argc, char **argv)
{
	struct vmac_msg m, reg, update, idle;
	struct session s;

	if (argc != 2) {
		fprintf(stderr, "usage: %s OUT_DIR\n", argv[0]);
		return 2;
	}
	out_dir = argv[1];

	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	seed("discover", &m);

	m = reply(VMAC_CH_SYSTEM, VMAC_SYS_ANNOUNCE, 0, 1);
	strcpy(m.u.announce.driver, "fuzz_motor");
	strcpy(m.u.announce.board, "fuzz-board");
	m.u.announce.major = FUZZ_BOARD_MAJOR;
	m.u.announce.minor = FUZZ_BOARD_MINOR;
	m.u.announce.firmware_major = 1;
	m.u.announce.caps.digital_inputs = VMAC_DIGITAL_INPUTS;
	m.u.announce.caps.digital_outputs = VMAC_DIGITAL_OUTPUTS;
	m.u.announce.caps.analog_inputs = VMAC_ANALOG_INPUTS;
	m.u.announce.caps.pwm_outputs = 1;
	m.u.announce.caps.encoders = 1;
	seed("announce", &m);

	reg = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION_ID, 2);
	reg.u.reg.major = FUZZ_BOARD_MAJOR;
	reg.u.reg.minor = FUZZ_BOARD_MINOR;
	reg.u.reg.watchdog_ms = 200;
	seed("register", &reg);
	m = reply(VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION_ID, 2);
	seed("register_ack", &m);

	update = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION_ID, 3);
	update.u.outputs.digital = 0x55;
	update.u.outputs.pwm = -500;
	seed("update", &update);
	m = reply(VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION_ID, 3);
	m.u.inputs.digital = 0xA5;
	m.u.inputs.analog[1] = VMAC_ANALOG_MAX;
	m.u.inputs.encoder = -1;
	m.u.inputs.applied = update.u.outputs;
	seed("update_reply", &m);

	idle = request(VMAC_CH_DEVICE, VMAC_OP_IDLE, SESSION_ID, 4);
	seed("idle", &idle);
	m = reply(VMAC_CH_DEVICE, VMAC_OP_ERROR, SESSION_ID, 4);
	m.u.error.code = VMAC_BERR_NOT_REGISTERED;
	m.u.error.op = VMAC_OP_IDLE;
	seed("error_reply", &m);

	m = request(VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, SESSION_ID, 5);
	m.u.shutdown_reason = VMAC_SHUT_DROPPED;
	seed("shutdown", &m);
	m = request(VMAC_CH_DEVICE, VMAC_OP_SLEEP, SESSION_ID, 6);
	m.u.sleep_s = 1;
	seed("sleep", &m);
	m = request(VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, SESSION_ID, 7);
	m.u.watchdog_ms = 60000;
	seed("watchdog", &m);

	/* Register, drive, keep alive, then go quiet past the 200 ms watchdog
	 * and send a stale UPDATE. */
	memset(&s, 0, sizeof(s));
	append(&s, 0, &reg);
	append(&s, 10, &update);
	append(&s, 10, &idle);
	append(&s, 60, &update);
	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 8);
	append(&s, 1, &m);
	write_file("session_watchdog", s.bytes, s.len);

	/* Version 2: the registration steps and the cyclic frame. */
	reg.version = 2;
	reg.device_id = SESSION_V2;
	seed("register_v2", &reg);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_SIZE, SESSION_V2, 11);
	seed("size", &m);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION_V2, 12);
	m.u.offset = SESSION_V2 & 0xFFFF;
	seed("offset", &m);
	{
		struct vmac_msg offset = m, get = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET_GET, SESSION_V2, 13);
		uint8_t frame[VMAC_PACKET_MAX];
		int n = vmac_proto_cyclic_begin(frame, sizeof(frame), 14, 0, 8);
		struct vmac_outputs out = {0x15, 300};
		seed("offset_get", &get);
		vmac_proto_cyclic_put(frame, SESSION_V2 & 0xFFFF, SESSION_V2 >> 16, VMAC_CYCLIC_DUE, &out);
		vmac_proto_cyclic_put(frame, 2, 7, 0, &out);
		write_file("cyclic", frame, (size_t)n);
		/* Register, take the offset, be served by two cyclic frames, then
		 * go quiet past the watchdog. */
		memset(&s, 0, sizeof(s));
		append(&s, 0, &reg);
		append(&s, 1, &offset);
		s.bytes[s.len++] = 5;
		s.bytes[s.len++] = (uint8_t)n;
		memcpy(s.bytes + s.len, frame, (size_t)n);
		s.len += (size_t)n;
		append(&s, 60, &get);
		write_file("session_cyclic", s.bytes, s.len);
	}

	/* SYNC (docs/TIME.md): one, then a second of them at 5 ms, then quiet;
	 * from the second on each names its predecessor's transmit time, 7 us
	 * after that one's host_ns (the two-step), the 15th none (a lost stamp);
	 * 30 of them, as 40 of the longer frame would not fit a session. */
	m = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_SYNC, 0, 1);
	m.u.sync.host_ns = 5000000000ull;
	seed("sync", &m);
	{
		int k;
		memset(&s, 0, sizeof(s));
		for (k = 0; k < 30; k++) {
			m.seq = (uint16_t)(k + 1);
			m.u.sync.prev_tx_ns = k > 0 && k != 15 ? m.u.sync.host_ns + 7000 : 0;
			m.u.sync.host_ns = 5000000000ull + (uint64_t)k * 5 * FUZZ_STEP_MS * 1000000u;
			append(&s, 5, &m);
		}
		m.u.sync.host_ns += 60000000000ull; /* a minute later: a step */
		append(&s, 255, &m);
		write_file("session_sync", s.bytes, s.len);
	}

	/* The sealed SYNC (docs/PROTOCOL.md, "The sealed SYNC"): MACs for
	 * offsets 0..7, one at the v2 session's offset under a key the fuzzer
	 * is not told. */
	{
		static const uint8_t key[VMAC_KEY_LEN] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
		uint8_t frame[VMAC_PACKET_MAX];
		int n = vmac_proto_sync_begin_auth(frame, sizeof(frame), 2, 1, 0, 8);
		vmac_proto_sync_stamp(frame, 5000000000ull);
		vmac_proto_sync_set_prev(frame, 4999000000ull + 7000);
		vmac_proto_sync_seal(frame, SESSION_V2 & 0xFFFF, key);
		write_file("sync_sealed", frame, (size_t)n);
	}

	/* Time-triggered I/O (docs/PROTOCOL.md, "Time-triggered I/O"): a TIMED
	 * CYCLIC with a DUE record at the v2 session's offset, a TIMED UPDATE
	 * (unicast), the TIMED reply; a session registers, takes its offset,
	 * is served by both while SYNC frames come, then goes quiet with an
	 * output still waiting (the watchdog cancels it). */
	{
		uint8_t frame[VMAC_PACKET_MAX];
		struct vmac_outputs out = {0x15, 300};
		struct vmac_msg offset = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION_V2, 12), timed;
		int n = vmac_proto_cyclic_begin_timed(frame, sizeof(frame), 20, 0, 8, 0, 0, 5001000000ull,
		                                      5001500000ull),
		    k;
		vmac_proto_cyclic_put(frame, SESSION_V2 & 0xFFFF, SESSION_V2 >> 16, VMAC_CYCLIC_DUE, &out);
		write_file("timed_cyclic", frame, (size_t)n);
		timed = msg(2, VMAC_FLAG_TIMED, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION_V2, 21);
		timed.u.outputs = out;
		timed.out_at = 5002000000ull;
		timed.in_at = 5002500000ull;
		seed("timed_update", &timed);
		m = msg(2, VMAC_FLAG_REPLY | VMAC_FLAG_TIMED, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION_V2, 21);
		m.u.inputs.applied = out;
		m.latch.latched_at = 5002500000ull;
		m.latch.clock = 2;
		m.latch.bound_ns = 1500;
		m.latch.offset_ns = -2250000000LL;
		seed("timed_reply", &m);
		offset.u.offset = SESSION_V2 & 0xFFFF;
		memset(&s, 0, sizeof(s));
		append(&s, 0, &reg);
		append(&s, 1, &offset);
		m = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_SYNC, 0, 1);
		for (k = 0; k < 20; k++) {
			m.seq = (uint16_t)(k + 1);
			m.u.sync.host_ns = 5000000000ull + (uint64_t)k * FUZZ_STEP_MS * 1000000u;
			append(&s, 1, &m);
		}
		append(&s, 1, &timed);
		s.bytes[s.len++] = 1;
		s.bytes[s.len++] = (uint8_t)n;
		memcpy(s.bytes + s.len, frame, (size_t)n);
		s.len += (size_t)n;
		timed.seq = 22;
		timed.out_at += 100000000ull;
		append(&s, 1, &timed);
		append(&s, 255, &m);
		write_file("session_timed", s.bytes, s.len);
	}

	/* Register, drive, sleep a second, wake and rediscover. */
	memset(&s, 0, sizeof(s));
	append(&s, 0, &reg);
	append(&s, 5, &update);
	m = request(VMAC_CH_DEVICE, VMAC_OP_SLEEP, SESSION_ID, 9);
	m.u.sleep_s = 1;
	append(&s, 5, &m);
	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 10);
	append(&s, 255, &m);
	append(&s, 0, &m);
	write_file("session_sleep", s.bytes, s.len);
	return 0;
}
