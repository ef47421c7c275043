/* The flight recorder (docs/RECORDING.md): for every machine, two rings of
 * what crossed the driver boundary, allocated once on the main thread when
 * its driver is loaded and written by the bus thread with no allocation:
 * one record per board per tick (the inputs the driver was given, the
 * outputs it returned) and the rarer events (operator input, params at
 * attach, level changes, misses and late replies with their times, driver
 * errors, the drop). On a drop or a driver failure the bus thread hands the
 * whole recorder to the main thread, which writes it out (recording.c) and
 * frees it. */
#ifndef VMAC_RECORDER_H
#define VMAC_RECORDER_H

#include <stddef.h>
#include <stdint.h>

#include "../common/value.h"
#include "../proto/proto.h"

#define VMAC_REC_NAME_MAX 31
#define VMAC_REC_TEXT_MAX 160
#define VMAC_REC_EVENTS 128     /* events kept per machine (the newest) */
#define VMAC_REC_BOARDS 8       /* VMAC_DRIVER_MAX_BOARDS */
#define VMAC_REC_STAGE 16       /* tick records written to the ring at once (512 bytes) */
#define VMAC_REC_STATES 3       /* dev.state snapshots kept (recorder.c, vmac_rec_state) */
#define VMAC_REC_STATE_MAX 4096 /* bytes of one; a larger dev.state is not kept */

enum vmac_rec_kind {
	VMAC_REC_ATTACH = 1, /* the driver attached (name: its version) */
	VMAC_REC_PARAM,      /* a param's value at attach (name, value) */
	VMAC_REC_INPUT,      /* operator input (name, value; code: 0 accepted, > 0 refused, -1 the driver failed) */
	VMAC_REC_LEVEL,      /* the machine's level changed (code: the new level) */
	VMAC_REC_MISS,       /* a board missed its deadline (board; a_ns sent, b_ns received or 0; text) */
	VMAC_REC_ERROR,      /* the driver failed (text) */
	VMAC_REC_DROP,       /* the machine was dropped (text) */
	VMAC_REC_SWAP,       /* a hot reload: another version took over (name: its version) */
};

/* One board's part of one tick, 32 bytes (two to a cache line): the
 * outputs' fields flattened so that the latch instant fits beside them. */
struct vmac_rec_tick {
	int64_t t_ns; /* bus time of the tick (the driver's inputs.time * 1e9) */
	struct vmac_inputs in;
	int32_t at;          /* the inputs' instant (dev.boards[i].t), vmac_rec_at_encode */
	int16_t out_pwm;     /* what the driver returned for the board: */
	uint8_t out_digital; /* its outputs (vmac_rec_tick_out) */
	uint8_t board : 7;
	uint8_t last : 1; /* the last board of its tick */
};

/* The inputs' instant of a tick record, relative to its tick: ns after the
 * tick times 2 (even) while within 2^30 ns (1.07 s) of it, else us times 2
 * plus 1 (odd, within 2^30 us: 17.9 minutes); VMAC_REC_AT_FAR beyond.
 * 0: at the tick's own time (dev.t was inputs.time). */
#define VMAC_REC_AT_FAR INT32_MIN
#define VMAC_REC_AT_NS_MAX ((int64_t)1 << 30)

static inline int32_t vmac_rec_at_encode(int64_t at_ns, int64_t t_ns)
{
	int64_t d = at_ns - t_ns, us;
	if (d > -VMAC_REC_AT_NS_MAX && d < VMAC_REC_AT_NS_MAX)
		return (int32_t)(d * 2);
	us = (d >= 0 ? d + 500 : d - 500) / 1000;
	return us > -VMAC_REC_AT_NS_MAX && us < VMAC_REC_AT_NS_MAX ? (int32_t)(us * 2 + 1) : VMAC_REC_AT_FAR;
}

/* The bus time (ns) a record's `at` says, t_ns for VMAC_REC_AT_FAR. */
static inline int64_t vmac_rec_at_ns(const struct vmac_rec_tick *t)
{
	if (t->at == VMAC_REC_AT_FAR)
		return t->t_ns;
	return t->at & 1 ? t->t_ns + ((int64_t)t->at - 1) / 2 * 1000 : t->t_ns + t->at / 2;
}

static inline struct vmac_outputs vmac_rec_tick_out(const struct vmac_rec_tick *t)
{
	struct vmac_outputs o = {t->out_digital, t->out_pwm};
	return o;
}

struct vmac_rec_event {
	int64_t t_ns;
	uint8_t kind; /* enum vmac_rec_kind */
	uint8_t board;
	int32_t code;
	int64_t a_ns, b_ns; /* MISS: CLOCK_MONOTONIC sent and received (0: no reply) */
	char name[VMAC_REC_NAME_MAX + 1];
	struct vmac_value value;
	char text[VMAC_REC_TEXT_MAX + 1];
};

struct vmac_recorder {
	/* The newest ticks_written % VMAC_REC_STAGE tick records: they go to
	 * the ring VMAC_REC_STAGE at a time (recorder.c, vmac_rec_tick). */
	_Alignas(64) struct vmac_rec_tick stage[VMAC_REC_STAGE];
	struct vmac_rec_tick *ticks; /* 64-byte aligned, ticks_cap a multiple of VMAC_REC_STAGE */
	uint32_t ticks_cap;
	uint64_t ticks_written; /* ever: the ring holds the last min(written, cap) */
	uint32_t ticks_next;    /* the slot the next tick goes to (ticks_written % ticks_cap, kept: no division) */
	struct vmac_rec_event events[VMAC_REC_EVENTS];
	uint64_t events_written;
	int64_t attach_ns;                  /* bus time of attach; -1 before */
	int from_attach;                    /* it has recorded since attach (not put in later, after a capture) */
	char reason[VMAC_REC_TEXT_MAX + 1]; /* why it was captured ("" while recording) */
	/* The machine, as at its last attach or swap (bus thread). */
	char machine[VMAC_REC_NAME_MAX + 1];
	char driver[VMAC_REC_NAME_MAX + 1];
	char version[VMAC_REC_NAME_MAX + 1];
	int64_t version_id; /* the store's id of the version (0: the driver's file) */
	unsigned level;
	double period_s;
	int nboards;
	struct {
		char name[VMAC_REC_NAME_MAX + 1];
		uint32_t minor;
	} boards[VMAC_REC_BOARDS];
	int64_t when_ns; /* CLOCK_MONOTONIC when captured */
	/* dev.state as checkpoints encoded it (core/driver/checkpoint.c), at
	 * most every half of the ring's span, so that a recording whose ring has
	 * wrapped can replay from the oldest one it still covers. */
	struct vmac_rec_state {
		int64_t t_ns;  /* bus time of the machine's tick it followed */
		uint64_t at;   /* ticks_written then: the state is before record `at` */
		uint32_t len;  /* 0: empty */
		uint8_t *data; /* VMAC_REC_STATE_MAX bytes, allocated with the recorder */
	} states[VMAC_REC_STATES];
	uint32_t states_next;
	int state_wanted; /* keep the next state whenever it comes (the first after a hot reload) */
	int64_t span_ns;  /* what the ring holds: ticks_cap x the period */
};

/* Main thread: a recorder holding seconds of ticks at period_s (at least
 * 64 ticks), or NULL (out of memory, or seconds 0: no recording). */
struct vmac_recorder *vmac_recorder_new(double seconds, double period_s);
void vmac_recorder_free(struct vmac_recorder *r);

/* Bus thread, no allocation: board's inputs (sampled at bus time at_ns:
 * dev.boards[board].t; t_ns when they have no instant of their own) and
 * outputs at the tick at t_ns. */
void vmac_rec_tick(struct vmac_recorder *r, int64_t t_ns, int board, int last, const struct vmac_inputs *in,
                   const struct vmac_outputs *out, int64_t at_ns);
/* Bus thread, after a checkpoint of the machine's dev.state (data, len bytes)
 * at bus time t_ns: kept when half the ring's span has passed since the
 * newest kept (or none is), or state_wanted is set, and it fits; no
 * allocation. */
void vmac_rec_state(struct vmac_recorder *r, int64_t t_ns, const uint8_t *data, size_t len);
/* The oldest state kept whose tick is still in the ring (NULL: none). */
const struct vmac_rec_state *vmac_rec_state_base(const struct vmac_recorder *r);

/* Bus thread, before the recorder goes to another thread: every record
 * written so far is visible to it (the ring is written with non-temporal
 * stores, which a lock's release does not order). */
void vmac_rec_seal(struct vmac_recorder *r);
/* An event: fills and returns the next slot (the caller sets the rest). */
struct vmac_rec_event *vmac_rec_event(struct vmac_recorder *r, int64_t t_ns, enum vmac_rec_kind kind);

/* Reading, in order, oldest first: how many ticks (events) are kept, and the i-th. */
uint32_t vmac_rec_nticks(const struct vmac_recorder *r);
const struct vmac_rec_tick *vmac_rec_tick_at(const struct vmac_recorder *r, uint32_t i);
uint32_t vmac_rec_nevents(const struct vmac_recorder *r);
const struct vmac_rec_event *vmac_rec_event_at(const struct vmac_recorder *r, uint32_t i);

#endif
