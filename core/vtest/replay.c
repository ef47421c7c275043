/* Replay of a flight recording (docs/RECORDING.md, "Replay"): the
 * recorded inputs, their instants (dev.t), operator input and timing fed
 * to a driver (the version recorded, or another one) on the virtual clock,
 * tick by tick, through the same driver API the host calls; the first output that differs from
 * the recording, or a failure, is reported with its tick, its inputs and
 * both outputs. No bus, no boards: the recording is the world. */
#include "replay.h"

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../loader/loader.h"
#include "../recorder/recording.h"

struct report {
	char *buf;
	size_t cap, len;
};

static void say(struct report *r, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void say(struct report *r, const char *fmt, ...)
{
	va_list ap;
	int n;
	if (r->len >= r->cap)
		return;
	va_start(ap, fmt);
	n = vsnprintf(r->buf + r->len, r->cap - r->len, fmt, ap);
	va_end(ap);
	if (n > 0)
		r->len = r->len + (size_t)n < r->cap ? r->len + (size_t)n : r->cap - 1;
}

static void say_board(struct report *r, const char *what, int board, const struct vmac_inputs *in)
{
	say(r, "    %s board %d: digital in 0x%02x, analog %u %u, encoder %d (driving 0x%02x, pwm %d)\n", what, board,
	    (unsigned)in->digital, (unsigned)in->analog[0], (unsigned)in->analog[1], (int)in->encoder,
	    (unsigned)in->applied.digital, (int)in->applied.pwm);
}

/* Whether an error event of the recording belongs to the tick at line i
 * (it comes at the tick's time, just before or after it). */
static int recorded_failure(const struct vmac_recording *rec, size_t i, const char **text)
{
	size_t j;
	int64_t t = rec->lines[i].t_ns, next = INT64_MAX;
	for (j = i + 1; j < rec->nlines; j++)
		if (rec->lines[j].is_tick) {
			next = rec->lines[j].t_ns;
			break;
		}
	for (j = i > 0 ? i - 1 : 0; j < rec->nlines && rec->lines[j].t_ns < next; j++)
		if (!rec->lines[j].is_tick && rec->lines[j].ev.kind == VMAC_REC_ERROR && rec->lines[j].t_ns >= t) {
			*text = rec->lines[j].ev.text;
			return 1;
		}
	return 0;
}

static void value_text(const struct vmac_value *v, char *out, size_t len)
{
	if (v->type == VMAC_VALUE_NUMBER)
		snprintf(out, len, "%.17g", v->number);
	else if (v->type == VMAC_VALUE_BOOL)
		snprintf(out, len, "%s", v->number != 0 ? "true" : "false");
	else
		snprintf(out, len, "%s", v->str);
}

/* One replay under way. */
struct replay {
	struct report r;
	struct vmac_recording rec;
	struct vmac_driver *d;
	size_t first;  /* the first line replayed */
	size_t ticks;  /* ticks replayed */
	size_t inputs; /* operator inputs replayed */
	int attached;
	int resume; /* the driver resumes from the recording's dev.state */
	char err[VMAC_DRIVER_ERR_MAX];
};

/* The driver the recording ran (or the current one), with the params the
 * machine had at attach as the host's settings. 0, or -1 said. */
static int load(struct replay *p, const struct vmac_config *base, int use_recorded)
{
	struct vmac_config cfg = *base;
	char msg[640], key[128], val[96];
	size_t i;
	int rc;
	for (i = 0; i < p->rec.nlines; i++) {
		const struct vmac_rec_event *e = &p->rec.lines[i].ev;
		if (p->rec.lines[i].is_tick || e->kind != VMAC_REC_PARAM)
			continue;
		snprintf(key, sizeof(key), "driver.%s.param.%s", p->rec.driver, e->name);
		value_text(&e->value, val, sizeof(val));
		if (vmac_config_set(&cfg, key, val, p->err, sizeof(p->err)) != 0)
			say(&p->r, "replay: param %s = %s not set: %s\n", e->name, val, p->err);
	}
	if (use_recorded && (p->rec.bundle || p->rec.source)) {
		/* The bundle that ran (its programmes with it), else the driver's
		 * source alone: never the programmes on this disk today. */
		struct vmac_bundle *b = NULL;
		rc = vmac_bundle_of_data(&cfg, p->rec.driver, p->rec.bundle ? p->rec.bundle : p->rec.source,
		                         p->rec.bundle ? p->rec.bundle_len : p->rec.source_len, &b, msg, sizeof(msg));
		if (rc == 0)
			rc = vmac_load_driver_bundle(&cfg, b, p->rec.machine, &p->d, msg, sizeof(msg));
		vmac_bundle_free(b);
	} else {
		rc = vmac_load_driver(&cfg, p->rec.driver, p->rec.machine, &p->d, msg, sizeof(msg));
	}
	if (rc != 0) {
		say(&p->r, "replay: %s\n", msg);
		return -1;
	}
	say(&p->r, "replay of %s (driver %s %s, recorded: %s) against %s %s\n", p->rec.machine, p->rec.driver,
	    p->rec.version, p->rec.reason, vmac_driver_name(p->d),
	    use_recorded && p->rec.bundle   ? "its bundle as recorded"
	    : use_recorded && p->rec.source ? "as recorded"
	                                    : vmac_driver_version(p->d));
	return 0;
}

/* Skip the records up to bus time t, keeping the levels they set. */
static void skip_to(struct replay *p, int64_t t)
{
	const struct vmac_recording *rec = &p->rec;
	for (; p->first < rec->nlines && rec->lines[p->first].t_ns <= t; p->first++)
		if (!rec->lines[p->first].is_tick && rec->lines[p->first].ev.kind == VMAC_REC_LEVEL)
			vmac_driver_set_level_now(p->d, (unsigned)rec->lines[p->first].ev.code);
}

/* A recording of a version that took over at a hot reload (one that
 * failed on probation): the ticks before ran the version before it, so
 * the replay starts at the take-over, from the dev.state the recording
 * holds since then (migrate, as the hot reload did), else afresh. */
static void took_over(struct replay *p)
{
	const struct vmac_recording *rec = &p->rec;
	int have = rec->state && rec->state_t_ns >= rec->took_over_ns;
	size_t before;
	skip_to(p, rec->took_over_ns);
	before = p->first;
	if (have)
		skip_to(p, rec->state_t_ns);
	p->resume = have && p->first < rec->nlines;
	say(&p->r,
	    "  %s %s took over at %.3f s after attach (a hot reload; the %zu records before ran the version before "
	    "it): the replay starts there, %s; %zu records skipped\n",
	    rec->driver, rec->version, (double)(rec->took_over_ns - rec->attach_ns) / 1e9, before,
	    p->resume ? "from the dev.state the recording holds (its migrate(dev, state))"
	              : "afresh (the recording holds no dev.state since then)",
	    p->first);
}

/* The machine's boards and level; a recording that starts after attach
 * resumes from the dev.state it holds (the oldest its ring still covered),
 * as a hot reload would: what came before is skipped, the levels it set
 * kept. */
static void prepare(struct replay *p)
{
	const struct vmac_recording *rec = &p->rec;
	double starts = rec->nlines ? (double)(rec->lines[0].t_ns - rec->attach_ns) / 1e9 : 0.0;
	int b;
	for (b = 0; b < rec->nboards; b++)
		vmac_driver_add_board(p->d, rec->boards[b].minor, rec->boards[b].name);
	vmac_driver_set_level_now(p->d, rec->level);
	if (rec->took_over_ns) {
		took_over(p);
		return;
	}
	if (rec->complete)
		return;
	if (rec->state) {
		skip_to(p, rec->state_t_ns);
		p->resume = p->first < rec->nlines;
	}
	if (p->resume)
		say(&p->r,
		    "  the recording starts %.3f s after attach: the driver resumes from its dev.state at %.3f s "
		    "(its migrate(dev, state), as at a hot reload); %zu records before it are skipped\n",
		    starts, (double)(rec->state_t_ns - rec->attach_ns) / 1e9, p->first);
	else
		say(&p->r,
		    "  the recording starts %.3f s after attach%s: the driver starts afresh at its first tick, so what "
		    "it did before is not known\n",
		    starts, rec->state ? "" : " and holds no dev.state to resume from");
}

/* attach (and resume) before the first line that needs a running driver.
 * 0, or 1 said. */
static int attach(struct replay *p, double t)
{
	double at = p->rec.complete && !p->rec.took_over_ns ? (double)p->rec.attach_ns / 1e9 : t;
	int got;
	p->attached = 1;
	if (vmac_driver_attach(p->d, at, p->err, sizeof(p->err)) != 0) {
		say(&p->r, "  attach failed: %s\n", p->err);
		return 1;
	}
	if (!p->resume)
		return 0;
	got = vmac_driver_resume_from(p->d, p->rec.state, p->rec.state_len, at, p->err, sizeof(p->err));
	if (got < 0) {
		say(&p->r, "  resuming from the recorded dev.state failed: %s\n", p->err);
		return 1;
	}
	if (got == 1)
		say(&p->r, "  (%s has no migrate(dev, state): it starts afresh instead)\n", vmac_driver_name(p->d));
	return 0;
}

static const char *outcome(int code)
{
	return code == 0 ? "accepted" : code < 0 ? "a failure" : "refused";
}

/* A recorded event other than a tick: an operator input (its outcome
 * compared) or a level. 0, or 1 when it differs. */
static int replay_event(struct replay *p, const struct vmac_recording_line *l, double t)
{
	char reply[256], val[96];
	int got;
	if (l->ev.kind == VMAC_REC_LEVEL)
		vmac_driver_set_level_now(p->d, (unsigned)l->ev.code);
	if (l->ev.kind != VMAC_REC_INPUT)
		return 0;
	got = vmac_driver_input(p->d, t, l->ev.name, &l->ev.value, reply, sizeof(reply), p->err, sizeof(p->err));
	p->inputs++;
	if ((got == 0) == (l->ev.code == 0) && (got < 0) == (l->ev.code < 0))
		return 0;
	value_text(&l->ev.value, val, sizeof(val));
	say(&p->r, "  DIFFERS at %.6f s: operator input %s = %s was %s in the recording, %s now%s%s\n", t, l->ev.name,
	    val, outcome(l->ev.code), outcome(got), got < 0 ? ": " : "", got < 0 ? p->err : "");
	return 1;
}

/* A recorded tick, its outputs compared. 0 on, 1 differs or fails, 2 the
 * recorded driver failed here and this one did not (the end). */
static int replay_tick(struct replay *p, size_t i, double t)
{
	const struct vmac_recording_line *l = &p->rec.lines[i];
	const struct vmac_inputs *in[VMAC_DRIVER_MAX_BOARDS];
	struct vmac_outputs out[VMAC_DRIVER_MAX_BOARDS], *outp[VMAC_DRIVER_MAX_BOARDS];
	const char *failure = NULL;
	int recorded_fail = recorded_failure(&p->rec, i, &failure), b;
	double at[VMAC_DRIVER_MAX_BOARDS];
	memset(out, 0, sizeof(out));
	for (b = 0; b < p->rec.nboards; b++) {
		in[b] = &l->in[b < l->nboards ? b : 0];
		outp[b] = &out[b];
		/* dev.boards[b].t as recorded; a board without "at" (and every
		 * board of a recording from before latch times) at the tick's time */
		at[b] = b < l->nboards && (l->has_at >> b & 1) ? (double)l->at_ns[b] / 1e9 : t;
	}
	if (l->has_at)
		vmac_driver_sample_times(p->d, at, p->rec.nboards);
	p->ticks++;
	if (vmac_driver_tick(p->d, t, in, outp, p->err, sizeof(p->err)) != 0) {
		say(&p->r, "  FAILS at tick %zu (%.6f s)%s: %s\n", p->ticks, t,
		    recorded_fail ? ", the same tick as in the recording" : "; the recording did not fail there",
		    p->err);
		for (b = 0; b < l->nboards; b++)
			say_board(&p->r, "inputs of", b, &l->in[b]);
		return 1;
	}
	if (recorded_fail) {
		say(&p->r, "  at tick %zu (%.6f s) the recorded driver failed (%.*s); this one does not\n", p->ticks, t,
		    (int)strcspn(failure, "\n"), failure);
		return 2;
	}
	for (b = 0; b < l->nboards; b++)
		if (out[b].digital != l->out[b].digital || out[b].pwm != l->out[b].pwm) {
			say(&p->r, "  DIFFERS at tick %zu (%.6f s), board %d:\n", p->ticks, t, b);
			say_board(&p->r, "inputs of", b, &l->in[b]);
			say(&p->r, "    recorded outputs: digital 0x%02x, pwm %d\n", (unsigned)l->out[b].digital,
			    (int)l->out[b].pwm);
			say(&p->r, "    replayed outputs: digital 0x%02x, pwm %d\n", (unsigned)out[b].digital,
			    (int)out[b].pwm);
			return 1;
		}
	return 0;
}

int vt_replay(const char *text, size_t len, const struct vmac_config *base, int use_recorded, char *report,
              size_t reportlen)
{
	struct replay p;
	size_t i;
	int rc = 0;

	memset(&p, 0, sizeof(p));
	p.r = (struct report){report, reportlen, 0};
	report[0] = 0;
	if (vmac_recording_read(text, len, &p.rec, p.err, sizeof(p.err)) != 0) {
		say(&p.r, "replay: %s\n", p.err);
		return -1;
	}
	if (load(&p, base, use_recorded) != 0) {
		vmac_recording_free(&p.rec);
		return -1;
	}
	prepare(&p);
	for (i = p.first; i < p.rec.nlines && rc == 0; i++) {
		const struct vmac_recording_line *l = &p.rec.lines[i];
		double t = (double)l->t_ns / 1e9;
		if (!p.attached && (l->is_tick || l->ev.kind == VMAC_REC_ATTACH || l->ev.kind == VMAC_REC_INPUT))
			rc = attach(&p, t);
		if (rc == 0)
			rc = l->is_tick ? replay_tick(&p, i, t) : replay_event(&p, l, t);
	}
	if (rc == 0 || rc == 2)
		say(&p.r, "  %zu ticks and %zu operator inputs replayed: every output as recorded\n", p.ticks,
		    p.inputs);
	vmac_driver_free(p.d);
	vmac_recording_free(&p.rec);
	return rc == 2 ? 0 : rc;
}
