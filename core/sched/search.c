/* The search for an even table (thesis Appendix I, docs/SCHEDULER.md): a
 * depth-first placement of every device, level by level, pruned by Hall's
 * conditions and a memo of dead states, run in bounded steps so that the
 * bus thread can stop and go on at the next slot. Pure computation: no
 * allocation after sched_search_alloc, no OS call. */
#include "sched_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- construction ---- */

int sched_search_alloc(struct search *q, unsigned nrec, unsigned K)
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

void sched_search_free(struct search *q)
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
int sched_finish(const struct vmac_sched *s, struct search *q, unsigned level)
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

/* Set the search up for q->items[0 .. q->nitems). RUN_MORE: go on with
 * search_run. */
int sched_search_start(const struct vmac_sched *s, struct search *q)
{
	unsigned K = s->max_level, N = s->nslots, i, n;
	uint64_t weight_sum = 0;

	for (i = 0; i < q->nitems; i++)
		weight_sum += sched_weight(s, q->items[i].level);
	if (weight_sum > (uint64_t)s->slices * N)
		return RUN_DEAD;
	if (q->nitems == 0)
		return RUN_FOUND;
	sort_items(s, q);
	q->first_last = q->lvl_begin[K]; /* first item of the deepest level */
	q->cap[0] = (int32_t)((weight_sum + N - 1) / N);
	if (q->first_last == 0)
		return sched_finish(s, q, 0) ? RUN_FOUND : RUN_DEAD;

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
int sched_search_run(const struct vmac_sched *s, struct search *q, unsigned *budget)
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
			if (sched_finish(s, q, level)) {
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
