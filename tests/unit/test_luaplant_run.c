/* Unit tests of a Lua plant at run time (core/driver/luaplant.h) and of the
 * one interface vmac-board and `vmac test` see it through (core/sim/sim.h):
 * a plant that raises, loops or eats memory fails alone, with its file and
 * line, and holds its inputs; math.random seeded and os.clock() plant time;
 * the sandbox's missing pieces; the C plants and a Lua plant behind
 * vmac_sim_*: names, fields, refusals, the safety line and the failure told
 * once. The load, inputs, actions and unsafe texts are test_luaplant.c's. */
#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "../../core/sim/sim.h"
#include "check_main.h"
#include "luaplant_helpers.h"

static void setup(void)
{
	luaplant_limits_reset();
}

/* ---- failure ---- */

/* Counts its steps into the encoder and raises at the third. */
static const char *const FAILING_PLANT = "return {\n"
                                         "  io = { count = 'encoder', lamp = 'di0' },\n"
                                         "  state = { count = 0, lamp = true },\n"
                                         "  step = function(p, dt, out)\n"
                                         "    p.count = p.count + 1\n"
                                         "    if p.count > 2 then p.lamp = false; error('boom at ' .. p.count) end\n"
                                         "  end,\n"
                                         "  actions = { bad = function(p, v) return p.nosuch.x end,\n"
                                         "              spin = function(p, v) while true do end end },\n"
                                         "}\n";

START_TEST(a_step_that_raises_fails_with_file_and_line)
{
	struct vmac_luaplant *p = plant_of(FAILING_PLANT);
	const char *why;
	steps_ok(p, 2, 0.01);
	ck_assert_msg(vmac_luaplant_failure(p) == NULL, "a running plant says it failed");
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "the step that raises did not fail");
	why = vmac_luaplant_failure(p);
	ck_assert_msg(why && strstr(why, PLANT_FILE ":6: boom at 3"), "the failure does not say '%s': %s",
	              PLANT_FILE ":6: boom at 3", why ? why : "(none)");
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(a_failed_plant_refuses_everything_and_holds_its_inputs)
{
	struct vmac_luaplant *p = plant_of(FAILING_PLANT);
	struct vmac_outputs out = {0x05, 300};
	struct vmac_inputs in;
	struct vmac_value v;
	char why[VMAC_DRIVER_ERR_MAX + 64] = "";
	steps_ok(p, 2, 0.01);
	ck_assert_int_eq(vmac_luaplant_step(p, 0.01), -1);
	in = sensed(p);
	ck_assert_msg(in.encoder == 2 && in.digital == 0x01,
	              "inputs after the failure: encoder %ld, digital 0x%02x; expected those of the last good step "
	              "(2, 0x01), not the state the failing step left",
	              (long)in.encoder, in.digital);
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "a step after the failure did not return -1");
	ck_assert_msg(vmac_luaplant_set(p, "count", 5, why, sizeof(why)) == -1, "an action after the failure ran");
	ck_assert_msg(strstr(why, "has failed") && strstr(why, "boom at 3"), "the refused action says: %s", why);
	ck_assert_msg(vmac_luaplant_field(p, "count", &v) == -1, "a field read after the failure answered");
	in = sensed(p);
	ck_assert_msg(in.encoder == 2 && in.digital == 0x01, "the inputs moved after the failure");
	vmac_luaplant_actuate(p, &out);
	in = sensed(p);
	ck_assert_msg(in.applied.digital == 0x05 && in.applied.pwm == 300 && in.encoder == 2,
	              "after the failure applied follows the board's outputs and the inputs hold: 0x%02x %d, %ld",
	              in.applied.digital, in.applied.pwm, (long)in.encoder);
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(an_action_that_raises_or_loops_fails_the_plant)
{
	struct vmac_luaplant *p = plant_of(FAILING_PLANT);
	char why[VMAC_DRIVER_ERR_MAX + 64] = "";
	ck_assert_msg(vmac_luaplant_set(p, "bad", 1, why, sizeof(why)) == -1, "an action that raises did not fail");
	ck_assert_msg(strstr(why, "the plant failed") && strstr(why, PLANT_FILE ":8:"),
	              "the failed action does not say where: %s", why);
	ck_assert_msg(vmac_luaplant_failure(p) && strstr(vmac_luaplant_failure(p), PLANT_FILE ":8:"),
	              "the plant's failure is not the action's: %s", vmac_luaplant_failure(p));
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "the plant steps on after its action failed");
	vmac_luaplant_free(p);

	p = plant_of(FAILING_PLANT);
	ck_assert_int_eq(vmac_luaplant_set(p, "spin", 1, why, sizeof(why)), -1);
	ck_assert_msg(strstr(why, "time budget exceeded"), "an action that never returns: %s", why);
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(an_endless_step_fails_at_its_instruction_budget)
{
	static const char *const loops[] = {
	    "while true do end",
	    "while true do pcall(function() while true do end end) end",
	    "local t = {} for i = 1, 1e12 do t[1] = i end",
	};
	char src[512];
	unsigned i;
	for (i = 0; i < sizeof(loops) / sizeof(loops[0]); i++) {
		struct vmac_luaplant *p;
		snprintf(src, sizeof(src), "return { io = {}, step = function(p, dt, out)\n%s\nend }", loops[i]);
		p = plant_of(src);
		ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "'%s' in a step did not fail", loops[i]);
		ck_assert_msg(strstr(vmac_luaplant_failure(p), "time budget exceeded"),
		              "'%s' failed, but not on its budget: %s", loops[i], vmac_luaplant_failure(p));
		vmac_luaplant_free(p);
	}
}
END_TEST

START_TEST(the_load_gets_fifty_budgets_a_step_one)
{
	/* A million loop turns: five budgets of a step, a tenth of a load's. */
	struct vmac_luaplant *p = plant_of("for i = 1, 1e6 do end\n"
	                                   "return { io = {}, step = function(p, dt, out)\n"
	                                   "  for i = 1, 1e6 do end\n"
	                                   "end }");
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "a step of a million loop turns did not fail");
	ck_assert_msg(strstr(vmac_luaplant_failure(p), "time budget exceeded"), "it failed otherwise: %s",
	              vmac_luaplant_failure(p));
	vmac_luaplant_free(p);
}
END_TEST

START_TEST(a_step_eating_memory_fails_at_the_memory_cap)
{
	/* 20 distinct strings of 60,000 bytes a step: 1.2 MB, a few hundred
	 * instructions; the 4 MiB cap is reached at the fourth step, long
	 * before any instruction budget. */
	struct vmac_luaplant *p =
	    plant_of("return { io = {}, state = { hog = {} }, step = function(p, dt, out)\n"
	             "  for i = 1, 20 do p.hog[#p.hog + 1] = string.rep('x', 60000) .. #p.hog end\n"
	             "end }");
	int steps = 0;
	const char *why;
	while (steps < 20 && vmac_luaplant_step(p, 0.01) == 0)
		steps++;
	why = vmac_luaplant_failure(p);
	ck_assert_msg(why != NULL, "20 steps of 1.2 MB each did not fail the plant");
	ck_assert_msg(steps >= 2 && steps <= 4, "the plant failed after %d good steps, expected 2..4 (4 MiB cap): %s",
	              steps, why);
	ck_assert_msg(strstr(why, "memory cap exceeded") && strstr(why, "4096 KiB"),
	              "the failure does not say the memory cap: %s", why);
	ck_assert_msg(!strstr(why, "budget"), "a memory hog failed on its budget: %s", why);
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "the plant steps on after the memory cap");
	vmac_luaplant_free(p);
}
END_TEST

/* ---- determinism ---- */

static const char *const RANDOM_PLANT = "return { io = {}, state = { first = math.random(1000000000) },\n"
                                        "  step = function(p) p.a = math.random(1000000000); p.b = math.random() end }";

/* The first draw (at load), and the two of a step, of a plant of seed. */
static void draws(uint64_t seed, double out[3])
{
	struct vmac_luaplant *p;
	luaplant_limits.seed = seed;
	p = plant_of(RANDOM_PLANT);
	steps_ok(p, 1, 0.01);
	out[0] = field_number(p, "first");
	out[1] = field_number(p, "a");
	out[2] = field_number(p, "b");
	vmac_luaplant_free(p);
}

START_TEST(the_same_seed_gives_the_same_random_numbers)
{
	double one[3], two[3], other[3];
	draws(7, one);
	draws(7, two);
	draws(8, other);
	ck_assert_msg(one[0] == two[0] && one[1] == two[1] && one[2] == two[2],
	              "seed 7 twice: %.0f %.0f %g, then %.0f %.0f %g", one[0], one[1], one[2], two[0], two[1], two[2]);
	ck_assert_msg(one[0] != other[0] || one[1] != other[1],
	              "seeds 7 and 8 drew the same numbers: %.0f %.0f, %.0f %.0f", one[0], one[1], other[0], other[1]);
	draws(7ull + (1ull << 40), other);
	ck_assert_msg(one[0] != other[0] || one[1] != other[1], "a seed above 2^32 drew what seed 7 drew");
}
END_TEST

START_TEST(os_clock_is_plant_time)
{
	struct vmac_luaplant *p;
	char why[256] = "";
	luaplant_limits.time_scale = 10; /* plant time is what is stepped, whatever the scale */
	p = plant_of("return { io = {}, state = { at_load = os.clock(), clock = -1 },\n"
	             "  step = function(p, dt) p.clock = os.clock() end,\n"
	             "  actions = { mark = function(p) p.marked = os.clock() end } }");
	ck_assert_msg(field_number(p, "at_load") == 0, "os.clock() at load: %g, expected 0",
	              field_number(p, "at_load"));
	steps_ok(p, 1, 0.1);
	ck_assert_msg(fabs(field_number(p, "clock") - 0.1) < 1e-9,
	              "os.clock() in the first step of 0.1 s: %.17g, expected 0.1 (the time the step brings the "
	              "plant to)",
	              field_number(p, "clock"));
	steps_ok(p, 29, 0.1);
	ck_assert_msg(fabs(field_number(p, "clock") - 3.0) < 1e-9, "os.clock() after 30 steps of 0.1 s: %.17g",
	              field_number(p, "clock"));
	ck_assert_msg(vmac_luaplant_set(p, "mark", 1, why, sizeof(why)) == 0, "mark refused: %s", why);
	ck_assert_msg(fabs(field_number(p, "marked") - 3.0) < 1e-9, "os.clock() in an action after 3 s: %.17g",
	              field_number(p, "marked"));
	vmac_luaplant_free(p);
}
END_TEST

/* ---- the sandbox ---- */

/* What a plant may not reach: each is a nil global or field, or a
 * read-only table, so calling or setting it raises. */
static const char *const FORBIDDEN[] = {
    "print('hi')",
    "io.write('hi')",
    "io.open('/etc/passwd')",
    "os.execute('true')",
    "os.getenv('HOME')",
    "os.exit(3)",
    "os.remove('/tmp/x')",
    "load('return 1')",
    "loadstring('return 1')",
    "loadfile('/etc/passwd')",
    "dofile('/etc/passwd')",
    "debug.getinfo(1)",
    "package.loaded",
    "require('os')",
    "require('dryer_helpers')",
    "string.dump(function() end)",
    "('x'):dump()",
    "collectgarbage('count')",
    "getfenv(1)",
    "setfenv(1, {})",
    "newproxy(true)",
    "jit.off()",
    "ffi.C",
    "module('x')",
    "rawset(string, 'dump', 1)",
    "rawset(math, 'random', 1)",
};

START_TEST(the_sandbox_has_no_files_processes_loaders_or_print)
{
	char src[512];
	unsigned i;
	for (i = 0; i < sizeof(FORBIDDEN) / sizeof(FORBIDDEN[0]); i++) {
		struct vmac_luaplant *p;
		const char *why;
		snprintf(src, sizeof(src), "return { io = {}, step = function(p, dt, out)\nlocal x = %s\nend }",
		         FORBIDDEN[i]);
		p = plant_of(src);
		ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "a step calling %s did not fail", FORBIDDEN[i]);
		why = vmac_luaplant_failure(p);
		ck_assert_msg(why && strstr(why, PLANT_FILE ":2:"), "%s failed, but not at its line: %s", FORBIDDEN[i],
		              why ? why : "(none)");
		vmac_luaplant_free(p);

		snprintf(src, sizeof(src), "local x = %s\nreturn { io = {}, step = function() end }", FORBIDDEN[i]);
		expect_refused(FORBIDDEN[i], src, PLANT_FILE ":1:", NULL);
	}
}
END_TEST

START_TEST(library_tables_are_read_only)
{
	struct vmac_luaplant *p = plant_of("return { io = {}, step = function() math.random = function() return 4 end "
	                                   "end }");
	ck_assert_msg(vmac_luaplant_step(p, 0.01) == -1, "a step replaced math.random");
	ck_assert_msg(strstr(vmac_luaplant_failure(p), "read-only"), "the failure: %s", vmac_luaplant_failure(p));
	vmac_luaplant_free(p);
}
END_TEST

/* ---- core/sim: C plants and a Lua plant behind one interface ---- */

static char plant_dir[64];

static void sim_setup(void)
{
	char path[128];
	setup();
	snprintf(plant_dir, sizeof(plant_dir), "/tmp/vmac-test-luaplant-XXXXXX");
	ck_assert_msg(mkdtemp(plant_dir) != NULL, "cannot make a folder for the plant files");
	snprintf(path, sizeof(path), "%s/plants", plant_dir);
	ck_assert_msg(mkdir(path, 0700) == 0, "cannot make %s", path);
}

static void sim_teardown(void)
{
	char cmd[160];
	snprintf(cmd, sizeof(cmd), "rm -rf '%s'", plant_dir);
	if (plant_dir[0] && system(cmd) != 0)
		fprintf(stderr, "test_luaplant_run: could not remove %s\n", plant_dir);
}

/* DIR/plants/NAME.lua holding src; its path into path. */
static void write_plant(const char *name, const char *src, char *path, size_t len)
{
	FILE *f;
	snprintf(path, len, "%s/plants/%s.lua", plant_dir, name);
	f = fopen(path, "w");
	ck_assert_msg(f != NULL, "cannot write %s", path);
	fputs(src, f);
	fclose(f);
}

START_TEST(every_c_plant_is_made_by_name_and_no_other)
{
	static const char *const kinds[] = {"washer", "dishwasher", "lights", "generic"};
	struct vmac_sim s;
	unsigned i;
	for (i = 0; i < sizeof(kinds) / sizeof(kinds[0]); i++) {
		struct vmac_caps caps;
		ck_assert_msg(vmac_sim_init_c(&s, kinds[i]) == 0, "no C plant '%s'", kinds[i]);
		ck_assert_str_eq(vmac_sim_name(&s), kinds[i]);
		ck_assert_str_eq(vmac_sim_driver(&s), kinds[i]);
		caps = vmac_sim_caps(&s);
		ck_assert_msg(caps.digital_inputs == 8 && caps.digital_outputs == 7 && caps.analog_inputs == 2 &&
		                  caps.pwm_outputs == 1 && caps.encoders == 1,
		              "%s does not announce the generic board's {8, 7, 2, 1, 1}", kinds[i]);
		ck_assert_msg(vmac_sim_failure(&s) == NULL && vmac_sim_step(&s, 0.35) == 0, "%s: a C plant failed",
		              kinds[i]);
		vmac_sim_fini(&s);
	}
	ck_assert_msg(vmac_sim_init_c(&s, "dryer") == -1, "a C plant 'dryer' was made");
	ck_assert_msg(vmac_sim_init_c(&s, "") == -1, "a C plant '' was made");
	ck_assert_msg(vmac_sim_init_c(&s, "Washer") == -1, "a C plant 'Washer' was made");
}
END_TEST

/* Field name of the C plant s: its number, or the test fails. */
static double c_field(struct vmac_sim *s, const char *name, enum vmac_value_type type)
{
	struct vmac_value v;
	ck_assert_msg(vmac_sim_field(s, name, &v) == 0, "the %s plant has no field '%s' (it lists: %s)",
	              vmac_sim_name(s), name, vmac_sim_fields_text(s));
	ck_assert_msg(v.type == type, "the %s plant's field '%s' is of type %d, expected %d", vmac_sim_name(s), name,
	              (int)v.type, (int)type);
	return v.number;
}

static void expect_no_field(struct vmac_sim *s, const char *name)
{
	struct vmac_value v;
	ck_assert_msg(vmac_sim_field(s, name, &v) == -1, "the %s plant answers a field '%s'", vmac_sim_name(s), name);
}

START_TEST(c_plants_answer_their_fields_by_name)
{
	struct vmac_sim s;
	char why[256];
	ck_assert_int_eq(vmac_sim_init_c(&s, "washer"), 0);
	ck_assert_int_eq(vmac_sim_set(&s, "load_kg", 4.5, why, sizeof(why)), 0);
	ck_assert_msg(c_field(&s, "load_kg", VMAC_VALUE_NUMBER) == 4.5, "washer load_kg after setting 4.5");
	ck_assert_msg(c_field(&s, "drum_rpm", VMAC_VALUE_NUMBER) == 0, "the washer's drum turns at rest");
	c_field(&s, "water_l", VMAC_VALUE_NUMBER);
	c_field(&s, "water_c", VMAC_VALUE_NUMBER);
	ck_assert_msg(c_field(&s, "door_closed", VMAC_VALUE_BOOL) == 1, "the washer's door starts open");
	ck_assert_msg(c_field(&s, "door_locked", VMAC_VALUE_BOOL) == 0, "the washer's door starts locked");
	ck_assert_msg(c_field(&s, "unsafe_episodes", VMAC_VALUE_NUMBER) == 0, "a new washer had an unsafe episode");
	expect_no_field(&s, "rpm");
	expect_no_field(&s, "wash_time_s");
	ck_assert_msg(strstr(vmac_sim_fields_text(&s), "drum_rpm"), "the washer's fields text: %s",
	              vmac_sim_fields_text(&s));
	vmac_sim_fini(&s);

	ck_assert_int_eq(vmac_sim_init_c(&s, "dishwasher"), 0);
	c_field(&s, "water_l", VMAC_VALUE_NUMBER);
	c_field(&s, "wash_time_s", VMAC_VALUE_NUMBER);
	c_field(&s, "door_closed", VMAC_VALUE_BOOL);
	expect_no_field(&s, "drum_rpm");
	vmac_sim_fini(&s);

	ck_assert_int_eq(vmac_sim_init_c(&s, "lights"), 0);
	c_field(&s, "on_seconds0", VMAC_VALUE_NUMBER);
	c_field(&s, "on_seconds4", VMAC_VALUE_NUMBER);
	expect_no_field(&s, "on_seconds5");
	expect_no_field(&s, "on_seconds");
	expect_no_field(&s, "on_seconds00");
	vmac_sim_fini(&s);

	ck_assert_int_eq(vmac_sim_init_c(&s, "generic"), 0);
	expect_no_field(&s, "di0");
	ck_assert_str_eq(vmac_sim_fields_text(&s), "none");
	vmac_sim_fini(&s);
}
END_TEST

static const char *const DRYER =
    "return {\n"
    "  io = { heater = 'do0', drum = 'do1', door_closed = 'di0' },\n"
    "  state = { door_closed = true, steps = 0, max_dt = 0, fail_after = -1 },\n"
    "  step = function(p, dt, out)\n"
    "    p.steps = p.steps + 1\n"
    "    if dt > p.max_dt then p.max_dt = dt end\n"
    "    if p.fail_after >= 0 and p.steps > p.fail_after then error('dryer broke') end\n"
    "    if out.heater and not out.drum then return 'heater on with the drum still' end\n"
    "  end,\n"
    "  actions = {\n"
    "    door = function(p, v)\n"
    "      if v ~= 0 and v ~= 1 then return false, 'door takes 0 (open) or 1 (closed)' end\n"
    "      p.door_closed = v == 1\n"
    "    end,\n"
    "    jam = function(p, v) error('jammed') end,\n"
    "  },\n"
    "}\n";

/* A Lua plant from DIR/plants/NAME.lua behind vmac_sim. */
static void lua_sim(struct vmac_sim *s, const char *name, const char *src)
{
	char path[160], err[VMAC_DRIVER_ERR_MAX];
	write_plant(name, src, path, sizeof(path));
	ck_assert_msg(vmac_sim_init_lua(s, path, &luaplant_limits, err, sizeof(err)) == 0, "%s did not load: %s", path,
	              err);
}

START_TEST(a_lua_plant_behind_sim_steps_in_pieces_and_answers_fields)
{
	struct vmac_sim s;
	char why[VMAC_DRIVER_ERR_MAX + 128];
	struct vmac_value v;
	lua_sim(&s, "dryer", DRYER);
	ck_assert_str_eq(vmac_sim_name(&s), "dryer");
	ck_assert_str_eq(vmac_sim_driver(&s), "dryer");
	ck_assert_int_eq(vmac_sim_step(&s, 0.35), 0);
	ck_assert_msg(vmac_sim_field(&s, "steps", &v) == 0 && v.number == 4,
	              "a 0.35 s step should be 4 steps of at most 0.1 s, the plant counted %g", v.number);
	ck_assert_msg(vmac_sim_field(&s, "max_dt", &v) == 0 && v.number <= VMAC_SIM_MAX_STEP_S,
	              "the plant got a step of %g s", v.number);
	ck_assert_msg(vmac_sim_field(&s, "door_closed", &v) == 0 && v.type == VMAC_VALUE_BOOL && v.number == 1,
	              "door_closed through vmac_sim_field");
	ck_assert_msg(vmac_sim_field(&s, "unsafe_episodes", &v) == 0 && v.number == 0,
	              "unsafe_episodes of a new plant");
	expect_no_field(&s, "nosuch");
	ck_assert_msg(vmac_sim_set(&s, "door", 7, why, sizeof(why)) == -1, "door 7 accepted");
	ck_assert_msg(strcmp(why, "the dryer plant refuses door = 7: door takes 0 (open) or 1 (closed)") == 0,
	              "the refusal as vmac-board prints it: '%s'", why);
	ck_assert_msg(vmac_sim_set(&s, "door", 0, why, sizeof(why)) == 0, "door 0 refused: %s", why);
	ck_assert_msg(vmac_sim_field(&s, "door_closed", &v) == 0 && v.number == 0, "door 0 left the door closed");
	vmac_sim_fini(&s);
}
END_TEST

/* The safety line of s for board (the report's text), as a string. */
static const char *safety_line(const struct vmac_sim *s, const char *board)
{
	static char line[256];
	struct vmac_plant_safety safety = vmac_sim_safety(s);
	size_t n = safety.text(safety.ctx, board, line, sizeof(line));
	ck_assert_msg(n == strlen(line), "the safety text's length %zu is not that of '%s'", n, line);
	return line;
}

START_TEST(a_lua_plants_unsafe_line_names_plant_board_text_and_episode)
{
	struct vmac_sim s;
	struct vmac_outputs heater_only = {0x01, 0}, both = {0x03, 0};
	struct vmac_plant_safety safety;
	char small[12];
	lua_sim(&s, "dryer", DRYER);
	safety = vmac_sim_safety(&s);
	ck_assert_uint_eq(safety.episodes(safety.ctx), 0);
	vmac_sim_actuate(&s, &heater_only);
	ck_assert_int_eq(vmac_sim_step(&s, 0.01), 0);
	ck_assert_msg(safety.episodes(safety.ctx) == 1, "heater without drum: %u episodes",
	              safety.episodes(safety.ctx));
	ck_assert_str_eq(safety_line(&s, "dryer-1"), "dryer UNSAFE: dryer-1 heater on with the drum still, episode 1");
	ck_assert_str_eq(safety_line(&s, NULL), "dryer UNSAFE: heater on with the drum still, episode 1");
	ck_assert_str_eq(safety_line(&s, ""), "dryer UNSAFE: heater on with the drum still, episode 1");
	vmac_sim_actuate(&s, &both);
	ck_assert_int_eq(vmac_sim_step(&s, 0.01), 0);
	vmac_sim_actuate(&s, &heater_only);
	ck_assert_int_eq(vmac_sim_step(&s, 0.01), 0);
	ck_assert_uint_eq(vmac_sim_unsafe_episodes(&s), 2);
	ck_assert_str_eq(safety_line(&s, "dryer-1"), "dryer UNSAFE: dryer-1 heater on with the drum still, episode 2");
	ck_assert_msg(safety.text(safety.ctx, "dryer-1", small, sizeof(small)) == sizeof(small) - 1 &&
	                  strcmp(small, "dryer UNSAF") == 0,
	              "a short buffer: '%s'", small);
	vmac_sim_fini(&s);
}
END_TEST

START_TEST(the_c_washers_unsafe_line_through_sim)
{
	struct vmac_sim s;
	char why[256];
	ck_assert_int_eq(vmac_sim_init_c(&s, "washer"), 0);
	ck_assert_int_eq(vmac_sim_set(&s, "water_l", 8, why, sizeof(why)), 0);
	ck_assert_msg(vmac_sim_unsafe_episodes(&s) == 1, "water above an unlocked door: %u episodes",
	              vmac_sim_unsafe_episodes(&s));
	ck_assert_str_eq(safety_line(&s, "washer-1"),
	                 "washer UNSAFE: washer-1 door closed and not locked, drum 0 rpm, water 8.0 l, episode 1");
	ck_assert_msg(vmac_sim_set(&s, "water_l", -1, why, sizeof(why)) == -1, "water_l -1 accepted");
	ck_assert_msg(strstr(why, "the washer plant refuses water_l = -1"), "the washer's refusal: %s", why);
	vmac_sim_fini(&s);
}
END_TEST

START_TEST(a_lua_plants_failure_is_told_once)
{
	struct vmac_sim s;
	struct vmac_inputs before, after;
	char why[VMAC_DRIVER_ERR_MAX + 128];
	lua_sim(&s, "dryer", DRYER);
	ck_assert_int_eq(vmac_sim_step(&s, 0.05), 0);
	ck_assert_int_eq(vmac_sim_set(&s, "fail_after", 1, why, sizeof(why)), 0);
	vmac_sim_sense(&s, &before);
	ck_assert_msg(vmac_sim_step(&s, 0.05) == -2, "the failing step did not return -2");
	ck_assert_msg(vmac_sim_failure(&s) && strstr(vmac_sim_failure(&s), "plants/dryer.lua:7: dryer broke"),
	              "the failure does not name file and line: %s", vmac_sim_failure(&s));
	ck_assert_msg(vmac_sim_step(&s, 0.05) == -1, "the second step after the failure did not return -1");
	ck_assert_msg(vmac_sim_step(&s, 0.3) == -1, "the third step after the failure did not return -1");
	vmac_sim_sense(&s, &after);
	ck_assert_msg(after.digital == before.digital, "the inputs moved after the failure");
	ck_assert_msg(vmac_sim_set(&s, "door", 0, why, sizeof(why)) == -1 && strstr(why, "has failed"),
	              "an action on the failed plant: %s", why);
	vmac_sim_fini(&s);
}
END_TEST

START_TEST(a_lua_plant_failing_in_an_action_is_told_at_the_next_step)
{
	struct vmac_sim s;
	char why[VMAC_DRIVER_ERR_MAX + 128];
	lua_sim(&s, "dryer", DRYER);
	ck_assert_msg(vmac_sim_set(&s, "jam", 1, why, sizeof(why)) == -1, "an action that raises was accepted");
	ck_assert_msg(strstr(why, "the dryer plant refuses jam = 1: the plant failed: ") && strstr(why, ":15: jammed"),
	              "the failing action says: %s", why);
	ck_assert_msg(vmac_sim_step(&s, 0.01) == -2, "the failure in an action is not told by the next step");
	ck_assert_msg(vmac_sim_step(&s, 0.01) == -1, "the failure is told twice");
	vmac_sim_fini(&s);
}
END_TEST

START_TEST(a_plant_file_that_cannot_be_read_or_loaded_is_refused)
{
	struct vmac_sim s;
	char path[160], err[VMAC_DRIVER_ERR_MAX] = "";
	snprintf(path, sizeof(path), "%s/plants/nosuch.lua", plant_dir);
	ck_assert_int_eq(vmac_sim_init_lua(&s, path, &luaplant_limits, err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "nosuch.lua"), "a missing file's error does not name it: %s", err);
	write_plant("broken", "return { io = {}, step = function( end }", path, sizeof(path));
	ck_assert_int_eq(vmac_sim_init_lua(&s, path, &luaplant_limits, err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "broken.lua:1:"), "a syntax error's error: %s", err);
	write_plant("my.dryer", "return { io = {}, step = function() end }", path, sizeof(path));
	ck_assert_int_eq(vmac_sim_init_lua(&s, path, &luaplant_limits, err, sizeof(err)), -1);
	ck_assert_msg(strstr(err, "name 'my.dryer'"), "a file name that is no plant name: %s", err);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("Lua plant at run time");
	TCase *tc = tcase_create("failure");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, a_step_that_raises_fails_with_file_and_line);
	tcase_add_test(tc, a_failed_plant_refuses_everything_and_holds_its_inputs);
	tcase_add_test(tc, an_action_that_raises_or_loops_fails_the_plant);
	tcase_add_test(tc, an_endless_step_fails_at_its_instruction_budget);
	tcase_add_test(tc, the_load_gets_fifty_budgets_a_step_one);
	tcase_add_test(tc, a_step_eating_memory_fails_at_the_memory_cap);
	suite_add_tcase(s, tc);

	tc = tcase_create("determinism");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, the_same_seed_gives_the_same_random_numbers);
	tcase_add_test(tc, os_clock_is_plant_time);
	suite_add_tcase(s, tc);

	tc = tcase_create("sandbox");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, the_sandbox_has_no_files_processes_loaders_or_print);
	tcase_add_test(tc, library_tables_are_read_only);
	suite_add_tcase(s, tc);

	tc = tcase_create("sim");
	tcase_add_checked_fixture(tc, sim_setup, sim_teardown);
	tcase_add_test(tc, every_c_plant_is_made_by_name_and_no_other);
	tcase_add_test(tc, c_plants_answer_their_fields_by_name);
	tcase_add_test(tc, a_lua_plant_behind_sim_steps_in_pieces_and_answers_fields);
	tcase_add_test(tc, a_lua_plants_unsafe_line_names_plant_board_text_and_episode);
	tcase_add_test(tc, the_c_washers_unsafe_line_through_sim);
	tcase_add_test(tc, a_lua_plants_failure_is_told_once);
	tcase_add_test(tc, a_lua_plant_failing_in_an_action_is_told_at_the_next_step);
	tcase_add_test(tc, a_plant_file_that_cannot_be_read_or_loaded_is_refused);
	suite_add_tcase(s, tc);
	return s;
}
