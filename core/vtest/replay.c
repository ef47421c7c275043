/* Replay of a flight recording (docs/RECORDING.md, "Replay"): the
 * recorded inputs, operator input and timing fed to a driver (the version
 * recorded, or another one) on the virtual clock, tick by tick, through
 * the same driver API the host calls; the first output that differs from
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

int vt_replay(const char *text, size_t len, const struct vmac_config *base, int use_recorded, char *report,
              size_t reportlen)
{
	struct report r = {report, reportlen, 0};
	struct vmac_recording rec;
	struct vmac_config cfg = *base;
	struct vmac_driver *d = NULL;
	char err[VMAC_DRIVER_ERR_MAX], msg[640], key[128], val[96];
	size_t i, first = 0, ticks = 0, inputs = 0;
	int b, rc = 1, attached = 0, resume = 0;

	report[0] = 0;
	if (vmac_recording_read(text, len, &rec, err, sizeof(err)) != 0) {
		say(&r, "replay: %s\n", err);
		return -1;
	}
	/* The params the machine had at attach, as the host's settings. */
	for (i = 0; i < rec.nlines; i++) {
		const struct vmac_rec_event *e = &rec.lines[i].ev;
		if (rec.lines[i].is_tick || e->kind != VMAC_REC_PARAM)
			continue;
		snprintf(key, sizeof(key), "driver.%s.param.%s", rec.driver, e->name);
		value_text(&e->value, val, sizeof(val));
		if (vmac_config_set(&cfg, key, val, err, sizeof(err)) != 0)
			say(&r, "replay: param %s = %s not set: %s\n", e->name, val, err);
	}
	if (use_recorded && rec.source)
		rc = vmac_load_driver_source(&cfg, rec.driver, rec.machine, rec.source, rec.source_len, &d, msg,
		                             sizeof(msg));
	else
		rc = vmac_load_driver(&cfg, rec.driver, rec.machine, &d, msg, sizeof(msg));
	if (rc != 0) {
		say(&r, "replay: %s\n", msg);
		vmac_recording_free(&rec);
		return -1;
	}
	say(&r, "replay of %s (driver %s %s, recorded: %s) against %s %s\n", rec.machine, rec.driver, rec.version,
	    rec.reason, vmac_driver_name(d), use_recorded && rec.source ? "as recorded" : vmac_driver_version(d));
	for (b = 0; b < rec.nboards; b++)
		vmac_driver_add_board(d, rec.boards[b].minor, rec.boards[b].name);
	vmac_driver_set_level_now(d, rec.level);
	/* A recording that starts after attach resumes from the dev.state it
	 * holds (the oldest its ring still covered), as a hot reload would:
	 * what came before is skipped, the levels it set kept. */
	if (!rec.complete && rec.state) {
		for (; first < rec.nlines && rec.lines[first].t_ns <= rec.state_t_ns; first++)
			if (!rec.lines[first].is_tick && rec.lines[first].ev.kind == VMAC_REC_LEVEL)
				vmac_driver_set_level_now(d, (unsigned)rec.lines[first].ev.code);
		resume = first < rec.nlines;
	}
	if (!rec.complete && resume)
		say(&r,
		    "  the recording starts %.3f s after attach: the driver resumes from its dev.state at %.3f s "
		    "(its migrate(dev, state), as at a hot reload); %zu records before it are skipped\n",
		    rec.nlines ? (double)(rec.lines[0].t_ns - rec.attach_ns) / 1e9 : 0.0,
		    (double)(rec.state_t_ns - rec.attach_ns) / 1e9, first);
	else if (!rec.complete)
		say(&r,
		    "  the recording starts %.3f s after attach%s: the driver starts afresh at its first tick, so what "
		    "it did before is not known\n",
		    rec.nlines ? (double)(rec.lines[0].t_ns - rec.attach_ns) / 1e9 : 0.0,
		    rec.state ? "" : " and holds no dev.state to resume from");
	rc = 0;
	for (i = first; i < rec.nlines && rc == 0; i++) {
		const struct vmac_recording_line *l = &rec.lines[i];
		double t = (double)l->t_ns / 1e9;
		if (!attached && (l->is_tick || l->ev.kind == VMAC_REC_ATTACH || l->ev.kind == VMAC_REC_INPUT)) {
			double at = rec.complete ? (double)rec.attach_ns / 1e9 : t;
			attached = 1;
			if (vmac_driver_attach(d, at, err, sizeof(err)) != 0) {
				say(&r, "  attach failed: %s\n", err);
				rc = 1;
				break;
			}
			if (resume) {
				int got = vmac_driver_resume_from(d, rec.state, rec.state_len, at, err, sizeof(err));
				if (got < 0) {
					say(&r, "  resuming from the recorded dev.state failed: %s\n", err);
					rc = 1;
					break;
				}
				if (got == 1)
					say(&r, "  (%s has no migrate(dev, state): it starts afresh instead)\n",
					    vmac_driver_name(d));
			}
		}
		if (!l->is_tick) {
			if (l->ev.kind == VMAC_REC_INPUT) {
				char reply[256];
				int got = vmac_driver_input(d, t, l->ev.name, &l->ev.value, reply, sizeof(reply), err,
				                            sizeof(err));
				inputs++;
				if ((got == 0) != (l->ev.code == 0) || (got < 0) != (l->ev.code < 0)) {
					value_text(&l->ev.value, val, sizeof(val));
					say(&r,
					    "  DIFFERS at %.6f s: operator input %s = %s was %s in the recording, %s "
					    "now%s%s\n",
					    t, l->ev.name, val,
					    l->ev.code == 0  ? "accepted"
					    : l->ev.code < 0 ? "a failure"
					                     : "refused",
					    got == 0  ? "accepted"
					    : got < 0 ? "a failure"
					              : "refused",
					    got < 0 ? ": " : "", got < 0 ? err : "");
					rc = 1;
				}
			} else if (l->ev.kind == VMAC_REC_LEVEL) {
				vmac_driver_set_level_now(d, (unsigned)l->ev.code);
			}
			continue;
		}
		{
			const struct vmac_inputs *in[VMAC_DRIVER_MAX_BOARDS];
			struct vmac_outputs out[VMAC_DRIVER_MAX_BOARDS], *outp[VMAC_DRIVER_MAX_BOARDS];
			const char *failure = NULL;
			int recorded_fail = recorded_failure(&rec, i, &failure), k;
			memset(out, 0, sizeof(out));
			for (b = 0; b < rec.nboards; b++) {
				in[b] = &l->in[b < l->nboards ? b : 0];
				outp[b] = &out[b];
			}
			ticks++;
			if (vmac_driver_tick(d, t, in, outp, err, sizeof(err)) != 0) {
				say(&r, "  FAILS at tick %zu (%.6f s)%s: %s\n", ticks, t,
				    recorded_fail ? ", the same tick as in the recording"
				                  : "; the recording did not fail there",
				    err);
				for (b = 0; b < l->nboards; b++)
					say_board(&r, "inputs of", b, &l->in[b]);
				rc = 1;
				break;
			}
			if (recorded_fail) {
				say(&r, "  at tick %zu (%.6f s) the recorded driver failed (%.*s); this one does not\n",
				    ticks, t, (int)strcspn(failure, "\n"), failure);
				break;
			}
			for (k = 0; k < l->nboards; k++)
				if (out[k].digital != l->out[k].digital || out[k].pwm != l->out[k].pwm) {
					say(&r, "  DIFFERS at tick %zu (%.6f s), board %d:\n", ticks, t, k);
					say_board(&r, "inputs of", k, &l->in[k]);
					say(&r, "    recorded outputs: digital 0x%02x, pwm %d\n",
					    (unsigned)l->out[k].digital, (int)l->out[k].pwm);
					say(&r, "    replayed outputs: digital 0x%02x, pwm %d\n",
					    (unsigned)out[k].digital, (int)out[k].pwm);
					rc = 1;
					break;
				}
		}
	}
	if (rc == 0)
		say(&r, "  %zu ticks and %zu operator inputs replayed: every output as recorded\n", ticks, inputs);
	vmac_driver_free(d);
	vmac_recording_free(&rec);
	return rc;
}
