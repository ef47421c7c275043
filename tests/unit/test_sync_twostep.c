/* Unit tests for the two-step SYNC on the board (firmware/board.c,
 * sync_feed; docs/TIME.md, "The two-step SYNC"): which sample of a SYNC
 * the clock gets. A host whose kernel sends each SYNC 50 us after the
 * host_ns it carries, and names that transmit time in the next SYNC: the
 * board takes the named time with the previous frame's receive time
 * (two-step) and its clock sees only the path; with prev_tx_ns 0 it takes
 * host_ns (one-step) and the 50 us with it. While the host names times, a
 * sample whose time a lost stamp, a lost frame or an implausible time
 * leaves unnamed is dropped, never fed one-step beside two-step ones nor
 * paired with the wrong frame; slow SYNC goes one-step; holdover counts
 * from the sample fed. */
#include <check.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "../../firmware/board.h"
#include "check_main.h"

#define HOST_START_NS 5000000000ull
#define KERNEL_NS 50000u /* the kernel sends 50 us after host_ns */
#define PATH_NS 3000u    /* and the board stamps 3 us after that */

static void fake_read(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
}

static void fake_write(void *ctx, const struct vmac_outputs *out)
{
	(void)ctx;
	(void)out;
}

static const struct vmac_board_io fake_hal = {fake_read, fake_write};

static void board_start(struct vmac_board *b)
{
	struct vmac_board_identity id;
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "motor");
	strcpy(id.board, "two-1");
	id.major = 3;
	id.minor = 7;
	id.protocol = 2;
	vmac_board_init(b, &id, &fake_hal, NULL, 0);
}

/* One SYNC of seq whose host_ns is at ms, prev_tx_ns as given, received at
 * its true send + PATH_NS (the board's counter is host time). */
static void sync_at(struct vmac_board *b, uint16_t seq, uint64_t ms, uint64_t prev_tx_ns)
{
	struct vmac_msg m;
	uint8_t frame[VMAC_FRAME_MAX], reply[VMAC_BOARD_REPLY_MAX];
	uint64_t host_ns = HOST_START_NS + ms * 1000000u;
	int len;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_SYNC;
	m.seq = seq;
	m.u.sync.host_ns = host_ns;
	m.u.sync.prev_tx_ns = prev_tx_ns;
	len = vmac_proto_encode(&m, frame, sizeof(frame));
	ck_assert_int_gt(len, 0);
	ck_assert_int_eq(
	    vmac_board_receive_at(b, frame, (size_t)len, ms, host_ns + KERNEL_NS + PATH_NS, reply, sizeof(reply)), 0);
}

/* The transmit time of the SYNC whose host_ns was at ms. */
static uint64_t tx_of(uint64_t ms)
{
	return HOST_START_NS + ms * 1000000u + KERNEL_NS;
}

/* n SYNC at 1 kHz from ms 0, each naming its predecessor's transmit time
 * when two_step (else 0); frame `lose_stamp` names none, frame `drop` never
 * arrives (-1: none of either). */
static void run(struct vmac_board *b, int n, int two_step, int lose_stamp, int drop)
{
	int k;
	for (k = 0; k < n; k++)
		if (k != drop)
			sync_at(b, (uint16_t)k, (uint64_t)k,
			        two_step && k > 0 && k != lose_stamp ? tx_of((uint64_t)k - 1) : 0);
}

static uint32_t fed(const struct vmac_board *b)
{
	return b->clock.counters.accepted + b->clock.counters.rejected;
}

/* The clock's offset (counter - host time) at ms, ns. */
static int64_t offset_at(const struct vmac_board *b, uint64_t ms)
{
	int64_t offset;
	uint64_t bound;
	ck_assert_int_eq(vmac_board_clock_offset(b, HOST_START_NS + ms * 1000000u, &offset, &bound), 0);
	return offset;
}

START_TEST(two_step_leaves_the_kernels_delay_out_one_step_keeps_it)
{
	struct vmac_board b;
	int64_t off;

	board_start(&b);
	run(&b, 1500, 1, -1, -1);
	off = offset_at(&b, 1500);
	/* frame 0 one-step at once (nothing before it to name its time), 1..1498
	 * two-step, each with the next frame; 1499's still waits */
	ck_assert_msg(b.clock.state == VMAC_CLOCK_LOCKED && b.counters.sync_two_step == 1498 && fed(&b) == 1499,
	              "two-step: clock %s, two-step %u, fed %u; want locked, 1498, 1499",
	              vmac_clock_state_name(b.clock.state), (unsigned)b.counters.sync_two_step, (unsigned)fed(&b));
	ck_assert_msg(off > (int64_t)PATH_NS - 2000 && off < (int64_t)PATH_NS + 2000,
	              "two-step: offset %lld ns, want the path's %u within 2 us", (long long)off, PATH_NS);

	board_start(&b);
	run(&b, 1500, 0, -1, -1);
	off = offset_at(&b, 1500);
	ck_assert_msg(b.clock.state == VMAC_CLOCK_LOCKED && b.counters.sync_two_step == 0 && fed(&b) == 1500,
	              "one-step: clock %s, two-step %u, fed %u; want locked, 0, 1500",
	              vmac_clock_state_name(b.clock.state), (unsigned)b.counters.sync_two_step, (unsigned)fed(&b));
	ck_assert_msg(off > (int64_t)(KERNEL_NS + PATH_NS) - 2000 && off < (int64_t)(KERNEL_NS + PATH_NS) + 2000,
	              "one-step: offset %lld ns, want the kernel's and the path's %u within 2 us", (long long)off,
	              KERNEL_NS + PATH_NS);
}
END_TEST

START_TEST(a_lost_stamp_drops_the_waiting_sample)
{
	struct vmac_board b;

	board_start(&b);
	run(&b, 1500, 1, 700, -1);
	/* frame 699 waited, 700 named nothing: 699 dropped (its host_ns is
	 * early by the kernel's 50 us); 700 waits as every sample while the host
	 * names times, and 701 names it: two-step */
	ck_assert_msg(b.counters.sync_two_step == 1497 && fed(&b) == 1498 && b.clock.counters.starts == 1,
	              "a lost stamp: two-step %u, fed %u, starts %u; want 1497, 1498, 1",
	              (unsigned)b.counters.sync_two_step, (unsigned)fed(&b), (unsigned)b.clock.counters.starts);
	ck_assert_int_eq(b.clock.state, VMAC_CLOCK_LOCKED);
}
END_TEST

START_TEST(a_lost_frame_pairs_no_time_with_the_wrong_frame)
{
	struct vmac_board b;
	int64_t off;

	board_start(&b);
	run(&b, 1500, 1, -1, 700);
	/* 701 names 700's transmit time, which is not 699's: 699 dropped, 701
	 * waits; a wrong pairing would be a sample 1 ms early */
	off = offset_at(&b, 1500);
	ck_assert_msg(b.counters.sync_two_step == 1496 && fed(&b) == 1497 && b.clock.counters.starts == 1 &&
	                  b.clock.counters.spikes == 0,
	              "a lost frame: two-step %u, fed %u, starts %u, spikes %u; want 1496, 1497, 1, 0",
	              (unsigned)b.counters.sync_two_step, (unsigned)fed(&b), (unsigned)b.clock.counters.starts,
	              (unsigned)b.clock.counters.spikes);
	ck_assert_msg(off > (int64_t)PATH_NS - 2000 && off < (int64_t)PATH_NS + 2000,
	              "offset %lld ns after a lost frame", (long long)off);
}
END_TEST

START_TEST(an_implausible_time_drops_its_sample_slow_sync_goes_one_step)
{
	struct vmac_board b;
	int k;

	/* a transmit time before the frame's own host_ns, or 20 ms after it */
	board_start(&b);
	sync_at(&b, 1, 0, 0);
	sync_at(&b, 2, 1, tx_of(0));
	sync_at(&b, 3, 2, HOST_START_NS + 1000000u - 1);           /* names 2's time 1 ns before its host_ns */
	sync_at(&b, 4, 3, tx_of(2));                               /* a good one: 3 two-step */
	sync_at(&b, 5, 4, tx_of(3) + VMAC_BOARD_TWO_STEP_SPAN_NS); /* 10 ms after it left */
	/* 1 one-step (nothing named yet); 2 and 4 dropped, unnamed; 3 two-step */
	ck_assert_msg(b.counters.sync_two_step == 1 && fed(&b) == 2,
	              "implausible times: two-step %u, fed %u; want 1, 2", (unsigned)b.counters.sync_two_step,
	              (unsigned)fed(&b));

	/* SYNC 30 ms apart: no sample waits (it would count against holdover) */
	board_start(&b);
	for (k = 0; k < 20; k++)
		sync_at(&b, (uint16_t)k, (uint64_t)k * 30, k ? tx_of((uint64_t)(k - 1) * 30) : 0);
	ck_assert_msg(b.counters.sync_two_step == 0 && fed(&b) == 20, "SYNC at 30 ms: two-step %u, fed %u; want 0, 20",
	              (unsigned)b.counters.sync_two_step, (unsigned)fed(&b));
}
END_TEST

START_TEST(holdover_counts_from_the_last_sample_fed)
{
	struct vmac_board b;
	uint64_t last_rx = tx_of(1498) + PATH_NS; /* the last sample fed: frame 1498's, fed with 1499 */

	board_start(&b);
	run(&b, 1500, 1, -1, -1);
	ck_assert_int_eq(vmac_board_clock_poll(&b, last_rx + VMAC_CLOCK_HOLDOVER_NS - 1000), VMAC_CLOCK_LOCKED);
	ck_assert_int_eq(vmac_board_clock_poll(&b, last_rx + VMAC_CLOCK_HOLDOVER_NS), VMAC_CLOCK_HOLDOVER);
	/* the host again, 61 ms on, naming the waiting sample's time: it goes
	 * two-step, behind the holdover's line; this one, so late, at once */
	sync_at(&b, 1500, 1560, tx_of(1499));
	ck_assert_msg(b.counters.sync_two_step == 1499 && fed(&b) == 1501 && b.clock.counters.starts == 1,
	              "after holdover: two-step %u, fed %u, starts %u; want 1499, 1501, 1",
	              (unsigned)b.counters.sync_two_step, (unsigned)fed(&b), (unsigned)b.clock.counters.starts);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("sync_twostep");
	TCase *tc = tcase_create("board");
	tcase_add_test(tc, two_step_leaves_the_kernels_delay_out_one_step_keeps_it);
	tcase_add_test(tc, a_lost_stamp_drops_the_waiting_sample);
	tcase_add_test(tc, a_lost_frame_pairs_no_time_with_the_wrong_frame);
	tcase_add_test(tc, an_implausible_time_drops_its_sample_slow_sync_goes_one_step);
	tcase_add_test(tc, holdover_counts_from_the_last_sample_fed);
	suite_add_tcase(s, tc);
	return s;
}
