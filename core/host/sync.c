/* The host's side of the two-step SYNC (docs/TIME.md, "The two-step
 * SYNC"): which SYNC frame a transmit timestamp from the kernel belongs to,
 * and the stamp each stream's next frame carries as prev_tx_ns. bus.c
 * builds, stamps and seals the frames; the transport (tx_stamp.c) asks the
 * kernel for the stamps and reads them back. No heap, no blocking, no log:
 * it runs in the tick. */
#include "bus_internal.h"

/* A stamp later than its frame's host_ns by more than this is not believed
 * (a realtime step between the two clocks' readings, a stamp of another
 * frame after a resync): the next frame says 0. */
#define TX_SPAN_MAX_NS 10000000

int32_t bus_sync_cookie(uint32_t stream, uint16_t seq)
{
	return (int32_t)(stream << 16 | seq);
}

uint64_t bus_sync_prev(const struct vmac_bus *bus, uint32_t stream, uint16_t seq)
{
	const struct sync_stream *s = &bus->sync_streams[stream];
	return s->stamped && (uint16_t)(s->seq + 1) == seq ? (uint64_t)s->tx_ns : 0;
}

void bus_sync_sent(struct vmac_bus *bus, uint32_t stream, uint16_t seq, int64_t host_ns)
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
