/* The LM3S6965's Ethernet MAC: vmac frames (EtherType 0x88B5) in and out
 * through its FIFOs, each received frame stamped by the receive interrupt
 * (the board's clock takes SYNC by these stamps). Receive: each frame
 * comes out of the FIFO as 32-bit words, the first holding the frame
 * length in its low half (counting the two length bytes and the 4-byte
 * FCS), then the frame from its destination address on, then the FCS.
 * Send: the first word holds the payload length (the frame less its
 * 14-byte header) and the first two destination bytes; the MAC pads to 60
 * bytes and adds the FCS itself. */
#include <string.h>

#include "lm3s6965.h"
#include "mcu.h"

#define RX_FRAME_MAX 1518 /* 14 header + 1500 payload + 4 FCS */
#define TX_PAYLOAD_MAX 1500
#define STAMPS 32 /* a power of two; frames beyond it are stamped as they leave */

static uint8_t our_mac[6];
static struct vmac_mcu_enet_counters counters;
/* One frame as the FIFO words carry it: 2 length bytes, header, payload,
 * FCS; word-aligned so that words go in and out whole. */
static uint32_t frame_words[(2 + RX_FRAME_MAX + 3) / 4];
/* When each frame in the receive FIFO came, oldest first: stamp_head is
 * advanced by the interrupt (or by the main loop, interrupts off), and
 * stamp_tail by the main loop as it takes a frame out. */
static volatile uint64_t stamps[STAMPS];
static volatile uint32_t stamp_head, stamp_tail;

void vmac_mcu_enet_init(const uint8_t mac[6])
{
	SYSCTL_RCGC2 |= SYSCTL_RCGC2_EMAC0 | SYSCTL_RCGC2_EPHY0;
	(void)SYSCTL_RCGC2;
	memcpy(our_mac, mac, sizeof(our_mac));
	MAC_IM = 0;
	MAC_IACK = MAC_INT_ALL;
	MAC_IA0 = (uint32_t)mac[0] | (uint32_t)mac[1] << 8 | (uint32_t)mac[2] << 16 | (uint32_t)mac[3] << 24;
	MAC_IA1 = (uint32_t)mac[4] | (uint32_t)mac[5] << 8;
	MAC_MDV = MAC_MDV_50MHZ;
	MAC_THR = MAC_THR_OFF;
	MAC_TCTL = MAC_TCTL_TXEN | MAC_TCTL_PADEN | MAC_TCTL_CRC | MAC_TCTL_DUPLEX;
	MAC_RCTL = MAC_RCTL_RSTFIFO;
	MAC_RCTL = MAC_RCTL_RXEN; /* our address and broadcasts (no multicast, not promiscuous) */
	/* The interrupt only wakes the main loop, which reads the FIFO. */
	MAC_IM = MAC_INT_RX;
	NVIC_ISER(IRQ_ETHERNET / 32) = 1u << (IRQ_ETHERNET % 32);
}

/* The frames in the FIFO that have no stamp yet get now; interrupts off.
 * Frames that came together share the time of the look after the last of
 * them: late, never early, which the clock's minimum filter is for. */
static void stamp_new_frames(void)
{
	uint32_t in_fifo = MAC_NP & 0x3F;
	uint64_t now;
	if (in_fifo > STAMPS)
		in_fifo = STAMPS; /* a 2 KiB FIFO of 60-byte frames: 31 at most */
	if (stamp_head - stamp_tail > in_fifo)
		stamp_tail = stamp_head - in_fifo; /* never more stamps than frames */
	if (stamp_head - stamp_tail == in_fifo)
		return;
	now = vmac_mcu_now_ns();
	while (stamp_head - stamp_tail < in_fifo)
		stamps[stamp_head++ % STAMPS] = now;
}

void vmac_mcu_enet_handler(void)
{
	uint32_t ris = MAC_RIS;
	if (ris & MAC_INT_FOV)
		counters.overruns++;
	MAC_IACK = ris;
	stamp_new_frames();
}

int vmac_mcu_enet_pending(void)
{
	return (MAC_NP & 0x3F) != 0;
}

static int is_broadcast(const uint8_t *mac)
{
	return (mac[0] & mac[1] & mac[2] & mac[3] & mac[4] & mac[5]) == 0xFF;
}

int vmac_mcu_enet_receive(const uint8_t **payload, uint8_t src[6], uint64_t *rx_ns)
{
	const uint8_t *bytes = (const uint8_t *)frame_words;
	uint32_t first, total, words, i, primask;
	size_t len;
	int declared;

	/* The stamp and the frame leave together, the interrupt kept out:
	 * it counts the stamps against the frames in the FIFO. */
	primask = lm3s_irq_save();
	if (!vmac_mcu_enet_pending()) {
		lm3s_irq_restore(primask);
		return -1;
	}
	stamp_new_frames(); /* one the interrupt has not seen yet */
	*rx_ns = stamps[stamp_tail++ % STAMPS];
	first = MAC_DATA;
	total = first & 0xFFFF; /* 2 length bytes + frame + 4 FCS */
	words = (total + 3) / 4;
	frame_words[0] = first;
	/* The whole frame leaves the FIFO, whatever becomes of it. */
	for (i = 1; i < words; i++) {
		uint32_t w = MAC_DATA;
		if (i < sizeof(frame_words) / 4)
			frame_words[i] = w;
	}
	lm3s_irq_restore(primask);
	counters.received++;
	if (total > sizeof(frame_words) || total < 2 + VMAC_MCU_ETH_HLEN + 4) {
		counters.oversize++;
		return 0;
	}
	len = total - 2 - VMAC_MCU_ETH_HLEN - 4; /* the payload, padding included */
	if (bytes[14] != (VMAC_MCU_ETHERTYPE >> 8) || bytes[15] != (VMAC_MCU_ETHERTYPE & 0xFF) ||
	    (memcmp(bytes + 2, our_mac, 6) != 0 && !is_broadcast(bytes + 2))) {
		counters.not_ours++; /* the MAC filters, but QEMU's model does not */
		return 0;
	}
	/* A payload padded to Ethernet's minimum: its vmac header says where
	 * it ends. Otherwise it goes on as it came, for the decoder to judge. */
	declared = vmac_proto_frame_length(bytes + 16, len);
	if (declared > 0 && (size_t)declared < len)
		len = (size_t)declared;
	memcpy(src, bytes + 8, 6);
	*payload = bytes + 16;
	return (int)len;
}

void vmac_mcu_enet_send(const uint8_t dst[6], const uint8_t *payload, size_t len)
{
	uint8_t *bytes = (uint8_t *)frame_words;
	uint32_t words, i;
	if (len == 0 || len > TX_PAYLOAD_MAX)
		return;
	/* The FIFO holds one frame: wait for the previous one to be gone. */
	while (MAC_TR & MAC_TR_NEWTX)
		;
	bytes[0] = (uint8_t)len;
	bytes[1] = (uint8_t)(len >> 8);
	memcpy(bytes + 2, dst, 6);
	memcpy(bytes + 8, our_mac, 6);
	bytes[14] = VMAC_MCU_ETHERTYPE >> 8;
	bytes[15] = VMAC_MCU_ETHERTYPE & 0xFF;
	memcpy(bytes + 16, payload, len);
	words = (uint32_t)(2 + VMAC_MCU_ETH_HLEN + len + 3) / 4;
	for (i = 0; i < words; i++)
		MAC_DATA = frame_words[i];
	MAC_TR = MAC_TR_NEWTX;
	counters.sent++;
}

const struct vmac_mcu_enet_counters *vmac_mcu_enet_counters(void)
{
	return &counters;
}
