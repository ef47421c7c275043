/* The audit trail of the HTTP API (docs/API.md, "Audit trail"). Once per
 * request, after its answer is queued, the dispatcher (http.c) hands it
 * here: a request that changes something (its route has an AUDIT type, as
 * every POST does; a POST to no endpoint is a "request") or whose token
 * was refused on any route becomes one audit event, in the format and
 * through the rate limit on refusals of core/host/audit.h:
 *
 *   input by token 0123456789abcdef "alice" (operate) from 127.0.0.1:
 *       POST /api/devices/washer-1/input washer-1.door:true -> 200
 *
 * WHO is the token the guard saw (guard.c fills k->audit), WHERE the
 * client's address, WHAT the method, the path, its query and what the
 * handler added (http_audit_detail), RESULT the status queued, WHY the
 * error's message or the lock-out the request caused. It never blocks and
 * never fails a request: the event goes to the in-memory log, which the
 * main thread copies into the store. */
#include "http_internal.h"

#include <arpa/inet.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>

#include "../host/audit.h"

#define PATH_SHOWN 160  /* of a path, at most this much is said */
#define QUERY_SHOWN 160 /* ... and of its query */

void http_client_address(struct MHD_Connection *c, char *out, size_t len)
{
	const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
	const struct sockaddr *sa = ci ? ci->client_addr : NULL;
	snprintf(out, len, "?");
	if (sa && sa->sa_family == AF_INET)
		inet_ntop(AF_INET, &((const struct sockaddr_in *)sa)->sin_addr, out, (socklen_t)len);
	else if (sa && sa->sa_family == AF_INET6)
		inet_ntop(AF_INET6, &((const struct sockaddr_in6 *)sa)->sin6_addr, out, (socklen_t)len);
}

void http_audit_detail(const struct conn *k, const char *fmt, ...)
{
	struct http_audit_note *n = k->audit;
	size_t used = strlen(n->detail);
	va_list ap;
	if (used + 2 >= sizeof(n->detail))
		return;
	if (used)
		n->detail[used++] = ' ';
	va_start(ap, fmt);
	vsnprintf(n->detail + used, sizeof(n->detail) - used, fmt, ap);
	va_end(ap);
}

void http_audit_device(const struct conn *k, const char *device)
{
	snprintf(k->audit->device, sizeof(k->audit->device), "%s", device);
}

void http_audit_type(const struct conn *k, const char *type)
{
	k->audit->type = type;
}

void http_audit_nothing(const struct conn *k)
{
	k->audit->nothing = 1;
}

/* s appended to out (used of len bytes taken) with every byte that is
 * not printable ASCII, a blank or '%' as %XX, at most max bytes of s. */
static size_t append_escaped(char *out, size_t len, size_t used, const char *s, size_t max)
{
	size_t i;
	for (i = 0; s[i] && i < max && used + 4 < len; i++) {
		unsigned char ch = (unsigned char)s[i];
		if (ch <= 0x20 || ch >= 0x7f || ch == '%' || ch == '"')
			used += (size_t)snprintf(out + used, len - used, "%%%02X", ch);
		else
			out[used++] = (char)ch;
	}
	if (s[i] && used + 4 < len)
		used += (size_t)snprintf(out + used, len - used, "...");
	out[used] = 0;
	return used;
}

struct query {
	char *out;
	size_t len, used;
	int n;
};

static enum MHD_Result query_arg(void *cls, enum MHD_ValueKind kind, const char *key, const char *value)
{
	struct query *q = cls;
	(void)kind;
	if (q->used + 8 >= q->len)
		return MHD_NO;
	q->out[q->used++] = q->n++ ? '&' : '?';
	q->used = append_escaped(q->out, q->len, q->used, key, 40);
	if (value && q->used + 4 < q->len) {
		q->out[q->used++] = '=';
		q->used = append_escaped(q->out, q->len, q->used, value, 60);
	}
	return MHD_YES;
}

/* WHAT: the method, the path with its query, and the handler's detail. */
static void what_of(struct MHD_Connection *c, const struct conn *k, const char *method, const char *url, char *out,
                    size_t len)
{
	char query[QUERY_SHOWN + 8] = "";
	struct query q = {query, sizeof(query), 0, 0};
	size_t used = (size_t)snprintf(out, len, "%s ", method);
	MHD_get_connection_values(c, MHD_GET_ARGUMENT_KIND, query_arg, &q);
	used = append_escaped(out, len, used < len ? used : len - 1, url, PATH_SHOWN);
	snprintf(out + used, len - used, "%s%s%s", query, k->audit->detail[0] ? " " : "", k->audit->detail);
}

/* WHO: the token the request came with. */
static void who_of(const struct http_audit_note *n, char *out, size_t len)
{
	switch (n->token) {
	case HTTP_TOKEN_VALID:
		if (n->token_name[0])
			snprintf(out, len, "token %s \"%s\" (%s)", n->token_id, n->token_name,
			         vmac_scope_name(n->token_scope));
		else
			snprintf(out, len, "token %s (%s)", n->token_id, vmac_scope_name(n->token_scope));
		break;
	case HTTP_TOKEN_INVALID: snprintf(out, len, "token %s (not valid)", n->token_id); break;
	case HTTP_TOKEN_MALFORMED: snprintf(out, len, "a malformed token"); break;
	default: snprintf(out, len, "no token"); break;
	}
}

void http_audit_request(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k, const char *method,
                        const char *url)
{
	const struct http_audit_note *n = k->audit;
	const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_HTTP_STATUS);
	unsigned status = ci ? ci->http_status : 0;
	char who[160], where[INET6_ADDRSTRLEN], what[VMAC_EVENT_TEXT], result[16];
	struct vmac_audit a;
	memset(&a, 0, sizeof(a));
	a.type = n->type ? n->type : strcmp(method, "POST") == 0 ? "request" : n->refused ? "auth" : NULL;
	if (!a.type || (n->nothing && !n->refused))
		return; /* a read, or a console that only read */
	who_of(n, who, sizeof(who));
	http_client_address(c, where, sizeof(where));
	what_of(c, k, method, url, what, sizeof(what));
	if (status)
		snprintf(result, sizeof(result), "%u", status);
	else
		snprintf(result, sizeof(result), "closed"); /* no answer could be queued */
	a.who = who;
	a.where = where;
	a.what = what;
	a.result = result;
	a.device = n->device[0] ? n->device : k->route.name;
	if (status == 0 || status >= 400) { /* a refusal: rate-limited, and why */
		a.key = n->key[0] ? n->key : "unknown";
		a.lockout = n->lockout[0] != 0;
		a.why = n->lockout[0] ? n->lockout : http_last_error();
	}
	vmac_audit_add(h->log, &a);
}
