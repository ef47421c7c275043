/* The boards' clocks as Prometheus series (prom_clock.h; docs/API.md,
 * "Metrics"): for every board of the status whose clock is known (it has
 * sent a TIMED reply), labelled machine, board and driver as a board's
 * other series are (api_metrics.c):
 *
 *   vmac_board_clock_state{state}    gauge: 1 for its state, 0 for the
 *                                    four others (an enum as labels)
 *   vmac_board_clock_bound_seconds   gauge: its estimated error bound
 *                                    (no sample while it says unknown)
 *   vmac_board_clock_offset_seconds  gauge: its counter less host time
 *   vmac_board_services_total{timing} counter: TIMED replies acted at
 *                                    the host's instants ("timed") or on
 *                                    arrival ("arrival") */
#include "prom_clock.h"

#include <stdio.h>

#define BOUND_UNKNOWN 0xFFFFFFFFu

const char *const http_prom_clock_states[] = {"unsynced", "locking", "locked", "holdover", "lost", NULL};

void http_prom_board_clocks(struct http_prom *p, const struct vmac_status *s)
{
	const struct vmac_device_status *d;
	int i, k;
#define EACH_CLOCK                                                                                                     \
	for (i = 0, d = s->devices; i < s->ndevices; i++, d = &s->devices[i])                                          \
		if (d->clock.known)
#define LABELS "machine", d->last_machine, "board", d->name, "driver", d->driver
	http_prom_family(p, "vmac_board_clock_state", "gauge",
	                 "1 for the state of the board's clock (unsynced, locking, locked, holdover, lost), 0 for "
	                 "the others; boards that sent a TIMED reply only");
	EACH_CLOCK
	{
		for (k = 0; http_prom_clock_states[k]; k++)
			http_prom_u64(p, "vmac_board_clock_state", d->clock.state == k ? 1 : 0, LABELS, "state",
			              http_prom_clock_states[k], NULL);
	}
	http_prom_family(p, "vmac_board_clock_bound_seconds", "gauge",
	                 "The estimated error bound of the board's clock, as it last said");
	EACH_CLOCK
	{
		if (d->clock.bound_ns != BOUND_UNKNOWN)
			http_prom_f64(p, "vmac_board_clock_bound_seconds", (double)d->clock.bound_ns / 1e9, LABELS,
			              NULL);
	}
	http_prom_family(p, "vmac_board_clock_offset_seconds", "gauge",
	                 "The board's clock less the host's, as it last said");
	EACH_CLOCK http_prom_f64(p, "vmac_board_clock_offset_seconds", (double)d->clock.offset_ns / 1e9, LABELS, NULL);
	http_prom_family(p, "vmac_board_services_total", "counter",
	                 "TIMED services of the board, by when it acted: at the host's instants (timed) or on "
	                 "arrival, its fallback (arrival)");
	EACH_CLOCK
	{
		http_prom_u64(p, "vmac_board_services_total", d->clock.services_timed, LABELS, "timing", "timed", NULL);
		http_prom_u64(p, "vmac_board_services_total", d->clock.services_arrival, LABELS, "timing", "arrival",
		              NULL);
	}
#undef EACH_CLOCK
#undef LABELS
}
