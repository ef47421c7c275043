/* vmac wire protocol: encode and decode the frames exchanged by host and boards.
 * Portable C99, no heap, no OS headers: the board firmware links this file too.
 * docs/PROTOCOL.md is the byte-by-byte contract; keep the two in step. */
#ifndef VMAC_PROTO_H
#define VMAC_PROTO_H

#include <stddef.h>
#include <stdint.h>

#define VMAC_PROTO_VERSION 1
#define VMAC_MAGIC0 0x56 /* 'V' */
#define VMAC_MAGIC1 0x4D /* 'M' */
#define VMAC_HDR_LEN 13  /* magic(2) version flags seq(2) device_id(4) channel op len */
#define VMAC_DATA_MAX 96
#define VMAC_FRAME_MAX (VMAC_HDR_LEN + VMAC_DATA_MAX)
#define VMAC_NAME_MAX 31 /* printable ASCII bytes, no NUL on the wire */

#define VMAC_FLAG_REPLY 0x01 /* set on every frame a board sends */

/* Channel byte: 0xFF marks a network-system frame (discovery, from the host's
 * network manager itself, as in the thesis); 0x00 a frame of a device session. */
enum vmac_channel { VMAC_CH_DEVICE = 0x00, VMAC_CH_SYSTEM = 0xFF };

enum vmac_sys_op {
	VMAC_SYS_DISCOVER = 0x01, /* host -> group: who is unknown? */
	VMAC_SYS_ANNOUNCE = 0x10, /* board -> host: driver name, major, minor, ... */
};

enum vmac_dev_op {
	VMAC_OP_REGISTER = 0x00, /* assign device id, confirm identity, set watchdog */
	VMAC_OP_SHUTDOWN = 0x01, /* outputs off, forget the session (safe state) */
	VMAC_OP_UPDATE = 0x02,   /* outputs down; reply carries inputs up */
	VMAC_OP_ERROR = 0x03,    /* board -> host only: the request could not be served */
	VMAC_OP_IDLE = 0x04,     /* keep-alive, outputs unchanged; reply carries inputs */
	VMAC_OP_SLEEP = 0x05,    /* outputs off, ignore discovery for N seconds */
	VMAC_OP_WATCHDOG = 0x06, /* set the comm-loss watchdog period */
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

/* Decoder and encoder errors, always negative. */
enum vmac_proto_err {
	VMAC_EPROTO_SHORT = -1,   /* fewer bytes than a header */
	VMAC_EPROTO_MAGIC = -2,   /* not a vmac frame */
	VMAC_EPROTO_VERSION = -3, /* protocol version we do not speak */
	VMAC_EPROTO_LENGTH = -4,  /* len byte disagrees with the datagram size */
	VMAC_EPROTO_OP = -5,      /* unknown channel/op, or op not valid in this direction */
	VMAC_EPROTO_PAYLOAD = -6, /* data size wrong for the op */
	VMAC_EPROTO_NAME = -7,    /* empty, oversize or non-printable name */
	VMAC_EPROTO_VALUE = -8,   /* a field out of its documented range */
	VMAC_EPROTO_SPACE = -9,   /* encode: buffer too small */
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

struct vmac_error {
	uint8_t code; /* enum vmac_board_error */
	uint8_t op;   /* the op of the request that failed */
};

/* One decoded frame. Which member of u is valid depends on channel, op and
 * whether VMAC_FLAG_REPLY is set; see vmac_proto_decode. */
struct vmac_msg {
	uint8_t flags;
	uint16_t seq;       /* host's sequence number, echoed in the reply */
	uint32_t device_id; /* session id the host gave in REGISTER; 0 before */
	uint8_t channel;
	uint8_t op;
	union {
		struct vmac_announce announce; /* ANNOUNCE */
		struct vmac_register reg;      /* REGISTER request */
		struct vmac_outputs outputs;   /* UPDATE request */
		struct vmac_inputs inputs;     /* UPDATE and IDLE replies */
		struct vmac_error error;       /* ERROR reply */
		uint16_t sleep_s;              /* SLEEP request, 1..3600 */
		uint16_t watchdog_ms;          /* WATCHDOG request, 1..60000 */
		uint8_t shutdown_reason;       /* SHUTDOWN request */
	} u;
};

/* Encode msg into buf. Returns the frame length (> 0) or a negative
 * enum vmac_proto_err. Fields out of range are refused, never clipped. */
int vmac_proto_encode(const struct vmac_msg *msg, uint8_t *buf, size_t cap);

/* Decode exactly len bytes of buf into msg. Returns 0 or a negative
 * enum vmac_proto_err; never reads past buf + len. */
int vmac_proto_decode(const uint8_t *buf, size_t len, struct vmac_msg *msg);

/* A short English text for a negative vmac_proto_err. Never NULL. */
const char *vmac_proto_strerror(int err);

/* Name of an op for logs ("UPDATE", "DISCOVER"); "?" when unknown. */
const char *vmac_proto_opname(uint8_t channel, uint8_t op);

/* A board's major id when none is given: the 32-bit FNV-1a hash of its
 * name, so that boards named alike in a test or a simulator get the same
 * identity every run. */
uint32_t vmac_proto_default_major(const char *board);

#endif
