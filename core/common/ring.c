/* SPSC ring: see ring.h. Acquire/release pairs make the element visible
 * before the index that publishes it. */
#include "ring.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

int vmac_ring_init(struct vmac_ring *r, size_t elem_size, size_t capacity)
{
	size_t cap = 1;
	while (cap < capacity)
		cap <<= 1;
	r->buf = calloc(cap, elem_size);
	if (!r->buf)
		return -ENOMEM;
	r->elem_size = elem_size;
	r->mask = cap - 1;
	atomic_init(&r->head, 0);
	atomic_init(&r->tail, 0);
	return 0;
}

void vmac_ring_fini(struct vmac_ring *r)
{
	free(r->buf);
	r->buf = NULL;
}

void *vmac_ring_reserve(struct vmac_ring *r)
{
	size_t head = atomic_load_explicit(&r->head, memory_order_relaxed);
	size_t tail = atomic_load_explicit(&r->tail, memory_order_acquire);
	if (head - tail > r->mask)
		return NULL;
	return r->buf + (head & r->mask) * r->elem_size;
}

void vmac_ring_commit(struct vmac_ring *r)
{
	size_t head = atomic_load_explicit(&r->head, memory_order_relaxed);
	atomic_store_explicit(&r->head, head + 1, memory_order_release);
}

void *vmac_ring_peek(struct vmac_ring *r)
{
	size_t tail = atomic_load_explicit(&r->tail, memory_order_relaxed);
	size_t head = atomic_load_explicit(&r->head, memory_order_acquire);
	if (tail == head)
		return NULL;
	return r->buf + (tail & r->mask) * r->elem_size;
}

void vmac_ring_release(struct vmac_ring *r)
{
	size_t tail = atomic_load_explicit(&r->tail, memory_order_relaxed);
	atomic_store_explicit(&r->tail, tail + 1, memory_order_release);
}

/* The copying forms, on the in-place ones. */
int vmac_ring_push(struct vmac_ring *r, const void *elem)
{
	void *slot = vmac_ring_reserve(r);
	if (!slot)
		return -1;
	memcpy(slot, elem, r->elem_size);
	vmac_ring_commit(r);
	return 0;
}

int vmac_ring_pop(struct vmac_ring *r, void *elem)
{
	const void *slot = vmac_ring_peek(r);
	if (!slot)
		return 0;
	memcpy(elem, slot, r->elem_size);
	vmac_ring_release(r);
	return 1;
}
