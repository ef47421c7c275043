/* The scheduler's insides, shared by sched.c (admission, switching
 * tables, read access) and search.c (the search for a table); the rest of
 * the host sees only sched.h. Names shared between the two carry sched_. */
#ifndef VMAC_SCHED_INTERNAL_H
#define VMAC_SCHED_INTERNAL_H

#include "sched.h"

#include <stdint.h>

enum rec_state { REC_FREE = 0, REC_WAITING, REC_RUNNING, REC_GHOST };

/* One device. level/offset/slice are its place in the table in force
 * (RUNNING, GHOST); want is the level asked for (WAITING, RUNNING). A GHOST
 * is a removed device whose slices stay reserved, unserviced, until a switch
 * lets them go; it is no longer in the id hash. */
struct rec {
	uint32_t id;
	uint8_t state;
	uint8_t level, want;
	uint16_t slice;
	uint32_t offset;
	uint64_t since;     /* slot_calls when the still pending change was asked */
	int32_t prev, next; /* admission-order list of every non-FREE record */
};

/* A device the search places: its level in the new table, the latest
 * first service it may get, relative to the switch slot T (0 = T itself),
 * and the relative offset that keeps it where it is (-1: none at this
 * level). */
struct item {
	int32_t rec;
	uint8_t level;
	uint32_t deadline;
	int32_t pref;
	uint32_t pos; /* result: relative offset */
};

/* Depth-first search frame of one item. */
struct frame {
	uint64_t key;     /* memo key of the state the frame was opened in */
	uint32_t rmin;    /* lowest candidate the Hall check allows */
	int64_t last_key; /* candidate key tried last (-1: none yet) */
};

#define MEMO_BITS 12

enum search_state { SEARCH_IDLE, SEARCH_RUNNING, SEARCH_FOUND };

/* One search for a new table, with its own scratch so that two can be under
 * way (see plan). All arrays are sized in vmac_sched_new. */
struct search {
	enum search_state state;
	uint64_t gen; /* s->gen it was started under: stale when they differ */
	uint64_t T;   /* the switch slot it plans for */
	int mode;     /* MODE_ALL: every pending change; MODE_ONE: `chosen` only */
	int32_t chosen;
	unsigned nitems, first_last, level, k;
	uint64_t fp; /* hash of the capacity profile of `level` */
	unsigned lvl_begin[VMAC_SCHED_MAX_LEVEL + 2];
	uint64_t fp_exit[VMAC_SCHED_MAX_LEVEL + 1];

	struct item *items;
	int32_t *order; /* items by (level, deadline) */
	int32_t *sorted_tmp;
	struct frame *frames;
	int32_t *item_of_rec;
	uint32_t *count;                  /* counting sort */
	int32_t *cap;                     /* capacity profile of the current level */
	int32_t *unplaced;                /* items of the current level not placed yet, by deadline */
	int32_t *taken;                   /* last level: items given to each slot */
	int32_t *below;                   /* scratch: items with deadline < r */
	uint32_t *reserve;                /* [2^n + t]: deeper items that must start by t < 2^n */
	uint32_t *deep_avail, *deep_hall; /* [n * N + t]: see fill_reach */
	uint64_t *memo_key;
	uint32_t *memo_epoch;
	uint32_t epoch;
};

enum { MODE_ALL = 0, MODE_ONE = 1 };

/* What is known about switching at a row of the block (for the current
 * s->gen: the answer for a row cannot change while nothing else does). */
#define ROW_HOPELESS(mode) (1u << (mode)) /* no table exists */

#define ROW_HARD(mode) (1u << (2 + (mode))) /* the quick search ran out */

#define ROW_TRIED(mode) (1u << (4 + (mode))) /* deep had its turn this round */

struct vmac_sched {
	unsigned slices, max_level, nslots; /* S, K, N = 1 << K */
	unsigned max_devices, nrec;
	struct rec *rec;
	int32_t *free_recs;
	unsigned nfree;
	int32_t head, tail; /* admission list */
	int32_t *hash;      /* id -> record (WAITING, RUNNING); -1 empty */
	unsigned hash_mask;
	int32_t *cell;  /* nslots * slices: record serviced, -1 none */
	uint16_t *load; /* live devices per row */
	unsigned used;  /* slice-slots per block of admitted devices, at want */
	unsigned admitted;
	unsigned pending;
	int have_slot;
	uint64_t last_slot;
	uint64_t slot_calls; /* vmac_sched_slot calls so far: the clock of `since` */
	uint64_t gen;        /* bumped by every change of devices or table */

	struct search quick, deep;
	uint8_t *rows;
	uint64_t rows_gen;
	uint64_t deep_cap, deep_steps; /* steps a deep search may take this round, taken */
	uint64_t *zobrist;             /* [2^n + r]: profile hashing */
	uint16_t *row_load;
	uint32_t *new_offset, *new_slice; /* install, per item */
};

enum { RUN_DEAD, RUN_FOUND, RUN_MORE };

/* sched.c */
unsigned sched_weight(const struct vmac_sched *s, unsigned level);

/* search.c */
int sched_search_alloc(struct search *q, unsigned nrec, unsigned K);
void sched_search_free(struct search *q);
int sched_finish(const struct vmac_sched *s, struct search *q, unsigned level);
int sched_search_start(const struct vmac_sched *s, struct search *q);
int sched_search_run(const struct vmac_sched *s, struct search *q, unsigned *budget);

#endif
