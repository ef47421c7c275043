/* vmac wire protocol: encode and decode the frames exchanged by host and boards.
 * Portable C99, no heap, no OS headers: the board firmware links this file too.
 * docs/PROTOCOL.md is the byte-by-byte contract; keep the two in step. */
#ifndef VMAC_PROTO_H
#define VMAC_PROTO_H

#include <stddef.h>
#include <stdint.h>

#define VMAC_PROTO_VERSION 2     /* the highest version spoken here */
#define VMAC_PROTO_VERSION_MIN 1 /* still served: boards of version 1 */
#define VMAC_MAGIC0 0x56         /* 'V' */
#define VMAC_MAGIC1 0x4D         /* 'M' */
#define VMAC_HDR_LEN 13          /* magic(2) version flags seq(2) device_id(4) channel op len */
#define VMAC_DATA_MAX 96
#define VMAC_FRAME_MAX (VMAC_HDR_LEN + VMAC_DATA_MAX) /* every frame but CYCLIC */
#define VMAC_NAME_MAX 31                              /* printable ASCII bytes, no NUL on the wire */

#define VMAC_FLAG_REPLY 0x01 /* set on every frame a board sends */
#define VMAC_FLAG_AUTH 0x02  /* the frame is authenticated: a trailer (or CYCLIC's record MACs) follows */
#define VMAC_FLAG_TIMED                                                                                                \
	0x04 /* v2: a CYCLIC or an UPDATE request carries the host instants its outputs and latch act at; an           \
	      * UPDATE reply to it, the latch time and the board's clock (docs/TIME.md) */

/* Authenticated frames (docs/PROTOCOL.md, "Authenticated frames"; the
 * keyed functions are in auth.h). A frame with VMAC_FLAG_AUTH carries,
 * after its data, a trailer: a freshness counter (u64: it never wraps) and
 * an 8-byte MAC.
 * A CYCLIC frame with it carries the counter after its first offset and a
 * MAC in each record instead. DISCOVER may carry the host's nonce. */
#define VMAC_AUTH_MAC_LEN 8
#define VMAC_AUTH_COUNTER_LEN 8
#define VMAC_AUTH_TRAILER_LEN (VMAC_AUTH_COUNTER_LEN + VMAC_AUTH_MAC_LEN)
#define VMAC_NONCE_LEN 8
#define VMAC_CYCLIC_AUTH_RECORD_LEN (6 + VMAC_AUTH_MAC_LEN)
#define VMAC_CYCLIC_AUTH_RECORDS_MAX 100 /* 23 + 14 x 100 = 1,423 bytes (TIMED: 1,439): one Ethernet payload */

/* Version 2: the cyclic frame (docs/PROTOCOL.md, "Version 2"). One CYCLIC
 * frame carries fixed-size records at the offsets the host gave each board
 * in its registration; a frame holds at most VMAC_CYCLIC_RECORDS_MAX of
 * them, so it fits one Ethernet payload (1500 bytes). */
#define VMAC_CYCLIC_RECORD_LEN 6 /* tag u16, flags u8, digital u8, pwm i16 */
#define VMAC_CYCLIC_RECORDS_MAX 240
#define VMAC_CYCLIC_TIMING_LEN 16 /* TIMED: out_at u64, in_at u64, after first (and counter) */
#define VMAC_CYCLIC_FRAME_MAX                                                                                          \
	(VMAC_HDR_LEN + 2 + VMAC_CYCLIC_TIMING_LEN + VMAC_CYCLIC_RECORD_LEN * VMAC_CYCLIC_RECORDS_MAX) /* 1471 */
#define VMAC_CYCLIC_DUE 0x01    /* record flag: answer this frame with your inputs */
#define VMAC_OFFSET_NONE 0xFFFF /* OFFSET_GET's answer from a board that has none */
#define VMAC_PACKET_MAX 1500    /* the largest frame of any version: one Ethernet payload */

/* Channel byte: 0xFF marks a network-system frame (discovery, from the host's
 * network manager itself, as in the thesis); 0x00 a frame of a device session. */
enum vmac_channel { VMAC_CH_DEVICE = 0x00, VMAC_CH_SYSTEM = 0xFF };

enum vmac_sys_op {
	VMAC_SYS_DISCOVER = 0x01, /* host -> group: who is unknown? */
	VMAC_SYS_CYCLIC = 0x04,   /* v2, host -> group: outputs of every device due, at their offsets */
	VMAC_SYS_SYNC = 0x05,     /* v2, host -> group: the host's clock at the frame's send (docs/TIME.md) */
	VMAC_SYS_ANNOUNCE = 0x10, /* board -> host: driver name, major, minor, ... */
};

enum vmac_dev_op {
	VMAC_OP_REGISTER = 0x00,   /* assign device id, confirm identity, set watchdog */
	VMAC_OP_SHUTDOWN = 0x01,   /* outputs off, forget the session (safe state) */
	VMAC_OP_UPDATE = 0x02,     /* outputs down; reply carries inputs up */
	VMAC_OP_ERROR = 0x03,      /* board -> host only: the request could not be served */
	VMAC_OP_IDLE = 0x04,       /* keep-alive, outputs unchanged; reply carries inputs */
	VMAC_OP_SLEEP = 0x05,      /* outputs off, ignore discovery for N seconds */
	VMAC_OP_WATCHDOG = 0x06,   /* set the comm-loss watchdog period */
	VMAC_OP_SIZE = 0x07,       /* v2: how many bytes a cyclic record of yours has? */
	VMAC_OP_OFFSET = 0x08,     /* v2: your record's offset in every cyclic frame; echoed */
	VMAC_OP_OFFSET_GET = 0x09, /* v2: which offset do you hold? */
};

/* Error codes carried by VMAC_OP_ERROR replies. */
enum vmac_board_error {
	VMAC_BERR_NOT_REGISTERED = 1, /* device id is not this board's current session */
	VMAC_BERR_BAD_REQUEST = 2,    /* request malformed or not valid in this state */
	VMAC_BERR_IDENTITY = 3,       /* REGISTER named another major/minor */
};

/* Why the host sent SHUTDOWN (informational: the board acts the same). */
enum vmac_shutdown_reason {
	VMAC_SHUT_HOST_STOP = 0,
	VMAC_SHUT_DROPPED = 1,
	VMAC_SHUT_DRIVER = 2,
};

/* Decoder and encoder errors, always negative, in a range of their own
 * (-20001 ..; core/common/errors.h lists the ranges). */
enum vmac_proto_err {
	VMAC_EPROTO_SHORT = -20001,   /* fewer bytes than a header */
	VMAC_EPROTO_MAGIC = -20002,   /* not a vmac frame */
	VMAC_EPROTO_VERSION = -20003, /* protocol version we do not speak */
	VMAC_EPROTO_LENGTH = -20004,  /* len byte disagrees with the datagram size */
	VMAC_EPROTO_OP = -20005,      /* unknown channel/op, or op not valid in this direction */
	VMAC_EPROTO_PAYLOAD = -20006, /* data size wrong for the op */
	VMAC_EPROTO_NAME = -20007,    /* empty, oversize or non-printable name */
	VMAC_EPROTO_VALUE = -20008,   /* a field out of its documented range */
	VMAC_EPROTO_SPACE = -20009,   /* encode: buffer too small */
	VMAC_EPROTO_AUTH = -20010,    /* an authenticated frame whose MAC does not verify */
};

#define VMAC_DIGITAL_OUTPUTS 7
#define VMAC_DIGITAL_INPUTS 8
#define VMAC_ANALOG_INPUTS 2
#define VMAC_PWM_MAX 1000    /* pwm is signed per-mille of full drive, -1000..1000 */
#define VMAC_ANALOG_MAX 4095 /* 12-bit converter counts */

struct vmac_caps {
	uint8_t digital_inputs, digital_outputs, analog_inputs, pwm_outputs, encoders;
};

struct vmac_announce {
	char driver[VMAC_NAME_MAX + 1]; /* NUL-terminated after decode */
	uint32_t major, minor;
	char board[VMAC_NAME_MAX + 1];
	uint8_t firmware_major, firmware_minor;
	struct vmac_caps caps;
};

struct vmac_register {
	uint32_t major, minor; /* must equal the board's own, or it answers IDENTITY */
	uint16_t watchdog_ms;  /* 1..60000 */
};

struct vmac_outputs {
	uint8_t digital; /* bit i = digital output i (0..6); bit 7 must be 0 */
	int16_t pwm;     /* -1000..1000 */
};

struct vmac_inputs {
	uint8_t digital;                     /* bit i = digital input i (0..7) */
	uint16_t analog[VMAC_ANALOG_INPUTS]; /* 0..4095 */
	int32_t encoder;                     /* counts, wraps */
	struct vmac_outputs applied;         /* what the board drives right now */
};

/* One record of a CYCLIC frame, as a board reads it at its offset. */
struct vmac_cyclic_record {
	uint16_t tag;  /* the session it is for: device_id >> 16 (never 0); 0 = no record here */
	uint8_t flags; /* VMAC_CYCLIC_DUE; other bits 0 */
	struct vmac_outputs outputs;
};

/* A decoded CYCLIC frame: records first..first+count-1, still in the
 * frame's bytes (read one with vmac_proto_cyclic_record). */
struct vmac_cyclic {
	uint64_t out_at, in_at; /* TIMED: the host instants (CLOCK_MONOTONIC ns) the records' outputs take
	                         * effect and the DUE records' inputs are latched; 0 when not TIMED */
	uint16_t first;         /* offset of the first record */
	uint8_t count;          /* 1..VMAC_CYCLIC_RECORDS_MAX (authenticated: ..VMAC_CYCLIC_AUTH_RECORDS_MAX) */
	const uint8_t *records; /* into the decoded buffer: valid while it is */
	const uint8_t *frame;   /* the frame itself (an authenticated record's MAC covers its header) */
};

/* DISCOVER's data: none, or the host's nonce of this discovery (a host
 * that authenticates boards sends one; an ANNOUNCE's MAC covers it). */
struct vmac_discover {
	uint8_t has_nonce;
	uint8_t nonce[VMAC_NONCE_LEN];
};

/* SYNC's data (v2, host -> group): the host's CLOCK_MONOTONIC at the
 * frame's send, taken as late as the host can (one-step), then the
 * kernel's transmit time of the previous SYNC of the same stream (the
 * plain frame, or one sealed chunk), 0 when unknown (two-step); the
 * header's seq is the sync sequence number. A board feeds one of them to
 * its clock (firmware/clock.h) with its own receive timestamp. */
#define VMAC_SYNC_LEN 16
/* Sealed (VMAC_FLAG_AUTH; docs/PROTOCOL.md, "Authenticated frames"): one
 * frame for many keyed boards, as the sealed CYCLIC. After host_ns and
 * prev_tx_ns come the host's SYNC counter (u64) and the first offset (u16), then `len` MACs of
 * 8 bytes, MAC i for the board at offset first + i (zeros: no board). */
#define VMAC_SYNC_AUTH_HEAD_LEN (VMAC_HDR_LEN + VMAC_SYNC_LEN + VMAC_AUTH_COUNTER_LEN + 2) /* 39 */
#define VMAC_SYNC_AUTH_MACS_MAX 100 /* 39 + 8 x 100 = 839 bytes */
struct vmac_sync {
	uint64_t host_ns;
	uint64_t prev_tx_ns;  /* the previous SYNC's of this stream, as the kernel stamped its send; 0 unknown */
	uint16_t first;       /* sealed: the offset of the first MAC (the counter is msg->counter) */
	uint8_t count;        /* sealed: the number of MACs, 1..VMAC_SYNC_AUTH_MACS_MAX; 0 unsealed */
	const uint8_t *frame; /* sealed: the frame itself, for vmac_proto_sync_open (auth.h) */
};

/* What a board adds to its UPDATE reply to a TIMED CYCLIC (VMAC_FLAG_TIMED
 * on the reply; 21 bytes after the 12 of inputs): when it latched them and
 * how good its clock is (docs/TIME.md, "Time-triggered I/O"). */
#define VMAC_TIMED_REPLY_LEN 33    /* inputs 12, latched_at u64, clock u8, bound_ns u32, offset_ns i64 */
#define VMAC_CLOCK_STATE_MASK 0x07 /* the clock byte's state: enum vmac_clock_state (firmware/clock.h) */
#define VMAC_LATCH_STATE_MAX 4     /* unsynced 0, locking 1, locked 2, holdover 3, lost 4 */
#define VMAC_CLOCK_ARRIVAL 0x80    /* the clock byte: this service was acted on arrival, not at the instants */
/* A TIMED UPDATE request (version 2, unicast: a board not served by the
 * cyclic frame): out_at u64 and in_at u64 before the 3 bytes of outputs,
 * as a TIMED CYCLIC carries them before its records. */
#define VMAC_TIMED_UPDATE_LEN 19
struct vmac_latch {
	uint64_t latched_at; /* host ns at which the inputs were latched, by the board's clock; 0: it cannot tell */
	uint8_t clock;       /* state (VMAC_CLOCK_STATE_MASK) | VMAC_CLOCK_ARRIVAL */
	uint32_t bound_ns;   /* the clock's estimated error bound, saturating; 0xFFFFFFFF when unknown */
	int64_t offset_ns;   /* the board's counter less host time; 0 when unknown */
};

struct vmac_error {
	uint8_t code; /* enum vmac_board_error */
	uint8_t op;   /* the op of the request that failed */
};

/* One decoded frame. Which member of u is valid depends on channel, op and
 * whether VMAC_FLAG_REPLY is set; see vmac_proto_decode. */
struct vmac_msg {
	uint8_t version; /* decode: the frame's; encode: 0 means 1, the version every board speaks */
	uint8_t flags;
	uint16_t seq;       /* host's sequence number, echoed in the reply */
	uint32_t device_id; /* session id the host gave in REGISTER; 0 before */
	uint8_t channel;
	uint8_t op;
	uint64_t counter; /* decode, VMAC_FLAG_AUTH: the trailer's freshness counter (CYCLIC, SYNC: the frame's) */
	struct vmac_latch latch; /* an UPDATE reply with VMAC_FLAG_TIMED (version 2) */
	uint64_t out_at, in_at;  /* an UPDATE request with VMAC_FLAG_TIMED: the host instants of its
	                          * outputs and its latch (CLOCK_MONOTONIC ns); 0 when not TIMED */
	union {
		struct vmac_discover discover; /* DISCOVER */
		struct vmac_announce announce; /* ANNOUNCE */
		struct vmac_register reg;      /* REGISTER request */
		struct vmac_outputs outputs;   /* UPDATE request */
		struct vmac_inputs inputs;     /* UPDATE and IDLE replies */
		struct vmac_error error;       /* ERROR reply */
		uint16_t sleep_s;              /* SLEEP request, 1..3600 */
		uint16_t watchdog_ms;          /* WATCHDOG request, 1..60000 */
		uint8_t shutdown_reason;       /* SHUTDOWN request */
		uint8_t record_size;           /* v2 SIZE reply: bytes per cyclic record */
		uint16_t offset;               /* v2 OFFSET request and reply, OFFSET_GET reply */
		struct vmac_cyclic cyclic;     /* v2 CYCLIC (decode only; build with vmac_proto_cyclic_*) */
		struct vmac_sync sync;         /* v2 SYNC */
	} u;
};

/* Encode msg into buf. Returns the frame length (> 0) or a negative
 * enum vmac_proto_err. Fields out of range are refused, never clipped.
 * An authenticated frame is encoded plain, then sealed (auth.h). */
int vmac_proto_encode(const struct vmac_msg *msg, uint8_t *buf, size_t cap);

/* Decode exactly len bytes of buf into msg. Returns 0 or a negative
 * enum vmac_proto_err; never reads past buf + len. A frame with
 * VMAC_FLAG_AUTH is decoded with its trailer (msg->counter) but its MAC is
 * not checked here: that needs the key (vmac_proto_open, auth.h). */
int vmac_proto_decode(const uint8_t *buf, size_t len, struct vmac_msg *msg);

/* The total length a frame's header declares (for a transport that pads
 * short frames, e.g. Ethernet to 46 bytes): the frame is buf[0..n). Returns
 * n, or a negative enum vmac_proto_err when the header cannot tell. */
int vmac_proto_frame_length(const uint8_t *buf, size_t len);

/* Start a CYCLIC frame in buf (cap bytes) carrying count records from
 * offset first, every record empty (tag 0). Returns the frame's length or a
 * negative enum vmac_proto_err. */
int vmac_proto_cyclic_begin(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count);
/* The same, authenticated: the frame carries counter, and each record a
 * MAC (vmac_proto_cyclic_seal_record, auth.h, after vmac_proto_cyclic_put). */
int vmac_proto_cyclic_begin_auth(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count,
                                 uint64_t counter);

/* The same, TIMED (auth as above when auth is nonzero): the frame carries
 * the host instants out_at and in_at before its records. */
int vmac_proto_cyclic_begin_timed(uint8_t *buf, size_t cap, uint16_t seq, uint16_t first, unsigned count, int auth,
                                  uint64_t counter, uint64_t out_at, uint64_t in_at);

/* How many bytes of a CYCLIC frame come before its first record (header,
 * first, and the counter and the timing when it has them). */
size_t vmac_proto_cyclic_head_len(const uint8_t *frame);

/* Where record index of a cyclic frame starts (any kind). */
uint8_t *vmac_proto_cyclic_slot(uint8_t *frame, unsigned index);

/* Write record index (0..count-1) of a frame made by vmac_proto_cyclic_begin.
 * The caller keeps outputs in range (the board refuses a bad record). */
void vmac_proto_cyclic_put(uint8_t *frame, unsigned index, uint16_t tag, uint8_t flags, const struct vmac_outputs *out);

/* Read the record at offset from a decoded CYCLIC message. Returns 0, 1 when
 * the frame holds no record at that offset, or VMAC_EPROTO_VALUE for a
 * record with reserved flag bits or outputs out of range. An authenticated
 * frame's record is read here; its MAC is checked by
 * vmac_proto_cyclic_open_record (auth.h). */
int vmac_proto_cyclic_record(const struct vmac_msg *m, uint16_t offset, struct vmac_cyclic_record *r);

/* Write host_ns into an encoded SYNC frame (buf, at least VMAC_HDR_LEN +
 * VMAC_SYNC_LEN bytes): the host stamps it at the last moment before the
 * send, after the frame was built. */
void vmac_proto_sync_stamp(uint8_t *buf, uint64_t host_ns);

/* Write prev_tx_ns (0: unknown) into an encoded SYNC frame, plain or
 * sealed, before it is sealed. */
void vmac_proto_sync_set_prev(uint8_t *buf, uint64_t prev_tx_ns);

/* Start a sealed SYNC frame in buf (cap bytes) for the count offsets from
 * first, with the host's SYNC counter: host_ns 0 (vmac_proto_sync_stamp
 * writes it) and every MAC zero (vmac_proto_sync_seal, auth.h, writes
 * them after the stamp). Returns the frame's length or a negative
 * enum vmac_proto_err. */
int vmac_proto_sync_begin_auth(uint8_t *buf, size_t cap, uint16_t seq, uint64_t counter, uint16_t first,
                               unsigned count);

/* A short English text for a negative vmac_proto_err. Never NULL. */
const char *vmac_proto_strerror(int err);

/* Name of an op for logs ("UPDATE", "DISCOVER"); "?" when unknown. */
const char *vmac_proto_opname(uint8_t channel, uint8_t op);

/* A board's major id when none is given: the 32-bit FNV-1a hash of its
 * name, so that boards named alike in a test or a simulator get the same
 * identity every run. */
uint32_t vmac_proto_default_major(const char *board);

#endif
