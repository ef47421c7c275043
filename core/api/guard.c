/* What keeps the API the operator's under abuse (docs/API.md, "Abuse"):
 * - failed attempts are counted per token id when the request presents a
 *   token of the right shape, and per client address only when it does
 *   not, so a guesser locks out what it guesses at and never a valid token
 *   (a valid token is checked before any lock-out);
 * - a locked entry is never evicted to make room: when every entry is
 *   locked, a failing request of a new key is refused as if locked;
 * - a connection must deliver a request's headers within
 *   http_header_timeout_s and its body within http_body_timeout_s (a
 *   slow client is cut off by a reaper thread that shuts its socket down;
 *   libmicrohttpd's own timeout is reset by every byte); a request is
 *   timed from its first byte (the kernel's count of bytes received:
 *   libmicrohttpd says nothing before the headers are whole), and a
 *   connection that sent nothing, new or kept alive, is closed after
 *   HTTP_IDLE_TIMEOUT_S without an event: browsers open connections
 *   ahead of their requests (over TLS, with the handshake done: bytes the
 *   server answered are no request's), and they and Prometheus keep
 *   connections between requests;
 * - libmicrohttpd bounds connections per address (http_connections_per_address).
 * Each lock-out is said in the audit trail with the request that caused it
 * (its type "lockout", audit.c), each batch of cut-off connections is an
 * event. */
#include "http_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <linux/tcp.h>
#include <netinet/in.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>

#include "../common/monotime.h"

#define REAP_EVERY_MS 500
#define CUT_SAID_EVERY_S 10.0

/* The key of the request's failures ("token ID" or "address A"), and
 * whether it presented a token of the right shape. */
static int key_of(struct MHD_Connection *c, const char *token, char *key, size_t len)
{
	char id[VMAC_TOKEN_ID_LEN + 1], addr[INET6_ADDRSTRLEN];
	if (token && vmac_token_id(token, id) == 0) {
		snprintf(key, len, "token %s", id);
		return 1;
	}
	http_client_address(c, addr, sizeof(addr));
	snprintf(key, len, "address %s", addr);
	return 0;
}

/* The entry of key (its window renewed when over), or a free or unlocked
 * one for it when create; NULL when none can be had (every entry locked).
 * Under g->lock. */
static struct guard_fail *entry(struct http_guard *g, const char *key, double now, int create)
{
	struct guard_fail *unused = NULL, *oldest = NULL, *spare;
	int i;
	for (i = 0; i < GUARD_FAIL_SLOTS; i++) {
		struct guard_fail *f = &g->fails[i];
		int over = now - f->window_start >= FAIL_WINDOW_S;
		if (f->key[0] && strcmp(f->key, key) == 0) {
			if (over)
				f->fails = 0, f->window_start = now, f->said = 0;
			return f;
		}
		if (!f->key[0] || over) {
			if (!unused)
				unused = f;
		} else if (f->fails < FAIL_LIMIT && (!oldest || f->window_start < oldest->window_start)) {
			oldest = f; /* the oldest unlocked entry: a locked one is never taken */
		}
	}
	spare = unused ? unused : oldest;
	if (!create || !spare)
		return NULL;
	memset(spare, 0, sizeof(*spare));
	snprintf(spare->key, sizeof(spare->key), "%s", key);
	spare->window_start = now;
	return spare;
}

/* One more failure of key: 1 when key was locked out already (answer 429),
 * with *wait_s until it is not; the failure that locks it is answered 401,
 * and what it locked is said in the audit trail with it (lockout: the
 * request's note, empty otherwise). */
static int failed(struct vmac_http *h, const char *key, double now, double *wait_s, char *lockout, size_t len)
{
	struct http_guard *g = &h->guard;
	struct guard_fail *f;
	int locked, say = 0;
	pthread_mutex_lock(&g->lock);
	f = entry(g, key, now, 1);
	if (!f) {
		locked = 1;
		*wait_s = FAIL_WINDOW_S;
		say = !g->full_said;
		g->full_said = 1;
	} else {
		g->full_said = 0;                /* the table has room again: a next time it is full is said again */
		locked = f->fails >= FAIL_LIMIT; /* this one is answered 401 when it is the tenth */
		if (!locked)
			f->fails++;
		*wait_s = FAIL_WINDOW_S - (now - f->window_start);
		if (f->fails >= FAIL_LIMIT && !f->said)
			f->said = say = 2;
	}
	pthread_mutex_unlock(&g->lock);
	if (say == 1)
		snprintf(lockout, len,
		         "every entry of the API's failed-attempt table is locked out: a failing request of anyone new "
		         "is refused (429) until one expires");
	else if (say == 2)
		snprintf(lockout, len, "%u failed attempts with %s in %.0f s: locked out (429) for %.0f s", FAIL_LIMIT,
		         key, FAIL_WINDOW_S, *wait_s + 0.5);
	return locked;
}

/* Whether key is locked out now (*wait_s until it is not). */
static int locked_out(struct vmac_http *h, const char *key, double now, double *wait_s)
{
	struct guard_fail *f;
	int locked;
	pthread_mutex_lock(&h->guard.lock);
	f = entry(&h->guard, key, now, 0);
	locked = f && f->fails >= FAIL_LIMIT;
	*wait_s = f ? FAIL_WINDOW_S - (now - f->window_start) : 0;
	pthread_mutex_unlock(&h->guard.lock);
	return locked;
}

static enum MHD_Result too_many(struct MHD_Connection *c, const char *key, double wait_s)
{
	char msg[200];
	snprintf(msg, sizeof(msg), "too many failed attempts with %s; try again in %.0f s", key, wait_s + 0.5);
	return http_reply(c, MHD_HTTP_TOO_MANY_REQUESTS, http_error_body(msg));
}

/* What the audit trail says of the request's token (k->audit). */
static void note_token(struct http_audit_note *n, const char *auth, const char *token, int shaped, const char *key,
                       const struct vmac_token_info *who, enum vmac_scope have)
{
	snprintf(n->key, sizeof(n->key), "%s", key);
	n->token = !auth     ? HTTP_TOKEN_ABSENT
	           : !shaped ? HTTP_TOKEN_MALFORMED
	           : have    ? HTTP_TOKEN_VALID
	                     : HTTP_TOKEN_INVALID;
	if (shaped)
		vmac_token_id(token, n->token_id);
	if (have) {
		snprintf(n->token_name, sizeof(n->token_name), "%s", who->name);
		n->token_scope = have;
	}
}

enum vmac_scope http_authorized(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k,
                                enum MHD_Result *ret)
{
	const char *auth = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
	const char *token = auth && strncmp(auth, "Bearer ", 7) == 0 ? auth + 7 : NULL;
	struct http_audit_note *n = k->audit;
	struct vmac_token_info who;
	double now = http_mono_s(), wait_s = 0;
	enum vmac_scope have = VMAC_SCOPE_NONE, need = k->route.need;
	char key[80], msg[160];
	int shaped = key_of(c, token, key, sizeof(key));
	memset(&who, 0, sizeof(who));
	/* Without a token of the right shape nothing is looked up once the
	 * address is locked; a token of the right shape is always checked. */
	if (!shaped && locked_out(h, key, now, &wait_s)) {
		note_token(n, auth, token, shaped, key, &who, have);
		n->refused = 1;
		*ret = too_many(c, key, wait_s);
		return VMAC_SCOPE_NONE;
	}
	if (shaped)
		have = vmac_token_check_info(h->store, token, &who);
	note_token(n, auth, token, shaped, key, &who, have);
	if (have == VMAC_SCOPE_NONE) {
		n->refused = 1;
		if (failed(h, key, now, &wait_s, n->lockout, sizeof(n->lockout))) {
			*ret = too_many(c, key, wait_s);
		} else {
			*ret = http_reply_header(
			    c, MHD_HTTP_UNAUTHORIZED,
			    http_error_body(auth
			                        ? "the token is not valid (unknown, revoked or malformed)"
			                        : "a token is needed: Authorization: Bearer TOKEN (vmac token create)"),
			    MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"vmac\"");
		}
		if (n->lockout[0])
			n->type = "lockout";
		return VMAC_SCOPE_NONE;
	}
	if (have < need) {
		n->refused = 1;
		snprintf(msg, sizeof(msg), "this needs a token of scope %s; this one is %s", vmac_scope_name(need),
		         vmac_scope_name(have));
		*ret = http_reply(c, MHD_HTTP_FORBIDDEN, http_error_body(msg));
		return VMAC_SCOPE_NONE;
	}
	return have;
}

/* ---- the deadlines of a request ---- */

/* The bytes the kernel has received and sent on a connection. */
struct tcp_bytes {
	uint64_t received, sent;
};

/* fd's counts, both 0 when the kernel cannot tell. */
static struct tcp_bytes tcp_bytes(int fd)
{
	struct tcp_info ti;
	socklen_t len = sizeof(ti);
	struct tcp_bytes n = {0, 0};
	memset(&ti, 0, sizeof(ti));
	if (getsockopt(fd, IPPROTO_TCP, TCP_INFO, &ti, &len) == 0) {
		n.received = ti.tcpi_bytes_received;
		n.sent = ti.tcpi_bytes_sent;
	}
	return n;
}

void http_guard_notify(void *cls, struct MHD_Connection *c, void **socket_context,
                       enum MHD_ConnectionNotificationCode code)
{
	struct vmac_http *h = cls;
	struct http_guard *g = &h->guard;
	struct guard_conn *slot = *socket_context;
	int i;
	pthread_mutex_lock(&g->lock);
	if (code == MHD_CONNECTION_NOTIFY_STARTED) {
		const union MHD_ConnectionInfo *fd = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
		for (i = 0; i < GUARD_CONNS && g->conns[i].fd >= 0; i++)
			;
		if (i < GUARD_CONNS && fd) {
			slot = &g->conns[i];
			slot->fd = fd->connect_fd;
			slot->since = slot->idle_since = http_mono_s();
			/* Idle until its first byte: a browser opens connections ahead of its requests. */
			slot->phase = GUARD_IDLE;
			slot->idle_bytes = slot->idle_sent = 0;
			http_client_address(c, slot->addr, sizeof(slot->addr));
			*socket_context = slot;
		}
	} else if (slot) { /* closed: libmicrohttpd says so before it closes the socket */
		slot->fd = -1;
		*socket_context = NULL;
	}
	pthread_mutex_unlock(&g->lock);
}

void http_guard_phase(struct MHD_Connection *c, struct vmac_http *h, enum guard_phase phase)
{
	const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
	struct guard_conn *slot = ci ? ci->socket_context : NULL;
	if (!slot)
		return;
	pthread_mutex_lock(&h->guard.lock);
	slot->phase = phase;
	slot->since = http_mono_s();
	/* What the kernel has received once a request is in: the baseline its
	 * connection's next bytes are told by when it goes idle (taken here,
	 * not when the answer is done, by which time a quick client may have
	 * sent more). */
	if (phase == GUARD_ANSWERING && slot->fd >= 0)
		slot->idle_bytes = tcp_bytes(slot->fd).received;
	if (phase == GUARD_IDLE && slot->fd >= 0) {
		slot->idle_sent = tcp_bytes(slot->fd).sent;
		slot->idle_since = slot->since;
	}
	pthread_mutex_unlock(&h->guard.lock);
}

/* An idle connection that has received bytes since its last request was
 * in (or, new, at all) is sending its next request (libmicrohttpd says
 * nothing before the headers are whole): its header deadline runs from
 * when the reaper saw them (at most REAP_EVERY_MS late), so trickled
 * headers are cut off and said. Unless the server has sent bytes since
 * it went idle: then what came was a TLS handshake (or a key update) the
 * server answered, never part of a request, whose headers the server
 * answers only once whole; the connection is idle still, from when it
 * was first (so at most HTTP_IDLE_TIMEOUT_S in all), with new baselines.
 * Under g->lock. */
static void idle_or_trickling(struct guard_conn *k, double now)
{
	struct tcp_bytes n = tcp_bytes(k->fd);
	if (n.sent > k->idle_sent) {
		k->idle_bytes = n.received;
		k->idle_sent = n.sent;
		k->phase = GUARD_IDLE;
		k->since = k->idle_since;
	} else if (k->phase == GUARD_IDLE && n.received > k->idle_bytes) {
		k->phase = GUARD_HEADERS;
		k->since = now;
	}
}

/* Every REAP_EVERY_MS: a connection past its phase's deadline is cut off
 * (its socket shut down: libmicrohttpd's thread then sees the end and
 * closes it). */
static void *reaper(void *arg)
{
	struct vmac_http *h = arg;
	struct http_guard *g = &h->guard;
	struct timespec until;
	char last[INET6_ADDRSTRLEN] = "";
	int i;
	pthread_mutex_lock(&g->lock);
	while (!g->stop) {
		double now = http_mono_s();
		for (i = 0; i < GUARD_CONNS; i++) {
			struct guard_conn *k = &g->conns[i];
			double limit;
			if (k->fd >= 0 && (k->phase == GUARD_IDLE || k->phase == GUARD_HEADERS))
				idle_or_trickling(k, now); /* GUARD_HEADERS: only ever entered from GUARD_IDLE, here */
			limit = k->phase == GUARD_HEADERS ? g->header_timeout_s
			        : k->phase == GUARD_BODY  ? g->body_timeout_s
			                                  : HTTP_IDLE_TIMEOUT_S;
			if (k->fd < 0 || k->phase == GUARD_ANSWERING || now - k->since < limit)
				continue;
			shutdown(k->fd, SHUT_RDWR);
			if (k->phase != GUARD_IDLE) {
				g->cut_unsaid++;
				snprintf(last, sizeof(last), "%s", k->addr);
			}
			k->phase = GUARD_ANSWERING; /* once */
		}
		if (g->cut_unsaid && now - g->cut_said_at >= CUT_SAID_EVERY_S) {
			char text[240];
			snprintf(
			    text, sizeof(text),
			    "%llu connections cut off: no complete request headers within %u s or body within %u s "
			    "(http_header_timeout_s, http_body_timeout_s; the last from %s)",
			    (unsigned long long)g->cut_unsaid, (unsigned)g->header_timeout_s,
			    (unsigned)g->body_timeout_s, last);
			g->cut_unsaid = 0;
			g->cut_said_at = now;
			pthread_mutex_unlock(&g->lock);
			vmac_event_log_add(h->log, "http", "", text);
			pthread_mutex_lock(&g->lock);
		}
		until = vmac_mono_after_ns(REAP_EVERY_MS * 1000000LL);
		pthread_cond_timedwait(&g->wake, &g->lock, &until);
	}
	pthread_mutex_unlock(&g->lock);
	return NULL;
}

int http_guard_start(struct vmac_http *h)
{
	struct http_guard *g = &h->guard;
	pthread_condattr_t attr;
	int i, rc;
	pthread_mutex_init(&g->lock, NULL);
	pthread_condattr_init(&attr);
	pthread_condattr_setclock(&attr, CLOCK_MONOTONIC);
	pthread_cond_init(&g->wake, &attr);
	pthread_condattr_destroy(&attr);
	for (i = 0; i < GUARD_CONNS; i++)
		g->conns[i].fd = -1;
	g->header_timeout_s = h->cfg.http_header_timeout_s;
	g->body_timeout_s = h->cfg.http_body_timeout_s;
	rc = pthread_create(&g->reaper, NULL, reaper, h);
	g->running = rc == 0;
	return -rc;
}

void http_guard_stop(struct vmac_http *h)
{
	struct http_guard *g = &h->guard;
	if (g->running) {
		pthread_mutex_lock(&g->lock);
		g->stop = 1;
		pthread_cond_signal(&g->wake);
		pthread_mutex_unlock(&g->lock);
		pthread_join(g->reaper, NULL);
		g->running = 0;
	}
	pthread_cond_destroy(&g->wake);
	pthread_mutex_destroy(&g->lock);
}
