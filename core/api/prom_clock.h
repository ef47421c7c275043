/* A board's clock in GET /metrics (docs/API.md, "Metrics"; docs/TIME.md):
 * the series of every board that has sent a TIMED reply (its
 * vmac_board_clock_status known), made from the status copy. Apart from
 * api_metrics.c so that tests/unit/test_prom.c checks it with a status it
 * fills by hand. */
#ifndef VMAC_PROM_CLOCK_H
#define VMAC_PROM_CLOCK_H

#include "../host/bus.h"
#include "prom_text.h"

/* The clock states' names, by vmac_board_clock_status.state (NULL past
 * the last): the label values of vmac_board_clock_state. */
extern const char *const http_prom_clock_states[];

/* vmac_board_clock_state, _bound_seconds, _offset_seconds and
 * vmac_board_services_total of every board of s with a known clock, each
 * family's samples together. */
void http_prom_board_clocks(struct http_prom *p, const struct vmac_status *s);

#endif
