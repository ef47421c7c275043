/* The bounded library functions of the sandbox (docs/DRIVERS.md "The
 * sandbox"): string.rep, find, match, gmatch, gsub, table.sort and insert,
 * each priced before it runs (sort counted as it goes) and refused past
 * PATTERN_STEPS_MAX steps; sandbox.c puts them in the driver's libraries
 * (drv_wrap_bounded).
 *
 * The budget hook runs between VM instructions, so a C library function,
 * once called, runs to its end. Each one whose work can grow faster than
 * what the driver holds, or that LuaJIT lets loop past it, is wrapped here:
 * the wrapper prices the call's worst case in steps before making it, and
 * refuses, naming the function, a call that could take more than
 * PATTERN_STEPS_MAX of them. A step is one character test of the pattern
 * matcher; the STEP_ weights price the rest of the work in those steps,
 * each what that work costs against one character test in LuaJIT
 * (docs/DRIVERS.md, "The sandbox", says what a step is worth in time, and
 * so how long a call let through may run). table.sort alone counts as it
 * goes: LuaJIT's quicksort can be driven to n^2 comparisons, so no price
 * from the table's length alone would be sound without refusing ordinary
 * sorts. What is not wrapped costs time linear in what it is given and
 * what it makes, and so is bounded by the memory cap (docs/DRIVERS.md "The
 * sandbox"). While LuaJIT's own function runs, d->lib_call names it (the
 * host reads it from another thread to say what a stalled driver was
 * doing). */
#include "internal.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define STEP_VISIT 4     /* the matcher visits an item: dispatch, the test, the quantifier */
#define STEP_SET_BYTE 2  /* a test against a [set]: per byte of the set */
#define STEP_BYTES 16    /* bytes memchr and memcmp get through in one step */
#define STEP_PLACE 8     /* a place a plain search tries: a memchr and a memcmp called */
#define STEP_MATCH 16    /* gsub: a match's replacement begun */
#define STEP_OUT 3       /* gsub: a byte added to the result */
#define STEP_CALL 32     /* gsub: a call into Lua or a table lookup made from C for a match */
#define STEP_CAPTURE 16  /* a capture pushed as a string */
#define STEP_COMPARE 96  /* table.sort: a comparison through sort_compare */
#define STEP_CMP_BYTES 4 /* bytes of two strings < compares in a step (lj_str_cmp: 4 at a time) */
#define STEP_MOVE 16     /* one element table.insert moves up */

enum bounded_kind {
	BOUNDED_REP,
	BOUNDED_FIND,
	BOUNDED_MATCH,
	BOUNDED_GMATCH,
	BOUNDED_GSUB,
	BOUNDED_SORT,
	BOUNDED_INSERT
};

/* A wrapped function: upvalue 1 of its closure is LuaJIT's own, upvalue 2
 * (a light userdata) this. */
struct bounded {
	const char *lib, *name, *full; /* "string", "find", "string.find" */
	lua_CFunction wrapper;
	enum bounded_kind kind;
};

static const struct bounded *bounded_of(lua_State *L)
{
	return lua_touserdata(L, lua_upvalueindex(2));
}

/* Call LuaJIT's own function with the arguments on the stack, d->lib_call
 * naming it meanwhile: [-all, +results], returns their number. A library
 * call inside another (a gsub replacement calling find) names the inner one
 * until it returns; after an error the pcall that catches it restores the
 * name (budget_checked_call). */
static int call_original(lua_State *L, const struct bounded *b)
{
	struct vmac_driver *d = drv_of(L);
	const char *outer = d->lib_call;
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	d->lib_call = b->full;
	lua_call(L, lua_gettop(L) - 1, LUA_MULTRET);
	d->lib_call = outer;
	return lua_gettop(L);
}

/* Raise a refusal: luaL_error's own formats have no %zu or %g. */
__attribute__((format(printf, 2, 3))) static int refuse(lua_State *L, const char *fmt, ...)
{
	char text[300];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(text, sizeof(text), fmt, ap);
	va_end(ap);
	return luaL_error(L, "%s", text);
}

/* string.rep bounded by the size of its result (REP_MAX): linear in it. */
static int safe_rep(lua_State *L)
{
	size_t len, seplen = 0;
	lua_Integer n;
	luaL_checklstring(L, 1, &len);
	n = luaL_checkinteger(L, 2);
	luaL_optlstring(L, 3, "", &seplen);
	if (n > 0 && ((double)(len + seplen) * (double)n > REP_MAX || n > REP_MAX))
		return luaL_error(L, "string.rep result too large (limit %d bytes)", REP_MAX);
	return call_original(L, bounded_of(L));
}

/* The index just past the set [...] that starts at p[i]: a ^ and a ] right
 * after the [ belong to the set, %x escapes one character. */
static size_t skip_set(const char *p, size_t plen, size_t i)
{
	i++;
	if (i < plen && p[i] == '^')
		i++;
	if (i < plen && p[i] == ']')
		i++;
	while (i < plen && p[i] != ']')
		i += p[i] == '%' ? 2 : 1;
	return i + 1;
}

/* One item of a pattern, as LuaJIT's matcher takes it. */
struct item {
	size_t end;   /* index just past it and its quantifier */
	double test;  /* one test of it against a character of the subject */
	double visit; /* the matcher's visit of it, its test included */
	char kind;    /* 'c' a capture's ( or ), 'b' %bxy, 'f' %f[set], 'r' a back-reference %1,
	                 '$' the end anchor, 's' one character: a char, ., %x or a [set] */
	char quant;   /* after an 's': '*', '+', '-', '?', or 0 */
};

/* The item that starts at p[i], in a subject of n bytes. */
static struct item next_item(const char *p, size_t plen, size_t i, double n)
{
	struct item it = {i + 1, 1, 0, 's', 0};
	char c = p[i], e = i + 1 < plen ? p[i + 1] : 0;
	if (c == '(' || c == ')') {
		it.kind = 'c';
		it.end += c == '(' && e == ')'; /* () is a position capture */
		it.test = 0;
	} else if (c == '$' && i + 1 == plen) {
		it.kind = '$';
	} else if (c == '%' && e == 'b') { /* scans for the closing one as far as the subject goes */
		it.kind = 'b';
		it.end = i + 4;
		it.test = n;
	} else if (c == '%' && e == 'f') { /* the set tested twice: the previous character and this one */
		it.kind = 'f';
		it.end = i + 2 < plen && p[i + 2] == '[' ? skip_set(p, plen, i + 2) : i + 2;
		it.test = 2.0 * STEP_SET_BYTE * (double)(it.end - i);
	} else if (c == '%' && e >= '0' && e <= '9') { /* compares as much as a capture holds */
		it.kind = 'r';
		it.end = i + 2;
		it.test = n / STEP_BYTES;
	} else {
		if (c == '[') {
			it.end = skip_set(p, plen, i);
			it.test = STEP_SET_BYTE * (double)(it.end - i);
		} else if (c == '%') {
			it.end = i + 2;
		}
		if (it.end < plen && (p[it.end] == '*' || p[it.end] == '+' || p[it.end] == '-' || p[it.end] == '?'))
			it.quant = p[it.end++];
	}
	it.visit = STEP_VISIT + it.test;
	return it;
}

/* Whether the matcher can fail at this item, whatever follows (x*, x-,
 * x? and a capture take what comes; x+ needs one character). */
static int can_fail(const struct item *it)
{
	return it->kind == 'b' || it->kind == 'f' || it->kind == 'r' || it->kind == '$' ||
	       (it->kind == 's' && (it->quant == 0 || it->quant == '+'));
}

/* Whether this item, at p[i], never fails when what follows can match
 * nothing at the end of the subject (follows_empty): .* and .- can always
 * take the subject to its end. */
static int absorbs(const struct item *it, const char *p, size_t i, int follows_empty)
{
	return follows_empty && p[i] == '.' && it->end == i + 2 && (it->quant == '*' || it->quant == '-');
}

/* Whether the rest of the pattern from p[at] on never fails: the first item
 * from there that can fail, or that absorbs (what follows it does not
 * matter then), absorbs; or there is none. Asked at positions that never go
 * back, it reads each item once (next is where the answer changes). */
struct rest_lookup {
	size_t next; /* the first such item at or after the last position asked; plen: none */
	int absorbs; /* that one absorbs (or there is none) */
	int started;
};

static int rest_never_fails(struct rest_lookup *r, const char *p, size_t plen, size_t at, double n, size_t empty_end)
{
	size_t i;
	struct item it;
	if (r->started && at <= r->next)
		return r->absorbs;
	r->started = 1;
	r->next = plen;
	r->absorbs = 1;
	for (i = at; i < plen; i = it.end) {
		it = next_item(p, plen, i, n);
		if (absorbs(&it, p, i, it.end >= empty_end) || can_fail(&it)) {
			r->next = i;
			r->absorbs = !can_fail(&it);
			break;
		}
	}
	return r->absorbs;
}

/* Worst-case steps of one call of the matcher over a subject of n bytes:
 * find or match (one match), one call of a gmatch iterator (the next
 * match), or gsub (every match, each with a replacement of per_match
 * steps, at most max_matches of them). LuaJIT's matcher (lib_string.c)
 * tries each start in turn (one, when the pattern is anchored with ^; a
 * gmatch pattern never is) and at each start walks the items. With v the
 * visit of an item and t one test of it (a [set]: its length), a visit
 * costs
 *
 *   an item, x?, a capture's ( or ), %f[set] (the set twice)    v
 *   x* and x+: take up to n, then try the rest after each count  v + n t
 *   x-: try the rest, then take one more, up to n times          v + n t
 *   %bxy: as far as the subject goes                             v + n
 *   a back-reference %1: a memcmp of up to n bytes               v + n / STEP_BYTES
 *
 * After x*, x+, x- or x? the rest is tried again only when it can fail
 * (rest_never_fails): not when it holds only captures and items with *, -
 * or ?, nor up to a .* or .- that can take the subject to its end; and .*
 * and .+ followed by what can match nothing there succeed at the first
 * try. A pattern in which nothing is tried again (%d+, [^,]*, ^%s*(.*)$) is
 * linear: a start fails, if at all, within the items before the rest
 * never fails (fail_steps), and a match scans only the characters it takes,
 * so the call costs starts x fail_steps + one start's worst (gsub: every
 * start may match, each visiting the items after that point once, and the
 * characters taken add up to n over all matches). In any other pattern an
 * item after j quantifiers that try the rest again is visited once for
 * each way of placing the start and the places where those j stopped, in
 * order, within the subject: C(n + j + 1, j + 1) ways, about
 * n^(j+1) / (j+1)! (anchored: C(n + j, j)); an x? that tries the rest again
 * doubles it. */
static double pattern_cost(const char *p, size_t plen, size_t len, int may_anchor, int gsub, double per_match,
                           double max_matches)
{
	double n = (double)len, starts = n + 1, levels = 1, visits = n + 1;
	double one_start = STEP_VISIT, all, fail_steps = STEP_VISIT, tail = STEP_VISIT, matches;
	size_t i, first = 0, empty_end = 0;
	int linear = 1;
	struct rest_lookup rest = {0, 1, 0};
	struct item it;

	plen = strnlen(p, plen); /* the matcher stops at a \0 */
	if (may_anchor && plen > 0 && p[0] == '^') {
		first = 1;
		starts = visits = 1;
		levels = 0;
	}
	for (i = first; i < plen; i = it.end) { /* where what follows can match nothing */
		it = next_item(p, plen, i, n);
		if (can_fail(&it) && it.kind != '$')
			empty_end = it.end;
	}
	all = visits * STEP_VISIT;
	for (i = first; i < plen; i = it.end) {
		double steps;
		int safe_here, again; /* the rest never fails from here; it is tried again after this item */
		it = next_item(p, plen, i, n);
		safe_here = rest_never_fails(&rest, p, plen, i, n, empty_end);
		again = it.quant && !rest_never_fails(&rest, p, plen, it.end, n, empty_end) &&
		        !(p[i] == '.' && (it.quant == '*' || it.quant == '+') && it.end >= empty_end);
		steps = it.visit;
		if (it.quant == '*' || it.quant == '+' || (it.quant == '-' && again))
			steps += n * it.test;
		if (!safe_here)
			fail_steps += it.quant == '+' ? it.visit : steps;
		else
			tail += it.visit;
		one_start += steps;
		all += visits * steps;
		if (again && it.quant == '?') {
			visits *= 2;
			linear = 0;
		} else if (again) {
			levels++;
			visits *= (n + levels) / levels;
			linear = 0;
		}
	}
	all += visits * STEP_VISIT; /* the end of the pattern */
	if (gsub) {
		matches = max_matches < starts ? max_matches : starts;
		per_match = (matches > 0 ? matches : 0) * (STEP_MATCH + per_match) + starts * STEP_OUT;
	}
	if (!linear)
		return all + (gsub ? per_match : 0);
	one_start += STEP_VISIT;
	if (!gsub)
		return starts * fail_steps + one_start;
	return starts * (fail_steps + tail) + one_start + per_match;
}

/* Whether LuaJIT takes p as a pattern in find (lj_str_haspattern): without
 * any of these characters it searches for it as plain text. */
static int has_specials(const char *p, size_t plen)
{
	size_t i;
	for (i = 0; i < plen; i++)
		switch (p[i]) {
		case '^':
		case '$':
		case '*':
		case '+':
		case '?':
		case '.':
		case '(':
		case '[':
		case '%':
		case '-': return 1;
		}
	return 0;
}

/* A plain search for m bytes in n (lj_str_find): memchr for the first byte,
 * then memcmp of the rest, at up to n - m + 1 places. */
static double plain_cost(size_t n, size_t m)
{
	if (m == 0 || m > n)
		return 1;
	return (double)(n - m + 1) * (STEP_PLACE + (double)m / STEP_BYTES);
}

/* Bytes of the subject from find's and match's init (argument 3) on, as
 * LuaJIT counts them: it takes init as 32 bits, and one that does not fit
 * (which the machine's conversion makes anything) as the whole subject. An
 * init that is no number is LuaJIT's to refuse. */
static size_t subject_from_init(lua_State *L, size_t n)
{
	lua_Number init = lua_isnumber(L, 3) ? lua_tonumber(L, 3) : 1, start;
	if (!(init >= -2147483648.0 && init < 2147483648.0))
		return n;
	start = (lua_Number)(int32_t)init;
	start = start < 0 ? start + (lua_Number)n : start - 1;
	if (start < 0)
		start = 0;
	return start < (lua_Number)n ? n - (size_t)start : 0;
}

/* Steps of one gsub replacement (argument 3): its characters, a capture
 * pushed for each %1 in it, or a call or lookup with the captures. */
static double replacement_cost(lua_State *L, const char *p, size_t plen)
{
	size_t len, i, captures = 0;
	const char *r;
	switch (lua_type(L, 3)) {
	case LUA_TNUMBER: return 32 * STEP_OUT; /* the number's text */
	case LUA_TSTRING:
		r = lua_tolstring(L, 3, &len);
		for (i = 0; i + 1 < len; i++)
			if (r[i] == '%' && r[i + 1] >= '0' && r[i + 1] <= '9')
				captures++;
		return (double)len * STEP_OUT + (double)captures * STEP_CAPTURE;
	case LUA_TFUNCTION:
	case LUA_TTABLE:
		for (i = 0; i < plen; i++)
			captures += p[i] == '(';
		return STEP_CALL + (double)(captures ? captures : 1) * STEP_CAPTURE;
	default: return 0; /* LuaJIT refuses it */
	}
}

/* A gmatch iterator: LuaJIT's (upvalue 1), each call one search of the rest
 * of the subject, priced when gmatch made it. */
static int gmatch_next(lua_State *L)
{
	drv_charge(L, lua_tonumber(L, lua_upvalueindex(3))); /* each call may cost what the pattern was priced at */
	return call_original(L, bounded_of(L));
}

/* string.find, match, gmatch and gsub bounded by pattern_cost (find of
 * plain text: plain_cost). */
static int safe_pattern(lua_State *L)
{
	const struct bounded *b = bounded_of(L);
	size_t n, plen;
	const char *p;
	double steps;
	luaL_checklstring(L, 1, &n);
	p = luaL_checklstring(L, 2, &plen);
	if (b->kind == BOUNDED_FIND && ((lua_gettop(L) >= 4 && lua_toboolean(L, 4)) || !has_specials(p, plen))) {
		size_t from = subject_from_init(L, n);
		steps = plain_cost(from, plen);
		if (steps > PATTERN_STEPS_MAX)
			return refuse(L,
			              "string.find: plain search too costly for %zu bytes in a %zu-byte subject "
			              "(worst case about %.2g steps, over %d): search for a shorter string",
			              plen, from, steps, PATTERN_STEPS_MAX);
		drv_charge(L, steps);
		return call_original(L, b);
	}
	if (b->kind == BOUNDED_GSUB)
		steps = pattern_cost(p, plen, n, 1, 1, replacement_cost(L, p, plen),
		                     lua_isnumber(L, 4) ? lua_tonumber(L, 4) : (double)n + 1);
	else
		steps = pattern_cost(p, plen, b->kind == BOUNDED_GMATCH ? n : subject_from_init(L, n),
		                     b->kind != BOUNDED_GMATCH, 0, 0, 0);
	if (steps > PATTERN_STEPS_MAX)
		return refuse(L,
		              "%s: pattern too costly for a %zu-byte subject (worst case about %.2g steps, over %d): "
		              "use fewer '*', '+', '-', a shorter pattern%s or a shorter string",
		              b->full, n, steps, PATTERN_STEPS_MAX, b->kind == BOUNDED_GSUB ? " or replacement" : "");
	drv_charge(L, steps);
	if (b->kind != BOUNDED_GMATCH)
		return call_original(L, b);
	call_original(L, b);
	lua_pushlightuserdata(L, (void *)b);
	lua_pushnumber(L, steps);
	lua_pushcclosure(L, gmatch_next, 3);
	return 1;
}

/* What table.sort's comparator counts, on safe_sort's stack (nothing can
 * reach the comparator once the sort has returned). */
struct sort_count {
	double steps;
	double unchecked;  /* steps since the wall clock was last looked at (drv_charge) */
	const char *outer; /* d->lib_call around the sort, for the refusal */
};

/* The comparator table.sort is given: upvalue 1 the driver's (or nil: <),
 * upvalue 2 the struct sort_count (a light userdata). */
static int sort_compare(lua_State *L)
{
	struct sort_count *count = lua_touserdata(L, lua_upvalueindex(2));
	int by_less = lua_isnil(L, lua_upvalueindex(1));
	double step = STEP_COMPARE;
	if (by_less && lua_type(L, 1) == LUA_TSTRING && lua_type(L, 2) == LUA_TSTRING) {
		size_t la = lua_objlen(L, 1), lb = lua_objlen(L, 2);
		step += (double)(la < lb ? la : lb) / STEP_CMP_BYTES;
	}
	count->steps += step;
	count->unchecked += step;
	if (count->unchecked >= CHARGE_STEPS) { /* the budget's clock, every so many steps of comparing */
		const char *inner = drv_of(L)->lib_call;
		count->unchecked = 0;
		drv_of(L)->lib_call = count->outer;
		drv_charge(L, CHARGE_STEPS);
		drv_of(L)->lib_call = inner;
	}
	if (count->steps > PATTERN_STEPS_MAX) {
		drv_of(L)->lib_call = count->outer;
		return luaL_error(L,
		                  "table.sort: too costly (over %d steps of comparing): sort fewer or shorter values",
		                  PATTERN_STEPS_MAX);
	}
	if (by_less) {
		lua_pushboolean(L, lua_lessthan(L, 1, 2));
		return 1;
	}
	lua_settop(L, 2);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, 2, 1);
	return 1;
}

/* table.sort counting its comparisons as they come (sort_compare): a
 * comparison costs STEP_COMPARE, two strings compared by < a step more per
 * STEP_CMP_BYTES of the shorter. Counted, not priced beforehand: LuaJIT's
 * quicksort takes its pivot from the middle of three, which an adversary's
 * order drives to n^2 / 4 comparisons. */
static int safe_sort(lua_State *L)
{
	struct sort_count count = {0, 0, drv_of(L)->lib_call};
	luaL_checktype(L, 1, LUA_TTABLE);
	if (!lua_isnoneornil(L, 2))
		luaL_checktype(L, 2, LUA_TFUNCTION);
	lua_settop(L, 2);
	lua_pushlightuserdata(L, &count);
	lua_pushcclosure(L, sort_compare, 2);
	return call_original(L, bounded_of(L));
}

/* table.insert(t, pos, v) moves t[pos..#t] up one, one at a time, from #t
 * down to pos: a pos far below 1 (or past 32 bits, which LuaJIT wraps)
 * loops billions of times over a table that stays small. */
static int safe_insert(lua_State *L)
{
	if (lua_gettop(L) == 3 && lua_istable(L, 1) && lua_isnumber(L, 2)) {
		lua_Number pos = lua_tonumber(L, 2), len = (lua_Number)lua_objlen(L, 1);
		lua_Number moves =
		    pos >= -2147483648.0 && pos < 2147483648.0 ? len + 1 - (lua_Number)(int32_t)pos : 4294967296.0;
		if (moves * STEP_MOVE > PATTERN_STEPS_MAX)
			return refuse(
			    L,
			    "table.insert: too costly (position %.14g of a %.14g-element table: %.14g elements "
			    "to move, over %d steps)",
			    pos, len, moves, PATTERN_STEPS_MAX);
		drv_charge(L, moves * STEP_MOVE);
	}
	return call_original(L, bounded_of(L));
}

/* The wrapped functions: drv_make_env() puts each in its library. */
static const struct bounded bounded[] = {
    {"string", "rep", "string.rep", safe_rep, BOUNDED_REP},
    {"string", "find", "string.find", safe_pattern, BOUNDED_FIND},
    {"string", "match", "string.match", safe_pattern, BOUNDED_MATCH},
    {"string", "gmatch", "string.gmatch", safe_pattern, BOUNDED_GMATCH},
    {"string", "gsub", "string.gsub", safe_pattern, BOUNDED_GSUB},
    {"table", "sort", "table.sort", safe_sort, BOUNDED_SORT},
    {"table", "insert", "table.insert", safe_insert, BOUNDED_INSERT},
    {NULL, NULL, NULL, NULL, BOUNDED_REP},
};

/* Put the bounded functions of lib into the table on top: [-0, +0]. */
void drv_wrap_bounded(lua_State *L, const char *lib)
{
	const struct bounded *b;
	for (b = bounded; b->lib; b++) {
		if (strcmp(b->lib, lib) != 0)
			continue;
		lua_getglobal(L, lib);
		lua_getfield(L, -1, b->name);
		lua_remove(L, -2);
		lua_pushlightuserdata(L, (void *)b);
		lua_pushcclosure(L, b->wrapper, 2);
		lua_setfield(L, -2, b->name);
	}
}
