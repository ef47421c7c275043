/* Prometheus's text exposition format (version 0.0.4), written into a
 * growing buffer: the # HELP and # TYPE lines of a metric family, then its
 * samples, label values and help texts escaped as the format says. GET
 * /metrics (api_metrics.c) is its one user; tests/unit/test_prom.c checks
 * the escaping. The names given are the caller's and must be valid metric
 * and label names; only label values and help texts are escaped. Names
 * carry the prefix http_, as in http_internal.h. */
#ifndef VMAC_PROM_TEXT_H
#define VMAC_PROM_TEXT_H

#include <stddef.h>
#include <stdint.h>

#define HTTP_PROM_CONTENT_TYPE "text/plain; version=0.0.4; charset=utf-8"

/* The text so far: text[0..len), NUL-terminated. Once an allocation has
 * failed, failed is set and nothing more is written. */
struct http_prom {
	char *text;
	size_t len, cap;
	int failed;
};

/* An empty text with room for about size_hint bytes (0: a default). */
void http_prom_init(struct http_prom *p, size_t size_hint);
/* The text, now the caller's (free it); NULL when an allocation failed.
 * p is empty again. */
char *http_prom_take(struct http_prom *p, size_t *len);
void http_prom_free(struct http_prom *p);

/* A family's header: "# HELP name help" and "# TYPE name type" (counter,
 * gauge or histogram); its samples follow, before any other family's. */
void http_prom_family(struct http_prom *p, const char *name, const char *type, const char *help);

/* One sample "name{label="value",...} value": after the value, pairs of
 * label name and value, ending with NULL. A pair whose value is "" is
 * left out (Prometheus reads an empty label as no label). */
void http_prom_u64(struct http_prom *p, const char *name, uint64_t value, ...) __attribute__((sentinel));
void http_prom_f64(struct http_prom *p, const char *name, double value, ...) __attribute__((sentinel));

/* A label value as the format wants it in quotes: backslash, double quote
 * and newline escaped (\\, \", \n), into out (room for outlen; cut short,
 * never inside an escape). */
void http_prom_escape(const char *value, char *out, size_t outlen);

#endif
