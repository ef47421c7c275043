/* Bus transport interface: how frames leave and reach the host (and the POSIX
 * board). The scheduler and drivers see only this, so a raw-Ethernet
 * transport (AF_PACKET, EtherType 0x88B5) can be added beside the UDP one. */
#ifndef VMAC_TRANSPORT_H
#define VMAC_TRANSPORT_H

#include <netinet/in.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>

#include "../proto/proto.h"

/* A peer's address on the bus; opaque to everything above the transport. */
struct vmac_addr {
	struct sockaddr_storage ss;
	socklen_t len;
};

/* One datagram in a batch. For receive, rx_ns is when the kernel took the
 * datagram off the wire (CLOCK_MONOTONIC ns), not when we read it. */
struct vmac_packet {
	uint8_t data[VMAC_FRAME_MAX + 1]; /* +1 so an oversize datagram is seen as such */
	size_t len;
	struct vmac_addr addr;
	int64_t rx_ns;
};

/* Where the bus is: a multicast group and port for discovery, and the local
 * interface address everything is sent from. */
struct vmac_bus_spec {
	struct in_addr group;
	uint16_t port;
	struct in_addr iface;
};

struct vmac_transport {
	int fd;                   /* unicast socket: cyclic traffic and discovery sends */
	struct vmac_addr group;   /* where DISCOVER goes */
	struct vmac_addr local;   /* our own unicast address */
	int64_t rt_minus_mono_ns; /* realtime - monotonic, to convert kernel stamps */
};

/* Parse "GROUP:PORT" (e.g. 239.255.86.77:5870). Returns 0 or -EINVAL. */
int vmac_bus_spec_parse(const char *text, struct vmac_bus_spec *spec);

/* Host side: open the unicast socket on spec->iface, ready to send to the
 * group. Returns 0 or a negative errno; err gets a readable reason. */
int vmac_transport_open_host(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);

/* Board side: a unicast socket of its own on spec->iface (port chosen by the
 * kernel). Discovery arrives on a separate listener, vmac_transport_listen. */
int vmac_transport_open_board(struct vmac_transport *t, const struct vmac_bus_spec *spec, char *err, size_t errlen);

/* Board side: a socket joined to the discovery group (shared by every board
 * of one process). Returns the fd or a negative errno. */
int vmac_transport_listen(const struct vmac_bus_spec *spec, char *err, size_t errlen);

void vmac_transport_close(struct vmac_transport *t);

/* Send n packets (batched). Returns how many were handed to the kernel, or a
 * negative errno when none could be. Never blocks. */
int vmac_transport_send(struct vmac_transport *t, struct vmac_packet *pkts, int n);

/* Receive up to max waiting datagrams from fd, never blocking. Returns the
 * number read (0 when none) or a negative errno. */
int vmac_transport_recv(struct vmac_transport *t, int fd, struct vmac_packet *pkts, int max);

/* Resample the realtime/monotonic offset used to convert kernel stamps. */
void vmac_transport_clock_sync(struct vmac_transport *t);

int vmac_addr_equal(const struct vmac_addr *a, const struct vmac_addr *b);
/* "127.0.0.1:40123" into buf; returns buf. */
char *vmac_addr_format(const struct vmac_addr *a, char *buf, size_t len);

/* CLOCK_MONOTONIC now, in ns. */
int64_t vmac_now_ns(void);

#endif
