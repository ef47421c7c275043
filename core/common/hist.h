/* Latency histogram with fixed buckets (no allocation): 1 us wide up to
 * 1 ms, 100 us wide up to 100 ms, then one overflow bucket. */
#ifndef VMAC_HIST_H
#define VMAC_HIST_H

#include <stdint.h>

#define VMAC_HIST_FINE 1000  /* 0..999 us, 1 us buckets */
#define VMAC_HIST_COARSE 990 /* 1000..99999 us, 100 us buckets */
#define VMAC_HIST_BUCKETS (VMAC_HIST_FINE + VMAC_HIST_COARSE + 1)

struct vmac_hist {
	uint64_t count;
	uint64_t sum_us; /* of every sample, in whole us as counted (GET /metrics: the histogram's _sum) */
	int64_t max_us;
	uint64_t bucket[VMAC_HIST_BUCKETS];
};

void vmac_hist_add(struct vmac_hist *h, int64_t value_us);
/* The value below which a fraction q (0..1) of samples lie, in us (bucket
 * upper bound; the max for the overflow bucket). 0 when empty. */
int64_t vmac_hist_quantile(const struct vmac_hist *h, double q);
/* Samples below le_us, exactly, when le_us is a bucket bound (1..1000, or
 * 1000 + a multiple of 100 up to 100,000): the cumulative count of a
 * Prometheus bucket. Another le_us counts up to the bound below it. */
uint64_t vmac_hist_below(const struct vmac_hist *h, int64_t le_us);

#endif
