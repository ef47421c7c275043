/* Unit tests for the kernel's transmit timestamps (core/transport/tx_stamp.c;
 * docs/TIME.md, "The two-step SYNC"), over UDP on loopback, which gives
 * software stamps: only the sends that ask get one, each comes back with its
 * packet's cookie (the kernel's OPT_ID counts only those), between the
 * send's start and end; sends beyond the pending ring give way, oldest
 * first, and their stamps are dropped, not given to another packet. */
#include <arpa/inet.h>
#include <check.h>
#include <string.h>
#include <unistd.h>

#include "../../core/transport/transport.h"
#include "check_main.h"

struct pair {
	struct vmac_transport host, board;
};

static void open_pair(struct pair *p, int stamps)
{
	struct vmac_bus_spec spec;
	char err[256] = "";
	ck_assert_int_eq(vmac_bus_spec_parse("239.255.86.78:5871", &spec), 0);
	spec.iface.s_addr = htonl(INADDR_LOOPBACK);
	ck_assert_msg(vmac_transport_open_host(&p->host, &spec, err, sizeof(err)) == 0, "host: %s", err);
	ck_assert_msg(vmac_transport_open_board(&p->board, &spec, err, sizeof(err)) == 0, "board: %s", err);
	if (stamps)
		ck_assert_int_eq(vmac_transport_tx_stamps_on(&p->host), 0);
}

static void close_pair(struct pair *p)
{
	vmac_transport_close(&p->host);
	vmac_transport_close(&p->board);
}

/* n packets to the board, packet i asking with cookie[i] (negative: not). */
static void send_n(struct pair *p, struct vmac_packet *pkts, const int32_t *cookie, int n)
{
	int i;
	for (i = 0; i < n; i++) {
		memset(&pkts[i], 0, sizeof(pkts[i]));
		memcpy(pkts[i].data, "VM", 2);
		pkts[i].len = 16;
		pkts[i].addr = p->board.local;
		pkts[i].tx_cookie = cookie[i];
	}
	ck_assert_int_eq(vmac_transport_send(&p->host, pkts, n), n);
}

/* Every stamp that comes within a second, up to max. */
static int read_stamps(struct pair *p, struct vmac_tx_stamp *got, int want, int max)
{
	int n = 0, tries;
	for (tries = 0; tries < 1000 && n < want; tries++) {
		n += vmac_transport_tx_read(&p->host, 0, got + n, max - n);
		if (n < want)
			usleep(1000);
	}
	return n;
}

START_TEST(only_the_sends_that_ask_get_a_stamp_each_with_its_cookie)
{
	static struct vmac_packet pkts[6];
	static const int32_t cookie[6] = {10, -1, 11, -1, 0x7FFF0012, -1};
	struct vmac_tx_stamp got[8];
	struct pair p;
	int64_t before, after;
	int n, i;

	open_pair(&p, 1);
	before = vmac_now_ns();
	send_n(&p, pkts, cookie, 6);
	after = vmac_now_ns();
	n = read_stamps(&p, got, 3, 8);
	ck_assert_msg(n == 3, "%d stamps for the 3 sends that asked", n);
	ck_assert_msg(got[0].cookie == 10 && got[1].cookie == 11 && got[2].cookie == 0x7FFF0012,
	              "cookies %u %u %u, want 10 11 0x7FFF0012", (unsigned)got[0].cookie, (unsigned)got[1].cookie,
	              (unsigned)got[2].cookie);
	for (i = 0; i < 3; i++)
		ck_assert_msg(got[i].tx_ns >= before && got[i].tx_ns <= after &&
		                  (i == 0 || got[i].tx_ns >= got[i - 1].tx_ns),
		              "stamp %d at %lld, the sends from %lld to %lld", i, (long long)got[i].tx_ns,
		              (long long)before, (long long)after);
	ck_assert_uint_eq(p.host.tx_count, 0);
	ck_assert_int_eq(vmac_transport_tx_read(&p.host, 1, got, 8), 0); /* nothing left */
	close_pair(&p);
}
END_TEST

START_TEST(sends_beyond_the_pending_ring_give_way_oldest_first)
{
	static struct vmac_packet pkts[VMAC_TRANSPORT_TX_PENDING + 6];
	int32_t cookie[VMAC_TRANSPORT_TX_PENDING + 6];
	struct vmac_tx_stamp got[VMAC_TRANSPORT_TX_PENDING + 6];
	struct pair p;
	int n, i;

	for (i = 0; i < VMAC_TRANSPORT_TX_PENDING + 6; i++)
		cookie[i] = i;
	open_pair(&p, 1);
	send_n(&p, pkts, cookie, VMAC_TRANSPORT_TX_PENDING + 6);
	n = read_stamps(&p, got, VMAC_TRANSPORT_TX_PENDING, VMAC_TRANSPORT_TX_PENDING + 6);
	ck_assert_msg(n == VMAC_TRANSPORT_TX_PENDING, "%d stamps, want the %d pending", n, VMAC_TRANSPORT_TX_PENDING);
	for (i = 0; i < n; i++)
		ck_assert_msg(got[i].cookie == (uint32_t)(i + 6), "stamp %d has cookie %u, want %d", i,
		              (unsigned)got[i].cookie, i + 6);
	close_pair(&p);
}
END_TEST

START_TEST(without_stamps_on_nothing_is_asked_or_read)
{
	static struct vmac_packet pkts[2];
	static const int32_t cookie[2] = {1, 2};
	struct vmac_tx_stamp got[4];
	struct pair p;

	open_pair(&p, 0);
	send_n(&p, pkts, cookie, 2);
	usleep(10000);
	ck_assert_int_eq(vmac_transport_tx_read(&p.host, 1, got, 4), 0);
	ck_assert_int_eq(p.host.tx_count, 0);
	close_pair(&p);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("tx_stamp");
	TCase *tc = tcase_create("udp");
	tcase_add_test(tc, only_the_sends_that_ask_get_a_stamp_each_with_its_cookie);
	tcase_add_test(tc, sends_beyond_the_pending_ring_give_way_oldest_first);
	tcase_add_test(tc, without_stamps_on_nothing_is_asked_or_read);
	suite_add_tcase(s, tc);
	return s;
}
