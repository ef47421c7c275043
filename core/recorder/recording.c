/* Recordings as files: see recording.h and docs/RECORDING.md. */
#include "recording.h"

#include <jansson.h>
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/name.h"

static const char *const kind_names[] = {NULL, "attach", "param", "input", "level", "miss", "error", "drop", "swap"};

const char *vmac_rec_kind_name(int kind)
{
	return kind > 0 && kind < (int)(sizeof(kind_names) / sizeof(kind_names[0])) ? kind_names[kind] : NULL;
}

static int kind_of(const char *name)
{
	int i;
	for (i = 1; i < (int)(sizeof(kind_names) / sizeof(kind_names[0])); i++)
		if (strcmp(kind_names[i], name) == 0)
			return i;
	return 0;
}

/* ---- writing ---- */

struct out {
	char *buf;
	size_t len, cap;
	int failed;
};

static void put(struct out *o, const char *s, size_t n)
{
	if (o->failed)
		return;
	if (o->cap - o->len < n + 1) {
		size_t cap = o->cap ? o->cap : 65536;
		char *b;
		while (cap - o->len < n + 1)
			cap *= 2;
		b = realloc(o->buf, cap);
		if (!b) {
			o->failed = 1;
			return;
		}
		o->buf = b;
		o->cap = cap;
	}
	memcpy(o->buf + o->len, s, n);
	o->len += n;
	o->buf[o->len] = 0;
}

/* One JSON line (the object is consumed). */
static void put_line(struct out *o, json_t *j)
{
	char *s = j ? json_dumps(j, JSON_COMPACT | JSON_ENSURE_ASCII) : NULL;
	json_decref(j);
	if (!s) {
		o->failed = 1;
		return;
	}
	put(o, s, strlen(s));
	put(o, "\n", 1);
	free(s);
}

static json_t *value_json(const struct vmac_value *v)
{
	switch (v->type) {
	case VMAC_VALUE_NUMBER: return json_real(v->number);
	case VMAC_VALUE_BOOL: return json_boolean(v->number != 0);
	case VMAC_VALUE_STRING: return json_string(v->str); /* NULL when not UTF-8: the key is left out */
	default: return json_null();
	}
}

/* A board of a tick line; "at" (the inputs' instant, bus time ns) only
 * when it is not the tick's own time. */
static json_t *tick_board_json(const struct vmac_rec_tick *t)
{
	json_t *in = json_pack("[iiiiii]", (int)t->in.digital, (int)t->in.analog[0], (int)t->in.analog[1],
	                       (int)t->in.encoder, (int)t->in.applied.digital, (int)t->in.applied.pwm);
	json_t *b =
	    json_pack("{s:i,s:o,s:[ii]}", "b", (int)t->board, "in", in, "out", (int)t->out_digital, (int)t->out_pwm);
	if (b && t->at != 0 && t->at != VMAC_REC_AT_FAR)
		json_object_set_new(b, "at", json_integer(vmac_rec_at_ns(t)));
	return b;
}

static json_t *event_json(const struct vmac_rec_event *e)
{
	json_t *j = json_pack("{s:I,s:s}", "t", (json_int_t)e->t_ns, "event", vmac_rec_kind_name(e->kind));
	if (!j)
		return NULL;
	switch (e->kind) {
	case VMAC_REC_ATTACH:
	case VMAC_REC_SWAP: json_object_set_new(j, "version", json_string(e->name)); break;
	case VMAC_REC_PARAM:
	case VMAC_REC_INPUT:
		json_object_set_new(j, "name", json_string(e->name));
		json_object_set_new(j, "value", value_json(&e->value));
		if (e->kind == VMAC_REC_INPUT)
			json_object_set_new(j, "code", json_integer(e->code));
		break;
	case VMAC_REC_LEVEL: json_object_set_new(j, "level", json_integer(e->code)); break;
	case VMAC_REC_MISS:
		json_object_set_new(j, "board", json_integer(e->board));
		json_object_set_new(j, "seq", json_integer(e->code));
		json_object_set_new(j, "sent_ns", json_integer(e->a_ns));
		json_object_set_new(j, "received_ns", json_integer(e->b_ns));
		json_object_set_new(j, "text", json_string(e->text));
		break;
	default: json_object_set_new(j, "text", json_string(e->text)); break;
	}
	return j;
}

/* The header's bundle: its bytes in base64 and their BLAKE2b-256 hash. */
static void put_bundle(json_t *h, const char *bundle, size_t len)
{
	size_t b64len = sodium_base64_ENCODED_LEN(len, sodium_base64_VARIANT_ORIGINAL);
	char *b64 = malloc(b64len);
	unsigned char hash[32];
	char hex[65];
	if (!b64)
		return; /* left out: the replay then has the source alone */
	sodium_bin2base64(b64, b64len, (const unsigned char *)bundle, len, sodium_base64_VARIANT_ORIGINAL);
	crypto_generichash(hash, sizeof(hash), (const unsigned char *)bundle, len, NULL, 0);
	sodium_bin2hex(hex, sizeof(hex), hash, sizeof(hash));
	json_object_set_new(h, "bundle", json_string(b64));
	json_object_set_new(h, "bundle_hash", json_string(hex));
	free(b64);
}

/* The header's bundle into r: 0, or -1 (not base64, or not what its hash
 * says: damaged). */
static int get_bundle(json_t *j, struct vmac_recording *r)
{
	const char *b64 = json_string_value(json_object_get(j, "bundle"));
	const char *want = json_string_value(json_object_get(j, "bundle_hash"));
	size_t n = b64 ? strlen(b64) : 0;
	unsigned char hash[32];
	char hex[65];
	if (!b64 || !want || n / 4 * 3 > (8u << 20) || !(r->bundle = malloc(n / 4 * 3 + 3)))
		return -1;
	if (sodium_base642bin((unsigned char *)r->bundle, n / 4 * 3 + 3, b64, n, NULL, &r->bundle_len, NULL,
	                      sodium_base64_VARIANT_ORIGINAL) != 0)
		return -1;
	crypto_generichash(hash, sizeof(hash), (const unsigned char *)r->bundle, r->bundle_len, NULL, 0);
	sodium_bin2hex(hex, sizeof(hex), hash, sizeof(hash));
	return strcmp(hex, want) == 0 ? 0 : -1;
}

/* The bus time the recorded version took over at a hot reload (the last
 * swap event naming it), or 0 when it ran since attach or the swap left
 * the ring. */
static int64_t took_over(const struct vmac_recorder *r)
{
	uint32_t i, n = vmac_rec_nevents(r);
	int64_t t = 0;
	for (i = 0; i < n; i++) {
		const struct vmac_rec_event *e = vmac_rec_event_at(r, i);
		if (e->kind == VMAC_REC_SWAP)
			t = strcmp(e->name, r->version) == 0 ? e->t_ns : 0;
	}
	return t;
}

/* The state a replay resumes from: the oldest kept whose tick the ring
 * still holds, and for a version that took over at a hot reload, the
 * oldest since it did. NULL: none. */
static const struct vmac_rec_state *resume_state(const struct vmac_recorder *r, int64_t since)
{
	const struct vmac_rec_state *best = NULL;
	uint64_t first = r->ticks_written - vmac_rec_nticks(r);
	int i;
	if (!since)
		return vmac_rec_state_base(r);
	for (i = 0; i < VMAC_REC_STATES; i++) {
		const struct vmac_rec_state *s = &r->states[i];
		if (s->len && s->at >= first && s->at < r->ticks_written && s->t_ns >= since &&
		    (!best || s->at < best->at))
			best = s;
	}
	return best;
}

char *vmac_recording_write(const struct vmac_recorder *r, const char *src, size_t srclen, const char *bundle,
                           size_t bundlelen, double captured, size_t *len)
{
	struct out o = {NULL, 0, 0, 0};
	uint32_t nt = vmac_rec_nticks(r), ne = vmac_rec_nevents(r), ti = 0, ei = 0, lines = 0;
	unsigned char hash[crypto_generichash_BYTES];
	char hex[2 * crypto_generichash_BYTES + 1];
	json_t *h, *boards = json_array();
	int i, complete = r->from_attach && r->ticks_written <= r->ticks_cap;
	int64_t swapped = took_over(r);

	for (i = 0; i < r->nboards; i++)
		json_array_append_new(
		    boards, json_pack("{s:s,s:I}", "name", r->boards[i].name, "minor", (json_int_t)r->boards[i].minor));
	h = json_pack("{s:s,s:i,s:s,s:s,s:s,s:I,s:s,s:f,s:i,s:f,s:I,s:b,s:o}", "format", "vmac-recording", "version",
	              VMAC_RECORDING_FORMAT, "machine", r->machine, "driver", r->driver, "driver_version", r->version,
	              "version_id", (json_int_t)r->version_id, "reason", r->reason, "captured", captured, "level",
	              (int)r->level, "period_s", r->period_s, "attach_t", (json_int_t)r->attach_ns, "complete",
	              complete, "boards", boards);
	if (h && src)
		json_object_set_new(h, "source", json_stringn(src, srclen)); /* NULL (left out) when not UTF-8 */
	if (h && bundle)
		put_bundle(h, bundle, bundlelen);
	if (h && swapped)
		json_object_set_new(h, "took_over_t", json_integer(swapped));
	if (h && (!complete || swapped)) { /* where a replay can resume: dev.state after a tick the ring still holds */
		const struct vmac_rec_state *st = resume_state(r, swapped);
		char *x = st ? malloc(2 * (size_t)st->len + 1) : NULL;
		if (x) {
			sodium_bin2hex(x, 2 * (size_t)st->len + 1, st->data, st->len);
			json_object_set_new(h, "state", json_pack("{s:I,s:s}", "t", (json_int_t)st->t_ns, "data", x));
			free(x);
		} else if (st) {
			o.failed = 1;
		}
	}
	put_line(&o, h);
	while (ti < nt || ei < ne) {
		const struct vmac_rec_tick *t = ti < nt ? vmac_rec_tick_at(r, ti) : NULL;
		const struct vmac_rec_event *e = ei < ne ? vmac_rec_event_at(r, ei) : NULL;
		if (e && (!t || e->t_ns <= t->t_ns)) { /* an event before the tick of the same time */
			put_line(&o, event_json(e));
			ei++;
		} else {
			json_t *b = json_array(), *line;
			int64_t at = t->t_ns;
			for (; ti < nt; ti++) {
				t = vmac_rec_tick_at(r, ti);
				if (t->t_ns != at)
					break;
				json_array_append_new(b, tick_board_json(t));
				if (t->last) {
					ti++;
					break;
				}
			}
			line = json_pack("{s:I,s:o}", "t", (json_int_t)at, "tick", b);
			put_line(&o, line);
		}
		lines++;
	}
	if (o.failed || !o.buf) {
		free(o.buf);
		return NULL;
	}
	crypto_generichash(hash, sizeof(hash), (const unsigned char *)o.buf, o.len, NULL, 0);
	sodium_bin2hex(hex, sizeof(hex), hash, sizeof(hash));
	put_line(&o, json_pack("{s:{s:I,s:s}}", "end", "lines", (json_int_t)lines, "blake2b", hex));
	if (o.failed) {
		free(o.buf);
		return NULL;
	}
	*len = o.len;
	return o.buf;
}

/* ---- reading ---- */

#define HEADER_START "{\"format\":\"vmac-recording\"" /* how every header the writer makes begins */

#define FAIL(...)                                                                                                      \
	do {                                                                                                           \
		snprintf(err, errlen, __VA_ARGS__);                                                                    \
		goto fail;                                                                                             \
	} while (0)

static int read_value(json_t *j, struct vmac_value *v)
{
	memset(v, 0, sizeof(*v));
	if (json_is_number(j)) {
		v->type = VMAC_VALUE_NUMBER;
		v->number = json_number_value(j);
	} else if (json_is_boolean(j)) {
		v->type = VMAC_VALUE_BOOL;
		v->number = json_is_true(j);
	} else if (json_is_string(j) && json_string_length(j) <= VMAC_VALUE_STR_MAX) {
		v->type = VMAC_VALUE_STRING;
		memcpy(v->str, json_string_value(j), json_string_length(j));
	} else if (!json_is_null(j) && j) {
		return -1;
	}
	return 0;
}

static void copy_str(char *dst, size_t cap, json_t *j)
{
	snprintf(dst, cap, "%s", json_is_string(j) ? json_string_value(j) : "");
}

static int read_tick(json_t *arr, struct vmac_recording_line *l)
{
	size_t i;
	json_t *b, *at;
	if (!json_is_array(arr) || json_array_size(arr) == 0 || json_array_size(arr) > VMAC_REC_BOARDS)
		return -1;
	json_array_foreach(arr, i, b)
	{
		json_int_t in[6], out[2], board;
		if (json_unpack(b, "{s:I,s:[IIIIII],s:[II]}", "b", &board, "in", &in[0], &in[1], &in[2], &in[3], &in[4],
		                &in[5], "out", &out[0], &out[1]) != 0 ||
		    board != (json_int_t)i)
			return -1;
		l->in[i].digital = (uint8_t)in[0];
		l->in[i].analog[0] = (uint16_t)in[1];
		l->in[i].analog[1] = (uint16_t)in[2];
		l->in[i].encoder = (int32_t)in[3];
		l->in[i].applied.digital = (uint8_t)in[4];
		l->in[i].applied.pwm = (int16_t)in[5];
		l->out[i].digital = (uint8_t)out[0];
		l->out[i].pwm = (int16_t)out[1];
		if ((at = json_object_get(b, "at")) != NULL) { /* optional: the tick's time when absent */
			if (!json_is_integer(at))
				return -1;
			l->at_ns[i] = json_integer_value(at);
			l->has_at |= 1u << i;
		}
	}
	l->nboards = (int)json_array_size(arr);
	return 0;
}

static int read_event(json_t *j, struct vmac_rec_event *e)
{
	const char *kind = json_string_value(json_object_get(j, "event"));
	memset(e, 0, sizeof(*e));
	if (!kind || !(e->kind = (uint8_t)kind_of(kind)))
		return -1;
	copy_str(e->name, sizeof(e->name),
	         json_object_get(j, e->kind == VMAC_REC_ATTACH || e->kind == VMAC_REC_SWAP ? "version" : "name"));
	copy_str(e->text, sizeof(e->text), json_object_get(j, "text"));
	if (read_value(json_object_get(j, "value"), &e->value) != 0)
		return -1;
	e->code = (int32_t)json_integer_value(json_object_get(j, e->kind == VMAC_REC_LEVEL  ? "level"
	                                                         : e->kind == VMAC_REC_MISS ? "seq"
	                                                                                    : "code"));
	e->board = (uint8_t)json_integer_value(json_object_get(j, "board"));
	e->a_ns = json_integer_value(json_object_get(j, "sent_ns"));
	e->b_ns = json_integer_value(json_object_get(j, "received_ns"));
	return 0;
}

/* The header line's fields (j, a vmac-recording object) into r: 0, or -1
 * with err (what r holds so far is freed by the caller). */
static int read_header(json_t *j, struct vmac_recording *r, char *err, size_t errlen)
{
	json_t *boards, *b;
	size_t i;
	if (json_integer_value(json_object_get(j, "version")) != VMAC_RECORDING_FORMAT)
		FAIL("recording in format %lld, this vmac reads %d",
		     (long long)json_integer_value(json_object_get(j, "version")), VMAC_RECORDING_FORMAT);
	copy_str(r->machine, sizeof(r->machine), json_object_get(j, "machine"));
	copy_str(r->driver, sizeof(r->driver), json_object_get(j, "driver"));
	copy_str(r->version, sizeof(r->version), json_object_get(j, "driver_version"));
	copy_str(r->reason, sizeof(r->reason), json_object_get(j, "reason"));
	r->captured = json_number_value(json_object_get(j, "captured"));
	r->period_s = json_number_value(json_object_get(j, "period_s"));
	r->level = (unsigned)json_integer_value(json_object_get(j, "level"));
	r->attach_ns = json_integer_value(json_object_get(j, "attach_t"));
	r->complete = json_is_true(json_object_get(j, "complete"));
	boards = json_object_get(j, "boards");
	if (!r->machine[0] || !r->driver[0] || !json_is_array(boards) || json_array_size(boards) == 0 ||
	    json_array_size(boards) > VMAC_REC_BOARDS)
		FAIL("recording damaged: its header lacks the machine, the driver or its boards");
	/* Names, never paths: vmac test --replay looks the driver up by it. */
	if (!vmac_valid_name(r->machine, sizeof(r->machine) - 1) || !vmac_valid_name(r->driver, sizeof(r->driver) - 1))
		FAIL("recording damaged: its machine or driver is not a name ([A-Za-z0-9._-], not starting with '.')");
	json_array_foreach(boards, i, b)
	{
		copy_str(r->boards[i].name, sizeof(r->boards[i].name), json_object_get(b, "name"));
		r->boards[i].minor = (uint32_t)json_integer_value(json_object_get(b, "minor"));
	}
	r->nboards = (int)json_array_size(boards);
	if (json_is_string(json_object_get(j, "source"))) {
		r->source_len = json_string_length(json_object_get(j, "source"));
		r->source = malloc(r->source_len + 1);
		if (!r->source)
			FAIL("out of memory");
		memcpy(r->source, json_string_value(json_object_get(j, "source")), r->source_len + 1);
	}
	if (json_is_integer(json_object_get(j, "took_over_t")))
		r->took_over_ns = json_integer_value(json_object_get(j, "took_over_t"));
	if (json_object_get(j, "bundle") && get_bundle(j, r) != 0)
		FAIL("recording damaged: its bundle is not what its bundle_hash says");
	if (json_object_get(j, "state")) {
		json_t *st = json_object_get(j, "state");
		const char *x = json_string_value(json_object_get(st, "data"));
		size_t xl = x ? strlen(x) : 0;
		if (!json_is_integer(json_object_get(st, "t")) || !x || xl == 0 || xl % 2 ||
		    xl / 2 > VMAC_REC_STATE_MAX || !(r->state = malloc(xl / 2)) ||
		    sodium_hex2bin(r->state, xl / 2, x, xl, NULL, &r->state_len, NULL) != 0 || r->state_len != xl / 2)
			FAIL("recording damaged: its header's state is not a time and hex data");
		r->state_t_ns = json_integer_value(json_object_get(st, "t"));
	}
	return 0;
fail:
	return -1;
}

int vmac_recording_read(const char *text, size_t len, struct vmac_recording *r, char *err, size_t errlen)
{
	const char *p = text, *end = text + len, *nl;
	json_t *j = NULL;
	json_error_t je;
	size_t lineno = 1, cap = 0;
	int ended = 0;

	memset(r, 0, sizeof(*r));
	nl = memchr(p, '\n', (size_t)(end - p));
	/* The header holds the driver's source: a file cut short is often cut in it. */
	if (!nl && len > 0 &&
	    memcmp(text, HEADER_START, len < sizeof(HEADER_START) - 1 ? len : sizeof(HEADER_START) - 1) == 0)
		FAIL("recording truncated: its header line has no end");
	if (!nl)
		FAIL(len ? "not a vmac recording (no header line)" : "not a vmac recording (empty)");
	j = json_loadb(p, (size_t)(nl - p), 0, &je);
	if (!json_is_object(j) || !json_is_string(json_object_get(j, "format")) ||
	    strcmp(json_string_value(json_object_get(j, "format")), "vmac-recording") != 0)
		FAIL("not a vmac recording (line 1 is not its header)");
	if (read_header(j, r, err, errlen) != 0)
		goto fail;
	json_decref(j);
	j = NULL;
	for (p = nl + 1; p < end; p = nl + 1) {
		struct vmac_recording_line *l;
		json_t *tick;
		lineno++;
		nl = memchr(p, '\n', (size_t)(end - p));
		if (!nl)
			FAIL("recording truncated: line %zu has no end", lineno);
		j = json_loadb(p, (size_t)(nl - p), 0, &je);
		if (!json_is_object(j))
			FAIL("recording damaged: line %zu is not JSON (%s)", lineno, je.text);
		if (json_object_get(j, "end")) {
			unsigned char hash[crypto_generichash_BYTES];
			char hex[2 * crypto_generichash_BYTES + 1];
			const char *want = json_string_value(json_object_get(json_object_get(j, "end"), "blake2b"));
			crypto_generichash(hash, sizeof(hash), (const unsigned char *)text, (size_t)(p - text), NULL,
			                   0);
			sodium_bin2hex(hex, sizeof(hex), hash, sizeof(hash));
			if (!want || strcmp(want, hex) != 0)
				FAIL("recording damaged: its hash does not match its contents");
			if ((size_t)json_integer_value(json_object_get(json_object_get(j, "end"), "lines")) !=
			    r->nlines)
				FAIL("recording damaged: the end line counts another number of lines");
			ended = 1;
			json_decref(j);
			j = NULL;
			break;
		}
		if (r->nlines == cap) {
			size_t ncap = cap ? 2 * cap : 1024;
			struct vmac_recording_line *n = realloc(r->lines, ncap * sizeof(*n));
			if (!n)
				FAIL("out of memory");
			r->lines = n;
			cap = ncap;
		}
		l = &r->lines[r->nlines];
		memset(l, 0, sizeof(*l));
		if (!json_is_integer(json_object_get(j, "t")))
			FAIL("recording damaged: line %zu has no time", lineno);
		l->t_ns = json_integer_value(json_object_get(j, "t"));
		if (r->nlines > 0 && l->t_ns < r->lines[r->nlines - 1].t_ns)
			FAIL("recording damaged: line %zu goes back in time", lineno);
		if ((tick = json_object_get(j, "tick")) != NULL) {
			l->is_tick = 1;
			if (read_tick(tick, l) != 0 || l->nboards > r->nboards)
				FAIL("recording damaged: line %zu is not a tick of this machine", lineno);
			r->nticks++;
		} else {
			if (read_event(j, &l->ev) != 0)
				FAIL("recording damaged: line %zu is not an event", lineno);
			l->ev.t_ns = l->t_ns; /* after read_event, which clears ev */
			r->nevents++;
		}
		r->nlines++;
		json_decref(j);
		j = NULL;
	}
	if (!ended)
		FAIL("recording truncated: no end line after %zu lines", lineno);
	return 0;
fail:
	json_decref(j);
	vmac_recording_free(r);
	return -1;
}

void vmac_recording_free(struct vmac_recording *r)
{
	free(r->source);
	free(r->bundle);
	free(r->lines);
	free(r->state);
	r->bundle = NULL;
	r->state = NULL;
	r->source = NULL;
	r->lines = NULL;
	r->nlines = 0;
}
