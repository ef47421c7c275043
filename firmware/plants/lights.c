/* Simulated home lighting: four relays (kitchen, dining, TV, garbage
 * disposal) and two toggle wall switches. The I/O map is the contract of the
 * "lights" Lua driver (docs/BOARD.md). */
#include <string.h>

#include "plants.h"

void vmac_lights_init(struct vmac_lights *l)
{
	memset(l, 0, sizeof(*l));
}

/* on_seconds[i] grows while relay output bit i is on. */
void vmac_lights_step(struct vmac_lights *l, double dt_s)
{
	int i;
	for (i = 0; i < VMAC_LIGHTS_RELAYS; i++) {
		if ((l->out.digital >> i) & 1)
			l->on_seconds[i] += dt_s;
	}
}

/* Input bit i is the position of wall switch i + 1. */
void vmac_lights_sense(const struct vmac_lights *l, struct vmac_inputs *in)
{
	int i;
	in->digital = 0;
	for (i = 0; i < VMAC_LIGHTS_SWITCHES; i++) {
		if (l->switch_pos[i])
			in->digital |= (uint8_t)(1u << i);
	}
	in->analog[0] = 0;
	in->analog[1] = 0;
	in->encoder = 0;
}

void vmac_lights_actuate(struct vmac_lights *l, const struct vmac_outputs *out)
{
	l->out = *out;
}

/* "switch1"/"switch2" 0/1 set a position; "toggle1"/"toggle2" flip it (value
 * ignored). */
int vmac_lights_set(struct vmac_lights *l, const char *name, double value)
{
	static const char *const set_names[VMAC_LIGHTS_SWITCHES] = {"switch1", "switch2"};
	static const char *const toggle_names[VMAC_LIGHTS_SWITCHES] = {"toggle1", "toggle2"};
	int i;
	for (i = 0; i < VMAC_LIGHTS_SWITCHES; i++) {
		if (strcmp(name, set_names[i]) == 0) {
			if (!vmac_plant_is_bit(value))
				return -1;
			l->switch_pos[i] = value == 1.0;
			return 0;
		}
		if (strcmp(name, toggle_names[i]) == 0) {
			l->switch_pos[i] = !l->switch_pos[i];
			return 0;
		}
	}
	return -1;
}
