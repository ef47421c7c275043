/* The transport interface's front: picks UDP (transport_udp.c) or raw
 * Ethernet (transport_eth.c) by kind, and holds what both share: the bus
 * spec's "eth:" form, the clocks and the kernel-stamp conversion, and peer
 * addresses (sockaddr_in or sockaddr_ll) compared and printed. */
#include "transport.h"

#include <arpa/inet.h>
#include <errno.h>
#include <linux/if_packet.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#define ETH_PREFIX "eth:"

int64_t vmac_now_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int64_t realtime_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

void vmac_transport_clock_sync(struct vmac_transport *t)
{
	t->rt_minus_mono_ns = realtime_ns() - vmac_now_ns();
}

int64_t vmac_transport_rx_stamp(const struct vmac_transport *t, struct msghdr *h, int64_t now_ns)
{
	struct cmsghdr *c;
	int64_t stamp = now_ns;
	for (c = CMSG_FIRSTHDR(h); c; c = CMSG_NXTHDR(h, c)) {
		if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPNS) {
			struct timespec ts;
			int64_t mono;
			memcpy(&ts, CMSG_DATA(c), sizeof(ts));
			mono = (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec - t->rt_minus_mono_ns;
			/* Guard against a realtime step: never later than now. */
			if (mono <= now_ns)
				stamp = mono;
		}
	}
	return stamp;
}

int vmac_transport_fail(char *err, size_t errlen, const char *what)
{
	int e = errno ? errno : EINVAL;
	snprintf(err, errlen, "%s: %s", what, strerror(e));
	return -e;
}

int vmac_bus_spec_parse(const char *text, struct vmac_bus_spec *spec)
{
	size_t n;
	if (strncmp(text, ETH_PREFIX, strlen(ETH_PREFIX)) != 0)
		return vmac_udp_bus_spec_parse(text, spec);
	text += strlen(ETH_PREFIX);
	n = strlen(text);
	/* An interface name is 1..IF_NAMESIZE-1 bytes with no '/' or space
	 * (the kernel's own rule, dev_valid_name). */
	if (n == 0 || n >= IF_NAMESIZE || strchr(text, '/') || strpbrk(text, " \t\n:") || !strcmp(text, ".") ||
	    !strcmp(text, ".."))
		return -EINVAL;
	spec->kind = VMAC_TRANSPORT_ETH;
	memset(&spec->group, 0, sizeof(spec->group));
	spec->port = 0;
	memcpy(spec->ifname, text, n + 1);
	return 0;
}

int vmac_transport_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	if (spec->kind == VMAC_TRANSPORT_ETH)
		return vmac_eth_open_host(t, spec, err, errlen);
	return vmac_udp_open_host(t, spec, err, errlen);
}

int vmac_transport_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	if (spec->kind == VMAC_TRANSPORT_ETH)
		return vmac_eth_open_board(t, spec, err, errlen);
	return vmac_udp_open_board(t, spec, err, errlen);
}

int vmac_transport_listen(const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	if (spec->kind == VMAC_TRANSPORT_ETH) {
		snprintf(err, errlen,
		         "raw Ethernet (eth:%s) has no separate discovery listener: a board's own socket receives "
		         "broadcasts and unicasts alike",
		         spec->ifname);
		return -EOPNOTSUPP;
	}
	return vmac_udp_listen(spec, err, errlen);
}

void vmac_transport_close(struct vmac_transport *t)
{
	if (t->kind == VMAC_TRANSPORT_ETH)
		vmac_eth_close(t);
	if (t->fd >= 0)
		close(t->fd);
	t->fd = -1;
}

int vmac_transport_send(struct vmac_transport *t, struct vmac_packet *pkts, int n)
{
	if (t->kind == VMAC_TRANSPORT_ETH)
		return vmac_eth_send(t, pkts, n);
	return vmac_udp_send(t, pkts, n);
}

int vmac_transport_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max)
{
	if (t->kind == VMAC_TRANSPORT_ETH)
		return vmac_eth_recv(t, fd, pkts, max);
	return vmac_udp_recv(t, fd, pkts, max);
}

int vmac_addr_equal(const struct vmac_addr *a, const struct vmac_addr *b)
{
	if (a->ss.ss_family != b->ss.ss_family)
		return 0;
	if (a->ss.ss_family == AF_PACKET) {
		const struct sockaddr_ll *x = (const struct sockaddr_ll *)&a->ss,
		                         *y = (const struct sockaddr_ll *)&b->ss;
		return x->sll_ifindex == y->sll_ifindex && memcmp(x->sll_addr, y->sll_addr, 6) == 0;
	}
	{
		const struct sockaddr_in *x = (const struct sockaddr_in *)&a->ss,
		                         *y = (const struct sockaddr_in *)&b->ss;
		return x->sin_port == y->sin_port && x->sin_addr.s_addr == y->sin_addr.s_addr;
	}
}

char *vmac_addr_format(const struct vmac_addr *a, char *buf, size_t len)
{
	if (a->ss.ss_family == AF_PACKET) {
		const unsigned char *m = ((const struct sockaddr_ll *)&a->ss)->sll_addr;
		snprintf(buf, len, "%02x:%02x:%02x:%02x:%02x:%02x", m[0], m[1], m[2], m[3], m[4], m[5]);
	} else {
		const struct sockaddr_in *sin = (const struct sockaddr_in *)&a->ss;
		char ip[INET_ADDRSTRLEN] = "?";
		inet_ntop(AF_INET, &sin->sin_addr, ip, sizeof(ip));
		snprintf(buf, len, "%s:%u", ip, (unsigned)ntohs(sin->sin_port));
	}
	return buf;
}
