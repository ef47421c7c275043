/* Simulated washing machine: tub with hot/cold fill and drain, a drum motor
 * with inertia and an encoder, a door with a PTC lock, and a safety monitor
 * that counts the moments the door is unlocked when it must not be. The I/O
 * map is the contract of the "washer" Lua driver (docs/BOARD.md). */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "plants.h"

/* Outputs (bit numbers). */
#define OUT_HOT_VALVE 0
#define OUT_COLD_VALVE 1
#define OUT_DRAIN_PUMP 2
#define OUT_DOOR_LOCK 3
#define OUT_MOTOR_ENABLE 4
/* Inputs (bit numbers). */
#define IN_DOOR_CLOSED 0
#define IN_DOOR_LOCKED 1
#define IN_TUB_EMPTY 2
#define IN_START_BUTTON 3
#define IN_CANCEL_BUTTON 4

/* Water. */
#define TUB_MAX_L 40.0        /* overflow: the level never rises above this */
#define TUB_EMPTY_BELOW_L 0.5 /* "tub empty" input threshold */
#define DEFAULT_FILL_LPS 0.5  /* per open valve */
#define MAX_FILL_LPS 5.0
#define DRAIN_LPS 1.0
#define HOT_WATER_C 60.0
#define COLD_WATER_C 15.0
#define AMBIENT_C 20.0
#define COOLING_TAU_S 600.0      /* tub water relaxes toward ambient */
#define LEVEL_COUNTS_PER_L 100.0 /* analog0 */
#define TEMP_COUNTS_PER_C 40.0   /* analog1 */
/* The drum motor's drive couples into the temperature sensor's line: while
 * the motor relay is on, each reading is off by -2..+2 counts (+-0.05 C),
 * 0 most often (the sum of two draws of -1, 0, +1: 1, 2, 3, 2, 1 in 9). */
#define TEMP_NOISE_DRAWS 2

/* Drum. The motor is first order: rpm moves toward drive / drag with time
 * constant inertia / drag. Drag is 1 while the motor is enabled (the drive
 * holds the drum), COAST_DRAG when disabled, plus a share per litre of water;
 * inertia grows with laundry and water. Dry and empty: 1 RPM per pwm unit,
 * tau 1.5 s. */
#define RPM_PER_PWM 1.0
#define DRUM_TAU_S 1.5         /* empty, dry, motor enabled */
#define LOAD_TAU_S_PER_KG 0.25 /* 3 kg: 2.25 s */
#define WATER_TAU_S_PER_L 0.05
#define WATER_DRAG_PER_L 0.005 /* 15 l: steady rpm about 7 % lower */
#define COAST_DRAG 0.3         /* mechanical friction alone, motor disabled */
#define DEFAULT_LOAD_KG 3.0
#define MAX_LOAD_KG 10.0
#define STILL_RPM 1e-6 /* below this a coasting drum has stopped */
#define COUNTS_PER_REV 360.0
#define ENCODER_SPAN 4294967296.0 /* 2^32: the accumulator wraps like int32 */

/* Door lock. A real front-loader's PTC lock stays engaged while its PTC
 * cools, 1-2 minutes after the solenoid goes off; the default here is short
 * so that demos and tests stay quick. */
#define DEFAULT_LOCK_RELEASE_S 2.0
#define MAX_LOCK_RELEASE_S 600.0
#define LOCK_TIME_EPSILON_S 1e-9 /* rounding of summed steps: 200 x 0.01 s is 2 s */

/* Safety monitor: the door must stay locked while the drum turns faster than
 * UNSAFE_RPM or the water is above DOOR_LEVEL_L (the washer driver's default
 * door_level_l). */
#define UNSAFE_RPM 2.0
#define DOOR_LEVEL_L 5.0

static int output_on(const struct vmac_washer *w, int bit)
{
	return (w->out.digital >> bit) & 1;
}

/* The PTC lock after dt_s more seconds: engaged at once on a closed door
 * with the solenoid on; with the solenoid off it holds for lock_release_s,
 * then releases; an open door is never locked. dt_s 0 applies a change of
 * outputs or door at once (lock_release_s 0: the solenoid off releases it). */
static void update_lock(struct vmac_washer *w, double dt_s)
{
	if (!w->door_closed) {
		w->door_locked = 0;
		w->lock_left_s = 0.0;
	} else if (output_on(w, OUT_DOOR_LOCK)) {
		w->door_locked = 1;
		w->lock_left_s = w->lock_release_s; /* the countdown starts when the solenoid goes off */
	} else if (w->door_locked) {
		w->lock_left_s -= dt_s;
		if (w->lock_left_s <= LOCK_TIME_EPSILON_S) {
			w->door_locked = 0;
			w->lock_left_s = 0.0;
		}
	}
}

/* Count an unsafe episode on entering one: a closed door not locked while the
 * drum turns or the water is above the door. An open door (the emergency
 * release) is not counted. */
static void monitor_safety(struct vmac_washer *w)
{
	int unsafe = w->door_closed && !w->door_locked && (fabs(w->drum_rpm) > UNSAFE_RPM || w->water_l > DOOR_LEVEL_L);
	if (unsafe && !w->unsafe) {
		w->unsafe_episodes++;
		w->unsafe_rpm = w->drum_rpm;
		w->unsafe_water_l = w->water_l;
	}
	w->unsafe = unsafe;
}

/* After an action or new outputs: the lock and the monitor at once. */
static void settle(struct vmac_washer *w)
{
	update_lock(w, 0.0);
	monitor_safety(w);
}

void vmac_washer_init(struct vmac_washer *w)
{
	memset(w, 0, sizeof(*w));
	w->water_c = AMBIENT_C;
	w->load_kg = DEFAULT_LOAD_KG;
	w->fill_rate_lps = DEFAULT_FILL_LPS;
	w->door_closed = 1;
	w->door_locked = 0;
	w->lock_release_s = DEFAULT_LOCK_RELEASE_S;
}

/* Fill (mixing temperature by volume), cool toward ambient, drain, clamp. */
static void step_water(struct vmac_washer *w, double dt_s)
{
	double hot_l = output_on(w, OUT_HOT_VALVE) ? w->fill_rate_lps * dt_s : 0.0;
	double cold_l = output_on(w, OUT_COLD_VALVE) ? w->fill_rate_lps * dt_s : 0.0;
	double total_l = w->water_l + hot_l + cold_l;

	if (total_l > 0.0 && hot_l + cold_l > 0.0)
		w->water_c = (w->water_l * w->water_c + hot_l * HOT_WATER_C + cold_l * COLD_WATER_C) / total_l;
	w->water_l = total_l;
	w->water_c = AMBIENT_C + (w->water_c - AMBIENT_C) * exp(-dt_s / COOLING_TAU_S);
	if (output_on(w, OUT_DRAIN_PUMP))
		w->water_l -= DRAIN_LPS * dt_s;
	if (w->water_l < 0.0)
		w->water_l = 0.0;
	if (w->water_l > TUB_MAX_L)
		w->water_l = TUB_MAX_L;
}

/* Exact solution of the first-order drum over dt_s (stable for any dt_s),
 * with the encoder advanced by the exact integral of the speed. */
static void step_drum(struct vmac_washer *w, double dt_s)
{
	int enabled = output_on(w, OUT_MOTOR_ENABLE);
	double pwm = w->out.pwm;
	double drag, inertia_s, tau_s, target_rpm, approach, rpm_seconds;

	if (pwm > VMAC_PWM_MAX)
		pwm = VMAC_PWM_MAX;
	if (pwm < -VMAC_PWM_MAX)
		pwm = -VMAC_PWM_MAX;
	drag = (enabled ? 1.0 : COAST_DRAG) + WATER_DRAG_PER_L * w->water_l;
	inertia_s = DRUM_TAU_S + LOAD_TAU_S_PER_KG * w->load_kg + WATER_TAU_S_PER_L * w->water_l;
	tau_s = inertia_s / drag;
	target_rpm = enabled ? RPM_PER_PWM * pwm / drag : 0.0;
	approach = -expm1(-dt_s / tau_s); /* share of the way to target_rpm covered in dt_s */

	/* integral of rpm over dt_s, in rpm * seconds */
	rpm_seconds = target_rpm * dt_s + (w->drum_rpm - target_rpm) * tau_s * approach;
	w->encoder_pos += rpm_seconds / 60.0 * COUNTS_PER_REV;
	if (w->encoder_pos >= ENCODER_SPAN / 2)
		w->encoder_pos -= ENCODER_SPAN;
	else if (w->encoder_pos < -ENCODER_SPAN / 2)
		w->encoder_pos += ENCODER_SPAN;

	w->drum_rpm += (target_rpm - w->drum_rpm) * approach;
	if (target_rpm == 0.0 && fabs(w->drum_rpm) < STILL_RPM)
		w->drum_rpm = 0.0;
}

void vmac_washer_step(struct vmac_washer *w, double dt_s)
{
	step_drum(w, dt_s);
	step_water(w, dt_s);
	update_lock(w, dt_s);
	monitor_safety(w);
	vmac_plant_button_step(&w->start_left_s, dt_s);
	vmac_plant_button_step(&w->cancel_left_s, dt_s);
}

/* The bits of a double (as many as fit), for the noise's hash. */
static uint64_t bits_of(double x)
{
	uint64_t bits = 0;
	memcpy(&bits, &x, sizeof(x) < sizeof(bits) ? sizeof(x) : sizeof(bits));
	return bits;
}

/* splitmix64's finaliser: every input bit moves about half the output bits. */
static uint64_t mix64(uint64_t x)
{
	x ^= x >> 30;
	x *= UINT64_C(0xbf58476d1ce4e5b9);
	x ^= x >> 27;
	x *= UINT64_C(0x94d049bb133111eb);
	x ^= x >> 31;
	return x;
}

/* The temperature reading's noise in counts, -2..+2 while the motor relay is
 * on, else 0. A counter-based generator whose counter is the plant's state
 * (drum position, water, temperature): no state of its own, so sensing stays
 * a pure function of the plant, the same run reads the same numbers (vmac
 * test stays a function of its seed), and a reading differs from the last
 * whenever the drum has turned. */
static int temp_noise_counts(const struct vmac_washer *w)
{
	uint64_t h;
	int k, counts = 0;
	if (!output_on(w, OUT_MOTOR_ENABLE))
		return 0;
	h = mix64(bits_of(w->encoder_pos) ^ mix64(bits_of(w->water_c) ^ mix64(bits_of(w->water_l))));
	for (k = 0; k < TEMP_NOISE_DRAWS; k++, h >>= 21)
		counts += (int)(h % 3u) - 1;
	return counts;
}

void vmac_washer_sense(const struct vmac_washer *w, struct vmac_inputs *in)
{
	in->digital =
	    (uint8_t)((w->door_closed ? 1u << IN_DOOR_CLOSED : 0u) | (w->door_locked ? 1u << IN_DOOR_LOCKED : 0u) |
	              (w->water_l < TUB_EMPTY_BELOW_L ? 1u << IN_TUB_EMPTY : 0u) |
	              (w->start_left_s > 0.0 ? 1u << IN_START_BUTTON : 0u) |
	              (w->cancel_left_s > 0.0 ? 1u << IN_CANCEL_BUTTON : 0u));
	in->analog[0] = vmac_plant_analog_counts(w->water_l * LEVEL_COUNTS_PER_L);
	in->analog[1] = vmac_plant_analog_counts(floor(w->water_c * TEMP_COUNTS_PER_C + 0.5) + temp_noise_counts(w));
	in->encoder = (int32_t)floor(w->encoder_pos);
}

void vmac_washer_actuate(struct vmac_washer *w, const struct vmac_outputs *out)
{
	w->out = *out;
	settle(w);
}

/* "door" 0/1 (opening a locked door is refused), "load_kg" 0..10,
 * "water_l" 0..40 (temperature unchanged), "fill_rate_lps" 0..5 per valve,
 * "lock_release_s" 0..600 (a lock already counting down releases no later
 * than the new delay from now), "start" and "cancel" (any value) press a
 * button for VMAC_PLANT_BUTTON_S, "door_release" (any value) opens the door
 * even when locked. */
int vmac_washer_set(struct vmac_washer *w, const char *name, double value)
{
	if (strcmp(name, "start") == 0 || strcmp(name, "cancel") == 0) {
		*(name[0] == 's' ? &w->start_left_s : &w->cancel_left_s) = VMAC_PLANT_BUTTON_S;
		return 0;
	}
	if (strcmp(name, "door_release") == 0) { /* the emergency release: opens even a locked door */
		w->door_closed = 0;
		settle(w);
		return 0;
	}
	if (strcmp(name, "door") == 0) {
		if (!vmac_plant_is_bit(value))
			return -1;
		if (value == 0.0 && w->door_locked)
			return -1;
		w->door_closed = value == 1.0;
		settle(w);
		return 0;
	}
	if (strcmp(name, "load_kg") == 0) {
		if (!vmac_plant_in_range(value, 0.0, MAX_LOAD_KG))
			return -1;
		w->load_kg = value;
		return 0;
	}
	if (strcmp(name, "water_l") == 0) {
		if (!vmac_plant_in_range(value, 0.0, TUB_MAX_L))
			return -1;
		w->water_l = value;
		monitor_safety(w);
		return 0;
	}
	if (strcmp(name, "lock_release_s") == 0) {
		if (!vmac_plant_in_range(value, 0.0, MAX_LOCK_RELEASE_S))
			return -1;
		w->lock_release_s = value;
		if (w->lock_left_s > value)
			w->lock_left_s = value;
		settle(w);
		return 0;
	}
	if (strcmp(name, "fill_rate_lps") == 0) {
		if (!vmac_plant_in_range(value, 0.0, MAX_FILL_LPS))
			return -1;
		w->fill_rate_lps = value;
		return 0;
	}
	return -1;
}
