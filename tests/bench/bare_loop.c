/* bare_loop: the baseline for `make bench`. The least a host can do for the
 * same exchange: discover and register the boards, then every period send
 * each one an UPDATE with one sendmmsg and collect the replies with
 * recvmmsg, with no drivers, no policy, no status. vmacd's CPU cost per
 * device per tick is reported as a ratio to this loop's.
 * usage: bare_loop --bus GROUP:PORT --boards N --period-us P --seconds S */
#include <arpa/inet.h>
#include <getopt.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include "../../core/transport/transport.h"

struct board {
	struct vmac_addr addr;
	struct vmac_announce ann;
	uint32_t id;
	int registered;
};

static int send_msg(struct vmac_transport *t, const struct vmac_addr *to, struct vmac_msg *m)
{
	struct vmac_packet p;
	int n = vmac_proto_encode(m, p.data, sizeof(p.data));
	if (n <= 0)
		return -1;
	p.len = (size_t)n;
	p.addr = *to;
	return vmac_transport_send(t, &p, 1);
}

static double cpu_seconds(void)
{
	struct rusage ru;
	getrusage(RUSAGE_SELF, &ru);
	return (double)ru.ru_utime.tv_sec + (double)ru.ru_stime.tv_sec +
	       ((double)ru.ru_utime.tv_usec + (double)ru.ru_stime.tv_usec) / 1e6;
}

int main(int argc, char **argv)
{
	static const struct option opts[] = {{"bus", required_argument, 0, 'b'},
	                                     {"boards", required_argument, 0, 'n'},
	                                     {"period-us", required_argument, 0, 'p'},
	                                     {"seconds", required_argument, 0, 's'},
	                                     {0, 0, 0, 0}};
	const char *bus = "239.255.86.77:5870";
	int want = 10, period_us = 1000, seconds = 10, opt, nb = 0, i;
	struct vmac_bus_spec spec;
	struct vmac_transport t;
	struct board *boards;
	struct vmac_packet *tx, rx[64];
	char err[160];
	uint16_t seq = 0;
	int64_t deadline;
	uint64_t ticks = 0, replies = 0, expirations;
	double cpu0;
	int tfd;
	struct itimerspec its;

	while ((opt = getopt_long(argc, argv, "", opts, NULL)) != -1) {
		switch (opt) {
		case 'b': bus = optarg; break;
		case 'n': want = atoi(optarg); break;
		case 'p': period_us = atoi(optarg); break;
		case 's': seconds = atoi(optarg); break;
		default: fprintf(stderr, "usage: bare_loop --bus G:P --boards N --period-us P --seconds S\n"); return 2;
		}
	}
	if (vmac_bus_spec_parse(bus, &spec) != 0 || want < 1 || period_us < 50 || seconds < 1) {
		fprintf(stderr, "bare_loop: bad arguments\n");
		return 2;
	}
	inet_pton(AF_INET, "127.0.0.1", &spec.iface);
	if (vmac_transport_open_host(&t, &spec, err, sizeof(err)) < 0) {
		fprintf(stderr, "bare_loop: %s\n", err);
		return 1;
	}
	boards = calloc((size_t)want, sizeof(*boards));
	tx = calloc((size_t)want, sizeof(*tx));

	/* Discovery and registration, until every board is ours (max 30 s). */
	deadline = vmac_now_ns() + 30000000000LL;
	while (nb < want || boards[want - 1].registered == 0) {
		struct vmac_msg m;
		struct pollfd pfd = {t.fd, POLLIN, 0};
		int n, k;
		if (vmac_now_ns() > deadline) {
			fprintf(stderr, "bare_loop: only %d of %d boards answered\n", nb, want);
			return 1;
		}
		memset(&m, 0, sizeof(m));
		m.channel = VMAC_CH_SYSTEM;
		m.op = VMAC_SYS_DISCOVER;
		m.seq = ++seq;
		send_msg(&t, &t.group, &m);
		while (poll(&pfd, 1, 200) > 0) {
			n = vmac_transport_recv(&t, t.fd, rx, 64);
			for (k = 0; k < n; k++) {
				struct vmac_msg r;
				if (vmac_proto_decode(rx[k].data, rx[k].len, &r) != 0)
					continue;
				if (r.channel == VMAC_CH_SYSTEM && r.op == VMAC_SYS_ANNOUNCE && nb < want) {
					struct board *b = &boards[nb];
					b->addr = rx[k].addr;
					b->ann = r.u.announce;
					b->id = (uint32_t)(nb + 1);
					memset(&m, 0, sizeof(m));
					m.channel = VMAC_CH_DEVICE;
					m.op = VMAC_OP_REGISTER;
					m.device_id = b->id;
					m.seq = ++seq;
					m.u.reg.major = b->ann.major;
					m.u.reg.minor = b->ann.minor;
					m.u.reg.watchdog_ms = 2000;
					send_msg(&t, &b->addr, &m);
					nb++;
				} else if (r.channel == VMAC_CH_DEVICE && r.op == VMAC_OP_REGISTER &&
				           r.device_id >= 1 && r.device_id <= (uint32_t)nb) {
					boards[r.device_id - 1].registered = 1;
				}
			}
		}
	}

	/* The measured loop: one UPDATE to every board per period. */
	tfd = timerfd_create(CLOCK_MONOTONIC, 0);
	memset(&its, 0, sizeof(its));
	its.it_interval.tv_nsec = (long)period_us * 1000;
	its.it_value.tv_nsec = (long)period_us * 1000;
	timerfd_settime(tfd, 0, &its, NULL);
	cpu0 = cpu_seconds();
	deadline = vmac_now_ns() + (int64_t)seconds * 1000000000;
	while (vmac_now_ns() < deadline) {
		if (read(tfd, &expirations, sizeof(expirations)) != sizeof(expirations))
			continue;
		for (i = 0; i < want; i++) {
			struct vmac_msg m;
			int n;
			memset(&m, 0, sizeof(m));
			m.channel = VMAC_CH_DEVICE;
			m.op = VMAC_OP_UPDATE;
			m.device_id = boards[i].id;
			m.seq = ++seq;
			n = vmac_proto_encode(&m, tx[i].data, sizeof(tx[i].data));
			tx[i].len = (size_t)n;
			tx[i].addr = boards[i].addr;
		}
		vmac_transport_send(&t, tx, want);
		for (;;) {
			int n = vmac_transport_recv(&t, t.fd, rx, 64), k;
			struct vmac_msg r;
			for (k = 0; k < n; k++)
				if (vmac_proto_decode(rx[k].data, rx[k].len, &r) == 0)
					replies++;
			if (n < 64)
				break;
		}
		ticks++;
	}
	printf("{\"boards\": %d, \"ticks\": %llu, \"replies\": %llu, \"cpu_s\": %.6f}\n", want,
	       (unsigned long long)ticks, (unsigned long long)replies, cpu_seconds() - cpu0);
	return 0;
}
