/* The arena of tests/fuzz/fuzz_arena.h: one mapping, size classes (16-byte
 * steps to 1 KiB, then powers of two), a free list per class threaded
 * through the free chunks, and the bump pointer. Lua hands back the size
 * of every block it frees, so chunks carry no header. Everything the
 * allocator knows is in struct arena and in the mapping, which is all a
 * snapshot copies. Under ASan, free chunks and the bytes past each
 * request are poisoned, so the host's C code reading a Lua string or table
 * past its end is still caught as it would be in the C library's heap. */
#include "fuzz_arena.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "../../core/driver/internal.h"

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#include <sanitizer/asan_interface.h>
#define POISON(p, n) ASAN_POISON_MEMORY_REGION(p, n)
#define UNPOISON(p, n) ASAN_UNPOISON_MEMORY_REGION(p, n)
#endif
#endif
#ifndef POISON
#define POISON(p, n) ((void)(p), (void)(n))
#define UNPOISON(p, n) ((void)(p), (void)(n))
#endif

#define ARENA_BYTES ((size_t)1 << 30) /* address space only: a driver's cap is far less */
#define SMALL_MAX 1024
#define NSMALL (SMALL_MAX / 16)
#define NCLASS (NSMALL + 21) /* then 2 KiB .. 1 GiB */

struct arena {
	char *base;
	size_t top;         /* bytes handed out from base so far */
	void *free[NCLASS]; /* the free chunks of each class, linked through their first word */
};

static struct arena arena, saved;
static char *saved_bytes;            /* the mapping's first saved.top bytes at the snapshot */
static struct vmac_driver saved_drv; /* the C side of the driver at the snapshot */

static int class_of(size_t n)
{
	if (n <= SMALL_MAX)
		return (int)((n + 15) / 16) - (n > 0);
	/* 2 KiB for 1025..2048 bytes, then one class per power of two */
	return NSMALL + (64 - __builtin_clzl((unsigned long)(n - 1))) - 11;
}

static size_t class_size(int c)
{
	return c < NSMALL ? (size_t)(c + 1) * 16 : (size_t)2 * SMALL_MAX << (c - NSMALL);
}

static void map(void)
{
	void *p;
	if (arena.base)
		return;
	p = mmap(NULL, ARENA_BYTES, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
	if (p == MAP_FAILED) {
		perror("fuzz_arena: mmap");
		abort();
	}
	arena.base = p;
}

static void *take(size_t n)
{
	int c = class_of(n);
	char *p;
	if (c >= NCLASS)
		return NULL;
	p = arena.free[c];
	if (p) {
		UNPOISON(p, sizeof(void *));
		arena.free[c] = *(void **)p;
	} else {
		if (arena.top + class_size(c) > ARENA_BYTES)
			return NULL;
		p = arena.base + arena.top;
		arena.top += class_size(c);
	}
	UNPOISON(p, n);
	POISON(p + n, class_size(c) - n);
	return p;
}

static void give(void *p, size_t n)
{
	int c = class_of(n);
	UNPOISON(p, sizeof(void *));
	*(void **)p = arena.free[c];
	arena.free[c] = p;
	POISON((char *)p + sizeof(void *), class_size(c) - sizeof(void *));
	POISON(p, sizeof(void *)); /* the link too: only take() reads it */
}

static void *fuzz_arena_alloc(void *ctx, void *ptr, size_t osize, size_t nsize)
{
	void *q;
	(void)ctx;
	if (nsize == 0) {
		if (ptr)
			give(ptr, osize);
		return NULL;
	}
	if (!ptr)
		return take(nsize);
	if (class_of(osize) == class_of(nsize)) {
		UNPOISON(ptr, nsize);
		POISON((char *)ptr + nsize, class_size(class_of(nsize)) - nsize);
		return ptr;
	}
	q = take(nsize);
	if (!q)
		return nsize < osize ? ptr : NULL; /* a shrink must not fail */
	memcpy(q, ptr, osize < nsize ? osize : nsize);
	give(ptr, osize);
	return q;
}

static struct vmac_driver *kept;

int fuzz_arena_on(void)
{
	static int on = -1;
	if (on < 0) {
		const char *fresh = getenv("VMAC_FUZZ_FRESH");
		on = !(fresh && fresh[0] && strcmp(fresh, "0") != 0);
	}
	return on;
}

void fuzz_arena_prepare(struct vmac_driver_limits *limits)
{
	if (!fuzz_arena_on())
		return;
	map();
	memset(arena.free, 0, sizeof(arena.free));
	arena.top = 0; /* what take() hands out it unpoisons */
	limits->heap = fuzz_arena_alloc;
	limits->heap_ctx = NULL;
}

void fuzz_arena_keep(struct vmac_driver *d)
{
	if (!fuzz_arena_on())
		return;
	saved = arena;
	free(saved_bytes);
	saved_bytes = malloc(arena.top ? arena.top : 1);
	if (!saved_bytes)
		abort();
	/* The poisoned bytes are copied as they are, not read as values. */
	UNPOISON(arena.base, arena.top);
	memcpy(saved_bytes, arena.base, arena.top);
	saved_drv = *d;
	kept = d;
}

struct vmac_driver *fuzz_arena_kept(void)
{
	if (!kept)
		return NULL;
	if (kept->describe != saved_drv.describe)
		free(kept->describe); /* made by a load after the snapshot */
	UNPOISON(arena.base, saved.top);
	memcpy(arena.base, saved_bytes, saved.top);
	arena = saved;
	*kept = saved_drv;
	return kept;
}

void fuzz_arena_done(struct vmac_driver *d)
{
	if (d != kept) /* with the arena on, every driver is the kept one */
		vmac_driver_free(d);
}

struct vmac_driver *fuzz_arena_fixed_driver(const char *target, const char *src, size_t len, size_t memory_bytes,
                                            uint64_t instructions)
{
	struct vmac_driver_limits limits;
	struct vmac_driver *d = fuzz_arena_kept();
	char err[VMAC_DRIVER_ERR_MAX];
	if (d)
		return d;
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = memory_bytes;
	limits.instructions = instructions;
	limits.max_level = 10;
	limits.default_level = 4;
	fuzz_arena_prepare(&limits);
	if (vmac_driver_load_source("fuzz.lua", src, len, &limits, &d, err, sizeof(err)) != 0) {
		fprintf(stderr, "%s: the driver does not load: %s\n", target, err);
		abort();
	}
	fuzz_arena_keep(d);
	return d;
}
