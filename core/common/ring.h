/* Single-producer single-consumer ring of fixed-size messages: how the bus
 * thread and the main thread talk without locks or allocation on the bus path. */
#ifndef VMAC_RING_H
#define VMAC_RING_H

#include <stdatomic.h>
#include <stddef.h>

struct vmac_ring {
	size_t elem_size;
	size_t mask;         /* capacity - 1; capacity is a power of two */
	_Atomic size_t head; /* next slot the producer writes */
	_Atomic size_t tail; /* next slot the consumer reads */
	unsigned char *buf;
};

/* capacity is rounded up to a power of two. Returns 0 or -ENOMEM. */
int vmac_ring_init(struct vmac_ring *r, size_t elem_size, size_t capacity);
void vmac_ring_fini(struct vmac_ring *r);
/* Producer side. Returns 0, or -1 when the ring is full (nothing written). */
int vmac_ring_push(struct vmac_ring *r, const void *elem);
/* Consumer side. Returns 1 with *elem filled, or 0 when empty. */
int vmac_ring_pop(struct vmac_ring *r, void *elem);

/* In place, for large elements: the producer writes into the slot
 * vmac_ring_reserve returns (NULL: full) and publishes it with
 * vmac_ring_commit; the consumer reads the slot vmac_ring_peek returns
 * (NULL: empty) and gives it back with vmac_ring_release. */
void *vmac_ring_reserve(struct vmac_ring *r);
void vmac_ring_commit(struct vmac_ring *r);
void *vmac_ring_peek(struct vmac_ring *r);
void vmac_ring_release(struct vmac_ring *r);

#endif
