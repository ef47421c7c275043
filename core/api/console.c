/* See console.h. */
#include "console.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct out {
	char *p;
	size_t len, used;
};

static void put(struct out *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

static void put(struct out *o, const char *fmt, ...)
{
	va_list ap;
	int n;
	if (o->used >= o->len)
		return;
	va_start(ap, fmt);
	n = vsnprintf(o->p + o->used, o->len - o->used, fmt, ap);
	va_end(ap);
	if (n > 0)
		o->used += (size_t)n < o->len - o->used ? (size_t)n : o->len - o->used - 1;
}

static int valid_name(const char *p, size_t n)
{
	size_t i;
	if (n == 0 || n > VMAC_NAME_MAX || !((p[0] >= 'a' && p[0] <= 'z') || (p[0] >= 'A' && p[0] <= 'Z')))
		return 0;
	for (i = 0; i < n; i++)
		if (!((p[i] >= 'a' && p[i] <= 'z') || (p[i] >= 'A' && p[i] <= 'Z') || (p[i] >= '0' && p[i] <= '9') ||
		      p[i] == '_' || p[i] == '-'))
			return 0;
	return 1;
}

/* true/false, a number, or a string (bare or "quoted"): 0, or -1 when a
 * string is over 63 bytes. */
static int parse_value(const char *v, struct vmac_value *out)
{
	char *end;
	size_t n = strlen(v);
	memset(out, 0, sizeof(*out));
	if (strcmp(v, "true") == 0 || strcmp(v, "false") == 0) {
		out->type = VMAC_VALUE_BOOL;
		out->number = v[0] == 't';
		return 0;
	}
	out->number = strtod(v, &end);
	if (n > 0 && *end == 0 && out->number == out->number) {
		out->type = VMAC_VALUE_NUMBER;
		return 0;
	}
	if (n >= 2 && v[0] == '"' && v[n - 1] == '"') {
		v++;
		n -= 2;
	}
	if (n > VMAC_DRIVER_STR_MAX)
		return -1;
	out->type = VMAC_VALUE_STRING;
	memcpy(out->str, v, n);
	out->str[n] = 0;
	return 0;
}

static void put_value(struct out *o, const struct vmac_value *v)
{
	switch (v->type) {
	case VMAC_VALUE_BOOL: put(o, "%s", v->number != 0 ? "true" : "false"); break;
	case VMAC_VALUE_NUMBER: put(o, "%.6g", v->number); break;
	case VMAC_VALUE_STRING: put(o, "%s", v->str); break;
	default: put(o, "-"); break;
	}
}

static int read_value(const struct vmac_console_ops *ops, const char *device, const char *name, struct out *a,
                      struct out *e, const char *what)
{
	const struct vmac_device_status *d = ops->device(ops->ctx, device);
	int i;
	if (!d) {
		put(e, "%s: no running device of that name\n", what);
		return VMAC_CON_DEVICE;
	}
	for (i = 0; i < d->nvars; i++)
		if (strcmp(d->vars[i].name, name) == 0) {
			put(a, "%s:", what);
			put_value(a, &d->vars[i].value);
			return 0;
		}
	for (i = 0; i < d->nparams; i++)
		if (strcmp(d->params[i].name, name) == 0) {
			put(a, "%s:", what);
			put_value(a, &d->params[i].value);
			return 0;
		}
	put(e, "%s: no such published variable or param\n", what);
	return VMAC_CON_NAME;
}

static int write_value(const struct vmac_console_ops *ops, const char *device, const char *name, char op,
                       const char *value, struct out *a, struct out *e, const char *what)
{
	struct vmac_bus_input_request req;
	char msg[VMAC_EVENT_TEXT];
	unsigned status;
	if (!ops->may_operate) {
		put(e, "%s: this needs a token of scope operate\n", what);
		return VMAC_CON_ACCESS;
	}
	memset(&req, 0, sizeof(req));
	snprintf(req.device, sizeof(req.device), "%s", device);
	snprintf(req.name, sizeof(req.name), "%s", name);
	req.persist = op == '>';
	if (op != '!' && parse_value(value, &req.value) != 0) {
		put(e, "%s: a string value is at most %d bytes\n", what, VMAC_DRIVER_STR_MAX);
		return VMAC_CON_SYNTAX;
	}
	status = ops->input(ops->ctx, &req, msg, sizeof(msg));
	if (status == 200) {
		put(a, "%s%c", what, op);
		if (op != '!')
			put_value(a, &req.value);
		return 0;
	}
	put(e, "%s: %s\n", what, msg);
	switch (status) {
	case 404: return VMAC_CON_DEVICE;
	case 409:
		return req.rc == VMAC_REFUSED_NAME          ? VMAC_CON_NAME
		       : req.rc == VMAC_REFUSED_READ_ONLY   ? VMAC_CON_READ_ONLY
		       : req.rc == VMAC_REFUSED_NOT_PERSIST ? VMAC_CON_PERSIST
		                                            : VMAC_CON_REFUSED;
	case 500:
	case 507: return req.persist ? VMAC_CON_PERSIST : VMAC_CON_HOST;
	default: return VMAC_CON_HOST;
	}
}

/* One submessage m (NUL-terminated). Returns 0 or its error code. */
static int submessage(const struct vmac_console_ops *ops, const char *m, struct out *a, struct out *e)
{
	const char *dot = strchr(m, '.'), *op = dot ? strpbrk(dot + 1, "?:>!") : NULL;
	char device[VMAC_NAME_MAX + 1], name[VMAC_NAME_MAX + 1], what[2 * VMAC_NAME_MAX + 2];
	size_t nd, nn, used;
	int rc;
	if (!dot || !op || (nd = (size_t)(dot - m)) >= sizeof(device) ||
	    (nn = (size_t)(op - dot - 1)) >= sizeof(name) || !valid_name(m, nd) || !valid_name(dot + 1, nn) ||
	    ((*op == '?' || *op == '!') && op[1] != 0) || ((*op == ':' || *op == '>') && op[1] == 0)) {
		put(a, "%.*s#%d", (int)strcspn(m, "?:>!"), m, VMAC_CON_SYNTAX);
		put(e, "%s: expected DEVICE.NAME? DEVICE.NAME:VALUE DEVICE.NAME>VALUE or DEVICE.NAME!\n", m);
		return VMAC_CON_SYNTAX;
	}
	memcpy(device, m, nd);
	device[nd] = 0;
	memcpy(name, dot + 1, nn);
	name[nn] = 0;
	snprintf(what, sizeof(what), "%s.%s", device, name);
	used = a->used;
	rc = *op == '?' ? read_value(ops, device, name, a, e, what)
	                : write_value(ops, device, name, *op, op + 1, a, e, what);
	if (rc)
		put(a, "%s#%d", what, rc);
	if (*op != '?' && ops->wrote && used < a->len)
		ops->wrote(ops->ctx, device, a->p + used);
	return rc;
}

int vmac_console_line(const struct vmac_console_ops *ops, const char *line, char *answer, size_t answerlen,
                      char *errors, size_t errorslen)
{
	struct out a = {answer, answerlen, 0}, e = {errors, errorslen, 0};
	char m[512];
	const char *p = line;
	int nerr = 0, first = 1;
	answer[0] = 0;
	errors[0] = 0;
	for (;;) {
		size_t n;
		p += strspn(p, " \t\r\n");
		if (!*p)
			break;
		n = strcspn(p, " \t\r\n");
		snprintf(m, sizeof(m), "%.*s", (int)(n < sizeof(m) ? n : sizeof(m) - 1), p);
		p += n;
		if (!first)
			put(&a, " ");
		first = 0;
		nerr += submessage(ops, m, &a, &e) != 0;
	}
	return nerr;
}
