/* Raw generic board with no machine behind it: the operator sets the inputs
 * directly and the outputs are only stored ("generic" driver, docs/BOARD.md). */
#include <math.h>
#include <string.h>

#include "plants.h"

void vmac_generic_init(struct vmac_generic *g)
{
	memset(g, 0, sizeof(*g));
}

/* Nothing moves by itself. */
void vmac_generic_step(struct vmac_generic *g, double dt_s)
{
	(void)g;
	(void)dt_s;
}

void vmac_generic_sense(const struct vmac_generic *g, struct vmac_inputs *in)
{
	int i;
	in->digital = g->digital_in;
	for (i = 0; i < VMAC_ANALOG_INPUTS; i++)
		in->analog[i] = g->analog_in[i];
	in->encoder = g->encoder;
}

void vmac_generic_actuate(struct vmac_generic *g, const struct vmac_outputs *out)
{
	g->out = *out;
}

static int is_integer(double value)
{
	return floor(value) == value;
}

/* "di0".."di7" 0/1, "ai0"/"ai1" 0..4095 counts, "encoder" any int32 count;
 * analog and encoder values must be whole numbers. */
int vmac_generic_set(struct vmac_generic *g, const char *name, double value)
{
	if (name[0] == 'd' && name[1] == 'i' && name[2] >= '0' && name[2] < '0' + VMAC_DIGITAL_INPUTS &&
	    name[3] == '\0') {
		uint8_t bit = (uint8_t)(1u << (name[2] - '0'));
		if (!vmac_plant_is_bit(value))
			return -1;
		if (value == 1.0)
			g->digital_in |= bit;
		else
			g->digital_in &= (uint8_t)~bit;
		return 0;
	}
	if (name[0] == 'a' && name[1] == 'i' && name[2] >= '0' && name[2] < '0' + VMAC_ANALOG_INPUTS &&
	    name[3] == '\0') {
		if (!vmac_plant_in_range(value, 0.0, VMAC_ANALOG_MAX) || !is_integer(value))
			return -1;
		g->analog_in[name[2] - '0'] = (uint16_t)value;
		return 0;
	}
	if (strcmp(name, "encoder") == 0) {
		if (!vmac_plant_in_range(value, -2147483648.0, 2147483647.0) || !is_integer(value))
			return -1;
		g->encoder = (int32_t)value;
		return 0;
	}
	return -1;
}
