/* Raw-Ethernet transport: vmac frames as the payload of Ethernet frames of
 * EtherType 0x88B5 (AF_PACKET), discovery and cyclic frames broadcast, the
 * rest unicast MAC to MAC. Pads short payloads to the 46-byte minimum and
 * trims them back by the length the vmac header declares. Receives from a
 * ring the kernel writes frames into (PACKET_MMAP), so that a batch costs no
 * system call, or with recvmmsg where the kernel refuses the ring. Needs
 * CAP_NET_RAW. Reached through transport.c. */
#include "transport.h"

#include <arpa/inet.h>
#include <errno.h>
#include <linux/if_arp.h>
#include <linux/if_ether.h>
#include <linux/if_packet.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>

#define BATCH_MAX VMAC_TRANSPORT_BATCH
#define ETH_PAYLOAD_MIN (ETH_ZLEN - ETH_HLEN) /* 46 */
/* recvmmsg calls one vmac_eth_recv makes at most, so a flood of frames it
 * skips (other EtherTypes, our own sends) cannot hold it for long; from the
 * ring, as many frames as those calls would read. */
#define RECV_ROUNDS_MAX 4
#define RING_LOOK_MAX (RECV_ROUNDS_MAX * BATCH_MAX)

/* The receive ring: TPACKET_V2, one fixed slot per frame, which the kernel
 * hands over alone (TP_STATUS_USER) and wakes the reader for as soon as the
 * frame is in. Not TPACKET_V3: it hands over whole blocks of frames, only
 * when a block is full or its timer (1 ms at the least) retires it, so a
 * reply would wait up to a millisecond to be seen: a whole reply window at
 * 1 kHz. A slot holds the slot header, the sender's sockaddr_ll and, from
 * offset 66, up to 1,982 bytes of the frame: a whole Ethernet frame of 1,514
 * bytes (a CYCLIC frame can be that long), and of a longer one the kernel
 * keeps the start and says how long it was. 4,096 slots, 8 MiB: a burst of
 * thousands of frames (a big bus announcing at once) waits without loss. */
#define RING_FRAME_BYTES 2048u
#define RING_BLOCK_BYTES (64u << 10) /* a multiple of every page size: slots never straddle a block */
#define RING_FRAMES 4096u
#define RING_BYTES ((size_t)RING_FRAMES * RING_FRAME_BYTES)

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

/* Set up the receive ring on fd (a socket not bound yet): t->rx_ring, or
 * NULL when the kernel refuses it (said on stderr, once per process), and
 * frames are read with recvmmsg. VMAC_ETH_RECVMMSG=1 in the environment
 * asks for recvmmsg: the tests' way to keep that path tried. */
static void ring_open(struct vmac_transport *t, int fd, const char *ifname)
{
	static int refusal_said;
	struct tpacket_req req;
	int version = TPACKET_V2;
	const char *what = "PACKET_VERSION", *force = getenv("VMAC_ETH_RECVMMSG");
	void *ring;

	t->rx_ring = NULL;
	t->rx_next = 0;
	if (force && strcmp(force, "1") == 0)
		return;
	memset(&req, 0, sizeof(req));
	req.tp_block_size = RING_BLOCK_BYTES;
	req.tp_block_nr = (unsigned)(RING_BYTES / RING_BLOCK_BYTES);
	req.tp_frame_size = RING_FRAME_BYTES;
	req.tp_frame_nr = RING_FRAMES;
	if (setsockopt(fd, SOL_PACKET, PACKET_VERSION, &version, sizeof(version)) == 0) {
		what = "PACKET_RX_RING";
		if (setsockopt(fd, SOL_PACKET, PACKET_RX_RING, &req, sizeof(req)) == 0) {
			what = "mmap";
			ring = mmap(NULL, RING_BYTES, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
			if (ring != MAP_FAILED) {
				t->rx_ring = ring;
				return;
			}
		}
	}
	if (!refusal_said) {
		fprintf(stderr, "vmac: raw Ethernet on %s: no receive ring (%s: %s); receiving with recvmmsg\n", ifname,
		        what, strerror(errno));
		refusal_said = 1;
	}
}

void vmac_eth_close(struct vmac_transport *t)
{
	if (t->rx_ring)
		munmap(t->rx_ring, RING_BYTES);
	t->rx_ring = NULL;
}

/* A failed open: what failed into err, the ring and the socket gone. */
static int close_fail(struct vmac_transport *t, int fd, char *err, size_t errlen, const char *what)
{
	int r = vmac_transport_fail(err, errlen, what);
	vmac_eth_close(t);
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
	/* Protocol 0: nothing arrives until the bind names our EtherType. */
	fd = socket(AF_PACKET, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
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
		return close_fail(t, fd, err, errlen, "reading the interface's MAC address");
	if (ifr.ifr_hwaddr.sa_family != ARPHRD_ETHER && ifr.ifr_hwaddr.sa_family != ARPHRD_LOOPBACK) {
		snprintf(err, errlen, "network interface '%s' is not Ethernet (link type %u)", spec->ifname,
		         (unsigned)ifr.ifr_hwaddr.sa_family);
		close(fd);
		return -EINVAL;
	}
	memcpy(t->mac, ifr.ifr_hwaddr.sa_data, 6);
	t->ifindex = (int)ifindex;

	/* As for UDP: a larger buffer rides out a burst without losing the
	 * replies we wait for (the ring, when there is one, has its own). */
	setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
	/* Stamps on arrival, for the ring's headers as for recvmmsg's. */
	setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
	/* Our own sends are skipped in vmac_eth_recv anyway; this spares the
	 * copies where the kernel can (Linux 4.20 and later). */
	setsockopt(fd, SOL_PACKET, PACKET_IGNORE_OUTGOING, &on, sizeof(on));
	/* Before the bind: the socket receives nothing yet, so no frame can
	 * wait in its queue beside the ring, where nobody would read it. */
	ring_open(t, fd, spec->ifname);

	memset(&sll, 0, sizeof(sll));
	sll.sll_family = AF_PACKET;
	sll.sll_protocol = htons(VMAC_ETHERTYPE);
	sll.sll_ifindex = t->ifindex;
	if (bind(fd, (struct sockaddr *)&sll, sizeof(sll)) < 0)
		return close_fail(t, fd, err, errlen, "bind to the network interface");
	if (promisc) {
		struct packet_mreq mr;
		memset(&mr, 0, sizeof(mr));
		mr.mr_ifindex = t->ifindex;
		mr.mr_type = PACKET_MR_PROMISC;
		if (setsockopt(fd, SOL_PACKET, PACKET_ADD_MEMBERSHIP, &mr, sizeof(mr)) < 0)
			return close_fail(t, fd, err, errlen, "promiscuous mode on the network interface");
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
	uint8_t ctrl[BATCH_MAX][VMAC_TRANSPORT_TX_CMSG_SPACE];
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
			vmac_transport_tx_ask(t, p, &msgs[built].msg_hdr, ctrl[built]);
		}
		if (built == 0) /* pkts[sent] has no Ethernet destination or is too long */
			return sent > 0 ? sent : -EINVAL;
		r = sendmmsg(t->fd, msgs, (unsigned)built, MSG_DONTWAIT);
		if (r < 0) {
			int e = errno;
			if (e == EINTR)
				continue;
			vmac_transport_tx_sent(t, pkts + sent, 1, 0);
			return sent > 0 ? sent : -e;
		}
		vmac_transport_tx_sent(t, pkts + sent, r < built ? r + 1 : r, r);
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

/* Whether a received frame (len bytes with its Ethernet header hdr, from
 * the sender the kernel names) is for us: not our own send looped back, from
 * our interface, of our EtherType and not from a VLAN. */
static int is_ours(const struct vmac_transport *t, const struct sockaddr_ll *from, const uint8_t *hdr, size_t len)
{
	return len >= ETH_HLEN && from->sll_pkttype != PACKET_OUTGOING && from->sll_ifindex == t->ifindex &&
	       hdr[12] == (VMAC_ETHERTYPE >> 8) && hdr[13] == (VMAC_ETHERTYPE & 0xff) && !was_vlan_tagged(t, from, hdr);
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

/* A frame the kernel left in the ring at frame (snap_len bytes of its
 * wire_len, header included; from is its sockaddr_ll): into p when it is
 * ours, with its stamp in CLOCK_MONOTONIC ns as vmac_transport_rx_stamp
 * converts it (never later than *now_ns, which is read again when a frame
 * seems to have come after it). Returns 1 when p was filled, 0 when the
 * frame is skipped. */
static int ring_take(struct vmac_transport *t, struct vmac_packet *p, const uint8_t *frame, size_t snap_len,
                     size_t wire_len, const struct sockaddr_ll *from, uint32_t sec, uint32_t nsec, int64_t *now_ns)
{
	size_t payload;
	int64_t mono;
	if (!is_ours(t, from, frame, snap_len))
		return 0;
	payload = snap_len - ETH_HLEN;
	if (payload > sizeof(p->data))
		payload = sizeof(p->data);
	memcpy(p->data, frame + ETH_HLEN, payload);
	take_frame(t, p, frame, payload, wire_len > ETH_HLEN + payload);
	mono = (int64_t)sec * 1000000000 + nsec - t->rt_minus_mono_ns;
	if (mono > *now_ns)
		*now_ns = vmac_now_ns();
	p->rx_ns = mono <= *now_ns ? mono : *now_ns;
	return 1;
}

/* Frames from the ring, in the order they came: each slot the kernel has
 * handed over (TP_STATUS_USER) is read, given back (TP_STATUS_KERNEL) and
 * passed; the first slot still the kernel's ends the call, and so does pkts
 * being full, before the next slot is touched: that frame is the first of
 * the next call. No system call. */
static int ring_recv(struct vmac_transport *t, struct vmac_packet *pkts, int max)
{
	int filled = 0, looked;
	int64_t now = 0; /* read when the first frame needs it */
	for (looked = 0; filled < max && looked < RING_LOOK_MAX; looked++) {
		uint8_t *slot = t->rx_ring + (size_t)t->rx_next * RING_FRAME_BYTES;
		struct tpacket2_hdr *h = (struct tpacket2_hdr *)slot;
		const struct sockaddr_ll *from =
		    (const struct sockaddr_ll *)(slot + TPACKET_ALIGN(sizeof(struct tpacket2_hdr)));
		/* Acquire: the frame's bytes are read only after its status. */
		if (!(__atomic_load_n(&h->tp_status, __ATOMIC_ACQUIRE) & TP_STATUS_USER))
			break;
		if (h->tp_mac <= RING_FRAME_BYTES && h->tp_snaplen <= RING_FRAME_BYTES - h->tp_mac)
			filled += ring_take(t, &pkts[filled], slot + h->tp_mac, h->tp_snaplen, h->tp_len, from,
			                    h->tp_sec, h->tp_nsec, &now);
		/* Release: the kernel may write the slot again only after we
		 * have read it. */
		__atomic_store_n(&h->tp_status, TP_STATUS_KERNEL, __ATOMIC_RELEASE);
		t->rx_next = (t->rx_next + 1) % RING_FRAMES;
	}
	return filled;
}

/* Frames read with recvmmsg, where there is no ring. */
static int mmsg_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max)
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
			if (!is_ours(t, &from[i], hdr[i], got))
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

int vmac_eth_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max)
{
	if (t->rx_ring && fd == t->fd)
		return ring_recv(t, pkts, max);
	return mmsg_recv(t, fd, pkts, max);
}
