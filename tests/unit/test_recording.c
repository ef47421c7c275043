/* Unit tests of the flight recorder (docs/RECORDING.md): its rings keep the
 * newest ticks and events in order when they wrap; a recording written and
 * read back holds every tick, event, param and operator input with every
 * value type, and the header's fields; a recording that lost its first ticks
 * says so; every truncation, every flipped byte and a file that is no
 * recording are refused with the reason; a recording without the driver's
 * source reads back without one; each board's latch instant (`at`) reads
 * back as recorded, and a tick line without one, or with keys this reader
 * does not know, reads as before. */
#include <check.h>
#include <sodium.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/recorder/recorder.h"
#include "../../core/recorder/recording.h"
#include "check_main.h"

#define NS_PER_S 1000000000LL
#define PERIOD_NS 100000000LL /* the recorders here tick every 100 ms */
#define SOURCE "return { name = 'washer', version = '1.2.0', io = {} } -- \"quoted\", \xc3\xa9\n"

static struct vmac_inputs inputs_of(uint32_t i)
{
	struct vmac_inputs in;
	memset(&in, 0, sizeof(in));
	in.digital = (uint8_t)i;
	in.analog[0] = (uint16_t)(i % 4096);
	in.analog[1] = (uint16_t)(4095 - i % 4096);
	in.encoder = (int32_t)i * -3;
	in.applied.digital = (uint8_t)(i & 0x7f);
	in.applied.pwm = (int16_t)(i % 2001) - 1000;
	return in;
}

static struct vmac_outputs outputs_of(uint32_t i)
{
	struct vmac_outputs out = {(uint8_t)((i * 7) & 0x7f), (int16_t)(1000 - (int)(i % 2001))};
	return out;
}

/* A recorder of one board named "w-1" (minor 3), attached at 0, that
 * recorded ticks 0..nticks-1 at PERIOD_NS apart (board inputs of index i). */
static struct vmac_recorder *recorded(uint32_t nticks)
{
	struct vmac_recorder *r = vmac_recorder_new(1.0, (double)PERIOD_NS / NS_PER_S); /* 10 ticks: 64, the least */
	uint32_t i;
	ck_assert_ptr_nonnull(r);
	snprintf(r->machine, sizeof(r->machine), "w-1");
	snprintf(r->driver, sizeof(r->driver), "washer");
	snprintf(r->version, sizeof(r->version), "1.2.0");
	snprintf(r->reason, sizeof(r->reason), "dropped: no reply");
	r->level = 4;
	r->period_s = (double)PERIOD_NS / NS_PER_S;
	r->nboards = 1;
	snprintf(r->boards[0].name, sizeof(r->boards[0].name), "w-1");
	r->boards[0].minor = 3;
	r->attach_ns = 0;
	r->from_attach = 1;
	snprintf(vmac_rec_event(r, 0, VMAC_REC_ATTACH)->name, VMAC_REC_NAME_MAX + 1, "1.2.0");
	for (i = 0; i < nticks; i++) {
		struct vmac_inputs in = inputs_of(i);
		struct vmac_outputs out = outputs_of(i);
		int64_t t = (int64_t)(i + 1) * PERIOD_NS;
		vmac_rec_tick(r, t, 0, 1, &in, &out, t);
	}
	return r;
}

/* Write r (with src, or none) and read it back into rec; the text is
 * returned (malloc'd, *len bytes). */
static char *round_trip(const struct vmac_recorder *r, const char *src, struct vmac_recording *rec, size_t *len)
{
	char err[256] = "";
	char *text = vmac_recording_write(r, src, src ? strlen(src) : 0, NULL, 0, 1795000000.25, len);
	ck_assert_msg(text != NULL, "writing the recording failed");
	ck_assert_msg(vmac_recording_read(text, *len, rec, err, sizeof(err)) == 0, "reading it back failed: %s", err);
	return text;
}

START_TEST(the_tick_ring_keeps_the_newest_in_order_and_says_it_is_incomplete)
{
	struct vmac_recorder *r = recorded(100);
	struct vmac_recording rec;
	uint32_t i, n = 0;
	size_t len, l;
	char *text;

	ck_assert_msg(r->ticks_cap == 64, "a recorder of 1 s at 100 ms holds %u ticks, not the least (64)",
	              r->ticks_cap);
	ck_assert_uint_eq(vmac_rec_nticks(r), 64);
	for (i = 0; i < 64; i++) {
		const struct vmac_rec_tick *t = vmac_rec_tick_at(r, i);
		ck_assert_msg(t->t_ns == (int64_t)(i + 37) * PERIOD_NS,
		              "tick %u kept is at %lld ns, not tick %u's time", i, (long long)t->t_ns, i + 36);
		ck_assert_msg(t->in.encoder == (int32_t)(i + 36) * -3, "tick %u kept holds another tick's inputs", i);
	}
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_msg(!rec.complete, "a recording that lost its first 36 ticks says it is complete");
	ck_assert_uint_eq(rec.nticks, 64);
	for (l = 0; l < rec.nlines; l++)
		if (rec.lines[l].is_tick) {
			ck_assert_msg(rec.lines[l].t_ns == (int64_t)(n + 37) * PERIOD_NS, "tick line %u out of order",
			              n);
			n++;
		}
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);

	r = recorded(64); /* exactly full: nothing lost */
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_msg(rec.complete, "a recording with every tick since attach says it is incomplete");
	ck_assert_uint_eq(rec.nticks, 64);
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);

	r = recorded(10); /* put in after a capture: not from attach */
	r->from_attach = 0;
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_msg(!rec.complete, "a recorder put in after attach says its recording is complete");
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);
}
END_TEST

/* The ring is written a stage at a time (recorder.c): whatever the count,
 * part of a stage or many wraps, the newest ticks read back in order, each
 * the one written at its place. */
START_TEST(every_count_of_ticks_reads_back_whether_staged_or_in_the_ring)
{
	uint32_t n, i, kept;
	for (n = 0; n <= 3 * 64 + VMAC_REC_STAGE + 3; n++) {
		struct vmac_recorder *r = recorded(n);
		kept = n < r->ticks_cap ? n : r->ticks_cap;
		ck_assert_msg(vmac_rec_nticks(r) == kept, "%u ticks written, %u kept, not %u", n, vmac_rec_nticks(r),
		              kept);
		for (i = 0; i < kept; i++) {
			const struct vmac_rec_tick *t = vmac_rec_tick_at(r, i);
			uint32_t want = n - kept + i;
			ck_assert_msg(t->t_ns == (int64_t)(want + 1) * PERIOD_NS && t->in.encoder == (int32_t)want * -3,
			              "after %u ticks, the %u-th kept is not tick %u (at %lld ns)", n, i, want,
			              (long long)t->t_ns);
		}
		vmac_rec_seal(r);
		vmac_recorder_free(r);
	}
}
END_TEST

/* dev.state snapshots (vmac_rec_state): kept at most every half of the
 * ring's span; a recording whose ring wrapped carries the oldest one the
 * ring still covers, a complete one none. */
START_TEST(a_wrapped_recording_carries_the_oldest_state_its_ring_covers)
{
	static const uint8_t a[] = "state-a", b[] = "state-b", c[] = "state-c";
	struct vmac_recorder *r = recorded(0); /* 64 ticks at 100 ms: a span of 6.4 s */
	struct vmac_recording rec;
	size_t len;
	char *text;
	uint32_t i;

	ck_assert_msg(vmac_rec_state_base(r) == NULL, "a new recorder has a state");
	for (i = 0; i < 200; i++) {
		struct vmac_inputs in = inputs_of(i);
		struct vmac_outputs out = outputs_of(i);
		int64_t t = (int64_t)(i + 1) * PERIOD_NS;
		vmac_rec_tick(r, t, 0, 1, &in, &out, t);
		if (i == 100)
			vmac_rec_state(r, t, a, sizeof(a));
		if (i == 110) /* 1 s later: within half the span of a, not kept */
			vmac_rec_state(r, t, c, sizeof(c));
		if (i == 140) /* 4 s later: kept */
			vmac_rec_state(r, t, b, sizeof(b));
	}
	/* The ring holds ticks 136..199: a (after tick 100) is out of it, b (after 140) is the base. */
	ck_assert_msg(vmac_rec_state_base(r) && vmac_rec_state_base(r)->len == sizeof(b) &&
	                  memcmp(vmac_rec_state_base(r)->data, b, sizeof(b)) == 0,
	              "the base state is not the newest the ring still covers");
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_msg(!rec.complete && rec.state && rec.state_len == sizeof(b) && memcmp(rec.state, b, sizeof(b)) == 0,
	              "the recording does not carry state b");
	ck_assert_msg(rec.state_t_ns == 141 * PERIOD_NS, "the state is at %lld ns, not after tick 140",
	              (long long)rec.state_t_ns);
	vmac_recording_free(&rec);
	free(text);
	vmac_rec_state(r, 200 * PERIOD_NS, (const uint8_t *)"", 0); /* empty: not kept */
	ck_assert_msg(vmac_rec_state_base(r)->len == sizeof(b), "an empty state was kept");
	vmac_recorder_free(r);

	r = recorded(10); /* complete: replay starts at attach, no state needed */
	vmac_rec_state(r, 10 * PERIOD_NS, a, sizeof(a));
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_msg(rec.complete && rec.state == NULL, "a complete recording carries a state");
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);
}
END_TEST

START_TEST(a_recorder_is_sized_by_seconds_and_bounded)
{
	struct vmac_recorder *r = vmac_recorder_new(60, 0.1);
	ck_assert_ptr_nonnull(r);
	ck_assert_msg(r->ticks_cap == 608, "60 s at 100 ms hold %u ticks, not 600 rounded up to whole stages of %d",
	              r->ticks_cap, VMAC_REC_STAGE);
	ck_assert_msg(vmac_rec_nticks(r) == 0 && vmac_rec_nevents(r) == 0 && r->attach_ns == -1,
	              "a new recorder is not empty and unattached");
	vmac_recorder_free(r);
	r = vmac_recorder_new(3600, 1e-6); /* 3.6 G ticks asked for */
	ck_assert_ptr_nonnull(r);
	ck_assert_msg(r->ticks_cap == 1u << 22, "an hour at 1 us holds %u ticks, not the bound 4 Mi", r->ticks_cap);
	vmac_recorder_free(r);
	ck_assert_msg(vmac_recorder_new(0, 0.1) == NULL, "recorder_s 0 made a recorder");
	vmac_recorder_free(NULL);
}
END_TEST

START_TEST(the_event_ring_keeps_the_newest_128_in_order)
{
	struct vmac_recorder *r = vmac_recorder_new(1.0, 0.1);
	struct vmac_recording rec;
	size_t len, l;
	char *text;
	int32_t i, n = 0;

	ck_assert_ptr_nonnull(r);
	snprintf(r->machine, sizeof(r->machine), "m");
	snprintf(r->driver, sizeof(r->driver), "d");
	r->nboards = 1;
	r->attach_ns = 0;
	r->from_attach = 1;
	for (i = 0; i < 300; i++) {
		struct vmac_rec_event *e = vmac_rec_event(r, i, VMAC_REC_LEVEL);
		ck_assert_msg(e->code == 0 && e->name[0] == 0 && e->text[0] == 0,
		              "a reused event slot kept old fields");
		e->code = i;
	}
	ck_assert_uint_eq(vmac_rec_nevents(r), VMAC_REC_EVENTS);
	for (i = 0; i < VMAC_REC_EVENTS; i++)
		ck_assert_msg(vmac_rec_event_at(r, (uint32_t)i)->code == 300 - VMAC_REC_EVENTS + i,
		              "event %d kept is level %d, not %d", i, vmac_rec_event_at(r, (uint32_t)i)->code,
		              300 - VMAC_REC_EVENTS + i);
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_uint_eq(rec.nevents, VMAC_REC_EVENTS);
	ck_assert_uint_eq(rec.nticks, 0);
	for (l = 0; l < rec.nlines; l++, n++)
		ck_assert_msg(rec.lines[l].ev.kind == VMAC_REC_LEVEL &&
		                  rec.lines[l].ev.code == 300 - VMAC_REC_EVENTS + n,
		              "event line %zu is not the level %d", l, 300 - VMAC_REC_EVENTS + n);
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);
}
END_TEST

static void set_value(struct vmac_value *v, enum vmac_value_type type, double number, const char *str)
{
	memset(v, 0, sizeof(*v));
	v->type = type;
	v->number = number;
	snprintf(v->str, sizeof(v->str), "%s", str);
}

static void assert_value(const struct vmac_value *got, const struct vmac_value *want, const char *what)
{
	ck_assert_msg(got->type == want->type, "%s: type %d, not %d", what, got->type, want->type);
	if (want->type == VMAC_VALUE_STRING)
		ck_assert_msg(strcmp(got->str, want->str) == 0, "%s: \"%s\", not \"%s\"", what, got->str, want->str);
	else if (want->type != VMAC_VALUE_NONE)
		ck_assert_msg(got->number == want->number, "%s: %.17g, not %.17g", what, got->number, want->number);
}

START_TEST(everything_recorded_reads_back_as_it_was)
{
	static const struct {
		enum vmac_value_type type;
		double number;
		const char *str;
	} values[] = {
	    {VMAC_VALUE_NUMBER, 0.1, ""},
	    {VMAC_VALUE_NUMBER, -1e300, ""},
	    {VMAC_VALUE_BOOL, 1, ""},
	    {VMAC_VALUE_BOOL, 0, ""},
	    {VMAC_VALUE_STRING, 0, "quick \"with\" \\ and \xc3\xa9 and a tab\t"},
	    {VMAC_VALUE_STRING, 0, ""},
	    {VMAC_VALUE_NONE, 0, ""},
	};
	const int nvalues = (int)(sizeof(values) / sizeof(values[0]));
	struct vmac_recorder *r = vmac_recorder_new(10, 0.1);
	struct vmac_value want[8];
	struct vmac_recording rec;
	struct vmac_rec_event *e;
	struct vmac_inputs in[2];
	struct vmac_outputs out[2];
	size_t len, l, nparams = 0, ninputs = 0, nticks = 0;
	char *text;
	int i, b;

	ck_assert_ptr_nonnull(r);
	snprintf(r->machine, sizeof(r->machine), "washer-1");
	snprintf(r->driver, sizeof(r->driver), "washer");
	snprintf(r->version, sizeof(r->version), "1.2.0");
	snprintf(r->reason, sizeof(r->reason), "driver error: washer.lua:12: boom");
	r->version_id = 42;
	r->level = 5;
	r->period_s = 0.2;
	r->nboards = 2;
	snprintf(r->boards[0].name, sizeof(r->boards[0].name), "washer-1");
	snprintf(r->boards[1].name, sizeof(r->boards[1].name), "washer-1-aux");
	r->boards[0].minor = 0;
	r->boards[1].minor = 4000000000u;
	r->attach_ns = 5 * NS_PER_S;
	r->from_attach = 1;
	snprintf(vmac_rec_event(r, r->attach_ns, VMAC_REC_ATTACH)->name, VMAC_REC_NAME_MAX + 1, "1.2.0");
	for (i = 0; i < nvalues; i++) {
		e = vmac_rec_event(r, r->attach_ns, VMAC_REC_PARAM);
		snprintf(e->name, sizeof(e->name), "param_%d", i);
		set_value(&e->value, values[i].type, values[i].number, values[i].str);
		want[i] = e->value;
	}
	/* Two boards a tick; operator input of every type between the ticks,
	 * accepted (0), refused (1) and failing (-1). */
	for (i = 0; i < nvalues; i++) {
		int64_t t = r->attach_ns + (i + 1) * 200000000LL;
		for (b = 0; b < 2; b++) {
			memset(&in[b], 0, sizeof(in[b]));
			in[b].digital = b ? 0xff : (uint8_t)i;
			in[b].analog[0] = b ? 4095 : 0;
			in[b].analog[1] = (uint16_t)(i * 100);
			in[b].encoder = b ? INT32_MIN : INT32_MAX - i;
			in[b].applied.digital = 0x7f;
			in[b].applied.pwm = b ? -1000 : 1000;
			out[b].digital = (uint8_t)(0x40 >> b);
			out[b].pwm = (int16_t)(b ? -i : i * 100);
			vmac_rec_tick(r, t, b, b == 1, &in[b], &out[b], t);
		}
		e = vmac_rec_event(r, t + 50000000, VMAC_REC_INPUT);
		snprintf(e->name, sizeof(e->name), "input_%d", i);
		set_value(&e->value, values[i].type, values[i].number, values[i].str);
		e->code = i % 3 - 1;
	}
	e = vmac_rec_event(r, 7 * NS_PER_S, VMAC_REC_LEVEL);
	e->code = 3;
	e = vmac_rec_event(r, 7 * NS_PER_S, VMAC_REC_SWAP);
	snprintf(e->name, sizeof(e->name), "1.3.0");
	e = vmac_rec_event(r, 8 * NS_PER_S, VMAC_REC_MISS);
	e->board = 1;
	e->code = 65535;
	e->a_ns = 20232658855049LL;
	e->b_ns = 20232758855049LL;
	snprintf(e->text, sizeof(e->text), "no reply to UPDATE seq 65535 within 80 ms");
	e = vmac_rec_event(r, 8 * NS_PER_S + 1, VMAC_REC_ERROR);
	snprintf(e->text, sizeof(e->text), "washer.lua:12: boom\nstack traceback:\n\t[C]: in ?");
	e = vmac_rec_event(r, 8 * NS_PER_S + 2, VMAC_REC_DROP);
	snprintf(e->text, sizeof(e->text), "its driver failed");

	text = round_trip(r, SOURCE, &rec, &len);
	ck_assert_str_eq(rec.machine, "washer-1");
	ck_assert_str_eq(rec.driver, "washer");
	ck_assert_str_eq(rec.version, "1.2.0");
	ck_assert_str_eq(rec.reason, "driver error: washer.lua:12: boom");
	ck_assert_msg(rec.captured == 1795000000.25, "captured %.17g", rec.captured);
	ck_assert_msg(rec.period_s == 0.2, "period_s %.17g", rec.period_s);
	ck_assert_uint_eq(rec.level, 5);
	ck_assert_msg(rec.attach_ns == 5 * NS_PER_S, "attach_ns %lld", (long long)rec.attach_ns);
	ck_assert_msg(rec.complete, "a recording with every tick since attach is not complete");
	ck_assert_int_eq(rec.nboards, 2);
	ck_assert_str_eq(rec.boards[1].name, "washer-1-aux");
	ck_assert_msg(rec.boards[0].minor == 0 && rec.boards[1].minor == 4000000000u, "boards' minors %u %u",
	              rec.boards[0].minor, rec.boards[1].minor);
	ck_assert_msg(rec.source && rec.source_len == strlen(SOURCE) && strcmp(rec.source, SOURCE) == 0,
	              "the driver's source did not come back as it was: %s", rec.source ? rec.source : "(none)");
	ck_assert_uint_eq(rec.nticks, (size_t)nvalues);
	ck_assert_uint_eq(rec.nevents, 1 + 2 * (size_t)nvalues + 5);
	ck_assert_uint_eq(rec.nlines, rec.nticks + rec.nevents);

	for (l = 0; l < rec.nlines; l++) {
		const struct vmac_recording_line *line = &rec.lines[l];
		const struct vmac_rec_event *ev = &line->ev;
		char what[64];
		ck_assert_msg(l == 0 || line->t_ns >= rec.lines[l - 1].t_ns, "line %zu goes back in time", l);
		if (line->is_tick) {
			int k = (int)nticks++;
			ck_assert_msg(line->t_ns == r->attach_ns + (k + 1) * 200000000LL, "tick %d at %lld", k,
			              (long long)line->t_ns);
			ck_assert_int_eq(line->nboards, 2);
			ck_assert_msg(line->in[0].digital == (uint8_t)k && line->in[0].analog[0] == 0 &&
			                  line->in[0].analog[1] == k * 100 && line->in[0].encoder == INT32_MAX - k &&
			                  line->in[0].applied.digital == 0x7f && line->in[0].applied.pwm == 1000,
			              "tick %d: board 0's inputs changed", k);
			ck_assert_msg(line->in[1].digital == 0xff && line->in[1].analog[0] == 4095 &&
			                  line->in[1].encoder == INT32_MIN && line->in[1].applied.pwm == -1000,
			              "tick %d: board 1's inputs changed", k);
			ck_assert_msg(line->out[0].digital == 0x40 && line->out[0].pwm == k * 100 &&
			                  line->out[1].digital == 0x20 && line->out[1].pwm == -k,
			              "tick %d: the outputs changed", k);
			continue;
		}
		ck_assert_msg(ev->t_ns == line->t_ns, "event line %zu: its time is not the line's", l);
		switch (ev->kind) {
		case VMAC_REC_ATTACH: ck_assert_str_eq(ev->name, "1.2.0"); break;
		case VMAC_REC_PARAM:
			snprintf(what, sizeof(what), "param_%zu", nparams);
			ck_assert_str_eq(ev->name, what);
			assert_value(&ev->value, &want[nparams], what);
			nparams++;
			break;
		case VMAC_REC_INPUT:
			snprintf(what, sizeof(what), "input_%zu", ninputs);
			ck_assert_str_eq(ev->name, what);
			assert_value(&ev->value, &want[ninputs], what);
			ck_assert_msg(ev->code == (int)(ninputs % 3) - 1, "%s: code %d", what, ev->code);
			ck_assert_msg(line->t_ns == r->attach_ns + (int64_t)(ninputs + 1) * 200000000LL + 50000000,
			              "%s at %lld ns", what, (long long)line->t_ns);
			ninputs++;
			break;
		case VMAC_REC_LEVEL: ck_assert_int_eq(ev->code, 3); break;
		case VMAC_REC_SWAP: ck_assert_str_eq(ev->name, "1.3.0"); break;
		case VMAC_REC_MISS:
			ck_assert_msg(ev->board == 1 && ev->code == 65535 && ev->a_ns == 20232658855049LL &&
			                  ev->b_ns == 20232758855049LL,
			              "the miss: board %u seq %d sent %lld received %lld", ev->board, ev->code,
			              (long long)ev->a_ns, (long long)ev->b_ns);
			ck_assert_str_eq(ev->text, "no reply to UPDATE seq 65535 within 80 ms");
			break;
		case VMAC_REC_ERROR:
			ck_assert_str_eq(ev->text, "washer.lua:12: boom\nstack traceback:\n\t[C]: in ?");
			break;
		case VMAC_REC_DROP: ck_assert_str_eq(ev->text, "its driver failed"); break;
		default: ck_abort_msg("line %zu: an event of kind %d", l, ev->kind);
		}
	}
	ck_assert_msg(nparams == (size_t)nvalues && ninputs == (size_t)nvalues,
	              "%zu params and %zu inputs, not %d each", nparams, ninputs, nvalues);
	ck_assert_msg(rec.lines[rec.nlines - 1].ev.kind == VMAC_REC_DROP, "the drop is not the last line");
	ck_assert_msg(rec.lines[0].ev.kind == VMAC_REC_ATTACH, "the attach is not the first line");
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);
}
END_TEST

/* A small recording's text, with the driver's source (malloc'd). */
static char *small_recording(size_t *len)
{
	struct vmac_recorder *r = recorded(3);
	char *text;
	snprintf(vmac_rec_event(r, 4 * PERIOD_NS, VMAC_REC_DROP)->text, VMAC_REC_TEXT_MAX + 1, "no reply");
	text = vmac_recording_write(r, SOURCE, strlen(SOURCE), NULL, 0, 1795000000.0, len);
	ck_assert_ptr_nonnull(text);
	vmac_recorder_free(r);
	return text;
}

START_TEST(every_truncation_is_refused_as_truncated)
{
	struct vmac_recording rec;
	char err[256];
	size_t len, cut;
	char *text = small_recording(&len), *copy = malloc(len);

	ck_assert_ptr_nonnull(copy);
	for (cut = 0; cut < len; cut++) {
		memcpy(copy, text, cut); /* a copy of its own: the reader must not look past cut */
		err[0] = 0;
		ck_assert_msg(vmac_recording_read(copy, cut, &rec, err, sizeof(err)) == -1,
		              "the first %zu of %zu bytes read as a recording", cut, len);
		ck_assert_msg(rec.lines == NULL && rec.source == NULL, "a refused recording left memory behind");
		if (cut == 0)
			ck_assert_str_eq(err, "not a vmac recording (empty)");
		else
			ck_assert_msg(strncmp(err, "recording truncated", 19) == 0,
			              "the first %zu of %zu bytes: \"%s\", not \"recording truncated...\"", cut, len,
			              err);
	}
	free(copy);
	free(text);
}
END_TEST

START_TEST(every_flipped_byte_is_refused)
{
	struct vmac_recording rec;
	char err[256];
	size_t len, i;
	char *text = small_recording(&len);
	const char *digit = strstr(text, "\"in\":[") + 6;
	int bit;

	/* A digit of a tick's inputs: still a recording in form, its hash says no. */
	text[digit - text] ^= 0x01;
	ck_assert_msg(vmac_recording_read(text, len, &rec, err, sizeof(err)) == -1, "a changed input was taken");
	ck_assert_str_eq(err, "recording damaged: its hash does not match its contents");
	text[digit - text] ^= 0x01;
	ck_assert_msg(vmac_recording_read(text, len, &rec, err, sizeof(err)) == 0, "the intact recording: %s", err);
	vmac_recording_free(&rec);
	/* Any bit of any byte. */
	for (i = 0; i < len; i++)
		for (bit = 0; bit < 8; bit++) {
			text[i] ^= (char)(1 << bit);
			ck_assert_msg(vmac_recording_read(text, len, &rec, err, sizeof(err)) == -1,
			              "bit %d of byte %zu (of %zu) flipped was taken", bit, i, len);
			ck_assert_msg(strncmp(err, "recording ", 10) == 0 ||
			                  strncmp(err, "not a vmac recording", 20) == 0,
			              "byte %zu flipped: a message that says nothing of the file: %s", i, err);
			text[i] ^= (char)(1 << bit);
		}
	free(text);
}
END_TEST

START_TEST(a_file_that_is_no_recording_or_of_another_format_is_refused)
{
	static const char *const others[] = {
	    "-- a driver\nreturn {}\n",
	    "{\"format\":\"vmac-checkpoint\",\"version\":1}\n",
	    "not even a line",
	    "[1,2,3]\n",
	};
	struct vmac_recording rec;
	char err[256], *text, *v;
	size_t len, i;

	for (i = 0; i < sizeof(others) / sizeof(others[0]); i++) {
		ck_assert_msg(vmac_recording_read(others[i], strlen(others[i]), &rec, err, sizeof(err)) == -1,
		              "\"%s\" read as a recording", others[i]);
		ck_assert_msg(strncmp(err, "not a vmac recording", 20) == 0, "\"%s\": %s", others[i], err);
	}
	text = small_recording(&len);
	v = strstr(text, "\"version\":1");
	ck_assert_ptr_nonnull(v);
	v[10] = '2';
	ck_assert_msg(vmac_recording_read(text, len, &rec, err, sizeof(err)) == -1, "a format 2 file was read");
	ck_assert_str_eq(err, "recording in format 2, this vmac reads 1");
	free(text);
}
END_TEST

START_TEST(a_recording_without_the_source_reads_without_one)
{
	struct vmac_recorder *r = recorded(5);
	struct vmac_recording rec;
	size_t len;
	char *text = round_trip(r, NULL, &rec, &len);
	ck_assert_msg(strstr(text, "\"source\"") == NULL, "a recording without a source has a source key");
	ck_assert_msg(rec.source == NULL && rec.source_len == 0, "a recording without the source read one back");
	ck_assert_uint_eq(rec.nticks, 5);
	ck_assert_str_eq(rec.machine, "w-1");
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);
}
END_TEST

/* A recording names a machine and a driver, never a path: vmac test
 * --replay looks the driver up by its name. Each writes fine and is
 * refused when read. */
START_TEST(a_machine_or_driver_that_is_no_name_is_refused)
{
	static const char *const bad[] = {"..", ".", "../../etc/x", "a/b", ".hidden", "two words"};
	struct vmac_recording rec;
	char err[256];
	size_t i, len;
	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		int as_driver;
		for (as_driver = 0; as_driver < 2; as_driver++) {
			struct vmac_recorder *r = recorded(3);
			char *text;
			snprintf(as_driver ? r->driver : r->machine, sizeof(r->driver), "%s", bad[i]);
			text = vmac_recording_write(r, SOURCE, strlen(SOURCE), NULL, 0, 1795000000.0, &len);
			ck_assert_ptr_nonnull(text);
			err[0] = 0;
			ck_assert_msg(vmac_recording_read(text, len, &rec, err, sizeof(err)) == -1,
			              "a recording whose %s is '%s' was read", as_driver ? "driver" : "machine",
			              bad[i]);
			ck_assert_msg(strstr(err, "not a name") != NULL, "the refusal does not say why: %s", err);
			free(text);
			vmac_recorder_free(r);
		}
	}
}
END_TEST

/* The latch instants a tick record keeps in its 32 bits (recorder.h,
 * vmac_rec_at_encode): to the nanosecond within 2^30 ns of the tick, to
 * the microsecond beyond, none past 2^30 us; 0 (the tick's own time) and
 * none are left out of the file. */
static const struct {
	int64_t d;    /* at - t, ns */
	int64_t want; /* what reads back, at - t, ns */
	int in_file;  /* the file has "at" */
} latch_cases[] = {
    {0, 0, 0},
    {-1, -1, 1},
    {-137003, -137003, 1},                                     /* a reply 137 us before the tick */
    {-200000000, -200000000, 1},                               /* a period of 200 ms before */
    {1, 1, 1},                                                 /* a latch a clock's error after the tick */
    {-(((int64_t)1 << 30) - 1), -(((int64_t)1 << 30) - 1), 1}, /* the last to the ns */
    {((int64_t)1 << 30) - 1, ((int64_t)1 << 30) - 1, 1},
    {-((int64_t)1 << 30), -1073742000, 1}, /* the first to the us (1073741.824 us) */
    {-4000000400LL, -4000000000LL, 1},     /* a 4 s period: to the us */
    {1500000600LL, 1500001000LL, 1},
    {-1073741823000LL, -1073741823000LL, 1}, /* the last the us reach */
    {-1073741824000LL, 0, 0},                /* beyond 17.9 minutes: none */
    {INT64_MIN / 2, 0, 0},
};
#define NLATCH (sizeof(latch_cases) / sizeof(latch_cases[0]))

START_TEST(each_boards_latch_instant_reads_back_as_recorded)
{
	struct vmac_recorder *r = recorded(0);
	struct vmac_recording rec;
	size_t len, l, k = 0;
	char *text;
	uint32_t i;

	r->nboards = 2;
	snprintf(r->boards[1].name, sizeof(r->boards[1].name), "w-2");
	for (i = 0; i < NLATCH; i++) {
		struct vmac_inputs in = inputs_of(i);
		struct vmac_outputs out = outputs_of(i);
		int64_t t = 3600 * NS_PER_S + (int64_t)(i + 1) * PERIOD_NS + 123456789; /* an hour in, odd ns */
		vmac_rec_tick(r, t, 0, 0, &in, &out, t + latch_cases[i].d);
		vmac_rec_tick(r, t, 1, 1, &in, &out, t - 5000); /* board 1 replied 5 us before the tick */
	}
	for (i = 0; i < NLATCH; i++) {
		const struct vmac_rec_tick *t = vmac_rec_tick_at(r, 2 * i);
		ck_assert_msg(vmac_rec_at_ns(t) - t->t_ns == latch_cases[i].want,
		              "a latch %lld ns from its tick is kept as %lld ns, not %lld", (long long)latch_cases[i].d,
		              (long long)(vmac_rec_at_ns(t) - t->t_ns), (long long)latch_cases[i].want);
		ck_assert_msg(t->board == 0 && !t->last && vmac_rec_tick_out(t).pwm == outputs_of(i).pwm &&
		                  vmac_rec_tick_out(t).digital == outputs_of(i).digital &&
		                  t->in.encoder == inputs_of(i).encoder,
		              "tick %u: the record's board, last, inputs or outputs changed beside its latch", i);
		t = vmac_rec_tick_at(r, 2 * i + 1);
		ck_assert_msg(t->board == 1 && t->last && vmac_rec_at_ns(t) == t->t_ns - 5000,
		              "tick %u: board 1's record is not the last, at 5 us before", i);
	}
	text = round_trip(r, NULL, &rec, &len);
	ck_assert_uint_eq(rec.nticks, NLATCH);
	for (l = 0; l < rec.nlines; l++) {
		const struct vmac_recording_line *line = &rec.lines[l];
		if (!line->is_tick)
			continue;
		ck_assert_msg(line->nboards == 2 && (line->has_at & 2) && line->at_ns[1] == line->t_ns - 5000,
		              "tick line %zu: board 1's at is not 5 us before its tick", k);
		ck_assert_msg(!!(line->has_at & 1) == latch_cases[k].in_file,
		              "tick line %zu (a latch %lld ns from the tick): its at is %s the file", k,
		              (long long)latch_cases[k].d, latch_cases[k].in_file ? "not in" : "in");
		ck_assert_msg(!(line->has_at & 1) || line->at_ns[0] - line->t_ns == latch_cases[k].want,
		              "tick line %zu: at reads back %lld ns from the tick, not %lld", k,
		              (long long)(line->at_ns[0] - line->t_ns), (long long)latch_cases[k].want);
		ck_assert_msg(line->out[0].pwm == outputs_of((uint32_t)k).pwm &&
		                  line->in[1].encoder == inputs_of((uint32_t)k).encoder,
		              "tick line %zu: the inputs or outputs beside at changed", k);
		k++;
	}
	ck_assert_msg(strstr(text, "\"at\":3600223456789") == NULL && strstr(text, "\"at\":3600223451789") != NULL,
	              "the first tick's board 0 (at its tick's time) has an at, or board 1's is not 5 us before");
	vmac_recording_free(&rec);
	free(text);
	vmac_recorder_free(r);
}
END_TEST

/* body (the header and record lines) with its end line: the count and the
 * hash a writer gives. malloc'd. */
static char *with_end(const char *body, int lines)
{
	unsigned char hash[crypto_generichash_BYTES];
	char hex[2 * crypto_generichash_BYTES + 1];
	size_t n = strlen(body) + 256;
	char *text = malloc(n);
	ck_assert_ptr_nonnull(text);
	crypto_generichash(hash, sizeof(hash), (const unsigned char *)body, strlen(body), NULL, 0);
	sodium_bin2hex(hex, sizeof(hex), hash, sizeof(hash));
	snprintf(text, n, "%s{\"end\":{\"lines\":%d,\"blake2b\":\"%s\"}}\n", body, lines, hex);
	return text;
}

#define LATCH_HEADER                                                                                                   \
	"{\"format\":\"vmac-recording\",\"version\":1,\"machine\":\"p-1\",\"driver\":\"press\",\"attach_t\":0,"        \
	"\"complete\":true,\"boards\":[{\"name\":\"p-1\",\"minor\":0},{\"name\":\"p-2\",\"minor\":1}],"                \
	"\"later\":{\"x\":1}}\n"
#define LATCH_IN "\"in\":[1,2,3,4,5,6],\"out\":[0,0]"

/* Recordings from before latch times (no at) and from a later writer
 * (keys this one does not know, in the header, a line and a board) read;
 * an at that is not an integer is damage. */
START_TEST(a_tick_without_at_or_with_unknown_keys_reads_and_a_bad_at_is_refused)
{
	static const char *const good =
	    LATCH_HEADER "{\"t\":16000000,\"tick\":[{\"b\":0," LATCH_IN "},{\"b\":1," LATCH_IN "}]}\n"
	                 "{\"t\":32000000,\"tick\":[{\"b\":0," LATCH_IN ",\"at\":31999000,\"how\":\"instant\"},"
	                 "{\"b\":1," LATCH_IN ",\"at\":31999001}],\"why\":[1,2]}\n";
	static const char *const bad[] = {"\"at\":\"soon\"", "\"at\":3.5e7", "\"at\":null", "\"at\":[1]"};
	struct vmac_recording rec;
	char err[256] = "", body[1024], *text = with_end(good, 2);
	size_t i;

	ck_assert_msg(vmac_recording_read(text, strlen(text), &rec, err, sizeof(err)) == 0,
	              "a recording with unknown keys and ticks without at was refused: %s", err);
	ck_assert_msg(rec.nticks == 2 && rec.lines[0].has_at == 0, "a tick without at read one");
	ck_assert_msg(rec.lines[1].has_at == 3 && rec.lines[1].at_ns[0] == 31999000 &&
	                  rec.lines[1].at_ns[1] == 31999001,
	              "the second tick's at did not read back: %u %lld %lld", rec.lines[1].has_at,
	              (long long)rec.lines[1].at_ns[0], (long long)rec.lines[1].at_ns[1]);
	vmac_recording_free(&rec);
	free(text);
	for (i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		snprintf(body, sizeof(body), LATCH_HEADER "{\"t\":16000000,\"tick\":[{\"b\":0," LATCH_IN ",%s}]}\n",
		         bad[i]);
		text = with_end(body, 1);
		err[0] = 0;
		ck_assert_msg(vmac_recording_read(text, strlen(text), &rec, err, sizeof(err)) == -1,
		              "a tick whose board has %s was read", bad[i]);
		ck_assert_msg(strstr(err, "line 2 is not a tick") != NULL, "the refusal of %s does not say where: %s",
		              bad[i], err);
		free(text);
	}
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("recording");
	TCase *tc = tcase_create("recording");
	tcase_set_timeout(tc, 120);
	tcase_add_test(tc, the_tick_ring_keeps_the_newest_in_order_and_says_it_is_incomplete);
	tcase_add_test(tc, every_count_of_ticks_reads_back_whether_staged_or_in_the_ring);
	tcase_add_test(tc, a_recorder_is_sized_by_seconds_and_bounded);
	tcase_add_test(tc, a_wrapped_recording_carries_the_oldest_state_its_ring_covers);
	tcase_add_test(tc, the_event_ring_keeps_the_newest_128_in_order);
	tcase_add_test(tc, everything_recorded_reads_back_as_it_was);
	tcase_add_test(tc, every_truncation_is_refused_as_truncated);
	tcase_add_test(tc, every_flipped_byte_is_refused);
	tcase_add_test(tc, a_file_that_is_no_recording_or_of_another_format_is_refused);
	tcase_add_test(tc, a_recording_without_the_source_reads_without_one);
	tcase_add_test(tc, a_machine_or_driver_that_is_no_name_is_refused);
	tcase_add_test(tc, each_boards_latch_instant_reads_back_as_recorded);
	tcase_add_test(tc, a_tick_without_at_or_with_unknown_keys_reads_and_a_bad_at_is_refused);
	suite_add_tcase(s, tc);
	return s;
}
