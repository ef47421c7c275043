/* Unit tests of text values in the driver module (core/driver/instance.c):
 * a string variable longer than VMAC_DRIVER_STR_MAX is cut on a UTF-8
 * character boundary and ends with the cut mark, and the first cut of each
 * variable is told once, as a warning event that names it and its length
 * (docs/DRIVERS.md, "variables"). */
#include <check.h>
#include <stdio.h>
#include <string.h>

#include "../../core/driver/driver.h"
#include "check_main.h"

static struct vmac_driver_limits limits;

struct seen {
	int n;
	char kind[4][16];
	char text[4][200];
};
static struct seen seen;

static void keep_event(void *ctx, const char *kind, const char *text)
{
	(void)ctx;
	if (seen.n < 4) {
		snprintf(seen.kind[seen.n], sizeof(seen.kind[0]), "%s", kind);
		snprintf(seen.text[seen.n], sizeof(seen.text[0]), "%s", text);
	}
	seen.n++;
}

static int no_level(void *ctx, unsigned level, char *err, size_t errlen)
{
	(void)ctx;
	(void)level;
	(void)err;
	(void)errlen;
	return 0;
}

static void setup(void)
{
	memset(&limits, 0, sizeof(limits));
	memset(&seen, 0, sizeof(seen));
	limits.memory_bytes = 1 << 20;
	limits.instructions = 200000;
	limits.max_level = 10;
	limits.default_level = 4;
	limits.expect_name = "t";
}

/* A driver whose tick sets dev.vars.msg and dev.vars.other to the globals
 * MSG and OTHER, which each tick replaces from the time: see texts[]. */
static struct vmac_driver *load_texts(void)
{
	const char *src = "local texts = {\n"
	                  "  [1] = { string.rep('x', 100), 'short' },\n"
	                  "  [2] = { 'a' .. string.rep('\\226\\130\\172', 40), 'short' },\n" /* 'a' and 40 euro signs */
	                  "  [3] = { string.rep('y', 63), string.rep('z', 70) },\n"
	                  "}\n"
	                  "return { name = 't', version = '1', io = {}, variables = { msg = {}, other = {} },\n"
	                  "  tick = function(dev, i) local t = texts[math.floor(i.time)]\n"
	                  "    dev.vars.msg, dev.vars.other = t[1], t[2] end }\n";
	struct vmac_driver *d = NULL;
	struct vmac_driver_host host = {no_level, keep_event, NULL};
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_msg(vmac_driver_load_source("t.lua", src, strlen(src), &limits, &d, err, sizeof(err)) == 0,
	              "load failed: %s", err);
	vmac_driver_bind(d, &host);
	vmac_driver_add_board(d, 0, "b0");
	return d;
}

static const char *tick_and_read(struct vmac_driver *d, double t, const char *name)
{
	struct vmac_inputs in;
	struct vmac_outputs out;
	const struct vmac_inputs *ins[1] = {&in};
	struct vmac_outputs *outs[1] = {&out};
	char err[VMAC_DRIVER_ERR_MAX] = "";
	int i;
	memset(&in, 0, sizeof(in));
	ck_assert_msg(vmac_driver_tick(d, t, ins, outs, err, sizeof(err)) == 0, "tick at %g failed: %s", t, err);
	for (i = 0; i < vmac_driver_nvars(d); i++)
		if (strcmp(vmac_driver_variable(d, i)->name, name) == 0)
			return vmac_driver_variable(d, i)->value.str;
	ck_abort_msg("no variable %s", name);
	return NULL;
}

/* s is valid UTF-8 (well-formed lead and continuation bytes). */
static int valid_utf8(const char *s)
{
	const unsigned char *p = (const unsigned char *)s;
	while (*p) {
		int more = *p < 0x80             ? 0
		           : (*p & 0xE0) == 0xC0 ? 1
		           : (*p & 0xF0) == 0xE0 ? 2
		           : (*p & 0xF8) == 0xF0 ? 3
		                                 : -1;
		if (more < 0)
			return 0;
		for (p++; more > 0; more--, p++)
			if ((*p & 0xC0) != 0x80)
				return 0;
	}
	return 1;
}

static int ends_with_mark(const char *s)
{
	size_t n = strlen(s), m = strlen(VMAC_DRIVER_CUT_MARK);
	return n >= m && strcmp(s + n - m, VMAC_DRIVER_CUT_MARK) == 0;
}

START_TEST(a_long_text_is_cut_with_a_mark)
{
	struct vmac_driver *d = load_texts();
	const char *msg = tick_and_read(d, 1.0, "msg");
	ck_assert_msg(strlen(msg) == VMAC_DRIVER_STR_MAX, "a cut text is %zu bytes, not %d: '%s'", strlen(msg),
	              VMAC_DRIVER_STR_MAX, msg);
	ck_assert_msg(ends_with_mark(msg), "a cut text does not end with the mark: '%s'", msg);
	ck_assert_msg(strncmp(msg, "xxxxxxxxxx", 10) == 0, "a cut text does not keep its start: '%s'", msg);
	ck_assert_str_eq(tick_and_read(d, 1.5, "other"), "short");
	vmac_driver_free(d);
}
END_TEST

START_TEST(a_cut_falls_between_utf8_characters)
{
	struct vmac_driver *d = load_texts();
	const char *msg = tick_and_read(d, 2.0, "msg");
	/* 'a' then 3-byte characters: byte 60 is inside one, the cut backs
	 * off to the character's start at 58. */
	ck_assert_msg(valid_utf8(msg), "the cut text is not valid UTF-8: '%s'", msg);
	ck_assert_msg(ends_with_mark(msg), "a cut text does not end with the mark: '%s'", msg);
	ck_assert_msg(strlen(msg) == 58 + strlen(VMAC_DRIVER_CUT_MARK), "cut at %zu bytes, expected 58 and the mark",
	              strlen(msg) - strlen(VMAC_DRIVER_CUT_MARK));
	vmac_driver_free(d);
}
END_TEST

START_TEST(a_text_at_the_limit_is_whole)
{
	struct vmac_driver *d = load_texts();
	const char *msg = tick_and_read(d, 3.0, "msg");
	ck_assert_msg(strlen(msg) == 63 && !ends_with_mark(msg), "a text of exactly 63 bytes was changed: '%s'", msg);
	ck_assert_msg(seen.n == 1 && strstr(seen.text[0], "dev.vars.other") != NULL,
	              "a text at the limit was warned about (%d events, first '%s')", seen.n, seen.text[0]);
	vmac_driver_free(d);
}
END_TEST

START_TEST(each_variable_is_warned_about_once)
{
	struct vmac_driver *d = load_texts();
	tick_and_read(d, 1.0, "msg");
	ck_assert_msg(seen.n == 1, "%d events after the first cut, expected 1", seen.n);
	ck_assert_str_eq(seen.kind[0], "warning");
	ck_assert_msg(strstr(seen.text[0], "dev.vars.msg") && strstr(seen.text[0], "100 bytes"),
	              "the warning does not name the variable and its length: '%s'", seen.text[0]);
	tick_and_read(d, 1.5, "msg");
	tick_and_read(d, 2.0, "msg"); /* cut again, another text */
	ck_assert_msg(seen.n == 1, "msg was warned about %d times, expected once", seen.n);
	tick_and_read(d, 3.0, "msg"); /* other is cut now: its own warning */
	ck_assert_msg(seen.n == 2 && strstr(seen.text[1], "dev.vars.other") && strstr(seen.text[1], "70 bytes"),
	              "%d events; the second '%s' should name dev.vars.other and 70 bytes", seen.n, seen.text[1]);
	vmac_driver_free(d);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("driver_text");
	TCase *tc = tcase_create("driver_text");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, a_long_text_is_cut_with_a_mark);
	tcase_add_test(tc, a_cut_falls_between_utf8_characters);
	tcase_add_test(tc, a_text_at_the_limit_is_whole);
	tcase_add_test(tc, each_variable_is_warned_about_once);
	suite_add_tcase(s, tc);
	return s;
}
