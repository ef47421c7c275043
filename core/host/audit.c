/* The audit trail's one format and its rate limit on refusals: see
 * audit.h. */
#include "audit.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

#include "bus.h"
#include "events.h"

const char *const vmac_audit_types[VMAC_AUDIT_TYPE_COUNT] = {
    "input",    /* operator input: POST .../input, an MQTT set or cmd, a Sparkplug DCMD */
    "param",    /* a param set and persisted ("persist": true) */
    "cycle",    /* POST .../cycle */
    "record",   /* POST .../record */
    "console",  /* POST /api/console with a :, > or ! */
    "reload",   /* POST /api/drivers/NAME */
    "activate", /* POST /api/drivers/NAME/activate */
    "rollback", /* POST /api/drivers/NAME/rollback */
    "board",    /* POST /api/boards/NAME, .../remove */
    "token",    /* vmac token create, revoke */
    "lockout",  /* the failed attempt that locked a token id or an address out */
    "auth",     /* a read refused for its token */
    "request",  /* a POST to no endpoint */
    "refused",  /* the refusals of a window that were not each said */
};

#define WHY_MAX 240 /* of an event's text, at most this much says why */

void vmac_audit_limit_init(struct vmac_audit_limit *l)
{
	memset(l, 0, sizeof(*l));
	pthread_mutex_init(&l->lock, NULL);
}

void vmac_audit_text(const struct vmac_audit *a, char *out, size_t len)
{
	char head[256], tail[WHY_MAX + 48];
	size_t room;
	int nh, nt;
	nh = snprintf(head, sizeof(head), "%s by %s from %s: ", a->type, a->who, a->where);
	nt = snprintf(tail, sizeof(tail), " -> %s%s%.*s%s", a->result, a->why && a->why[0] ? " (" : "", WHY_MAX,
	              a->why ? a->why : "", a->why && a->why[0] ? ")" : "");
	if (nh < 0 || nt < 0 || len == 0)
		return;
	if ((size_t)nh >= sizeof(head))
		nh = (int)sizeof(head) - 1;
	if ((size_t)nt >= sizeof(tail))
		nt = (int)sizeof(tail) - 1;
	room = len > (size_t)(nh + nt) + 1 ? len - (size_t)(nh + nt) - 1 : 0;
	if (strlen(a->what) <= room)
		snprintf(out, len, "%s%s%s", head, a->what, tail);
	else if (room > 3)
		snprintf(out, len, "%s%.*s...%s", head, (int)(room - 3), a->what, tail);
	else
		snprintf(out, len, "%s%s", head, tail);
}

/* The window has ended: its summary (into text, "" when everything was
 * said) and a new one. Under l->lock. */
static void close_window(struct vmac_audit_limit *l, char *text, size_t len)
{
	const char *sep = " ";
	size_t used = 0;
	int i, n = 0, one = -1;
	text[0] = 0;
	for (i = 0; i < l->nkeys; i++)
		if (l->keys[i].unsaid) {
			n++;
			one = i;
		}
	if (l->unsaid && n == 1 && !l->unsaid_other) {
		snprintf(text, len, "refused: and %llu more refused requests from %s in the last %.0f s", l->unsaid,
		         l->keys[one].key, VMAC_AUDIT_WINDOW_S);
	} else if (l->unsaid) {
		used = (size_t)snprintf(text, len,
		                        "refused: and %llu more refused requests in the last %.0f s:", l->unsaid,
		                        VMAC_AUDIT_WINDOW_S);
		for (i = 0; i < l->nkeys && used < len; i++)
			if (l->keys[i].unsaid) {
				used += (size_t)snprintf(text + used, len - used, "%s%llu from %s", sep,
				                         l->keys[i].unsaid, l->keys[i].key);
				sep = ", ";
			}
		if (l->unsaid_other && used < len)
			snprintf(text + used, len - used, "%s%llu from others", sep, l->unsaid_other);
	}
	used = strlen(text);
	if (l->unsaid_lockouts && used + 1 < len)
		snprintf(text + used, len - used, " (%llu of them lock-outs)", l->unsaid_lockouts);
	memset(l->keys, 0, sizeof(l->keys));
	l->nkeys = 0;
	l->window_start_s = 0;
	l->refused_said = l->lockouts_said = 0;
	l->unsaid = l->unsaid_lockouts = l->unsaid_other = 0;
}

/* Whether the refusal a is said (counted either way). Under l->lock. */
static int within_limit(struct vmac_audit_limit *l, const struct vmac_audit *a, double now_s)
{
	int i, said;
	if (l->window_start_s == 0)
		l->window_start_s = now_s;
	for (i = 0; i < l->nkeys && strcmp(l->keys[i].key, a->key) != 0; i++)
		;
	if (i == l->nkeys && l->nkeys < VMAC_AUDIT_KEYS) {
		snprintf(l->keys[i].key, sizeof(l->keys[i].key), "%s", a->key);
		l->nkeys++;
	}
	if (a->lockout)
		said = l->lockouts_said < VMAC_AUDIT_LOCKOUTS_PER_WINDOW;
	else
		said = l->refused_said < VMAC_AUDIT_REFUSED_PER_WINDOW &&
		       (i == l->nkeys || l->keys[i].said < VMAC_AUDIT_REFUSED_PER_KEY);
	if (said) {
		if (a->lockout)
			l->lockouts_said++;
		else
			l->refused_said++;
		if (i < l->nkeys)
			l->keys[i].said++;
		return 1;
	}
	l->unsaid++;
	l->unsaid_lockouts += a->lockout != 0;
	if (i < l->nkeys)
		l->keys[i].unsaid++;
	else
		l->unsaid_other++;
	return 0;
}

void vmac_audit_flush_at(struct vmac_event_log *log, double now_s)
{
	struct vmac_audit_limit *l = &log->audit;
	char text[VMAC_EVENT_TEXT];
	text[0] = 0;
	pthread_mutex_lock(&l->lock);
	if (l->window_start_s != 0 && now_s - l->window_start_s >= VMAC_AUDIT_WINDOW_S)
		close_window(l, text, sizeof(text));
	pthread_mutex_unlock(&l->lock);
	if (text[0])
		vmac_event_log_add(log, "audit", "", text);
}

void vmac_audit_add_at(struct vmac_event_log *log, const struct vmac_audit *a, double now_s)
{
	struct vmac_audit_limit *l = &log->audit;
	char text[VMAC_EVENT_TEXT];
	int said = 1;
	if (a->key) {
		vmac_audit_flush_at(log, now_s); /* a window that has ended is said before this one opens */
		pthread_mutex_lock(&l->lock);
		said = within_limit(l, a, now_s);
		pthread_mutex_unlock(&l->lock);
	}
	if (!said)
		return;
	vmac_audit_text(a, text, sizeof(text));
	vmac_event_log_add(log, "audit", a->device ? a->device : "", text);
}

static double mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

void vmac_audit_add(struct vmac_event_log *log, const struct vmac_audit *a)
{
	vmac_audit_add_at(log, a, mono_s());
}

void vmac_audit_flush(struct vmac_event_log *log)
{
	vmac_audit_flush_at(log, mono_s());
}

void vmac_audit_input(const struct vmac_bus_input_request *req, char *out, size_t len)
{
	const struct vmac_value *v = &req->value;
	char value[2 * VMAC_DRIVER_STR_MAX + 16];
	size_t i, n = 0;
	switch (v->type) {
	case VMAC_VALUE_BOOL: snprintf(value, sizeof(value), "%s", v->number != 0 ? "true" : "false"); break;
	case VMAC_VALUE_NUMBER: snprintf(value, sizeof(value), "%.15g", v->number); break;
	case VMAC_VALUE_STRING:
		if (v->str[0] && strspn(v->str, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._+-") ==
		                     strlen(v->str)) {
			snprintf(value, sizeof(value), "%s", v->str);
			break;
		}
		value[n++] = '"';
		for (i = 0; v->str[i] && n + 8 < sizeof(value); i++) {
			unsigned char c = (unsigned char)v->str[i];
			if (c == '"' || c == '\\')
				n += (size_t)snprintf(value + n, sizeof(value) - n, "\\%c", c);
			else if (c < 0x20 || c == 0x7f)
				n += (size_t)snprintf(value + n, sizeof(value) - n, "\\u%04x", c);
			else
				value[n++] = (char)c;
		}
		value[n++] = '"';
		value[n] = 0;
		break;
	default: value[0] = 0; break;
	}
	if (v->type == VMAC_VALUE_NONE)
		snprintf(out, len, "%s.%s!", req->device, req->name);
	else
		snprintf(out, len, "%s.%s%c%s", req->device, req->name, req->persist ? '>' : ':', value);
}

int vmac_audit_type_of(const char *text, char *type, size_t len)
{
	size_t n = strcspn(text, " :");
	int i;
	for (i = 0; i < VMAC_AUDIT_TYPE_COUNT; i++)
		if (strlen(vmac_audit_types[i]) == n && strncmp(text, vmac_audit_types[i], n) == 0) {
			snprintf(type, len, "%s", vmac_audit_types[i]);
			return 0;
		}
	return -1;
}
