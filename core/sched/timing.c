/* The seed's patterns of timed multitasking as options of a machine
 * (timing.h): names, the checks, the resolution to instants' offsets. */
#include "timing.h"

#include <stdio.h>
#include <string.h>

static const char *const names[] = {"default", "phase", "offsets", "arrival"};

const char *vmac_timing_name(int pattern)
{
	return pattern >= 0 && pattern <= VMAC_TIMING_ARRIVAL ? names[pattern] : "?";
}

int vmac_timing_parse(const char *name)
{
	int i;
	for (i = VMAC_TIMING_PHASE; i <= VMAC_TIMING_ARRIVAL; i++)
		if (strcmp(name, names[i]) == 0)
			return i;
	return -1;
}

uint32_t vmac_timing_lead_us(uint32_t timed_lead_us, uint32_t slot_us)
{
	return timed_lead_us ? timed_lead_us : slot_us / 2;
}

int vmac_timing_check(const struct vmac_timing_want *want, uint32_t lead_us, uint32_t period_us, char *err,
                      size_t errlen)
{
	const char *bad = NULL;
	uint32_t us = 0;
	if (want->pattern < VMAC_TIMING_DEFAULT || want->pattern > VMAC_TIMING_ARRIVAL) {
		snprintf(err, errlen, "timing: pattern must be phase, offsets or arrival");
		return -1;
	}
	if (want->pattern != VMAC_TIMING_OFFSETS) {
		int named = want->pattern == VMAC_TIMING_DEFAULT ? VMAC_TIMING_PHASE : want->pattern;
		if (want->input_us || want->output_us) {
			snprintf(err, errlen, "timing: input_us and output_us are for pattern offsets, not %s",
			         vmac_timing_name(named));
			return -1;
		}
		return 0;
	}
	if (want->input_us < lead_us || want->input_us >= period_us)
		bad = "input_us", us = want->input_us;
	else if (want->output_us < lead_us || want->output_us >= period_us)
		bad = "output_us", us = want->output_us;
	if (bad) {
		snprintf(err, errlen,
		         "timing: %s = %u must be at least the host's lead (timed_lead_us: %u us) and below the "
		         "period (%u us)",
		         bad, (unsigned)us, (unsigned)lead_us, (unsigned)period_us);
		return -1;
	}
	return 0;
}

int vmac_timing_resolve(const struct vmac_timing_want *want, uint32_t clock_sync_ms, uint32_t lead_us,
                        uint32_t period_us, struct vmac_timing *out, char *err, size_t errlen)
{
	memset(out, 0, sizeof(*out));
	out->pattern = VMAC_TIMING_ARRIVAL;
	if (vmac_timing_check(want, lead_us, period_us, err, errlen) != 0)
		return -1;
	if (clock_sync_ms == 0 || want->pattern == VMAC_TIMING_ARRIVAL)
		return 0;
	if (want->pattern == VMAC_TIMING_OFFSETS) {
		out->pattern = VMAC_TIMING_OFFSETS;
		out->in_ns = (int64_t)want->input_us * 1000;
		out->out_ns = (int64_t)want->output_us * 1000;
		return 0;
	}
	out->pattern = VMAC_TIMING_PHASE;
	out->in_ns = out->out_ns = (int64_t)lead_us * 1000;
	return 0;
}
