/* Unit tests of the audit trail's format and its rate limit
 * (core/host/audit.c, docs/API.md "Audit trail"): the text is the
 * documented grammar and keeps its result when it is cut; operator input
 * is written as the console writes it; a flood of refusals from one key or
 * from many costs a bounded number of events, and the window's summary
 * says how many were not each said, and from whom; lock-outs have a budget
 * of their own; accepted requests are never held back. */
#include <check.h>
#include <regex.h>
#include <stdio.h>
#include <string.h>

#include "../../core/host/audit.h"
#include "../../core/host/events.h"
#include "check_main.h"

/* docs/API.md's regular expression of an audit event's text (POSIX ERE
 * here; the doc gives it in Python's syntax, the same without the
 * non-greedy WHO, which holds no " from " in any of these). */
#define AUDIT_RE "^([a-z]+) by (.+) from ([^ ]+): (.+) -> ([0-9]{3}|[a-z_]+)( \\((.*)\\))?$"

static struct vmac_event_log log_;

static void setup(void)
{
	vmac_event_log_init(&log_);
}

static int audit_events(void)
{
	struct vmac_event ev[VMAC_EVENT_LOG_SIZE];
	int n = vmac_event_log_latest(&log_, ev, VMAC_EVENT_LOG_SIZE), i, count = 0;
	for (i = 0; i < n; i++)
		count += strcmp(ev[i].kind, "audit") == 0;
	return count;
}

static const char *last_text(void)
{
	static struct vmac_event e;
	ck_assert_int_eq(vmac_event_log_latest(&log_, &e, 1), 1);
	return e.text;
}

static struct vmac_audit refusal(const char *key)
{
	struct vmac_audit a = {"auth", "no token", "10.0.0.5", "GET /api/status", "401", "a token is needed",
	                       "",     key,        0};
	return a;
}

START_TEST(the_text_follows_the_grammar_and_keeps_its_result)
{
	struct vmac_audit a = {"input",
	                       "token 0123456789abcdef \"alice\" (operate)",
	                       "127.0.0.1",
	                       "POST /api/devices/washer-1/input washer-1.door:true",
	                       "200",
	                       NULL,
	                       "washer-1",
	                       NULL,
	                       0};
	char text[VMAC_EVENT_TEXT], long_what[2000];
	regex_t re;
	regmatch_t m[8];
	ck_assert_int_eq(regcomp(&re, AUDIT_RE, REG_EXTENDED), 0);
	vmac_audit_text(&a, text, sizeof(text));
	ck_assert_str_eq(text, "input by token 0123456789abcdef \"alice\" (operate) from 127.0.0.1: POST "
	                       "/api/devices/washer-1/input washer-1.door:true -> 200");
	ck_assert_msg(regexec(&re, text, 8, m, 0) == 0, "does not match the documented grammar: %s", text);
	memset(long_what, 'x', sizeof(long_what) - 1);
	long_what[sizeof(long_what) - 1] = 0;
	a.what = long_what;
	a.result = "409";
	a.why = "cycle is already running";
	vmac_audit_text(&a, text, sizeof(text));
	ck_assert_msg(strlen(text) < sizeof(text) && strstr(text, "... -> 409 (cycle is already running)"),
	              "a long request lost its result: ...%s", text + strlen(text) - 60);
	ck_assert_msg(regexec(&re, text, 8, m, 0) == 0 && m[5].rm_so >= 0 &&
	                  strncmp(text + m[5].rm_so, "409", 3) == 0 && m[7].rm_so >= 0,
	              "the result and why of a cut text do not parse: %s", text);
	regfree(&re);
}
END_TEST

START_TEST(input_is_written_as_the_console_writes_it)
{
	struct vmac_bus_input_request req;
	char text[200];
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "washer-1");
	snprintf(req.name, sizeof(req.name), "door");
	req.value.type = VMAC_VALUE_BOOL;
	req.value.number = 1;
	vmac_audit_input(&req, text, sizeof(text));
	ck_assert_str_eq(text, "washer-1.door:true");
	req.value.type = VMAC_VALUE_NUMBER;
	req.value.number = 0.1;
	vmac_audit_input(&req, text, sizeof(text));
	ck_assert_str_eq(text, "washer-1.door:0.1");
	snprintf(req.name, sizeof(req.name), "program");
	req.value.type = VMAC_VALUE_STRING;
	snprintf(req.value.str, sizeof(req.value.str), "quick");
	req.persist = 1;
	vmac_audit_input(&req, text, sizeof(text));
	ck_assert_str_eq(text, "washer-1.program>quick");
	snprintf(req.value.str, sizeof(req.value.str), "a \"b\" -> c");
	req.persist = 0;
	vmac_audit_input(&req, text, sizeof(text));
	ck_assert_str_eq(text, "washer-1.program:\"a \\\"b\\\" -> c\"");
	snprintf(req.name, sizeof(req.name), "start");
	req.value.type = VMAC_VALUE_NONE;
	vmac_audit_input(&req, text, sizeof(text));
	ck_assert_str_eq(text, "washer-1.start!");
}
END_TEST

START_TEST(the_type_of_a_text_is_its_first_word)
{
	char type[16];
	ck_assert_int_eq(vmac_audit_type_of("input by no token from ::1: POST /x -> 401", type, sizeof(type)), 0);
	ck_assert_str_eq(type, "input");
	ck_assert_int_eq(vmac_audit_type_of("refused: and 3 more refused requests", type, sizeof(type)), 0);
	ck_assert_str_eq(type, "refused");
	ck_assert_int_eq(vmac_audit_type_of("inputs by x", type, sizeof(type)), -1);
	ck_assert_int_eq(vmac_audit_type_of("", type, sizeof(type)), -1);
}
END_TEST

START_TEST(a_flood_from_one_key_is_said_in_a_bounded_number_of_events)
{
	struct vmac_audit a = refusal("address 10.0.0.5");
	int i;
	for (i = 0; i < 2000; i++)
		vmac_audit_add_at(&log_, &a, 100.0 + i * 0.001);
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY);
	vmac_audit_flush_at(&log_, 100.0 + VMAC_AUDIT_WINDOW_S - 0.01); /* not over yet */
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY);
	vmac_audit_flush_at(&log_, 100.0 + VMAC_AUDIT_WINDOW_S);
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY + 1);
	ck_assert_str_eq(last_text(), "refused: and 1990 more refused requests from address 10.0.0.5 in the last 10 s");
	vmac_audit_flush_at(&log_, 200.0); /* said once */
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY + 1);
	vmac_audit_add_at(&log_, &a, 300.0); /* a new window: said again */
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY + 2);
}
END_TEST

START_TEST(a_flood_from_many_keys_is_bounded_too)
{
	char key[40];
	int i;
	for (i = 0; i < 2000; i++) {
		struct vmac_audit a;
		snprintf(key, sizeof(key), "address 10.0.%d.%d", i / 250, i % 250);
		a = refusal(key);
		vmac_audit_add_at(&log_, &a, 100.0);
	}
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_WINDOW);
	vmac_audit_flush_at(&log_, 111.0);
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_WINDOW + 1);
	ck_assert_msg(strncmp(last_text(), "refused: and 1970 more refused requests in the last 10 s: ", 58) == 0 &&
	                  strstr(last_text(), " from others"),
	              "the summary of many keys: %s", last_text());
}
END_TEST

START_TEST(lockouts_have_a_budget_of_their_own_and_accepted_requests_none)
{
	struct vmac_audit a = refusal("address 10.0.0.5"), ok;
	char key[40];
	int i;
	for (i = 0; i < 100; i++) /* the refusals' budget spent */
		vmac_audit_add_at(&log_, &a, 100.0);
	for (i = 0; i < 20; i++) {
		snprintf(key, sizeof(key), "token %016x", i);
		a = refusal(key);
		a.type = "lockout";
		a.lockout = 1;
		vmac_audit_add_at(&log_, &a, 100.0);
	}
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY + VMAC_AUDIT_LOCKOUTS_PER_WINDOW);
	ok = refusal(NULL);
	ok.type = "input";
	ok.result = "200";
	ok.why = NULL;
	for (i = 0; i < 50; i++)
		vmac_audit_add_at(&log_, &ok, 100.0);
	ck_assert_int_eq(audit_events(), VMAC_AUDIT_REFUSED_PER_KEY + VMAC_AUDIT_LOCKOUTS_PER_WINDOW + 50);
	vmac_audit_flush_at(&log_, 110.0);
	ck_assert_msg(strstr(last_text(), "and 100 more refused requests") &&
	                  strstr(last_text(), "(10 of them lock-outs)"),
	              "the summary: %s", last_text());
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("audit");
	TCase *tc = tcase_create("audit");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, the_text_follows_the_grammar_and_keeps_its_result);
	tcase_add_test(tc, input_is_written_as_the_console_writes_it);
	tcase_add_test(tc, the_type_of_a_text_is_its_first_word);
	tcase_add_test(tc, a_flood_from_one_key_is_said_in_a_bounded_number_of_events);
	tcase_add_test(tc, a_flood_from_many_keys_is_bounded_too);
	tcase_add_test(tc, lockouts_have_a_budget_of_their_own_and_accepted_requests_none);
	suite_add_tcase(s, tc);
	return s;
}
