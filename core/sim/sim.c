/* The simulated machine behind one board (sim.h): each call goes to the C
 * plant or the Lua plant; the C plants' fields for tests are named here. */
#include "sim.h"

#include "../driver/driver.h"

#include <stdio.h>
#include <string.h>

int vmac_sim_init_c(struct vmac_sim *s, const char *kind)
{
	enum vmac_plant_kind k;
	memset(s, 0, sizeof(*s));
	if (vmac_plant_kind_from_name(kind, &k) != 0)
		return -1;
	vmac_plant_init(&s->c, k);
	return 0;
}

int vmac_sim_init_lua(struct vmac_sim *s, const char *path, const struct vmac_luaplant_limits *lim, char *err,
                      size_t errlen)
{
	memset(s, 0, sizeof(*s));
	vmac_plant_init(&s->c, VMAC_PLANT_GENERIC); /* unused, but a valid plant */
	return vmac_luaplant_load_file(path, lim, &s->lua, err, errlen);
}

void vmac_sim_fini(struct vmac_sim *s)
{
	vmac_luaplant_free(s->lua);
	s->lua = NULL;
}

const char *vmac_sim_name(const struct vmac_sim *s)
{
	return s->lua ? vmac_luaplant_name(s->lua) : vmac_plant_name(s->c.kind);
}

const char *vmac_sim_driver(const struct vmac_sim *s)
{
	return s->lua ? vmac_luaplant_driver(s->lua) : vmac_plant_default_driver(s->c.kind);
}

struct vmac_caps vmac_sim_caps(const struct vmac_sim *s)
{
	return vmac_plant_caps(s->c.kind); /* the generic board's, for every plant */
}

int vmac_sim_step(struct vmac_sim *s, double dt_s)
{
	if (!s->lua) {
		vmac_plant_step(&s->c, dt_s);
		return 0;
	}
	while (dt_s > 0) {
		double step = dt_s > VMAC_SIM_MAX_STEP_S ? VMAC_SIM_MAX_STEP_S : dt_s;
		if (vmac_luaplant_step(s->lua, step) != 0) {
			if (s->failure_told)
				return -1;
			s->failure_told = 1;
			return -2;
		}
		dt_s -= step;
	}
	return 0;
}

void vmac_sim_sense(const struct vmac_sim *s, struct vmac_inputs *in)
{
	if (s->lua)
		vmac_luaplant_sense(s->lua, in);
	else
		vmac_plant_sense(&s->c, in);
}

void vmac_sim_actuate(struct vmac_sim *s, const struct vmac_outputs *out)
{
	if (s->lua)
		vmac_luaplant_actuate(s->lua, out);
	else
		vmac_plant_actuate(&s->c, out);
}

int vmac_sim_set(struct vmac_sim *s, const char *name, double value, char *why, size_t whylen)
{
	if (s->lua) {
		char text[VMAC_DRIVER_ERR_MAX + 64];
		if (vmac_luaplant_set(s->lua, name, value, text, sizeof(text)) == 0)
			return 0;
		snprintf(why, whylen, "the %s plant refuses %s = %g: %s", vmac_luaplant_name(s->lua), name, value,
		         text);
		return -1;
	}
	if (vmac_plant_set(&s->c, name, value) == 0)
		return 0;
	snprintf(why, whylen, "the %s plant refuses %s = %g (names and ranges: docs/BOARD.md)",
	         vmac_plant_name(s->c.kind), name, value);
	return -1;
}

static void number(struct vmac_value *v, double x)
{
	memset(v, 0, sizeof(*v));
	v->type = VMAC_VALUE_NUMBER;
	v->number = x;
}

static void boolean(struct vmac_value *v, int x)
{
	memset(v, 0, sizeof(*v));
	v->type = VMAC_VALUE_BOOL;
	v->number = x != 0;
}

/* A C plant's fields (docs/TESTING.md, "A board object"). */
static int c_field(const struct vmac_plant *p, const char *f, struct vmac_value *v)
{
	const struct vmac_washer *wa = &p->s.washer;
	const struct vmac_dishwasher *dw = &p->s.dishwasher;
	const struct vmac_lights *li = &p->s.lights;
	switch (p->kind) {
	case VMAC_PLANT_WASHER:
		if (!strcmp(f, "drum_rpm"))
			number(v, wa->drum_rpm);
		else if (!strcmp(f, "water_l"))
			number(v, wa->water_l);
		else if (!strcmp(f, "water_c"))
			number(v, wa->water_c);
		else if (!strcmp(f, "load_kg"))
			number(v, wa->load_kg);
		else if (!strcmp(f, "door_closed"))
			boolean(v, wa->door_closed);
		else if (!strcmp(f, "door_locked"))
			boolean(v, wa->door_locked);
		else if (!strcmp(f, "unsafe_episodes"))
			number(v, wa->unsafe_episodes);
		else
			return -1;
		return 0;
	case VMAC_PLANT_DISHWASHER:
		if (!strcmp(f, "water_l"))
			number(v, dw->water_l);
		else if (!strcmp(f, "wash_time_s"))
			number(v, dw->wash_time_s);
		else if (!strcmp(f, "door_closed"))
			boolean(v, dw->door_closed);
		else
			return -1;
		return 0;
	case VMAC_PLANT_LIGHTS:
		if (!strncmp(f, "on_seconds", 10) && f[10] >= '0' && f[10] <= '4' && !f[11]) {
			number(v, li->on_seconds[f[10] - '0']);
			return 0;
		}
		return -1;
	default: return -1;
	}
}

int vmac_sim_field(struct vmac_sim *s, const char *name, struct vmac_value *v)
{
	return s->lua ? vmac_luaplant_field(s->lua, name, v) : c_field(&s->c, name, v);
}

const char *vmac_sim_fields_text(const struct vmac_sim *s)
{
	if (s->lua)
		return "the fields of its state, and unsafe_episodes";
	switch (s->c.kind) {
	case VMAC_PLANT_WASHER: return "drum_rpm water_l water_c load_kg door_closed door_locked unsafe_episodes";
	case VMAC_PLANT_DISHWASHER: return "water_l wash_time_s door_closed";
	case VMAC_PLANT_LIGHTS: return "on_seconds0..on_seconds4";
	default: return "none";
	}
}

uint32_t vmac_sim_unsafe_episodes(const struct vmac_sim *s)
{
	return s->lua ? vmac_luaplant_unsafe_episodes(s->lua) : vmac_plant_unsafe_episodes(&s->c);
}

const char *vmac_sim_failure(const struct vmac_sim *s)
{
	return s->lua ? vmac_luaplant_failure(s->lua) : NULL;
}

static uint32_t safety_episodes(const void *ctx)
{
	return vmac_sim_unsafe_episodes((const struct vmac_sim *)ctx);
}

/* "dryer UNSAFE: dryer-1 heater on with the drum still, episode 2" */
static size_t safety_text(const void *ctx, const char *board_name, char *buf, size_t cap)
{
	const struct vmac_sim *s = ctx;
	int n;
	if (!s->lua)
		return vmac_plant_unsafe_text(&s->c, board_name, buf, cap);
	n = snprintf(buf, cap, "%s UNSAFE: %s%s%s, episode %lu", vmac_luaplant_name(s->lua),
	             board_name ? board_name : "", board_name && board_name[0] ? " " : "",
	             vmac_luaplant_unsafe_text(s->lua), (unsigned long)vmac_luaplant_unsafe_episodes(s->lua));
	if (n < 0)
		return 0;
	return (size_t)n < cap ? (size_t)n : (cap > 0 ? cap - 1 : 0);
}

struct vmac_plant_safety vmac_sim_safety(const struct vmac_sim *s)
{
	struct vmac_plant_safety safety;
	safety.episodes = safety_episodes;
	safety.text = safety_text;
	safety.ctx = s;
	return safety;
}

static void io_read(void *ctx, struct vmac_inputs *in)
{
	vmac_sim_sense((const struct vmac_sim *)ctx, in);
}

static void io_write(void *ctx, const struct vmac_outputs *out)
{
	vmac_sim_actuate((struct vmac_sim *)ctx, out);
}

const struct vmac_board_io vmac_sim_io = {io_read, io_write};
