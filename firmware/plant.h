/* Simulated machines behind a board's I/O (washer, dishwasher, lights,
 * generic). Portable C99, no heap: a plant is a value inside struct
 * vmac_plant, stepped by whoever owns the clock (vmac-board in real time,
 * the test runner in virtual time). The I/O map of each plant is in
 * docs/BOARD.md. */
#ifndef VMAC_PLANT_H
#define VMAC_PLANT_H

#include <stddef.h>
#include <stdint.h>

#include "../core/proto/proto.h"

struct vmac_washer {
	double drum_rpm;       /* signed, + = forward */
	double encoder_pos;    /* encoder counts, fractional accumulator */
	double water_l;        /* litres in the tub */
	double water_c;        /* water temperature, Celsius */
	double load_kg;        /* laundry in the drum */
	double fill_rate_lps;  /* flow of each open valve, litres/second */
	int door_closed;       /* 1 = closed (operator action) */
	int door_locked;       /* PTC lock: engaged while closed and the solenoid is on, and for
	                          lock_release_s after the solenoid goes off */
	double lock_release_s; /* how long the lock stays engaged after the solenoid goes off, seconds */
	double lock_left_s;    /* solenoid off, lock still engaged: it releases when this reaches 0 */
	double start_left_s;   /* start button held down for this much longer */
	double cancel_left_s;  /* cancel button held down for this much longer */
	/* Safety monitor: an unsafe episode is a closed door not locked while the
	 * drum turns or the water is above the door. */
	int unsafe;               /* 1 while an episode lasts */
	uint32_t unsafe_episodes; /* episodes entered since init */
	double unsafe_rpm;        /* drum speed when the last episode began */
	double unsafe_water_l;    /* water level when the last episode began */
	struct vmac_outputs out;
};

struct vmac_dishwasher {
	double water_l;
	double wash_time_s;   /* how long the wash motor has run with water */
	double fill_rate_lps; /* flow of the open fill valve, litres/second */
	int door_closed;
	double start_left_s;  /* start button held down for this much longer */
	double cancel_left_s; /* cancel button held down for this much longer */
	struct vmac_outputs out;
};

struct vmac_lights {
	int switch_pos[2];    /* wall switch positions, toggled by the operator */
	double on_seconds[5]; /* time each relay has been on, for inspection */
	struct vmac_outputs out;
};

struct vmac_generic {
	uint8_t digital_in; /* set by the operator */
	uint16_t analog_in[VMAC_ANALOG_INPUTS];
	int32_t encoder;
	struct vmac_outputs out;
};

enum vmac_plant_kind { VMAC_PLANT_GENERIC, VMAC_PLANT_WASHER, VMAC_PLANT_DISHWASHER, VMAC_PLANT_LIGHTS };

struct vmac_plant {
	enum vmac_plant_kind kind;
	union {
		struct vmac_washer washer;
		struct vmac_dishwasher dishwasher;
		struct vmac_lights lights;
		struct vmac_generic generic;
	} s;
};

/* Look up a plant kind by name ("washer"); returns 0, or -1 when unknown. */
int vmac_plant_kind_from_name(const char *name, enum vmac_plant_kind *kind);
const char *vmac_plant_name(enum vmac_plant_kind kind);
/* Driver a board of this plant announces by default ("washer"). */
const char *vmac_plant_default_driver(enum vmac_plant_kind kind);
/* Capabilities the board announces for this plant. */
struct vmac_caps vmac_plant_caps(enum vmac_plant_kind kind);

/* Initial state: water empty, drum still, door closed, switches off. */
void vmac_plant_init(struct vmac_plant *p, enum vmac_plant_kind kind);
/* Advance the physics by dt_s seconds (0 < dt_s <= 0.1) under the outputs
 * last written. */
void vmac_plant_step(struct vmac_plant *p, double dt_s);
/* Sensors now: fills digital, analog and encoder of in. */
void vmac_plant_sense(const struct vmac_plant *p, struct vmac_inputs *in);
/* The board drives these outputs from now on. */
void vmac_plant_actuate(struct vmac_plant *p, const struct vmac_outputs *out);
/* Operator action on the machine, e.g. ("door", 0) opens the washer door,
 * ("switch1", 1), ("load_kg", 3.5). Returns 0, or -1 for an unknown name or
 * a value out of range. The names are listed in docs/BOARD.md. */
int vmac_plant_set(struct vmac_plant *p, const char *name, double value);

/* Unsafe episodes of the plant's own safety monitor since init (the washer:
 * a closed door not locked while the drum turns or the water is above the
 * door); 0 for a plant without one. The owner compares it with the count it
 * last reported and reports a new episode with vmac_plant_unsafe_text: the
 * plant itself prints nothing. */
uint32_t vmac_plant_unsafe_episodes(const struct vmac_plant *p);
/* The line for the last unsafe episode, without a newline, into buf (cap
 * bytes, truncated to fit, always NUL-terminated when cap > 0):
 * "washer UNSAFE: BOARD door closed and not locked, drum 45 rpm, water 12.3 l,
 * episode 1", with BOARD the board_name given (left out when NULL or empty).
 * The numbers are those of the moment the episode began. Returns the length
 * written. No stdio: the same text on POSIX and on the MCU. */
size_t vmac_plant_unsafe_text(const struct vmac_plant *p, const char *board_name, char *buf, size_t cap);

/* A machine's safety monitor as firmware/report.c reads it, whatever
 * simulates the machine (a C plant here, a Lua plant: core/sim/): the
 * unsafe episodes counted so far, and the line of the last one in
 * vmac_plant_unsafe_text's form. */
struct vmac_plant_safety {
	uint32_t (*episodes)(const void *ctx);
	size_t (*text)(const void *ctx, const char *board_name, char *buf, size_t cap);
	const void *ctx;
};
/* The C plant p's own monitor (p must outlive the view). */
struct vmac_plant_safety vmac_plant_safety_of(const struct vmac_plant *p);

/* A momentary button pressed by an operator action stays down this long (of
 * plant time), long enough for any service period to see it. */
#define VMAC_PLANT_BUTTON_S 0.5
/* Let a held button's time run: *left_s counts down to 0. */
void vmac_plant_button_step(double *left_s, double dt_s);

/* struct vmac_board_io adapters: ctx is a struct vmac_plant *. */
void vmac_plant_io_read(void *ctx, struct vmac_inputs *in);
void vmac_plant_io_write(void *ctx, const struct vmac_outputs *out);

#endif
