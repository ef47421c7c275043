/* The board's log lines: see report.h. The numbers are written here, digit
 * by digit, so that a microcontroller needs no printf. */
#include "report.h"

#include <string.h>

struct text {
	char *buf;
	size_t len, at;
};

static void add(struct text *t, const char *s)
{
	while (*s && t->at + 1 < t->len)
		t->buf[t->at++] = *s++;
	t->buf[t->at] = 0;
}

static void add_u64(struct text *t, uint64_t v)
{
	char d[21];
	int n = 0;
	do
		d[n++] = (char)('0' + v % 10);
	while ((v /= 10) != 0);
	while (n > 0) {
		char c[2] = {d[--n], 0};
		add(t, c);
	}
}

static void add_unsigned(struct text *t, uint32_t v)
{
	add_u64(t, v);
}

/* v in units of 10^-decimals, as a decimal with its sign when sign is set
 * ("-1.999871234", "+199.9"; decimals 1..9). */
static void add_fixed(struct text *t, int64_t v, int decimals, int sign)
{
	uint64_t m = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v, scale = 1, frac;
	char digits[10];
	int i;
	for (i = 0; i < decimals; i++)
		scale *= 10;
	if (v < 0)
		add(t, "-");
	else if (sign)
		add(t, "+");
	add_u64(t, m / scale);
	add(t, ".");
	frac = m % scale;
	for (i = decimals - 1; i >= 0; i--) {
		digits[i] = (char)('0' + frac % 10);
		frac /= 10;
	}
	digits[decimals] = 0;
	add(t, digits);
}

static void add_signed(struct text *t, int32_t v)
{
	if (v < 0) {
		add(t, "-");
		add_unsigned(t, (uint32_t)(-(int64_t)v));
	} else {
		add_unsigned(t, (uint32_t)v);
	}
}

static void add_hex(struct text *t, uint32_t v, int digits)
{
	static const char hex[] = "0123456789abcdef";
	while (digits-- > 0) {
		char c[2] = {hex[(v >> (4 * digits)) & 15], 0};
		add(t, c);
	}
}

static struct text start(const struct vmac_board *b, char *line, size_t len)
{
	struct text t = {line, len, 0};
	if (len)
		line[0] = 0;
	add(&t, b->id.board);
	add(&t, ": ");
	return t;
}

void vmac_report_init(struct vmac_report *r, const struct vmac_board *b, const struct vmac_plant_safety *s, int quiet)
{
	r->state = b->state;
	r->outputs = b->outputs;
	r->unsafe = s->episodes(s->ctx);
	r->clock = b->clock.state;
	r->timed = b->timed.mode;
	r->quiet = quiet;
}

int vmac_report_next(struct vmac_report *r, const struct vmac_board *b, const struct vmac_plant_safety *s, char *line,
                     size_t len)
{
	struct text t;
	if (b->state != r->state) {
		r->state = b->state;
		if (!r->quiet || b->state != VMAC_BOARD_KNOWN) {
			t = start(b, line, len);
			add(&t, "state ");
			add(&t, vmac_board_state_name(b->state));
			add(&t, " device 0x");
			add_hex(&t, b->device_id, 8);
			add(&t, " watchdog ");
			add_unsigned(&t, b->watchdog_ms);
			add(&t, " ms");
			return 1;
		}
	}
	if (b->clock.state != r->clock) {
		r->clock = b->clock.state;
		if (!r->quiet || b->clock.state == VMAC_CLOCK_LOST) {
			vmac_report_clock(b, 0, line, len);
			return 1;
		}
	}
	if (b->timed.mode != r->timed) {
		r->timed = b->timed.mode;
		if (b->timed.mode == VMAC_TIMED_MODE_INSTANTS && !r->quiet) {
			t = start(b, line, len);
			add(&t, "acting at host instants");
			return 1;
		}
		if (b->timed.mode == VMAC_TIMED_MODE_ARRIVAL) {
			t = start(b, line, len);
			add(&t, "acting on arrival (clock ");
			add(&t, vmac_clock_state_name(b->clock.state));
			add(&t, ")");
			return 1;
		}
	}
	if (b->outputs.digital != r->outputs.digital || b->outputs.pwm != r->outputs.pwm) {
		r->outputs = b->outputs;
		if (!r->quiet) {
			t = start(b, line, len);
			add(&t, "outputs digital=0x");
			add_hex(&t, b->outputs.digital, 2);
			add(&t, " pwm=");
			add_signed(&t, b->outputs.pwm);
			return 1;
		}
	}
	if (s->episodes(s->ctx) != r->unsafe) {
		/* A safety event: said even when quiet. Episodes entered since the
		 * last report share the line of the last. */
		r->unsafe = s->episodes(s->ctx);
		s->text(s->ctx, b->id.board, line, len);
		return 1;
	}
	return 0;
}

void vmac_report_watchdog(const struct vmac_board *b, char *line, size_t len)
{
	struct text t = start(b, line, len);
	add(&t, "watchdog: no frame for ");
	add_unsigned(&t, b->watchdog_ms);
	add(&t, " ms, outputs off");
}

void vmac_report_clock(const struct vmac_board *b, int with_counters, char *line, size_t len)
{
	struct text t = start(b, line, len);
	int64_t offset_ns;
	uint64_t bound_ns;
	add(&t, "clock ");
	add(&t, vmac_clock_state_name(b->clock.state));
	if (vmac_board_clock_offset(b, b->clock_local_ns, &offset_ns, &bound_ns) == 0) {
		add(&t, ", offset ");
		add_fixed(&t, offset_ns, 9, 1);
		add(&t, " s, drift ");
		/* the learnt frequency is host ns per local ns, - 1: the counter's own drift is its opposite */
		add_fixed(&t, -(int64_t)vmac_clock_freq_ppb(&b->clock) / 100, 1, 1);
		add(&t, " ppm, bound ");
		add_fixed(&t, (int64_t)(bound_ns > 999999999 ? 999999999 : bound_ns) / 100, 1, 0);
		add(&t, " us");
	} else if (b->clock.state == VMAC_CLOCK_LOST) {
		add(&t, ", acting on arrival");
	}
	if (!with_counters)
		return;
	add(&t, "; sync accepted ");
	add_unsigned(&t, b->clock.counters.accepted);
	add(&t, ", rejected ");
	add_unsigned(&t, b->clock.counters.rejected);
	add(&t, ", ignored ");
	add_unsigned(&t, b->counters.sync_ignored);
	add(&t, ", two-step ");
	add_unsigned(&t, b->counters.sync_two_step);
}

void vmac_report_counters(const struct vmac_board *b, char *line, size_t len)
{
	struct text t = start(b, line, len);
	add(&t, "frames ok ");
	add_unsigned(&t, b->counters.frames_ok);
	add(&t, ", malformed ");
	add_unsigned(&t, b->counters.frames_malformed);
	add(&t, ", ignored ");
	add_unsigned(&t, b->counters.frames_ignored);
	add(&t, ", watchdog trips ");
	add_unsigned(&t, b->counters.watchdog_trips);
	add(&t, ", auth_failed ");
	add_unsigned(&t, b->counters.auth_failed);
}

int vmac_report_timed(const struct vmac_board *b, char *line, size_t len)
{
	const struct vmac_board_counters *c = &b->counters;
	struct text t;
	if (c->timed == 0 && c->timed_arrival == 0)
		return 0;
	t = start(b, line, len);
	add(&t, "timed ");
	add_unsigned(&t, c->timed);
	add(&t, ", on arrival ");
	add_unsigned(&t, c->timed_arrival);
	add(&t, ", late ");
	add_unsigned(&t, c->timed_late);
	add(&t, ", overrun ");
	add_unsigned(&t, c->timed_overrun);
	return 1;
}
