/* Unit tests of what vmacd says on MQTT and reads back (core/mqtt; docs/MQTT.md,
 * "Payloads" and "Conformance: payloads and topics"): values as text, command
 * payloads untyped and typed by their declaration, the site view's reading
 * of the native topics, and a board's clock in a machine's health and its
 * Home Assistant sensors. White-box: core/mqtt/mqtt_internal.h. */
#include <check.h>
#include <jansson.h>
#include <math.h>
#include <string.h>
#include <unistd.h>

#include "../../core/mqtt/mqtt_internal.h"
#include "../../core/mqtt/site.h"
#include "check_main.h"
#include "proto_helpers.h"

static const char *text_of(struct vmac_value v)
{
	static char out[MQTT_TEXT_MAX];
	mqtt_value_text(&v, out, sizeof(out));
	return out;
}

static struct vmac_value number(double x)
{
	struct vmac_value v;
	memset(&v, 0, sizeof(v));
	v.type = VMAC_VALUE_NUMBER;
	v.number = x;
	return v;
}

START_TEST(value_text_says_unknown_as_home_assistant_reads_it)
{
	struct vmac_value none, yes, word;
	memset(&none, 0, sizeof(none));
	none.type = VMAC_VALUE_NONE;
	ck_assert_str_eq(text_of(none), "None"); /* HA's PAYLOAD_NONE, not an empty (ignored) payload */
	ck_assert_str_eq(text_of(number(NAN)), "None");
	ck_assert_str_eq(text_of(number(INFINITY)), "None");
	ck_assert_str_eq(text_of(number(-INFINITY)), "None");
	ck_assert_str_eq(text_of(number(2)), "2"); /* a numeric select's option, not 2.0 */
	ck_assert_str_eq(text_of(number(12.5)), "12.5");
	ck_assert_str_eq(text_of(number(-0.001)), "-0.001");
	yes = number(1);
	yes.type = VMAC_VALUE_BOOL;
	ck_assert_str_eq(text_of(yes), "true");
	word = number(0);
	word.type = VMAC_VALUE_STRING;
	strcpy(word.str, "quick");
	ck_assert_str_eq(text_of(word), "quick");
}
END_TEST

static const char *text_at(double x, int precision)
{
	static char out[MQTT_TEXT_MAX];
	struct vmac_value v = number(x);
	mqtt_value_text_at(&v, precision, out, sizeof(out));
	return out;
}

static int precision_of(const char *decl)
{
	json_t *d = json_loads(decl, 0, NULL);
	int p = mqtt_declared_precision(d);
	json_decref(d);
	return p;
}

START_TEST(a_declared_precision_rounds_what_is_published)
{
	ck_assert_str_eq(text_at(21.449, 1), "21.4");
	ck_assert_str_eq(text_at(21.45001, 1), "21.5");
	ck_assert_str_eq(text_at(-0.04, 1), "0.0"); /* never -0.0: it would read as a change */
	ck_assert_str_eq(text_at(3.7, 0), "4");
	ck_assert_str_eq(text_at(12.3456789, -1), "12.3456789");
	ck_assert_str_eq(text_at(NAN, 2), "None");
	ck_assert_int_eq(precision_of("{\"unit\": \"degC\", \"precision\": 1}"), 1);
	ck_assert_int_eq(precision_of("{\"precision\": 1.0}"), 1); /* Lua numbers come as reals */
	ck_assert_int_eq(precision_of("{\"unit\": \"degC\"}"), -1);
	ck_assert_int_eq(precision_of("{\"precision\": 7}"), -1);
	ck_assert_int_eq(precision_of("{\"precision\": 1.5}"), -1);
	ck_assert_int_eq(precision_of("{\"precision\": 1, \"values\": [1.5, 2.5]}"), -1); /* options stay as written */
}
END_TEST

/* Whether x, with sent published last, goes out at precision. */
static int moves(double x, int precision, const char *sent)
{
	struct vmac_value v = number(x);
	char text[MQTT_TEXT_MAX];
	mqtt_value_text_at(&v, precision, text, sizeof(text));
	return mqtt_value_moved(&v, precision, text, sent);
}

START_TEST(a_precision_goes_out_a_whole_step_from_what_was_sent)
{
	struct vmac_value none, word;
	/* 37.45 C read with +-2 counts of 0.025 C: neighbours of 37.4 that are not a step away stay unsent. */
	ck_assert_msg(!moves(37.45, 1, "37.4") && !moves(37.475, 1, "37.4"), "noise at 37.45 moved 37.4");
	ck_assert_msg(!moves(37.425, 1, "37.5") && !moves(37.45, 1, "37.5"), "noise at 37.45 moved 37.5");
	ck_assert_msg(moves(37.5, 1, "37.4") && moves(37.4, 1, "37.5"), "a whole step (binary 0.1 +- an ulp) stays");
	ck_assert_msg(moves(37.3, 1, "37.5") && moves(38.0, 1, "37.4"), "more than a step stays");
	ck_assert_msg(!moves(37.4, 1, "37.4"), "the same text went out again");
	ck_assert_msg(moves(45.0, 0, "44") && !moves(44.6, 0, "44"), "precision 0: a step is 1");
	ck_assert_msg(moves(0.000001, 6, "0.000000") && !moves(0.0000004, 6, "0.000000"), "precision 6: 1e-6");
	/* Anything else goes out when its text changes. */
	ck_assert_msg(moves(21.44, 1, "None") && moves(21.44, 1, "true"), "a number after None or a boolean");
	ck_assert_msg(moves(21.44, -1, "21.45") && !moves(21.44, -1, "21.44"), "no precision: every change");
	memset(&none, 0, sizeof(none));
	ck_assert_msg(mqtt_value_moved(&none, 1, "None", "21.4"), "None after a number");
	word = number(0);
	word.type = VMAC_VALUE_STRING;
	strcpy(word.str, "21.41");
	ck_assert_msg(mqtt_value_moved(&word, 1, "21.41", "21.4"), "a string after a number");
}
END_TEST

/* Noise of -n..+n counts of 0.025 C, the sum of n draws of -1, 0, +1 (the
 * washer plant's is n = 2), from a fixed LCG: the same every run. */
static int noise_counts(unsigned *state, int n)
{
	int k, sum = 0;
	for (k = 0; k < n; k++) {
		*state = *state * 1103515245u + 12345u;
		sum += (int)((*state >> 16) % 3u) - 1;
	}
	return sum;
}

/* Readings of exact_c (falling by fall_c each) with noise of noise_n counts
 * through the throttle at one decimal, as mqtt_devices.c applies it: the
 * messages and the changes of the rounded text; every number shown is less
 * than a step from the reading. */
static void throttle(double exact_c, double fall_c, int noise_n, int readings, int *messages, int *flickers)
{
	char sent[MQTT_TEXT_MAX] = "None", text[MQTT_TEXT_MAX], last[MQTT_TEXT_MAX] = "";
	unsigned state = 1;
	int k;
	*messages = *flickers = 0;
	for (k = 0; k < readings; k++, exact_c -= fall_c) {
		struct vmac_value v = number((floor(exact_c * 40 + 0.5) + noise_counts(&state, noise_n)) * 0.025);
		mqtt_value_text_at(&v, 1, text, sizeof(text));
		*flickers += strcmp(text, last) != 0;
		snprintf(last, sizeof(last), "%s", text);
		if (mqtt_value_moved(&v, 1, text, sent)) {
			snprintf(sent, sizeof(sent), "%s", text);
			++*messages;
		}
		ck_assert_msg(fabs(strtod(sent, NULL) - v.number) < 0.1,
		              "reading %d: %.3f C shown as %s, a step or more off", k, v.number, sent);
	}
}

START_TEST(noise_narrower_than_a_step_does_not_flip_what_is_shown)
{
	int messages, flickers;
	/* 37.45 C, right on a rounding boundary of 0.1 C, with +-1 count (0.05 C from end to end). */
	throttle(37.45, 0, 1, 1000, &messages, &flickers);
	ck_assert_msg(messages == 1 && flickers > 100,
	              "a still 37.45 C with +-1 count of noise: %d messages (%d changes "
	              "of its rounded text), not 1",
	              messages, flickers);
	/* Cooling by a count every 6 readings, 3.6 C: once per 0.1 C it falls. */
	throttle(37.5, 0.004, 1, 900, &messages, &flickers);
	ck_assert_msg(messages <= 37 && flickers > 3 * messages,
	              "a fall of 36 steps with +-1 count of noise: %d messages "
	              "(%d changes of its rounded text)",
	              messages, flickers);
}
END_TEST

/* With +-2 counts, readings 0.1 C apart come from one temperature: a whole
 * step, which goes out (a change of a step always does), but only when both
 * ends of the noise come while it sits on the boundary's count. */
START_TEST(noise_of_a_whole_step_flips_it_far_less_than_its_rounding)
{
	int messages, flickers;
	throttle(37.5, 0.004, 2, 900, &messages, &flickers);
	ck_assert_msg(messages <= 36 * 3 / 2 && flickers > 4 * messages,
	              "a fall of 36 steps with +-2 counts of noise: %d "
	              "messages, %d changes of its rounded text",
	              messages, flickers);
}
END_TEST

/* A machine is named by its board's ANNOUNCE, and that name is the
 * Sparkplug Device ID in every topic (tck-id-intro-device-id-string,
 * -chars, tck-id-topic-structure-namespace-valid-device-id): each byte the
 * bus's decoder lets through is an ASCII letter, digit, '_' or '-', so the
 * id is UTF-8 and holds no '+', '/', '#' or control character. */
START_TEST(every_machine_name_the_bus_takes_is_a_sparkplug_device_id)
{
	struct vmac_msg m = sample_announce(), out;
	uint8_t frame[VMAC_FRAME_MAX];
	int n = vmac_proto_encode(&m, frame, sizeof(frame)), c, at = -1, k;
	ck_assert_msg(n > 0, "the sample ANNOUNCE does not encode: %s", errname(n));
	for (k = 0; k + 7 <= n; k++) /* where its board name, "bench-1", is in the frame */
		if (memcmp(frame + k, "bench-1", 7) == 0)
			at = k;
	ck_assert_msg(at >= 0, "the board name is not in the encoded ANNOUNCE");
	for (c = 0; c < 256; c++) {
		int allowed =
		    (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
		int rc;
		frame[at + 5] = (uint8_t)c; /* bench-1 with byte c in the middle */
		rc = decode_exact(frame, (size_t)n, &out);
		ck_assert_msg((rc == 0) == allowed,
		              "a board name with byte 0x%02x: decode says %s, a Sparkplug Device ID "
		              "%s",
		              c, errname(rc), allowed ? "may hold it" : "may not");
		if (rc == 0)
			ck_assert_msg(strlen(out.u.announce.board) == 7 && (unsigned char)out.u.announce.board[5] == c,
			              "byte 0x%02x: the board name came back as \"%s\"", c, out.u.announce.board);
	}
}
END_TEST

/* payload (NUL-terminated) read against decl (JSON text, or NULL). */
static int typed(const char *payload, const char *decl, struct vmac_value *v, const char **why)
{
	json_t *d = decl ? json_loads(decl, 0, NULL) : NULL;
	int rc;
	*why = "";
	if (decl)
		ck_assert_msg(d != NULL, "bad test declaration %s", decl);
	rc = mqtt_payload_typed(payload, (int)strlen(payload), d, v, why);
	json_decref(d);
	return rc;
}

START_TEST(untyped_payloads_read_as_their_text_says)
{
	struct vmac_value v;
	const char *why;
	ck_assert_int_eq(typed("ON", NULL, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_BOOL && v.number == 1, "ON is true for an undeclared name");
	ck_assert_int_eq(typed(" 12.5 ", NULL, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_NUMBER && v.number == 12.5, "a number with blanks around it");
	ck_assert_int_eq(typed("\"12\"", NULL, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_STRING && strcmp(v.str, "12") == 0, "a JSON string stays a string");
	ck_assert_int_eq(typed("PRESS", NULL, &v, &why), 0);
	ck_assert_int_eq(v.type, VMAC_VALUE_NONE);
	ck_assert_int_eq(typed("{\"a\": 1}", NULL, &v, &why), -1);
	ck_assert_msg(strstr(why, "JSON") != NULL, "why: %s", why);
	ck_assert_int_eq(mqtt_payload_value("x", -1, &v, &why), -1);
	ck_assert_msg(strstr(why, "256 bytes") != NULL, "why: %s", why);
	ck_assert_int_eq(mqtt_payload_value("a\0b", 3, &v, &why), -1);
	ck_assert_msg(strstr(why, "NUL") != NULL, "why: %s", why);
}
END_TEST

START_TEST(a_select_or_text_gets_the_payload_as_a_string)
{
	static const char *const looks_like_other_things[] = {"1",     "on",   "true",  "OFF", "null",
	                                                      "PRESS", "2.50", "\"q\"", "[x]"};
	const char *select = "{\"default\": \"1\", \"values\": [\"1\", \"on\", \"true\"]}";
	const char *text = "{\"default\": \"\"}";
	struct vmac_value v;
	const char *why;
	size_t i;
	for (i = 0; i < sizeof(looks_like_other_things) / sizeof(looks_like_other_things[0]); i++) {
		const char *p = looks_like_other_things[i];
		ck_assert_msg(typed(p, select, &v, &why) == 0 && v.type == VMAC_VALUE_STRING && strcmp(v.str, p) == 0,
		              "select payload %s: type %d str %s (%s)", p, v.type, v.str, why);
		ck_assert_msg(typed(p, text, &v, &why) == 0 && v.type == VMAC_VALUE_STRING && strcmp(v.str, p) == 0,
		              "text payload %s: type %d str %s (%s)", p, v.type, v.str, why);
	}
	ck_assert_int_eq(typed("", text, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_NONE, "an empty payload is no value (set refuses it)");
	ck_assert_int_eq(typed("a\tb", text, &v, &why), -1);
	ck_assert_msg(strstr(why, "control") != NULL, "why: %s", why);
	ck_assert_int_eq(typed("0123456789012345678901234567890123456789012345678901234567890123", text, &v, &why), -1);
	ck_assert_msg(strstr(why, "63 bytes") != NULL, "why: %s", why);
}
END_TEST

START_TEST(a_number_boolean_or_numeric_choice_gets_its_type)
{
	const char *num = "{\"default\": 5, \"min\": 0, \"max\": 10}";
	const char *unit = "{\"unit\": \"degC\"}";
	const char *flag = "{\"default\": false}";
	const char *gear = "{\"default\": 1, \"values\": [1, 2, 3]}";
	struct vmac_value v;
	const char *why;
	ck_assert_int_eq(typed("7", num, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_NUMBER && v.number == 7, "a number for a number");
	ck_assert_int_eq(typed("on", num, &v, &why), -1);
	ck_assert_msg(strcmp(why, "expected a number") == 0, "why: %s", why);
	ck_assert_int_eq(typed("warm", unit, &v, &why), -1);
	ck_assert_int_eq(typed("1e400", num, &v, &why), -1); /* not finite: never a number */
	ck_assert_int_eq(typed("OFF", flag, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_BOOL && v.number == 0, "OFF for a boolean");
	ck_assert_int_eq(typed("1", flag, &v, &why), -1);
	ck_assert_msg(strcmp(why, "expected true/false/ON/OFF") == 0, "why: %s", why);
	ck_assert_int_eq(typed("2", gear, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_NUMBER && v.number == 2, "the option \"2\" is the number 2");
	ck_assert_int_eq(typed("fast", gear, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_STRING, "not a number: the driver refuses it as none of its values");
	ck_assert_int_eq(typed("", num, &v, &why), 0);
	ck_assert_msg(v.type == VMAC_VALUE_NONE, "empty: no value");
}
END_TEST

/* ---- the site view ---- */

static json_t *device_of(json_t *view, const char *host, const char *device)
{
	size_t i, k;
	json_t *h, *d;
	json_array_foreach(json_object_get(view, "hosts"), i,
	                   h) if (strcmp(json_string_value(json_object_get(h, "host")), host) == 0)
	    json_array_foreach(json_object_get(h, "devices"), k,
	                       d) if (strcmp(json_string_value(json_object_get(d, "device")), device) == 0) return d;
	return NULL;
}

static void feed(struct vmac_site *s, const char *topic, const char *payload)
{
	ck_assert_msg(vmac_site_feed(s, topic, payload, (int)strlen(payload)) == 1, "%s not taken as a site topic",
	              topic);
}

START_TEST(site_view_reads_host_topics_and_none)
{
	struct vmac_site *s = vmac_site_new("vmac", "a");
	json_t *view, *dev, *values;
	feed(s, "vmac/b/status", "online");
	feed(s, "vmac/b/washer-1/_availability", "online");
	feed(s, "vmac/b/washer-1/error", "E42");            /* a variable named error is a value */
	feed(s, "vmac/b/washer-1/availability", "no");      /* and so is one named availability */
	feed(s, "vmac/b/washer-1/_error", "{\"code\": 1}"); /* a refusal: not a value */
	feed(s, "vmac/b/washer-1/_health", "{}");           /* any other host topic: not a value either */
	feed(s, "vmac/b/washer-1/temp_c", "21.5");
	feed(s, "vmac/b/washer-1/gone", "here");
	feed(s, "vmac/b/washer-1/gone", "None"); /* no value any more */
	feed(s, "vmac/b/washer-1/never", "None");
	view = vmac_site_json(s);
	dev = device_of(view, "b", "washer-1");
	ck_assert_msg(dev != NULL, "washer-1 of b in the view");
	ck_assert_str_eq(json_string_value(json_object_get(dev, "state")), "online");
	values = json_object_get(dev, "values");
	ck_assert_str_eq(json_string_value(json_object_get(values, "error")), "E42");
	ck_assert_str_eq(json_string_value(json_object_get(values, "availability")), "no");
	ck_assert_msg(json_real_value(json_object_get(values, "temp_c")) == 21.5, "temp_c 21.5");
	ck_assert_msg(!json_object_get(values, "gone") && !json_object_get(values, "never"), "None is no value: %s",
	              json_dumps(values, 0));
	ck_assert_msg(!json_object_get(values, "_error") && !json_object_get(values, "_health"),
	              "host topics as values");
	ck_assert_int_eq(json_object_size(values), 3);
	ck_assert_int_eq(json_integer_value(json_object_get(view, "malformed")), 0);
	json_decref(view);
	feed(s, "vmac/b/washer-1/_availability", "maybe"); /* vmacd never says that */
	view = vmac_site_json(s);
	ck_assert_int_eq(json_integer_value(json_object_get(view, "malformed")), 1);
	json_decref(view);
	vmac_site_free(s);
}
END_TEST

/* The web UI's address for HA's configuration_url: ui_url, else from the
 * http setting (the host name for 0.0.0.0, https with tls_cert), none for
 * port 0; a ui_url that is no http(s) URL stops the host. */
/* A connection's machines are found whatever order they are asked in, the
 * status's order (from after the last find) or any other. */
START_TEST(a_machine_is_found_in_any_order)
{
	struct mqtt_device devices[4];
	struct mqtt_conn c;
	static const char *const names[] = {"washer-1", "dish-1", "lights-1", "lamp-9"};
	static const int order[] = {0, 1, 2, 3, 0, 1, 2, 3, 3, 2, 1, 0, 2, 0, 3, 1};
	int i;
	memset(&c, 0, sizeof(c));
	memset(devices, 0, sizeof(devices));
	for (i = 0; i < 4; i++)
		snprintf(devices[i].name, sizeof(devices[i].name), "%s", names[i]);
	c.devices = devices;
	c.ndevices = c.cap = 4;
	for (i = 0; i < (int)(sizeof(order) / sizeof(order[0])); i++)
		ck_assert_msg(mqtt_conn_device_find(&c, names[order[i]]) == &devices[order[i]],
		              "lookup %d: %s not found where it is", i, names[order[i]]);
	ck_assert_msg(mqtt_conn_device_find(&c, "oven-1") == NULL, "a machine not in the table was found");
	c.ndevices = 0;
	ck_assert_msg(mqtt_conn_device_find(&c, "washer-1") == NULL, "an empty table found a machine");
}
END_TEST

START_TEST(ui_url_from_the_setting_or_the_http_address)
{
	struct vmac_config cfg;
	struct vmac_mqtt_settings s;
	char err[256], host[64], want[128];
	vmac_config_defaults(&cfg);
	snprintf(cfg.mqtt_url, sizeof(cfg.mqtt_url), "mqtt://127.0.0.1:1883");
	snprintf(cfg.http, sizeof(cfg.http), "127.0.0.1:8080");
	ck_assert_int_eq(vmac_mqtt_settings_parse(&cfg, &s, err, sizeof(err)), 0);
	ck_assert_str_eq(s.ui_url, "http://127.0.0.1:8080/");
	snprintf(cfg.tls_cert, sizeof(cfg.tls_cert), "/etc/vmac/cert.pem");
	ck_assert_int_eq(vmac_mqtt_settings_parse(&cfg, &s, err, sizeof(err)), 0);
	ck_assert_str_eq(s.ui_url, "https://127.0.0.1:8080/");
	cfg.tls_cert[0] = 0;
	snprintf(cfg.http, sizeof(cfg.http), "0.0.0.0:9000");
	ck_assert_int_eq(gethostname(host, sizeof(host)), 0);
	host[sizeof(host) - 1] = 0;
	ck_assert_int_eq(vmac_mqtt_settings_parse(&cfg, &s, err, sizeof(err)), 0);
	snprintf(want, sizeof(want), "http://%s:9000/", host);
	ck_assert_str_eq(s.ui_url, want);
	snprintf(cfg.http, sizeof(cfg.http), "127.0.0.1:0");
	ck_assert_int_eq(vmac_mqtt_settings_parse(&cfg, &s, err, sizeof(err)), 0);
	ck_assert_str_eq(s.ui_url, "");
	snprintf(cfg.ui_url, sizeof(cfg.ui_url), "https://plant.example/vmac/");
	ck_assert_int_eq(vmac_mqtt_settings_parse(&cfg, &s, err, sizeof(err)), 0);
	ck_assert_str_eq(s.ui_url, "https://plant.example/vmac/");
	snprintf(cfg.ui_url, sizeof(cfg.ui_url), "plant.example");
	ck_assert_int_ne(vmac_mqtt_settings_parse(&cfg, &s, err, sizeof(err)), 0);
	ck_assert_ptr_nonnull(strstr(err, "ui_url"));
}
END_TEST

/* A machine's _health ends with its primary board's clock: null until it
 * sends a TIMED reply (HA reads None as unknown), then its state, its
 * bound in us (null while unknown) and whether it acted on arrival. */
START_TEST(health_says_the_board_clock_or_null)
{
	struct vmac_board_clock_status c;
	char out[160];
	memset(&c, 0, sizeof(c));
	c.state = 2;
	c.bound_ns = 1500;
	mqtt_health_clock_fields(&c, out, sizeof(out));
	ck_assert_str_eq(out, ",\"clock_state\":null,\"clock_bound_us\":null,\"clock_on_arrival\":null");
	c.known = 1;
	mqtt_health_clock_fields(&c, out, sizeof(out));
	ck_assert_str_eq(out, ",\"clock_state\":\"locked\",\"clock_bound_us\":1.5,\"clock_on_arrival\":false");
	c.state = 3;
	c.on_arrival = 1;
	c.bound_ns = 0xFFFFFFFFu;
	mqtt_health_clock_fields(&c, out, sizeof(out));
	ck_assert_str_eq(out, ",\"clock_state\":\"holdover\",\"clock_bound_us\":null,\"clock_on_arrival\":true");
	c.state = 9; /* not a state: said as none rather than a wrong one */
	mqtt_health_clock_fields(&c, out, sizeof(out));
	ck_assert_ptr_nonnull(strstr(out, "\"clock_state\":null"));
}
END_TEST

/* Its Home Assistant sensors: the state an enum of the five states
 * (diagnostic, no state class: HA refuses one on an enum), the bound a
 * measurement in us, off by default. */
START_TEST(home_assistant_has_the_clock_as_diagnostic_sensors)
{
	struct vmac_mqtt_settings s;
	struct vmac_device_status st;
	json_t *manifest = json_pack("{s:{}}", "variables"), *configs, *clock = NULL, *bound = NULL, *cfg;
	const char *topic;
	memset(&s, 0, sizeof(s));
	memset(&st, 0, sizeof(st));
	snprintf(s.host_id, sizeof(s.host_id), "kitchen");
	snprintf(s.prefix, sizeof(s.prefix), "vmac");
	snprintf(s.discovery_prefix, sizeof(s.discovery_prefix), "homeassistant");
	configs = mqtt_ha_configs(&s, "washer-1", "washer", "1.2.0", manifest, &st);
	json_object_foreach(configs, topic, cfg)
	{
		if (strstr(topic, "/_health_clock_state/"))
			clock = cfg;
		if (strstr(topic, "/_health_clock_bound_us/"))
			bound = cfg;
	}
	ck_assert_ptr_nonnull(clock);
	ck_assert_ptr_nonnull(bound);
	ck_assert_str_eq(json_string_value(json_object_get(clock, "device_class")), "enum");
	ck_assert_str_eq(json_string_value(json_object_get(clock, "entity_category")), "diagnostic");
	ck_assert_str_eq(json_string_value(json_object_get(clock, "value_template")), "{{ value_json.clock_state }}");
	ck_assert_str_eq(json_string_value(json_object_get(clock, "state_topic")), "vmac/kitchen/washer-1/_health");
	ck_assert_ptr_null(json_object_get(clock, "state_class"));
	ck_assert_int_eq(json_array_size(json_object_get(clock, "options")), 5);
	ck_assert_str_eq(json_string_value(json_array_get(json_object_get(clock, "options"), 2)), "locked");
	ck_assert_str_eq(json_string_value(json_object_get(bound, "unit_of_measurement")), "µs");
	ck_assert_str_eq(json_string_value(json_object_get(bound, "state_class")), "measurement");
	ck_assert(json_is_false(json_object_get(bound, "enabled_by_default")));
	json_decref(configs);
	json_decref(manifest);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("mqtt");
	TCase *tc = tcase_create("payloads");
	tcase_add_test(tc, value_text_says_unknown_as_home_assistant_reads_it);
	tcase_add_test(tc, untyped_payloads_read_as_their_text_says);
	tcase_add_test(tc, a_select_or_text_gets_the_payload_as_a_string);
	tcase_add_test(tc, a_number_boolean_or_numeric_choice_gets_its_type);
	tcase_add_test(tc, a_declared_precision_rounds_what_is_published);
	tcase_add_test(tc, a_precision_goes_out_a_whole_step_from_what_was_sent);
	tcase_add_test(tc, noise_narrower_than_a_step_does_not_flip_what_is_shown);
	tcase_add_test(tc, noise_of_a_whole_step_flips_it_far_less_than_its_rounding);
	suite_add_tcase(s, tc);
	tcase_add_test(tc, ui_url_from_the_setting_or_the_http_address);
	tcase_add_test(tc, a_machine_is_found_in_any_order);
	tcase_add_test(tc, health_says_the_board_clock_or_null);
	tcase_add_test(tc, home_assistant_has_the_clock_as_diagnostic_sensors);
	tc = tcase_create("site");
	tcase_add_test(tc, site_view_reads_host_topics_and_none);
	suite_add_tcase(s, tc);
	tc = tcase_create("sparkplug ids");
	tcase_add_test(tc, every_machine_name_the_bus_takes_is_a_sparkplug_device_id);
	suite_add_tcase(s, tc);
	return s;
}
