/* Time-triggered I/O's instants on the 2^n schedule (docs/TIME.md, "The
 * patterns"; seed 002's timed multitasking): the pattern a machine asks for
 * (its manifest's `timing`, the host's driver.NAME.timing.*), resolved
 * against its period and the host's lead, and the host instants
 * (CLOCK_MONOTONIC ns) its boards latch inputs and release outputs at.
 * Portable C11, no OS call, no allocation: the bus thread calls it in the
 * tick, the driver loader to check a manifest. */
#ifndef VMAC_SCHED_TIMING_H
#define VMAC_SCHED_TIMING_H

#include <stddef.h>
#include <stdint.h>

enum vmac_timing_pattern {
	VMAC_TIMING_DEFAULT = 0, /* named by nobody: phase when the host syncs clocks */
	VMAC_TIMING_PHASE,       /* phase-aligned, one period delay: in and out at slot start + lead */
	VMAC_TIMING_OFFSETS,     /* fixed offsets, one period delay: in at input_us, out at output_us */
	VMAC_TIMING_ARRIVAL,     /* no instants: boards act when a frame arrives (no TIMED frames) */
};

/* What a machine asks for. */
struct vmac_timing_want {
	int pattern;        /* enum vmac_timing_pattern */
	uint32_t input_us;  /* VMAC_TIMING_OFFSETS only */
	uint32_t output_us; /* VMAC_TIMING_OFFSETS only */
};

/* What the host runs: the pattern resolved (never DEFAULT), the instants'
 * offsets from the anchor slot's planned start. */
struct vmac_timing {
	int pattern;
	int64_t in_ns, out_ns; /* 0 for arrival */
};

/* "default", "phase", "offsets", "arrival"; parse: the pattern named, or -1. */
const char *vmac_timing_name(int pattern);
int vmac_timing_parse(const char *name);

/* The lead the host runs with: timed_lead_us, or half a slot when 0. */
uint32_t vmac_timing_lead_us(uint32_t timed_lead_us, uint32_t slot_us);

/* want checked against the lead and the period: offsets each at least
 * lead_us and below period_us; input_us and output_us given for offsets
 * only. 0, or -1 with err. */
int vmac_timing_check(const struct vmac_timing_want *want, uint32_t lead_us, uint32_t period_us, char *err,
                      size_t errlen);

/* What a machine wanting want runs at period_us: arrival whenever
 * clock_sync_ms is 0 (no board's clock is fed), phase when it names none.
 * 0, or -1 with err (vmac_timing_check's), out then arrival. */
int vmac_timing_resolve(const struct vmac_timing_want *want, uint32_t clock_sync_ms, uint32_t lead_us,
                        uint32_t period_us, struct vmac_timing *out, char *err, size_t errlen);

/* The instants of a service whose anchor slot starts (as planned) at
 * anchor_ns; both 0 for arrival. */
static inline void vmac_timing_instants(const struct vmac_timing *t, int64_t anchor_ns, uint64_t *out_at,
                                        uint64_t *in_at)
{
	if (t->pattern == VMAC_TIMING_ARRIVAL) {
		*out_at = *in_at = 0;
		return;
	}
	*out_at = (uint64_t)(anchor_ns + t->out_ns);
	*in_at = (uint64_t)(anchor_ns + t->in_ns);
}

#endif
