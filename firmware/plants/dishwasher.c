/* Simulated dishwasher: fill valve, wash motor, drain pump, a level switch
 * and a door without lock. The I/O map is the contract of the "dishwasher"
 * Lua driver (docs/BOARD.md). */
#include <string.h>

#include "plants.h"

/* Outputs (bit numbers). */
#define OUT_FILL_VALVE 0
#define OUT_WASH_MOTOR 1
#define OUT_DRAIN_PUMP 2
/* Inputs (bit numbers). */
#define IN_DOOR_CLOSED 0
#define IN_LEVEL_SWITCH 1
#define IN_START_BUTTON 2
#define IN_CANCEL_BUTTON 3

#define TANK_MAX_L 6.0     /* overflow: the level never rises above this */
#define LEVEL_SWITCH_L 3.0 /* level switch made at or above this */
#define DEFAULT_FILL_LPS 0.25
#define MAX_FILL_LPS 5.0
#define DRAIN_LPS 0.5
#define LEVEL_COUNTS_PER_L 100.0 /* analog0 */

static int output_on(const struct vmac_dishwasher *d, int bit)
{
	return (d->out.digital >> bit) & 1;
}

void vmac_dishwasher_init(struct vmac_dishwasher *d)
{
	memset(d, 0, sizeof(*d));
	d->fill_rate_lps = DEFAULT_FILL_LPS;
	d->door_closed = 1;
}

/* Washing counts only with the level switch made at the start of the step. */
void vmac_dishwasher_step(struct vmac_dishwasher *d, double dt_s)
{
	if (output_on(d, OUT_WASH_MOTOR) && d->water_l >= LEVEL_SWITCH_L)
		d->wash_time_s += dt_s;
	if (output_on(d, OUT_FILL_VALVE))
		d->water_l += d->fill_rate_lps * dt_s;
	if (output_on(d, OUT_DRAIN_PUMP))
		d->water_l -= DRAIN_LPS * dt_s;
	if (d->water_l < 0.0)
		d->water_l = 0.0;
	if (d->water_l > TANK_MAX_L)
		d->water_l = TANK_MAX_L;
	vmac_plant_button_step(&d->start_left_s, dt_s);
	vmac_plant_button_step(&d->cancel_left_s, dt_s);
}

void vmac_dishwasher_sense(const struct vmac_dishwasher *d, struct vmac_inputs *in)
{
	in->digital = (uint8_t)((d->door_closed ? 1u << IN_DOOR_CLOSED : 0u) |
	                        (d->water_l >= LEVEL_SWITCH_L ? 1u << IN_LEVEL_SWITCH : 0u) |
	                        (d->start_left_s > 0.0 ? 1u << IN_START_BUTTON : 0u) |
	                        (d->cancel_left_s > 0.0 ? 1u << IN_CANCEL_BUTTON : 0u));
	in->analog[0] = vmac_plant_analog_counts(d->water_l * LEVEL_COUNTS_PER_L);
	in->analog[1] = 0;
	in->encoder = 0;
}

void vmac_dishwasher_actuate(struct vmac_dishwasher *d, const struct vmac_outputs *out)
{
	d->out = *out;
}

/* "door" 0/1, "water_l" 0..6, "fill_rate_lps" 0..5, "start" and "cancel"
 * (any value) press a button for VMAC_PLANT_BUTTON_S. */
int vmac_dishwasher_set(struct vmac_dishwasher *d, const char *name, double value)
{
	if (strcmp(name, "start") == 0 || strcmp(name, "cancel") == 0) {
		*(name[0] == 's' ? &d->start_left_s : &d->cancel_left_s) = VMAC_PLANT_BUTTON_S;
		return 0;
	}
	if (strcmp(name, "door") == 0) {
		if (!vmac_plant_is_bit(value))
			return -1;
		d->door_closed = value == 1.0;
		return 0;
	}
	if (strcmp(name, "water_l") == 0) {
		if (!vmac_plant_in_range(value, 0.0, TANK_MAX_L))
			return -1;
		d->water_l = value;
		return 0;
	}
	if (strcmp(name, "fill_rate_lps") == 0) {
		if (!vmac_plant_in_range(value, 0.0, MAX_FILL_LPS))
			return -1;
		d->fill_rate_lps = value;
		return 0;
	}
	return -1;
}
