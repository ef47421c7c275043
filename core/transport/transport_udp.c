/* UDP transport: discovery by multicast to GROUP:PORT, cyclic traffic by
 * unicast. Works on loopback (IP_MULTICAST_IF 127.0.0.1) and on a LAN with
 * the interface chosen. Receive times come from the kernel (SO_TIMESTAMPNS).
 * Reached through transport.c, which also holds the clocks and addresses. */
#include "transport.h"

#include <arpa/inet.h>
#include <errno.h>
#include <string.h>
#include <unistd.h>

#include "../common/addr.h"

#define BATCH_MAX VMAC_TRANSPORT_BATCH

int vmac_udp_bus_spec_parse(const char *text, struct vmac_bus_spec *spec)
{
	struct in_addr group;
	uint16_t port;
	if (vmac_addr_parse(text, &group, &port) != 0 || port == 0 || !IN_MULTICAST(ntohl(group.s_addr)))
		return -EINVAL;
	spec->kind = VMAC_TRANSPORT_UDP;
	spec->group = group;
	spec->port = port;
	memset(spec->ifname, 0, sizeof(spec->ifname));
	return 0;
}

static void set_addr(struct vmac_addr *a, struct in_addr ip, uint16_t port)
{
	struct sockaddr_in *sin = (struct sockaddr_in *)&a->ss;
	memset(a, 0, sizeof(*a));
	sin->sin_family = AF_INET;
	sin->sin_addr = ip;
	sin->sin_port = htons(port);
	a->len = sizeof(*sin);
}

static int open_unicast(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	int on = 1, ttl = 1, rcvbuf = 4 << 20;
	unsigned char loop = 1;
	int fd = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);

	memset(t, 0, sizeof(*t));
	t->kind = VMAC_TRANSPORT_UDP;
	t->fd = -1;
	if (fd < 0)
		return vmac_transport_fail(err, errlen, "socket");
	set_addr(&t->local, spec->iface, 0);
	if (bind(fd, (struct sockaddr *)&t->local.ss, t->local.len) < 0) {
		int r = vmac_transport_fail(err, errlen, "bind to interface address");
		close(fd);
		return r;
	}
	t->local.len = sizeof(t->local.ss);
	getsockname(fd, (struct sockaddr *)&t->local.ss, &t->local.len);
	/* A larger receive buffer rides out a burst (many replies in one slot, or
	 * a flood of junk) without losing the replies we wait for. */
	setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
	setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
	if (setsockopt(fd, IPPROTO_IP, IP_MULTICAST_IF, &spec->iface, sizeof(spec->iface)) < 0 ||
	    setsockopt(fd, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, sizeof(ttl)) < 0 ||
	    setsockopt(fd, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof(loop)) < 0) {
		int r = vmac_transport_fail(err, errlen, "multicast options");
		close(fd);
		return r;
	}
	set_addr(&t->group, spec->group, spec->port);
	t->fd = fd;
	vmac_transport_clock_sync(t);
	return 0;
}

int vmac_udp_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	return open_unicast(t, spec, err, errlen);
}

int vmac_udp_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	return open_unicast(t, spec, err, errlen);
}

int vmac_udp_listen(const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	struct ip_mreq mreq;
	struct vmac_addr a;
	int on = 1;
	int fd = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);

	if (fd < 0)
		return vmac_transport_fail(err, errlen, "socket");
	setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &on, sizeof(on));
	setsockopt(fd, SOL_SOCKET, SO_REUSEPORT, &on, sizeof(on));
	setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
	/* Bound to the group address, so only this group's traffic arrives. */
	set_addr(&a, spec->group, spec->port);
	if (bind(fd, (struct sockaddr *)&a.ss, a.len) < 0) {
		int r = vmac_transport_fail(err, errlen, "bind to discovery group");
		close(fd);
		return r;
	}
	mreq.imr_multiaddr = spec->group;
	mreq.imr_interface = spec->iface;
	if (setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof(mreq)) < 0) {
		int r = vmac_transport_fail(err, errlen, "join discovery group");
		close(fd);
		return r;
	}
	return fd;
}

int vmac_udp_send(struct vmac_transport *t, struct vmac_packet *pkts, int n)
{
	struct mmsghdr msgs[BATCH_MAX];
	struct iovec iov[BATCH_MAX];
	uint8_t ctrl[BATCH_MAX][VMAC_TRANSPORT_TX_CMSG_SPACE];
	int sent = 0;

	while (sent < n) {
		int i, chunk = n - sent > BATCH_MAX ? BATCH_MAX : n - sent, r;
		for (i = 0; i < chunk; i++) {
			struct vmac_packet *p = &pkts[sent + i];
			iov[i].iov_base = p->data;
			iov[i].iov_len = p->len;
			memset(&msgs[i], 0, sizeof(msgs[i]));
			msgs[i].msg_hdr.msg_name = &p->addr.ss;
			msgs[i].msg_hdr.msg_namelen = p->addr.len;
			msgs[i].msg_hdr.msg_iov = &iov[i];
			msgs[i].msg_hdr.msg_iovlen = 1;
			vmac_transport_tx_ask(t, p, &msgs[i].msg_hdr, ctrl[i]);
		}
		r = sendmmsg(t->fd, msgs, (unsigned)chunk, MSG_DONTWAIT);
		if (r < 0) {
			int e = errno;
			if (e == EINTR)
				continue;
			vmac_transport_tx_sent(t, pkts + sent, 1, 0);
			if (sent > 0)
				return sent;
			/* A datagram the kernel refused (e.g. ECONNREFUSED left over
			 * from an ICMP) is skipped, not retried forever. */
			if (e == ECONNREFUSED || e == EHOSTUNREACH || e == ENETUNREACH) {
				sent++;
				continue;
			}
			return -e;
		}
		vmac_transport_tx_sent(t, pkts + sent, r < chunk ? r + 1 : r, r);
		sent += r;
		if (r < chunk && r == 0)
			break;
	}
	return sent;
}

int vmac_udp_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max)
{
	struct mmsghdr msgs[BATCH_MAX];
	struct iovec iov[BATCH_MAX];
	char ctrl[BATCH_MAX][VMAC_TRANSPORT_CMSG_SPACE];
	int i, r, n = max > BATCH_MAX ? BATCH_MAX : max;
	int64_t now = vmac_now_ns();

	for (i = 0; i < n; i++) {
		iov[i].iov_base = pkts[i].data;
		iov[i].iov_len = sizeof(pkts[i].data);
		memset(&msgs[i], 0, sizeof(msgs[i]));
		msgs[i].msg_hdr.msg_name = &pkts[i].addr.ss;
		msgs[i].msg_hdr.msg_namelen = sizeof(pkts[i].addr.ss);
		msgs[i].msg_hdr.msg_iov = &iov[i];
		msgs[i].msg_hdr.msg_iovlen = 1;
		msgs[i].msg_hdr.msg_control = ctrl[i];
		msgs[i].msg_hdr.msg_controllen = sizeof(ctrl[i]);
	}
	do {
		r = recvmmsg(fd, msgs, (unsigned)n, MSG_DONTWAIT, NULL);
	} while (r < 0 && errno == EINTR);
	if (r < 0)
		return (errno == EAGAIN || errno == EWOULDBLOCK || errno == ECONNREFUSED) ? 0 : -errno;
	for (i = 0; i < r; i++) {
		struct vmac_packet *p = &pkts[i];
		p->len = msgs[i].msg_len;
		if (msgs[i].msg_hdr.msg_flags & MSG_TRUNC)
			p->len = sizeof(p->data); /* oversize: decoder rejects it */
		p->addr.len = msgs[i].msg_hdr.msg_namelen;
		memset(p->mac, 0, sizeof(p->mac));
		p->rx_ns = vmac_transport_rx_stamp(t, &msgs[i].msg_hdr, now);
	}
	return r;
}
