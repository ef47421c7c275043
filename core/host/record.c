/* The flight recorder's bus side (docs/RECORDING.md): what crossed the
 * driver boundary goes into the machine's recorder (core/recorder/), in
 * memory the main thread allocated when it loaded the driver: no
 * allocation, no disk, no waiting. When the machine goes away the recorder
 * goes to the main thread: captured (a drop, a driver failure: it says why)
 * or to be freed (the host stopping). */
#include "bus_internal.h"

#include <stdio.h>
#include <string.h>

static int64_t rec_now(const struct vmac_bus *bus)
{
	return bus_now(bus) - bus->start_ns; /* bus time, as the driver's inputs.time */
}

static void describe(struct vmac_bus *bus, struct machine *m)
{
	struct vmac_recorder *r = m->rec;
	int i;
	snprintf(r->machine, sizeof(r->machine), "%s", bus->dev[m->primary].ann.board);
	snprintf(r->driver, sizeof(r->driver), "%s", m->driver);
	snprintf(r->version, sizeof(r->version), "%s", vmac_driver_version(m->drv));
	r->version_id = vmac_driver_tag(m->drv);
	r->level = m->level;
	r->period_s = (double)(bus->slot_ns << m->level) / 1e9;
	r->nboards = m->nboards < VMAC_REC_BOARDS ? m->nboards : VMAC_REC_BOARDS;
	for (i = 0; i < r->nboards; i++) {
		const struct device *b = &bus->dev[m->board[i]];
		snprintf(r->boards[i].name, sizeof(r->boards[i].name), "%s", b->ann.board);
		r->boards[i].minor = b->ann.minor;
	}
}

/* A board joined m after its recorder was described: named in the
 * recording's header too, at the index its ticks carry it at, or a
 * recording whose ticks grew a board would not read back ("a tick of
 * another machine"). A machine never loses one board alone (its boards
 * are dropped together), so the list only grows. */
void bus_rec_join(struct vmac_bus *bus, struct machine *m)
{
	struct vmac_recorder *r = m->rec;
	const struct device *b;
	if (!r || r->nboards >= VMAC_REC_BOARDS || r->nboards >= m->nboards)
		return;
	b = &bus->dev[m->board[r->nboards]];
	snprintf(r->boards[r->nboards].name, sizeof(r->boards[r->nboards].name), "%s", b->ann.board);
	r->boards[r->nboards].minor = b->ann.minor;
	r->nboards++;
}

void bus_rec_attach(struct vmac_bus *bus, struct machine *m, int64_t t_ns)
{
	struct vmac_rec_event *e;
	int i;
	if (!m->rec)
		return;
	describe(bus, m);
	m->rec->attach_ns = m->attach_ns = t_ns;
	m->rec->from_attach = 1;
	e = vmac_rec_event(m->rec, m->rec->attach_ns, VMAC_REC_ATTACH);
	snprintf(e->name, sizeof(e->name), "%s", m->rec->version);
	for (i = 0; i < m->nparams; i++) { /* as the attach job left them */
		e = vmac_rec_event(m->rec, m->rec->attach_ns, VMAC_REC_PARAM);
		memcpy(e->name, m->params[i].name, sizeof(e->name) - 1);
		e->value = m->params[i].value;
	}
}

/* sample_s: each board's dev.t as the driver got it (bus time, s), kept
 * in ns as its tick's t is (the nearest: a replay's at / 1e9 is that
 * double again). */
void bus_rec_tick(struct vmac_bus *bus, struct machine *m, int64_t t, int n, const struct vmac_inputs *in,
                  const struct vmac_outputs *out, const double *sample_s)
{
	int i;
	(void)bus;
	if (!m->rec)
		return;
	for (i = 0; i < n; i++) {
		double s = sample_s[i] * 1e9;
		vmac_rec_tick(m->rec, t, i, i == n - 1, &in[i], &out[i], (int64_t)(s >= 0 ? s + 0.5 : s - 0.5));
	}
}

void bus_rec_state(struct vmac_bus *bus, struct machine *m, int64_t now, const uint8_t *data, size_t len)
{
	if (m->rec)
		vmac_rec_state(m->rec, now - bus->start_ns, data, len);
}

uint64_t bus_rec_input(struct vmac_bus *bus, struct machine *m, int64_t t_ns, const char *name,
                       const struct vmac_value *v)
{
	struct vmac_rec_event *e;
	(void)bus;
	if (!m->rec)
		return 0;
	e = vmac_rec_event(m->rec, t_ns, VMAC_REC_INPUT);
	snprintf(e->name, sizeof(e->name), "%s", name);
	e->value = *v;
	return m->rec->events_written;
}

void bus_rec_input_rc(struct machine *m, uint64_t n, int rc)
{
	/* Unless input() made so many events that the ring wrapped over it. */
	if (m->rec && n > 0 && m->rec->events_written - n < VMAC_REC_EVENTS)
		m->rec->events[(n - 1) % VMAC_REC_EVENTS].code = rc;
}

void bus_rec_level(struct vmac_bus *bus, struct machine *m, unsigned level)
{
	if (m->rec)
		vmac_rec_event(m->rec, rec_now(bus), VMAC_REC_LEVEL)->code = (int32_t)level;
}

void bus_rec_miss(struct vmac_bus *bus, struct device *d, const char *why)
{
	struct machine *m = d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	struct vmac_rec_event *e;
	int i;
	if (!m || !m->rec)
		return;
	e = vmac_rec_event(m->rec, rec_now(bus), VMAC_REC_MISS);
	for (i = 0; i < m->nboards; i++)
		if (&bus->dev[m->board[i]] == d)
			e->board = (uint8_t)i;
	e->code = d->seq;
	e->a_ns = d->sent_ns;
	e->b_ns = d->last_seen_ns > d->sent_ns ? d->last_seen_ns : 0;
	snprintf(e->text, sizeof(e->text), "%s", why);
}

void bus_rec_failure(struct vmac_bus *bus, struct machine *m, int kind, const char *text)
{
	struct vmac_rec_event *e;
	if (!m->rec)
		return;
	e = vmac_rec_event(m->rec, rec_now(bus), (enum vmac_rec_kind)kind);
	snprintf(e->text, sizeof(e->text), "%s", text);
	if (!m->rec->reason[0]) { /* its first line */
		int n = (int)strcspn(text, "\n");
		snprintf(m->rec->reason, sizeof(m->rec->reason), "%s: %.*s",
		         kind == VMAC_REC_ERROR ? "driver error" : "dropped", n, text);
	}
}

void bus_rec_swap(struct vmac_bus *bus, struct machine *m)
{
	if (!m->rec)
		return;
	describe(bus, m);
	snprintf(vmac_rec_event(m->rec, rec_now(bus), VMAC_REC_SWAP)->name, VMAC_REC_NAME_MAX + 1, "%s",
	         m->rec->version);
	/* The new version's dev.state after its first tick, kept: a recording
	 * of it (one failing on probation) replays from there, as the reload
	 * began it. */
	m->rec->state_wanted = 1;
	m->want_checkpoint = 1;
}

/* Hand m's recorder to the main thread: a RECORDING (captured; replace:
 * the machine runs on and wants a new one) or an UNLOAD (to be freed). A
 * full ring loses it, never blocking. */
static void hand_over(struct vmac_bus *bus, struct machine *m, enum vmac_bus_msg_kind kind, int replace)
{
	struct vmac_bus_msg msg;
	struct vmac_recorder *r = m->rec;
	m->rec = NULL;
	/* An input in flight has its event in r, not in the recorder that
	 * comes next: its outcome is not written into that one's events. */
	bus->jobs[m - bus->mach].rec_n = 0;
	memset(&msg, 0, sizeof(msg));
	msg.kind = kind;
	msg.time_ns = bus_now(bus);
	msg.rec = r;
	msg.replace = replace;
	msg.slot = m->primary;
	msg.generation = bus->dev[m->primary].generation;
	r->when_ns = msg.time_ns;
	snprintf(msg.device, sizeof(msg.device), "%s", r->machine);
	vmac_rec_seal(r);
	if (bus_post(bus, &msg) != 0)
		vmac_recorder_free(r);
}

void bus_rec_release(struct vmac_bus *bus, struct machine *m)
{
	if (m->rec)
		hand_over(bus, m, m->rec->reason[0] && m->rec->attach_ns >= 0 ? VMAC_MSG_RECORDING : VMAC_MSG_UNLOAD,
		          0);
}

int bus_rec_capture(struct vmac_bus *bus, struct machine *m, const char *why)
{
	if (!m->rec)
		return -1;
	snprintf(m->rec->reason, sizeof(m->rec->reason), "%.*s", (int)strcspn(why, "\n"), why);
	hand_over(bus, m, VMAC_MSG_RECORDING, 1);
	return 0;
}

void bus_rec_install(struct vmac_bus *bus, const struct vmac_host_cmd *c)
{
	struct device *d = c->slot < bus->ndev ? &bus->dev[c->slot] : NULL;
	struct machine *m = d && d->generation == c->generation && d->mach >= 0 ? &bus->mach[d->mach] : NULL;
	if (!m || !m->used || !m->attached || m->primary != c->slot || m->rec || bus->stopping) {
		struct vmac_bus_msg u; /* the machine went away meanwhile */
		memset(&u, 0, sizeof(u));
		u.kind = VMAC_MSG_UNLOAD;
		u.rec = c->rec;
		if (bus_post(bus, &u) != 0)
			vmac_recorder_free(c->rec);
		return;
	}
	m->rec = c->rec;
	describe(bus, m);
	m->rec->attach_ns = m->attach_ns;
	m->rec->from_attach = 0;
}
