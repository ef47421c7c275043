/* vmac wire protocol codec: the one place that turns frames into messages and back.
 * Used by the host's bus thread and by the board firmware; C99, no heap. */
#include "proto.h"

#include <string.h>

static void put16(uint8_t *p, uint16_t v)
{
	p[0] = (uint8_t)(v >> 8);
	p[1] = (uint8_t)v;
}

static void put32(uint8_t *p, uint32_t v)
{
	p[0] = (uint8_t)(v >> 24);
	p[1] = (uint8_t)(v >> 16);
	p[2] = (uint8_t)(v >> 8);
	p[3] = (uint8_t)v;
}

static void put64(uint8_t *p, uint64_t v)
{
	put32(p, (uint32_t)(v >> 32));
	put32(p + 4, (uint32_t)v);
}

static uint16_t get16(const uint8_t *p)
{
	return (uint16_t)((p[0] << 8) | p[1]);
}

static uint32_t get32(const uint8_t *p)
{
	return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3];
}

static uint64_t get64(const uint8_t *p)
{
	return ((uint64_t)get32(p) << 32) | get32(p + 4);
}

/* Names (driver and board) are 1..31 bytes of [A-Za-z0-9_-]: a driver name
 * becomes a file name and a board name a console prefix, so nothing else. */
static int name_ok(const uint8_t *s, size_t len)
{
	size_t i;
	if (len == 0 || len > VMAC_NAME_MAX)
		return 0;
	for (i = 0; i < len; i++) {
		uint8_t c = s[i];
		int ok =
		    (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
		if (!ok)
			return 0;
	}
	return 1;
}

/* A version-2 CYCLIC frame (its len counts records). */
static int is_cyclic(const uint8_t *buf)
{
	return buf[2] >= 2 && buf[10] == VMAC_CH_SYSTEM && buf[11] == VMAC_SYS_CYCLIC;
}

/* A sealed SYNC (version 2): its len counts MACs, one per offset. */
static int is_sync_auth(const uint8_t *buf)
{
	return buf[2] >= 2 && buf[10] == VMAC_CH_SYSTEM && buf[11] == VMAC_SYS_SYNC &&
	       (buf[3] & (VMAC_FLAG_AUTH | VMAC_FLAG_REPLY)) == VMAC_FLAG_AUTH;
}

size_t vmac_proto_cyclic_head_len(const uint8_t *frame)
{
	return VMAC_HDR_LEN + 2 + ((frame[3] & VMAC_FLAG_AUTH) ? VMAC_AUTH_COUNTER_LEN : 0) +
	       ((frame[3] & VMAC_FLAG_TIMED) ? VMAC_CYCLIC_TIMING_LEN : 0);
}

/* Which flags a frame may carry: TIMED only on a version-2 CYCLIC and a
 * version-2 UPDATE, request or reply. */
static int flags_ok(const uint8_t *buf)
{
	uint8_t f = buf[3];
	if ((f & ~(VMAC_FLAG_REPLY | VMAC_FLAG_AUTH | VMAC_FLAG_TIMED)) != 0)
		return 0;
	if (!(f & VMAC_FLAG_TIMED))
		return 1;
	return buf[2] >= 2 &&
	       (is_cyclic(buf) ? !(f & VMAC_FLAG_REPLY) : buf[10] == VMAC_CH_DEVICE && buf[11] == VMAC_OP_UPDATE);
}

static int latch_clock_ok(uint8_t clock)
{
	return (clock & ~(VMAC_CLOCK_STATE_MASK | VMAC_CLOCK_ARRIVAL)) == 0 &&
	       (clock & VMAC_CLOCK_STATE_MASK) <= VMAC_LATCH_STATE_MAX;
}

static int outputs_ok(const struct vmac_outputs *o)
{
	return (o->digital & 0x80) == 0 && o->pwm >= -VMAC_PWM_MAX && o->pwm <= VMAC_PWM_MAX;
}

/* Expected data length of a request/reply, or -1 when the op is not valid in
 * that direction. ANNOUNCE is variable and checked by its own decoder. */
#define LEN_ANNOUNCE -2 /* variable: checked by decode_announce */
#define LEN_CYCLIC -3   /* len counts records: checked on its own */
#define LEN_DISCOVER -4 /* none, or the host's nonce */
#define SYS_KEY 0x200   /* switch key of a system-channel op (0x100 marks replies) */

static int data_len_for(uint8_t version, uint8_t channel, uint8_t op, int reply)
{
	if (channel == VMAC_CH_SYSTEM) {
		if (op == VMAC_SYS_DISCOVER && !reply)
			return LEN_DISCOVER;
		if (op == VMAC_SYS_ANNOUNCE && reply)
			return LEN_ANNOUNCE;
		if (op == VMAC_SYS_CYCLIC && !reply && version >= 2)
			return LEN_CYCLIC;
		if (op == VMAC_SYS_SYNC && !reply && version >= 2)
			return VMAC_SYNC_LEN;
		return -1;
	}
	if (channel != VMAC_CH_DEVICE)
		return -1;
	if (version < 2 && op >= VMAC_OP_SIZE)
		return -1;
	switch (op) {
	case VMAC_OP_REGISTER: return reply ? 0 : 10;
	case VMAC_OP_SHUTDOWN: return reply ? 0 : 1;
	case VMAC_OP_UPDATE: return reply ? 12 : 3;
	case VMAC_OP_IDLE: return reply ? 12 : 0;
	case VMAC_OP_ERROR: return reply ? 2 : -1;
	case VMAC_OP_SLEEP: return reply ? 0 : 2;
	case VMAC_OP_WATCHDOG: return reply ? 0 : 2;
	case VMAC_OP_SIZE: return reply ? 1 : 0;
	case VMAC_OP_OFFSET: return 2;
	case VMAC_OP_OFFSET_GET: return reply ? 2 : 0;
	default: return -1;
	}
}

/* strlen that never reads past max bytes (a name without its NUL). */
static size_t bounded_len(const char *s, size_t max)
{
	size_t n = 0;
	while (n < max && s[n])
		n++;
	return n;
}

static int caps_ok(const struct vmac_caps *c)
{
	return c->digital_inputs <= VMAC_DIGITAL_INPUTS && c->digital_outputs <= VMAC_DIGITAL_OUTPUTS &&
	       c->analog_inputs <= VMAC_ANALOG_INPUTS && c->pwm_outputs <= 1 && c->encoders <= 1;
}

static int error_code_ok(uint8_t code)
{
	return code >= VMAC_BERR_NOT_REGISTERED && code <= VMAC_BERR_IDENTITY;
}

static int encode_announce(const struct vmac_announce *a, uint8_t *d, size_t cap)
{
	size_t dl = bounded_len(a->driver, sizeof(a->driver)), bl = bounded_len(a->board, sizeof(a->board));
	size_t n = 17 + dl + bl;
	if (!name_ok((const uint8_t *)a->driver, dl) || !name_ok((const uint8_t *)a->board, bl))
		return VMAC_EPROTO_NAME;
	if (!caps_ok(&a->caps))
		return VMAC_EPROTO_VALUE;
	if (n > cap)
		return VMAC_EPROTO_SPACE;
	*d++ = (uint8_t)dl;
	memcpy(d, a->driver, dl);
	d += dl;
	put32(d, a->major);
	put32(d + 4, a->minor);
	d += 8;
	*d++ = (uint8_t)bl;
	memcpy(d, a->board, bl);
	d += bl;
	*d++ = a->firmware_major;
	*d++ = a->firmware_minor;
	*d++ = a->caps.digital_inputs;
	*d++ = a->caps.digital_outputs;
	*d++ = a->caps.analog_inputs;
	*d++ = a->caps.pwm_outputs;
	*d++ = a->caps.encoders;
	return (int)n;
}

static int decode_announce(const uint8_t *d, size_t len, struct vmac_announce *a)
{
	size_t dl, bl;
	if (len < 17)
		return VMAC_EPROTO_PAYLOAD;
	dl = d[0];
	if (dl + 17 > len)
		return VMAC_EPROTO_PAYLOAD;
	bl = d[1 + dl + 8];
	if (17 + dl + bl != len)
		return VMAC_EPROTO_PAYLOAD;
	if (!name_ok(d + 1, dl) || !name_ok(d + 1 + dl + 9, bl))
		return VMAC_EPROTO_NAME;
	memcpy(a->driver, d + 1, dl);
	a->driver[dl] = '\0';
	a->major = get32(d + 1 + dl);
	a->minor = get32(d + 1 + dl + 4);
	memcpy(a->board, d + 1 + dl + 9, bl);
	a->board[bl] = '\0';
	d += 1 + dl + 9 + bl;
	a->firmware_major = d[0];
	a->firmware_minor = d[1];
	a->caps.digital_inputs = d[2];
	a->caps.digital_outputs = d[3];
	a->caps.analog_inputs = d[4];
	a->caps.pwm_outputs = d[5];
	a->caps.encoders = d[6];
	if (!caps_ok(&a->caps))
		return VMAC_EPROTO_VALUE;
	return 0;
}

/* A frame's 13 bytes of header into buf (the reader is read_header). */
static void put_header(uint8_t *buf, uint8_t version, uint8_t flags, uint16_t seq, uint32_t device_id, uint8_t channel,
                       uint8_t op, uint8_t len)
{
	buf[0] = VMAC_MAGIC0;
	buf[1] = VMAC_MAGIC1;
	buf[2] = version;
	buf[3] = flags;
	put16(buf + 4, seq);
	put32(buf + 6, device_id);
	buf[10] = channel;
	buf[11] = op;
	buf[12] = len;
}

int vmac_proto_encode(const struct vmac_msg *m, uint8_t *buf, size_t cap)
{
	int reply = (m->flags & VMAC_FLAG_REPLY) != 0;
	uint8_t version = m->version ? m->version : 1;
	int want = data_len_for(version, m->channel, m->op, reply);
	uint8_t *d = buf + VMAC_HDR_LEN;
	int n;

	if (version < VMAC_PROTO_VERSION_MIN || version > VMAC_PROTO_VERSION)
		return VMAC_EPROTO_VERSION;
	/* CYCLIC is built in place (vmac_proto_cyclic_begin), never from a msg;
	 * TIMED only on a version-2 UPDATE, request or reply (sealing comes after). */
	if (want == -1 || want == LEN_CYCLIC || (m->flags & ~(VMAC_FLAG_REPLY | VMAC_FLAG_TIMED)) != 0)
		return VMAC_EPROTO_OP;
	if ((m->flags & VMAC_FLAG_TIMED) && (version < 2 || m->channel != VMAC_CH_DEVICE || m->op != VMAC_OP_UPDATE))
		return VMAC_EPROTO_OP;
	if (m->flags & VMAC_FLAG_TIMED)
		want = reply ? VMAC_TIMED_REPLY_LEN : VMAC_TIMED_UPDATE_LEN;
	if (cap < VMAC_HDR_LEN)
		return VMAC_EPROTO_SPACE;
	if ((m->channel == VMAC_CH_SYSTEM) != (m->device_id == 0))
		return VMAC_EPROTO_VALUE;
	if (want == LEN_DISCOVER)
		want = m->u.discover.has_nonce ? VMAC_NONCE_LEN : 0;
	if (want >= 0 && (size_t)want > cap - VMAC_HDR_LEN)
		return VMAC_EPROTO_SPACE;

	n = want;
	switch (m->channel == VMAC_CH_SYSTEM ? SYS_KEY | m->op : (reply << 8) | m->op) {
	case SYS_KEY | VMAC_SYS_DISCOVER:
		if (n)
			memcpy(d, m->u.discover.nonce, VMAC_NONCE_LEN);
		break;
	case SYS_KEY | VMAC_SYS_SYNC:
		put64(d, m->u.sync.host_ns);
		put64(d + 8, m->u.sync.prev_tx_ns);
		break;
	case SYS_KEY | VMAC_SYS_ANNOUNCE: {
		size_t room = cap - VMAC_HDR_LEN;
		n = encode_announce(&m->u.announce, d, room > VMAC_DATA_MAX ? VMAC_DATA_MAX : room);
		if (n < 0)
			return n;
		break;
	}
	case VMAC_OP_REGISTER:
		if (m->u.reg.watchdog_ms < 1 || m->u.reg.watchdog_ms > 60000)
			return VMAC_EPROTO_VALUE;
		put32(d, m->u.reg.major);
		put32(d + 4, m->u.reg.minor);
		put16(d + 8, m->u.reg.watchdog_ms);
		break;
	case VMAC_OP_SHUTDOWN: d[0] = m->u.shutdown_reason; break;
	case VMAC_OP_UPDATE:
		if (!outputs_ok(&m->u.outputs))
			return VMAC_EPROTO_VALUE;
		if (m->flags & VMAC_FLAG_TIMED) { /* the instants first, as a TIMED CYCLIC's before its records */
			put64(d, m->out_at);
			put64(d + 8, m->in_at);
			d += 16;
		}
		d[0] = m->u.outputs.digital;
		put16(d + 1, (uint16_t)m->u.outputs.pwm);
		break;
	case VMAC_OP_SLEEP:
		if (m->u.sleep_s < 1 || m->u.sleep_s > 3600)
			return VMAC_EPROTO_VALUE;
		put16(d, m->u.sleep_s);
		break;
	case VMAC_OP_WATCHDOG:
		if (m->u.watchdog_ms < 1 || m->u.watchdog_ms > 60000)
			return VMAC_EPROTO_VALUE;
		put16(d, m->u.watchdog_ms);
		break;
	case VMAC_OP_OFFSET:
	case 0x100 | VMAC_OP_OFFSET:
	case 0x100 | VMAC_OP_OFFSET_GET: put16(d, m->u.offset); break;
	case 0x100 | VMAC_OP_SIZE:
		if (m->u.record_size == 0)
			return VMAC_EPROTO_VALUE;
		d[0] = m->u.record_size;
		break;
	case 0x100 | VMAC_OP_UPDATE:
	case 0x100 | VMAC_OP_IDLE: {
		const struct vmac_inputs *in = &m->u.inputs;
		if (in->analog[0] > VMAC_ANALOG_MAX || in->analog[1] > VMAC_ANALOG_MAX || !outputs_ok(&in->applied))
			return VMAC_EPROTO_VALUE;
		d[0] = in->digital;
		put16(d + 1, in->analog[0]);
		put16(d + 3, in->analog[1]);
		put32(d + 5, (uint32_t)in->encoder);
		d[9] = in->applied.digital;
		put16(d + 10, (uint16_t)in->applied.pwm);
		if (m->flags & VMAC_FLAG_TIMED) {
			if (!latch_clock_ok(m->latch.clock))
				return VMAC_EPROTO_VALUE;
			put64(d + 12, m->latch.latched_at);
			d[20] = m->latch.clock;
			put32(d + 21, m->latch.bound_ns);
			put64(d + 25, (uint64_t)m->latch.offset_ns);
		}
		break;
	}
	case 0x100 | VMAC_OP_ERROR:
		if (!error_code_ok(m->u.error.code))
			return VMAC_EPROTO_VALUE;
		d[0] = m->u.error.code;
		d[1] = m->u.error.op;
		break;
	default: /* zero-length: REGISTER, SHUTDOWN, SLEEP, WATCHDOG acks; IDLE, SIZE, OFFSET_GET requests */ break;
	}

	put_header(buf, version, m->flags, m->seq, m->device_id, m->channel, m->op, (uint8_t)n);
	return VMAC_HDR_LEN + n;
}

/* m cleared, and its header's fields from buf's 13 bytes. */
static void read_header(const uint8_t *buf, struct vmac_msg *m)
{
	memset(m, 0, sizeof(*m));
	m->version = buf[2];
	m->flags = buf[3];
	m->seq = get16(buf + 4);
	m->device_id = get32(buf + 6);
	m->channel = buf[10];
	m->op = buf[11];
}

/* A sealed SYNC whose header was found sound: host_ns, counter, first,
 * then len MACs (checked one by one, by each board for its own offset). */
static int decode_sync_auth(const uint8_t *buf, size_t len, struct vmac_msg *m)
{
	const uint8_t *d = buf + VMAC_HDR_LEN;
	uint8_t n = buf[12];
	if (n < 1 || n > VMAC_SYNC_AUTH_MACS_MAX || (int)len != vmac_proto_frame_length(buf, len))
		return VMAC_EPROTO_LENGTH;
	if ((buf[3] & ~VMAC_FLAG_AUTH) != 0)
		return VMAC_EPROTO_OP;
	read_header(buf, m);
	m->u.sync.host_ns = get64(d);
	m->u.sync.prev_tx_ns = get64(d + 8);
	m->counter = get64(d + VMAC_SYNC_LEN);
	m->u.sync.first = get16(d + VMAC_SYNC_LEN + VMAC_AUTH_COUNTER_LEN);
	m->u.sync.count = n;
	m->u.sync.frame = buf;
	if (m->device_id != 0 || (unsigned)m->u.sync.first + n > 0xFFFF) /* 0xFFFF is VMAC_OFFSET_NONE */
		return VMAC_EPROTO_VALUE;
	return 0;
}

/* The first checks of any frame: long enough, ours, a version we speak. */
static int check_start(const uint8_t *buf, size_t len)
{
	if (len < VMAC_HDR_LEN)
		return VMAC_EPROTO_SHORT;
	if (buf[0] != VMAC_MAGIC0 || buf[1] != VMAC_MAGIC1)
		return VMAC_EPROTO_MAGIC;
	if (buf[2] < VMAC_PROTO_VERSION_MIN || buf[2] > VMAC_PROTO_VERSION)
		return VMAC_EPROTO_VERSION;
	return 0;
}

/* len counts data bytes, or a CYCLIC frame's records; the frame has room
 * for them, their trailer or first offset, and nothing more; its flags are
 * ones it may carry. */
static int check_length_and_flags(const uint8_t *buf, size_t len)
{
	size_t n = buf[12];
	if ((int)len != vmac_proto_frame_length(buf, len) ||
	    (is_cyclic(buf)
	         ? n < 1 || n > ((buf[3] & VMAC_FLAG_AUTH) ? VMAC_CYCLIC_AUTH_RECORDS_MAX : VMAC_CYCLIC_RECORDS_MAX)
	         : n > VMAC_DATA_MAX))
		return VMAC_EPROTO_LENGTH;
	return flags_ok(buf) ? 0 : VMAC_EPROTO_OP;
}

/* The header read into m: the op valid in its direction, the channel and
 * device id agreeing, the data as long as the op wants; an authenticated
 * frame's counter. */
static int check_op_and_payload(const uint8_t *buf, struct vmac_msg *m)
{
	size_t n = buf[12];
	int want = data_len_for(m->version, m->channel, m->op, (m->flags & VMAC_FLAG_REPLY) != 0);
	if (want == -1)
		return VMAC_EPROTO_OP;
	if ((m->channel == VMAC_CH_SYSTEM) != (m->device_id == 0))
		return VMAC_EPROTO_VALUE;
	if (m->flags & VMAC_FLAG_TIMED && !is_cyclic(buf))
		want = (m->flags & VMAC_FLAG_REPLY) ? VMAC_TIMED_REPLY_LEN : VMAC_TIMED_UPDATE_LEN;
	if (want == LEN_DISCOVER ? n != 0 && n != VMAC_NONCE_LEN : want >= 0 && (size_t)want != n)
		return VMAC_EPROTO_PAYLOAD;
	if ((m->flags & VMAC_FLAG_AUTH) && !is_cyclic(buf))
		m->counter = get64(buf + VMAC_HDR_LEN + n);
	return 0;
}

/* A system frame's data (n bytes at d; CYCLIC: n records). */
static int decode_system(const uint8_t *buf, size_t n, struct vmac_msg *m)
{
	const uint8_t *d = buf + VMAC_HDR_LEN;
	switch (m->op) {
	case VMAC_SYS_DISCOVER:
		m->u.discover.has_nonce = n != 0;
		if (n)
			memcpy(m->u.discover.nonce, d, VMAC_NONCE_LEN);
		break;
	case VMAC_SYS_ANNOUNCE: return decode_announce(d, n, &m->u.announce);
	case VMAC_SYS_SYNC:
		m->u.sync.host_ns = get64(d);
		m->u.sync.prev_tx_ns = get64(d + 8);
		break;
	case VMAC_SYS_CYCLIC:
		/* Records are checked one by one when read (a board reads only its
		 * own): decoding stays O(1) however many the frame carries. */
		m->u.cyclic.first = get16(d);
		m->u.cyclic.count = (uint8_t)n;
		m->u.cyclic.frame = buf;
		m->u.cyclic.records = buf + vmac_proto_cyclic_head_len(buf);
		if (m->flags & VMAC_FLAG_AUTH)
			m->counter = get64(d + 2);
		if (m->flags & VMAC_FLAG_TIMED) {
			const uint8_t *t = m->u.cyclic.records - VMAC_CYCLIC_TIMING_LEN;
			m->u.cyclic.out_at = get64(t);
			m->u.cyclic.in_at = get64(t + 8);
		}
		if ((unsigned)m->u.cyclic.first + n > 0xFFFF) /* 0xFFFF is VMAC_OFFSET_NONE */
			return VMAC_EPROTO_VALUE;
		break;
	default: break;
	}
	return 0;
}

/* UPDATE's and IDLE's reply: the inputs, and a TIMED reply's latch. */
static int decode_inputs(const uint8_t *d, struct vmac_msg *m)
{
	struct vmac_inputs *in = &m->u.inputs;
	in->digital = d[0];
	in->analog[0] = get16(d + 1);
	in->analog[1] = get16(d + 3);
	in->encoder = (int32_t)get32(d + 5);
	in->applied.digital = d[9];
	in->applied.pwm = (int16_t)get16(d + 10);
	if (in->analog[0] > VMAC_ANALOG_MAX || in->analog[1] > VMAC_ANALOG_MAX || !outputs_ok(&in->applied))
		return VMAC_EPROTO_VALUE;
	if (m->flags & VMAC_FLAG_TIMED) {
		m->latch.latched_at = get64(d + 12);
		m->latch.clock = d[20];
		m->latch.bound_ns = get32(d + 21);
		m->latch.offset_ns = (int64_t)get64(d + 25);
		if (!latch_clock_ok(m->latch.clock))
			return VMAC_EPROTO_VALUE;
	}
	return 0;
}

/* A device frame's data, at d (its length already checked). */
static int decode_device(const uint8_t *d, struct vmac_msg *m)
{
	switch (((m->flags & VMAC_FLAG_REPLY) ? 0x100 : 0) | m->op) {
	case VMAC_OP_OFFSET:
	case 0x100 | VMAC_OP_OFFSET:
	case 0x100 | VMAC_OP_OFFSET_GET: m->u.offset = get16(d); break;
	case 0x100 | VMAC_OP_SIZE:
		m->u.record_size = d[0];
		if (m->u.record_size == 0)
			return VMAC_EPROTO_VALUE;
		break;
	case VMAC_OP_REGISTER:
		m->u.reg.major = get32(d);
		m->u.reg.minor = get32(d + 4);
		m->u.reg.watchdog_ms = get16(d + 8);
		if (m->u.reg.watchdog_ms < 1 || m->u.reg.watchdog_ms > 60000)
			return VMAC_EPROTO_VALUE;
		break;
	case VMAC_OP_SHUTDOWN: m->u.shutdown_reason = d[0]; break;
	case VMAC_OP_UPDATE:
		if (m->flags & VMAC_FLAG_TIMED) {
			m->out_at = get64(d);
			m->in_at = get64(d + 8);
			d += 16;
		}
		m->u.outputs.digital = d[0];
		m->u.outputs.pwm = (int16_t)get16(d + 1);
		if (!outputs_ok(&m->u.outputs))
			return VMAC_EPROTO_VALUE;
		break;
	case VMAC_OP_SLEEP:
		m->u.sleep_s = get16(d);
		if (m->u.sleep_s < 1 || m->u.sleep_s > 3600)
			return VMAC_EPROTO_VALUE;
		break;
	case VMAC_OP_WATCHDOG:
		m->u.watchdog_ms = get16(d);
		if (m->u.watchdog_ms < 1 || m->u.watchdog_ms > 60000)
			return VMAC_EPROTO_VALUE;
		break;
	case 0x100 | VMAC_OP_UPDATE:
	case 0x100 | VMAC_OP_IDLE: return decode_inputs(d, m);
	case 0x100 | VMAC_OP_ERROR:
		m->u.error.code = d[0];
		m->u.error.op = d[1];
		if (!error_code_ok(m->u.error.code))
			return VMAC_EPROTO_VALUE;
		break;
	default: break;
	}
	return 0;
}

int vmac_proto_decode(const uint8_t *buf, size_t len, struct vmac_msg *m)
{
	int rc = check_start(buf, len);
	if (rc != 0)
		return rc;
	if (is_sync_auth(buf))
		return decode_sync_auth(buf, len, m);
	rc = check_length_and_flags(buf, len);
	if (rc != 0)
		return rc;
	read_header(buf, m);
	rc = check_op_and_payload(buf, m);
	if (rc != 0)
		return rc;
	return m->channel == VMAC_CH_SYSTEM ? decode_system(buf, buf[12], m) : decode_device(buf + VMAC_HDR_LEN, m);
}

int vmac_proto_frame_length(const uint8_t *buf, size_t len)
{
	int auth;
	if (len < VMAC_HDR_LEN)
		return VMAC_EPROTO_SHORT;
	if (buf[0] != VMAC_MAGIC0 || buf[1] != VMAC_MAGIC1)
		return VMAC_EPROTO_MAGIC;
	auth = (buf[3] & VMAC_FLAG_AUTH) != 0;
	if (is_sync_auth(buf))
		return VMAC_SYNC_AUTH_HEAD_LEN + VMAC_AUTH_MAC_LEN * buf[12];
	if (is_cyclic(buf))
		return (int)vmac_proto_cyclic_head_len(buf) +
		       (auth ? VMAC_CYCLIC_AUTH_RECORD_LEN : VMAC_CYCLIC_RECORD_LEN) * buf[12];
	return VMAC_HDR_LEN + buf[12] + (auth ? VMAC_AUTH_TRAILER_LEN : 0);
}

static int cyclic_begin(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count, int auth,
                        uint64_t counter, const uint64_t *at)
{
	size_t head = VMAC_HDR_LEN + 2 + (auth ? VMAC_AUTH_COUNTER_LEN : 0) + (at ? VMAC_CYCLIC_TIMING_LEN : 0);
	size_t n = head + (size_t)(auth ? VMAC_CYCLIC_AUTH_RECORD_LEN : VMAC_CYCLIC_RECORD_LEN) * count;
	if (count < 1 || count > (auth ? VMAC_CYCLIC_AUTH_RECORDS_MAX : VMAC_CYCLIC_RECORDS_MAX) ||
	    (unsigned)first + count > 0xFFFF)
		return VMAC_EPROTO_VALUE;
	if (n > cap)
		return VMAC_EPROTO_SPACE;
	put_header(buf, 2, (uint8_t)((auth ? VMAC_FLAG_AUTH : 0) | (at ? VMAC_FLAG_TIMED : 0)), seq, 0, VMAC_CH_SYSTEM,
	           VMAC_SYS_CYCLIC, (uint8_t)count);
	put16(buf + VMAC_HDR_LEN, first);
	if (auth)
		put64(buf + VMAC_HDR_LEN + 2, counter);
	if (at) {
		put64(buf + head - VMAC_CYCLIC_TIMING_LEN, at[0]);
		put64(buf + head - 8, at[1]);
	}
	memset(buf + head, 0, n - head);
	return (int)n;
}

int vmac_proto_cyclic_begin(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count)
{
	return cyclic_begin(buf, cap, seq, first, count, 0, 0, NULL);
}

int vmac_proto_cyclic_begin_auth(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count,
                                 uint64_t counter)
{
	return cyclic_begin(buf, cap, seq, first, count, 1, counter, NULL);
}

int vmac_proto_cyclic_begin_timed(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count, int auth,
                                  uint64_t counter, uint64_t out_at, uint64_t in_at)
{
	uint64_t at[2] = {out_at, in_at};
	return cyclic_begin(buf, cap, seq, first, count, auth != 0, counter, at);
}

uint8_t *vmac_proto_cyclic_slot(uint8_t *frame, unsigned index)
{
	return frame + vmac_proto_cyclic_head_len(frame) +
	       (size_t)((frame[3] & VMAC_FLAG_AUTH) ? VMAC_CYCLIC_AUTH_RECORD_LEN : VMAC_CYCLIC_RECORD_LEN) * index;
}

void vmac_proto_cyclic_put(uint8_t *frame, unsigned index, uint16_t tag, uint8_t flags, const struct vmac_outputs *out)
{
	uint8_t *r = vmac_proto_cyclic_slot(frame, index);
	put16(r, tag);
	r[2] = flags;
	r[3] = out->digital;
	put16(r + 4, (uint16_t)out->pwm);
}

int vmac_proto_cyclic_record(const struct vmac_msg *m, uint16_t offset, struct vmac_cyclic_record *rec)
{
	const uint8_t *r;
	if (offset < m->u.cyclic.first || offset - m->u.cyclic.first >= m->u.cyclic.count)
		return 1;
	r = m->u.cyclic.records +
	    (size_t)((m->flags & VMAC_FLAG_AUTH) ? VMAC_CYCLIC_AUTH_RECORD_LEN : VMAC_CYCLIC_RECORD_LEN) *
	        (offset - m->u.cyclic.first);
	rec->tag = get16(r);
	rec->flags = r[2];
	rec->outputs.digital = r[3];
	rec->outputs.pwm = (int16_t)get16(r + 4);
	if ((rec->flags & ~VMAC_CYCLIC_DUE) != 0 || !outputs_ok(&rec->outputs))
		return VMAC_EPROTO_VALUE;
	return 0;
}

void vmac_proto_sync_stamp(uint8_t *buf, uint64_t host_ns)
{
	put64(buf + VMAC_HDR_LEN, host_ns);
}

void vmac_proto_sync_set_prev(uint8_t *buf, uint64_t prev_tx_ns)
{
	put64(buf + VMAC_HDR_LEN + 8, prev_tx_ns);
}

int vmac_proto_sync_begin_auth(uint8_t *buf, size_t cap, uint16_t seq, uint64_t counter, uint16_t first, unsigned count)
{
	size_t n = VMAC_SYNC_AUTH_HEAD_LEN + (size_t)VMAC_AUTH_MAC_LEN * count;
	if (count < 1 || count > VMAC_SYNC_AUTH_MACS_MAX || (unsigned)first + count > 0xFFFF)
		return VMAC_EPROTO_VALUE;
	if (n > cap)
		return VMAC_EPROTO_SPACE;
	put_header(buf, 2, VMAC_FLAG_AUTH, seq, 0, VMAC_CH_SYSTEM, VMAC_SYS_SYNC, (uint8_t)count);
	put64(buf + VMAC_HDR_LEN, 0);
	put64(buf + VMAC_HDR_LEN + 8, 0);
	put64(buf + VMAC_HDR_LEN + VMAC_SYNC_LEN, counter);
	put16(buf + VMAC_HDR_LEN + VMAC_SYNC_LEN + VMAC_AUTH_COUNTER_LEN, first);
	memset(buf + VMAC_SYNC_AUTH_HEAD_LEN, 0, n - VMAC_SYNC_AUTH_HEAD_LEN);
	return (int)n;
}

const char *vmac_proto_strerror(int err)
{
	switch (err) {
	case 0: return "ok";
	case VMAC_EPROTO_SHORT: return "frame shorter than a header";
	case VMAC_EPROTO_MAGIC: return "not a vmac frame (bad magic)";
	case VMAC_EPROTO_VERSION: return "unsupported protocol version";
	case VMAC_EPROTO_LENGTH: return "length byte disagrees with frame size";
	case VMAC_EPROTO_OP: return "unknown op or op not valid in this direction";
	case VMAC_EPROTO_PAYLOAD: return "data size wrong for op";
	case VMAC_EPROTO_NAME: return "empty, oversize or invalid name";
	case VMAC_EPROTO_VALUE: return "field out of range";
	case VMAC_EPROTO_SPACE: return "buffer too small";
	case VMAC_EPROTO_AUTH: return "authentication failed (MAC)";
	default: return "unknown protocol error";
	}
}

const char *vmac_proto_opname(uint8_t channel, uint8_t op)
{
	if (channel == VMAC_CH_SYSTEM)
		return op == VMAC_SYS_DISCOVER   ? "DISCOVER"
		       : op == VMAC_SYS_ANNOUNCE ? "ANNOUNCE"
		       : op == VMAC_SYS_CYCLIC   ? "CYCLIC"
		       : op == VMAC_SYS_SYNC     ? "SYNC"
		                                 : "?";
	if (channel != VMAC_CH_DEVICE)
		return "?";
	switch (op) {
	case VMAC_OP_REGISTER: return "REGISTER";
	case VMAC_OP_SHUTDOWN: return "SHUTDOWN";
	case VMAC_OP_UPDATE: return "UPDATE";
	case VMAC_OP_ERROR: return "ERROR";
	case VMAC_OP_IDLE: return "IDLE";
	case VMAC_OP_SLEEP: return "SLEEP";
	case VMAC_OP_WATCHDOG: return "WATCHDOG";
	case VMAC_OP_SIZE: return "SIZE";
	case VMAC_OP_OFFSET: return "OFFSET";
	case VMAC_OP_OFFSET_GET: return "OFFSET_GET";
	default: return "?";
	}
}

uint32_t vmac_proto_default_major(const char *board)
{
	uint32_t h = 2166136261u;
	while (*board)
		h = (h ^ (uint8_t)*board++) * 16777619u;
	return h;
}
