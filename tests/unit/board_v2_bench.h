/* The bench of the version-2 board tests: a fake HAL, two boards (the one
 * under test and a rival on the same bus), a virtual clock, and the steps and
 * checks of registration and CYCLIC service. Static state, static inline
 * functions: each including program has its own bench. Used by
 * test_board_v2.c and test_board_cyclic.c. */
#ifndef VMAC_TESTS_BOARD_V2_BENCH_H
#define VMAC_TESTS_BOARD_V2_BENCH_H

#include "../../firmware/board.h"
#include "proto_helpers.h"

/* ---- the board: fake HAL ---------------------------------------------- */

#define MAX_WRITES 64

struct fake_io {
	struct vmac_outputs writes[MAX_WRITES]; /* every write_outputs call, in order */
	int n_writes;
	struct vmac_inputs inputs; /* what read_inputs returns, always */
};

static inline void fake_read_inputs(void *ctx, struct vmac_inputs *in)
{
	struct fake_io *io = ctx;
	*in = io->inputs;
	/* Junk in `applied`: the board must overwrite it with what it drives. */
	in->applied.digital = 0x33;
	in->applied.pwm = 333;
}

static inline void fake_write_outputs(void *ctx, const struct vmac_outputs *out)
{
	struct fake_io *io = ctx;
	ck_assert_msg(io->n_writes < MAX_WRITES, "more than %d write_outputs calls", MAX_WRITES);
	io->writes[io->n_writes++] = *out;
}

static const struct vmac_board_io fake_hal = {fake_read_inputs, fake_write_outputs};

/* ---- the bench: a board, its HAL and its last reply ------------------- */

#define BOARD_MAJOR 3
#define BOARD_MINOR 7
#define RIVAL_MINOR 8
#define SESSION_ID 0x00050025u     /* generation 5, slot 37 */
#define SESSION_TAG 5              /* SESSION_ID >> 16 */
#define NEW_SESSION_ID 0x00060025u /* generation 6 of slot 37: the offset's next holder */
#define OTHER_ID 0x00BADBADu
#define SLOT 37 /* the offset the host gives */
#define SPAN 40 /* records in the test's CYCLIC frames: offsets 0..39 */
#define START_MS 1000

struct bench {
	struct vmac_board board;
	struct fake_io io;
	uint8_t reply[VMAC_FRAME_MAX];
	int reply_len;
	struct vmac_msg answer; /* reply_len > 0: the decoded reply */
	const char *name;
};

static struct bench rig;   /* the board under test */
static struct bench rival; /* a second board on the same bus */
static uint64_t now_ms;

static inline void bench_init(struct bench *b, const char *name, uint32_t minor, uint8_t protocol)
{
	struct vmac_board_identity id;
	memset(b, 0, sizeof(*b));
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "test_motor");
	strcpy(id.board, name);
	id.major = BOARD_MAJOR;
	id.minor = minor;
	id.caps.digital_inputs = 8;
	id.caps.digital_outputs = 7;
	id.caps.analog_inputs = 2;
	id.caps.pwm_outputs = 1;
	id.caps.encoders = 1;
	id.protocol = protocol;
	b->name = name;
	b->io.inputs.digital = 0xC3;
	b->io.inputs.analog[0] = 1234;
	b->io.inputs.analog[1] = VMAC_ANALOG_MAX;
	b->io.inputs.encoder = -98765;
	vmac_board_init(&b->board, &id, &fake_hal, &b->io, now_ms);
}

static inline void setup(void)
{
	now_ms = START_MS;
	bench_init(&rig, "bench-1", BOARD_MINOR, 0);
	bench_init(&rival, "bench-2", RIVAL_MINOR, 0);
}

/* Deliver raw bytes at now_ms; decode any reply into b->answer. */
static inline int deliver(struct bench *b, const uint8_t *frame, size_t len)
{
	uint8_t *copy = heap_copy(frame, len);
	int rc;
	memset(b->reply, 0, sizeof(b->reply));
	memset(&b->answer, 0, sizeof(b->answer));
	b->reply_len = vmac_board_receive(&b->board, copy, len, now_ms, b->reply, sizeof(b->reply));
	free(copy);
	ck_assert_msg(b->reply_len >= 0 && b->reply_len <= VMAC_FRAME_MAX, "%s: reply length %d outside 0..%d", b->name,
	              b->reply_len, VMAC_FRAME_MAX);
	if (b->reply_len > 0) {
		rc = vmac_proto_decode(b->reply, (size_t)b->reply_len, &b->answer);
		ck_assert_msg(rc == 0, "%s: its %d-byte reply does not decode: %s", b->name, b->reply_len, errname(rc));
		ck_assert_msg(b->answer.flags & VMAC_FLAG_REPLY, "%s: its reply lacks the reply flag (flags 0x%02x)",
		              b->name, b->answer.flags);
	}
	return b->reply_len;
}

static inline int send_msg(struct bench *b, const struct vmac_msg *m)
{
	uint8_t frame[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(m, frame, sizeof(frame));
	ck_assert_msg(n > 0, "test bug: cannot encode request op 0x%02x: %s", m->op, errname(n));
	return deliver(b, frame, (size_t)n);
}

static inline int send_op(struct bench *b, uint8_t version, uint8_t op, uint32_t device_id, uint16_t seq)
{
	struct vmac_msg m = msg(version, 0, VMAC_CH_DEVICE, op, device_id, seq);
	return send_msg(b, &m);
}

static inline int send_discover(struct bench *b, uint16_t seq)
{
	struct vmac_msg m = msg(1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, seq); /* always sent as version 1 */
	return send_msg(b, &m);
}

static inline int send_register(struct bench *b, uint8_t version, uint32_t device_id, uint16_t watchdog_ms,
                                uint16_t seq)
{
	struct vmac_msg m = msg(version, 0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, device_id, seq);
	m.u.reg.major = b->board.id.major;
	m.u.reg.minor = b->board.id.minor;
	m.u.reg.watchdog_ms = watchdog_ms;
	return send_msg(b, &m);
}

static inline int send_offset(struct bench *b, uint32_t device_id, uint16_t offset, uint16_t seq)
{
	struct vmac_msg m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, device_id, seq);
	m.u.offset = offset;
	return send_msg(b, &m);
}

static inline void expect_state(struct bench *b, enum vmac_board_state want, const char *when)
{
	ck_assert_msg(b->board.state == want, "%s, %s: board is %s, want %s", b->name, when,
	              vmac_board_state_name(b->board.state), vmac_board_state_name(want));
}

static inline void expect_silent(struct bench *b, const char *when)
{
	ck_assert_msg(b->reply_len == 0, "%s, %s: answered with %d bytes (channel 0x%02x op 0x%02x), want silence",
	              b->name, when, b->reply_len, b->answer.channel, b->answer.op);
}

static inline void expect_reply(struct bench *b, uint8_t op, uint16_t seq, uint32_t device_id, const char *when)
{
	ck_assert_msg(b->reply_len > 0, "%s, %s: no reply, want %s", b->name, when,
	              vmac_proto_opname(VMAC_CH_DEVICE, op));
	ck_assert_msg(b->answer.channel == VMAC_CH_DEVICE && b->answer.op == op,
	              "%s, %s: reply is channel 0x%02x %s, want the device channel's %s", b->name, when,
	              b->answer.channel, vmac_proto_opname(b->answer.channel, b->answer.op),
	              vmac_proto_opname(VMAC_CH_DEVICE, op));
	ck_assert_msg(b->reply[2] == 2 && b->answer.version == 2, "%s, %s: reply of version %u, want 2", b->name, when,
	              b->reply[2]);
	ck_assert_msg(b->answer.seq == seq, "%s, %s: reply seq %u, want %u", b->name, when, b->answer.seq, seq);
	ck_assert_msg(b->answer.device_id == device_id, "%s, %s: reply device id 0x%08x, want 0x%08x", b->name, when,
	              (unsigned)b->answer.device_id, (unsigned)device_id);
}

static inline void expect_offset(struct bench *b, uint16_t want, const char *when)
{
	ck_assert_msg(b->board.offset == want, "%s, %s: board holds offset %u, want %u", b->name, when, b->board.offset,
	              want);
}

static inline void expect_driving(struct bench *b, uint8_t digital, int16_t pwm, const char *when)
{
	const struct vmac_outputs *w;
	ck_assert_msg(b->io.n_writes > 0, "%s, %s: write_outputs was never called", b->name, when);
	w = &b->io.writes[b->io.n_writes - 1];
	ck_assert_msg(w->digital == digital && w->pwm == pwm,
	              "%s, %s: last write_outputs was 0x%02x/%d, want 0x%02x/%d", b->name, when, w->digital, w->pwm,
	              digital, pwm);
	ck_assert_msg(b->board.outputs.digital == digital && b->board.outputs.pwm == pwm,
	              "%s, %s: board says it drives 0x%02x/%d, want 0x%02x/%d", b->name, when, b->board.outputs.digital,
	              b->board.outputs.pwm, digital, pwm);
}

static inline void expect_no_write_since(struct bench *b, int n_writes, const char *when)
{
	ck_assert_msg(b->io.n_writes == n_writes,
	              "%s, %s: write_outputs called %d more times (last 0x%02x/%d), want none", b->name, when,
	              b->io.n_writes - n_writes, b->io.writes[b->io.n_writes - 1].digital,
	              b->io.writes[b->io.n_writes - 1].pwm);
}

static inline void expect_never_drove(struct bench *b, uint8_t digital, int16_t pwm, const char *when)
{
	int i;
	for (i = 0; i < b->io.n_writes; i++)
		ck_assert_msg(!(b->io.writes[i].digital == digital && b->io.writes[i].pwm == pwm),
		              "%s, %s: write %d drove 0x%02x/%d, a record that was not its own", b->name, when, i,
		              digital, pwm);
}

/* REGISTER in version 2 as device_id with the given watchdog; the board must
 * ack in version 2. */
static inline void register_v2(struct bench *b, uint32_t device_id, uint16_t watchdog_ms)
{
	send_register(b, 2, device_id, watchdog_ms, 100);
	expect_reply(b, VMAC_OP_REGISTER, 100, device_id, "REGISTER of version 2");
	expect_state(b, VMAC_BOARD_KNOWN, "after REGISTER");
}

/* REGISTER and OFFSET: the board is served by the cyclic frame at offset. */
static inline void join(struct bench *b, uint32_t device_id, uint16_t offset, uint16_t watchdog_ms)
{
	register_v2(b, device_id, watchdog_ms);
	send_offset(b, device_id, offset, 101);
	expect_reply(b, VMAC_OP_OFFSET, 101, device_id, "OFFSET");
	ck_assert_msg(b->answer.u.offset == offset, "%s: OFFSET %u echoed as %u", b->name, offset, b->answer.u.offset);
	expect_offset(b, offset, "after OFFSET");
}

/* A CYCLIC frame of offsets first..first+count-1, every record empty. */
struct cyclic_frame {
	uint8_t bytes[VMAC_CYCLIC_FRAME_MAX];
	int len;
	uint16_t first, seq;
};

static inline void cyclic_new(struct cyclic_frame *f, uint16_t seq, uint16_t first, unsigned count)
{
	f->len = vmac_proto_cyclic_begin(f->bytes, sizeof(f->bytes), seq, first, count);
	ck_assert_msg(f->len > 0, "test bug: cyclic_begin(first %u, count %u) returned %s", first, count,
	              errname(f->len));
	f->first = first;
	f->seq = seq;
}

static inline void cyclic_set(struct cyclic_frame *f, uint16_t offset, uint16_t tag, uint8_t flags, uint8_t digital,
                              int16_t pwm)
{
	put_record(f->bytes, (unsigned)(offset - f->first), tag, flags, digital, pwm);
}

static inline int send_cyclic(struct bench *b, const struct cyclic_frame *f)
{
	return deliver(b, f->bytes, (size_t)f->len);
}

/* Frame [0, SPAN) with one record at SLOT, sent to b. */
static inline int send_record(struct bench *b, uint16_t seq, uint16_t tag, uint8_t flags, uint8_t digital, int16_t pwm)
{
	struct cyclic_frame f;
	cyclic_new(&f, seq, 0, SPAN);
	cyclic_set(&f, SLOT, tag, flags, digital, pwm);
	return send_cyclic(b, &f);
}

static inline void expect_update_reply(struct bench *b, uint16_t seq, uint32_t device_id, uint8_t digital, int16_t pwm,
                                       const char *when)
{
	const struct vmac_inputs *in = &b->answer.u.inputs;
	expect_reply(b, VMAC_OP_UPDATE, seq, device_id, when);
	ck_assert_msg(b->reply_len == VMAC_HDR_LEN + 12, "%s, %s: UPDATE reply of %d bytes, want 25", b->name, when,
	              b->reply_len);
	ck_assert_msg(in->digital == 0xC3 && in->analog[0] == 1234 && in->analog[1] == VMAC_ANALOG_MAX &&
	                  in->encoder == -98765,
	              "%s, %s: reply inputs 0x%02x/%u/%u/%ld, want the HAL's 0xc3/1234/4095/-98765", b->name, when,
	              in->digital, in->analog[0], in->analog[1], (long)in->encoder);
	ck_assert_msg(in->applied.digital == digital && in->applied.pwm == pwm,
	              "%s, %s: reply applied 0x%02x/%d, want the 0x%02x/%d just driven", b->name, when,
	              in->applied.digital, in->applied.pwm, digital, pwm);
}

#endif
