/* The communication scheduler: admission, the even 2^n table of thesis
 * Appendix I, and the switch from one table to the next without postponing
 * any running device. See sched.h for the contract and docs/SCHEDULER.md for
 * the rule and the argument. Used by the bus thread: no allocation after
 * vmac_sched_new, no OS calls, bounded work per call. */
#include "sched.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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
#define ROW_HOPELESS(mode) (1u << (mode))    /* no table exists */
#define ROW_HARD(mode) (1u << (2 + (mode)))  /* the quick search ran out */
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

/* ---- small helpers ---- */

static unsigned weight(const struct vmac_sched *s, unsigned level)
{
	return 1u << (s->max_level - level);
}

static int is_pending(const struct rec *r)
{
	return r->state == REC_WAITING || r->state == REC_GHOST || (r->state == REC_RUNNING && r->want != r->level);
}

static uint32_t hash32(uint32_t x)
{
	x ^= x >> 16;
	x *= 0x7feb352dU;
	x ^= x >> 15;
	x *= 0x846ca68bU;
	x ^= x >> 16;
	return x;
}

static uint64_t splitmix64(uint64_t *state)
{
	uint64_t z = (*state += 0x9E3779B97F4A7C15ULL);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
	return z ^ (z >> 31);
}

static int32_t hash_find(const struct vmac_sched *s, uint32_t id)
{
	unsigned i = hash32(id) & s->hash_mask;
	while (s->hash[i] >= 0) {
		if (s->rec[s->hash[i]].id == id)
			return s->hash[i];
		i = (i + 1) & s->hash_mask;
	}
	return -1;
}

static void hash_put(struct vmac_sched *s, int32_t r)
{
	unsigned i = hash32(s->rec[r].id) & s->hash_mask;
	while (s->hash[i] >= 0)
		i = (i + 1) & s->hash_mask;
	s->hash[i] = r;
}

/* Linear probing with backward-shift deletion: no tombstones to build up. */
static void hash_del(struct vmac_sched *s, int32_t r)
{
	unsigned i = hash32(s->rec[r].id) & s->hash_mask, j;
	while (s->hash[i] != r)
		i = (i + 1) & s->hash_mask;
	j = i;
	for (;;) {
		unsigned home;
		j = (j + 1) & s->hash_mask;
		if (s->hash[j] < 0)
			break;
		home = hash32(s->rec[s->hash[j]].id) & s->hash_mask;
		/* move j back to i unless its home lies cyclically in (i, j] */
		if ((i <= j) ? (home <= i || home > j) : (home <= i && home > j)) {
			s->hash[i] = s->hash[j];
			i = j;
		}
	}
	s->hash[i] = -1;
}

static int32_t rec_alloc(struct vmac_sched *s)
{
	int32_t r;
	if (s->nfree == 0)
		return -1;
	r = s->free_recs[--s->nfree];
	memset(&s->rec[r], 0, sizeof(s->rec[r]));
	s->rec[r].prev = s->tail;
	s->rec[r].next = -1;
	if (s->tail >= 0)
		s->rec[s->tail].next = r;
	else
		s->head = r;
	s->tail = r;
	return r;
}

static void rec_release(struct vmac_sched *s, int32_t r)
{
	struct rec *x = &s->rec[r];
	if (x->prev >= 0)
		s->rec[x->prev].next = x->next;
	else
		s->head = x->next;
	if (x->next >= 0)
		s->rec[x->next].prev = x->prev;
	else
		s->tail = x->prev;
	x->state = REC_FREE;
	s->free_recs[s->nfree++] = r;
}

/* Stop servicing x in the table in force (its slices stay reserved). */
static void grid_clear(struct vmac_sched *s, const struct rec *x)
{
	unsigned period = 1u << x->level, row;
	for (row = x->offset; row < s->nslots; row += period) {
		s->cell[row * s->slices + x->slice] = -1;
		s->load[row]--;
	}
}

/* ---- construction ---- */

static int search_alloc(struct search *q, unsigned nrec, unsigned K)
{
	unsigned n = 1u << K;
	q->items = calloc(nrec + 1, sizeof(*q->items));
	q->order = calloc(nrec + 1, sizeof(*q->order));
	q->sorted_tmp = calloc(nrec + 1, sizeof(*q->sorted_tmp));
	q->frames = calloc(nrec + 1, sizeof(*q->frames));
	q->item_of_rec = calloc(nrec, sizeof(*q->item_of_rec));
	q->count = calloc(n + K + 2, sizeof(*q->count));
	q->cap = calloc(n, sizeof(*q->cap));
	q->unplaced = calloc(n, sizeof(*q->unplaced));
	q->taken = calloc(n, sizeof(*q->taken));
	q->below = calloc(n + 1, sizeof(*q->below));
	q->reserve = calloc(2 * n, sizeof(*q->reserve));
	q->deep_avail = calloc((size_t)(K + 1) * n, sizeof(*q->deep_avail));
	q->deep_hall = calloc((size_t)(K + 1) * n, sizeof(*q->deep_hall));
	q->memo_key = calloc(1u << MEMO_BITS, sizeof(*q->memo_key));
	q->memo_epoch = calloc(1u << MEMO_BITS, sizeof(*q->memo_epoch));
	return q->items && q->order && q->sorted_tmp && q->frames && q->item_of_rec && q->count && q->cap &&
	       q->unplaced && q->taken && q->below && q->reserve && q->deep_avail && q->deep_hall && q->memo_key &&
	       q->memo_epoch;
}

static void search_free(struct search *q)
{
	free(q->items);
	free(q->order);
	free(q->sorted_tmp);
	free(q->frames);
	free(q->item_of_rec);
	free(q->count);
	free(q->cap);
	free(q->unplaced);
	free(q->taken);
	free(q->below);
	free(q->reserve);
	free(q->deep_avail);
	free(q->deep_hall);
	free(q->memo_key);
	free(q->memo_epoch);
}

struct vmac_sched *vmac_sched_new(unsigned slices_per_slot, unsigned max_level, unsigned max_devices)
{
	struct vmac_sched *s;
	unsigned n, hash_size = 2, i;
	uint64_t seed = 0x5EED5EEDULL;
	if (slices_per_slot < 1 || slices_per_slot > VMAC_SCHED_MAX_SLICES || max_level > VMAC_SCHED_MAX_LEVEL ||
	    max_devices < 1 || max_devices > 65535)
		return NULL;
	s = calloc(1, sizeof(*s));
	if (!s)
		return NULL;
	s->slices = slices_per_slot;
	s->max_level = max_level;
	s->nslots = n = 1u << max_level;
	s->max_devices = max_devices < slices_per_slot * n ? max_devices : slices_per_slot * n;
	/* A removed device keeps its record until a switch frees its slices;
	 * there are never more of those than devices in the table (<= max):
	 * removals are switched before anything that adds load. */
	s->nrec = 2 * s->max_devices;
	while (hash_size < 2 * s->max_devices)
		hash_size *= 2;
	s->hash_mask = hash_size - 1;
	s->head = s->tail = -1;

	s->rec = calloc(s->nrec, sizeof(*s->rec));
	s->free_recs = calloc(s->nrec, sizeof(*s->free_recs));
	s->hash = calloc(hash_size, sizeof(*s->hash));
	s->cell = calloc((size_t)n * s->slices, sizeof(*s->cell));
	s->load = calloc(n, sizeof(*s->load));
	s->rows = calloc(n, sizeof(*s->rows));
	s->zobrist = calloc(2 * n, sizeof(*s->zobrist));
	s->row_load = calloc(n, sizeof(*s->row_load));
	s->new_offset = calloc(s->nrec + 1, sizeof(*s->new_offset));
	s->new_slice = calloc(s->nrec + 1, sizeof(*s->new_slice));
	if (!s->rec || !s->free_recs || !s->hash || !s->cell || !s->load || !s->rows || !s->zobrist || !s->row_load ||
	    !s->new_offset || !s->new_slice || !search_alloc(&s->quick, s->nrec, max_level) ||
	    !search_alloc(&s->deep, s->nrec, max_level)) {
		vmac_sched_free(s);
		return NULL;
	}
	for (i = 0; i < s->nrec; i++)
		s->free_recs[i] = (int32_t)(s->nrec - 1 - i);
	s->nfree = s->nrec;
	for (i = 0; i < hash_size; i++)
		s->hash[i] = -1;
	for (i = 0; i < n * s->slices; i++)
		s->cell[i] = -1;
	for (i = 0; i < 2 * n; i++)
		s->zobrist[i] = splitmix64(&seed);
	return s;
}

void vmac_sched_free(struct vmac_sched *s)
{
	if (!s)
		return;
	free(s->rec);
	free(s->free_recs);
	free(s->hash);
	free(s->cell);
	free(s->load);
	free(s->rows);
	free(s->zobrist);
	free(s->row_load);
	free(s->new_offset);
	free(s->new_slice);
	search_free(&s->quick);
	search_free(&s->deep);
	free(s);
}

/* ---- admission ---- */

static int refuse_full(const struct vmac_sched *s, unsigned level, unsigned free_cap, char *err, size_t errlen)
{
	if (err && errlen)
		snprintf(err, errlen,
		         "schedule full: need level %u (1 slice every %u slots, %u slice-slots per block), "
		         "free capacity %u of %u slice-slots per block",
		         level, 1u << level, weight(s, level), free_cap, s->slices * s->nslots);
	return -ENOSPC;
}

static int bad_level(const struct vmac_sched *s, unsigned level, char *err, size_t errlen)
{
	if (err && errlen)
		snprintf(err, errlen, "level %u out of range 0..%u", level, s->max_level);
	return -EINVAL;
}

int vmac_sched_add(struct vmac_sched *s, uint32_t device, unsigned level, char *err, size_t errlen)
{
	unsigned total = s->slices * s->nslots;
	int32_t r;
	if (level > s->max_level)
		return bad_level(s, level, err, errlen);
	if (hash_find(s, device) >= 0) {
		if (err && errlen)
			snprintf(err, errlen, "device %u is already scheduled", (unsigned)device);
		return -EEXIST;
	}
	if (s->used + weight(s, level) > total)
		return refuse_full(s, level, total - s->used, err, errlen);
	if (s->admitted >= s->max_devices) {
		if (err && errlen)
			snprintf(err, errlen, "schedule full: %u devices already (max_devices)", s->admitted);
		return -ENOSPC;
	}
	r = rec_alloc(s);
	if (r < 0) { /* cannot happen: see nrec in vmac_sched_new */
		if (err && errlen)
			snprintf(err, errlen, "schedule full: no free device record");
		return -ENOSPC;
	}
	s->rec[r].id = device;
	s->rec[r].state = REC_WAITING;
	s->rec[r].want = (uint8_t)level;
	s->rec[r].since = s->slot_calls;
	hash_put(s, r);
	s->used += weight(s, level);
	s->admitted++;
	s->pending++;
	s->gen++;
	return 0;
}

int vmac_sched_remove(struct vmac_sched *s, uint32_t device)
{
	int32_t r = hash_find(s, device);
	struct rec *x;
	if (r < 0)
		return -ENOENT;
	x = &s->rec[r];
	hash_del(s, r);
	s->used -= weight(s, x->want);
	s->admitted--;
	if (is_pending(x))
		s->pending--;
	s->gen++;
	if (x->state == REC_WAITING) {
		rec_release(s, r);
		return 0;
	}
	grid_clear(s, x);
	x->state = REC_GHOST;
	x->since = s->slot_calls;
	s->pending++;
	return 0;
}

int vmac_sched_set_level(struct vmac_sched *s, uint32_t device, unsigned level, char *err, size_t errlen)
{
	unsigned total = s->slices * s->nslots, others;
	int32_t r = hash_find(s, device);
	struct rec *x;
	int was_pending;
	if (r < 0) {
		if (err && errlen)
			snprintf(err, errlen, "device %u is not scheduled", (unsigned)device);
		return -ENOENT;
	}
	if (level > s->max_level)
		return bad_level(s, level, err, errlen);
	x = &s->rec[r];
	others = s->used - weight(s, x->want);
	if (others + weight(s, level) > total)
		return refuse_full(s, level, total - others, err, errlen);
	if (x->want == level)
		return 0;
	was_pending = is_pending(x);
	s->used = others + weight(s, level);
	x->want = (uint8_t)level;
	if (is_pending(x) && !was_pending)
		x->since = s->slot_calls;
	s->pending += is_pending(x) - was_pending;
	s->gen++;
	return 0;
}

/* ---- the search for a table ----
 *
 * Given a switch slot T and a set of items (level, deadline), find offsets
 * so that every item is first serviced no later than its deadline (relative
 * to T) and the new table is even. Work in relative time (slot T is 0). A
 * level-n item at relative offset r takes one unit of "capacity" of node r
 * at depth n of the binary trie of residues; both children of a node
 * inherit what is left of it, so the capacity profile of depth n + 1 is the
 * depth-n profile written twice (cap[r + 2^n] = cap[r]). The root starts
 * with C = ceil(W / N) units; the table is even exactly when every slot ends
 * with 0 or 1 unit left (loads C or C - 1), and no load exceeds C <= S.
 *
 * Items are placed level by level (ascending n, as the thesis does), each
 * level by deadline. The first candidate for an item is its old place, then
 * the node with most capacity left (the thesis's emptiest slot), later
 * first. A depth-first search backs up when a choice leads nowhere; a memo
 * of dead states (hashed capacity profiles) keeps it from repeating work.
 * Before an item is placed, necessary conditions prune (frame_open): Hall at
 * this level's nodes (the capacity at nodes <= t covers the items that must
 * start by t, deeper ones that must start before 2^n included), and slot by
 * slot, Hall again (the units at slots <= t hold at least what the remaining
 * items must put there) and fill (the units above 1 at slots >= t can still
 * be used up). The deepest level is solved exactly without search
 * (last_level). The search runs in steps and can stop and go on later. */

static void memo_mark(struct search *q, uint64_t key)
{
	unsigned i = (unsigned)(key >> (64 - MEMO_BITS));
	q->memo_key[i] = key;
	q->memo_epoch[i] = q->epoch;
}

static int memo_dead(const struct search *q, uint64_t key)
{
	unsigned i = (unsigned)(key >> (64 - MEMO_BITS));
	return q->memo_epoch[i] == q->epoch && q->memo_key[i] == key;
}

/* Sort items by (level, deadline) into q->order; fill q->lvl_begin. */
static void sort_items(const struct vmac_sched *s, struct search *q)
{
	unsigned i, n, sum, nitems = q->nitems;
	uint32_t *count = q->count;
	memset(count, 0, (s->nslots + 1) * sizeof(*count));
	for (i = 0; i < nitems; i++)
		count[q->items[i].deadline + 1]++;
	for (i = 1; i <= s->nslots; i++)
		count[i] += count[i - 1];
	for (i = 0; i < nitems; i++)
		q->sorted_tmp[count[q->items[i].deadline]++] = (int32_t)i;
	memset(count, 0, (s->max_level + 2) * sizeof(*count));
	for (i = 0; i < nitems; i++)
		count[q->items[i].level + 1]++;
	for (n = 1, sum = 0; n <= s->max_level + 1; n++) {
		sum += count[n];
		count[n] = sum;
	}
	for (n = 0; n <= s->max_level + 1; n++)
		q->lvl_begin[n] = count[n];
	for (i = 0; i < nitems; i++) {
		int32_t it = q->sorted_tmp[i];
		q->order[count[q->items[it].level]++] = it;
	}
}

static uint64_t profile_hash(const struct vmac_sched *s, const struct search *q, unsigned level)
{
	unsigned p = 1u << level, r;
	uint64_t h = 0;
	for (r = 0; r < p; r++)
		h += (uint64_t)q->cap[r] * s->zobrist[p + r];
	return h;
}

/* An item of level j that may be first serviced at p <= D (p < 2^j) is
 * serviced at the slots p + m 2^j. With q = t >> j and r = t mod 2^j:
 *   - at most reach_j(t, D) = 2^(K-j) - q - [r > D] of them are >= t
 *     (when p = D, as late as allowed);
 *   - at least least_j(t, D) = q + [r >= D] of them are <= t (same p).
 * deep_avail[n * N + t] and deep_hall[n * N + t] sum these over the items
 * deeper than n. */
static void fill_reach(const struct vmac_sched *s, struct search *q)
{
	unsigned K = s->max_level, N = s->nslots, j, t, k;
	uint32_t *avail = q->deep_avail + (size_t)K * N; /* level K: nothing deeper */
	uint32_t *hall = q->deep_hall + (size_t)K * N;
	memset(avail, 0, N * sizeof(*avail));
	memset(hall, 0, N * sizeof(*hall));
	for (j = K; j > 0; j--) {
		uint32_t *avail_up = q->deep_avail + (size_t)(j - 1) * N, *hall_up = q->deep_hall + (size_t)(j - 1) * N;
		unsigned cnt = q->lvl_begin[j + 1] - q->lvl_begin[j], p = 1u << j;
		int32_t *below = q->below; /* [r]: items of level j with deadline < r */
		memset(below, 0, (p + 1) * sizeof(*below));
		for (k = q->lvl_begin[j]; k < q->lvl_begin[j + 1]; k++)
			below[q->items[q->order[k]].deadline + 1]++;
		for (t = 1; t <= p; t++)
			below[t] += below[t - 1];
		for (t = 0; t < N; t++) {
			unsigned qt = t >> j, r = t & (p - 1);
			avail_up[t] = avail[t] + cnt * ((N >> j) - qt) - (uint32_t)below[r];
			hall_up[t] = hall[t] + cnt * qt + (uint32_t)below[r + 1];
		}
		avail = avail_up;
		hall = hall_up;
	}
}

/* Enter item k (index in order) in the state before placing it (cap,
 * unplaced). Returns 0 if the state is hopeless, else fills the frame. */
static int frame_open(const struct vmac_sched *s, struct search *q, unsigned k, uint64_t fp)
{
	const struct item *it = &q->items[q->order[k]];
	struct frame *f = &q->frames[k];
	unsigned level = it->level, p = 1u << level, N = s->nslots, t;
	const uint32_t *avail = q->deep_avail + (size_t)level * N, *hall = q->deep_hall + (size_t)level * N;
	int64_t slack = 0, need = 0, unplaced = 0, room = 0;
	long last_bad = -1;
	f->key = fp ^ ((uint64_t)(k + 1) * 0xD6E8FEB86659FD93ULL);
	if (memo_dead(q, f->key))
		return 0;
	/* Hall at this level's nodes */
	for (t = 0; t < p; t++) {
		q->below[t] = (int32_t)unplaced;
		unplaced += q->unplaced[t];
		slack += q->cap[t] - (int64_t)q->reserve[p + t] - q->unplaced[t];
		if (slack < 0)
			goto dead;
		if (slack < 1 && t < it->deadline)
			last_bad = (long)t;
	}
	q->below[p] = (int32_t)unplaced;
	/* Hall slot by slot */
	for (t = 0; t < N; t++) {
		unsigned r = t & (p - 1), qt = t >> level;
		room += q->cap[r];
		if (room < hall[t] + unplaced * qt + q->below[r + 1])
			goto dead;
	}
	/* fill slot by slot */
	for (t = N; t-- > 0;) {
		unsigned r = t & (p - 1), qt = t >> level;
		if (q->cap[r] > 1)
			need += q->cap[r] - 1;
		if (need > avail[t] + unplaced * (int64_t)((N >> level) - qt) - q->below[r])
			goto dead;
	}
	f->rmin = (uint32_t)(last_bad + 1); /* placing below it breaks Hall */
	f->last_key = -1;
	return 1;
dead:
	memo_mark(q, f->key);
	return 0;
}

/* Next candidate of frame k, or -1: the item's old place first, then the
 * node with most capacity left (the thesis's emptiest slot), then the
 * latest. Candidates go in decreasing order of that key; cap is as it was
 * when the frame opened, so "smaller than the last key tried" is the rest. */
static int64_t cand_key(const struct item *it, const int32_t *cap, long r)
{
	return ((int64_t)(r == it->pref) << 40) | ((int64_t)cap[r] << 32) | r;
}

static long frame_next(struct search *q, unsigned k)
{
	const struct item *it = &q->items[q->order[k]];
	struct frame *f = &q->frames[k];
	long best = -1, r;
	int64_t best_key = -1;
	for (r = (long)it->deadline; r >= (long)f->rmin; r--) {
		int64_t key;
		if (q->cap[r] <= 0)
			continue;
		key = cand_key(it, q->cap, r);
		if (f->last_key >= 0 && key >= f->last_key)
			continue; /* tried already */
		if (key > best_key) {
			best_key = key;
			best = r;
		}
	}
	f->last_key = best_key;
	return best;
}

/* Double the profile from level n to n + 1 and count level n + 1's items. */
static void level_up(struct search *q, unsigned n)
{
	unsigned p = 1u << n, k;
	memcpy(q->cap + p, q->cap, p * sizeof(*q->cap));
	memset(q->unplaced, 0, 2 * p * sizeof(*q->unplaced));
	for (k = q->lvl_begin[n + 1]; k < q->lvl_begin[n + 2]; k++)
		q->unplaced[q->items[q->order[k]].deadline]++;
}

/* The deepest level needs no search. Each of its slots t has cap[t] units
 * left; it must take at least cap[t] - 1 and at most cap[t] of the level-K
 * items, each at a slot <= its deadline. Going down from the last slot, an
 * item whose deadline is >= t can go anywhere below too, so which one fills
 * a slot's minimum does not matter for the slots below; take the least
 * flexible (smallest deadline: the newest on a stack). What is left fills
 * the spare units, smallest deadline to lowest free slot. Both steps are
 * exact for deadlines that are prefixes, so this fails only if no
 * assignment exists. First try keeping every item whose old place still
 * has room, then, if that fails, without. */
static int last_level(const struct vmac_sched *s, struct search *q, int keep)
{
	unsigned N = s->nslots, t, k, top = 0, next, first = q->first_last;
	int32_t *taken = q->taken, *stack = q->sorted_tmp;
	memset(taken, 0, N * sizeof(*taken));
	for (k = first; k < q->nitems; k++) {
		struct item *it = &q->items[q->order[k]];
		it->pos = UINT32_MAX;
		if (keep && it->pref >= 0 && taken[it->pref] < q->cap[it->pref]) {
			it->pos = (uint32_t)it->pref;
			taken[it->pref]++;
		}
	}
	next = q->nitems; /* items are sorted by deadline: walk down */
	for (t = N; t-- > 0;) {
		int32_t need = q->cap[t] - 1 - taken[t];
		while (next > first && q->items[q->order[next - 1]].deadline >= t) {
			next--;
			if (q->items[q->order[next]].pos == UINT32_MAX)
				stack[top++] = q->order[next];
		}
		for (; need > 0; need--) {
			if (top == 0)
				return 0;
			q->items[stack[--top]].pos = t;
			taken[t]++;
		}
	}
	for (t = 0; top > 0; t++) { /* stack top = smallest deadline left */
		struct item *it = &q->items[stack[top - 1]];
		while (t < N && taken[t] >= q->cap[t])
			t++;
		if (t >= N || t > it->deadline)
			return 0;
		it->pos = t;
		taken[t]++;
		top--;
	}
	return 1;
}

/* All items above the deepest level are placed: finish with last_level. */
static int finish(const struct vmac_sched *s, struct search *q, unsigned level)
{
	for (; level < s->max_level; level++)
		memcpy(q->cap + (1u << level), q->cap, (1u << level) * sizeof(*q->cap));
	return last_level(s, q, 1) || last_level(s, q, 0);
}

/* Going back from an item to the one before, of a lower level: forget the
 * deeper levels' counts and take the profile hash the lower level had when
 * it was left (the profile itself is intact: a deeper level only writes the
 * copies above 2^level, and has undone its own placements). */
static uint64_t back_up(struct search *q, unsigned *level, unsigned to, uint64_t fp)
{
	if (*level == to)
		return fp;
	while (*level > to) {
		memset(q->unplaced, 0, (1u << *level) * sizeof(*q->unplaced));
		(*level)--;
	}
	return q->fp_exit[to];
}

/* Undo the placement of item k. */
static uint64_t unplace(const struct vmac_sched *s, struct search *q, unsigned k, unsigned level, uint64_t fp)
{
	const struct item *it = &q->items[q->order[k]];
	q->cap[it->pos]++;
	q->unplaced[it->deadline]++;
	return fp + s->zobrist[(1u << level) + it->pos];
}

enum { RUN_DEAD, RUN_FOUND, RUN_MORE };

/* Set the search up for q->items[0 .. q->nitems). RUN_MORE: go on with
 * search_run. */
static int search_start(const struct vmac_sched *s, struct search *q)
{
	unsigned K = s->max_level, N = s->nslots, i, n;
	uint64_t weight_sum = 0;

	for (i = 0; i < q->nitems; i++)
		weight_sum += weight(s, q->items[i].level);
	if (weight_sum > (uint64_t)s->slices * N)
		return RUN_DEAD;
	if (q->nitems == 0)
		return RUN_FOUND;
	sort_items(s, q);
	q->first_last = q->lvl_begin[K]; /* first item of the deepest level */
	q->cap[0] = (int32_t)((weight_sum + N - 1) / N);
	if (q->first_last == 0)
		return finish(s, q, 0) ? RUN_FOUND : RUN_DEAD;

	memset(q->reserve, 0, 2 * N * sizeof(*q->reserve));
	for (i = 0; i < q->nitems; i++) {
		const struct item *it = &q->items[i];
		for (n = 0; n < it->level && it->deadline >= (1u << n); n++)
			;
		for (; n < it->level; n++)
			q->reserve[(1u << n) + it->deadline]++;
	}
	fill_reach(s, q);
	if (++q->epoch == 0) { /* wrapped: forget every old mark */
		memset(q->memo_epoch, 0, (1u << MEMO_BITS) * sizeof(*q->memo_epoch));
		q->epoch = 1;
	}

	/* enter the level of the first item; empty levels are passed by level_up */
	q->unplaced[0] = (int32_t)q->lvl_begin[1];
	q->level = 0;
	while (q->level < q->items[q->order[0]].level)
		level_up(q, q->level++);
	q->fp = profile_hash(s, q, q->level);
	q->k = 0;
	return frame_open(s, q, 0, q->fp) ? RUN_MORE : RUN_DEAD;
}

/* Run the search for at most *budget steps (one candidate each). RUN_FOUND
 * fills items[].pos; RUN_MORE keeps the state in q for the next call. */
static int search_run(const struct vmac_sched *s, struct search *q, unsigned *budget)
{
	unsigned k = q->k, level = q->level;
	uint64_t fp = q->fp;
	int rc = RUN_MORE;
	while (*budget > 0) {
		struct item *it = &q->items[q->order[k]];
		long r;
		(*budget)--;
		r = frame_next(q, k);
		if (r < 0) {
			/* frame k exhausted: its state is dead; back up to k - 1 */
			memo_mark(q, q->frames[k].key);
			if (k == 0) {
				rc = RUN_DEAD;
				break;
			}
			k--;
			fp = back_up(q, &level, q->items[q->order[k]].level, fp);
			fp = unplace(s, q, k, level, fp);
			continue;
		}
		it->pos = (uint32_t)r;
		q->cap[r]--;
		q->unplaced[it->deadline]--;
		fp -= s->zobrist[(1u << level) + (unsigned)r];
		if (k + 1 == q->first_last) {
			if (finish(s, q, level)) {
				rc = RUN_FOUND;
				break;
			}
			fp = unplace(s, q, k, level, fp); /* and try k's next candidate */
			continue;
		}
		k++;
		if (q->items[q->order[k]].level != level) {
			q->fp_exit[level] = fp;
			while (level < q->items[q->order[k]].level)
				level_up(q, level++);
			fp = profile_hash(s, q, level);
		}
		if (!frame_open(s, q, k, fp)) {
			/* hopeless: try item k - 1's next candidate */
			k--;
			fp = back_up(q, &level, q->items[q->order[k]].level, fp);
			fp = unplace(s, q, k, level, fp);
		}
	}
	q->k = k;
	q->level = level;
	q->fp = fp;
	return rc;
}

/* ---- switching tables ---- */

/* How many slots after T the next service at `offset`, `level` comes
 * (0: at T itself). */
static uint32_t rel_offset(uint64_t T, uint32_t offset, unsigned level)
{
	uint32_t mask = (1u << level) - 1;
	return (offset - (uint32_t)(T & mask)) & mask;
}

/* Fill q->items for a switch at slot T: with MODE_ALL every pending change
 * at once, with MODE_ONE only the change of record `chosen` (the others
 * wait; their devices keep their places and levels). A running device's
 * deadline is its next service in the table in force: a switch never
 * postpones it (for a new level: the first service at the new level comes
 * no later than the next one at the old). */
static void build_items(const struct vmac_sched *s, struct search *q, uint64_t T, int mode, int32_t chosen)
{
	unsigned nitems = 0;
	int32_t r;
	for (r = s->head; r >= 0; r = s->rec[r].next) {
		const struct rec *x = &s->rec[r];
		int change = mode == MODE_ALL || r == chosen;
		struct item *it = &q->items[nitems];
		unsigned level;
		uint32_t a = 0;
		q->item_of_rec[r] = -1;
		if (x->state == REC_RUNNING || x->state == REC_GHOST)
			a = rel_offset(T, x->offset, x->level);
		if (x->state == REC_RUNNING) {
			level = change ? x->want : x->level;
			it->deadline = a < (1u << level) ? a : (1u << level) - 1;
			it->pref = level == x->level ? (int32_t)a : -1;
		} else if (x->state == REC_GHOST) {
			if (change)
				continue; /* removed for good */
			level = x->level;
			it->deadline = (1u << level) - 1; /* not serviced: anywhere will do */
			it->pref = (int32_t)a;
		} else { /* WAITING */
			if (!change)
				continue;
			level = x->want;
			it->deadline = (1u << level) - 1;
			it->pref = -1;
		}
		it->rec = r;
		it->level = (uint8_t)level;
		q->item_of_rec[r] = (int32_t)nitems++;
	}
	q->nitems = nitems;
	q->T = T;
	q->mode = mode;
	q->chosen = chosen;
	q->gen = s->gen;
}

/* Check the search's answer once more (deadlines, capacity, evenness) and
 * put it in force from slot q->T. Slices: devices in ascending level, then
 * in admission order, each takes the lowest slice free in its rows; all
 * rows of a device's class hold the same devices of lower or equal level,
 * so that slice is the same in every one of its rows and below the row's
 * load. Returns 0, or -1 and changes nothing. */
static int install(struct vmac_sched *s, const struct search *q)
{
	unsigned N = s->nslots, S = s->slices, level, row, i, lo = ~0u, hi = 0;
	int32_t r, next;
	memset(s->row_load, 0, N * sizeof(*s->row_load));
	for (i = 0; i < q->nitems; i++) {
		const struct item *it = &q->items[i];
		if (it->pos > it->deadline)
			return -1;
		s->new_offset[i] = (uint32_t)((it->pos + q->T) & ((1u << it->level) - 1));
	}
	for (level = 0; level <= s->max_level; level++) {
		for (r = s->head; r >= 0; r = s->rec[r].next) {
			int32_t i2 = q->item_of_rec[r];
			uint32_t off;
			if (i2 < 0 || q->items[i2].level != level)
				continue;
			off = s->new_offset[i2];
			s->new_slice[i2] = s->row_load[off];
			for (row = off; row < N; row += 1u << level) {
				if (++s->row_load[row] > S)
					return -1;
			}
		}
	}
	for (row = 0; row < N; row++) {
		lo = s->row_load[row] < lo ? s->row_load[row] : lo;
		hi = s->row_load[row] > hi ? s->row_load[row] : hi;
	}
	if (q->nitems && hi - lo > 1)
		return -1;

	/* commit */
	for (i = 0; i < N * S; i++)
		s->cell[i] = -1;
	memset(s->load, 0, N * sizeof(*s->load));
	s->pending = 0;
	for (r = s->head; r >= 0; r = next) {
		struct rec *x = &s->rec[r];
		int32_t i2 = q->item_of_rec[r];
		next = x->next;
		if (i2 < 0) {
			if (x->state == REC_GHOST) {
				rec_release(s, r);
				continue;
			}
		} else {
			x->level = q->items[i2].level;
			x->offset = s->new_offset[i2];
			x->slice = (uint16_t)s->new_slice[i2];
			if (x->state == REC_WAITING)
				x->state = REC_RUNNING;
			if (x->state == REC_RUNNING) {
				for (row = x->offset; row < N; row += 1u << x->level) {
					s->cell[row * S + x->slice] = r;
					s->load[row]++;
				}
			}
		}
		s->pending += is_pending(x);
	}
	s->gen++;
	return 0;
}

/* The change to switch alone when switching them all at once does not
 * work: removals first, then level changes that free capacity, then those
 * that take some, then new devices (so capacity is never short on the way);
 * oldest first. */
static int32_t pick_change(const struct vmac_sched *s)
{
	int32_t r, best = -1;
	int best_class = 4;
	for (r = s->head; r >= 0; r = s->rec[r].next) {
		const struct rec *x = &s->rec[r];
		int cls;
		if (!is_pending(x))
			continue;
		cls = x->state == REC_GHOST ? 0 : x->state == REC_WAITING ? 3 : x->want > x->level ? 1 : 2;
		if (cls < best_class || (cls == best_class && x->since < s->rec[best].since)) {
			best = r;
			best_class = cls;
		}
	}
	return best;
}

/* Steps of search one search may take per slot: bounds the work of a
 * vmac_sched_slot call (two searches, each step O(N + devices)). */
static unsigned slot_budget(const struct vmac_sched *s)
{
	return 256 + 2 * (s->nrec - s->nfree);
}

/* Start search q for a switch at slot T, in mode `mode` or, if that is
 * ruled out at T's row (`skip`: row flags that rule a mode out), the next
 * one. Returns the mode started, or -1. */
static int start_at(struct vmac_sched *s, struct search *q, uint64_t T, int mode, int last_mode,
                    unsigned (*skip)(int mode))
{
	uint8_t *row = &s->rows[T & (s->nslots - 1)];
	for (; mode <= last_mode; mode++) {
		int rc;
		if (*row & skip(mode))
			continue;
		if (mode == MODE_ONE && s->pending < 2)
			break; /* the same as MODE_ALL */
		build_items(s, q, T, mode, mode == MODE_ALL ? -1 : pick_change(s));
		rc = search_start(s, q);
		if (rc == RUN_DEAD) {
			*row |= (uint8_t)ROW_HOPELESS(mode);
			continue;
		}
		q->state = rc == RUN_FOUND ? SEARCH_FOUND : SEARCH_RUNNING;
		return mode;
	}
	q->state = SEARCH_IDLE;
	return -1;
}

static unsigned skip_known(int mode) /* quick: every row once per mode */
{
	return ROW_HOPELESS(mode) | ROW_HARD(mode);
}

static unsigned skip_not_hard(int mode) /* deep: rows where quick ran out */
{
	return ROW_HOPELESS(mode) | ROW_TRIED(mode);
}

/* Work toward a switch; called at the start of each slot while changes are
 * pending. Two searches, each with a bounded number of steps per slot:
 *   - quick: a fresh search for a switch at this very slot, which must
 *     finish within this call. What it learns about the row (no table at
 *     all, or ran out of steps) is kept until something changes (s->gen);
 *   - deep: for a row where quick ran out of steps, a search that goes on
 *     across slots. Its table depends on the row only (every period divides
 *     the block), so it is put in force at the next slot of that row, a
 *     block later if need be. Hard rows take turns, each up to deep_cap
 *     steps per round; the cap doubles every round (iterative deepening), so
 *     a row that has a table gets it found in the end.
 * Every row is tried by quick within one block of slots. */
static void plan(struct vmac_sched *s, uint64_t slot)
{
	struct search *quick = &s->quick, *deep = &s->deep;
	unsigned N = s->nslots, budget;
	int mode;
	if (s->rows_gen != s->gen) {
		memset(s->rows, 0, N);
		s->rows_gen = s->gen;
		s->deep_cap = 16 * slot_budget(s);
	}
	if (deep->state != SEARCH_IDLE && deep->gen != s->gen)
		deep->state = SEARCH_IDLE;
	while (deep->state != SEARCH_IDLE && deep->T < slot)
		deep->T += N; /* its row comes again every block */

	if (deep->state == SEARCH_FOUND && deep->T == slot) {
		deep->state = SEARCH_IDLE;
		if (install(s, deep) == 0)
			return;
	}

	budget = slot_budget(s);
	for (mode = start_at(s, quick, slot, MODE_ALL, MODE_ONE, skip_known); mode >= 0;) {
		int rc = quick->state == SEARCH_FOUND ? RUN_FOUND : search_run(s, quick, &budget);
		quick->state = SEARCH_IDLE;
		if (rc == RUN_FOUND && install(s, quick) == 0)
			return;
		s->rows[slot & (N - 1)] |= (uint8_t)(rc == RUN_MORE ? ROW_HARD(mode) : ROW_HOPELESS(mode));
		if (mode == MODE_ONE || budget == 0)
			break;
		mode = start_at(s, quick, slot, MODE_ONE, MODE_ONE, skip_known);
	}

	if (deep->state == SEARCH_IDLE) {
		unsigned round, d;
		for (round = 0; round < 2 && deep->state == SEARCH_IDLE; round++) {
			int any_hard = 0;
			for (d = 1; d <= N && deep->state == SEARCH_IDLE; d++) {
				uint64_t T = slot + d;
				uint8_t r = s->rows[T & (N - 1)];
				for (mode = MODE_ALL; mode <= MODE_ONE && deep->state == SEARCH_IDLE; mode++) {
					if (!(r & ROW_HARD(mode)) || (r & ROW_HOPELESS(mode)))
						continue;
					any_hard = 1;
					if (start_at(s, deep, T, mode, mode, skip_not_hard) >= 0)
						s->deep_steps = 0;
				}
			}
			if (deep->state != SEARCH_IDLE || !any_hard)
				break;
			/* every hard row had its turn: next round, twice the steps */
			for (d = 0; d < N; d++)
				s->rows[d] &= (uint8_t) ~(ROW_TRIED(MODE_ALL) | ROW_TRIED(MODE_ONE));
			s->deep_cap = s->deep_cap < UINT32_MAX / 2 ? 2 * s->deep_cap : UINT32_MAX;
		}
	}
	if (deep->state == SEARCH_RUNNING) {
		int rc;
		budget = slot_budget(s);
		s->deep_steps += budget;
		rc = search_run(s, deep, &budget);
		s->deep_steps -= budget;
		if (rc == RUN_FOUND) {
			deep->state = SEARCH_FOUND;
		} else if (rc == RUN_DEAD) {
			s->rows[deep->T & (N - 1)] |= (uint8_t)ROW_HOPELESS(deep->mode);
			deep->state = SEARCH_IDLE;
		} else if (s->deep_steps >= s->deep_cap) {
			s->rows[deep->T & (N - 1)] |= (uint8_t)ROW_TRIED(deep->mode);
			deep->state = SEARCH_IDLE;
		}
	}
}

int vmac_sched_slot(struct vmac_sched *s, uint64_t slot, struct vmac_sched_entry *out, int max)
{
	unsigned row, i, S = s->slices;
	int n = 0;
	if (s->have_slot && slot <= s->last_slot)
		return -EINVAL;
	s->have_slot = 1;
	s->last_slot = slot;
	s->slot_calls++;
	if (s->pending)
		plan(s, slot);
	row = (unsigned)(slot & (s->nslots - 1));
	if ((int)s->load[row] > max)
		return -ENOBUFS;
	for (i = 0; i < S; i++) {
		int32_t r = s->cell[row * S + i];
		if (r < 0)
			continue;
		out[n].device = s->rec[r].id;
		out[n].slice = (uint16_t)i;
		out[n].level = s->rec[r].level;
		n++;
	}
	return n;
}

/* ---- read access ---- */

unsigned vmac_sched_slices(const struct vmac_sched *s)
{
	return s->slices;
}

unsigned vmac_sched_max_level(const struct vmac_sched *s)
{
	return s->max_level;
}

unsigned vmac_sched_load(const struct vmac_sched *s, unsigned row)
{
	return row < s->nslots ? s->load[row] : 0;
}

void vmac_sched_capacity(const struct vmac_sched *s, unsigned *used, unsigned *total)
{
	if (used)
		*used = s->used;
	if (total)
		*total = s->slices * s->nslots;
}

static void describe(const struct rec *x, struct vmac_sched_device *out)
{
	memset(out, 0, sizeof(*out));
	out->device = x->id;
	out->want_level = x->want;
	if (x->state == REC_WAITING) {
		out->state = VMAC_SCHED_WAITING;
		return;
	}
	out->state = VMAC_SCHED_RUNNING;
	out->level = x->level;
	out->offset = x->offset;
	out->slice = x->slice;
}

int vmac_sched_device(const struct vmac_sched *s, uint32_t device, struct vmac_sched_device *out)
{
	int32_t r = hash_find(s, device);
	if (r < 0)
		return -ENOENT;
	describe(&s->rec[r], out);
	return 0;
}

int vmac_sched_devices(const struct vmac_sched *s, struct vmac_sched_device *out, int max)
{
	int n = 0;
	int32_t r;
	for (r = s->head; r >= 0; r = s->rec[r].next) {
		if (s->rec[r].state == REC_GHOST)
			continue;
		if (n < max)
			describe(&s->rec[r], &out[n]);
		n++;
	}
	return n;
}

unsigned vmac_sched_pending(const struct vmac_sched *s, uint64_t *waited_slots)
{
	if (waited_slots) {
		uint64_t oldest = s->slot_calls;
		int32_t r;
		for (r = s->head; r >= 0; r = s->rec[r].next)
			if (is_pending(&s->rec[r]) && s->rec[r].since < oldest)
				oldest = s->rec[r].since;
		*waited_slots = s->slot_calls - oldest;
	}
	return s->pending;
}
