/* Unit tests for the board state machine (firmware/board.c): discovery,
 * registration, updates, the comm-loss watchdog, shutdown and sleep, driven
 * through a fake HAL that records every output write. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../firmware/board.h"
#include "check_main.h"
#include "frames.h"

/* ---- fake HAL --------------------------------------------------------- */

#define MAX_WRITES 64

struct fake_io {
	struct vmac_outputs writes[MAX_WRITES]; /* every write_outputs call, in order */
	int n_writes;
	struct vmac_inputs inputs; /* what read_inputs returns, always */
	int n_reads;
};

static void fake_read_inputs(void *ctx, struct vmac_inputs *in)
{
	struct fake_io *io = ctx;
	io->n_reads++;
	*in = io->inputs;
	/* Junk in `applied`: the board must overwrite it with what it drives. */
	in->applied.digital = 0x33;
	in->applied.pwm = 333;
}

static void fake_write_outputs(void *ctx, const struct vmac_outputs *out)
{
	struct fake_io *io = ctx;
	ck_assert_msg(io->n_writes < MAX_WRITES, "more than %d write_outputs calls", MAX_WRITES);
	io->writes[io->n_writes++] = *out;
}

static const struct vmac_board_io fake_hal = {fake_read_inputs, fake_write_outputs};

/* ---- the rig: one board, its fake HAL, a clock and the last reply ------ */

#define BOARD_MAJOR 3
#define BOARD_MINOR 7
#define SESSION_ID 0x00C0FFEEu
#define OTHER_ID 0x00BADBADu

static struct {
	struct vmac_board board;
	struct fake_io io;
	uint64_t now_ms;
	uint8_t reply[VMAC_BOARD_REPLY_MAX];
	int reply_len;
	struct vmac_msg answer; /* reply_len > 0: the decoded reply */
} rig;

static void setup(void)
{
	struct vmac_board_identity id;
	memset(&rig, 0, sizeof(rig));
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "test_motor");
	strcpy(id.board, "bench-1");
	id.major = BOARD_MAJOR;
	id.minor = BOARD_MINOR;
	id.caps.digital_inputs = 8;
	id.caps.digital_outputs = 7;
	id.caps.analog_inputs = 2;
	id.caps.pwm_outputs = 1;
	id.caps.encoders = 1;
	rig.io.inputs.digital = 0xC3;
	rig.io.inputs.analog[0] = 1234;
	rig.io.inputs.analog[1] = VMAC_ANALOG_MAX;
	rig.io.inputs.encoder = -98765;
	rig.now_ms = 1000;
	vmac_board_init(&rig.board, &id, &fake_hal, &rig.io, rig.now_ms);
}

static const struct vmac_outputs *last_write(void)
{
	ck_assert_msg(rig.io.n_writes > 0, "write_outputs was never called");
	return &rig.io.writes[rig.io.n_writes - 1];
}

static void expect_outputs_off(const char *when)
{
	const struct vmac_outputs *w = last_write();
	ck_assert_msg(w->digital == 0 && w->pwm == 0, "%s: last write_outputs was digital 0x%02x pwm %d, want all off",
	              when, w->digital, w->pwm);
	ck_assert_msg(rig.board.outputs.digital == 0 && rig.board.outputs.pwm == 0,
	              "%s: board says it drives digital 0x%02x pwm %d, want all off", when, rig.board.outputs.digital,
	              rig.board.outputs.pwm);
}

static void expect_no_write_since(int n_writes, const char *when)
{
	ck_assert_msg(rig.io.n_writes == n_writes, "%s: write_outputs called %d more times, want none", when,
	              rig.io.n_writes - n_writes);
}

static void expect_state(enum vmac_board_state want, const char *when)
{
	ck_assert_msg(rig.board.state == want, "%s: board is %s, want %s", when, vmac_board_state_name(rig.board.state),
	              vmac_board_state_name(want));
}

/* Deliver raw bytes at rig.now_ms; decode any reply into rig.answer. */
static int deliver(const uint8_t *frame, size_t len)
{
	int rc;
	memset(rig.reply, 0, sizeof(rig.reply));
	memset(&rig.answer, 0, sizeof(rig.answer));
	rig.reply_len = vmac_board_receive(&rig.board, frame, len, rig.now_ms, rig.reply, sizeof(rig.reply));
	ck_assert_msg(rig.reply_len >= 0 && rig.reply_len <= VMAC_FRAME_MAX, "reply length %d outside 0..%d",
	              rig.reply_len, VMAC_FRAME_MAX);
	if (rig.reply_len > 0) {
		rc = vmac_proto_decode(rig.reply, (size_t)rig.reply_len, &rig.answer);
		ck_assert_msg(rc == 0, "board's %d-byte reply does not decode: %d (%s)", rig.reply_len, rc,
		              vmac_proto_strerror(rc));
		ck_assert_msg(rig.answer.flags & VMAC_FLAG_REPLY, "board's reply lacks the reply flag (flags 0x%02x)",
		              rig.answer.flags);
	}
	return rig.reply_len;
}

static int send_msg(const struct vmac_msg *m)
{
	uint8_t frame[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(m, frame, sizeof(frame));
	ck_assert_msg(n > 0, "test bug: cannot encode request op 0x%02x: %d (%s)", m->op, n, vmac_proto_strerror(n));
	return deliver(frame, (size_t)n);
}

static int send_discover(uint16_t seq)
{
	struct vmac_msg m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, seq);
	return send_msg(&m);
}

static int send_register(uint16_t seq, uint32_t device_id, uint32_t major, uint32_t minor, uint16_t watchdog_ms)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_REGISTER, device_id, seq);
	m.u.reg.major = major;
	m.u.reg.minor = minor;
	m.u.reg.watchdog_ms = watchdog_ms;
	return send_msg(&m);
}

static int send_update(uint16_t seq, uint32_t device_id, uint8_t digital, int16_t pwm)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, device_id, seq);
	m.u.outputs.digital = digital;
	m.u.outputs.pwm = pwm;
	return send_msg(&m);
}

static int send_u16(uint8_t op, uint16_t seq, uint16_t value)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, op, SESSION_ID, seq);
	if (op == VMAC_OP_SLEEP)
		m.u.sleep_s = value;
	else
		m.u.watchdog_ms = value;
	return send_msg(&m);
}

/* Register as SESSION_ID with the given watchdog; the board must ack. */
static void register_board(uint16_t watchdog_ms)
{
	int n = send_register(100, SESSION_ID, BOARD_MAJOR, BOARD_MINOR, watchdog_ms);
	ck_assert_msg(n > 0 && rig.answer.op == VMAC_OP_REGISTER,
	              "REGISTER at %llu ms: reply length %d op 0x%02x, want a REGISTER ack",
	              (unsigned long long)rig.now_ms, n, rig.answer.op);
	expect_state(VMAC_BOARD_KNOWN, "after REGISTER");
}

/* Register and switch outputs on (digital 0x5A, pwm -750). */
static void register_and_drive(uint16_t watchdog_ms)
{
	register_board(watchdog_ms);
	send_update(101, SESSION_ID, 0x5A, -750);
	ck_assert_msg(rig.board.outputs.digital == 0x5A && rig.board.outputs.pwm == -750,
	              "UPDATE 0x5a/-750 left the board driving 0x%02x/%d", rig.board.outputs.digital,
	              rig.board.outputs.pwm);
}

static void expect_error_reply(uint8_t code, uint8_t failed_op, uint16_t seq, const char *when)
{
	ck_assert_msg(rig.reply_len > 0, "%s: no reply, want ERROR code %u", when, code);
	ck_assert_msg(rig.answer.op == VMAC_OP_ERROR, "%s: reply op %s, want ERROR", when,
	              vmac_proto_opname(rig.answer.channel, rig.answer.op));
	ck_assert_msg(rig.answer.u.error.code == code, "%s: ERROR code %u, want %u", when, rig.answer.u.error.code,
	              code);
	ck_assert_msg(rig.answer.u.error.op == failed_op, "%s: ERROR names op 0x%02x, want 0x%02x", when,
	              rig.answer.u.error.op, failed_op);
	ck_assert_msg(rig.answer.seq == seq, "%s: ERROR seq %u, want %u", when, rig.answer.seq, seq);
}

static void expect_announce(uint16_t seq, const char *when)
{
	ck_assert_msg(rig.reply_len > 0, "%s: DISCOVER got no reply, want ANNOUNCE", when);
	ck_assert_msg(rig.answer.channel == VMAC_CH_SYSTEM && rig.answer.op == VMAC_SYS_ANNOUNCE,
	              "%s: DISCOVER answered with channel 0x%02x op 0x%02x, want ANNOUNCE", when, rig.answer.channel,
	              rig.answer.op);
	ck_assert_msg(rig.answer.seq == seq, "%s: ANNOUNCE seq %u, want the DISCOVER's %u", when, rig.answer.seq, seq);
}

/* ---- discovery -------------------------------------------------------- */

START_TEST(starts_unknown_with_outputs_written_off)
{
	expect_state(VMAC_BOARD_UNKNOWN, "after init");
	expect_outputs_off("after init");
	ck_assert_msg(rig.board.device_id == 0, "device id 0x%08x after init, want 0", (unsigned)rig.board.device_id);
}
END_TEST

START_TEST(unknown_board_answers_discover_with_its_identity)
{
	const struct vmac_announce *a = &rig.answer.u.announce;
	send_discover(0x4242);
	expect_announce(0x4242, "fresh board");
	ck_assert_msg(rig.answer.device_id == 0, "ANNOUNCE carries device id 0x%08x, want 0",
	              (unsigned)rig.answer.device_id);
	ck_assert_msg(strcmp(a->driver, "test_motor") == 0, "ANNOUNCE driver \"%s\", want \"test_motor\"", a->driver);
	ck_assert_msg(strcmp(a->board, "bench-1") == 0, "ANNOUNCE board \"%s\", want \"bench-1\"", a->board);
	ck_assert_msg(a->major == BOARD_MAJOR && a->minor == BOARD_MINOR, "ANNOUNCE version %u.%u, want %u.%u",
	              (unsigned)a->major, (unsigned)a->minor, BOARD_MAJOR, BOARD_MINOR);
	ck_assert_msg(a->firmware_major == VMAC_FIRMWARE_MAJOR && a->firmware_minor == VMAC_FIRMWARE_MINOR,
	              "ANNOUNCE firmware %u.%u, want %u.%u", a->firmware_major, a->firmware_minor, VMAC_FIRMWARE_MAJOR,
	              VMAC_FIRMWARE_MINOR);
	ck_assert_msg(a->caps.digital_inputs == 8 && a->caps.digital_outputs == 7 && a->caps.analog_inputs == 2 &&
	                  a->caps.pwm_outputs == 1 && a->caps.encoders == 1,
	              "ANNOUNCE caps %u/%u/%u/%u/%u, want 8/7/2/1/1", a->caps.digital_inputs, a->caps.digital_outputs,
	              a->caps.analog_inputs, a->caps.pwm_outputs, a->caps.encoders);
	expect_state(VMAC_BOARD_UNKNOWN, "after answering DISCOVER");
}
END_TEST

START_TEST(known_board_ignores_discover)
{
	register_board(500);
	ck_assert_msg(send_discover(7) == 0, "registered board answered DISCOVER with %d bytes (op 0x%02x)",
	              rig.reply_len, rig.answer.op);
	expect_state(VMAC_BOARD_KNOWN, "after DISCOVER");
}
END_TEST

/* ---- registration ----------------------------------------------------- */

START_TEST(register_with_wrong_identity_is_refused)
{
	send_register(11, SESSION_ID, BOARD_MAJOR + 1, BOARD_MINOR, 500);
	expect_error_reply(VMAC_BERR_IDENTITY, VMAC_OP_REGISTER, 11, "REGISTER naming major+1");
	expect_state(VMAC_BOARD_UNKNOWN, "after REGISTER naming major+1");

	send_register(12, SESSION_ID, BOARD_MAJOR, BOARD_MINOR + 1, 500);
	expect_error_reply(VMAC_BERR_IDENTITY, VMAC_OP_REGISTER, 12, "REGISTER naming minor+1");
	expect_state(VMAC_BOARD_UNKNOWN, "after REGISTER naming minor+1");
	ck_assert_msg(rig.board.device_id == 0, "refused REGISTER left device id 0x%08x, want 0",
	              (unsigned)rig.board.device_id);
	expect_outputs_off("after refused REGISTER");

	send_discover(13);
	expect_announce(13, "after refused REGISTER");
}
END_TEST

START_TEST(register_makes_board_known_with_outputs_off)
{
	int writes_before;
	send_register(0x0102, SESSION_ID, BOARD_MAJOR, BOARD_MINOR, 250);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_REGISTER && rig.answer.channel == VMAC_CH_DEVICE,
	              "REGISTER answered with length %d channel 0x%02x op 0x%02x, want a REGISTER ack", rig.reply_len,
	              rig.answer.channel, rig.answer.op);
	ck_assert_msg(rig.answer.seq == 0x0102, "REGISTER ack seq %u, want 258", rig.answer.seq);
	ck_assert_msg(rig.answer.device_id == SESSION_ID, "REGISTER ack device id 0x%08x, want 0x%08x",
	              (unsigned)rig.answer.device_id, SESSION_ID);
	expect_state(VMAC_BOARD_KNOWN, "after REGISTER");
	ck_assert_msg(rig.board.device_id == SESSION_ID, "board keeps device id 0x%08x, want 0x%08x",
	              (unsigned)rig.board.device_id, SESSION_ID);
	ck_assert_msg(rig.board.watchdog_ms == 250, "board watchdog %u ms, want the 250 ms REGISTER asked for",
	              rig.board.watchdog_ms);
	expect_outputs_off("after REGISTER");

	/* IDLE reports what the board drives: still nothing. */
	writes_before = rig.io.n_writes;
	send_msg(&(struct vmac_msg){.seq = 1, .device_id = SESSION_ID, .channel = VMAC_CH_DEVICE, .op = VMAC_OP_IDLE});
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_IDLE, "IDLE got length %d op 0x%02x", rig.reply_len,
	              rig.answer.op);
	ck_assert_msg(rig.answer.u.inputs.applied.digital == 0 && rig.answer.u.inputs.applied.pwm == 0,
	              "IDLE after REGISTER reports applied 0x%02x/%d, want 0/0", rig.answer.u.inputs.applied.digital,
	              rig.answer.u.inputs.applied.pwm);
	expect_no_write_since(writes_before, "IDLE");
}
END_TEST

/* ---- updates ---------------------------------------------------------- */

START_TEST(update_drives_outputs_and_replies_inputs)
{
	const struct vmac_inputs *in = &rig.answer.u.inputs;
	const struct vmac_outputs *w;
	register_board(500);
	send_update(0x7777, SESSION_ID, 0x5A, -750);

	w = last_write();
	ck_assert_msg(w->digital == 0x5A && w->pwm == -750, "UPDATE 0x5a/-750 wrote 0x%02x/%d to the pins", w->digital,
	              w->pwm);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_UPDATE, "UPDATE got length %d op 0x%02x",
	              rig.reply_len, rig.answer.op);
	ck_assert_msg(rig.answer.seq == 0x7777 && rig.answer.device_id == SESSION_ID,
	              "UPDATE reply seq 0x%04x id 0x%08x, want 0x7777 id 0x%08x", rig.answer.seq,
	              (unsigned)rig.answer.device_id, SESSION_ID);
	ck_assert_msg(in->digital == 0xC3 && in->analog[0] == 1234 && in->analog[1] == VMAC_ANALOG_MAX &&
	                  in->encoder == -98765,
	              "UPDATE reply inputs 0x%02x/%u/%u/%ld, want the HAL's 0xc3/1234/4095/-98765", in->digital,
	              in->analog[0], in->analog[1], (long)in->encoder);
	ck_assert_msg(in->applied.digital == 0x5A && in->applied.pwm == -750,
	              "UPDATE reply applied 0x%02x/%d, want the 0x5a/-750 just driven", in->applied.digital,
	              in->applied.pwm);
}
END_TEST

START_TEST(idle_keeps_outputs_and_reports_them)
{
	int writes_before;
	register_and_drive(500);
	writes_before = rig.io.n_writes;
	send_msg(&(struct vmac_msg){.seq = 9, .device_id = SESSION_ID, .channel = VMAC_CH_DEVICE, .op = VMAC_OP_IDLE});
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_IDLE && rig.answer.seq == 9,
	              "IDLE got length %d op 0x%02x seq %u", rig.reply_len, rig.answer.op, rig.answer.seq);
	ck_assert_msg(rig.answer.u.inputs.applied.digital == 0x5A && rig.answer.u.inputs.applied.pwm == -750,
	              "IDLE reports applied 0x%02x/%d, want 0x5a/-750", rig.answer.u.inputs.applied.digital,
	              rig.answer.u.inputs.applied.pwm);
	expect_no_write_since(writes_before, "IDLE");
}
END_TEST

START_TEST(request_for_another_session_is_refused_and_does_not_feed_watchdog)
{
	int writes_before;
	register_and_drive(100); /* at 1000 ms */
	writes_before = rig.io.n_writes;

	rig.now_ms = 1060;
	send_update(55, OTHER_ID, 0x01, 1000);
	expect_error_reply(VMAC_BERR_NOT_REGISTERED, VMAC_OP_UPDATE, 55, "UPDATE for another device id");
	expect_no_write_since(writes_before, "UPDATE for another device id");
	expect_state(VMAC_BOARD_KNOWN, "after a request for another session");

	rig.now_ms = 1100; /* 100 ms after the last frame of our session */
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms) == 1,
	              "watchdog did not trip at 1100 ms: the foreign UPDATE at 1060 ms fed it");
}
END_TEST

START_TEST(unknown_board_refuses_device_requests)
{
	send_update(3, SESSION_ID, 0x01, 10);
	expect_error_reply(VMAC_BERR_NOT_REGISTERED, VMAC_OP_UPDATE, 3, "UPDATE to an unknown board");
	expect_outputs_off("UPDATE to an unknown board");
	ck_assert_msg(rig.answer.device_id == SESSION_ID, "ERROR carries device id 0x%08x, want the request's 0x%08x",
	              (unsigned)rig.answer.device_id, SESSION_ID);
}
END_TEST

/* ---- watchdog --------------------------------------------------------- */

START_TEST(watchdog_trips_after_period_without_valid_frame)
{
	int writes_before;
	register_and_drive(200); /* last valid frame at 1000 ms */
	writes_before = rig.io.n_writes;

	rig.now_ms = 1200;
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms) == 1,
	              "poll 200 ms after the last frame returned 0, want 1");
	ck_assert_msg(rig.io.n_writes == writes_before + 1, "watchdog trip made %d output writes, want 1",
	              rig.io.n_writes - writes_before);
	expect_outputs_off("after watchdog trip");
	expect_state(VMAC_BOARD_UNKNOWN, "after watchdog trip");
	ck_assert_msg(rig.board.counters.watchdog_trips == 1, "watchdog_trips %u, want 1",
	              (unsigned)rig.board.counters.watchdog_trips);
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms + 1000) == 0, "second poll after the trip returned 1");
	ck_assert_msg(rig.board.counters.watchdog_trips == 1, "watchdog_trips %u after a second poll, want 1",
	              (unsigned)rig.board.counters.watchdog_trips);

	send_discover(31);
	expect_announce(31, "after watchdog trip");
}
END_TEST

START_TEST(watchdog_does_not_trip_one_ms_early)
{
	register_and_drive(200);
	rig.now_ms = 1150;
	send_msg(&(struct vmac_msg){.seq = 2, .device_id = SESSION_ID, .channel = VMAC_CH_DEVICE, .op = VMAC_OP_IDLE});

	rig.now_ms = 1150 + 199;
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms) == 0, "watchdog tripped 199 ms after the last frame");
	expect_state(VMAC_BOARD_KNOWN, "199 ms after the last frame");
	ck_assert_msg(rig.board.outputs.digital == 0x5A && rig.board.outputs.pwm == -750,
	              "outputs 0x%02x/%d 199 ms after the last frame, want 0x5a/-750", rig.board.outputs.digital,
	              rig.board.outputs.pwm);
	rig.now_ms = 1150 + 200;
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms) == 1,
	              "watchdog did not trip 200 ms after the last frame");
}
END_TEST

START_TEST(outputs_stay_off_after_reregister_until_update)
{
	register_and_drive(200);
	rig.now_ms = 1200;
	vmac_board_poll(&rig.board, rig.now_ms);
	expect_state(VMAC_BOARD_UNKNOWN, "after watchdog trip");

	register_board(200);
	expect_outputs_off("after re-REGISTER");
	send_msg(&(struct vmac_msg){.seq = 4, .device_id = SESSION_ID, .channel = VMAC_CH_DEVICE, .op = VMAC_OP_IDLE});
	ck_assert_msg(rig.answer.u.inputs.applied.digital == 0 && rig.answer.u.inputs.applied.pwm == 0,
	              "IDLE after re-REGISTER reports applied 0x%02x/%d, want 0/0", rig.answer.u.inputs.applied.digital,
	              rig.answer.u.inputs.applied.pwm);

	send_update(5, SESSION_ID, 0x01, 10);
	ck_assert_msg(last_write()->digital == 0x01 && last_write()->pwm == 10,
	              "UPDATE after re-REGISTER wrote 0x%02x/%d, want 0x01/10", last_write()->digital,
	              last_write()->pwm);
}
END_TEST

START_TEST(register_while_known_turns_outputs_off)
{
	register_and_drive(500);
	/* The host restarted and registers again: nothing stays on from before. */
	register_board(500);
	expect_outputs_off("REGISTER while driving");
}
END_TEST

START_TEST(stale_update_after_watchdog_trip_is_refused)
{
	int writes_before, i;
	register_and_drive(100);

	/* No poll in between: receive must enforce the watchdog itself. */
	rig.now_ms = 1100;
	send_update(66, SESSION_ID, 0x7F, 1000);
	expect_error_reply(VMAC_BERR_NOT_REGISTERED, VMAC_OP_UPDATE, 66, "UPDATE arriving as the watchdog expires");
	expect_state(VMAC_BOARD_UNKNOWN, "after stale UPDATE");
	expect_outputs_off("after stale UPDATE");

	/* And with the trip already seen by a poll. */
	writes_before = rig.io.n_writes;
	rig.now_ms = 1150;
	send_update(67, SESSION_ID, 0x7F, 1000);
	expect_error_reply(VMAC_BERR_NOT_REGISTERED, VMAC_OP_UPDATE, 67, "UPDATE after the watchdog tripped");
	expect_no_write_since(writes_before, "stale UPDATE");
	for (i = 0; i < rig.io.n_writes; i++)
		ck_assert_msg(!(rig.io.writes[i].digital == 0x7F && rig.io.writes[i].pwm == 1000),
		              "write %d drove the stale UPDATE's 0x7f/1000", i);
}
END_TEST

START_TEST(watchdog_request_changes_the_period)
{
	register_and_drive(100); /* at 1000 ms */
	rig.now_ms = 1050;
	send_u16(VMAC_OP_WATCHDOG, 21, 1000);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_WATCHDOG && rig.answer.seq == 21 &&
	                  rig.answer.device_id == SESSION_ID,
	              "WATCHDOG got length %d op 0x%02x seq %u id 0x%08x, want an ack", rig.reply_len, rig.answer.op,
	              rig.answer.seq, (unsigned)rig.answer.device_id);
	ck_assert_msg(rig.board.watchdog_ms == 1000, "board watchdog %u ms, want 1000", rig.board.watchdog_ms);

	ck_assert_msg(vmac_board_poll(&rig.board, 1150) == 0, "tripped at 1150 ms on the old 100 ms period");
	ck_assert_msg(vmac_board_poll(&rig.board, 2049) == 0, "tripped at 2049 ms, 999 ms into the 1000 ms period");
	ck_assert_msg(vmac_board_poll(&rig.board, 2050) == 1, "did not trip at 2050 ms, 1000 ms after the last frame");
}
END_TEST

/* ---- shutdown and sleep ----------------------------------------------- */

START_TEST(shutdown_turns_outputs_off_and_forgets_session)
{
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_SHUTDOWN, SESSION_ID, 0x0A0B);
	register_and_drive(500);
	m.u.shutdown_reason = VMAC_SHUT_HOST_STOP;
	send_msg(&m);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_SHUTDOWN,
	              "SHUTDOWN got length %d op 0x%02x, want a SHUTDOWN ack", rig.reply_len, rig.answer.op);
	ck_assert_msg(rig.answer.seq == 0x0A0B && rig.answer.device_id == SESSION_ID,
	              "SHUTDOWN ack seq 0x%04x id 0x%08x, want 0x0a0b id 0x%08x", rig.answer.seq,
	              (unsigned)rig.answer.device_id, SESSION_ID);
	expect_outputs_off("after SHUTDOWN");
	expect_state(VMAC_BOARD_UNKNOWN, "after SHUTDOWN");
	ck_assert_msg(rig.board.device_id == 0, "device id 0x%08x after SHUTDOWN, want 0",
	              (unsigned)rig.board.device_id);

	send_discover(1);
	expect_announce(1, "after SHUTDOWN");
}
END_TEST

START_TEST(sleep_turns_outputs_off_and_silences_discovery)
{
	register_and_drive(500); /* at 1000 ms */
	send_u16(VMAC_OP_SLEEP, 40, 2);
	ck_assert_msg(rig.reply_len > 0 && rig.answer.op == VMAC_OP_SLEEP && rig.answer.seq == 40 &&
	                  rig.answer.device_id == SESSION_ID,
	              "SLEEP got length %d op 0x%02x seq %u id 0x%08x, want an ack", rig.reply_len, rig.answer.op,
	              rig.answer.seq, (unsigned)rig.answer.device_id);
	expect_outputs_off("after SLEEP");
	expect_state(VMAC_BOARD_SLEEPING, "after SLEEP");

	rig.now_ms = 1000 + 600; /* past the 500 ms watchdog: sleep is not a session */
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms) == 0, "watchdog tripped while asleep");
	rig.now_ms = 1000 + 1999;
	ck_assert_msg(send_discover(41) == 0, "answered DISCOVER 1999 ms into a 2 s sleep (op 0x%02x)", rig.answer.op);
	ck_assert_msg(send_register(42, SESSION_ID, BOARD_MAJOR, BOARD_MINOR, 500) == 0,
	              "answered REGISTER 1999 ms into a 2 s sleep (op 0x%02x)", rig.answer.op);
	expect_state(VMAC_BOARD_SLEEPING, "1999 ms into a 2 s sleep");

	rig.now_ms = 1000 + 2000;
	send_discover(43);
	expect_announce(43, "2000 ms after SLEEP 2");
	expect_outputs_off("after waking");
}
END_TEST

/* ---- frames the board must not answer --------------------------------- */

START_TEST(malformed_frames_are_counted_and_not_answered)
{
	uint8_t frame[VMAC_FRAME_MAX];
	struct vmac_msg m = request(VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION_ID, 1);
	int n, writes_before;

	register_and_drive(100);
	writes_before = rig.io.n_writes;
	m.u.outputs.digital = 0x01;
	n = vmac_proto_encode(&m, frame, sizeof(frame));

	rig.now_ms = 1050;
	frame[0] = 'X';
	ck_assert_msg(deliver(frame, (size_t)n) == 0, "bad-magic frame answered with %d bytes", rig.reply_len);
	frame[0] = VMAC_MAGIC0;
	frame[14] = 0x04; /* pwm 0x0400 = 1024 */
	ck_assert_msg(deliver(frame, (size_t)n) == 0, "out-of-range UPDATE answered with %d bytes", rig.reply_len);
	ck_assert_msg(deliver(frame, 6) == 0, "the UPDATE cut to 6 bytes answered with %d bytes", rig.reply_len);
	ck_assert_msg(deliver(frame, 0) == 0, "empty datagram answered with %d bytes", rig.reply_len);

	ck_assert_msg(rig.board.counters.frames_malformed == 4, "frames_malformed %u, want 4",
	              (unsigned)rig.board.counters.frames_malformed);
	expect_no_write_since(writes_before, "malformed frames");
	rig.now_ms = 1100;
	ck_assert_msg(vmac_board_poll(&rig.board, rig.now_ms) == 1, "malformed frames fed the watchdog");
}
END_TEST

START_TEST(reply_flagged_frames_are_ignored)
{
	struct vmac_msg m;
	int writes_before;
	register_and_drive(500);
	writes_before = rig.io.n_writes;

	m = reply(VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION_ID, 0);
	m.u.inputs.applied.digital = 0x7F;
	ck_assert_msg(send_msg(&m) == 0, "board answered an UPDATE reply with %d bytes", rig.reply_len);
	m.op = VMAC_OP_REGISTER;
	ck_assert_msg(send_msg(&m) == 0, "board answered a REGISTER ack with %d bytes", rig.reply_len);
	m.device_id = 0;
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_ANNOUNCE;
	strcpy(m.u.announce.driver, "other");
	strcpy(m.u.announce.board, "other-board");
	ck_assert_msg(send_msg(&m) == 0, "board answered another board's ANNOUNCE with %d bytes", rig.reply_len);

	ck_assert_msg(rig.board.counters.frames_ignored == 3, "frames_ignored %u, want 3",
	              (unsigned)rig.board.counters.frames_ignored);
	ck_assert_msg(rig.board.counters.frames_malformed == 0, "frames_malformed %u, want 0",
	              (unsigned)rig.board.counters.frames_malformed);
	expect_no_write_since(writes_before, "reply-flagged frames");
	expect_state(VMAC_BOARD_KNOWN, "after reply-flagged frames");
}
END_TEST

START_TEST(small_reply_buffer_gets_silence_not_overflow)
{
	uint8_t frame[VMAC_FRAME_MAX], small[VMAC_HDR_LEN + 16];
	struct vmac_msg m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	int n, got;
	size_t i;

	n = vmac_proto_encode(&m, frame, sizeof(frame));
	memset(small, 0xA5, sizeof(small));
	got = vmac_board_receive(&rig.board, frame, (size_t)n, rig.now_ms, small, VMAC_HDR_LEN);
	ck_assert_msg(got == 0, "ANNOUNCE into a %d-byte buffer returned %d, want 0", VMAC_HDR_LEN, got);
	for (i = VMAC_HDR_LEN; i < sizeof(small); i++)
		ck_assert_msg(small[i] == 0xA5, "reply into a %d-byte buffer wrote offset %zu", VMAC_HDR_LEN, i);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("board");
	TCase *tc;

	tc = tcase_create("discovery");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, starts_unknown_with_outputs_written_off);
	tcase_add_test(tc, unknown_board_answers_discover_with_its_identity);
	tcase_add_test(tc, known_board_ignores_discover);
	suite_add_tcase(s, tc);

	tc = tcase_create("session");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, register_with_wrong_identity_is_refused);
	tcase_add_test(tc, register_makes_board_known_with_outputs_off);
	tcase_add_test(tc, update_drives_outputs_and_replies_inputs);
	tcase_add_test(tc, idle_keeps_outputs_and_reports_them);
	tcase_add_test(tc, request_for_another_session_is_refused_and_does_not_feed_watchdog);
	tcase_add_test(tc, unknown_board_refuses_device_requests);
	tcase_add_test(tc, register_while_known_turns_outputs_off);
	suite_add_tcase(s, tc);

	tc = tcase_create("watchdog");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, watchdog_trips_after_period_without_valid_frame);
	tcase_add_test(tc, watchdog_does_not_trip_one_ms_early);
	tcase_add_test(tc, outputs_stay_off_after_reregister_until_update);
	tcase_add_test(tc, stale_update_after_watchdog_trip_is_refused);
	tcase_add_test(tc, watchdog_request_changes_the_period);
	suite_add_tcase(s, tc);

	tc = tcase_create("safe_states");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, shutdown_turns_outputs_off_and_forgets_session);
	tcase_add_test(tc, sleep_turns_outputs_off_and_silences_discovery);
	suite_add_tcase(s, tc);

	tc = tcase_create("robustness");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, malformed_frames_are_counted_and_not_answered);
	tcase_add_test(tc, reply_flagged_frames_are_ignored);
	tcase_add_test(tc, small_reply_buffer_gets_silence_not_overflow);
	suite_add_tcase(s, tc);

	return s;
}
