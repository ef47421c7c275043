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

static void add_unsigned(struct text *t, uint32_t v)
{
	char d[11];
	int n = 0;
	do
		d[n++] = (char)('0' + v % 10);
	while ((v /= 10) != 0);
	while (n > 0) {
		char c[2] = {d[--n], 0};
		add(t, c);
	}
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
