/* Unit tests of a plant model in Lua (core/driver/luaplant.h; docs/BOARD.md,
 * "Plant models in Lua"), the half that checks what a plant is: the load
 * and its refusals, each naming the field at fault; the inputs read from
 * the state and the outputs the step sees; operator actions (functions,
 * buttons, state fields) and their refusals; unsafe episodes and their
 * text. Failures, determinism, the sandbox and core/sim are in
 * test_luaplant_run.c. */
#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check_main.h"
#include "luaplant_helpers.h"

/* The smallest plant that loads, to which a refusal adds one mistake. */
#define STEP "step = function(p, dt, out) end"

static void setup(void)
{
	luaplant_limits_reset();
}

/* ---- the load ---- */

START_TEST(a_file_that_returns_no_table_is_refused)
{
	expect_refused("return 5", "return 5", PLANT_FILE ": plant: the file must return a table", "got number");
	expect_refused("no return", "local x = 1", "must return a table", "got nil");
}
END_TEST

START_TEST(an_unknown_top_level_field_is_refused_by_name)
{
	expect_refused("stepp", "return { io = {}, " STEP ", stepp = 1 }", "unknown field 'stepp'",
	               "name, driver, io, state, step, actions");
	expect_refused("a numeric key", "return { io = {}, " STEP ", 7 }", "unknown field 'number'", NULL);
}
END_TEST

START_TEST(io_missing_or_a_bad_channel_is_refused)
{
	expect_refused("no io", "return { " STEP " }", "io must be a table", NULL);
	expect_refused("io a text", "return { io = 'do0', " STEP " }", "io must be a table", NULL);
	expect_refused("channel do9", "return { io = { lamp = 'do9' }, " STEP " }", "io.lamp: unknown channel 'do9'",
	               NULL);
	expect_refused("channel a number", "return { io = { lamp = 3 }, " STEP " }", "io.lamp: must be a channel",
	               NULL);
	expect_refused("two names on one output", "return { io = { a = 'do1', b = 'do1' }, " STEP " }",
	               "is already io.", NULL);
}
END_TEST

START_TEST(io_board_is_refused_a_plant_is_behind_one_board)
{
	expect_refused("board = 1", "return { io = { door = { 'di0', board = 1 } }, " STEP " }",
	               "io.door: board: a plant is behind one board", NULL);
	expect_refused("board = 0", "return { io = { door = { 'di0', board = 0 } }, " STEP " }",
	               "io.door: board: a plant is behind one board", NULL);
}
END_TEST

START_TEST(an_analog_scale_of_zero_is_refused)
{
	expect_refused("scale 0", "return { io = { temp = { 'ai0', scale = 0 } }, " STEP " }",
	               "io.temp: scale must be a number other than 0", NULL);
	expect_refused("scale NaN", "return { io = { temp = { 'ai1', scale = 0/0 } }, " STEP " }",
	               "io.temp: scale and offset must be numbers", NULL);
	expect_refused("offset inf", "return { io = { temp = { 'ai1', offset = 1/0 } }, " STEP " }",
	               "io.temp: scale must be a number other than 0, offset a number", NULL);
}
END_TEST

START_TEST(step_missing_or_not_a_function_is_refused)
{
	expect_refused("no step", "return { io = {} }", PLANT_FILE ": plant: step must be a function", NULL);
	expect_refused("step a number", "return { io = {}, step = 5 }", "step must be a function", NULL);
}
END_TEST

START_TEST(state_not_a_table_is_refused)
{
	expect_refused("state 5", "return { io = {}, " STEP ", state = 5 }", "state must be a table", NULL);
	expect_refused("state a text", "return { io = {}, " STEP ", state = 'hot' }", "state must be a table", NULL);
}
END_TEST

START_TEST(an_action_naming_no_digital_input_is_refused)
{
	expect_refused("an output as a button", "return { io = { lamp = 'do0' }, " STEP ", actions = { go = 'lamp' } }",
	               "actions.go: 'lamp' is not a digital input of io", NULL);
	expect_refused("an analog input as a button", "return { io = { t = 'ai0' }, " STEP ", actions = { go = 't' } }",
	               "actions.go: 't' is not a digital input", NULL);
	expect_refused("a missing input", "return { io = { b = 'di0' }, " STEP ", actions = { go = 'nosuch' } }",
	               "actions.go: 'nosuch' is not a digital input", NULL);
	expect_refused("a channel rather than a name",
	               "return { io = { b = 'di0' }, " STEP ", actions = { go = 'di0' } }",
	               "actions.go: 'di0' is not a digital input", NULL);
}
END_TEST

START_TEST(an_action_that_is_no_function_or_text_is_refused)
{
	expect_refused("action 5", "return { io = {}, " STEP ", actions = { go = 5 } }",
	               "actions.go: must be a function (p, value) or the name of a digital input", NULL);
	expect_refused("actions 5", "return { io = {}, " STEP ", actions = 5 }", "actions must be a table", NULL);
	expect_refused("a bad action name", "return { io = {}, " STEP ", actions = { ['go now'] = function() end } }",
	               "actions: names are", NULL);
}
END_TEST

START_TEST(a_bad_name_or_driver_is_refused)
{
	expect_refused("a space in name", "return { name = 'dry er', io = {}, " STEP " }", "name 'dry er': names are",
	               NULL);
	expect_refused("name a number", "return { name = 5, io = {}, " STEP " }", "name must be a text", NULL);
	expect_refused("name of 32", "return { name = string.rep('d', 32), io = {}, " STEP " }", "name 'dddd", NULL);
	expect_refused("driver with a dot", "return { driver = 'my.dryer', io = {}, " STEP " }",
	               "driver 'my.dryer': names are", NULL);
	expect_refused("driver empty", "return { driver = '', io = {}, " STEP " }", "driver '': names are", NULL);
}
END_TEST

START_TEST(names_default_to_the_file_and_the_name)
{
	struct vmac_luaplant *p = plant_of("return { io = {}, " STEP " }");
	ck_assert_str_eq(vmac_luaplant_name(p), "t");
	ck_assert_str_eq(vmac_luaplant_driver(p), "t");
	vmac_luaplant_free(p);
	p = plant_of("return { name = 'dryer', io = {}, " STEP " }");
	ck_assert_msg(strcmp(vmac_luaplant_driver(p), "dryer") == 0, "driver defaults to the name, got '%s'",
	              vmac_luaplant_driver(p));
	vmac_luaplant_free(p);
	p = plant_of("return { name = 'dryer', driver = 'dryer_v2', io = {}, " STEP " }");
	ck_assert_str_eq(vmac_luaplant_name(p), "dryer");
	ck_assert_str_eq(vmac_luaplant_driver(p), "dryer_v2");
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(a_syntax_error_names_file_and_line)
{
	expect_refused("syntax", "return {\n  io = {},\n  step = function(p, dt, out\nend }", PLANT_FILE ":4:", NULL);
}
END_TEST

START_TEST(a_long_path_is_named_by_its_tail)
{
	/* Lua's messages cut a chunk name of 60 bytes or more at its start:
	 * the plant's messages name the tail of the path that fits. */
	static const char *const path = "/var/lib/a-folder-with-a-long-name/site-of-the-test/drivers/plants/dryer.lua";
	static const char *const src = "return {\n  io = {},\n  step = function(p, dt, out\nend }";
	struct vmac_luaplant *p = NULL;
	char err[VMAC_DRIVER_ERR_MAX] = "";
	ck_assert_int_eq(vmac_luaplant_load(path, src, strlen(src), "dryer", &luaplant_limits, &p, err, sizeof(err)),
	                 -1);
	ck_assert_msg(strncmp(err, "site-of-the-test/drivers/plants/dryer.lua:4:", 44) == 0,
	              "a long path's syntax error: %s", err);
	ck_assert_int_eq(vmac_luaplant_load(path, "return 1", 8, "dryer", &luaplant_limits, &p, err, sizeof(err)), -1);
	ck_assert_msg(strncmp(err, "site-of-the-test/drivers/plants/dryer.lua: plant: ", 50) == 0,
	              "a long path's refusal: %s", err);
}
END_TEST

START_TEST(a_file_that_raises_at_load_names_file_and_line)
{
	expect_refused("error()", "local x = 1\nerror('no dryer today')\nreturn {}", PLANT_FILE ":2: no dryer today",
	               NULL);
	expect_refused("a nil call", "\n\nlocal t = nil\nt.x = 1\nreturn {}", PLANT_FILE ":4:", NULL);
	expect_refused("a loop at load", "while true do end", "time budget exceeded", NULL);
	expect_refused("memory at load", "local t = {} for i = 1, 100 do t[i] = string.rep('x', 60000) .. i end",
	               PLANT_FILE ": memory cap exceeded", NULL);
}
END_TEST

/* ---- inputs and outputs ---- */

/* The board's inputs of a plant whose field `v` (io channel chan, with
 * extra io options opts) holds the Lua expression expr. */
static struct vmac_inputs inputs_of(const char *chan, const char *opts, const char *expr)
{
	char src[512];
	struct vmac_luaplant *p;
	struct vmac_inputs in;
	snprintf(src, sizeof(src), "return { io = { v = { '%s'%s } }, state = { v = %s }, " STEP " }", chan, opts,
	         expr);
	p = plant_of(src);
	in = sensed(p);
	vmac_luaplant_free(p);
	return in;
}

START_TEST(a_digital_input_is_on_for_true_or_a_number_other_than_0)
{
	static const struct {
		const char *expr;
		int on;
	} cases[] = {{"true", 1}, {"false", 0}, {"1", 1},    {"0", 0},  {"-3", 1},
	             {"0.5", 1},  {"nil", 0},   {"'on'", 0}, {"{}", 0}, {"0/0", 1}};
	unsigned i;
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		struct vmac_inputs in = inputs_of("di5", "", cases[i].expr);
		ck_assert_msg(in.digital == (cases[i].on ? 0x20 : 0), "di5 from %s: digital 0x%02x, expected 0x%02x",
		              cases[i].expr, in.digital, cases[i].on ? 0x20 : 0);
	}
}
END_TEST

START_TEST(an_analog_input_is_counts_rounded_and_clipped)
{
	static const struct {
		const char *expr;
		int counts;
	} cases[] = {
	    {"20", 800},   {"20.01", 800},  {"20.03", 801}, {"-20", 0},    {"-25", 0},   {"184.75", 4095},
	    {"1e9", 4095}, {"1/0", 4095},   {"-1/0", 0},    {"0/0", 0},    {"'hot'", 0}, {"true", 0},
	    {"nil", 0},    {"184.7", 4094}, {"-19.97", 1},  {"-19.98", 0},
	};
	unsigned i;
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		struct vmac_inputs in = inputs_of("ai1", ", scale = 0.05, offset = -20", cases[i].expr);
		ck_assert_msg(in.analog[1] == cases[i].counts && in.analog[0] == 0,
		              "ai1 (scale 0.05, offset -20) from %s: %u counts, expected %d (ai0 %u)", cases[i].expr,
		              in.analog[1], cases[i].counts, in.analog[0]);
	}
	ck_assert_uint_eq(inputs_of("ai0", "", "4095.4").analog[0], 4095);
	ck_assert_uint_eq(inputs_of("ai0", "", "17.5").analog[0], 18);
	ck_assert_msg(inputs_of("ai0", ", scale = -2", "-100").analog[0] == 50,
	              "a negative scale: -100 / -2 should read 50 counts");
}
END_TEST

START_TEST(the_encoder_wraps_to_a_signed_32_bit_count)
{
	static const struct {
		const char *expr;
		int32_t counts;
	} cases[] = {
	    {"0", 0},
	    {"12345", 12345},
	    {"-1", -1},
	    {"2^31 - 1", INT32_MAX},
	    {"2^31", INT32_MIN},
	    {"-2^31", INT32_MIN},
	    {"-2^31 - 1", INT32_MAX},
	    {"2^32", 0},
	    {"2^32 + 5", 5},
	    {"-2^32 - 7", -7},
	    {"1.7", 1},
	    {"0/0", 0},
	    {"1/0", 0},
	    {"'x'", 0},
	};
	unsigned i;
	for (i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		struct vmac_inputs in = inputs_of("encoder", "", cases[i].expr);
		ck_assert_msg(in.encoder == cases[i].counts, "encoder from %s: %ld, expected %ld", cases[i].expr,
		              (long)in.encoder, (long)cases[i].counts);
	}
}
END_TEST

/* A dryer-like plant: it heats while the heater is on and the door closed,
 * turns the drum by the PWM, and notes what its step saw in `out`. */
static const char *const OUTPUTS_PLANT =
    "return {\n"
    "  io = { heater = 'do0', fan = 'do6', motor = 'pwm', door_closed = 'di0', hot = 'di1',\n"
    "         temp_c = { 'ai0', scale = 0.05, offset = -20 }, drum = 'encoder' },\n"
    "  state = { temp_c = 20, door_closed = true, drum = 0 },\n"
    "  step = function(p, dt, out)\n"
    "    p.seen_heater, p.seen_fan, p.seen_motor = out.heater, out.fan, out.motor\n"
    "    p.seen_kinds = type(out.heater) .. ' ' .. type(out.fan) .. ' ' .. type(out.motor)\n"
    "    if out.heater and p.door_closed then p.temp_c = p.temp_c + 10 * dt end\n"
    "    p.hot = p.temp_c > 21\n"
    "    p.drum = p.drum + out.motor * dt\n"
    "  end,\n"
    "}\n";

START_TEST(outputs_reach_the_step_as_booleans_and_a_pwm_number)
{
	struct vmac_luaplant *p = plant_of(OUTPUTS_PLANT);
	struct vmac_outputs out = {0x41, -250}; /* do0 and do6 on */
	struct vmac_value v;
	vmac_luaplant_actuate(p, &out);
	steps_ok(p, 1, 0.1);
	ck_assert_msg(vmac_luaplant_field(p, "seen_kinds", &v) == 0 && v.type == VMAC_VALUE_STRING,
	              "the step did not record the kinds of out's fields");
	ck_assert_msg(strcmp(v.str, "boolean boolean number") == 0, "out.heater, out.fan, out.motor were: %s", v.str);
	ck_assert_msg(field_number(p, "seen_heater") == 1 && field_number(p, "seen_fan") == 1,
	              "do0 and do6 on, but the step saw heater %g, fan %g", field_number(p, "seen_heater"),
	              field_number(p, "seen_fan"));
	ck_assert_msg(field_number(p, "seen_motor") == -250, "pwm -250, the step saw %g",
	              field_number(p, "seen_motor"));
	out.digital = 0;
	out.pwm = 1000;
	vmac_luaplant_actuate(p, &out);
	steps_ok(p, 1, 0.1);
	ck_assert_msg(field_number(p, "seen_heater") == 0 && field_number(p, "seen_fan") == 0,
	              "outputs off, but the step saw heater %g, fan %g", field_number(p, "seen_heater"),
	              field_number(p, "seen_fan"));
	ck_assert_msg(field_number(p, "seen_motor") == 1000, "pwm 1000, the step saw %g",
	              field_number(p, "seen_motor"));
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(inputs_follow_what_the_step_computes_from_the_outputs)
{
	struct vmac_luaplant *p = plant_of(OUTPUTS_PLANT);
	struct vmac_outputs out = {0x01, 500};
	struct vmac_inputs in = sensed(p);
	ck_assert_msg(in.digital == 0x01 && in.analog[0] == 800 && in.encoder == 0,
	              "at load: digital 0x%02x (want 0x01), temp %u counts (want 800), drum %ld", in.digital,
	              in.analog[0], (long)in.encoder);
	vmac_luaplant_actuate(p, &out);
	steps_ok(p, 10, 0.1); /* 1 s: +10 degrees, 500 counts of drum */
	in = sensed(p);
	ck_assert_msg(in.analog[0] == 1000, "temp after 1 s of heating: %u counts, expected 1000 (30 C)", in.analog[0]);
	ck_assert_msg(in.digital == 0x03, "door closed and hot: digital 0x%02x, expected 0x03", in.digital);
	ck_assert_msg(in.encoder == 500, "drum after 1 s at pwm 500: %ld counts, expected 500", (long)in.encoder);
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(applied_reports_the_outputs_actuated)
{
	struct vmac_luaplant *p = plant_of(OUTPUTS_PLANT);
	struct vmac_outputs out = {0x41, -999};
	struct vmac_inputs in = sensed(p);
	ck_assert_msg(in.applied.digital == 0 && in.applied.pwm == 0, "applied at load: 0x%02x %d", in.applied.digital,
	              in.applied.pwm);
	vmac_luaplant_actuate(p, &out);
	in = sensed(p);
	ck_assert_msg(in.applied.digital == 0x41 && in.applied.pwm == -999,
	              "applied right after actuate: 0x%02x %d, expected 0x41 -999", in.applied.digital, in.applied.pwm);
	steps_ok(p, 2, 0.05);
	in = sensed(p);
	ck_assert_msg(in.applied.digital == 0x41 && in.applied.pwm == -999, "applied after steps: 0x%02x %d",
	              in.applied.digital, in.applied.pwm);
	vmac_luaplant_free(p);
}
END_TEST

/* ---- actions ---- */

static const char *const ACTIONS_PLANT =
    "return {\n"
    "  io = { door_closed = 'di0', start_button = 'di3', loaded = 'di4' },\n"
    "  state = { door_closed = true, start_button = false, load_kg = 0, loaded = false, label = 'x' },\n"
    "  step = function(p, dt, out) p.loaded = p.load_kg > 0 end,\n"
    "  actions = {\n"
    "    door = function(p, v)\n"
    "      if v ~= 0 and v ~= 1 then return false, 'door takes 0 (open) or 1 (closed)' end\n"
    "      p.door_closed = v == 1\n"
    "    end,\n"
    "    silent_no = function(p, v) return false end,\n"
    "    yes_nil = function(p, v) p.said_yes = v return nil, 'not a refusal' end,\n"
    "    start = 'start_button',\n"
    "  },\n"
    "}\n";

START_TEST(an_action_function_that_accepts_changes_the_state)
{
	struct vmac_luaplant *p = plant_of(ACTIONS_PLANT);
	char why[256] = "";
	ck_assert_msg(vmac_luaplant_set(p, "door", 0, why, sizeof(why)) == 0, "door 0 refused: %s", why);
	ck_assert_msg(field_number(p, "door_closed") == 0, "door 0 did not open the door");
	ck_assert_msg(digital_in(p, 0) == 0, "the door input still reads closed right after door 0");
	ck_assert_msg(vmac_luaplant_set(p, "yes_nil", 3, why, sizeof(why)) == 0,
	              "an action returning nil, 'text' is no refusal, got: %s", why);
	ck_assert_msg(field_number(p, "said_yes") == 3, "the action did not get its value");
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(an_action_function_refusing_says_why_and_changes_nothing)
{
	struct vmac_luaplant *p = plant_of(ACTIONS_PLANT);
	struct vmac_inputs before = sensed(p), after;
	char why[256] = "";
	ck_assert_msg(vmac_luaplant_set(p, "door", 7, why, sizeof(why)) == 1, "door 7 was not refused");
	ck_assert_msg(strcmp(why, "door takes 0 (open) or 1 (closed)") == 0, "the refusal says: '%s'", why);
	after = sensed(p);
	ck_assert_msg(before.digital == after.digital && field_number(p, "door_closed") == 1,
	              "a refused action changed the plant: digital 0x%02x, was 0x%02x", after.digital, before.digital);
	ck_assert_msg(vmac_luaplant_set(p, "silent_no", 1, why, sizeof(why)) == 1, "false alone was not a refusal");
	ck_assert_msg(strstr(why, "says no") != NULL, "a refusal without a reason says: '%s'", why);
	ck_assert_msg(vmac_luaplant_failure(p) == NULL, "a refusal failed the plant: %s", vmac_luaplant_failure(p));
	vmac_luaplant_free(p);
}
END_TEST

/* After a button action: the input reads on until held_s of real time
 * (steps of plant_dt_s at time_scale), and off from then on. */
static void expect_button_held(double time_scale, double plant_dt_s)
{
	struct vmac_luaplant *p;
	char why[256] = "";
	double real_dt_s = plant_dt_s / time_scale, held_s = 0;
	int steps = 0;
	luaplant_limits.time_scale = time_scale;
	p = plant_of(ACTIONS_PLANT);
	ck_assert_msg(digital_in(p, 3) == 0, "the start button reads on before it is pressed");
	ck_assert_msg(vmac_luaplant_set(p, "start", 1, why, sizeof(why)) == 0, "start refused: %s", why);
	ck_assert_msg(digital_in(p, 3) == 1, "the start button does not read on right after the action");
	while (held_s + real_dt_s < VMAC_LUAPLANT_BUTTON_S - 1e-9) {
		steps_ok(p, 1, plant_dt_s);
		held_s += real_dt_s;
		steps++;
		ck_assert_msg(digital_in(p, 3) == 1, "time scale %g: the button let go after %d steps (%.3f s real)",
		              time_scale, steps, held_s);
	}
	steps_ok(p, 1, plant_dt_s);
	steps++;
	ck_assert_msg(digital_in(p, 3) == 0,
	              "time scale %g, steps of %g s: the button still reads on after %d steps = %.3f s of real time "
	              "(it holds %.1f s)",
	              time_scale, plant_dt_s, steps, steps * real_dt_s, VMAC_LUAPLANT_BUTTON_S);
	ck_assert_msg(field_number(p, "start_button") == 0, "the button action changed the state's field");
	steps_ok(p, 5, plant_dt_s);
	ck_assert_msg(digital_in(p, 3) == 0, "the button came back on");
	vmac_luaplant_free(p);
}

START_TEST(a_button_holds_its_input_half_a_second_of_real_time)
{
	expect_button_held(1, 0.1);
	expect_button_held(1, 0.01);
	expect_button_held(1, 0.001);
	expect_button_held(10, 0.1); /* 5 s of plant time */
	expect_button_held(0.5, 0.1);
}
END_TEST

START_TEST(a_numeric_state_field_takes_any_number)
{
	struct vmac_luaplant *p = plant_of(ACTIONS_PLANT);
	char why[256] = "";
	ck_assert_msg(vmac_luaplant_set(p, "load_kg", 5.5, why, sizeof(why)) == 0, "load_kg 5.5 refused: %s", why);
	ck_assert_msg(field_number(p, "load_kg") == 5.5, "load_kg is %g after setting 5.5", field_number(p, "load_kg"));
	steps_ok(p, 1, 0.01);
	ck_assert_msg(digital_in(p, 4) == 1, "the step did not see the load set");
	ck_assert_msg(vmac_luaplant_set(p, "load_kg", -1e6, why, sizeof(why)) == 0, "load_kg -1e6 refused: %s", why);
	ck_assert_msg(vmac_luaplant_set(p, "load_kg", NAN, why, sizeof(why)) == 1, "load_kg NaN accepted");
	ck_assert_msg(strstr(why, "load_kg takes a number") != NULL, "NaN refused with: '%s'", why);
	ck_assert_msg(field_number(p, "load_kg") == -1e6, "a refused NaN changed load_kg to %g",
	              field_number(p, "load_kg"));
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(a_boolean_state_field_takes_0_or_1)
{
	struct vmac_luaplant *p = plant_of(ACTIONS_PLANT);
	char why[256] = "";
	ck_assert_msg(vmac_luaplant_set(p, "door_closed", 0, why, sizeof(why)) == 0, "door_closed 0 refused: %s", why);
	ck_assert_msg(field_number(p, "door_closed") == 0 && digital_in(p, 0) == 0, "door_closed 0 did not open");
	ck_assert_msg(vmac_luaplant_set(p, "door_closed", 1, why, sizeof(why)) == 0, "door_closed 1 refused: %s", why);
	ck_assert_msg(field_number(p, "door_closed") == 1 && digital_in(p, 0) == 1, "door_closed 1 did not close");
	ck_assert_msg(vmac_luaplant_set(p, "door_closed", 2, why, sizeof(why)) == 1, "door_closed 2 accepted");
	ck_assert_msg(strstr(why, "door_closed takes 0 or 1") != NULL, "2 refused with: '%s'", why);
	ck_assert_msg(vmac_luaplant_set(p, "door_closed", NAN, why, sizeof(why)) == 1, "door_closed NaN accepted");
	ck_assert_msg(vmac_luaplant_set(p, "door_closed", 0.5, why, sizeof(why)) == 1, "door_closed 0.5 accepted");
	ck_assert_msg(field_number(p, "door_closed") == 1, "a refused value changed door_closed");
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(an_unknown_name_is_refused_listing_actions_and_fields)
{
	struct vmac_luaplant *p = plant_of(ACTIONS_PLANT);
	char why[512] = "";
	static const char *const listed[] = {"door", "start", "silent_no", "load_kg", "door_closed", "start_button"};
	unsigned i;
	ck_assert_msg(vmac_luaplant_set(p, "sauna", 1, why, sizeof(why)) == 1, "an unknown name was accepted");
	ck_assert_msg(strstr(why, "no action or state field 'sauna'") != NULL, "the refusal says: '%s'", why);
	for (i = 0; i < sizeof(listed) / sizeof(listed[0]); i++)
		ck_assert_msg(strstr(why, listed[i]) != NULL, "the refusal does not list '%s': '%s'", listed[i], why);
	ck_assert_msg(strstr(why, "label") == NULL, "a text field is listed as settable: '%s'", why);
	ck_assert_msg(vmac_luaplant_set(p, "label", 1, why, sizeof(why)) == 1, "a text field took a number");
	ck_assert_msg(vmac_luaplant_failure(p) == NULL, "a refusal failed the plant");
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(actions_are_fixed_at_load)
{
	/* The plant's code holds its actions table and changes it later: an
	 * action that then names no digital input must not reach the board. */
	struct vmac_luaplant *p = plant_of("local actions = { start = 'button', go = 'button' }\n"
	                                   "return { io = { button = 'di2', lamp = 'do1' }, actions = actions,\n"
	                                   "  step = function(p, dt, out)\n"
	                                   "    actions.start = 'nosuch'; actions.go = 'lamp'\n"
	                                   "    actions.new = function(p) p.x = 1 end\n"
	                                   "  end }\n");
	char why[256] = "";
	int rc;
	steps_ok(p, 1, 0.01);
	rc = vmac_luaplant_set(p, "start", 1, why, sizeof(why));
	ck_assert_msg(rc == 0 && digital_in(p, 2) == 1, "the start button checked at load: rc %d (%s), di2 %d", rc, why,
	              digital_in(p, 2));
	rc = vmac_luaplant_set(p, "go", 1, why, sizeof(why));
	ck_assert_msg(rc == 0 && sensed(p).digital == 0x04, "go (button) after the change: rc %d (%s), digital 0x%02x",
	              rc, why, sensed(p).digital);
	ck_assert_msg(vmac_luaplant_set(p, "new", 1, why, sizeof(why)) == 1, "an action added after load was run");
	vmac_luaplant_free(p);
}
END_TEST

/* ---- unsafe episodes ---- */

static const char *const UNSAFE_PLANT = "return {\n"
                                        "  io = {},\n"
                                        "  state = { mode = 0 },\n"
                                        "  step = function(p, dt, out)\n"
                                        "    if p.mode == 1 then return 'heater on with the drum still' end\n"
                                        "    if p.mode == 2 then return 'x' .. string.rep('\\195\\169', 100) end\n"
                                        "    if p.mode == 3 then return 'a\\tb\\nc\\127d\\0e' end\n"
                                        "    if p.mode == 4 then return 42 end\n"
                                        "    if p.mode == 5 then return false end\n"
                                        "  end,\n"
                                        "}\n";

static void set_mode(struct vmac_luaplant *p, double mode)
{
	char why[256] = "";
	ck_assert_msg(vmac_luaplant_set(p, "mode", mode, why, sizeof(why)) == 0, "mode %g refused: %s", mode, why);
}

START_TEST(an_unsafe_episode_counts_once_per_stretch_of_texts)
{
	struct vmac_luaplant *p = plant_of(UNSAFE_PLANT);
	steps_ok(p, 3, 0.01);
	ck_assert_uint_eq(vmac_luaplant_unsafe_episodes(p), 0);
	ck_assert_str_eq(vmac_luaplant_unsafe_text(p), "");
	set_mode(p, 1);
	steps_ok(p, 5, 0.01);
	ck_assert_msg(vmac_luaplant_unsafe_episodes(p) == 1, "5 unsafe steps in a row: %u episodes, expected 1",
	              vmac_luaplant_unsafe_episodes(p));
	ck_assert_str_eq(vmac_luaplant_unsafe_text(p), "heater on with the drum still");
	ck_assert_msg(field_number(p, "unsafe_episodes") == 1, "field unsafe_episodes disagrees");
	set_mode(p, 5); /* false is safe too */
	steps_ok(p, 2, 0.01);
	set_mode(p, 1);
	steps_ok(p, 2, 0.01);
	ck_assert_msg(vmac_luaplant_unsafe_episodes(p) == 2, "safe, then unsafe again: %u episodes, expected 2",
	              vmac_luaplant_unsafe_episodes(p));
	set_mode(p, 3); /* another text, no safe step between: the same episode */
	steps_ok(p, 1, 0.01);
	ck_assert_msg(vmac_luaplant_unsafe_episodes(p) == 2, "a new text within an episode counted: %u",
	              vmac_luaplant_unsafe_episodes(p));
	ck_assert_msg(strcmp(vmac_luaplant_unsafe_text(p), "heater on with the drum still") == 0,
	              "the episode's text is not the one it began with: '%s'", vmac_luaplant_unsafe_text(p));
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(an_unsafe_text_is_one_printable_line)
{
	struct vmac_luaplant *p = plant_of(UNSAFE_PLANT);
	set_mode(p, 3);
	steps_ok(p, 1, 0.01);
	ck_assert_msg(strcmp(vmac_luaplant_unsafe_text(p), "a b c d") == 0,
	              "control characters (tab, newline, DEL) not made spaces, or the text not cut at a NUL: '%s'",
	              vmac_luaplant_unsafe_text(p));
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(a_long_unsafe_text_is_cut_at_120_bytes_on_a_character)
{
	struct vmac_luaplant *p = plant_of(UNSAFE_PLANT);
	const char *text;
	size_t n, i;
	set_mode(p, 2); /* 'x' then 100 two-byte characters: byte 120 is inside one */
	steps_ok(p, 1, 0.01);
	text = vmac_luaplant_unsafe_text(p);
	n = strlen(text);
	ck_assert_msg(n == 119, "the text kept is %zu bytes, expected 119 (120 would split a character)", n);
	ck_assert_msg(text[0] == 'x', "the text does not begin as returned");
	for (i = 1; i + 1 < n; i += 2)
		ck_assert_msg((unsigned char)text[i] == 0xC3 && (unsigned char)text[i + 1] == 0xA9,
		              "byte %zu of the cut text is not the character returned", i);
	vmac_luaplant_free(p);
	p = plant_of("return { io = {}, step = function() return string.rep('y', 500) end }");
	steps_ok(p, 1, 0.01);
	ck_assert_msg(strlen(vmac_luaplant_unsafe_text(p)) == VMAC_LUAPLANT_UNSAFE_MAX, "an ASCII text kept %zu bytes",
	              strlen(vmac_luaplant_unsafe_text(p)));
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(a_step_returning_a_number_fails_naming_it)
{
	struct vmac_luaplant *p = plant_of(UNSAFE_PLANT);
	const char *why;
	set_mode(p, 4);
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "a step returning 42 did not fail");
	why = vmac_luaplant_failure(p);
	ck_assert_msg(why && strstr(why, "step returned a number") && strstr(why, PLANT_FILE),
	              "the failure does not name the number returned and the file: %s", why ? why : "(none)");
	ck_assert_uint_eq(vmac_luaplant_unsafe_episodes(p), 0);
	vmac_luaplant_free(p);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("Lua plant");
	TCase *tc = tcase_create("load");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, a_file_that_returns_no_table_is_refused);
	tcase_add_test(tc, an_unknown_top_level_field_is_refused_by_name);
	tcase_add_test(tc, io_missing_or_a_bad_channel_is_refused);
	tcase_add_test(tc, io_board_is_refused_a_plant_is_behind_one_board);
	tcase_add_test(tc, an_analog_scale_of_zero_is_refused);
	tcase_add_test(tc, step_missing_or_not_a_function_is_refused);
	tcase_add_test(tc, state_not_a_table_is_refused);
	tcase_add_test(tc, an_action_naming_no_digital_input_is_refused);
	tcase_add_test(tc, an_action_that_is_no_function_or_text_is_refused);
	tcase_add_test(tc, a_bad_name_or_driver_is_refused);
	tcase_add_test(tc, names_default_to_the_file_and_the_name);
	tcase_add_test(tc, a_syntax_error_names_file_and_line);
	tcase_add_test(tc, a_file_that_raises_at_load_names_file_and_line);
	tcase_add_test(tc, a_long_path_is_named_by_its_tail);
	suite_add_tcase(s, tc);

	tc = tcase_create("inputs and outputs");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, a_digital_input_is_on_for_true_or_a_number_other_than_0);
	tcase_add_test(tc, an_analog_input_is_counts_rounded_and_clipped);
	tcase_add_test(tc, the_encoder_wraps_to_a_signed_32_bit_count);
	tcase_add_test(tc, outputs_reach_the_step_as_booleans_and_a_pwm_number);
	tcase_add_test(tc, inputs_follow_what_the_step_computes_from_the_outputs);
	tcase_add_test(tc, applied_reports_the_outputs_actuated);
	suite_add_tcase(s, tc);

	tc = tcase_create("actions");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, an_action_function_that_accepts_changes_the_state);
	tcase_add_test(tc, an_action_function_refusing_says_why_and_changes_nothing);
	tcase_add_test(tc, a_button_holds_its_input_half_a_second_of_real_time);
	tcase_add_test(tc, a_numeric_state_field_takes_any_number);
	tcase_add_test(tc, a_boolean_state_field_takes_0_or_1);
	tcase_add_test(tc, an_unknown_name_is_refused_listing_actions_and_fields);
	tcase_add_test(tc, actions_are_fixed_at_load);
	suite_add_tcase(s, tc);

	tc = tcase_create("unsafe episodes");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, an_unsafe_episode_counts_once_per_stretch_of_texts);
	tcase_add_test(tc, an_unsafe_text_is_one_printable_line);
	tcase_add_test(tc, a_long_unsafe_text_is_cut_at_120_bytes_on_a_character);
	tcase_add_test(tc, a_step_returning_a_number_fails_naming_it);
	suite_add_tcase(s, tc);
	return s;
}
