/* Raw-Ethernet transport: vmac frames as the payload of Ethernet frames of
 * EtherType 0x88B5 (AF_PACKET), discovery and cyclic frames broadcast, the
 * rest unicast MAC to MAC. Pads short payloads to the 46-byte minimum and
 * trims them back by the length the vmac header declares. Needs
 * CAP_NET_RAW. Reached through transport.c. */
#include "transport.h"

#include <arpa/inet.h>
#include <errno.h>
#include <linux/if_arp.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <unistd.h>

#define BATCH_MAX VMAC_TRANSPORT_BATCH
#define ETH_PAYLOAD_MIN (ETH_ZLEN - ETH_HLEN) /* 46 */
/* recvmmsg calls one vmac_eth_recv makes at most, so a flood of frames it
 * skips (other EtherTypes, our own sends) cannot hold it for long. */
#define RECV_ROUNDS_MAX 4

static const uint8_t zero_padding[ETH_PAYLOAD_MIN];

static void set_ll(struct vmac_addr *a, int ifindex, const uint8_t mac[6])
{
	struct sockaddr_ll *sll = (struct sockaddr_ll *)&a->ss;
	memset(a, 0, sizeof(*a));
	sll->sll_family = AF_PACKET;
	sll->sll_protocol = htons(VMAC_ETHERTYPE);
	sll->sll_ifindex = ifindex;
	sll->sll_halen = 6;
	memcpy(sll->sll_addr, mac, 6);
	a->len = sizeof(*sll);
}

static int close_fail(int fd, char *err, size_t errlen, const char *what)
{
	int r = vmac_transport_fail(err, errlen, what);
	close(fd);
	return r;
}

/* The one socket of either side, bound to spec->ifname; promisc for a board
 * process, whose boards each answer to a locally administered MAC. */
static int open_eth(struct vmac_transport *t, const struct vmac_bus_spec *spec, int promisc, char *err, size_t errlen)
{
	static const uint8_t broadcast[6] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff};
	struct sockaddr_ll sll;
	struct ifreq ifr;
	int on = 1, rcvbuf = 4 << 20, fd;
	unsigned ifindex;

	memset(t, 0, sizeof(*t));
	t->kind = VMAC_TRANSPORT_ETH;
	t->fd = -1;
	ifindex = if_nametoindex(spec->ifname);
	if (ifindex == 0) {
		snprintf(err, errlen, "no network interface '%s'", spec->ifname);
		return -ENODEV;
	}
	fd = socket(AF_PACKET, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, htons(VMAC_ETHERTYPE));
	if (fd < 0) {
		int e = errno;
		if (e == EPERM || e == EACCES) {
			snprintf(err, errlen,
			         "raw Ethernet (eth:%s) needs CAP_NET_RAW: run as root, or give the program the "
			         "capability with 'setcap cap_net_raw+ep PROGRAM'",
			         spec->ifname);
			return -e;
		}
		return vmac_transport_fail(err, errlen, "raw Ethernet socket");
	}

	memset(&ifr, 0, sizeof(ifr));
	memcpy(ifr.ifr_name, spec->ifname, strnlen(spec->ifname, IF_NAMESIZE - 1));
	if (ioctl(fd, SIOCGIFHWADDR, &ifr) < 0)
		return close_fail(fd, err, errlen, "reading the interface's MAC address");
	if (ifr.ifr_hwaddr.sa_family != ARPHRD_ETHER && ifr.ifr_hwaddr.sa_family != ARPHRD_LOOPBACK) {
		snprintf(err, errlen, "network interface '%s' is not Ethernet (link type %u)", spec->ifname,
		         (unsigned)ifr.ifr_hwaddr.sa_family);
		close(fd);
		return -EINVAL;
	}
	memcpy(t->mac, ifr.ifr_hwaddr.sa_data, 6);
	t->ifindex = (int)ifindex;

	memset(&sll, 0, sizeof(sll));
	sll.sll_family = AF_PACKET;
	sll.sll_protocol = htons(VMAC_ETHERTYPE);
	sll.sll_ifindex = t->ifindex;
	if (bind(fd, (struct sockaddr *)&sll, sizeof(sll)) < 0)
		return close_fail(fd, err, errlen, "bind to the network interface");
	/* As for UDP: a larger buffer rides out a burst without losing the
	 * replies we wait for. */
	setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
	setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
	/* Our own sends are skipped in vmac_eth_recv anyway; this spares the
	 * copies where the kernel can (Linux 4.20 and later). */
	setsockopt(fd, SOL_PACKET, PACKET_IGNORE_OUTGOING, &on, sizeof(on));
	if (promisc) {
		struct packet_mreq mr;
		memset(&mr, 0, sizeof(mr));
		mr.mr_ifindex = t->ifindex;
		mr.mr_type = PACKET_MR_PROMISC;
		if (setsockopt(fd, SOL_PACKET, PACKET_ADD_MEMBERSHIP, &mr, sizeof(mr)) < 0)
			return close_fail(fd, err, errlen, "promiscuous mode on the network interface");
	}
	set_ll(&t->local, t->ifindex, t->mac);
	set_ll(&t->group, t->ifindex, broadcast);
	t->fd = fd;
	vmac_transport_clock_sync(t);
	return 0;
}

int vmac_eth_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	return open_eth(t, spec, 0, err, errlen);
}

int vmac_eth_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen)
{
	return open_eth(t, spec, 1, err, errlen);
}

static int mac_is_zero(const uint8_t mac[6])
{
	return (mac[0] | mac[1] | mac[2] | mac[3] | mac[4] | mac[5]) == 0;
}

/* A packet's destination must be an Ethernet address and its payload fit. */
static int sendable(const struct vmac_packet *p)
{
	const struct sockaddr_ll *to = (const struct sockaddr_ll *)&p->addr.ss;
	return to->sll_family == AF_PACKET && to->sll_halen == 6 && p->len <= VMAC_PACKET_MAX;
}

int vmac_eth_send(struct vmac_transport *t, struct vmac_packet *pkts, int n)
{
	struct mmsghdr msgs[BATCH_MAX];
	struct iovec iov[BATCH_MAX][3]; /* header, payload, padding */
	uint8_t hdr[BATCH_MAX][ETH_HLEN];
	int sent = 0;

	while (sent < n) {
		int built, chunk = n - sent > BATCH_MAX ? BATCH_MAX : n - sent, r;
		for (built = 0; built < chunk; built++) {
			struct vmac_packet *p = &pkts[sent + built];
			const struct sockaddr_ll *to = (const struct sockaddr_ll *)&p->addr.ss;
			size_t niov = 2;
			if (!sendable(p))
				break;
			memcpy(hdr[built], to->sll_addr, 6);
			memcpy(hdr[built] + 6, mac_is_zero(p->mac) ? t->mac : p->mac, 6);
			hdr[built][12] = VMAC_ETHERTYPE >> 8;
			hdr[built][13] = VMAC_ETHERTYPE & 0xff;
			iov[built][0].iov_base = hdr[built];
			iov[built][0].iov_len = ETH_HLEN;
			iov[built][1].iov_base = p->data;
			iov[built][1].iov_len = p->len;
			if (p->len < ETH_PAYLOAD_MIN) {
				iov[built][2].iov_base = (void *)zero_padding;
				iov[built][2].iov_len = ETH_PAYLOAD_MIN - p->len;
				niov = 3;
			}
			/* No msg_name: the socket is bound to the interface and
			 * the header we built says where the frame goes. */
			memset(&msgs[built], 0, sizeof(msgs[built]));
			msgs[built].msg_hdr.msg_iov = iov[built];
			msgs[built].msg_hdr.msg_iovlen = niov;
		}
		if (built == 0) /* pkts[sent] has no Ethernet destination or is too long */
			return sent > 0 ? sent : -EINVAL;
		r = sendmmsg(t->fd, msgs, (unsigned)built, MSG_DONTWAIT);
		if (r < 0) {
			if (errno == EINTR)
				continue;
			return sent > 0 ? sent : -errno;
		}
		sent += r;
		if (r == 0)
			break;
	}
	return sent;
}

/* Whether a frame is one Linux took an 802.1Q tag off before handing it to
 * us: for a tag with a VLAN id and no VLAN device on the interface, the
 * kernel strips the tag (so the EtherType we see is the inner one) and marks
 * the frame PACKET_OTHERHOST, which otherwise never goes with our own MAC or
 * a group address. Such a frame belongs to another network: skip it. (A
 * tagged frame to another board's MAC, seen in promiscuous mode, cannot be
 * told from an untagged one.) */
static int was_vlan_tagged(const struct vmac_transport *t, const struct sockaddr_ll *from, const uint8_t *hdr)
{
	return from->sll_pkttype == PACKET_OTHERHOST && ((hdr[0] & 1) || memcmp(hdr, t->mac, 6) == 0);
}

/* Fill p from a received frame already in p->data (payload) and hdr (its
 * Ethernet header); payload_len is how much of the payload came. */
static void take_frame(struct vmac_transport *t, struct vmac_packet *p, const uint8_t *hdr, size_t payload_len,
                       int truncated)
{
	p->len = payload_len;
	if (truncated)
		p->len = sizeof(p->data); /* oversize: the decoder rejects it */
	else if (payload_len == ETH_PAYLOAD_MIN) {
		/* Maybe a short frame padded to the minimum: its header says
		 * where it ends. Anything else goes on as it came, for the
		 * decoder to judge (and count). */
		int declared = vmac_proto_frame_length(p->data, payload_len);
		if (declared > 0 && declared <= ETH_PAYLOAD_MIN)
			p->len = (size_t)declared;
	}
	set_ll(&p->addr, t->ifindex, hdr + 6);
	memcpy(p->mac, hdr, 6);
}

int vmac_eth_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max)
{
	struct mmsghdr msgs[BATCH_MAX];
	struct iovec iov[BATCH_MAX][2]; /* header, payload */
	uint8_t hdr[BATCH_MAX][ETH_HLEN];
	struct sockaddr_ll from[BATCH_MAX];
	union {
		char buf[VMAC_TRANSPORT_CMSG_SPACE];
		struct cmsghdr align;
	} ctrl[BATCH_MAX];
	int filled = 0, round;

	for (round = 0; round < RECV_ROUNDS_MAX && filled < max; round++) {
		int i, r, base = filled, want = max - filled > BATCH_MAX ? BATCH_MAX : max - filled;
		int64_t now = vmac_now_ns();
		for (i = 0; i < want; i++) {
			iov[i][0].iov_base = hdr[i];
			iov[i][0].iov_len = ETH_HLEN;
			iov[i][1].iov_base = pkts[base + i].data;
			iov[i][1].iov_len = sizeof(pkts[base + i].data);
			memset(&msgs[i], 0, sizeof(msgs[i]));
			msgs[i].msg_hdr.msg_name = &from[i];
			msgs[i].msg_hdr.msg_namelen = sizeof(from[i]);
			msgs[i].msg_hdr.msg_iov = iov[i];
			msgs[i].msg_hdr.msg_iovlen = 2;
			msgs[i].msg_hdr.msg_control = ctrl[i].buf;
			msgs[i].msg_hdr.msg_controllen = sizeof(ctrl[i].buf);
		}
		do {
			r = recvmmsg(fd, msgs, (unsigned)want, MSG_DONTWAIT, NULL);
		} while (r < 0 && errno == EINTR);
		if (r < 0) {
			if (errno == EAGAIN || errno == EWOULDBLOCK || filled > 0)
				return filled;
			return -errno;
		}
		/* Keep what is ours, moved down over the frames skipped: a slot
		 * is only ever moved to a lower one, never over one still unread. */
		for (i = 0; i < r; i++) {
			struct vmac_packet *p = &pkts[filled];
			size_t got = msgs[i].msg_len;
			if (got < ETH_HLEN || from[i].sll_pkttype == PACKET_OUTGOING ||
			    from[i].sll_ifindex != t->ifindex || hdr[i][12] != (VMAC_ETHERTYPE >> 8) ||
			    hdr[i][13] != (VMAC_ETHERTYPE & 0xff) || was_vlan_tagged(t, &from[i], hdr[i]))
				continue;
			if (p != &pkts[base + i])
				memcpy(p->data, pkts[base + i].data, got - ETH_HLEN);
			take_frame(t, p, hdr[i], got - ETH_HLEN, (msgs[i].msg_hdr.msg_flags & MSG_TRUNC) != 0);
			p->rx_ns = vmac_transport_rx_stamp(t, &msgs[i].msg_hdr, now);
			filled++;
		}
		if (r < want)
			break; /* the socket is drained */
	}
	return filled;
}
