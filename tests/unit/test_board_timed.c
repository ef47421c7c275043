/* Time-triggered I/O on the board (firmware/timed.c; docs/PROTOCOL.md,
 * "Time-triggered I/O"): a TIMED CYCLIC record, its clock locked, drives
 * at out_at and latches at in_at on the board's counter (through
 * vmac_board_next_deadline and vmac_board_run_due), answers with the TIMED
 * reply right after the latch; an instant already past is acted on at
 * once; a clock not usable acts on arrival and says ARRIVAL; a record that
 * finds an earlier one waiting drives that one at once; SHUTDOWN, SLEEP, a
 * new REGISTER and a watchdog trip cancel what waits; a keyed board takes
 * it sealed only and seals its answer. A TIMED UPDATE (unicast) is
 * served by the same machinery; a board of version 1 counts it malformed.
 * The board's counter here runs 3.5 s ahead of host time, exactly, and the
 * clock is locked by SYNC frames through vmac_board_receive_at, as
 * vmac-board feeds it. */
#include <check.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../firmware/board.h"
#include "../../firmware/report.h"
#include "check_main.h"
#include "frames.h"

#define SESSION 0x00030025u
#define TAG 3
#define OFFSET 0x25
#define SKEW_NS 3500000000ull  /* the board's counter less host time */
#define HOST0_NS 5000000000ull /* host time at the start of each test */
#define MS 1000000ull
#define ACTIONS_MAX 16

static const uint8_t key[VMAC_KEY_LEN] = {9, 8, 7, 6, 5, 4, 3, 2, 1, 0, 1, 2, 3, 4, 5, 6};
static const uint8_t nonce[VMAC_NONCE_LEN] = {1, 2, 3, 4, 5, 6, 7, 8};

static struct {
	struct vmac_board board;
	uint64_t host_ns; /* host time now; the board's counter reads host_ns + skew */
	int64_t skew;     /* SKEW_NS, unless a test says otherwise before start() */
	struct vmac_outputs driven;
	int writes;
	uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
	uint64_t host_counter, sync_counter;
	uint8_t reply[VMAC_BOARD_REPLY_MAX];
	int reply_len;
	struct vmac_msg answer;
	struct vmac_timed_action acts[ACTIONS_MAX];
	int nacts;
} rig;

static void read_inputs(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
	in->digital = 0x81;
	in->encoder = 42;
	in->applied.digital = 0x33; /* junk: the board writes what it drives */
}

static void write_outputs(void *ctx, const struct vmac_outputs *out)
{
	(void)ctx;
	rig.driven = *out;
	rig.writes++;
}

static const struct vmac_board_io hal = {read_inputs, write_outputs};

static void acted(void *ctx, const struct vmac_board *b, const struct vmac_timed_action *a)
{
	(void)ctx;
	(void)b;
	ck_assert_int_lt(rig.nacts, ACTIONS_MAX);
	rig.acts[rig.nacts++] = *a;
}

static uint32_t no_episodes(const void *ctx)
{
	(void)ctx;
	return 0;
}

static size_t no_text(const void *ctx, const char *name, char *line, size_t len)
{
	(void)ctx;
	(void)name;
	if (len)
		line[0] = 0;
	return 0;
}

static const struct vmac_plant_safety none = {no_episodes, no_text, NULL};

static uint64_t now_ms(void)
{
	return rig.host_ns / MS;
}

static uint64_t local(uint64_t host_ns)
{
	return host_ns + (uint64_t)rig.skew;
}

/* The reply (if any) decoded into rig.answer, opened first when sealed. */
static int take_reply(int n)
{
	rig.reply_len = n;
	memset(&rig.answer, 0, sizeof(rig.answer));
	if (n > 0) {
		if (rig.board.id.keyed && rig.reply[10] == VMAC_CH_DEVICE)
			ck_assert_msg(vmac_proto_open(rig.reply, (size_t)n, rig.to_host, NULL, 0) == 0,
			              "a keyed board's reply does not open under its session's key");
		ck_assert_int_eq(vmac_proto_decode(rig.reply, (size_t)n, &rig.answer), 0);
	}
	return n;
}

static int deliver(const uint8_t *frame, size_t len)
{
	return take_reply(
	    vmac_board_receive_at(&rig.board, frame, len, now_ms(), local(rig.host_ns), rig.reply, sizeof(rig.reply)));
}

static int send_msg(struct vmac_msg *m)
{
	uint8_t buf[VMAC_PACKET_MAX];
	int n = vmac_proto_encode(m, buf, sizeof(buf));
	ck_assert_int_gt(n, 0);
	if (rig.board.id.keyed && m->channel == VMAC_CH_DEVICE)
		n = vmac_proto_seal(buf, (size_t)n, sizeof(buf), ++rig.host_counter, rig.to_board, NULL, 0);
	return deliver(buf, (size_t)n);
}

/* n SYNC frames, one a millisecond, exact: the host's time in each. */
static void sync_frames(int n)
{
	uint8_t buf[VMAC_PACKET_MAX];
	int k, len;
	for (k = 0; k < n; k++) {
		if (rig.board.id.keyed) { /* the sealed SYNC, its MAC at our offset: all a keyed board takes */
			len = vmac_proto_sync_begin_auth(buf, sizeof(buf), (uint16_t)k, ++rig.sync_counter, OFFSET, 1);
			ck_assert_int_gt(len, 0);
			vmac_proto_sync_stamp(buf, rig.host_ns);
			vmac_proto_sync_seal(buf, 0, rig.to_board);
		} else {
			struct vmac_msg m = msg(2, 0, VMAC_CH_SYSTEM, VMAC_SYS_SYNC, 0, (uint16_t)k);
			m.u.sync.host_ns = rig.host_ns;
			len = vmac_proto_encode(&m, buf, sizeof(buf));
			ck_assert_int_gt(len, 0);
		}
		ck_assert_int_eq(deliver(buf, (size_t)len), 0);
		rig.host_ns += MS;
	}
}

static void expect_locked(void)
{
	ck_assert_msg(rig.board.clock.state == VMAC_CLOCK_LOCKED, "the clock did not lock in 1.5 s: %s",
	              vmac_clock_state_name(rig.board.clock.state));
}

/* A board (keyed or not), its clock locked (locked 0: never synced) by
 * plain SYNC before its session and trusted again by one in it, or keyed
 * by the sealed SYNC in it, in a session at OFFSET with a watchdog of
 * 500 ms (keyed: 60 s). */
static void start_skewed(int keyed, int locked, int64_t skew)
{
	struct vmac_board_identity id;
	struct vmac_msg m;
	memset(&rig, 0, sizeof(rig));
	rig.skew = skew;
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "motor");
	strcpy(id.board, "motor-1");
	id.major = 3;
	id.caps.digital_outputs = 7;
	id.caps.pwm_outputs = 1;
	id.keyed = (uint8_t)keyed;
	memcpy(id.key, key, sizeof(key));
	rig.host_ns = HOST0_NS;
	vmac_board_init(&rig.board, &id, &hal, NULL, now_ms());
	rig.board.acted = acted;
	vmac_proto_session_keys(key, nonce, SESSION, rig.to_board, rig.to_host);
	if (locked && !keyed) {
		sync_frames(1500);
		expect_locked();
	}
	m = msg(1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	m.u.discover.has_nonce = (uint8_t)keyed;
	memcpy(m.u.discover.nonce, nonce, sizeof(nonce));
	ck_assert_int_gt(send_msg(&m), 0);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION, 2);
	m.u.reg.major = 3;
	m.u.reg.watchdog_ms = keyed ? 60000 : 500; /* keyed: its clock locks in the session, 1.5 s */
	ck_assert_int_gt(send_msg(&m), 0);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION, 3);
	m.u.offset = OFFSET;
	ck_assert_int_gt(send_msg(&m), 0);
	ck_assert_int_eq(rig.board.state, VMAC_BOARD_KNOWN);
	if (locked && keyed) { /* no key to check a SYNC with before its session and offset */
		sync_frames(1500);
		expect_locked();
	} else if (locked) { /* the new session's first SYNC: the same line, trusted again */
		sync_frames(1);
		expect_locked();
	}
	rig.writes = 0;
	rig.nacts = 0;
}

static void start(int keyed, int locked)
{
	start_skewed(keyed, locked, (int64_t)SKEW_NS);
}

/* A TIMED CYCLIC of one record at OFFSET, sealed on a keyed board. */
static int timed(uint16_t seq, uint8_t flags, uint8_t digital, int16_t pwm, uint64_t out_at, uint64_t in_at)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	struct vmac_outputs out;
	int keyed = rig.board.id.keyed, n;
	out.digital = digital;
	out.pwm = pwm;
	n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), seq, OFFSET, 1, keyed, keyed ? ++rig.host_counter : 0,
	                                  out_at, in_at);
	ck_assert_int_gt(n, 0);
	vmac_proto_cyclic_put(buf, 0, TAG, flags, &out);
	if (keyed)
		vmac_proto_cyclic_seal_record(buf, 0, rig.to_board);
	return deliver(buf, (size_t)n);
}

static int run_due_at(uint64_t host_ns)
{
	rig.host_ns = host_ns;
	return take_reply(vmac_board_run_due(&rig.board, local(host_ns), rig.reply, sizeof(rig.reply)));
}

static uint64_t deadline(void)
{
	uint64_t at = 0;
	ck_assert_msg(vmac_board_next_deadline(&rig.board, &at) == 1, "nothing waits");
	return at;
}

static void expect_nothing_waits(const char *when)
{
	uint64_t at;
	ck_assert_msg(vmac_board_next_deadline(&rig.board, &at) == 0, "%s: something still waits (at %llu)", when,
	              (unsigned long long)at);
}

static int64_t diff(uint64_t a, uint64_t b)
{
	return a >= b ? (int64_t)(a - b) : -(int64_t)(b - a);
}

/* rig.answer is a TIMED reply of seq, applied digital, clock byte state
 * (| ARRIVAL). */
static void expect_timed_reply(uint16_t seq, uint8_t applied, uint8_t clock, const char *when)
{
	ck_assert_msg(rig.reply_len > 0, "%s: no reply", when);
	ck_assert_msg(rig.answer.op == VMAC_OP_UPDATE && rig.answer.channel == VMAC_CH_DEVICE &&
	                  rig.answer.device_id == SESSION && rig.answer.seq == seq,
	              "%s: reply op 0x%02x seq %u device 0x%08x, want an UPDATE reply of seq %u", when, rig.answer.op,
	              rig.answer.seq, (unsigned)rig.answer.device_id, seq);
	ck_assert_msg((rig.answer.flags & (VMAC_FLAG_REPLY | VMAC_FLAG_TIMED)) == (VMAC_FLAG_REPLY | VMAC_FLAG_TIMED),
	              "%s: reply flags 0x%02x, want REPLY | TIMED", when, rig.answer.flags);
	ck_assert_msg(rig.reply_len ==
	                  VMAC_HDR_LEN + VMAC_TIMED_REPLY_LEN + (rig.board.id.keyed ? VMAC_AUTH_TRAILER_LEN : 0),
	              "%s: a TIMED reply of %d bytes", when, rig.reply_len);
	ck_assert_msg(rig.answer.u.inputs.digital == 0x81 && rig.answer.u.inputs.encoder == 42,
	              "%s: reply inputs not the HAL's", when);
	ck_assert_msg(rig.answer.u.inputs.applied.digital == applied, "%s: applied 0x%02x, want 0x%02x", when,
	              rig.answer.u.inputs.applied.digital, applied);
	ck_assert_msg(rig.answer.latch.clock == clock, "%s: clock byte 0x%02x, want 0x%02x", when,
	              rig.answer.latch.clock, clock);
}

START_TEST(a_timed_record_drives_at_out_at_and_latches_at_in_at)
{
	uint64_t arrival, out_at, in_at;
	start(0, 1);
	arrival = rig.host_ns;
	out_at = arrival + 2 * MS;
	in_at = arrival + 3 * MS;
	ck_assert_msg(timed(0x0102, VMAC_CYCLIC_DUE, 0x05, -250, out_at, in_at) == 0,
	              "answered on arrival; the latch is 3 ms ahead");
	ck_assert_msg(rig.writes == 0, "drove on arrival; out_at is 2 ms ahead");
	ck_assert_msg(rig.board.last_valid_ms == arrival / MS, "the watchdog was not fed on arrival");
	ck_assert_msg(rig.board.counters.timed == 1 && rig.board.counters.timed_arrival == 0,
	              "counted timed %u, on arrival %u", rig.board.counters.timed, rig.board.counters.timed_arrival);
	ck_assert_msg(llabs(diff(deadline(), local(out_at))) <= 2, "next deadline %lld ns off out_at's local time",
	              (long long)diff(deadline(), local(out_at)));
	ck_assert_int_eq(run_due_at(out_at - 1000), 0);
	ck_assert_msg(rig.writes == 0, "drove 1 us before out_at");
	ck_assert_int_eq(run_due_at(out_at + 2), 0);
	ck_assert_msg(rig.writes == 1 && rig.driven.digital == 0x05 && rig.driven.pwm == -250, "not driven at out_at");
	ck_assert_msg(llabs(diff(deadline(), local(in_at))) <= 2, "the latch is not next, at in_at");
	ck_assert_int_eq(run_due_at(in_at - 1000), 0);
	ck_assert_int_gt(run_due_at(in_at + 2), 0);
	expect_timed_reply(0x0102, 0x05, VMAC_CLOCK_LOCKED, "the latch at in_at");
	ck_assert_msg(llabs(diff(rig.answer.latch.latched_at, in_at)) <= 1000, "latched_at %lld ns off in_at",
	              (long long)diff(rig.answer.latch.latched_at, in_at));
	ck_assert_msg(rig.answer.latch.bound_ns <= 10000, "a locked clock's bound of %u ns", rig.answer.latch.bound_ns);
	ck_assert_msg(llabs(rig.answer.latch.offset_ns - (int64_t)SKEW_NS) <= 1000, "offset %lld ns, want 3.5 s",
	              (long long)rig.answer.latch.offset_ns);
	expect_nothing_waits("after the latch");
	ck_assert_int_eq(rig.nacts, 2);
	ck_assert_msg(rig.acts[0].kind == VMAC_TIMED_OUT && rig.acts[0].how == VMAC_TIMED_AT_INSTANT &&
	                  rig.acts[0].host_ns == out_at && llabs(diff(rig.acts[0].local_ns, local(out_at))) <= 2,
	              "the output's action is not at its instant");
	ck_assert_msg(rig.acts[1].kind == VMAC_TIMED_LATCH && rig.acts[1].how == VMAC_TIMED_AT_INSTANT &&
	                  rig.acts[1].host_ns == in_at && rig.acts[1].outputs.digital == 0x05,
	              "the latch's action is not at its instant");
}
END_TEST

START_TEST(a_latch_before_the_outputs_reports_the_outputs_then_driven)
{
	uint64_t t;
	start(0, 1);
	t = rig.host_ns;
	timed(1, 0, 0x01, 0, t, t); /* 0x01 driven at once, no reply (not DUE) */
	ck_assert_msg(rig.reply_len == 0 && rig.driven.digital == 0x01, "a record without DUE at its instant");
	timed(2, VMAC_CYCLIC_DUE, 0x02, 0, t + 2 * MS, t + 1 * MS);
	ck_assert_int_gt(run_due_at(t + 1 * MS), 0);
	expect_timed_reply(2, 0x01, VMAC_CLOCK_LOCKED, "a latch 1 ms before its record's outputs");
	ck_assert_msg(rig.driven.digital == 0x01, "the outputs came before their instant");
	ck_assert_int_eq(run_due_at(t + 2 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0x02, "the outputs not driven at out_at");
	/* One instant for both: the outputs first, the latch reports them. */
	timed(3, VMAC_CYCLIC_DUE, 0x03, 0, t + 5 * MS, t + 5 * MS);
	ck_assert_int_gt(run_due_at(t + 6 * MS), 0);
	expect_timed_reply(3, 0x03, VMAC_CLOCK_LOCKED, "both at one instant");
}
END_TEST

START_TEST(an_instant_already_past_is_acted_on_at_once)
{
	uint64_t t;
	start(0, 1);
	t = rig.host_ns;
	ck_assert_int_gt(timed(7, VMAC_CYCLIC_DUE, 0x06, 100, t - 1 * MS, t - 1 * MS), 0);
	expect_timed_reply(7, 0x06, VMAC_CLOCK_LOCKED, "instants 1 ms past");
	ck_assert_msg(rig.driven.digital == 0x06 && rig.driven.pwm == 100, "not driven at once");
	ck_assert_msg(llabs(diff(rig.answer.latch.latched_at, t)) <= 1000, "latched_at is not the arrival");
	ck_assert_msg(rig.board.counters.timed == 1 && rig.board.counters.timed_late == 1,
	              "counted timed %u late %u, want 1 and 1", rig.board.counters.timed,
	              rig.board.counters.timed_late);
	ck_assert_msg(rig.acts[0].how == VMAC_TIMED_LATE, "the action is not said late");
	expect_nothing_waits("after a late record");
	/* Instants at host time 0 and 1 (a host's bug), on a counter 4 s
	 * behind host time (host 0 is before its 0): long past, never the
	 * counter's far future. */
	start_skewed(0, 1, -4000000000LL);
	ck_assert_int_gt(timed(8, VMAC_CYCLIC_DUE, 0x01, 0, 0, 1), 0);
	expect_timed_reply(8, 0x01, VMAC_CLOCK_LOCKED, "instants at host time 0 and 1");
	expect_nothing_waits("after instants at host time 0");
	ck_assert_int_eq(rig.board.counters.timed_late, 1);
}
END_TEST

START_TEST(a_clock_not_usable_acts_on_arrival_and_says_so)
{
	struct vmac_report rep;
	char line[VMAC_REPORT_LINE];
	uint64_t t;
	start(0, 0);
	t = rig.host_ns;
	ck_assert_int_gt(timed(9, VMAC_CYCLIC_DUE, 0x05, 0, t + 10 * MS, t + 10 * MS), 0);
	expect_timed_reply(9, 0x05, VMAC_CLOCK_UNSYNCED | VMAC_CLOCK_ARRIVAL, "an unsynced clock");
	ck_assert_msg(rig.answer.latch.latched_at == 0 && rig.answer.latch.bound_ns == 0xFFFFFFFFu &&
	                  rig.answer.latch.offset_ns == 0,
	              "an unsynced clock claims a latch time, bound or offset");
	ck_assert_msg(rig.board.counters.timed_arrival == 1 && rig.board.counters.timed == 0, "not counted on arrival");
	expect_nothing_waits("on arrival");
	/* Locking: still on arrival, but the clock can say when. */
	sync_frames(5);
	ck_assert_int_eq(rig.board.clock.state, VMAC_CLOCK_LOCKING);
	t = rig.host_ns;
	ck_assert_int_gt(timed(10, VMAC_CYCLIC_DUE, 0x04, 0, t + 10 * MS, t + 10 * MS), 0);
	expect_timed_reply(10, 0x04, VMAC_CLOCK_LOCKING | VMAC_CLOCK_ARRIVAL, "a locking clock");
	ck_assert_msg(llabs(diff(rig.answer.latch.latched_at, t)) <= 100000, "latched_at is not the arrival's");
	/* The log says it. */
	rig.board.timed.mode = VMAC_TIMED_MODE_INSTANTS;
	vmac_report_init(&rep, &rig.board, &none, 0);
	rig.board.timed.mode = VMAC_TIMED_MODE_ARRIVAL;
	ck_assert_int_eq(vmac_report_next(&rep, &rig.board, &none, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "motor-1: acting on arrival (clock locking)");
	ck_assert_int_eq(vmac_report_next(&rep, &rig.board, &none, line, sizeof(line)), 0);
}
END_TEST

/* A new REGISTER (a host restarted, or another one): the clock, locked on
 * the old session's line, is not used until the new session's first SYNC
 * says it is the same line (docs/TIME.md, "A new session"). */
START_TEST(a_new_session_acts_on_arrival_until_its_first_sync)
{
	struct vmac_msg m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION, 4);
	uint64_t t;
	start(0, 1);
	m.u.reg.major = 3;
	m.u.reg.watchdog_ms = 500;
	ck_assert_int_gt(send_msg(&m), 0);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION, 5);
	m.u.offset = OFFSET;
	ck_assert_int_gt(send_msg(&m), 0);
	t = rig.host_ns;
	ck_assert_int_gt(timed(11, VMAC_CYCLIC_DUE, 0x03, 0, t + 10 * MS, t + 10 * MS), 0);
	expect_timed_reply(11, 0x03, VMAC_CLOCK_LOCKING | VMAC_CLOCK_ARRIVAL, "a new session before its SYNC");
	sync_frames(1);
	t = rig.host_ns;
	ck_assert_msg(timed(12, VMAC_CYCLIC_DUE, 0x06, 0, t + 10 * MS, t + 10 * MS) == 0,
	              "after the new session's first SYNC, agreeing, a record 10 ms ahead was served on arrival");
	ck_assert_msg(llabs(diff(deadline(), local(t + 10 * MS))) <= 2, "the record does not wait for its instant");
}
END_TEST

START_TEST(without_a_receive_time_a_record_is_served_on_arrival)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	struct vmac_outputs out = {0x05, 0};
	int n;
	start(0, 1);
	n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 4, OFFSET, 1, 0, 0, rig.host_ns + MS, rig.host_ns + MS);
	vmac_proto_cyclic_put(buf, 0, TAG, VMAC_CYCLIC_DUE, &out);
	take_reply(vmac_board_receive(&rig.board, buf, (size_t)n, now_ms(), rig.reply, sizeof(rig.reply)));
	expect_timed_reply(4, 0x05, VMAC_CLOCK_LOCKED | VMAC_CLOCK_ARRIVAL, "vmac_board_receive");
	ck_assert_msg(rig.answer.latch.latched_at == 0, "latched_at claimed without a receive time");
	expect_nothing_waits("vmac_board_receive");
}
END_TEST

START_TEST(a_record_finding_outputs_waiting_drives_them_at_once)
{
	uint64_t t;
	start(0, 1);
	t = rig.host_ns;
	timed(1, 0, 0x01, 0, t + 5 * MS, t + 5 * MS);
	rig.host_ns += MS;
	ck_assert_int_eq(timed(2, 0, 0x02, 0, t + 6 * MS, t + 6 * MS), 0);
	ck_assert_msg(rig.writes == 1 && rig.driven.digital == 0x01, "the earlier outputs were not driven at once");
	ck_assert_msg(rig.board.counters.timed_overrun == 1, "no overrun counted");
	ck_assert_msg(rig.acts[0].how == VMAC_TIMED_OVERRUN, "the forced output not said an overrun");
	ck_assert_msg(llabs(diff(deadline(), local(t + 6 * MS))) <= 2, "the new outputs do not wait for theirs");
	run_due_at(t + 6 * MS);
	ck_assert_msg(rig.driven.digital == 0x02, "the new outputs not driven at their instant");
	/* A latch waiting when a DUE record comes: done at once, its answer
	 * given by the receive; the new latch waits. */
	t = rig.host_ns;
	timed(3, VMAC_CYCLIC_DUE, 0x03, 0, t + 5 * MS, t + 5 * MS);
	ck_assert_int_gt(timed(4, VMAC_CYCLIC_DUE, 0x04, 0, t + 6 * MS, t + 6 * MS), 0);
	expect_timed_reply(3, 0x03, VMAC_CLOCK_LOCKED, "the forced latch");
	ck_assert_int_gt(run_due_at(t + 6 * MS), 0);
	expect_timed_reply(4, 0x04, VMAC_CLOCK_LOCKED, "the new latch");
	ck_assert_int_eq(rig.board.counters.timed_overrun, 2);
	/* A record without DUE leaves a waiting latch in its place: its
	 * answer still comes, at its instant. */
	t = rig.host_ns;
	timed(5, VMAC_CYCLIC_DUE, 0x05, 0, t + 5 * MS, t + 5 * MS);
	ck_assert_int_eq(timed(6, 0, 0x06, 0, t + 6 * MS, t + 6 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0x05, "the earlier outputs not driven at once");
	ck_assert_int_gt(run_due_at(t + 5 * MS), 0);
	expect_timed_reply(5, 0x05, VMAC_CLOCK_LOCKED, "the latch a record without DUE found waiting");
	ck_assert_int_eq(run_due_at(t + 6 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0x06, "the record without DUE not driven at its instant");
}
END_TEST

/* Plain outputs (a plain UPDATE, a plain CYCLIC record: a machine
 * switched to acting on arrival) driven while TIMED outputs wait are the
 * newer: the waiting ones are never driven after them. A waiting latch
 * keeps its instant and its answer. */
START_TEST(plain_outputs_supersede_timed_outputs_still_waiting)
{
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	struct vmac_outputs off = {0};
	struct vmac_msg m;
	uint64_t t;
	int n;
	start(0, 1);
	t = rig.host_ns;
	timed(1, VMAC_CYCLIC_DUE, 0x05, 0, t + 5 * MS, t + 5 * MS);
	rig.host_ns = t + MS;
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION, 2);
	m.u.outputs.digital = 0x00;
	ck_assert_int_gt(send_msg(&m), 0);
	ck_assert_int_gt(run_due_at(t + 5 * MS), 0);
	expect_timed_reply(1, 0x00, VMAC_CLOCK_LOCKED, "the latch a plain UPDATE found waiting");
	ck_assert_msg(rig.driven.digital == 0x00, "the older TIMED outputs 0x%02x driven after a plain UPDATE's 0x00",
	              rig.driven.digital);
	t = rig.host_ns;
	timed(3, 0, 0x06, 0, t + 5 * MS, t + 5 * MS);
	n = vmac_proto_cyclic_begin(buf, sizeof(buf), 4, OFFSET, 1);
	ck_assert_int_gt(n, 0);
	vmac_proto_cyclic_put(buf, 0, TAG, 0, &off);
	rig.host_ns = t + MS;
	ck_assert_int_eq(deliver(buf, (size_t)n), 0);
	expect_nothing_waits("after a plain CYCLIC record");
	ck_assert_int_eq(run_due_at(t + 5 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0x00, "the older TIMED outputs 0x%02x driven after a plain CYCLIC's 0x00",
	              rig.driven.digital);
}
END_TEST

/* What waits is cancelled by each of these, and never driven afterwards. */
static void expect_cancelled_by(uint8_t op, const char *what)
{
	struct vmac_msg m;
	uint64_t t;
	start(0, 1);
	t = rig.host_ns;
	timed(1, 0, 0x05, 0, t, t); /* driving 0x05 now */
	timed(2, VMAC_CYCLIC_DUE, 0x07, 500, t + 50 * MS, t + 50 * MS);
	ck_assert_int_eq(rig.driven.digital, 0x05);
	m = msg(2, 0, VMAC_CH_DEVICE, op, SESSION, 5);
	if (op == VMAC_OP_SLEEP)
		m.u.sleep_s = 10;
	if (op == VMAC_OP_REGISTER) {
		m.u.reg.major = 3;
		m.u.reg.watchdog_ms = 500;
	}
	if (op == 0xFF) {
		rig.host_ns += 600 * MS; /* the watchdog trips at the next look */
		ck_assert_int_eq(vmac_board_poll(&rig.board, now_ms()), 1);
		rig.host_ns = t;
	} else {
		send_msg(&m);
	}
	ck_assert_msg(rig.driven.digital == 0 && rig.driven.pwm == 0, "%s: outputs not off", what);
	expect_nothing_waits(what);
	ck_assert_int_eq(run_due_at(t + 60 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0 && rig.driven.pwm == 0, "%s: the waiting outputs were driven after it",
	              what);
}

START_TEST(shutdown_sleep_register_and_the_watchdog_cancel_what_waits)
{
	expect_cancelled_by(VMAC_OP_SHUTDOWN, "SHUTDOWN");
	expect_cancelled_by(VMAC_OP_SLEEP, "SLEEP");
	expect_cancelled_by(VMAC_OP_REGISTER, "a new REGISTER");
	expect_cancelled_by(0xFF, "a watchdog trip");
}
END_TEST

START_TEST(a_keyed_board_takes_timed_records_sealed_and_seals_its_answer)
{
	struct vmac_report rep;
	char line[VMAC_REPORT_LINE];
	uint8_t buf[VMAC_CYCLIC_FRAME_MAX];
	struct vmac_outputs out = {0x05, 0};
	uint64_t t;
	int n;
	start(1, 1);
	t = rig.host_ns;
	/* Unsealed: not obeyed, nothing waits. */
	n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 4, OFFSET, 1, 0, 0, t + MS, t + MS);
	vmac_proto_cyclic_put(buf, 0, TAG, VMAC_CYCLIC_DUE, &out);
	ck_assert_int_eq(deliver(buf, (size_t)n), 0);
	expect_nothing_waits("an unsealed TIMED record to a keyed board");
	/* Sealed with the instants changed after: the MAC covers them. */
	n = vmac_proto_cyclic_begin_timed(buf, sizeof(buf), 5, OFFSET, 1, 1, ++rig.host_counter, t + MS, t + MS);
	vmac_proto_cyclic_put(buf, 0, TAG, VMAC_CYCLIC_DUE, &out);
	vmac_proto_cyclic_seal_record(buf, 0, rig.to_board);
	buf[VMAC_HDR_LEN + 2 + 4 + 7] ^= 1; /* out_at's last byte */
	ck_assert_int_eq(deliver(buf, (size_t)n), 0);
	expect_nothing_waits("a sealed TIMED record whose out_at was changed");
	ck_assert_int_eq(rig.writes, 0);
	/* Its clock locked by the sealed SYNC: the outputs and the latch wait
	 * for their instant, the answer sealed. */
	ck_assert_int_eq(timed(6, VMAC_CYCLIC_DUE, 0x05, 0, t + MS, t + MS), 0);
	ck_assert_int_eq(rig.writes, 0);
	ck_assert_int_gt(run_due_at(t + MS), 0);
	ck_assert_msg(rig.answer.flags == (VMAC_FLAG_REPLY | VMAC_FLAG_TIMED | VMAC_FLAG_AUTH),
	              "a keyed board's TIMED reply has flags 0x%02x, want 0x07", rig.answer.flags);
	expect_timed_reply(6, 0x05, VMAC_CLOCK_LOCKED, "sealed, at the instant");
	ck_assert_msg(llabs(diff(rig.answer.latch.latched_at, t + MS)) <= 1000, "latched_at off the instant");
	expect_nothing_waits("a keyed board");
	vmac_report_init(&rep, &rig.board, &none, 0);
	rig.board.timed.mode = VMAC_TIMED_MODE_NONE;
	rep.timed = VMAC_TIMED_MODE_NONE;
	timed(7, 0, 0x01, 0, t + 2 * MS, t + 2 * MS);
	ck_assert_int_eq(vmac_report_next(&rep, &rig.board, &none, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "motor-1: acting at host instants");
}
END_TEST

/* A clock lost while outputs wait: they are driven at the counter's
 * instant they were given (no output waits forever on a clock), the latch
 * says lost without a time, and the next record acts on arrival. */
START_TEST(outputs_waiting_when_the_clock_is_lost_are_still_driven_at_their_instant)
{
	struct vmac_msg m;
	uint64_t t, at;
	start(0, 1);
	m = msg(2, 0, VMAC_CH_DEVICE, VMAC_OP_WATCHDOG, SESSION, 4);
	m.u.watchdog_ms = 60000; /* the session outlives the wait */
	ck_assert_int_gt(send_msg(&m), 0);
	t = rig.host_ns;
	at = t + 40000 * MS; /* 40 s ahead, no SYNC meanwhile: lost before */
	ck_assert_int_eq(timed(1, VMAC_CYCLIC_DUE, 0x05, 0, at, at), 0);
	ck_assert_int_eq(vmac_board_clock_poll(&rig.board, local(at)), VMAC_CLOCK_LOST);
	ck_assert_int_gt(run_due_at(at), 0);
	ck_assert_msg(rig.driven.digital == 0x05, "the waiting outputs were not driven once the clock was lost");
	expect_timed_reply(1, 0x05, VMAC_CLOCK_LOST, "latched with the clock lost");
	ck_assert_msg(rig.answer.latch.latched_at == 0 && rig.answer.latch.bound_ns == 0xFFFFFFFFu,
	              "a lost clock claims a latch time or bound");
	ck_assert_int_gt(timed(2, VMAC_CYCLIC_DUE, 0x00, 0, at + MS, at + MS), 0);
	expect_timed_reply(2, 0x00, VMAC_CLOCK_LOST | VMAC_CLOCK_ARRIVAL, "the next record, clock lost");
	ck_assert_msg(rig.driven.digital == 0 && rig.board.counters.timed_arrival == 1, "not served on arrival");
	expect_nothing_waits("after a lost clock");
}
END_TEST

/* A TIMED UPDATE (unicast) of the session: sealed on a keyed board. */
static int timed_update(uint16_t seq, uint8_t digital, int16_t pwm, uint64_t out_at, uint64_t in_at)
{
	struct vmac_msg m = msg(2, VMAC_FLAG_TIMED, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION, seq);
	m.u.outputs.digital = digital;
	m.u.outputs.pwm = pwm;
	m.out_at = out_at;
	m.in_at = in_at;
	return send_msg(&m);
}

/* The unicast form is served by the same machinery as a DUE record: at
 * the instants, its answer the TIMED reply; it forces a waiting TIMED
 * CYCLIC's outputs as another record would, and a SHUTDOWN cancels it. */
START_TEST(a_timed_update_drives_at_out_at_and_latches_at_in_at)
{
	uint64_t t;
	start(0, 1);
	t = rig.host_ns;
	ck_assert_msg(timed_update(0x1234, 0x05, -250, t + 2 * MS, t + 3 * MS) == 0,
	              "a TIMED UPDATE answered on arrival; its latch is 3 ms ahead");
	ck_assert_msg(rig.writes == 0, "a TIMED UPDATE drove on arrival; out_at is 2 ms ahead");
	ck_assert_msg(rig.board.last_valid_ms == t / MS && rig.board.counters.timed == 1,
	              "a TIMED UPDATE did not feed the watchdog or was not counted timed");
	ck_assert_int_eq(run_due_at(t + 2 * MS - 1000), 0);
	ck_assert_msg(rig.writes == 0, "drove 1 us before out_at");
	ck_assert_int_eq(run_due_at(t + 2 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0x05 && rig.driven.pwm == -250, "a TIMED UPDATE not driven at out_at");
	ck_assert_int_gt(run_due_at(t + 3 * MS), 0);
	expect_timed_reply(0x1234, 0x05, VMAC_CLOCK_LOCKED, "a TIMED UPDATE's latch at in_at");
	ck_assert_msg(llabs(diff(rig.answer.latch.latched_at, t + 3 * MS)) <= 1000, "latched_at %lld ns off in_at",
	              (long long)diff(rig.answer.latch.latched_at, t + 3 * MS));
	ck_assert_msg(rig.acts[0].how == VMAC_TIMED_AT_INSTANT && rig.acts[1].how == VMAC_TIMED_AT_INSTANT,
	              "a TIMED UPDATE's actions not at their instants");
	/* A TIMED CYCLIC's outputs waiting when a TIMED UPDATE comes: driven
	 * at once, then the UPDATE's wait for theirs. */
	t = rig.host_ns;
	timed(2, 0, 0x01, 0, t + 5 * MS, t + 5 * MS);
	ck_assert_int_eq(timed_update(3, 0x02, 0, t + 6 * MS, t + 6 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0x01 && rig.board.counters.timed_overrun == 1,
	              "the waiting CYCLIC outputs were not forced by the TIMED UPDATE");
	/* SHUTDOWN cancels what the UPDATE left waiting. */
	send_msg(&(struct vmac_msg){.version = 2, .seq = 4, .device_id = SESSION, .op = VMAC_OP_SHUTDOWN});
	expect_nothing_waits("SHUTDOWN after a TIMED UPDATE");
	ck_assert_int_eq(run_due_at(t + 7 * MS), 0);
	ck_assert_msg(rig.driven.digital == 0, "a TIMED UPDATE's outputs were driven after SHUTDOWN");
}
END_TEST

START_TEST(a_timed_update_without_a_usable_clock_acts_on_arrival_and_says_so)
{
	uint64_t t;
	start(0, 0);
	t = rig.host_ns;
	ck_assert_int_gt(timed_update(9, 0x03, 0, t + 10 * MS, t + 10 * MS), 0);
	expect_timed_reply(9, 0x03, VMAC_CLOCK_UNSYNCED | VMAC_CLOCK_ARRIVAL, "a TIMED UPDATE, clock unsynced");
	ck_assert_msg(rig.driven.digital == 0x03 && rig.board.counters.timed_arrival == 1,
	              "a TIMED UPDATE not served on arrival");
	expect_nothing_waits("a TIMED UPDATE on arrival");
}
END_TEST

START_TEST(a_keyed_board_takes_a_timed_update_sealed_only)
{
	struct vmac_msg m = msg(2, VMAC_FLAG_TIMED, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION, 5);
	uint8_t buf[VMAC_PACKET_MAX];
	uint64_t t;
	int n;
	start(1, 1);
	t = rig.host_ns;
	m.u.outputs.digital = 0x05;
	m.out_at = m.in_at = t + MS;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_int_eq(deliver(buf, (size_t)n), 0);
	expect_nothing_waits("an unsealed TIMED UPDATE to a keyed board");
	n = vmac_proto_seal(buf, (size_t)n, sizeof(buf), ++rig.host_counter, rig.to_board, NULL, 0);
	buf[VMAC_HDR_LEN + 7] ^= 1; /* out_at's last byte, after the seal */
	ck_assert_int_eq(deliver(buf, (size_t)n), 0);
	expect_nothing_waits("a sealed TIMED UPDATE whose out_at was changed");
	ck_assert_msg(rig.writes == 0 && rig.board.counters.auth_failed == 2, "auth_failed %u, want 2",
	              rig.board.counters.auth_failed);
	ck_assert_int_eq(timed_update(6, 0x05, 0, t + MS, t + MS), 0);
	ck_assert_int_gt(run_due_at(t + MS), 0);
	ck_assert_msg(rig.answer.flags == (VMAC_FLAG_REPLY | VMAC_FLAG_TIMED | VMAC_FLAG_AUTH),
	              "a keyed board's answer to a TIMED UPDATE has flags 0x%02x, want 0x07", rig.answer.flags);
	expect_timed_reply(6, 0x05, VMAC_CLOCK_LOCKED, "a sealed TIMED UPDATE at its instant");
}
END_TEST

/* A board of version 1 never reads one: it is malformed to it, nothing is
 * driven and nothing answered. */
START_TEST(a_version_1_board_counts_a_timed_update_malformed)
{
	struct vmac_msg m = msg(2, VMAC_FLAG_TIMED, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION, 5);
	uint8_t buf[VMAC_PACKET_MAX];
	uint32_t bad;
	int n;
	start(0, 1);
	rig.board.id.protocol = 1;
	bad = rig.board.counters.frames_malformed;
	m.u.outputs.digital = 0x05;
	m.out_at = m.in_at = rig.host_ns;
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_msg(deliver(buf, (size_t)n) == 0 && rig.writes == 0, "a version-1 board obeyed a TIMED UPDATE");
	ck_assert_msg(rig.board.counters.frames_malformed == bad + 1, "a version-1 board did not count it malformed");
	expect_nothing_waits("a version-1 board");
}
END_TEST

START_TEST(the_board_announces_firmware_1_2_and_says_when_it_acts_at_instants)
{
	struct vmac_report rep;
	char line[VMAC_REPORT_LINE];
	struct vmac_msg m;
	uint8_t buf[VMAC_FRAME_MAX];
	int n;
	start(0, 1);
	vmac_report_init(&rep, &rig.board, &none, 0);
	timed(1, 0, 0x01, 0, rig.host_ns, rig.host_ns);
	ck_assert_int_eq(vmac_report_next(&rep, &rig.board, &none, line, sizeof(line)), 1);
	ck_assert_str_eq(line, "motor-1: acting at host instants");
	vmac_board_safe(&rig.board);
	m = msg(1, 0, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 1);
	n = vmac_proto_encode(&m, buf, sizeof(buf));
	ck_assert_int_gt(deliver(buf, (size_t)n), 0);
	ck_assert_msg(rig.answer.u.announce.firmware_major == 1 && rig.answer.u.announce.firmware_minor == 2,
	              "announces firmware %u.%u, want 1.2 (takes TIMED CYCLIC and TIMED UPDATE)",
	              rig.answer.u.announce.firmware_major, rig.answer.u.announce.firmware_minor);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("board_timed");
	TCase *tc = tcase_create("time-triggered I/O");
	tcase_add_test(tc, a_timed_record_drives_at_out_at_and_latches_at_in_at);
	tcase_add_test(tc, a_latch_before_the_outputs_reports_the_outputs_then_driven);
	tcase_add_test(tc, an_instant_already_past_is_acted_on_at_once);
	tcase_add_test(tc, a_clock_not_usable_acts_on_arrival_and_says_so);
	tcase_add_test(tc, a_new_session_acts_on_arrival_until_its_first_sync);
	tcase_add_test(tc, without_a_receive_time_a_record_is_served_on_arrival);
	tcase_add_test(tc, a_record_finding_outputs_waiting_drives_them_at_once);
	tcase_add_test(tc, plain_outputs_supersede_timed_outputs_still_waiting);
	tcase_add_test(tc, shutdown_sleep_register_and_the_watchdog_cancel_what_waits);
	tcase_add_test(tc, a_keyed_board_takes_timed_records_sealed_and_seals_its_answer);
	tcase_add_test(tc, outputs_waiting_when_the_clock_is_lost_are_still_driven_at_their_instant);
	tcase_add_test(tc, a_timed_update_drives_at_out_at_and_latches_at_in_at);
	tcase_add_test(tc, a_timed_update_without_a_usable_clock_acts_on_arrival_and_says_so);
	tcase_add_test(tc, a_keyed_board_takes_a_timed_update_sealed_only);
	tcase_add_test(tc, a_version_1_board_counts_a_timed_update_malformed);
	tcase_add_test(tc, the_board_announces_firmware_1_2_and_says_when_it_acts_at_instants);
	suite_add_tcase(s, tc);
	return s;
}
