/* Prometheus's text exposition format written into a growing buffer: see
 * prom_text.h. */
#include "prom_text.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PROM_DEFAULT_SIZE (64 * 1024)

void http_prom_init(struct http_prom *p, size_t size_hint)
{
	memset(p, 0, sizeof(*p));
	p->cap = size_hint ? size_hint : PROM_DEFAULT_SIZE;
	p->text = malloc(p->cap);
	if (!p->text)
		p->failed = 1;
	else
		p->text[0] = 0;
}

char *http_prom_take(struct http_prom *p, size_t *len)
{
	char *text = p->failed ? NULL : p->text;
	*len = p->failed ? 0 : p->len;
	if (p->failed)
		free(p->text);
	memset(p, 0, sizeof(*p));
	return text;
}

void http_prom_free(struct http_prom *p)
{
	free(p->text);
	memset(p, 0, sizeof(*p));
}

/* Room for n more bytes and a NUL: 0, or -1 (failed). */
static int reserve(struct http_prom *p, size_t n)
{
	size_t want = p->len + n + 1, cap = p->cap ? p->cap : PROM_DEFAULT_SIZE;
	char *grown;
	if (p->failed)
		return -1;
	if (want <= p->cap)
		return 0;
	while (cap < want)
		cap *= 2;
	grown = realloc(p->text, cap);
	if (!grown) {
		p->failed = 1;
		return -1;
	}
	p->text = grown;
	p->cap = cap;
	return 0;
}

static void put(struct http_prom *p, const char *s, size_t n)
{
	if (reserve(p, n) != 0)
		return;
	memcpy(p->text + p->len, s, n);
	p->len += n;
	p->text[p->len] = 0;
}

static void puts_(struct http_prom *p, const char *s)
{
	put(p, s, strlen(s));
}

/* s with backslash and newline escaped, and double quote when quoted (a
 * label value; a help text leaves quotes as they are). */
static void put_escaped(struct http_prom *p, const char *s, int quoted)
{
	const char *run = s;
	for (; *s; s++) {
		const char *esc = *s == '\\' ? "\\\\" : *s == '\n' ? "\\n" : quoted && *s == '"' ? "\\\"" : NULL;
		if (!esc)
			continue;
		put(p, run, (size_t)(s - run));
		puts_(p, esc);
		run = s + 1;
	}
	put(p, run, (size_t)(s - run));
}

void http_prom_escape(const char *value, char *out, size_t outlen)
{
	size_t n = 0;
	if (!outlen)
		return;
	for (; *value; value++) {
		const char *esc = *value == '\\' ? "\\\\" : *value == '\n' ? "\\n" : *value == '"' ? "\\\"" : NULL;
		size_t k = esc ? 2 : 1;
		if (n + k >= outlen)
			break;
		if (esc)
			memcpy(out + n, esc, 2);
		else
			out[n] = *value;
		n += k;
	}
	out[n] = 0;
}

void http_prom_family(struct http_prom *p, const char *name, const char *type, const char *help)
{
	puts_(p, "# HELP ");
	puts_(p, name);
	puts_(p, " ");
	put_escaped(p, help, 0);
	puts_(p, "\n# TYPE ");
	puts_(p, name);
	puts_(p, " ");
	puts_(p, type);
	puts_(p, "\n");
}

/* name{labels} and a space; labels as http_prom_u64 takes them. */
static void put_name(struct http_prom *p, const char *name, va_list ap)
{
	const char *label;
	int n = 0;
	puts_(p, name);
	while ((label = va_arg(ap, const char *)) != NULL) {
		const char *value = va_arg(ap, const char *);
		if (!value || !value[0])
			continue;
		puts_(p, n++ ? "," : "{");
		puts_(p, label);
		puts_(p, "=\"");
		put_escaped(p, value, 1);
		puts_(p, "\"");
	}
	puts_(p, n ? "} " : " ");
}

void http_prom_u64(struct http_prom *p, const char *name, uint64_t value, ...)
{
	char num[24];
	va_list ap;
	va_start(ap, value);
	put_name(p, name, ap);
	va_end(ap);
	snprintf(num, sizeof(num), "%llu\n", (unsigned long long)value);
	puts_(p, num);
}

void http_prom_f64(struct http_prom *p, const char *name, double value, ...)
{
	char num[40];
	va_list ap;
	va_start(ap, value);
	put_name(p, name, ap);
	va_end(ap);
	if (isnan(value))
		snprintf(num, sizeof(num), "NaN\n");
	else if (isinf(value))
		snprintf(num, sizeof(num), "%cInf\n", value > 0 ? '+' : '-');
	else
		snprintf(num, sizeof(num), "%.15g\n", value);
	puts_(p, num);
}
