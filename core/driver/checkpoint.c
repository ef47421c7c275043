/* Checkpoints of a machine's dev.state (docs/DRIVERS.md "Recovery after a
 * restart"): dev:checkpoint() asks for one; vmac_driver_checkpoint encodes
 * a plain-data copy of dev.state into the caller's buffer (bus thread, no
 * allocation outside the driver's own heap); vmac_driver_offer_checkpoint
 * decodes one into a freshly loaded instance (main thread, before the hand
 * over), and vmac_driver_recover hands it to the driver's recover(dev,
 * saved) after attach.
 *
 * The encoding (version 1), little-endian, written and read only here:
 *   "VMCK" 0x01, then one value:
 *   'F' | 'T'              false, true
 *   'N' f64                a number
 *   'S' u32 len, bytes     a string
 *   '{' (key value)* '}'   a table; tables are numbered 1, 2, ... in the
 *                          order their '{' comes
 *   '@' u32 n              table n again (shared tables and cycles)
 * A key is never nil nor NaN. Functions, coroutines, userdata and light
 * userdata are left out (an entry whose key or value is one disappears), as
 * in a hot reload's copy; at most VMAC_CHECKPOINT_ENTRIES entries and
 * VMAC_CHECKPOINT_DEPTH tables deep. Decoding checks every byte: a damaged
 * checkpoint is refused with the reason, never half taken. */
#include "internal.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../common/errors.h"

#define MAGIC "VMCK"
#define FORMAT 1
#define HEADER 5

/* ---- dev:checkpoint() ---- */

int drv_dev_checkpoint(lua_State *L)
{
	drv_of(L)->checkpoint_asked = 1;
	return 0;
}

int vmac_driver_checkpoint_asked(const struct vmac_driver *d)
{
	return d->checkpoint_asked;
}

/* ---- encoding, in the driver's protection ---- */

struct enc {
	uint8_t *buf;
	size_t cap, len;
	int seen; /* stack index: table -> its number */
	int tables, entries;
	char why[160];
};

/* n more bytes; with buf NULL only counted (would_encode). */
static int put(struct enc *e, const void *p, size_t n)
{
	if (e->cap - e->len < n) {
		snprintf(e->why, sizeof(e->why), "dev.state encodes to more than %zu bytes (checkpoint_kib)", e->cap);
		return -E2BIG;
	}
	if (e->buf)
		memcpy(e->buf + e->len, p, n);
	e->len += n;
	return 0;
}

static int put_u32(struct enc *e, uint32_t v)
{
	uint8_t b[4] = {(uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16), (uint8_t)(v >> 24)};
	return put(e, b, 4);
}

static int put_tag(struct enc *e, char tag)
{
	uint8_t t = (uint8_t)tag;
	return put(e, &t, 1);
}

/* Whether the value at i is plain data (what a checkpoint keeps). */
static int plain(lua_State *L, int i)
{
	int t = lua_type(L, i);
	return t == LUA_TBOOLEAN || t == LUA_TNUMBER || t == LUA_TSTRING || t == LUA_TTABLE;
}

static int enc_value(struct enc *e, lua_State *L, int i, int depth);

static int enc_table(struct enc *e, lua_State *L, int i, int depth)
{
	lua_pushvalue(L, i);
	lua_rawget(L, e->seen);
	if (!lua_isnil(L, -1)) {
		uint32_t n = (uint32_t)lua_tonumber(L, -1);
		lua_pop(L, 1);
		return put_tag(e, '@') || put_u32(e, n);
	}
	lua_pop(L, 1);
	if (depth > VMAC_CHECKPOINT_DEPTH) {
		snprintf(e->why, sizeof(e->why), "dev.state is nested deeper than %d tables", VMAC_CHECKPOINT_DEPTH);
		return -E2BIG;
	}
	luaL_checkstack(L, 4, "checkpoint");
	lua_pushvalue(L, i);
	lua_pushnumber(L, ++e->tables);
	lua_rawset(L, e->seen);
	if (put_tag(e, '{'))
		return -E2BIG;
	lua_pushnil(L);
	while (lua_next(L, i)) {
		int k = lua_gettop(L) - 1, v = k + 1;
		if (plain(L, k) && plain(L, v)) {
			if (++e->entries > VMAC_CHECKPOINT_ENTRIES) {
				snprintf(e->why, sizeof(e->why), "dev.state holds more than %d entries",
				         VMAC_CHECKPOINT_ENTRIES);
				return -E2BIG;
			}
			if (enc_value(e, L, k, depth + 1) || enc_value(e, L, v, depth + 1))
				return -E2BIG;
		}
		lua_pop(L, 1);
	}
	return put_tag(e, '}');
}

static int enc_value(struct enc *e, lua_State *L, int i, int depth)
{
	switch (lua_type(L, i)) {
	case LUA_TBOOLEAN: return put_tag(e, lua_toboolean(L, i) ? 'T' : 'F');
	case LUA_TNUMBER: {
		double x = lua_tonumber(L, i);
		uint64_t u;
		uint8_t b[8];
		int k;
		memcpy(&u, &x, 8);
		for (k = 0; k < 8; k++)
			b[k] = (uint8_t)(u >> (8 * k));
		return put_tag(e, 'N') || put(e, b, 8);
	}
	case LUA_TSTRING: {
		size_t n;
		const char *s = lua_tolstring(L, i, &n); /* a string already: nothing converted */
		return put_tag(e, 'S') || put_u32(e, (uint32_t)n) || put(e, s, n);
	}
	case LUA_TTABLE: return enc_table(e, L, i, depth);
	default: return put_tag(e, 'F'); /* not reached: plain() filters */
	}
}

/* The whole checkpoint of the value at state (a table; anything else is
 * an empty one): 0, or -1 with e->why. [-0, +1] the table of seen tables. */
static int enc_state(struct enc *e, lua_State *L, int state)
{
	lua_newtable(L);
	e->seen = lua_gettop(L);
	if (put(e, MAGIC, 4) || put_tag(e, FORMAT))
		return -E2BIG;
	return lua_istable(L, state) ? enc_table(e, L, state, 0) : (put_tag(e, '{') || put_tag(e, '}'));
}

static int encode_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct enc *e = args;
	lua_State *L = d->L;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_keys);
	lua_rawgeti(L, -1, key_state(d));
	lua_rawget(L, -3);
	if (enc_state(e, L, lua_gettop(L)) != 0) {
		snprintf(err, errlen, "%s", e->why);
		return -E2BIG;
	}
	return 0;
}

int vmac_driver_checkpoint(struct vmac_driver *d, uint8_t *buf, size_t cap, size_t *len, char *err, size_t errlen)
{
	struct enc e;
	int rc;
	memset(&e, 0, sizeof(e));
	e.buf = buf;
	e.cap = cap;
	d->checkpoint_asked = 0;
	*len = 0;
	/* drv_protect_any: a failure here (too large, the cap) fails only the
	 * checkpoint, never the running driver. */
	if (d->failed) {
		snprintf(err, errlen, "%s", d->failure);
		return -VMAC_EDRIVER;
	}
	rc = drv_protect_any(d, encode_work, &e, err, errlen);
	if (rc != 0) /* encode_work's -E2BIG, or the protection's own code (out of memory) */
		return rc < 0 ? rc : -VMAC_EFAIL;
	*len = e.len;
	return 0;
}

/* ---- decoding, into a new instance's state ---- */

struct dec {
	const uint8_t *p, *end;
	int tables; /* stack index: number -> table */
	int ntables, entries;
	char why[160];
};

static int damaged(struct dec *c, const char *what)
{
	snprintf(c->why, sizeof(c->why), "checkpoint damaged: %s", what);
	return -EBADMSG;
}

static int get_u32(struct dec *c, uint32_t *v)
{
	if (c->end - c->p < 4)
		return damaged(c, "ends inside a length");
	*v = (uint32_t)c->p[0] | (uint32_t)c->p[1] << 8 | (uint32_t)c->p[2] << 16 | (uint32_t)c->p[3] << 24;
	c->p += 4;
	return 0;
}

/* [-0, +1]: the value at c->p. */
static int dec_value(struct dec *c, lua_State *L, int depth)
{
	uint8_t tag;
	if (c->p >= c->end)
		return damaged(c, "ends before a value");
	tag = *c->p++;
	luaL_checkstack(L, 4, "checkpoint");
	switch (tag) {
	case 'F': lua_pushboolean(L, 0); return 0;
	case 'T': lua_pushboolean(L, 1); return 0;
	case 'N': {
		uint64_t u = 0;
		double x;
		int k;
		if (c->end - c->p < 8)
			return damaged(c, "ends inside a number");
		for (k = 0; k < 8; k++)
			u |= (uint64_t)c->p[k] << (8 * k);
		c->p += 8;
		memcpy(&x, &u, 8);
		lua_pushnumber(L, x);
		return 0;
	}
	case 'S': {
		uint32_t n;
		if (get_u32(c, &n))
			return -EBADMSG;
		if ((size_t)(c->end - c->p) < n)
			return damaged(c, "ends inside a string");
		lua_pushlstring(L, (const char *)c->p, n);
		c->p += n;
		return 0;
	}
	case '@': {
		uint32_t n;
		if (get_u32(c, &n))
			return -EBADMSG;
		if (n == 0 || n > (uint32_t)c->ntables)
			return damaged(c, "refers to a table not yet seen");
		lua_rawgeti(L, c->tables, (int)n);
		return 0;
	}
	case '{':
		if (depth > VMAC_CHECKPOINT_DEPTH)
			return damaged(c, "tables nested too deep");
		lua_newtable(L);
		lua_pushvalue(L, -1);
		lua_rawseti(L, c->tables, ++c->ntables);
		for (;;) {
			if (c->p >= c->end)
				return damaged(c, "ends inside a table");
			if (*c->p == '}') {
				c->p++;
				return 0;
			}
			if (++c->entries > VMAC_CHECKPOINT_ENTRIES)
				return damaged(c, "too many entries");
			if (dec_value(c, L, depth + 1) || dec_value(c, L, depth + 1))
				return -EBADMSG;
			/* lua_type, not lua_isnumber: that takes the string key "nan" for NaN. */
			if (lua_type(L, -2) == LUA_TNUMBER && lua_tonumber(L, -2) != lua_tonumber(L, -2))
				return damaged(c, "a key is NaN");
			lua_rawset(L, -3);
		}
	default: return damaged(c, "unknown tag");
	}
}

struct offer {
	const uint8_t *buf;
	size_t len;
	const struct vmac_checkpoint_info *info;
};

/* Whether the table at i encodes again in at most cap bytes (counted, not
 * written): 0, or -1 with why. What a checkpoint gives a driver must be
 * what its next checkpoint can hold, and a table the file nests shallow and
 * refers to deep may come first in the encoder's order at the deep place,
 * its whole subtree then deeper than VMAC_CHECKPOINT_DEPTH (found by
 * tests/fuzz/fuzz_checkpoint.c). [-0, +0] */
static int would_encode(lua_State *L, int i, size_t cap, char *why, size_t whylen)
{
	struct enc e;
	int top = lua_gettop(L), rc;
	memset(&e, 0, sizeof(e));
	e.cap = cap;
	rc = enc_state(&e, L, i);
	lua_settop(L, top);
	if (rc)
		snprintf(why, whylen, "checkpoint damaged: its dev.state would not checkpoint again: %s", e.why);
	return rc ? -EBADMSG : 0;
}

/* [-0, +1] on success: the dev.state a checkpoint holds, decoded. */
static int decode_state(lua_State *L, const uint8_t *buf, size_t len, char *err, size_t errlen)
{
	struct dec c;
	memset(&c, 0, sizeof(c));
	c.p = buf + HEADER;
	c.end = buf + len;
	lua_newtable(L);
	c.tables = lua_gettop(L);
	if (dec_value(&c, L, 0) != 0)
		goto fail;
	if (!lua_istable(L, -1)) {
		damaged(&c, "dev.state is not a table");
		goto fail;
	}
	if (c.p != c.end) {
		damaged(&c, "bytes after the end");
		goto fail;
	}
	lua_remove(L, c.tables);
	if (would_encode(L, lua_gettop(L), len, c.why, sizeof(c.why)) != 0)
		goto fail;
	return 0;
fail:
	snprintf(err, errlen, "%s", c.why);
	return -EBADMSG;
}

/* A checkpoint's header: 0, or -1 with err. */
static int check_header(const uint8_t *buf, size_t len, char *err, size_t errlen)
{
	if (len < HEADER || memcmp(buf, MAGIC, 4) != 0) {
		snprintf(err, errlen, "checkpoint damaged: not a vmac checkpoint");
		return -EBADMSG;
	}
	if (buf[4] != FORMAT) {
		snprintf(err, errlen, "checkpoint in format %u, this host reads %u", (unsigned)buf[4], FORMAT);
		return -EPROTONOSUPPORT;
	}
	return 0;
}

static int offer_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	struct offer *o = args;
	lua_State *L = d->L;
	lua_createtable(L, 0, 5); /* saved */
	if (decode_state(L, o->buf, o->len, err, errlen) != 0)
		return -EBADMSG;
	lua_setfield(L, -2, "state");
	lua_pushnumber(L, o->info->age_s);
	lua_setfield(L, -2, "age_s");
	lua_pushstring(L, o->info->version);
	lua_setfield(L, -2, "version");
	lua_pushnumber(L, o->info->time);
	lua_setfield(L, -2, "time");
	lua_pushboolean(L, o->info->restarted);
	lua_setfield(L, -2, "restarted");
	if (d->ref_saved != LUA_NOREF)
		luaL_unref(L, LUA_REGISTRYINDEX, d->ref_saved);
	d->ref_saved = luaL_ref(L, LUA_REGISTRYINDEX);
	return 0;
}

int vmac_driver_offer_checkpoint(struct vmac_driver *d, const uint8_t *buf, size_t len,
                                 const struct vmac_checkpoint_info *info, char *err, size_t errlen)
{
	struct offer o = {buf, len, info};
	int rc = check_header(buf, len, err, errlen);
	if (rc != 0)
		return rc;
	return drv_protect(d, offer_work, &o, err, errlen);
}

/* ---- a replay resuming from a recorded dev.state ---- */

static int resume_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	const struct offer *o = args;
	lua_State *L = d->L;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_migrate);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	if (decode_state(L, o->buf, o->len, err, errlen) != 0)
		return -EBADMSG;
	return drv_guarded_call(d, 2, 0, 1, err, errlen);
}

int vmac_driver_resume_from(struct vmac_driver *d, const uint8_t *buf, size_t len, double time_s, char *err,
                            size_t errlen)
{
	struct offer o = {buf, len, NULL};
	int rc = check_header(buf, len, err, errlen);
	if (rc != 0)
		return rc;
	if (d->ref_migrate == LUA_NOREF)
		return 1;
	d->now_s = time_s;
	return drv_protect(d, resume_work, &o, err, errlen);
}

/* ---- recover(dev, saved) ---- */

static int recover_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	lua_State *L = d->L;
	int saved = d->ref_saved;
	(void)args;
	d->ref_saved = LUA_NOREF;
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_recover);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_rawgeti(L, LUA_REGISTRYINDEX, saved);
	luaL_unref(L, LUA_REGISTRYINDEX, saved);
	return drv_guarded_call(d, 2, 0, 1, err, errlen);
}

static int forget_work(struct vmac_driver *d, void *args, char *err, size_t errlen)
{
	(void)args;
	(void)err;
	(void)errlen;
	luaL_unref(d->L, LUA_REGISTRYINDEX, d->ref_saved);
	d->ref_saved = LUA_NOREF;
	return 0;
}

int vmac_driver_recover(struct vmac_driver *d, double time_s, char *err, size_t errlen)
{
	if (d->ref_saved == LUA_NOREF)
		return VMAC_RECOVER_NONE;
	if (d->ref_recover == LUA_NOREF) {
		drv_protect_quiet(d, forget_work, NULL);
		return VMAC_RECOVER_UNUSED;
	}
	d->now_s = time_s;
	return drv_protect(d, recover_work, NULL, err, errlen) == 0 ? VMAC_RECOVER_DONE : -1;
}
