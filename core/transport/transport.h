/* Bus transport interface: how frames leave and reach the host (and the POSIX
 * board). The scheduler and drivers see only this. Two transports sit behind
 * it: UDP (transport_udp.c: multicast discovery, unicast traffic) and raw
 * Ethernet (transport_eth.c: AF_PACKET, EtherType 0x88B5); transport.c picks
 * one by kind and holds what both share (clocks, addresses). */
#ifndef VMAC_TRANSPORT_H
#define VMAC_TRANSPORT_H

#include <net/if.h>
#include <netinet/in.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>
#include <time.h>

#include "../proto/proto.h"

/* A peer's address on the bus; opaque to everything above the transport.
 * UDP: a sockaddr_in. Ethernet: a sockaddr_ll (the MAC and the ifindex). */
struct vmac_addr {
	struct sockaddr_storage ss;
	socklen_t len;
};

/* One frame in a batch. For receive, rx_ns is when the kernel took the frame
 * off the wire (CLOCK_MONOTONIC ns), not when we read it. */
struct vmac_packet {
	uint8_t data[VMAC_PACKET_MAX + 1]; /* +1 so an oversize datagram is seen as such */
	size_t len;
	struct vmac_addr addr; /* receive: the sender; send: the destination */
	uint8_t mac[6];        /* Ethernet only. receive: the destination MAC the frame was sent to; send: the
	                        * source MAC to put on it (all zero: the interface's own) */
	int64_t rx_ns;         /* receive: kernel timestamp, CLOCK_MONOTONIC ns */
	int32_t tx_cookie;     /* send: >= 0 asks for the kernel's transmit timestamp, returned with this
	                        * cookie by vmac_transport_tx_read; negative: none. Ignored unless
	                        * vmac_transport_tx_stamps_on succeeded on the transport */
};

/* A transmit timestamp: when the kernel handed a packet that asked for one
 * to the device's driver (software: no hardware stamps), CLOCK_MONOTONIC ns. */
struct vmac_tx_stamp {
	uint32_t cookie; /* the packet's tx_cookie */
	int64_t tx_ns;
};

/* Sends that asked for a stamp and have not had it yet, at most. */
#define VMAC_TRANSPORT_TX_PENDING 64
struct vmac_tx_pending {
	uint32_t id; /* the kernel's OPT_ID counter for it */
	uint32_t cookie;
};

enum vmac_transport_kind { VMAC_TRANSPORT_UDP, VMAC_TRANSPORT_ETH };

/* Where the bus is. UDP: a multicast group and port for discovery, and the
 * local interface address everything is sent from. Ethernet: the interface. */
struct vmac_bus_spec {
	enum vmac_transport_kind kind;
	struct in_addr group; /* UDP */
	uint16_t port;
	struct in_addr iface;
	char ifname[IF_NAMESIZE]; /* Ethernet */
};

struct vmac_transport {
	enum vmac_transport_kind kind;
	int fd;                   /* the one socket: cyclic traffic and discovery sends */
	struct vmac_addr group;   /* where DISCOVER and CYCLIC frames go: the UDP multicast group, or the Ethernet
	                           * broadcast address ff:ff:ff:ff:ff:ff on the interface */
	struct vmac_addr local;   /* our own address: IP:port, or the interface's MAC */
	int64_t rt_minus_mono_ns; /* realtime - monotonic, to convert kernel stamps */
	int ifindex;              /* Ethernet */
	uint8_t mac[6];           /* Ethernet: the interface's MAC */
	uint8_t *rx_ring;         /* Ethernet: the receive ring the kernel writes frames into (PACKET_RX_RING,
	                           * mmap'd; unmapped by vmac_transport_close), NULL when frames are read with
	                           * recvmmsg instead */
	uint32_t rx_next;         /* Ethernet: the ring slot to read next, where the last receive stopped */
	/* Transmit timestamps (tx_stamp.c): on or not, the kernel's counter of
	 * the next send that asks, the sends waiting for theirs (a ring), and
	 * how often the counters were set back to 0 after a send that failed. */
	int tx_stamps;
	uint32_t tx_next_id;
	struct vmac_tx_pending tx_pending[VMAC_TRANSPORT_TX_PENDING];
	uint32_t tx_head, tx_count;
	uint64_t tx_resyncs;
};

/* The EtherType of vmac frames on raw Ethernet (IEEE local experimental). */
#define VMAC_ETHERTYPE 0x88B5

/* Parse "GROUP:PORT" (UDP, e.g. 239.255.86.77:5870, GROUP multicast, PORT
 * not 0) or "eth:IFACE" (raw Ethernet, IFACE 1..15 characters). Sets kind,
 * group, port and ifname; leaves spec->iface as it was (the caller sets it).
 * Returns 0 or -EINVAL. */
int vmac_bus_spec_parse(const char *text, struct vmac_bus_spec *spec);

/* Host side: open the one socket (UDP: on spec->iface, ready to send to the
 * group; Ethernet: on spec->ifname). Returns 0 or a negative errno; err gets
 * one readable line (for Ethernet without CAP_NET_RAW, it says so and how to
 * grant it). Never falls back from one transport to the other. */
int vmac_transport_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);

/* Board side. UDP: a unicast socket of its own on spec->iface (port chosen by
 * the kernel); discovery arrives on a separate listener,
 * vmac_transport_listen. Ethernet: the one socket, in promiscuous mode, since
 * a board process serves many boards each with its own MAC; it receives
 * broadcasts and unicasts alike (tell them apart by p->mac). */
int vmac_transport_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);

/* Board side, UDP only: a socket joined to the discovery group (shared by
 * every board of one process). Returns the fd or a negative errno; for
 * Ethernet -EOPNOTSUPP (the board's own socket gets discovery too). */
int vmac_transport_listen(const struct vmac_bus_spec *spec, char *err, size_t errlen);

void vmac_transport_close(struct vmac_transport *t);

/* Send n packets (batched: one system call per up to 64). Ethernet pads a
 * payload shorter than 46 bytes with zeros. Returns how many were handed to
 * the kernel, or a negative errno when none could be. Never blocks. */
int vmac_transport_send(struct vmac_transport *t, struct vmac_packet *pkts, int n);

/* Receive up to max waiting frames from fd (UDP: t->fd or a listener;
 * Ethernet: t->fd), never blocking. Returns the number read (0 when none
 * waits) or a negative errno. Ethernet skips our own frames looped back,
 * frames of another EtherType and frames the kernel took a VLAN tag off, and
 * trims the zero padding of a short frame to the length its header declares
 * (anything else, garbage included, comes as it was, for the decoder); it
 * reads from a ring the kernel writes frames into, without a system call,
 * where the kernel allows one (else with recvmmsg), and a frame that does
 * not fit in pkts waits there for the next call. */
int vmac_transport_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max);

/* Resample the realtime/monotonic offset used to convert kernel stamps. */
void vmac_transport_clock_sync(struct vmac_transport *t);

/* Ask the kernel for software transmit timestamps of the packets whose
 * tx_cookie is not negative (SO_TIMESTAMPING: SOFTWARE, OPT_ID, OPT_TSONLY;
 * TX_SOFTWARE per send). Returns 0, or a negative errno and stamps stay
 * off. Each stamp then waits in the socket's error queue, which makes epoll
 * report EPOLLERR on the socket until vmac_transport_tx_read empties it. */
int vmac_transport_tx_stamps_on(struct vmac_transport *t);

/* Read up to max transmit stamps waiting, never blocking, each matched to
 * its packet's cookie (stamps matching no pending send are dropped). Reads
 * at most 2 x VMAC_TRANSPORT_TX_PENDING messages a call, and none (no
 * system call) when no send awaits a stamp, unless all (epoll said
 * EPOLLERR: whatever waits is read, so that it stops saying so). Returns
 * how many were written to out (0 when stamps are off or none waits). */
int vmac_transport_tx_read(struct vmac_transport *t, int all, struct vmac_tx_stamp *out, int max);

/* Same peer: family and IPv4 address and port, or MAC and ifindex. */
int vmac_addr_equal(const struct vmac_addr *a, const struct vmac_addr *b);
/* "127.0.0.1:40123" or "02:00:00:00:00:07" into buf; returns buf. */
char *vmac_addr_format(const struct vmac_addr *a, char *buf, size_t len);

/* CLOCK_MONOTONIC now, in ns. */
int64_t vmac_now_ns(void);

/* ---- Between transport.c and the transports only; callers use the above. */

int vmac_udp_bus_spec_parse(const char *text, struct vmac_bus_spec *spec);
int vmac_udp_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);
int vmac_udp_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);
int vmac_udp_listen(const struct vmac_bus_spec *spec, char *err, size_t errlen);
int vmac_udp_send(struct vmac_transport *t, struct vmac_packet *pkts, int n);
int vmac_udp_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max);

int vmac_eth_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);
int vmac_eth_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);
int vmac_eth_send(struct vmac_transport *t, struct vmac_packet *pkts, int n);
int vmac_eth_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max);
void vmac_eth_close(struct vmac_transport *t);

/* Batch size of one sendmmsg or recvmmsg. */
#define VMAC_TRANSPORT_BATCH 64

/* The control buffer one received message needs for its SO_TIMESTAMPNS. */
#define VMAC_TRANSPORT_CMSG_SPACE CMSG_SPACE(sizeof(struct timespec))

/* When the kernel took a received message off the wire, from its
 * SO_TIMESTAMPNS control message, in CLOCK_MONOTONIC ns; now_ns (read before
 * the receive) when there is none or it lies after now_ns (a realtime step). */
int64_t vmac_transport_rx_stamp(const struct vmac_transport *t, struct msghdr *h, int64_t now_ns);

/* The control buffer of one send that asks for a transmit stamp. */
#define VMAC_TRANSPORT_TX_CMSG_SPACE CMSG_SPACE(sizeof(uint32_t))

/* The senders, per packet before the send: if stamps are on and p asks
 * for one, h's control message asks the kernel for it (in ctrl). */
void vmac_transport_tx_ask(const struct vmac_transport *t, const struct vmac_packet *p, struct msghdr *h,
                           uint8_t ctrl[VMAC_TRANSPORT_TX_CMSG_SPACE]);
/* ...and after it: of pkts[0..tried), the first `sent` were taken by the
 * kernel. Their stamps are awaited; a stamped packet not taken sets the
 * kernel's counter and ours back to 0 (the kernel may have counted it). */
void vmac_transport_tx_sent(struct vmac_transport *t, const struct vmac_packet *pkts, int tried, int sent);

/* "what: strerror(errno)" into err; returns -errno (-EINVAL if errno is 0). */
int vmac_transport_fail(char *err, size_t errlen, const char *what);

#endif
