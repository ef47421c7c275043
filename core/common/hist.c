/* Latency histogram: see hist.h. */
#include "hist.h"

void vmac_hist_add(struct vmac_hist *h, int64_t us)
{
	int i;
	if (us < 0)
		us = 0;
	if (us < VMAC_HIST_FINE)
		i = (int)us;
	else if (us < VMAC_HIST_FINE + 100 * VMAC_HIST_COARSE)
		i = VMAC_HIST_FINE + (int)((us - VMAC_HIST_FINE) / 100);
	else
		i = VMAC_HIST_BUCKETS - 1;
	h->bucket[i]++;
	h->count++;
	h->sum_us += (uint64_t)us;
	if (us > h->max_us)
		h->max_us = us;
}

int64_t vmac_hist_quantile(const struct vmac_hist *h, double q)
{
	uint64_t want, seen = 0;
	int i;
	if (h->count == 0)
		return 0;
	want = (uint64_t)(q * (double)h->count);
	if (want >= h->count)
		want = h->count - 1;
	for (i = 0; i < VMAC_HIST_BUCKETS; i++) {
		seen += h->bucket[i];
		if (seen > want) {
			int64_t v;
			if (i < VMAC_HIST_FINE)
				v = i;
			else if (i < VMAC_HIST_BUCKETS - 1)
				v = VMAC_HIST_FINE + (int64_t)(i - VMAC_HIST_FINE + 1) * 100;
			else
				v = h->max_us;
			return v < h->max_us ? v : h->max_us;
		}
	}
	return h->max_us;
}

uint64_t vmac_hist_below(const struct vmac_hist *h, int64_t le_us)
{
	uint64_t n = 0;
	int i, end; /* the buckets wholly below le_us: [0, end) */
	if (le_us <= VMAC_HIST_FINE)
		end = le_us > 0 ? (int)le_us : 0;
	else if (le_us < VMAC_HIST_FINE + 100 * VMAC_HIST_COARSE)
		end = VMAC_HIST_FINE + (int)((le_us - VMAC_HIST_FINE) / 100);
	else
		end = VMAC_HIST_BUCKETS - 1;
	for (i = 0; i < end; i++)
		n += h->bucket[i];
	return n;
}
