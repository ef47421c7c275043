/* Internal interface between firmware/plant.c (the dispatcher) and the
 * per-machine simulations in firmware/plants/. Not for use outside firmware/. */
#ifndef VMAC_PLANTS_H
#define VMAC_PLANTS_H

#include "../plant.h"

/* Wall switches and relays of the lights plant. */
#define VMAC_LIGHTS_SWITCHES 2
#define VMAC_LIGHTS_RELAYS 4

/* Converter counts for a reading: rounded to the nearest count and clipped to
 * 0..VMAC_ANALOG_MAX (NaN reads 0). Defined in plant.c. */
uint16_t vmac_plant_analog_counts(double counts);
/* 1 when value is exactly 0 or 1 (an operator's on/off), else 0. */
int vmac_plant_is_bit(double value);
/* 1 when lo <= value <= hi (never for NaN), else 0. */
int vmac_plant_in_range(double value, double lo, double hi);

/* Each machine: init to its rest state, step by dt_s seconds (0 < dt_s <= 0.1)
 * under its stored outputs, sense its inputs, store new outputs, and take an
 * operator action (0, or -1 for an unknown name or a refused value). */
void vmac_washer_init(struct vmac_washer *w);
void vmac_washer_step(struct vmac_washer *w, double dt_s);
void vmac_washer_sense(const struct vmac_washer *w, struct vmac_inputs *in);
void vmac_washer_actuate(struct vmac_washer *w, const struct vmac_outputs *out);
int vmac_washer_set(struct vmac_washer *w, const char *name, double value);

void vmac_dishwasher_init(struct vmac_dishwasher *d);
void vmac_dishwasher_step(struct vmac_dishwasher *d, double dt_s);
void vmac_dishwasher_sense(const struct vmac_dishwasher *d, struct vmac_inputs *in);
void vmac_dishwasher_actuate(struct vmac_dishwasher *d, const struct vmac_outputs *out);
int vmac_dishwasher_set(struct vmac_dishwasher *d, const char *name, double value);

void vmac_lights_init(struct vmac_lights *l);
void vmac_lights_step(struct vmac_lights *l, double dt_s);
void vmac_lights_sense(const struct vmac_lights *l, struct vmac_inputs *in);
void vmac_lights_actuate(struct vmac_lights *l, const struct vmac_outputs *out);
int vmac_lights_set(struct vmac_lights *l, const char *name, double value);

void vmac_generic_init(struct vmac_generic *g);
void vmac_generic_step(struct vmac_generic *g, double dt_s);
void vmac_generic_sense(const struct vmac_generic *g, struct vmac_inputs *in);
void vmac_generic_actuate(struct vmac_generic *g, const struct vmac_outputs *out);
int vmac_generic_set(struct vmac_generic *g, const char *name, double value);

#endif
