/* Unit tests of checkpoints (docs/DRIVERS.md "Recovery after a restart"):
 * dev.state encoded by one instance and recovered by another with every
 * plain value, shared table and cycle intact and everything else left out;
 * the limits (checkpoint_kib, depth, entries, a heap at its cap) failing
 * only the checkpoint; every damaged input refused cleanly; recover()'s
 * outcomes and dev:checkpoint()'s flag; the store keeping the newest
 * checkpoint per machine. White-box (core/driver/internal.h) where the test
 * must put userdata into dev.state or set a heap's cap, which no driver can. */
#include <check.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../core/driver/internal.h"
#include "../../core/store/store.h"
#include "check_main.h"

#define BUF_CAP (256 * 1024)

static struct vmac_driver_limits limits;
static uint8_t buf[BUF_CAP];
static size_t buf_len;

static void setup(void)
{
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = 1 << 20;
	limits.instructions = 2000000;
	limits.max_level = 10;
	limits.default_level = 4;
	limits.expect_name = "t";
	buf_len = 0;
}

static struct vmac_driver *load_ok(const char *text)
{
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(vmac_driver_load_source("t.lua", text, strlen(text), &limits, &d, err, sizeof(err)) == 0,
	              "load failed: %s", err);
	ck_assert_int_eq(vmac_driver_add_board(d, 0, "b0"), 0);
	return d;
}

/* A driver whose attach runs body with dev in scope. */
static struct vmac_driver *attached_with(const char *body)
{
	char text[4096], err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_driver *d;
	snprintf(text, sizeof(text),
	         "return { name = 't', version = '1.2.3', io = {},\n"
	         "  attach = function(dev) %s end,\n"
	         "  tick = function(dev) dev.state.ticks = (dev.state.ticks or 0) + 1 end }",
	         body);
	d = load_ok(text);
	ck_assert_msg(vmac_driver_attach(d, 0, err, sizeof(err)) == 0, "attach (%s) failed: %s", body, err);
	return d;
}

static int tick(struct vmac_driver *d, double t, char *err, size_t errlen)
{
	struct vmac_inputs in;
	struct vmac_outputs out;
	const struct vmac_inputs *ins[1] = {&in};
	struct vmac_outputs *outs[1] = {&out};
	memset(&in, 0, sizeof(in));
	return vmac_driver_tick(d, t, ins, outs, err, errlen);
}

static void tick_ok(struct vmac_driver *d, const char *where)
{
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(tick(d, 1, err, sizeof(err)) == 0, "%s: a tick failed: %s", where, err);
}

static void says(const char *err, const char *want, const char *where)
{
	ck_assert_msg(strstr(err, want) != NULL, "%s: error '%s' does not say '%s'", where, err, want);
}

/* d's dev.state into buf (buf_len); the checkpoint must succeed. */
static void checkpoint_ok(struct vmac_driver *d, const char *where)
{
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(vmac_driver_checkpoint(d, buf, sizeof(buf), &buf_len, err, sizeof(err)) == 0,
	              "%s: checkpoint failed: %s", where, err);
	ck_assert_msg(buf_len >= 7 && memcmp(buf, "VMCK\x01", 5) == 0, "%s: checkpoint of %zu bytes has no header",
	              where, buf_len);
}

static const struct vmac_checkpoint_info info = {1700000000.5, 12.25, "1.2.3", 1};

/* ---- the round trip ---- */

/* Every kind of plain value and key, sharing and cycles, and what must be
 * left out: functions, coroutines, function keys, metatables. */
#define RICH_STATE                                                                                                     \
	"local s = dev.state\n"                                                                                        \
	"s.yes, s.no = true, false\n"                                                                                  \
	"s.int, s.neg, s.frac, s.huge, s.tiny, s.nz = 42, -17, 0.1, 1e308, 5e-324, -0.0\n"                             \
	"s.v_nan, s.v_inf, s.v_ninf = 0/0, math.huge, -math.huge\n"                                                    \
	"s.bin, s.empty = 'a\\0b\\255\\254\\0', ''\n"                                                                  \
	"s.nest = { a = { b = { c = { d = 'deep' } } } }\n"                                                            \
	"local shared = { n = 1 }\n"                                                                                   \
	"s.one, s.two, s.list = shared, shared, { shared, 'x' }\n"                                                     \
	"s.self = s\n"                                                                                                 \
	"local a, b = { name = 'a' }, { name = 'b' }\n"                                                                \
	"a.next, b.next = b, a\n"                                                                                      \
	"s.ring = a\n"                                                                                                 \
	"s[1], s[2], s[3], s[-5], s[2.5], s[2^53] = 'one', 'two', 'three', 'minus five', 'two and a half', 'big'\n"    \
	"s['1'], s['nan'], s['inf'], s['k\\0ey'] = 'string one', 'string nan', 'string inf', 'nul key'\n"              \
	"s[true], s[false] = 'T', 'F'\n"                                                                               \
	"local tk = { k = 1 }\n"                                                                                       \
	"s[tk], s.tk = 'table key', tk\n"                                                                              \
	"s.fn = function() end\n"                                                                                      \
	"s.co = coroutine.create(s.fn)\n"                                                                              \
	"s[s.fn] = 'function key'\n"                                                                                   \
	"s.mixed = { function() end, 2, f = function() end, g = 'kept' }\n"                                            \
	"s.obj = setmetatable({ x = 2 }, { __index = function() return 'm' end })\n"

/* Checks saved in Lua; raises naming what was lost. 37 top-level keys
 * (RICH_STATE's 35, put_userdata's udlist, the writer's ticks) and 13
 * tables reachable from the state. */
static const char *const rich_reader =
    "local function check(ok, what) if not ok then error('checkpoint lost: ' .. what, 2) end end\n"
    "return { name = 't', version = '2', io = {}, variables = { checked = {} },\n"
    "  tick = function(dev) end,\n"
    "  recover = function(dev, saved)\n"
    "    local s = saved.state\n"
    "    check(saved.age_s == 12.25, 'age_s ' .. tostring(saved.age_s))\n"
    "    check(saved.version == '1.2.3', 'version ' .. tostring(saved.version))\n"
    "    check(saved.time == 1700000000.5, 'time ' .. tostring(saved.time))\n"
    "    check(saved.restarted == true, 'restarted ' .. tostring(saved.restarted))\n"
    "    check(s.yes == true and s.no == false, 'booleans')\n"
    "    check(s.int == 42 and s.neg == -17 and s.frac == 0.1, 'numbers')\n"
    "    check(s.huge == 1e308 and s.tiny == 5e-324 and s.tiny > 0, 'huge and denormal numbers')\n"
    "    check(s.nz == 0 and 1 / s.nz == -math.huge, 'negative zero')\n"
    "    check(type(s.v_nan) == 'number' and s.v_nan ~= s.v_nan, 'NaN as a value')\n"
    "    check(s.v_inf == math.huge and s.v_ninf == -math.huge, 'infinities')\n"
    "    check(s.bin == 'a\\0b\\255\\254\\0' and #s.bin == 6, 'string with NULs and non-UTF-8 bytes')\n"
    "    check(s.empty == '', 'empty string')\n"
    "    check(s.nest.a.b.c.d == 'deep', 'nested tables')\n"
    "    check(s.one == s.two and s.list[1] == s.one and s.one.n == 1 and s.list[2] == 'x', 'shared table')\n"
    "    check(s.self == s, 'the cycle back to dev.state')\n"
    "    check(s.ring.name == 'a' and s.ring.next.name == 'b' and s.ring.next.next == s.ring, 'two-table cycle')\n"
    "    check(s[1] == 'one' and s[2] == 'two' and s[3] == 'three', 'array part')\n"
    "    check(s[-5] == 'minus five' and s[2.5] == 'two and a half' and s[2^53] == 'big', 'number keys')\n"
    "    check(s['1'] == 'string one', 'string key \"1\" apart from 1')\n"
    "    check(s['nan'] == 'string nan' and s['inf'] == 'string inf', 'string keys nan and inf')\n"
    "    check(s['k\\0ey'] == 'nul key', 'a key with a NUL')\n"
    "    check(s[true] == 'T' and s[false] == 'F', 'boolean keys')\n"
    "    check(type(s.tk) == 'table' and s[s.tk] == 'table key' and s.tk.k == 1, 'a table key is s.tk itself')\n"
    "    check(s.fn == nil and s.co == nil, 'function and coroutine left out')\n"
    "    check(s.ud == nil and s.lud == nil and next(s.udlist) == nil, 'userdata left out')\n"
    "    check(s.mixed[1] == nil and s.mixed[2] == 2 and s.mixed.f == nil and s.mixed.g == 'kept', 'mixed')\n"
    "    check(s.obj.x == 2 and getmetatable(s.obj) == nil and s.obj.y == nil, 'metatable left out')\n"
    "    local seen, tables = {}, 0\n"
    "    local function walk(t)\n"
    "      if seen[t] then return end\n"
    "      seen[t], tables = true, tables + 1\n"
    "      check(getmetatable(t) == nil, 'a metatable was kept')\n"
    "      for k, v in pairs(t) do\n"
    "        for _, x in ipairs({ k, v }) do\n"
    "          local ty = type(x)\n"
    "          check(ty == 'boolean' or ty == 'number' or ty == 'string' or ty == 'table', 'a ' .. ty .. ' kept')\n"
    "          if ty == 'table' then walk(x) end\n"
    "        end\n"
    "      end\n"
    "    end\n"
    "    walk(s)\n"
    "    local n = 0\n"
    "    for _ in pairs(s) do n = n + 1 end\n"
    "    check(n == 37, 'top-level keys: ' .. n .. ', not 37')\n"
    "    check(tables == 13, 'tables: ' .. tables .. ', not 13')\n"
    "    dev.vars.checked = n\n"
    "  end }";

/* Userdata no driver can make: full userdata as a value and a key, light
 * userdata, and a table holding only userdata (it stays, empty). */
static int put_userdata(lua_State *L)
{
	struct vmac_driver *d = lua_touserdata(L, 1);
	lua_rawgeti(L, LUA_REGISTRYINDEX, d->ref_dev);
	lua_pushstring(L, "state");
	lua_rawget(L, -2);
	if (!lua_istable(L, -1))
		return luaL_error(L, "dev.state is not a table");
	lua_newuserdata(L, 16);
	lua_pushvalue(L, -1);
	lua_setfield(L, -3, "ud");
	lua_pushstring(L, "userdata key");
	lua_rawset(L, -3);
	lua_pushlightuserdata(L, d);
	lua_setfield(L, -2, "lud");
	lua_newtable(L);
	lua_newuserdata(L, 8);
	lua_rawseti(L, -2, 1);
	lua_setfield(L, -2, "udlist");
	return 0;
}

static const struct vmac_variable *var(const struct vmac_driver *d, const char *name)
{
	int i;
	for (i = 0; i < vmac_driver_nvars(d); i++)
		if (strcmp(vmac_driver_variable(d, i)->name, name) == 0)
			return vmac_driver_variable(d, i);
	ck_abort_msg("no variable %s", name);
	return NULL;
}

START_TEST(round_trip_keeps_plain_data_sharing_and_cycles)
{
	struct vmac_driver *w = attached_with(RICH_STATE), *r;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int rc;
	ck_assert_msg(lua_cpcall(w->L, put_userdata, w) == 0, "could not put userdata into dev.state");
	tick_ok(w, "writer");
	checkpoint_ok(w, "the rich state");
	tick_ok(w, "writer after the checkpoint");

	r = load_ok(rich_reader);
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &info, err, sizeof(err)) == 0,
	              "a valid checkpoint of %zu bytes was refused: %s", buf_len, err);
	ck_assert_msg(vmac_driver_attach(r, 2, err, sizeof(err)) == 0, "reader attach: %s", err);
	rc = vmac_driver_recover(r, 2, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_DONE, "recover returned %d, not DONE: %s", rc, err);
	tick_ok(r, "reader after recover");
	ck_assert_msg(var(r, "checked")->value.number == 37, "recover's checks did not all run (checked = %g)",
	              var(r, "checked")->value.number);
	rc = vmac_driver_recover(r, 3, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_NONE, "a second recover returned %d: the checkpoint is handed over once", rc);
	vmac_driver_free(w);
	vmac_driver_free(r);
}
END_TEST

START_TEST(restarted_false_and_version_arrive_as_given)
{
	struct vmac_driver *w = attached_with("dev.state.n = 7"), *r;
	struct vmac_checkpoint_info same_run = {1234.5, 0.5, "0.9-beta", 0};
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int rc;
	checkpoint_ok(w, "small state");
	r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end,\n"
	            "  recover = function(dev, saved)\n"
	            "    assert(saved.restarted == false, 'restarted: ' .. tostring(saved.restarted))\n"
	            "    assert(saved.version == '0.9-beta', 'version: ' .. tostring(saved.version))\n"
	            "    assert(saved.age_s == 0.5 and saved.time == 1234.5, 'age_s, time')\n"
	            "    assert(saved.state.n == 7, 'state.n')\n"
	            "  end }");
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &same_run, err, sizeof(err)) == 0, "offer: %s",
	              err);
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_DONE, "recover returned %d: %s", rc, err);
	vmac_driver_free(w);
	vmac_driver_free(r);
}
END_TEST

/* ---- limits ---- */

START_TEST(over_checkpoint_kib_fails_only_the_checkpoint)
{
	struct vmac_driver *d = attached_with("dev.state.big = string.rep('x', 5000)");
	char err[VMAC_DRIVER_ERR_MAX] = "";
	size_t len = 99, exact;
	ck_assert_msg(vmac_driver_checkpoint(d, buf, 4096, &len, err, sizeof(err)) == -E2BIG,
	              "5000 bytes of state fitted into 4096");
	says(err, "checkpoint_kib", "over the cap");
	says(err, "4096", "over the cap");
	ck_assert_msg(len == 0, "a failed checkpoint says %zu bytes used", len);
	tick_ok(d, "after a checkpoint too large");
	/* The boundary: exactly its size fits, one byte less does not. */
	checkpoint_ok(d, "with room");
	exact = buf_len;
	ck_assert_msg(vmac_driver_checkpoint(d, buf, exact, &len, err, sizeof(err)) == 0 && len == exact,
	              "a checkpoint of %zu bytes did not fit into exactly %zu: %s", len, exact, err);
	ck_assert_msg(vmac_driver_checkpoint(d, buf, exact - 1, &len, err, sizeof(err)) == -E2BIG,
	              "a checkpoint of %zu bytes fitted into %zu", exact, exact - 1);
	ck_assert_msg(vmac_driver_checkpoint(d, buf, 3, &len, err, sizeof(err)) == -E2BIG, "the header fitted 3 bytes");
	tick_ok(d, "after the boundary");
	vmac_driver_free(d);
}
END_TEST

START_TEST(depth_limit_is_the_same_both_ways)
{
	char body[200], err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_driver *d, *r;
	size_t len;
	/* VMAC_CHECKPOINT_DEPTH tables below dev.state: saved, and read back. */
	snprintf(body, sizeof(body), "local t = dev.state for i = 1, %d do t.next = {} t = t.next end t.end_ = true",
	         VMAC_CHECKPOINT_DEPTH);
	d = attached_with(body);
	checkpoint_ok(d, "at the depth limit");
	r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end,\n"
	            "  recover = function(dev, saved)\n"
	            "    local t, n = saved.state, 0 while t.next do t, n = t.next, n + 1 end\n"
	            "    assert(n == 32 and t.end_ == true, 'depth ' .. n)\n"
	            "  end }");
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &info, err, sizeof(err)) == 0,
	              "the decoder refused what the encoder wrote at the depth limit: %s", err);
	ck_assert_msg(vmac_driver_recover(r, 0, err, sizeof(err)) == VMAC_RECOVER_DONE, "recover: %s", err);
	vmac_driver_free(d);
	vmac_driver_free(r);
	/* One deeper: refused, the driver runs on. */
	snprintf(body, sizeof(body), "local t = dev.state for i = 1, %d do t.next = {} t = t.next end",
	         VMAC_CHECKPOINT_DEPTH + 1);
	d = attached_with(body);
	ck_assert_msg(vmac_driver_checkpoint(d, buf, sizeof(buf), &len, err, sizeof(err)) == -E2BIG,
	              "a state %d deep was saved", VMAC_CHECKPOINT_DEPTH + 1);
	says(err, "deeper than 32", "too deep");
	tick_ok(d, "after a checkpoint too deep");
	vmac_driver_free(d);
}
END_TEST

START_TEST(entry_limit_is_the_same_both_ways)
{
	char body[200], err[VMAC_DRIVER_ERR_MAX] = "";
	struct vmac_driver *d, *r;
	size_t len;
	snprintf(body, sizeof(body), "for i = 1, %d do dev.state[i] = i end", VMAC_CHECKPOINT_ENTRIES);
	d = attached_with(body);
	checkpoint_ok(d, "at the entry limit");
	r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end,\n"
	            "  recover = function(dev, saved) assert(#saved.state == 10000, 'entries') end }");
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &info, err, sizeof(err)) == 0,
	              "the decoder refused what the encoder wrote at the entry limit: %s", err);
	ck_assert_msg(vmac_driver_recover(r, 0, err, sizeof(err)) == VMAC_RECOVER_DONE, "recover: %s", err);
	vmac_driver_free(d);
	vmac_driver_free(r);
	/* One more, in a nested table: entries count over all tables. */
	snprintf(body, sizeof(body), "for i = 1, %d do dev.state[i] = i end dev.state.more = {}",
	         VMAC_CHECKPOINT_ENTRIES - 1);
	d = attached_with(body);
	checkpoint_ok(d, "exactly at the limit with a nested table");
	vmac_driver_free(d);
	snprintf(body, sizeof(body), "for i = 1, %d do dev.state[i] = i end dev.state.more = { 1 }",
	         VMAC_CHECKPOINT_ENTRIES - 1);
	d = attached_with(body);
	ck_assert_msg(vmac_driver_checkpoint(d, buf, sizeof(buf), &len, err, sizeof(err)) == -E2BIG,
	              "%d entries were saved", VMAC_CHECKPOINT_ENTRIES + 1);
	says(err, "more than 10000 entries", "too many entries");
	tick_ok(d, "after a checkpoint of too many entries");
	vmac_driver_free(d);
}
END_TEST

START_TEST(a_heap_at_its_cap_fails_only_the_checkpoint)
{
	struct vmac_driver *d = attached_with("for i = 1, 3000 do dev.state[i] = { i, tostring(i) } end");
	char err[VMAC_DRIVER_ERR_MAX] = "";
	size_t cap = d->cap, len;
	int rc;
	/* At the cap, the host's reserve left: the checkpoint may work or not. */
	d->cap = d->used;
	rc = vmac_driver_checkpoint(d, buf, sizeof(buf), &len, err, sizeof(err));
	ck_assert_msg(rc == 0 || strstr(err, "memory cap exceeded") != NULL, "at the cap: rc %d, error '%s'", rc, err);
	/* Past the reserve too: nothing can be allocated, it must fail. */
	ck_assert_msg(d->used > HOST_RESERVE, "the state holds less than the reserve");
	d->cap = d->used - HOST_RESERVE;
	err[0] = 0;
	ck_assert_msg(vmac_driver_checkpoint(d, buf, sizeof(buf), &len, err, sizeof(err)) < 0,
	              "a checkpoint with no memory at all succeeded");
	says(err, "memory cap exceeded", "past the reserve");
	d->cap = cap;
	tick_ok(d, "after the checkpoint that ran out of memory");
	checkpoint_ok(d, "with the cap back");
	vmac_driver_free(d);
}
END_TEST

/* ---- damaged input ---- */

/* A reader whose recover accepts any table; it counts in dev.state. */
static const char *const any_reader =
    "return { name = 't', version = '2', io = {}, tick = function() end,\n"
    "  recover = function(dev, saved)\n"
    "    assert(type(saved.state) == 'table', 'saved.state is a ' .. type(saved.state))\n"
    "    dev.state.recovered = (dev.state.recovered or 0) + 1\n"
    "  end }";

/* Offer len bytes of p: must fail, with an error saying want, and leave
 * nothing to recover. */
static void refused(struct vmac_driver *r, const void *p, size_t len, const char *want, const char *what)
{
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int rc;
	ck_assert_msg(vmac_driver_offer_checkpoint(r, p, len, &info, err, sizeof(err)) < 0, "%s (%zu bytes) was taken",
	              what, len);
	says(err, want, what);
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_NONE, "%s: recover returned %d after a refused offer (%s)", what, rc, err);
}

static void taken(struct vmac_driver *r, const void *p, size_t len, const char *what)
{
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int rc;
	ck_assert_msg(vmac_driver_offer_checkpoint(r, p, len, &info, err, sizeof(err)) == 0, "%s was refused: %s", what,
	              err);
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_DONE, "%s: recover returned %d: %s", what, rc, err);
}

START_TEST(every_truncation_is_refused)
{
	struct vmac_driver *w = attached_with(RICH_STATE), *r = load_ok(any_reader);
	char what[64];
	size_t n;
	checkpoint_ok(w, "the rich state");
	for (n = 0; n < buf_len; n++) {
		snprintf(what, sizeof(what), "the first %zu of %zu bytes", n, buf_len);
		refused(r, buf, n, n < 5 ? "checkpoint damaged: not a vmac checkpoint" : "checkpoint damaged", what);
	}
	taken(r, buf, buf_len, "the whole checkpoint after every truncation");
	tick_ok(r, "the reader after every truncation");
	vmac_driver_free(w);
	vmac_driver_free(r);
}
END_TEST

/* Hand-made checkpoints: C strings, their length without the final NUL. */
#define CK(s) s, sizeof(s) - 1
#define NAN_BITS "\x00\x00\x00\x00\x00\x00\xf8\x7f"

START_TEST(malformed_checkpoints_are_refused_with_the_reason)
{
	struct vmac_driver *r = load_ok(any_reader);
	static uint8_t deep[2 * 1000 + 16], many[2 + 10 * (VMAC_CHECKPOINT_ENTRIES + 1) + 16];
	size_t n = 0;
	int i;
	refused(r, CK(""), "not a vmac checkpoint", "nothing");
	refused(r, CK("VMCX\x01{}"), "checkpoint damaged: not a vmac checkpoint", "bad magic");
	refused(r, CK("VMCK\x02{}"), "checkpoint in format 2, this host reads 1", "format 2");
	refused(r, CK("VMCK\x00{}"), "checkpoint in format 0", "format 0");
	refused(r, CK("VMCK\x01"), "checkpoint damaged: ends before a value", "a header alone");
	refused(r, CK("VMCK\x01Z"), "checkpoint damaged: unknown tag", "an unknown tag at the top");
	refused(r, CK("VMCK\x01{SZ"), "checkpoint damaged: ends inside a length", "a string length cut");
	refused(r, CK("VMCK\x01{S\x01\x00\x00\x00kZ}"), "checkpoint damaged: unknown tag", "an unknown tag inside");
	refused(r, CK("VMCK\x01{S\x01\x00\x00\x00k@\x02\x00\x00\x00}"), "checkpoint damaged: refers to a table not yet",
	        "'@' to table 2 of 1");
	refused(r, CK("VMCK\x01{S\x01\x00\x00\x00k@\x00\x00\x00\x00}"), "checkpoint damaged: refers to a table not yet",
	        "'@' to table 0");
	refused(r, CK("VMCK\x01{S\x01\x00\x00\x00k@\xff\xff\xff\xff}"), "checkpoint damaged: refers to a table not yet",
	        "'@' to table 2^32-1");
	refused(r, CK("VMCK\x01@\x01\x00\x00\x00"), "checkpoint damaged: refers to a table not yet", "'@' at the top");
	refused(r, CK("VMCK\x01{}x"), "checkpoint damaged: bytes after the end", "a byte after the end");
	refused(r, CK("VMCK\x01{}{}"), "checkpoint damaged: bytes after the end", "a second table after the end");
	refused(r, CK("VMCK\x01{N" NAN_BITS "T}"), "checkpoint damaged: a key is NaN", "a NaN key");
	refused(r, CK("VMCK\x01T"), "checkpoint damaged: dev.state is not a table", "true at the top");
	refused(r, CK("VMCK\x01N\x00\x00\x00\x00\x00\x00\xf0\x3f"), "checkpoint damaged: dev.state is not a table",
	        "a number at the top");
	refused(r, CK("VMCK\x01S\x00\x00\x00\x00"), "checkpoint damaged: dev.state is not a table", "a string at top");
	refused(r, CK("VMCK\x01{S\xff\xff\xff\xffxy}"), "checkpoint damaged: ends inside a string", "a huge string");
	refused(r, CK("VMCK\x01{N\x00\x00}"), "checkpoint damaged: ends inside a number", "a number cut");
	refused(r, CK("VMCK\x01{TT"), "checkpoint damaged: ends inside a table", "a table never closed");
	refused(r, CK("VMCK\x01{T}"), "checkpoint damaged", "a key without its value");
	refused(r, CK("VMCK\x01}"), "checkpoint damaged: unknown tag", "a '}' alone");
	/* 1000 tables deep: refused at the limit, no stack overflow. */
	memcpy(deep, "VMCK\x01", 5);
	n = 5;
	deep[n++] = '{';
	for (i = 0; i < 1000; i++) {
		deep[n++] = 'T';
		deep[n++] = '{';
	}
	refused(r, deep, n, "checkpoint damaged: tables nested too deep", "1000 tables deep");
	/* One entry over the limit. */
	memcpy(many, "VMCK\x01{", 6);
	n = 6;
	for (i = 0; i <= VMAC_CHECKPOINT_ENTRIES; i++) {
		double key = i;
		many[n++] = 'N';
		memcpy(many + n, &key, 8); /* little-endian hosts only, as the format */
		n += 8;
		many[n++] = 'T';
	}
	many[n++] = '}';
	refused(r, many, n, "checkpoint damaged: too many entries", "10001 entries");
	/* What is well formed is taken: a self-reference, the limit exactly, keys
	 * that are strings Lua could read as numbers. */
	taken(r, CK("VMCK\x01{S\x04\x00\x00\x00self@\x01\x00\x00\x00}"), "a table referring to itself");
	many[n - 11] = '}'; /* the last entry dropped */
	taken(r, many, n - 10, "10000 entries");
	taken(r, CK("VMCK\x01{S\x03\x00\x00\x00nanTS\x04\x00\x00\x00-infT}"), "string keys 'nan' and '-inf'");
	tick_ok(r, "the reader after the malformed checkpoints");
	ck_assert_msg(r->failed == 0 && r->broken == 0, "the reader was marked failed: %s", r->failure);
	vmac_driver_free(r);
}
END_TEST

/* A table the file nests shallow and refers to deep: the encoder may reach
 * it first at the deep place, and its whole chain then lies deeper than
 * VMAC_CHECKPOINT_DEPTH. Such a checkpoint is refused, for what a driver is
 * given must checkpoint again (found by tests/fuzz/fuzz_checkpoint.c).
 * Root {[first] = A, [second] = B}: A a chain of 30 tables, B a chain of 30
 * whose innermost refers to A. Which key the encoder takes first is
 * LuaJIT's hash order, so both orders of the keys are offered: one of them
 * is refused, and whatever is taken checkpoints again. */
static size_t chain(uint8_t *p, int ref)
{
	size_t n = 0;
	int i;
	p[n++] = '{';
	for (i = 1; i < 30; i++) {
		p[n++] = 'T';
		p[n++] = '{';
	}
	if (ref) {
		p[n++] = 'F';
		p[n++] = '@';
		memcpy(p + n, "\x02\x00\x00\x00", 4); /* table 2: A, after the root */
		n += 4;
	}
	for (i = 0; i < 30; i++)
		p[n++] = '}';
	return n;
}

START_TEST(a_checkpoint_taken_checkpoints_again)
{
	struct vmac_driver *r;
	uint8_t ck[512], again[512];
	char err[VMAC_DRIVER_ERR_MAX];
	int order, refusals = 0;
	for (order = 0; order < 2; order++) {
		double first = order ? 2 : 1, second = order ? 1 : 2;
		size_t n = 0, len;
		memcpy(ck, "VMCK\x01{N", 7);
		n = 7;
		memcpy(ck + n, &first, 8); /* little-endian hosts only, as the format */
		n += 8;
		n += chain(ck + n, 0);
		ck[n++] = 'N';
		memcpy(ck + n, &second, 8);
		n += 8;
		n += chain(ck + n, 1);
		ck[n++] = '}';
		r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end,\n"
		            "  recover = function(dev, saved) dev.state = saved.state end }");
		err[0] = 0;
		if (vmac_driver_offer_checkpoint(r, ck, n, &info, err, sizeof(err)) != 0) {
			says(err,
			     "checkpoint damaged: its dev.state would not checkpoint again: dev.state is nested deeper",
			     "a table shallow in the file, deep in the encoder's order");
			refusals++;
		} else {
			ck_assert_msg(vmac_driver_recover(r, 0, err, sizeof(err)) == VMAC_RECOVER_DONE, "recover: %s",
			              err);
			ck_assert_msg(vmac_driver_checkpoint(r, again, sizeof(again), &len, err, sizeof(err)) == 0,
			              "keys in order %d: a checkpoint taken does not checkpoint again: %s", order, err);
		}
		vmac_driver_free(r);
	}
	ck_assert_msg(refusals == 1, "%d of the two orders refused (one must be: the encoder takes one first)",
	              refusals);
}
END_TEST

START_TEST(random_byte_flips_are_taken_or_refused_cleanly)
{
	struct vmac_driver *w = attached_with(RICH_STATE), *r = load_ok(any_reader);
	static uint8_t copy[BUF_CAP];
	char err[VMAC_DRIVER_ERR_MAX];
	uint32_t seed = 20240611;
	int round, took = 0, refusals = 0;
	checkpoint_ok(w, "the rich state");
	for (round = 0; round < 2000; round++) {
		int flips, k, rc;
		memcpy(copy, buf, buf_len);
		seed = seed * 1103515245 + 12345;
		flips = 1 + (int)((seed >> 16) % 4);
		for (k = 0; k < flips; k++) {
			size_t at;
			seed = seed * 1103515245 + 12345;
			at = (seed >> 8) % buf_len;
			seed = seed * 1103515245 + 12345;
			copy[at] ^= (uint8_t)(1 + (seed >> 16) % 255);
		}
		err[0] = 0;
		rc = vmac_driver_offer_checkpoint(r, copy, buf_len, &info, err, sizeof(err));
		if (rc == 0) {
			took++;
			rc = vmac_driver_recover(r, 0, err, sizeof(err));
			ck_assert_msg(rc == VMAC_RECOVER_DONE, "round %d: a taken checkpoint's recover returned %d: %s",
			              round, rc, err);
		} else {
			refusals++;
			ck_assert_msg(rc == -EBADMSG || rc == -EPROTONOSUPPORT, "round %d: offer returned %d", round,
			              rc);
			ck_assert_msg(strncmp(err, "checkpoint damaged: ", 20) == 0 ||
			                  strncmp(err, "checkpoint in format ", 21) == 0,
			              "round %d: refused with '%s'", round, err);
			rc = vmac_driver_recover(r, 0, err, sizeof(err));
			ck_assert_msg(rc == VMAC_RECOVER_NONE, "round %d: recover after a refusal returned %d", round,
			              rc);
		}
	}
	ck_assert_msg(took > 0 && refusals > 0, "2000 flips: %d taken, %d refused; both should happen", took, refusals);
	tick_ok(r, "the reader after 2000 flipped checkpoints");
	vmac_driver_free(w);
	vmac_driver_free(r);
}
END_TEST

/* ---- recover() and dev:checkpoint() ---- */

START_TEST(recover_absent_raising_or_without_a_checkpoint)
{
	struct vmac_driver *w = attached_with("dev.state.n = 1"), *r;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int rc;
	checkpoint_ok(w, "small state");

	/* No recover: the checkpoint is dropped. */
	r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end }");
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &info, err, sizeof(err)) == 0, "offer: %s", err);
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_UNUSED, "no recover(): returned %d, not UNUSED", rc);
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_NONE, "no recover(), asked again: returned %d, not NONE (dropped)", rc);
	tick_ok(r, "a driver without recover()");
	vmac_driver_free(r);

	/* recover raising: a driver failure with its text. */
	r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end,\n"
	            "  recover = function(dev, saved) error('cannot take state n = ' .. saved.state.n) end }");
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &info, err, sizeof(err)) == 0, "offer: %s", err);
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == -1, "a raising recover() returned %d", rc);
	says(err, "cannot take state n = 1", "raising recover");
	says(err, "t.lua:2:", "raising recover (where)");
	vmac_driver_free(r);

	/* Nothing offered: recover() is not called. */
	r = load_ok("return { name = 't', version = '2', io = {}, tick = function() end,\n"
	            "  recover = function() error('recover ran with nothing offered') end }");
	rc = vmac_driver_recover(r, 0, err, sizeof(err));
	ck_assert_msg(rc == VMAC_RECOVER_NONE, "nothing offered: returned %d (%s)", rc, err);
	tick_ok(r, "a driver offered nothing");
	vmac_driver_free(r);
	vmac_driver_free(w);
}
END_TEST

START_TEST(a_second_offer_replaces_the_first)
{
	struct vmac_driver *w = attached_with("dev.state.n = 1"), *r;
	static uint8_t first[64];
	size_t first_len;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	checkpoint_ok(w, "n = 1");
	ck_assert_msg(buf_len <= sizeof(first), "checkpoint of n = 1 is %zu bytes", buf_len);
	memcpy(first, buf, buf_len);
	first_len = buf_len;
	tick_ok(w, "writer"); /* adds ticks = 1 */
	checkpoint_ok(w, "n = 1, ticks = 1");
	r = load_ok(
	    "return { name = 't', version = '2', io = {}, tick = function() end,\n"
	    "  recover = function(dev, saved) assert(saved.state.ticks == 1, 'the older checkpoint came') end }");
	ck_assert_msg(vmac_driver_offer_checkpoint(r, first, first_len, &info, err, sizeof(err)) == 0, "offer 1: %s",
	              err);
	ck_assert_msg(vmac_driver_offer_checkpoint(r, buf, buf_len, &info, err, sizeof(err)) == 0, "offer 2: %s", err);
	ck_assert_msg(vmac_driver_recover(r, 0, err, sizeof(err)) == VMAC_RECOVER_DONE, "recover: %s", err);
	vmac_driver_free(r);
	vmac_driver_free(w);
}
END_TEST

START_TEST(dev_checkpoint_asks_and_a_checkpoint_clears)
{
	struct vmac_driver *d =
	    load_ok("return { name = 't', version = '1', io = {},\n"
	            "  tick = function(dev) dev.state.big = string.rep('x', 100) dev:checkpoint() end }");
	char err[VMAC_DRIVER_ERR_MAX] = "";
	size_t len;
	ck_assert_msg(vmac_driver_attach(d, 0, err, sizeof(err)) == 0, "attach: %s", err);
	ck_assert_msg(!vmac_driver_checkpoint_asked(d), "asked before any dev:checkpoint()");
	tick_ok(d, "a tick that asks");
	ck_assert_msg(vmac_driver_checkpoint_asked(d), "dev:checkpoint() did not set the flag");
	checkpoint_ok(d, "asked");
	ck_assert_msg(!vmac_driver_checkpoint_asked(d), "a checkpoint did not clear the flag");
	/* A failed checkpoint clears it too (the bus decides when to retry). */
	tick_ok(d, "asking again");
	ck_assert_msg(vmac_driver_checkpoint_asked(d), "the second dev:checkpoint() did not set the flag");
	ck_assert_msg(vmac_driver_checkpoint(d, buf, 16, &len, err, sizeof(err)) == -E2BIG, "100 bytes fitted into 16");
	ck_assert_msg(!vmac_driver_checkpoint_asked(d), "a failed checkpoint did not clear the flag");
	vmac_driver_free(d);
}
END_TEST

/* ---- the store ---- */

START_TEST(store_keeps_the_newest_checkpoint_per_machine)
{
	char dir[] = "/tmp/vmac-test-checkpoint-XXXXXX", cmd[128], err[512] = "", driver[VMAC_NAME_MAX + 1],
	     version[32];
	struct vmac_store *s = NULL;
	static const uint8_t d1[] = {'V', 'M', 'C', 'K', 1, '{', 0, 0xff, '}'}, d2[] = {1, 2, 3},
	                     d3[] = {0, 0, 0, 0, 0}, d1b[] = {'n', 'e', 'w', 0, 'e', 'r'};
	const struct vmac_checkpoint first[] = {
	    {"washer-1", "washer", "1.0", 1700000000.25, d1, sizeof(d1)},
	    {"lights-1", "lights", "2.3.4", 1700000001.5, d2, sizeof(d2)},
	    {"dish-1", "dishwasher", "0.1", 1.0, d3, sizeof(d3)},
	};
	const struct vmac_checkpoint second[] = {{"washer-1", "washer", "1.1", 1700000099.75, d1b, sizeof(d1b)}};
	const struct vmac_checkpoint *want[] = {&second[0], &first[1], &first[2]};
	uint8_t *data;
	size_t len;
	double time;
	int i, rc;
	ck_assert_msg(mkdtemp(dir) != NULL, "mkdtemp failed");
	ck_assert_msg(vmac_store_open(dir, &s, err, sizeof(err)) == 0, "open: %s", err);
	ck_assert_msg(vmac_store_checkpoints_put(s, first, 3, err, sizeof(err)) == 0, "put of three: %s", err);
	for (i = 0; i < 3; i++) {
		rc = vmac_store_checkpoint_get(s, first[i].machine, &data, &len, driver, sizeof(driver), version,
		                               sizeof(version), &time, err, sizeof(err));
		ck_assert_msg(rc == 1, "get %s after the first put: %d (%s)", first[i].machine, rc, err);
		ck_assert_msg(len == first[i].len && memcmp(data, first[i].data, len) == 0,
		              "%s: data differs (%zu bytes)", first[i].machine, len);
		ck_assert_str_eq(driver, first[i].driver);
		ck_assert_str_eq(version, first[i].version);
		ck_assert_msg(time == first[i].time, "%s: time %.17g, not %.17g", first[i].machine, time,
		              first[i].time);
		free(data);
	}
	ck_assert_msg(vmac_store_checkpoints_put(s, second, 1, err, sizeof(err)) == 0, "second put: %s", err);
	/* Kept across a reopen: the store is the host's memory over a restart. */
	vmac_store_close(s);
	ck_assert_msg(vmac_store_open(dir, &s, err, sizeof(err)) == 0, "reopen: %s", err);
	for (i = 0; i < 3; i++) {
		rc = vmac_store_checkpoint_get(s, want[i]->machine, &data, &len, driver, sizeof(driver), version,
		                               sizeof(version), &time, err, sizeof(err));
		ck_assert_msg(rc == 1, "get %s after the second put: %d (%s)", want[i]->machine, rc, err);
		ck_assert_msg(len == want[i]->len && memcmp(data, want[i]->data, len) == 0,
		              "%s: not the newest data (%zu bytes)", want[i]->machine, len);
		ck_assert_str_eq(driver, want[i]->driver);
		ck_assert_str_eq(version, want[i]->version);
		ck_assert_msg(time == want[i]->time, "%s: time %.17g, not %.17g", want[i]->machine, time,
		              want[i]->time);
		free(data);
	}
	data = (uint8_t *)1;
	len = 99;
	rc = vmac_store_checkpoint_get(s, "nosuch", &data, &len, driver, sizeof(driver), version, sizeof(version),
	                               &time, err, sizeof(err));
	ck_assert_msg(rc == 0, "get of an unknown machine returned %d (%s)", rc, err);
	ck_assert_msg(data == NULL && len == 0, "an unknown machine left data %p, %zu bytes", (void *)data, len);
	ck_assert_msg(vmac_store_checkpoints_put(s, NULL, 0, err, sizeof(err)) == 0, "a put of none failed: %s", err);
	vmac_store_close(s);
	snprintf(cmd, sizeof(cmd), "rm -rf %s", dir);
	ck_assert_int_eq(system(cmd), 0);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("checkpoint");
	TCase *tc = tcase_create("checkpoint");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_set_timeout(tc, 120);
	tcase_add_test(tc, round_trip_keeps_plain_data_sharing_and_cycles);
	tcase_add_test(tc, a_checkpoint_taken_checkpoints_again);
	tcase_add_test(tc, restarted_false_and_version_arrive_as_given);
	tcase_add_test(tc, over_checkpoint_kib_fails_only_the_checkpoint);
	tcase_add_test(tc, depth_limit_is_the_same_both_ways);
	tcase_add_test(tc, entry_limit_is_the_same_both_ways);
	tcase_add_test(tc, a_heap_at_its_cap_fails_only_the_checkpoint);
	tcase_add_test(tc, every_truncation_is_refused);
	tcase_add_test(tc, malformed_checkpoints_are_refused_with_the_reason);
	tcase_add_test(tc, random_byte_flips_are_taken_or_refused_cleanly);
	tcase_add_test(tc, recover_absent_raising_or_without_a_checkpoint);
	tcase_add_test(tc, a_second_offer_replaces_the_first);
	tcase_add_test(tc, dev_checkpoint_asks_and_a_checkpoint_clears);
	tcase_add_test(tc, store_keeps_the_newest_checkpoint_per_machine);
	suite_add_tcase(s, tc);
	return s;
}
