/* vmac-board's dispatch: every received frame goes to the one board it is
 * for, found in O(1), never by offering it to every board (but DISCOVER,
 * which every unknown board must answer). The replies of one batch leave
 * together, one sendmmsg per 64; a reply that left later than --late-us
 * after its request came in is printed, so a miss on the host can be told apart from
 * a late board. */
#include <inttypes.h>
#include <stdio.h>
#include <string.h>

#include "boards.h"

/* Where the next reply is written; sends the batch when it is full (a
 * DISCOVER to thousands of boards, or many CYCLIC frames at once). */
static struct vmac_packet *reply_slot(struct board_set *s)
{
	if (s->nreplies == BOARDS_REPLY_MAX)
		boards_flush(s);
	return &s->replies[s->nreplies];
}

/* Hand the frame to board i; its reply, if any, is queued to go back to the
 * sender (on Ethernet from the board's own MAC). The watchdog is checked
 * first so that its trip is printed before the frame is looked at. */
static void deliver(struct board_set *s, int32_t i, const struct vmac_packet *in, uint64_t now_ms)
{
	struct posix_board *pb = &s->boards[i];
	struct vmac_packet *out = reply_slot(s);
	int len;

	boards_poll_one(s, i, now_ms);
	if (in->data[3] & VMAC_FLAG_TIMED) {
		/* A TIMED CYCLIC or TIMED UPDATE (no reply gets here): its
		 * instants are on the board's counter, the arrival on it too. */
		pb->timed_addr = in->addr;
		len = vmac_board_receive_at(&pb->board, in->data, in->len, now_ms, boards_local_ns(s, i, in->rx_ns, 1),
		                            out->data, sizeof(out->data));
		boards_timed_track(s, i);
	} else {
		len = vmac_board_receive(&pb->board, in->data, in->len, now_ms, out->data, sizeof(out->data));
	}
	boards_track(s, i);
	if (len <= 0)
		return;
	out->len = (size_t)len;
	out->addr = in->addr;
	memcpy(out->mac, pb->mac, sizeof(out->mac));
	out->rx_ns = in->rx_ns; /* kept for the late-reply check */
	s->reply_board[s->nreplies++] = i;
}

/* Every record with a tag goes to the board holding its offset. */
static void route_cyclic(struct board_set *s, const struct vmac_packet *p, uint64_t now_ms)
{
	struct vmac_msg m;
	const uint8_t *record;
	unsigned k, stride;

	if (vmac_proto_decode(p->data, p->len, &m) != 0) {
		s->unroutable++;
		return;
	}
	record = m.u.cyclic.records;
	stride = (m.flags & VMAC_FLAG_AUTH) ? VMAC_CYCLIC_AUTH_RECORD_LEN : VMAC_CYCLIC_RECORD_LEN;
	for (k = 0; k < m.u.cyclic.count; k++, record += stride) {
		int32_t i;
		if (record[0] == 0 && record[1] == 0)
			continue; /* tag 0: an empty record */
		/* first + count <= 0xFFFF (the decoder checks), so this is in the table. */
		i = s->by_offset[m.u.cyclic.first + k];
		if (i != BOARD_NONE)
			deliver(s, i, p, now_ms);
	}
}

/* SYNC goes to every board (docs/TIME.md), each with the frame's receive
 * time on its own counter; it is never answered. O(boards) a frame, as
 * DISCOVER, but at the host's clock_sync_ms. */
static void route_sync(struct board_set *s, const struct vmac_packet *p, uint64_t now_ms)
{
	uint8_t none[VMAC_BOARD_REPLY_MAX];
	int32_t i;
	for (i = 0; i < s->count; i++) {
		boards_poll_one(s, i, now_ms);
		vmac_board_receive_at(&s->boards[i].board, p->data, p->len, now_ms, boards_local_ns(s, i, p->rx_ns, 1),
		                      none, sizeof(none));
	}
}

/* UDP: a REGISTER goes to the board of the identity it names. */
static int32_t route_register(struct board_set *s, const struct vmac_packet *p)
{
	struct vmac_msg m;
	if (vmac_proto_decode(p->data, p->len, &m) != 0 || m.channel != VMAC_CH_DEVICE || m.op != VMAC_OP_REGISTER)
		return BOARD_NONE;
	return boards_by_identity(s, m.u.reg.major, m.u.reg.minor);
}

static void route(struct board_set *s, const struct vmac_packet *p, uint64_t now_ms)
{
	const uint8_t *d = p->data;
	int32_t i;

	if (p->len < VMAC_HDR_LEN || d[0] != VMAC_MAGIC0 || d[1] != VMAC_MAGIC1) {
		s->unroutable++;
		return;
	}
	if (d[3] & VMAC_FLAG_REPLY)
		return; /* another board's answer (raw Ethernet sees them): not for us */
	if (d[10] == VMAC_CH_SYSTEM) {
		if (d[11] == VMAC_SYS_CYCLIC) {
			route_cyclic(s, p, now_ms);
		} else if (d[11] == VMAC_SYS_SYNC) {
			route_sync(s, p, now_ms);
		} else if (d[11] == VMAC_SYS_DISCOVER) {
			/* Rare (once per discovery period): only unknown boards answer. */
			for (i = 0; i < s->count; i++)
				deliver(s, i, p, now_ms);
		} else {
			s->unroutable++;
		}
		return;
	}
	if (s->eth) {
		/* The destination MAC names the board: 02:xx:xx:xx then its number. */
		unsigned number = (unsigned)p->mac[4] << 8 | p->mac[5];
		if (memcmp(p->mac, s->mac_prefix, sizeof(s->mac_prefix)) != 0)
			return; /* a board of another process on this link */
		i = number >= 1 && number <= (unsigned)s->count ? (int32_t)number - 1 : BOARD_NONE;
	} else if (d[11] == VMAC_OP_REGISTER) {
		i = route_register(s, p);
	} else {
		i = s->by_session[d[8] << 8 | d[9]]; /* the low 16 bits of device_id */
	}
	if (i == BOARD_NONE) {
		s->unroutable++;
		return;
	}
	deliver(s, i, p, now_ms);
}

void boards_dispatch(struct board_set *s, struct vmac_packet *pkts, int n, uint64_t now_ms)
{
	int k;
	for (k = 0; k < n; k++)
		route(s, &pkts[k], now_ms);
}

/* The late lines of one flush, written out with one call: a burst of late
 * replies (a whole frame's, when the process was scheduled late) must not
 * cost a write per line and so make the next batch late too. */
static char late_text[1 << 16];
static size_t late_used;

static void late_write(void)
{
	fwrite(late_text, 1, late_used, stdout);
	fflush(stdout);
	late_used = 0;
}

static void report_late(struct board_set *s, int k, int64_t tx_ns)
{
	const struct vmac_packet *p = &s->replies[k];
	unsigned seq = (unsigned)p->data[4] << 8 | p->data[5];
	int n;
	if (sizeof(late_text) - late_used < 200)
		late_write();
	n = snprintf(late_text + late_used, sizeof(late_text) - late_used,
	             "%s: late reply seq %u: request in at %" PRId64 " ns, reply out at %" PRId64 " ns (+%" PRId64
	             " us)\n",
	             s->boards[s->reply_board[k]].board.id.board, seq, p->rx_ns, tx_ns, (tx_ns - p->rx_ns) / 1000);
	if (n > 0 && (size_t)n < sizeof(late_text) - late_used)
		late_used += (size_t)n;
}

void boards_flush(struct board_set *s)
{
	int n = s->nreplies, done, k;

	s->nreplies = 0;
	/* In chunks of one sendmmsg each (the transport's own batch), so that
	 * each reply's time out is its own chunk's, not the last one's. */
	for (done = 0; done < n; done += VMAC_TRANSPORT_BATCH) {
		int chunk = n - done < VMAC_TRANSPORT_BATCH ? n - done : VMAC_TRANSPORT_BATCH;
		int sent = vmac_transport_send(s->transport, s->replies + done, chunk);
		int64_t tx_ns = vmac_now_ns(); /* handed to the kernel: the board's part ends here */
		if (sent < 0)
			sent = 0;
		s->unsent += (uint64_t)(chunk - sent);
		if (s->late_ns <= 0)
			continue;
		/* Only answers on the device channel: the host holds those to a
		 * deadline; an ANNOUNCE has none. */
		for (k = done; k < done + sent; k++) {
			if (tx_ns - s->replies[k].rx_ns > s->late_ns && s->replies[k].data[10] == VMAC_CH_DEVICE) {
				s->late_replies++;
				report_late(s, k, tx_ns);
			}
		}
	}
	if (late_used > 0)
		late_write();
}
