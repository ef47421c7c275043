/* Unit tests of the transports (core/transport): bus specs parse to the
 * right kind and refuse the rest; Ethernet addresses compare and print as
 * MACs; UDP still carries a frame over loopback; raw Ethernet carries frames
 * both ways over a veth pair in a network namespace of its own (addresses,
 * destination MACs, padding trimmed, kernel stamps, other EtherTypes and our
 * own sends skipped, batches above one system call, a burst of 500 read in
 * order 64 at a time), once from the receive ring and once with recvmmsg
 * (VMAC_ETH_RECVMMSG=1, what it falls back to); and without CAP_NET_RAW it
 * says so in one line. The veth tests need root and network namespaces:
 * elsewhere they are SKIPPED loudly and the reason appended to
 * $VMAC_SKIP_FILE (make test lists it), or they fail when CI=true
 * (vmac_test_cannot_run, check_main.h). */
#include <arpa/inet.h>
#include <check.h>
#include <errno.h>
#include <linux/capability.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <poll.h>
#include <sched.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../../core/transport/transport.h"
#include "check_main.h"
#include "frames.h"

static const uint8_t board_mac[6] = {0x02, 0x00, 0x00, 0x00, 0x00, 0x07};
static const uint8_t broadcast_mac[6] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};

static struct vmac_addr mac_addr(const uint8_t mac[6], int ifindex)
{
	struct vmac_addr a;
	struct sockaddr_ll *sll = (struct sockaddr_ll *)&a.ss;
	memset(&a, 0, sizeof(a));
	sll->sll_family = AF_PACKET;
	sll->sll_protocol = htons(VMAC_ETHERTYPE);
	sll->sll_ifindex = ifindex;
	sll->sll_halen = 6;
	memcpy(sll->sll_addr, mac, 6);
	a.len = sizeof(*sll);
	return a;
}

START_TEST(bus_specs_parse_to_their_transport)
{
	struct vmac_bus_spec spec;
	char name16[32];

	memset(&spec, 0, sizeof(spec));
	ck_assert_int_eq(vmac_bus_spec_parse("eth:veth0", &spec), 0);
	ck_assert_int_eq(spec.kind, VMAC_TRANSPORT_ETH);
	ck_assert_str_eq(spec.ifname, "veth0");

	memset(&spec, 0, sizeof(spec));
	spec.iface.s_addr = htonl(INADDR_LOOPBACK); /* the caller's, left as it was */
	ck_assert_int_eq(vmac_bus_spec_parse("239.255.86.77:5870", &spec), 0);
	ck_assert_int_eq(spec.kind, VMAC_TRANSPORT_UDP);
	ck_assert_uint_eq(ntohl(spec.group.s_addr), 0xEFFF564Du);
	ck_assert_uint_eq(spec.port, 5870);
	ck_assert_uint_eq(ntohl(spec.iface.s_addr), INADDR_LOOPBACK);
	ck_assert_str_eq(spec.ifname, "");

	ck_assert_int_eq(vmac_bus_spec_parse("eth:abcdefghijklmno", &spec), 0); /* 15: the longest name */
	ck_assert_str_eq(spec.ifname, "abcdefghijklmno");

	snprintf(name16, sizeof(name16), "eth:%s", "abcdefghijklmnop");
	ck_assert_int_eq(vmac_bus_spec_parse(name16, &spec), -EINVAL);
	ck_assert_int_eq(vmac_bus_spec_parse("eth:", &spec), -EINVAL);
	ck_assert_int_eq(vmac_bus_spec_parse("eth:a/b", &spec), -EINVAL);
	ck_assert_int_eq(vmac_bus_spec_parse("1.2.3.4:5", &spec), -EINVAL); /* not multicast */
	ck_assert_int_eq(vmac_bus_spec_parse("239.255.86.77:0", &spec), -EINVAL);
	ck_assert_int_eq(vmac_bus_spec_parse("foo", &spec), -EINVAL);
	ck_assert_int_eq(vmac_bus_spec_parse("", &spec), -EINVAL);
}
END_TEST

START_TEST(ethernet_addresses_compare_and_print_as_macs)
{
	static const uint8_t other[6] = {0x02, 0x00, 0x00, 0x00, 0x00, 0x08};
	struct vmac_addr a = mac_addr(board_mac, 3), b = mac_addr(board_mac, 3);
	struct vmac_addr c = mac_addr(other, 3), d = mac_addr(board_mac, 4), all = mac_addr(broadcast_mac, 1), ip;
	struct sockaddr_in *sin = (struct sockaddr_in *)&ip.ss;
	char buf[64];

	ck_assert_str_eq(vmac_addr_format(&a, buf, sizeof(buf)), "02:00:00:00:00:07");
	ck_assert_str_eq(vmac_addr_format(&all, buf, sizeof(buf)), "ff:ff:ff:ff:ff:ff");
	ck_assert_msg(vmac_addr_equal(&a, &b), "the same MAC on the same interface is one peer");
	ck_assert_msg(!vmac_addr_equal(&a, &c), "two MACs are two peers");
	ck_assert_msg(!vmac_addr_equal(&a, &d), "one MAC on two interfaces is two peers");

	memset(&ip, 0, sizeof(ip));
	sin->sin_family = AF_INET;
	sin->sin_port = htons(5870);
	sin->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
	ip.len = sizeof(*sin);
	ck_assert_str_eq(vmac_addr_format(&ip, buf, sizeof(buf)), "127.0.0.1:5870");
	ck_assert_msg(!vmac_addr_equal(&a, &ip), "a MAC and an IP address are two peers");
	ck_assert_msg(vmac_addr_equal(&ip, &ip), "an IP address is itself");
}
END_TEST

/* Receive into pkts[got..max) until want packets are there or timeout_ms
 * has passed; returns how many are there. */
static int recv_until(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int got, int want, int max,
                      int timeout_ms)
{
	int64_t deadline = vmac_now_ns() + (int64_t)timeout_ms * 1000000;
	while (got < want) {
		struct pollfd pfd = {.fd = fd, .events = POLLIN};
		int64_t left_ms = (deadline - vmac_now_ns()) / 1000000;
		int n;
		if (left_ms <= 0)
			break;
		poll(&pfd, 1, (int)left_ms);
		n = vmac_transport_recv(t, fd, pkts + got, max - got);
		if (n < 0)
			break;
		got += n;
	}
	return got;
}

START_TEST(udp_carries_a_frame_over_loopback)
{
	struct vmac_bus_spec spec;
	struct vmac_transport host, board;
	struct vmac_packet out, in[4];
	struct vmac_msg m;
	char err[256] = "";
	int n;

	ck_assert_int_eq(vmac_bus_spec_parse("239.255.86.77:5870", &spec), 0);
	spec.iface.s_addr = htonl(INADDR_LOOPBACK);
	ck_assert_msg(vmac_transport_open_host(&host, &spec, err, sizeof(err)) == 0, "host: %s", err);
	ck_assert_msg(vmac_transport_open_board(&board, &spec, err, sizeof(err)) == 0, "board: %s", err);
	ck_assert_int_eq(host.kind, VMAC_TRANSPORT_UDP);

	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 0);
	memset(&out, 0, sizeof(out));
	n = vmac_proto_encode(&m, out.data, sizeof(out.data));
	ck_assert_int_eq(n, VMAC_HDR_LEN);
	out.len = (size_t)n;
	out.addr = board.local;
	ck_assert_int_eq(vmac_transport_send(&host, &out, 1), 1);
	ck_assert_int_eq(recv_until(&board, board.fd, in, 0, 1, 4, 2000), 1);
	ck_assert_uint_eq(in[0].len, VMAC_HDR_LEN); /* UDP: nothing padded, nothing trimmed */
	ck_assert_msg(vmac_addr_equal(&in[0].addr, &host.local), "the sender is the host's socket");
	ck_assert_msg(in[0].rx_ns <= vmac_now_ns() && in[0].rx_ns > vmac_now_ns() - 1000000000, "rx_ns is not now");
	vmac_transport_close(&host);
	vmac_transport_close(&board);
}
END_TEST

START_TEST(ethernet_refuses_a_missing_interface_and_a_listener)
{
	struct vmac_bus_spec spec;
	struct vmac_transport t;
	char err[256] = "";

	ck_assert_int_eq(vmac_bus_spec_parse("eth:vmacnosuch0", &spec), 0);
	ck_assert_int_eq(vmac_transport_open_host(&t, &spec, err, sizeof(err)), -ENODEV);
	ck_assert_str_eq(err, "no network interface 'vmacnosuch0'");
	ck_assert_int_eq(t.fd, -1);
	ck_assert_int_eq(vmac_transport_listen(&spec, err, sizeof(err)), -EOPNOTSUPP);
	ck_assert_msg(strstr(err, "eth:vmacnosuch0") != NULL, "the listener's refusal names the bus: %s", err);
}
END_TEST

/* ---- CAP_NET_RAW: dropped in a child, which reports what open said. */

static int drop_cap_net_raw(void)
{
	struct __user_cap_header_struct hdr = {.version = _LINUX_CAPABILITY_VERSION_3, .pid = 0};
	struct __user_cap_data_struct data[_LINUX_CAPABILITY_U32S_3];
	if (syscall(SYS_capget, &hdr, data) != 0)
		return -errno;
	data[CAP_TO_INDEX(CAP_NET_RAW)].effective &= ~CAP_TO_MASK(CAP_NET_RAW);
	data[CAP_TO_INDEX(CAP_NET_RAW)].permitted &= ~CAP_TO_MASK(CAP_NET_RAW);
	data[CAP_TO_INDEX(CAP_NET_RAW)].inheritable &= ~CAP_TO_MASK(CAP_NET_RAW);
	return syscall(SYS_capset, &hdr, data) != 0 ? -errno : 0;
}

START_TEST(ethernet_without_cap_net_raw_says_so_in_one_line)
{
	char text[512] = "";
	int pipefd[2], status, rc = 0;
	ssize_t got;
	pid_t pid;

	ck_assert_int_eq(pipe(pipefd), 0);
	pid = fork();
	ck_assert_int_ge(pid, 0);
	if (pid == 0) {
		struct vmac_bus_spec spec;
		struct vmac_transport t;
		char err[400] = "", line[512];
		int r = drop_cap_net_raw();
		if (r == 0) {
			vmac_bus_spec_parse("eth:lo", &spec);
			r = vmac_transport_open_host(&t, &spec, err, sizeof(err));
			snprintf(line, sizeof(line), "%d %s", r, err);
		} else
			snprintf(line, sizeof(line), "capset %d", r);
		if (write(pipefd[1], line, strlen(line)) < 0)
			_exit(2);
		_exit(0);
	}
	close(pipefd[1]);
	got = read(pipefd[0], text, sizeof(text) - 1);
	close(pipefd[0]);
	waitpid(pid, &status, 0);
	ck_assert_msg(got > 0, "the child said nothing");
	text[got] = '\0';
	ck_assert_msg(sscanf(text, "%d", &rc) == 1, "dropping CAP_NET_RAW failed: %s", text);
	ck_assert_msg(rc == -EPERM || rc == -EACCES, "open without CAP_NET_RAW gave %s", text);
	ck_assert_msg(strstr(text, "raw Ethernet (eth:lo) needs CAP_NET_RAW: run as root, or give the program the "
	                           "capability with 'setcap cap_net_raw+ep PROGRAM'") != NULL,
	              "the message does not say what to do: %s", text);
	ck_assert_msg(strchr(text, '\n') == NULL, "the message is more than one line: %s", text);
}
END_TEST

/* ---- The veth round trip, in a child in a network namespace of its own.
 * The child reports one line on a pipe: "OK", "SKIP reason" or "FAIL ...". */

static int report_fd = -1;

__attribute__((format(printf, 2, 3), noreturn)) static void child_report(const char *kind, const char *fmt, ...)
{
	char line[600];
	int n = snprintf(line, sizeof(line), "%s ", kind);
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(line + n, sizeof(line) - (size_t)n, fmt, ap);
	va_end(ap);
	if (write(report_fd, line, strlen(line)) < 0)
		_exit(3);
	_exit(strcmp(kind, "OK") == 0 ? 0 : 1);
}

#define EXPECT(cond, ...)                                                                                              \
	do {                                                                                                           \
		if (!(cond))                                                                                           \
			child_report("FAIL", "line " VMAC_STR(__LINE__) ": " __VA_ARGS__);                             \
	} while (0)
#define VMAC_STR(x) VMAC_STR2(x)
#define VMAC_STR2(x) #x

static int wait_running(const char *ifname)
{
	struct ifreq ifr;
	int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0), i, ok = 0;
	memset(&ifr, 0, sizeof(ifr));
	snprintf(ifr.ifr_name, sizeof(ifr.ifr_name), "%s", ifname);
	for (i = 0; i < 200 && !ok; i++) {
		ok = ioctl(fd, SIOCGIFFLAGS, &ifr) == 0 && (ifr.ifr_flags & IFF_RUNNING);
		if (!ok)
			usleep(10000);
	}
	close(fd);
	return ok;
}

/* Send one raw frame of any EtherType on ifname (tag: an 802.1Q VLAN tag
 * before it, when nonzero), to see that the transport does not return it. */
static void send_foreign(const char *ifname, const uint8_t dst[6], const uint8_t src[6], uint16_t vlan_tci,
                         uint16_t ethertype, const uint8_t *payload, size_t len)
{
	uint8_t frame[128];
	size_t at = 12;
	struct sockaddr_ll sll;
	int fd = socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, 0);
	EXPECT(fd >= 0, "raw socket for a foreign frame: %s", strerror(errno));
	memset(frame, 0, sizeof(frame));
	memcpy(frame, dst, 6);
	memcpy(frame + 6, src, 6);
	if (vlan_tci) {
		frame[at++] = 0x81;
		frame[at++] = 0x00;
		frame[at++] = (uint8_t)(vlan_tci >> 8);
		frame[at++] = (uint8_t)vlan_tci;
	}
	frame[at++] = (uint8_t)(ethertype >> 8);
	frame[at++] = (uint8_t)ethertype;
	memcpy(frame + at, payload, len);
	at += len < 46 ? 46 : len;
	memset(&sll, 0, sizeof(sll));
	sll.sll_family = AF_PACKET;
	sll.sll_ifindex = (int)if_nametoindex(ifname);
	EXPECT(sendto(fd, frame, at, 0, (struct sockaddr *)&sll, sizeof(sll)) == (ssize_t)at,
	       "sending a foreign frame: %s", strerror(errno));
	close(fd);
}

/* A socket that sees every frame arriving on ifname, as it was on the wire. */
static int open_sniffer(const char *ifname)
{
	struct sockaddr_ll sll;
	int fd = socket(AF_PACKET, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, htons(ETH_P_ALL));
	EXPECT(fd >= 0, "sniffer socket: %s", strerror(errno));
	memset(&sll, 0, sizeof(sll));
	sll.sll_family = AF_PACKET;
	sll.sll_protocol = htons(ETH_P_ALL);
	sll.sll_ifindex = (int)if_nametoindex(ifname);
	EXPECT(bind(fd, (struct sockaddr *)&sll, sizeof(sll)) == 0, "sniffer bind: %s", strerror(errno));
	return fd;
}

/* The length on the wire of the first vmac frame the sniffer saw (header
 * included), after checking that its padding is zeros; 0 when none. */
static size_t sniffed_vmac_frame(int fd, size_t vmac_len)
{
	uint8_t frame[2048];
	ssize_t n;
	while ((n = recv(fd, frame, sizeof(frame), MSG_DONTWAIT)) >= 0) {
		size_t i;
		if (n < ETH_HLEN || frame[12] != (VMAC_ETHERTYPE >> 8) || frame[13] != (VMAC_ETHERTYPE & 0xff))
			continue;
		for (i = ETH_HLEN + vmac_len; i < (size_t)n; i++)
			EXPECT(frame[i] == 0, "padding byte %zu is 0x%02x, not zero", i, frame[i]);
		return (size_t)n;
	}
	return 0;
}

static size_t encode(struct vmac_msg *m, struct vmac_packet *p)
{
	int n = vmac_proto_encode(m, p->data, sizeof(p->data));
	EXPECT(n > 0, "encoding a test frame: %d", n);
	p->len = (size_t)n;
	return (size_t)n;
}

static void expect_fresh(const struct vmac_packet *p, const char *what)
{
	int64_t now = vmac_now_ns();
	EXPECT(p->rx_ns <= now && p->rx_ns > now - 1000000000, "%s: rx_ns %lld is not within a second of now %lld",
	       what, (long long)p->rx_ns, (long long)now);
}

#define BATCH_TEST 100 /* more than one sendmmsg/recvmmsg batch */
#define BURST 500      /* replies in one burst: many receive calls' worth */
#define BURST_CHUNKS 5 /* sends of the burst, with frames to skip between them */

/* A burst of BURST replies from the board to the host, sent in chunks with
 * frames the host must skip between them (another EtherType, a VLAN tag,
 * the host's own broadcast), all in the host's receive queue before it
 * reads: they come out in order, each with its kernel stamp, 64 per call
 * (what does not fit in one call waits for the next), and then nothing. */
static void burst_in_order(struct vmac_transport *host, struct vmac_transport *board)
{
	static struct vmac_packet out[BURST], in[BURST + VMAC_TRANSPORT_BATCH];
	struct vmac_packet own;
	struct pollfd pfd = {.fd = host->fd, .events = POLLIN};
	struct vmac_msg m;
	struct vmac_addr expected = mac_addr(board_mac, host->ifindex);
	int64_t sent_ns, read_ns, deadline;
	size_t len = 0;
	int i, got = 0, calls = 0, first = -1;

	for (i = 0; i < BURST; i++) {
		m = reply(VMAC_CH_DEVICE, VMAC_OP_ERROR, 0x00070001, (uint16_t)(i + 1));
		m.u.error.code = VMAC_BERR_NOT_REGISTERED;
		m.u.error.op = VMAC_OP_UPDATE;
		memset(&out[i], 0, sizeof(out[i]));
		len = encode(&m, &out[i]);
		out[i].addr = mac_addr(host->mac, board->ifindex);
		memcpy(out[i].mac, board_mac, 6);
	}
	memset(&own, 0, sizeof(own));
	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 0);
	encode(&m, &own);
	own.addr = host->group;

	vmac_transport_clock_sync(host);
	sent_ns = vmac_now_ns();
	for (i = 0; i < BURST_CHUNKS; i++) {
		struct vmac_packet *chunk = &out[i * (BURST / BURST_CHUNKS)];
		EXPECT(vmac_transport_send(board, chunk, BURST / BURST_CHUNKS) == BURST / BURST_CHUNKS,
		       "sending chunk %d of the burst", i);
		send_foreign("vt1", host->mac, board_mac, 0, 0x88B6, chunk->data, len);
		send_foreign("vt1", host->mac, board_mac, 5, VMAC_ETHERTYPE, chunk->data, len);
		EXPECT(vmac_transport_send(host, &own, 1) == 1, "the host's own broadcast");
	}
	EXPECT(poll(&pfd, 1, 2000) == 1 && (pfd.revents & POLLIN), "no POLLIN for a burst of %d frames", BURST);
	usleep(100000); /* the whole burst is in before the first read */

	read_ns = vmac_now_ns();
	deadline = read_ns + 2000000000;
	while (got < BURST && vmac_now_ns() < deadline) {
		int n = vmac_transport_recv(host, host->fd, in + got, VMAC_TRANSPORT_BATCH);
		EXPECT(n >= 0 && n <= VMAC_TRANSPORT_BATCH, "receive call %d returned %d", calls, n);
		if (calls++ == 0) {
			first = n;
			pfd.revents = 0;
			EXPECT(poll(&pfd, 1, 0) == 1 && (pfd.revents & POLLIN),
			       "no POLLIN while %d frames of the burst still wait", BURST - n);
		}
		got += n;
		if (n == 0)
			usleep(1000);
	}
	EXPECT(got == BURST, "the host received %d of a burst of %d in %d calls", got, BURST, calls);
	EXPECT(first == VMAC_TRANSPORT_BATCH, "the first call of 64 took %d frames with %d waiting", first, BURST);
	EXPECT(calls >= (BURST + VMAC_TRANSPORT_BATCH - 1) / VMAC_TRANSPORT_BATCH, "%d frames in %d calls of 64", got,
	       calls);
	for (i = 0; i < got; i++) {
		struct vmac_msg r;
		char a[32];
		EXPECT(vmac_proto_decode(in[i].data, in[i].len, &r) == 0 && r.seq == i + 1,
		       "frame %d of the burst is out of order, damaged or foreign (%zu bytes)", i, in[i].len);
		EXPECT(in[i].len == len, "frame %d of the burst: padding not trimmed (%zu bytes)", i, in[i].len);
		EXPECT(vmac_addr_equal(&in[i].addr, &expected), "frame %d of the burst from %s", i,
		       vmac_addr_format(&in[i].addr, a, sizeof(a)));
		EXPECT(memcmp(in[i].mac, host->mac, 6) == 0, "frame %d of the burst: destination MAC", i);
		/* The kernel's stamp: before the reads began, 100 ms after
		 * the burst was in. */
		EXPECT(in[i].rx_ns >= sent_ns - 1000000 && in[i].rx_ns < read_ns,
		       "frame %d of the burst stamped %lld ns, not between the send (%lld) and the first read (%lld)",
		       i, (long long)in[i].rx_ns, (long long)sent_ns, (long long)read_ns);
		EXPECT(i == 0 || in[i].rx_ns >= in[i - 1].rx_ns, "frame %d of the burst stamped before frame %d", i,
		       i - 1);
	}
	EXPECT(vmac_transport_recv(host, host->fd, in, VMAC_TRANSPORT_BATCH) == 0, "something after the burst");
	pfd.revents = 0;
	EXPECT(poll(&pfd, 1, 0) == 0, "POLLIN (revents 0x%x) with nothing left to read", (unsigned)pfd.revents);
}

static void veth_round_trip(int recvmmsg)
{
	static struct vmac_packet out[BATCH_TEST], in[BATCH_TEST + 8];
	struct vmac_bus_spec host_spec, board_spec;
	struct vmac_transport host, board;
	struct vmac_msg m;
	struct vmac_addr expected;
	char err[256] = "", a[32], b[32];
	size_t discover_len, error_len, wire_len;
	int n, i, sniffer;

	if (recvmmsg)
		setenv("VMAC_ETH_RECVMMSG", "1", 1);
	if (unshare(CLONE_NEWNET) != 0)
		child_report("SKIP", "unshare(CLONE_NEWNET): %s", strerror(errno));
	if (system("ip link add vt0 type veth peer name vt1 && ip link set vt0 up && ip link set vt1 up") != 0)
		child_report("SKIP", "could not make a veth pair with 'ip link add vt0 type veth peer name vt1'");
	EXPECT(wait_running("vt0") && wait_running("vt1"), "the veth pair did not come up");

	EXPECT(vmac_bus_spec_parse("eth:vt0", &host_spec) == 0, "eth:vt0 refused");
	EXPECT(vmac_bus_spec_parse("eth:vt1", &board_spec) == 0, "eth:vt1 refused");
	EXPECT(vmac_transport_open_host(&host, &host_spec, err, sizeof(err)) == 0, "host on vt0: %s", err);
	EXPECT(vmac_transport_open_board(&board, &board_spec, err, sizeof(err)) == 0, "board on vt1: %s", err);
	EXPECT(host.kind == VMAC_TRANSPORT_ETH && host.ifindex == (int)if_nametoindex("vt0"), "host transport");
	EXPECT(memcmp(host.mac, board.mac, 6) != 0, "the two ends of the veth pair have one MAC");
	EXPECT((host.rx_ring != NULL) == !recvmmsg && (board.rx_ring != NULL) == !recvmmsg,
	       "receive rings: host %p, board %p, with VMAC_ETH_RECVMMSG %s", (void *)host.rx_ring,
	       (void *)board.rx_ring, recvmmsg ? "set" : "unset");
	expected = mac_addr(host.mac, host.ifindex);
	EXPECT(vmac_addr_equal(&host.local, &expected), "host.local is not the interface's MAC");
	EXPECT(strcmp(vmac_addr_format(&host.group, a, sizeof(a)), "ff:ff:ff:ff:ff:ff") == 0, "group is %s", a);
	EXPECT(vmac_transport_listen(&board_spec, err, sizeof(err)) == -EOPNOTSUPP, "listen on Ethernet");

	/* Frames the host must not see: another EtherType, and a vmac
	 * payload behind a VLAN tag, both to the host's MAC. */
	m = reply(VMAC_CH_DEVICE, VMAC_OP_ERROR, 0x00070001, 0);
	m.u.error.code = VMAC_BERR_NOT_REGISTERED;
	m.u.error.op = VMAC_OP_UPDATE;
	memset(&out[0], 0, sizeof(out[0]));
	error_len = encode(&m, &out[0]);
	send_foreign("vt1", host.mac, board_mac, 0, 0x88B6, out[0].data, error_len);
	send_foreign("vt1", host.mac, board_mac, 5, VMAC_ETHERTYPE, out[0].data, error_len);

	/* Board -> host, unicast from the board's own locally administered
	 * MAC: 15 bytes, padded to 46 on the wire, trimmed back on arrival. */
	out[0].addr = mac_addr(host.mac, board.ifindex);
	memcpy(out[0].mac, board_mac, 6);
	sniffer = open_sniffer("vt0");
	EXPECT(vmac_transport_send(&board, out, 1) == 1, "board send");
	n = recv_until(&host, host.fd, in, 0, 1, BATCH_TEST, 2000);
	usleep(100000); /* anything else on its way arrives too */
	wire_len = sniffed_vmac_frame(sniffer, error_len);
	EXPECT(wire_len == ETH_ZLEN, "the frame was %zu bytes on the wire, not padded to %d", wire_len, ETH_ZLEN);
	close(sniffer);
	n += vmac_transport_recv(&host, host.fd, in + n, BATCH_TEST - n);
	EXPECT(n == 1, "the host received %d frames, not the one vmac frame (a foreign frame came through?)", n);
	EXPECT(in[0].len == error_len, "padding not trimmed: %zu bytes, not %zu", in[0].len, error_len);
	EXPECT(memcmp(in[0].data, out[0].data, error_len) == 0, "the frame's bytes changed");
	expected = mac_addr(board_mac, host.ifindex);
	EXPECT(vmac_addr_equal(&in[0].addr, &expected), "sender %s, not 02:00:00:00:00:07",
	       vmac_addr_format(&in[0].addr, a, sizeof(a)));
	EXPECT(in[0].addr.len == sizeof(struct sockaddr_ll), "sender address length %u", (unsigned)in[0].addr.len);
	EXPECT(memcmp(in[0].mac, host.mac, 6) == 0, "destination MAC is not the host's");
	expect_fresh(&in[0], "board -> host");
	EXPECT(vmac_transport_recv(&board, board.fd, in, 4) == 0, "the board got its own frame back");

	/* Host -> every board, broadcast from the interface's MAC: a
	 * DISCOVER, 13 bytes. */
	m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, 0);
	memset(&out[0], 0, sizeof(out[0]));
	discover_len = encode(&m, &out[0]);
	EXPECT(discover_len == VMAC_HDR_LEN, "a DISCOVER is %zu bytes", discover_len);
	out[0].addr = host.group;
	send_foreign("vt0", broadcast_mac, host.mac, 5, VMAC_ETHERTYPE, out[0].data, discover_len);
	EXPECT(vmac_transport_send(&host, out, 1) == 1, "host send");
	n = recv_until(&board, board.fd, in, 0, 1, 4, 2000);
	usleep(100000);
	n += vmac_transport_recv(&board, board.fd, in + n, 4 - n);
	EXPECT(n == 1, "the board received %d frames, not the DISCOVER alone (the VLAN-tagged one came through?)", n);
	EXPECT(in[0].len == discover_len, "padding not trimmed: %zu bytes", in[0].len);
	EXPECT(vmac_addr_equal(&in[0].addr, &board.local) == 0, "the board sees itself as the sender");
	EXPECT(strcmp(vmac_addr_format(&in[0].addr, a, sizeof(a)), vmac_addr_format(&host.local, b, sizeof(b))) == 0,
	       "sender %s, not the host's %s", a, b);
	EXPECT(memcmp(in[0].mac, broadcast_mac, 6) == 0, "destination MAC is not the broadcast");
	expect_fresh(&in[0], "host -> board");
	EXPECT(vmac_transport_recv(&host, host.fd, in, 4) == 0, "the host got its own broadcast back");

	/* Host -> the board's own MAC (promiscuous), with a payload that is
	 * no vmac frame: padded, and handed on at the full 46 bytes for the
	 * decoder to refuse; and one above the minimum, left as it is. */
	memset(&out[0], 0, sizeof(out[0]));
	memcpy(out[0].data, "not vmac", 8);
	out[0].len = 8;
	out[0].addr = mac_addr(board_mac, host.ifindex);
	memset(&out[1], 0, sizeof(out[1]));
	memset(out[1].data, 0xA5, 200);
	out[1].len = 200;
	out[1].addr = out[0].addr;
	EXPECT(vmac_transport_send(&host, out, 2) == 2, "host send of two");
	n = recv_until(&board, board.fd, in, 0, 2, 4, 2000);
	EXPECT(n == 2, "the board received %d frames of 2", n);
	EXPECT(in[0].len == 46, "garbage trimmed to %zu bytes: it must reach the decoder as it came", in[0].len);
	EXPECT(memcmp(in[0].data, "not vmac", 8) == 0 && in[0].data[8] == 0 && in[0].data[45] == 0, "garbage bytes");
	EXPECT(in[1].len == 200 && in[1].data[199] == 0xA5, "a 200-byte payload came as %zu bytes", in[1].len);
	EXPECT(memcmp(in[0].mac, board_mac, 6) == 0, "destination MAC is not the board's own");

	/* A batch larger than one sendmmsg and one recvmmsg. */
	for (i = 0; i < BATCH_TEST; i++) {
		m = request(VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0, (uint16_t)(i + 1));
		memset(&out[i], 0, sizeof(out[i]));
		encode(&m, &out[i]);
		out[i].addr = host.group;
	}
	EXPECT(vmac_transport_send(&host, out, BATCH_TEST) == BATCH_TEST, "a batch of %d", BATCH_TEST);
	n = recv_until(&board, board.fd, in, 0, BATCH_TEST, BATCH_TEST + 8, 2000);
	EXPECT(n == BATCH_TEST, "the board received %d of %d", n, BATCH_TEST);
	for (i = 0; i < n; i++) {
		struct vmac_msg got;
		EXPECT(vmac_proto_decode(in[i].data, in[i].len, &got) == 0 && got.seq == i + 1,
		       "frame %d of the batch out of order or damaged", i);
	}

	burst_in_order(&host, &board);

	/* A destination that is no MAC is refused, not sent somewhere. */
	out[0].addr = host.local;
	((struct sockaddr_ll *)&out[0].addr.ss)->sll_family = AF_INET;
	EXPECT(vmac_transport_send(&host, out, 1) == -EINVAL, "an IP destination on Ethernet");

	vmac_transport_close(&host);
	vmac_transport_close(&board);
	EXPECT(host.rx_ring == NULL && host.fd == -1, "the host's transport not closed");
	child_report("OK", "%s", "");
}

/* What a veth round trip needs, for vmac_test_cannot_run. */
#define VETH_NEEDS "raw Ethernet round trip over veth (needs root and network namespaces)"

/* The veth round trip in a child; recvmmsg: without the receive ring. */
static void run_veth_round_trip(int recvmmsg)
{
	char text[700] = "";
	int pipefd[2], status;
	ssize_t got, total = 0;
	pid_t pid;

	if (geteuid() != 0) {
		vmac_test_cannot_run(VETH_NEEDS, "not root");
		return;
	}
	ck_assert_int_eq(pipe(pipefd), 0);
	pid = fork();
	ck_assert_int_ge(pid, 0);
	if (pid == 0) {
		close(pipefd[0]);
		report_fd = pipefd[1];
		veth_round_trip(recvmmsg);
		_exit(4);
	}
	close(pipefd[1]);
	while ((got = read(pipefd[0], text + total, sizeof(text) - 1 - (size_t)total)) > 0)
		total += got;
	close(pipefd[0]);
	ck_assert_int_eq(waitpid(pid, &status, 0), pid);
	text[total] = '\0';
	if (strncmp(text, "SKIP ", 5) == 0) {
		vmac_test_cannot_run(VETH_NEEDS, text + 5);
		return;
	}
	ck_assert_msg(strncmp(text, "OK", 2) == 0 && WIFEXITED(status) && WEXITSTATUS(status) == 0,
	              "the veth round trip%s: %s (exit status %d)", recvmmsg ? " with recvmmsg" : "",
	              total ? text : "(the child said nothing)", status);
}

START_TEST(ethernet_round_trip_over_veth)
{
	run_veth_round_trip(0);
}
END_TEST

START_TEST(ethernet_round_trip_over_veth_with_recvmmsg)
{
	run_veth_round_trip(1);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("transport");
	TCase *tc = tcase_create("transport");
	tcase_add_test(tc, bus_specs_parse_to_their_transport);
	tcase_add_test(tc, ethernet_addresses_compare_and_print_as_macs);
	tcase_add_test(tc, udp_carries_a_frame_over_loopback);
	tcase_add_test(tc, ethernet_refuses_a_missing_interface_and_a_listener);
	tcase_add_test(tc, ethernet_without_cap_net_raw_says_so_in_one_line);
	tcase_add_test(tc, ethernet_round_trip_over_veth);
	tcase_add_test(tc, ethernet_round_trip_over_veth_with_recvmmsg);
	tcase_set_timeout(tc, 30);
	suite_add_tcase(s, tc);
	return s;
}
