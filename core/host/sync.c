/* The host's SYNC frames (docs/TIME.md; docs/PROTOCOL.md, "SYNC", "The
 * sealed SYNC"): built for the tick they fall due in (the plain frame on an
 * open bus, a sealed one per chunk of offsets holding a keyed board),
 * stamped with the host's time as the batch leaves and sealed after it;
 * and the two-step ("The two-step SYNC"): which frame a transmit timestamp
 * from the kernel belongs to, and the stamp each stream's next frame
 * carries as prev_tx_ns. The transport (tx_stamp.c) asks the kernel for
 * the stamps and reads them back. No heap, no blocking, no log: it runs in
 * the tick. */
#include "bus_internal.h"

#include <string.h>

#include "../proto/auth.h"

/* A stamp later than its frame's host_ns by more than this is not believed
 * (a realtime step between the two clocks' readings, a stamp of another
 * frame after a resync): the next frame says 0. */
#define TX_SPAN_MAX_NS 10000000

/* The cookie a stream's frame of seq asks the transport's stamp with. */
static int32_t sync_cookie(uint32_t stream, uint16_t seq)
{
	return (int32_t)(stream << 16 | seq);
}

/* prev_tx_ns for the stream's frame of seq: the transmit time of its frame
 * of seq - 1 when the kernel gave it, else 0. */
static uint64_t sync_prev(const struct vmac_bus *bus, uint32_t stream, uint16_t seq)
{
	const struct sync_stream *s = &bus->sync_streams[stream];
	return s->stamped && (uint16_t)(s->seq + 1) == seq ? (uint64_t)s->tx_ns : 0;
}

/* The stream's frame of seq stamped host_ns, about to go. */
static void sync_sent(struct vmac_bus *bus, uint32_t stream, uint16_t seq, int64_t host_ns)
{
	struct sync_stream *s = &bus->sync_streams[stream];
	s->seq = seq;
	s->stamped = 0;
	s->host_ns = host_ns;
}

void bus_sync_read_stamps(struct vmac_bus *bus, int all)
{
	struct vmac_tx_stamp got[16];
	int i, n;
	do {
		n = vmac_transport_tx_read(&bus->tr, all, got, 16);
		for (i = 0; i < n; i++) {
			uint32_t stream = got[i].cookie >> 16;
			struct sync_stream *s;
			if (stream > bus->nsync_chunks)
				continue;
			s = &bus->sync_streams[stream];
			if (s->seq != (uint16_t)got[i].cookie || s->stamped || got[i].tx_ns < s->host_ns ||
			    got[i].tx_ns - s->host_ns > TX_SPAN_MAX_NS)
				continue;
			s->tx_ns = got[i].tx_ns;
			s->stamped = 1;
			bus->counters.sync_stamps++;
		}
	} while (n == 16);
}

/* A keyed board that holds a session and an offset (its slot: v2 cyclic,
 * or reading TIMED UPDATEs): the sealed SYNC carries a MAC for it. */
static int sync_keyed(const struct vmac_bus *bus, const struct device *d)
{
	return d->keyed && bus_holds_offset(bus, d) &&
	       (d->state == DEV_REGISTERING || d->state == DEV_RUNNING || d->state == DEV_TO_SLEEP);
}

/* The SYNC frames of this batch get the host's time as late as the host
 * can take it, the send itself follows; the sealed ones are sealed after
 * the stamp (their MACs cover it), one SipHash per keyed board: a delay
 * common to every board of the frame (docs/TIME.md, "Trust"), and which
 * the next frame's prev_tx_ns, the kernel's stamp of this one, leaves out
 * (below). */
void bus_sync_stamp(struct vmac_bus *bus)
{
	uint64_t now = (uint64_t)bus_now(bus);
	int k;
	if (bus->sync_tx >= 0) {
		uint8_t *f = bus->tx[bus->sync_tx].data;
		vmac_proto_sync_stamp(f, now);
		sync_sent(bus, 0, (uint16_t)(f[4] << 8 | f[5]), (int64_t)now);
	}
	bus->sync_tx = -1;
	for (k = 0; k < bus->nsync_auth; k++) {
		uint8_t *f = bus->tx[bus->sync_auth_tx[k]].data;
		uint32_t first = (uint32_t)(f[VMAC_SYNC_AUTH_HEAD_LEN - 2] << 8 | f[VMAC_SYNC_AUTH_HEAD_LEN - 1]), i;
		vmac_proto_sync_stamp(f, now);
		sync_sent(bus, 1 + first / VMAC_SYNC_AUTH_MACS_MAX, (uint16_t)(f[4] << 8 | f[5]), (int64_t)now);
		for (i = 0; i < f[12]; i++)
			if (sync_keyed(bus, &bus->dev[first + i]))
				vmac_proto_sync_seal(f, i, bus->dev[first + i].to_board);
	}
	bus->nsync_auth = 0;
}

/* The sealed SYNC frames: one per chunk of offsets that holds a keyed
 * board, its MACs left to bus_flush (sync_stamp). */
static void send_sync_sealed(struct vmac_bus *bus)
{
	uint32_t first, i, count;
	bus->sync_counter++; /* one a SYNC, whether any chunk goes: never repeated in a run */
	for (first = 0; first < bus->nused; first += VMAC_SYNC_AUTH_MACS_MAX) {
		struct vmac_packet *p;
		int n;
		count = bus->nused - first < VMAC_SYNC_AUTH_MACS_MAX ? bus->nused - first : VMAC_SYNC_AUTH_MACS_MAX;
		for (i = 0; i < count && !sync_keyed(bus, &bus->dev[first + i]); i++)
			;
		if (i == count || !(p = bus_tx_slot(bus)))
			continue;
		n = vmac_proto_sync_begin_auth(p->data, sizeof(p->data), bus->sync_seq, bus->sync_counter,
		                               (uint16_t)first, count);
		if (n <= 0) {
			bus->ntx--;
			continue;
		}
		p->len = (size_t)n;
		p->addr = bus->tr.group;
		memset(p->mac, 0, sizeof(p->mac));
		p->tx_cookie = sync_cookie(1 + first / VMAC_SYNC_AUTH_MACS_MAX, bus->sync_seq);
		vmac_proto_sync_set_prev(p->data, sync_prev(bus, 1 + first / VMAC_SYNC_AUTH_MACS_MAX, bus->sync_seq));
		bus->sync_auth_tx[bus->nsync_auth++] = (int)(p - bus->tx);
		bus->counters.syncs_sealed++;
	}
}

/* SYNC to the group (docs/TIME.md): queued before this tick's CYCLIC
 * frames, its host time written by bus_flush just before the batch is
 * handed to the kernel. No allocation, no log: it runs on every tick due. */
void bus_send_sync(struct vmac_bus *bus)
{
	struct vmac_packet *p;
	struct vmac_msg m;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_SYNC;
	m.seq = ++bus->sync_seq;
	m.u.sync.prev_tx_ns = sync_prev(bus, 0, m.seq);
	send_sync_sealed(bus);
	/* Plain, on an open bus only: unkeyed boards sync before they
	 * announce, so the host cannot know whether any listens. On an
	 * enrolled bus no board it serves takes one (a keyed board takes the
	 * sealed SYNC only, an unkeyed one is never served): it would cost a
	 * datagram and a transmit stamp a tick for nobody. */
	if (vmac_config_trust_open(&bus->cfg) && (p = bus_queue_group(bus, &m))) {
		p->tx_cookie = sync_cookie(0, m.seq);
		bus->sync_tx = bus->ntx - 1;
	}
	if (bus->sync_tx >= 0 || bus->nsync_auth > 0)
		bus->counters.syncs++;
}
