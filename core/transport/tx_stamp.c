/* The kernel's transmit timestamps (SO_TIMESTAMPING, software): asked for
 * per packet (a packet whose tx_cookie is not negative) by a control message
 * on its send, read back from the socket's error queue without blocking,
 * and matched to the packet by the kernel's OPT_ID counter, which counts
 * only the packets that asked. Both transports' senders call in here; the
 * host's SYNC uses it (docs/TIME.md, "The two-step SYNC"). */
#include "transport.h" /* first: struct timespec before linux/errqueue.h */

#include <errno.h>
#include <linux/errqueue.h>
#include <linux/if_packet.h>
#include <linux/net_tstamp.h>
#include <netinet/in.h>
#include <string.h>
#include <sys/socket.h>

/* Reported: software stamps, each with its counter (OPT_ID) and without a
 * copy of the packet (OPT_TSONLY). Generated: only for the packets whose
 * send asks (SOF_TIMESTAMPING_TX_SOFTWARE in a control message). */
#define REPORT_FLAGS (SOF_TIMESTAMPING_SOFTWARE | SOF_TIMESTAMPING_OPT_ID | SOF_TIMESTAMPING_OPT_TSONLY)

int vmac_transport_tx_stamps_on(struct vmac_transport *t)
{
	unsigned flags = REPORT_FLAGS;
	if (setsockopt(t->fd, SOL_SOCKET, SO_TIMESTAMPING, &flags, sizeof(flags)) < 0)
		return -errno;
	t->tx_stamps = 1;
	t->tx_next_id = 0;
	t->tx_head = t->tx_count = 0;
	return 0;
}

void vmac_transport_tx_ask(const struct vmac_transport *t, const struct vmac_packet *p, struct msghdr *h,
                           uint8_t ctrl[VMAC_TRANSPORT_TX_CMSG_SPACE])
{
	struct cmsghdr *c;
	uint32_t gen = SOF_TIMESTAMPING_TX_SOFTWARE;
	if (!t->tx_stamps || p->tx_cookie < 0)
		return;
	memset(ctrl, 0, VMAC_TRANSPORT_TX_CMSG_SPACE);
	h->msg_control = ctrl;
	h->msg_controllen = VMAC_TRANSPORT_TX_CMSG_SPACE;
	c = CMSG_FIRSTHDR(h);
	c->cmsg_level = SOL_SOCKET;
	c->cmsg_type = SO_TIMESTAMPING;
	c->cmsg_len = CMSG_LEN(sizeof(gen));
	memcpy(CMSG_DATA(c), &gen, sizeof(gen));
}

/* Everything in the error queue read and dropped, then the kernel's
 * counter back to 0 (OPT_ID off and on again) and ours with it. */
static void resync(struct vmac_transport *t)
{
	unsigned flags = REPORT_FLAGS & ~(unsigned)SOF_TIMESTAMPING_OPT_ID;
	uint8_t ctrl[256];
	int i;
	for (i = 0; i < 4 * VMAC_TRANSPORT_TX_PENDING; i++) {
		struct msghdr h;
		memset(&h, 0, sizeof(h));
		h.msg_control = ctrl;
		h.msg_controllen = sizeof(ctrl);
		if (recvmsg(t->fd, &h, MSG_ERRQUEUE | MSG_DONTWAIT) < 0 && errno != EINTR)
			break;
	}
	setsockopt(t->fd, SOL_SOCKET, SO_TIMESTAMPING, &flags, sizeof(flags));
	flags = REPORT_FLAGS;
	if (setsockopt(t->fd, SOL_SOCKET, SO_TIMESTAMPING, &flags, sizeof(flags)) < 0)
		t->tx_stamps = 0;
	t->tx_next_id = 0;
	t->tx_head = t->tx_count = 0;
	t->tx_resyncs++;
}

void vmac_transport_tx_sent(struct vmac_transport *t, const struct vmac_packet *pkts, int tried, int sent)
{
	int i, lost = 0;
	if (!t->tx_stamps)
		return;
	for (i = 0; i < tried; i++) {
		uint32_t at;
		if (pkts[i].tx_cookie < 0)
			continue;
		if (i >= sent) {
			lost = 1; /* the kernel may have counted it or not: we cannot tell */
			continue;
		}
		at = (t->tx_head + t->tx_count) % VMAC_TRANSPORT_TX_PENDING;
		if (t->tx_count == VMAC_TRANSPORT_TX_PENDING) /* the oldest, never stamped, gives way */
			t->tx_head = (t->tx_head + 1) % VMAC_TRANSPORT_TX_PENDING;
		else
			t->tx_count++;
		t->tx_pending[at].id = t->tx_next_id++;
		t->tx_pending[at].cookie = (uint32_t)pkts[i].tx_cookie;
	}
	if (lost)
		resync(t);
}

/* The pending send whose kernel counter is id: its cookie, 0; -1 when none
 * (its stamp came after it gave way, or a resync forgot it). Sends before
 * it that never got a stamp are forgotten (a frame the kernel dropped). */
static int take_pending(struct vmac_transport *t, uint32_t id, uint32_t *cookie)
{
	while (t->tx_count > 0) {
		const struct vmac_tx_pending *p = &t->tx_pending[t->tx_head];
		int32_t ahead = (int32_t)(id - p->id);
		if (ahead < 0)
			return -1; /* older than every pending send */
		t->tx_head = (t->tx_head + 1) % VMAC_TRANSPORT_TX_PENDING;
		t->tx_count--;
		if (ahead == 0) {
			*cookie = p->cookie;
			return 0;
		}
	}
	return -1;
}

/* The extended error of an error-queue message: IPv4's, IPv6's or a
 * packet socket's. */
static int is_extended_err(const struct cmsghdr *c)
{
	return (c->cmsg_level == SOL_IP && c->cmsg_type == IP_RECVERR) ||
	       (c->cmsg_level == SOL_IPV6 && c->cmsg_type == IPV6_RECVERR) ||
	       (c->cmsg_level == SOL_PACKET && c->cmsg_type == PACKET_TX_TIMESTAMP);
}

/* One error-queue message: its software stamp and the counter, 0; or -1
 * for anything else (another error, no stamp). */
static int parse_stamp(const struct vmac_transport *t, struct msghdr *h, uint32_t *id, int64_t *tx_ns)
{
	struct cmsghdr *c;
	int has_ts = 0, has_id = 0;
	for (c = CMSG_FIRSTHDR(h); c; c = CMSG_NXTHDR(h, c)) {
		if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPING &&
		    c->cmsg_len >= CMSG_LEN(3 * sizeof(struct timespec))) {
			struct timespec ts[3];
			memcpy(ts, CMSG_DATA(c), sizeof(ts));
			*tx_ns = (int64_t)ts[0].tv_sec * 1000000000 + ts[0].tv_nsec - t->rt_minus_mono_ns;
			has_ts = ts[0].tv_sec != 0 || ts[0].tv_nsec != 0;
		} else if (is_extended_err(c) && c->cmsg_len >= CMSG_LEN(sizeof(struct sock_extended_err))) {
			struct sock_extended_err e;
			memcpy(&e, CMSG_DATA(c), sizeof(e));
			if (e.ee_errno == ENOMSG && e.ee_origin == SO_EE_ORIGIN_TIMESTAMPING) {
				*id = e.ee_data;
				has_id = 1;
			}
		}
	}
	return has_ts && has_id ? 0 : -1;
}

int vmac_transport_tx_read(struct vmac_transport *t, int all, struct vmac_tx_stamp *out, int max)
{
	uint8_t ctrl[256];
	int n = 0, reads;
	if (!t->tx_stamps || (t->tx_count == 0 && !all))
		return 0;
	/* Bounded: what is left waits for the next call (epoll says EPOLLERR
	 * again while the queue is not empty). */
	for (reads = 0; reads < 2 * VMAC_TRANSPORT_TX_PENDING && n < max; reads++) {
		struct msghdr h;
		uint32_t id = 0, cookie;
		int64_t tx_ns = 0;
		memset(&h, 0, sizeof(h));
		h.msg_control = ctrl;
		h.msg_controllen = sizeof(ctrl);
		if (recvmsg(t->fd, &h, MSG_ERRQUEUE | MSG_DONTWAIT) < 0) {
			if (errno == EINTR)
				continue;
			break; /* EAGAIN: the queue is empty */
		}
		if (parse_stamp(t, &h, &id, &tx_ns) != 0 || take_pending(t, id, &cookie) != 0)
			continue;
		out[n].cookie = cookie;
		out[n].tx_ns = tx_ns;
		n++;
		if (!all && t->tx_count == 0)
			break; /* every stamp asked for is in: no read to find the queue empty */
	}
	return n;
}
