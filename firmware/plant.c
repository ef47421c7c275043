/* Plant dispatcher: names, capabilities and the I/O adapters of the simulated
 * machines; each call is forwarded by kind to firmware/plants/<kind>.c. */
#include "plant.h"

#include <math.h>
#include <string.h>

#include "plants/plants.h"

/* A step longer than this is cut into pieces, so fill, drain and switches
 * interact at no coarser a grain than the contract promises the plants. */
#define PLANT_MAX_STEP_S 0.1

static const struct {
	enum vmac_plant_kind kind;
	const char *name;
} kinds[] = {
    {VMAC_PLANT_GENERIC, "generic"},
    {VMAC_PLANT_WASHER, "washer"},
    {VMAC_PLANT_DISHWASHER, "dishwasher"},
    {VMAC_PLANT_LIGHTS, "lights"},
};

#define KIND_COUNT (sizeof(kinds) / sizeof(kinds[0]))

uint16_t vmac_plant_analog_counts(double counts)
{
	if (!(counts > 0.0))
		return 0;
	if (counts >= VMAC_ANALOG_MAX)
		return VMAC_ANALOG_MAX;
	return (uint16_t)floor(counts + 0.5);
}

int vmac_plant_is_bit(double value)
{
	return value == 0.0 || value == 1.0;
}

int vmac_plant_in_range(double value, double lo, double hi)
{
	return value >= lo && value <= hi;
}

int vmac_plant_kind_from_name(const char *name, enum vmac_plant_kind *kind)
{
	size_t i;
	if (name == NULL)
		return -1;
	for (i = 0; i < KIND_COUNT; i++) {
		if (strcmp(name, kinds[i].name) == 0) {
			*kind = kinds[i].kind;
			return 0;
		}
	}
	return -1;
}

const char *vmac_plant_name(enum vmac_plant_kind kind)
{
	size_t i;
	for (i = 0; i < KIND_COUNT; i++) {
		if (kinds[i].kind == kind)
			return kinds[i].name;
	}
	return "?";
}

/* Every plant's board announces the driver named like the plant. */
const char *vmac_plant_default_driver(enum vmac_plant_kind kind)
{
	return vmac_plant_name(kind);
}

/* All plants sit on the same generic board (docs/BOARD.md). */
struct vmac_caps vmac_plant_caps(enum vmac_plant_kind kind)
{
	struct vmac_caps caps;
	(void)kind;
	caps.digital_inputs = VMAC_DIGITAL_INPUTS;
	caps.digital_outputs = VMAC_DIGITAL_OUTPUTS;
	caps.analog_inputs = VMAC_ANALOG_INPUTS;
	caps.pwm_outputs = 1;
	caps.encoders = 1;
	return caps;
}

/* An unknown kind becomes a generic plant, so p is always a valid plant. */
void vmac_plant_init(struct vmac_plant *p, enum vmac_plant_kind kind)
{
	memset(p, 0, sizeof(*p));
	switch (kind) {
	case VMAC_PLANT_WASHER:
		p->kind = kind;
		vmac_washer_init(&p->s.washer);
		break;
	case VMAC_PLANT_DISHWASHER:
		p->kind = kind;
		vmac_dishwasher_init(&p->s.dishwasher);
		break;
	case VMAC_PLANT_LIGHTS:
		p->kind = kind;
		vmac_lights_init(&p->s.lights);
		break;
	case VMAC_PLANT_GENERIC:
	default:
		p->kind = VMAC_PLANT_GENERIC;
		vmac_generic_init(&p->s.generic);
		break;
	}
}

static void step_once(struct vmac_plant *p, double dt_s)
{
	switch (p->kind) {
	case VMAC_PLANT_WASHER: vmac_washer_step(&p->s.washer, dt_s); break;
	case VMAC_PLANT_DISHWASHER: vmac_dishwasher_step(&p->s.dishwasher, dt_s); break;
	case VMAC_PLANT_LIGHTS: vmac_lights_step(&p->s.lights, dt_s); break;
	case VMAC_PLANT_GENERIC:
	default: vmac_generic_step(&p->s.generic, dt_s); break;
	}
}

/* dt_s <= 0 (or NaN) does nothing; a dt_s above 0.1 s is taken in 0.1 s
 * pieces rather than refused, so a late real-time caller loses no time. */
void vmac_plant_step(struct vmac_plant *p, double dt_s)
{
	while (dt_s > PLANT_MAX_STEP_S) {
		step_once(p, PLANT_MAX_STEP_S);
		dt_s -= PLANT_MAX_STEP_S;
	}
	if (dt_s > 0.0)
		step_once(p, dt_s);
}

void vmac_plant_sense(const struct vmac_plant *p, struct vmac_inputs *in)
{
	switch (p->kind) {
	case VMAC_PLANT_WASHER: vmac_washer_sense(&p->s.washer, in); break;
	case VMAC_PLANT_DISHWASHER: vmac_dishwasher_sense(&p->s.dishwasher, in); break;
	case VMAC_PLANT_LIGHTS: vmac_lights_sense(&p->s.lights, in); break;
	case VMAC_PLANT_GENERIC:
	default: vmac_generic_sense(&p->s.generic, in); break;
	}
}

void vmac_plant_actuate(struct vmac_plant *p, const struct vmac_outputs *out)
{
	switch (p->kind) {
	case VMAC_PLANT_WASHER: vmac_washer_actuate(&p->s.washer, out); break;
	case VMAC_PLANT_DISHWASHER: vmac_dishwasher_actuate(&p->s.dishwasher, out); break;
	case VMAC_PLANT_LIGHTS: vmac_lights_actuate(&p->s.lights, out); break;
	case VMAC_PLANT_GENERIC:
	default: vmac_generic_actuate(&p->s.generic, out); break;
	}
}

int vmac_plant_set(struct vmac_plant *p, const char *name, double value)
{
	if (name == NULL)
		return -1;
	switch (p->kind) {
	case VMAC_PLANT_WASHER: return vmac_washer_set(&p->s.washer, name, value);
	case VMAC_PLANT_DISHWASHER: return vmac_dishwasher_set(&p->s.dishwasher, name, value);
	case VMAC_PLANT_LIGHTS: return vmac_lights_set(&p->s.lights, name, value);
	case VMAC_PLANT_GENERIC:
	default: return vmac_generic_set(&p->s.generic, name, value);
	}
}

void vmac_plant_io_read(void *ctx, struct vmac_inputs *in)
{
	vmac_plant_sense((const struct vmac_plant *)ctx, in);
}

void vmac_plant_io_write(void *ctx, const struct vmac_outputs *out)
{
	vmac_plant_actuate((struct vmac_plant *)ctx, out);
}

uint32_t vmac_plant_unsafe_episodes(const struct vmac_plant *p)
{
	return p->kind == VMAC_PLANT_WASHER ? p->s.washer.unsafe_episodes : 0;
}

static uint32_t safety_episodes(const void *ctx)
{
	return vmac_plant_unsafe_episodes((const struct vmac_plant *)ctx);
}

static size_t safety_text(const void *ctx, const char *board_name, char *buf, size_t cap)
{
	return vmac_plant_unsafe_text((const struct vmac_plant *)ctx, board_name, buf, cap);
}

struct vmac_plant_safety vmac_plant_safety_of(const struct vmac_plant *p)
{
	struct vmac_plant_safety s;
	s.episodes = safety_episodes;
	s.text = safety_text;
	s.ctx = p;
	return s;
}

/* A line being written into a caller's buffer: whatever does not fit is
 * dropped, the text stays NUL-terminated. */
struct text {
	char *buf;
	size_t cap, len;
};

static void text_putc(struct text *t, char c)
{
	if (t->len + 1 < t->cap)
		t->buf[t->len++] = c;
	if (t->cap > 0)
		t->buf[t->len] = '\0';
}

static void text_put(struct text *t, const char *s)
{
	for (; *s; s++)
		text_putc(t, *s);
}

/* value rounded to `decimals` places (0..3) in decimal, with "-" when it
 * rounds to below 0; magnitudes beyond 4e9 / 10^decimals are clipped. */
static void text_put_fixed(struct text *t, double value, int decimals)
{
	char digits[16];
	double scale = 1.0, scaled;
	uint32_t whole, frac;
	int i, n = 0;

	for (i = 0; i < decimals; i++)
		scale *= 10.0;
	scaled = value == value ? floor(fabs(value) * scale + 0.5) : 0.0; /* NaN reads 0 */
	if (scaled > 4e9)
		scaled = 4e9;
	if (value < 0.0 && scaled > 0.0)
		text_putc(t, '-');
	whole = (uint32_t)(scaled / scale);
	frac = (uint32_t)(scaled - (double)whole * scale);
	do {
		digits[n++] = (char)('0' + whole % 10);
		whole /= 10;
	} while (whole > 0);
	while (n > 0)
		text_putc(t, digits[--n]);
	if (decimals > 0) {
		for (i = 0; i < decimals; i++, frac /= 10)
			digits[i] = (char)('0' + frac % 10);
		text_putc(t, '.');
		while (i > 0)
			text_putc(t, digits[--i]);
	}
}

size_t vmac_plant_unsafe_text(const struct vmac_plant *p, const char *board_name, char *buf, size_t cap)
{
	struct text t;
	t.buf = buf;
	t.cap = cap;
	t.len = 0;
	text_put(&t, vmac_plant_name(p->kind));
	text_put(&t, " UNSAFE: ");
	if (board_name != NULL && board_name[0] != '\0') {
		text_put(&t, board_name);
		text_put(&t, " ");
	}
	if (p->kind == VMAC_PLANT_WASHER) {
		const struct vmac_washer *w = &p->s.washer;
		text_put(&t, "door closed and not locked, drum ");
		text_put_fixed(&t, w->unsafe_rpm, 0);
		text_put(&t, " rpm, water ");
		text_put_fixed(&t, w->unsafe_water_l, 1);
		text_put(&t, " l, episode ");
		text_put_fixed(&t, (double)w->unsafe_episodes, 0);
	} else {
		text_put(&t, "no safety monitor");
	}
	return t.len;
}

void vmac_plant_button_step(double *left_s, double dt_s)
{
	*left_s = *left_s > dt_s ? *left_s - dt_s : 0.0;
}
