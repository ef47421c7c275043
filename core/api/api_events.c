/* The endpoints of events (docs/API.md): GET /api/events as Server-Sent
 * Events (replay after a seq, keep-alives, ended by a stopping host) and
 * GET /api/events/log from the store. */
#include "http_internal.h"

#include <arpa/inet.h>
#include <errno.h>
#include <jansson.h>
#include <microhttpd.h>
#include <sodium.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../common/addr.h"
#include "../common/errors.h"
#include "../loader/loader.h"
#include "../reload/deploy.h"
#include "console.h"
#include "ui_assets.h"

/* GET /api/events/log[?after=SEQ][&limit=N]: the events the store keeps. */
static void append_event(void *ctx, const struct vmac_stored_event *e)
{
	json_array_append_new(ctx, json_pack("{s:I, s:f, s:s, s:s, s:s}", "seq", (json_int_t)e->seq, "time", e->time,
	                                     "kind", e->kind, "device", e->device, "text", e->text));
}

enum MHD_Result http_event_log(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *after_s = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "after");
	const char *limit_s = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "limit");
	unsigned long long after;
	long limit;
	const char *why;
	char err[512];
	json_t *list;
	(void)k;
	if (http_parse_event_log(after_s, limit_s, &after, &limit, &why) != 0)
		return http_reply(c, MHD_HTTP_BAD_REQUEST, http_error_body(why));
	list = json_array();
	if (vmac_store_events_list(h->store, after, (int)limit, append_event, list, err, sizeof(err)) < 0) {
		json_decref(list);
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body(err));
	}
	return http_reply(c, MHD_HTTP_OK, json_pack("{s:o}", "events", list));
}

static void sse_append(struct sse *e, const char *text)
{
	size_t n = strlen(text);
	if (e->len + n < sizeof(e->buf)) {
		memcpy(e->buf + e->len, text, n);
		e->len += n;
	}
}

/* The stream's next bytes: blocks (its own connection thread) until an
 * event, a keep-alive or the host's stop. */
static ssize_t sse_read(void *cls, uint64_t pos, char *out, size_t max)
{
	struct sse *e = cls;
	size_t n;
	(void)pos;
	while (e->off == e->len) {
		struct vmac_event ev[SSE_BATCH];
		uint64_t lost;
		char line[128];
		double now;
		int i, got;
		if (atomic_load(&e->h->stopping))
			return MHD_CONTENT_READER_END_OF_STREAM;
		got = vmac_event_log_since(e->h->log, e->after, ev, SSE_BATCH, SSE_WAIT_MS, &lost);
		now = http_mono_s();
		e->len = e->off = 0;
		if (lost) {
			snprintf(line, sizeof(line), ": %llu events were lost (the log keeps the last %d)\n\n",
			         (unsigned long long)lost, VMAC_EVENT_LOG_SIZE);
			sse_append(e, line);
		}
		for (i = 0; i < got; i++) {
			json_t *j = json_pack("{s:I, s:f, s:s, s:s, s:s}", "seq", (json_int_t)ev[i].seq, "time",
			                      (double)ev[i].time_ns / 1e9, "kind", ev[i].kind, "device", ev[i].device,
			                      "text", ev[i].text);
			char *data = j ? json_dumps(j, JSON_COMPACT) : NULL;
			json_decref(j);
			snprintf(line, sizeof(line), "id: %llu\nevent: %s\ndata: ", (unsigned long long)ev[i].seq,
			         ev[i].kind);
			sse_append(e, line);
			sse_append(e, data ? data : "{}");
			sse_append(e, "\n\n");
			free(data);
			e->after = ev[i].seq;
		}
		if (e->len == 0 && now - e->last_sent >= SSE_KEEPALIVE_S)
			sse_append(e, ": keep-alive\n\n");
		if (e->len)
			e->last_sent = now;
	}
	n = e->len - e->off < max ? e->len - e->off : max;
	memcpy(out, e->buf + e->off, n);
	e->off += n;
	return (ssize_t)n;
}

enum MHD_Result http_events_stream(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	const char *after = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, "after");
	const char *resume = MHD_lookup_connection_value(c, MHD_HEADER_KIND, "Last-Event-ID");
	struct sse *e;
	unsigned long long seq;
	(void)k;
	if (http_parse_events_from(after, resume, &seq) != 0)
		return http_reply(c, MHD_HTTP_BAD_REQUEST,
		                  http_error_body("after (or Last-Event-ID) must be an event's seq"));
	e = calloc(1, sizeof(*e));
	if (!e)
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body("out of memory"));
	e->h = h;
	e->after = seq;
	e->last_sent = http_mono_s();
	/* Something at once, so the client sees the stream is open before the
	 * first event (and how soon to reconnect when it ends). */
	sse_append(e, "retry: 2000\n: vmac events\n\n");
	return http_stream_response(c, sse_read, e, free);
}
