/* The communication scheduler: admission, the even 2^n table of thesis
 * Appendix I, and the switch from one table to the next without postponing
 * any running device. See sched.h for the contract and docs/SCHEDULER.md for
 * the rule and the argument. The search for a table is search.c;
 * sched_internal.h holds what the two share. Used by the bus thread: no
 * allocation after vmac_sched_new, no OS calls, bounded work per call. */
#include "sched_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- small helpers ---- */

unsigned sched_weight(const struct vmac_sched *s, unsigned level)
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
	    !s->new_offset || !s->new_slice || !sched_search_alloc(&s->quick, s->nrec, max_level) ||
	    !sched_search_alloc(&s->deep, s->nrec, max_level)) {
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
	sched_search_free(&s->quick);
	sched_search_free(&s->deep);
	free(s);
}

/* ---- admission ---- */

static int refuse_full(const struct vmac_sched *s, unsigned level, unsigned free_cap, char *err, size_t errlen)
{
	if (err && errlen)
		snprintf(err, errlen,
		         "schedule full: need level %u (1 slice every %u slots, %u slice-slots per block), "
		         "free capacity %u of %u slice-slots per block",
		         level, 1u << level, sched_weight(s, level), free_cap, s->slices * s->nslots);
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
	if (s->used + sched_weight(s, level) > total)
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
	s->used += sched_weight(s, level);
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
	s->used -= sched_weight(s, x->want);
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
	others = s->used - sched_weight(s, x->want);
	if (others + sched_weight(s, level) > total)
		return refuse_full(s, level, total - others, err, errlen);
	if (x->want == level)
		return 0;
	was_pending = is_pending(x);
	s->used = others + sched_weight(s, level);
	x->want = (uint8_t)level;
	if (is_pending(x) && !was_pending)
		x->since = s->slot_calls;
	s->pending += is_pending(x) - was_pending;
	s->gen++;
	return 0;
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
		rc = sched_search_start(s, q);
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
		int rc = quick->state == SEARCH_FOUND ? RUN_FOUND : sched_search_run(s, quick, &budget);
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
		rc = sched_search_run(s, deep, &budget);
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
