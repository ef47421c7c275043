/* Unit tests for the simulated washer (firmware/plants/washer.c) through the
 * plant interface (firmware/plant.h): the PTC door lock that stays engaged
 * for lock_release_s after the solenoid goes off, the emergency release, and
 * the safety monitor that counts a closed door left unlocked while the drum
 * turns or the water is above the door, and the motor's noise on the
 * temperature reading. */
#include <check.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../firmware/plant.h"
#include "check_main.h"

#define OUT_DOOR_LOCK 0x08    /* do3 */
#define OUT_MOTOR_ENABLE 0x10 /* do4 */
#define OUT_DRAIN_PUMP 0x04   /* do2 */
#define OUT_HOT_VALVE 0x01    /* do0 */
#define IN_DOOR_CLOSED 0x01   /* di0 */
#define IN_DOOR_LOCKED 0x02   /* di1 */
#define STEP_S 0.01           /* vmac-board's physics sub-step */
#define DEFAULT_LOCK_RELEASE_S 2.0
#define TEMP_COUNTS_PER_C 40.0 /* analog1 */
#define NOISE_MAX_COUNTS 2

static struct vmac_plant plant;
static const struct vmac_washer *washer = &plant.s.washer;

static void setup(void)
{
	vmac_plant_init(&plant, VMAC_PLANT_WASHER);
}

static void drive(uint8_t digital, int16_t pwm)
{
	struct vmac_outputs out;
	out.digital = digital;
	out.pwm = pwm;
	vmac_plant_actuate(&plant, &out);
}

/* Plant time passes in vmac-board's sub-steps. */
static void run_s(double seconds)
{
	long steps = lround(seconds / STEP_S), k;
	for (k = 0; k < steps; k++)
		vmac_plant_step(&plant, STEP_S);
}

/* The lock as the driver sees it: the door-locked input. */
static int sensed_locked(void)
{
	struct vmac_inputs in;
	memset(&in, 0, sizeof(in));
	vmac_plant_sense(&plant, &in);
	return (in.digital & IN_DOOR_LOCKED) != 0;
}

static int sensed_closed(void)
{
	struct vmac_inputs in;
	memset(&in, 0, sizeof(in));
	vmac_plant_sense(&plant, &in);
	return (in.digital & IN_DOOR_CLOSED) != 0;
}

static void expect_locked(int want, const char *when)
{
	ck_assert_msg(sensed_locked() == want, "%s: the door lock reads %s, expected %s", when,
	              sensed_locked() ? "locked" : "unlocked", want ? "locked" : "unlocked");
	ck_assert_msg(washer->door_locked == want, "%s: plant field door_locked is %d, expected %d", when,
	              washer->door_locked, want);
}

/* Locked with the solenoid on, then the solenoid off: the PTC starts cooling. */
static void lock_then_release_solenoid(uint8_t other_outputs)
{
	drive(OUT_DOOR_LOCK | other_outputs, 0);
	expect_locked(1, "the solenoid just turned on");
	run_s(1.0);
	drive(other_outputs, 0);
}

/* ---- the PTC door lock ------------------------------------------------ */

START_TEST(lock_engages_at_once_with_the_solenoid_on_a_closed_door)
{
	expect_locked(0, "at rest");
	drive(OUT_DOOR_LOCK, 0);
	expect_locked(1, "the instant the solenoid turned on, before any plant time");
}
END_TEST

START_TEST(lock_holds_for_lock_release_s_after_the_solenoid_goes_off)
{
	ck_assert_msg(washer->lock_release_s == DEFAULT_LOCK_RELEASE_S, "default lock_release_s is %g, expected %g",
	              washer->lock_release_s, DEFAULT_LOCK_RELEASE_S);
	lock_then_release_solenoid(0);
	expect_locked(1, "the instant the solenoid went off");
	run_s(DEFAULT_LOCK_RELEASE_S - 0.1);
	expect_locked(1, "1.9 s after the solenoid went off");
	ck_assert_msg(vmac_plant_set(&plant, "door", 0) == -1, "the door opened while the PTC lock still held it");
	ck_assert_msg(sensed_closed(), "a refused door action opened the door");
	run_s(0.1);
	expect_locked(0, "2.0 s (lock_release_s) after the solenoid went off");
	ck_assert_msg(vmac_plant_set(&plant, "door", 0) == 0, "the released door refused to open");
	ck_assert_msg(!sensed_closed(), "the door reads closed after opening it");
}
END_TEST

START_TEST(lock_release_in_one_long_step_waits_the_same)
{
	lock_then_release_solenoid(0);
	vmac_plant_step(&plant, 1.95); /* cut into 0.1 s pieces by the dispatcher */
	expect_locked(1, "one 1.95 s step after the solenoid went off");
	vmac_plant_step(&plant, 0.05);
	expect_locked(0, "2.0 s of steps after the solenoid went off");
}
END_TEST

START_TEST(re_energising_within_the_delay_keeps_it_locked_without_a_gap)
{
	long k;
	lock_then_release_solenoid(0);
	run_s(1.5);
	drive(OUT_DOOR_LOCK, 0);
	expect_locked(1, "the solenoid back on 1.5 s after it went off");
	for (k = 0; k < 300; k++) {
		vmac_plant_step(&plant, STEP_S);
		ck_assert_msg(sensed_locked(), "the lock released %.2f s after the solenoid came back on",
		              (k + 1) * STEP_S);
	}
	/* The delay starts again from the second time the solenoid goes off. */
	drive(0, 0);
	run_s(DEFAULT_LOCK_RELEASE_S - 0.1);
	expect_locked(1, "1.9 s after the solenoid went off a second time");
	run_s(0.1);
	expect_locked(0, "2.0 s after the solenoid went off a second time");
}
END_TEST

START_TEST(lock_release_s_sets_the_delay)
{
	ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", 5) == 0, "lock_release_s 5 refused");
	lock_then_release_solenoid(0);
	run_s(4.9);
	expect_locked(1, "4.9 s after the solenoid went off, lock_release_s 5");
	run_s(0.1);
	expect_locked(0, "5.0 s after the solenoid went off, lock_release_s 5");
}
END_TEST

START_TEST(lock_release_s_zero_releases_with_the_solenoid)
{
	ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", 0) == 0, "lock_release_s 0 refused");
	lock_then_release_solenoid(0);
	expect_locked(0, "the instant the solenoid went off, lock_release_s 0");
}
END_TEST

START_TEST(lock_release_s_shortened_while_cooling_caps_the_wait)
{
	ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", 120) == 0, "lock_release_s 120 refused");
	lock_then_release_solenoid(0);
	run_s(10.0);
	expect_locked(1, "10 s after the solenoid went off, lock_release_s 120");
	ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", 1) == 0, "lock_release_s 1 refused");
	run_s(0.9);
	expect_locked(1, "0.9 s after lock_release_s became 1");
	run_s(0.1);
	expect_locked(0, "1.0 s after lock_release_s became 1");
}
END_TEST

START_TEST(lock_release_s_out_of_range_is_refused)
{
	static const double bad[] = {-0.001, 600.001, -1, 1e9};
	size_t k;
	for (k = 0; k < sizeof(bad) / sizeof(bad[0]); k++)
		ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", bad[k]) == -1, "lock_release_s %g accepted",
		              bad[k]);
	ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", NAN) == -1, "lock_release_s NaN accepted");
	ck_assert_msg(washer->lock_release_s == DEFAULT_LOCK_RELEASE_S,
	              "a refused lock_release_s changed the delay to %g", washer->lock_release_s);
	ck_assert_msg(vmac_plant_set(&plant, "lock_release_s", 600) == 0, "lock_release_s 600 (the maximum) refused");
}
END_TEST

START_TEST(door_release_opens_a_held_lock_at_once)
{
	drive(OUT_DOOR_LOCK, 0);
	ck_assert_msg(vmac_plant_set(&plant, "door_release", 1) == 0, "door_release refused with the solenoid on");
	expect_locked(0, "door_release with the solenoid on");
	ck_assert_msg(!sensed_closed(), "door_release left the door closed");

	setup();
	lock_then_release_solenoid(0);
	run_s(0.5);
	expect_locked(1, "0.5 s into the lock's delay");
	ck_assert_msg(vmac_plant_set(&plant, "door_release", 0) == 0, "door_release refused while the PTC cools");
	expect_locked(0, "door_release while the PTC cools");
	ck_assert_msg(!sensed_closed(), "door_release left the door closed");
	/* Closed again with the solenoid off: no lock left over from before. */
	ck_assert_msg(vmac_plant_set(&plant, "door", 1) == 0, "closing the door refused");
	expect_locked(0, "the door closed again with the solenoid off");
}
END_TEST

/* ---- the safety monitor ------------------------------------------------ */

START_TEST(monitor_counts_water_above_the_door_once_the_lock_releases)
{
	char text[160];
	drive(OUT_DOOR_LOCK, 0);
	ck_assert_int_eq(vmac_plant_set(&plant, "water_l", 12.25), 0);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 0, "water above a locked door counted as unsafe");
	lock_then_release_solenoid(0); /* the host crashed: the watchdog turned everything off */
	run_s(DEFAULT_LOCK_RELEASE_S - 0.1);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 0,
	              "an unsafe episode counted while the PTC lock still held the door (%u)",
	              (unsigned)vmac_plant_unsafe_episodes(&plant));
	run_s(0.1);
	expect_locked(0, "lock_release_s after the solenoid went off");
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 1,
	              "%u unsafe episodes after the lock released with 12.25 l above the door, expected 1",
	              (unsigned)vmac_plant_unsafe_episodes(&plant));
	ck_assert_msg(washer->unsafe, "the plant does not say the episode lasts");
	vmac_plant_unsafe_text(&plant, "washer-1", text, sizeof(text));
	ck_assert_str_eq(text,
	                 "washer UNSAFE: washer-1 door closed and not locked, drum 0 rpm, water 12.3 l, episode 1");

	run_s(5.0);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 1, "one lasting episode counted %u times",
	              (unsigned)vmac_plant_unsafe_episodes(&plant));

	drive(OUT_DOOR_LOCK, 0); /* the host came back and locked it again */
	run_s(0.1);
	ck_assert_msg(!washer->unsafe, "still unsafe with the door locked again");
	drive(0, 0);
	run_s(DEFAULT_LOCK_RELEASE_S);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 2, "%u episodes after a second release, expected 2",
	              (unsigned)vmac_plant_unsafe_episodes(&plant));
}
END_TEST

START_TEST(monitor_counts_a_turning_drum_behind_an_unlocked_door)
{
	static const char prefix[] = "washer UNSAFE: door closed and not locked, drum -";
	char text[160];
	drive(OUT_MOTOR_ENABLE, -300); /* no lock solenoid */
	run_s(1.0);
	ck_assert_msg(washer->drum_rpm < -2.0, "the drum did not turn (%g rpm)", washer->drum_rpm);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 1, "%u unsafe episodes with the drum turning unlocked",
	              (unsigned)vmac_plant_unsafe_episodes(&plant));
	/* The episode began as the drum passed 2 rpm (backwards), in the first steps. */
	vmac_plant_unsafe_text(&plant, NULL, text, sizeof(text));
	ck_assert_msg(strncmp(text, prefix, strlen(prefix)) == 0, "the text without a board name is '%s'", text);
	ck_assert_msg(washer->unsafe_rpm < -2.0 && washer->unsafe_rpm > -10.0,
	              "the episode's rpm %g is not the moment the drum passed -2 rpm", washer->unsafe_rpm);
}
END_TEST

START_TEST(monitor_stays_quiet_through_a_safe_cycle)
{
	/* Lock, water above the door, spin, drain, stop, wait, unlock: as the
	 * washer driver does it. */
	drive(OUT_DOOR_LOCK, 0);
	ck_assert_int_eq(vmac_plant_set(&plant, "water_l", 15), 0);
	drive(OUT_DOOR_LOCK | OUT_MOTOR_ENABLE, 400);
	run_s(10.0);
	drive(OUT_DOOR_LOCK | OUT_DRAIN_PUMP, 0);
	run_s(60.0); /* 15 l drained at 1 l/s, the drum coasts to a stop */
	ck_assert_msg(washer->water_l < 0.5 && fabs(washer->drum_rpm) < 2.0,
	              "not drained and still before unlocking: %g l, %g rpm", washer->water_l, washer->drum_rpm);
	drive(0, 0);
	run_s(DEFAULT_LOCK_RELEASE_S + 1.0);
	expect_locked(0, "after the safe unlock");
	/* Below the door and still, an unlocked door is fine. */
	ck_assert_int_eq(vmac_plant_set(&plant, "water_l", 4.9), 0);
	run_s(1.0);
	/* An open door (the emergency release) with water above it is not a
	 * lock episode: the door is not closed. */
	drive(OUT_DOOR_LOCK, 0);
	ck_assert_int_eq(vmac_plant_set(&plant, "water_l", 20), 0);
	ck_assert_int_eq(vmac_plant_set(&plant, "door_release", 1), 0);
	run_s(DEFAULT_LOCK_RELEASE_S + 1.0);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 0, "%u unsafe episodes in a safe cycle",
	              (unsigned)vmac_plant_unsafe_episodes(&plant));
}
END_TEST

START_TEST(unsafe_text_fits_any_buffer)
{
	char text[16];
	memset(text, 'x', sizeof(text));
	ck_assert_int_eq(vmac_plant_set(&plant, "water_l", 8), 0);
	ck_assert_msg(vmac_plant_unsafe_episodes(&plant) == 1, "water above an unlocked door not counted at once");
	ck_assert_uint_eq(vmac_plant_unsafe_text(&plant, "washer-1", text, sizeof(text)), sizeof(text) - 1);
	ck_assert_str_eq(text, "washer UNSAFE: ");
	ck_assert_uint_eq(vmac_plant_unsafe_text(&plant, "washer-1", text, 0), 0);
}
END_TEST

START_TEST(other_plants_have_no_unsafe_episodes)
{
	vmac_plant_init(&plant, VMAC_PLANT_DISHWASHER);
	ck_assert_uint_eq(vmac_plant_unsafe_episodes(&plant), 0);
	vmac_plant_init(&plant, VMAC_PLANT_GENERIC);
	ck_assert_uint_eq(vmac_plant_unsafe_episodes(&plant), 0);
}
END_TEST

/* analog1 as sensed less the exact reading of the water's temperature. */
static int temp_noise_counts(const struct vmac_plant *p)
{
	struct vmac_inputs in;
	memset(&in, 0, sizeof(in));
	vmac_plant_sense(p, &in);
	return (int)in.analog[1] - (int)floor(p->s.washer.water_c * TEMP_COUNTS_PER_C + 0.5);
}

/* Warm water in the tub (not a whole number of counts), the door locked. */
static void fill_warm(struct vmac_plant *p)
{
	struct vmac_outputs out;
	long k;
	out.digital = OUT_DOOR_LOCK | OUT_HOT_VALVE;
	out.pwm = 0;
	vmac_plant_actuate(p, &out);
	for (k = 0; k < 1000; k++) /* 10 s: 5 l at 60 C */
		vmac_plant_step(p, STEP_S);
	out.digital = OUT_DOOR_LOCK;
	vmac_plant_actuate(p, &out);
}

START_TEST(temperature_reads_exactly_while_the_motor_is_off)
{
	long k;
	fill_warm(&plant);
	for (k = 0; k < 1000; k++) {
		vmac_plant_step(&plant, STEP_S);
		ck_assert_msg(temp_noise_counts(&plant) == 0,
		              "step %ld with the motor off: the temperature reads %d counts "
		              "off its exact %g C",
		              k, temp_noise_counts(&plant), washer->water_c);
	}
}
END_TEST

START_TEST(the_motor_adds_a_count_or_two_of_noise)
{
	long seen[2 * NOISE_MAX_COUNTS + 1] = {0}, k, steps = 6000, changes = 0, sum = 0;
	int last = 0, i;
	fill_warm(&plant);
	drive(OUT_DOOR_LOCK | OUT_MOTOR_ENABLE, 45);
	for (k = 0; k < steps; k++) {
		int off;
		vmac_plant_step(&plant, STEP_S);
		off = temp_noise_counts(&plant);
		ck_assert_msg(off >= -NOISE_MAX_COUNTS && off <= NOISE_MAX_COUNTS,
		              "step %ld: the temperature reads %d counts off, more than %d", k, off, NOISE_MAX_COUNTS);
		seen[off + NOISE_MAX_COUNTS]++;
		changes += k > 0 && off != last;
		sum += off;
		last = off;
	}
	for (i = 0; i <= 2 * NOISE_MAX_COUNTS; i++)
		ck_assert_msg(seen[i] > steps / 20,
		              "an offset of %d counts came %ld times in %ld readings (1 in 9 expected "
		              "at +-2, 2 in 9 at +-1, 3 in 9 at 0)",
		              i - NOISE_MAX_COUNTS, seen[i], steps);
	ck_assert_msg(seen[NOISE_MAX_COUNTS] > seen[0] && seen[NOISE_MAX_COUNTS] > seen[2 * NOISE_MAX_COUNTS],
	              "0 counts off (%ld) is not the most frequent: -2 %ld, +2 %ld", seen[NOISE_MAX_COUNTS], seen[0],
	              seen[2 * NOISE_MAX_COUNTS]);
	ck_assert_msg(labs(sum) < steps / 20, "the noise is biased: %ld counts over %ld readings", sum, steps);
	ck_assert_msg(changes > steps / 2, "the offset changed in %ld of %ld steps of a turning drum", changes, steps);
}
END_TEST

START_TEST(the_noise_is_the_same_every_run)
{
	static struct vmac_plant again;
	struct vmac_outputs out;
	long k;
	vmac_plant_init(&again, VMAC_PLANT_WASHER);
	fill_warm(&plant);
	fill_warm(&again);
	out.digital = OUT_DOOR_LOCK | OUT_MOTOR_ENABLE;
	out.pwm = 45;
	vmac_plant_actuate(&plant, &out);
	vmac_plant_actuate(&again, &out);
	for (k = 0; k < 3000; k++) {
		struct vmac_inputs a, b;
		vmac_plant_step(&plant, STEP_S);
		vmac_plant_step(&again, STEP_S);
		memset(&a, 0, sizeof(a));
		memset(&b, 0, sizeof(b));
		vmac_plant_sense(&plant, &a);
		vmac_plant_sense(&again, &b);
		ck_assert_msg(a.analog[1] == b.analog[1], "step %ld: two runs read %u and %u counts", k,
		              (unsigned)a.analog[1], (unsigned)b.analog[1]);
		vmac_plant_sense(&plant, &b);
		ck_assert_msg(a.analog[1] == b.analog[1], "step %ld: two readings of one state differ (%u, %u)", k,
		              (unsigned)a.analog[1], (unsigned)b.analog[1]);
	}
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("washer plant");
	TCase *tc = tcase_create("PTC door lock");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, lock_engages_at_once_with_the_solenoid_on_a_closed_door);
	tcase_add_test(tc, lock_holds_for_lock_release_s_after_the_solenoid_goes_off);
	tcase_add_test(tc, lock_release_in_one_long_step_waits_the_same);
	tcase_add_test(tc, re_energising_within_the_delay_keeps_it_locked_without_a_gap);
	tcase_add_test(tc, lock_release_s_sets_the_delay);
	tcase_add_test(tc, lock_release_s_zero_releases_with_the_solenoid);
	tcase_add_test(tc, lock_release_s_shortened_while_cooling_caps_the_wait);
	tcase_add_test(tc, lock_release_s_out_of_range_is_refused);
	tcase_add_test(tc, door_release_opens_a_held_lock_at_once);
	suite_add_tcase(s, tc);

	tc = tcase_create("safety monitor");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, monitor_counts_water_above_the_door_once_the_lock_releases);
	tcase_add_test(tc, monitor_counts_a_turning_drum_behind_an_unlocked_door);
	tcase_add_test(tc, monitor_stays_quiet_through_a_safe_cycle);
	tcase_add_test(tc, unsafe_text_fits_any_buffer);
	tcase_add_test(tc, other_plants_have_no_unsafe_episodes);
	suite_add_tcase(s, tc);

	tc = tcase_create("temperature noise");
	tcase_add_checked_fixture(tc, setup, NULL);
	tcase_add_test(tc, temperature_reads_exactly_while_the_motor_is_off);
	tcase_add_test(tc, the_motor_adds_a_count_or_two_of_noise);
	tcase_add_test(tc, the_noise_is_the_same_every_run);
	suite_add_tcase(s, tc);
	return s;
}
