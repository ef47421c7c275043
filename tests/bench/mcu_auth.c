/* The cost of authenticated frames on the Cortex-M3 (docs/PERFORMANCE.md,
 * "Authenticated frames on the Cortex-M3"): the firmware's own
 * vmac_board_receive, built as the firmware is (make mcu-auth-bench), on
 * the frames a served board gets most, unkeyed and keyed: a unicast UPDATE
 * and a CYCLIC frame whose record for the board is due. Each run of
 * RUNS frames sits between two calls of bench_mark(phase);
 * tests/bench/mcu_auth.py runs this image in QEMU with one instruction per
 * translation block and counts, from QEMU's execution trace, the
 * instructions between the marks (and their cycles by the Cortex-M3's
 * timing table). Frames are made before a run's first mark: what is
 * counted is the board's work alone. Exits through semihosting, with
 * failure unless every frame was answered. */
#include <string.h>

#include "../../core/proto/auth.h"
#include "../../firmware/board.h"

#define RUNS 32
#define SESSION 0x00030025u
#define OFFSET 0x25

int main(void);
void bench_mark(int phase);

static const uint8_t key[VMAC_KEY_LEN] = {0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77,
                                          0x88, 0x99, 0xaa, 0xbb, 0xcc, 0xdd, 0xee, 0xff};
static const uint8_t nonce[VMAC_NONCE_LEN] = {1, 2, 3, 4, 5, 6, 7, 8};

static void read_inputs(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	memset(in, 0, sizeof(*in));
	in->digital = 0x81;
}

static void write_outputs(void *ctx, const struct vmac_outputs *out)
{
	(void)ctx;
	(void)out;
}

static const struct vmac_board_io io = {read_inputs, write_outputs};

static struct vmac_board board;
static uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
static uint64_t host_counter;
static uint8_t frames[RUNS][64];
static int lens[RUNS];
static uint8_t reply[VMAC_BOARD_REPLY_MAX];
static volatile int replied; /* keeps every reply's work observable */

/* A phase boundary the trace finds by this function's address. */
__attribute__((noinline)) void bench_mark(int phase)
{
	__asm__ volatile("" : : "r"(phase) : "memory");
}

/* QEMU exits 0 on success, 1 else. */
static void semihosting_exit(int ok)
{
	register uint32_t op __asm__("r0") = 0x18; /* SYS_EXIT */
	/* ADP_Stopped_ApplicationExit, or ADP_Stopped_RunTimeErrorUnknown */
	register uint32_t why __asm__("r1") = ok ? 0x20026u : 0x20023u;
	__asm__ volatile("bkpt 0xab" : : "r"(op), "r"(why) : "memory");
}

static int put(struct vmac_msg *m, uint8_t *buf, int keyed)
{
	int n = vmac_proto_encode(m, buf, 64);
	if (keyed && n > 0)
		n = vmac_proto_seal(buf, (size_t)n, 64, ++host_counter, to_board, NULL, 0);
	return n;
}

static void request(struct vmac_msg *m, uint8_t channel, uint8_t op, uint32_t device_id)
{
	memset(m, 0, sizeof(*m));
	m->version = 2;
	m->channel = channel;
	m->op = op;
	m->device_id = device_id;
	m->seq = 1;
}

/* A board of the session SESSION at OFFSET, keyed or not, as a host makes it. */
static void session(int keyed)
{
	struct vmac_board_identity id;
	struct vmac_msg m;
	uint8_t buf[64];
	int n;
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "washer");
	strcpy(id.board, "washer-1");
	id.major = 3;
	id.caps.digital_outputs = 7;
	id.keyed = (uint8_t)keyed;
	memcpy(id.key, key, sizeof(key));
	vmac_board_init(&board, &id, &io, NULL, 0);
	vmac_proto_session_keys(key, nonce, SESSION, to_board, to_host);
	host_counter = 0;
	request(&m, VMAC_CH_SYSTEM, VMAC_SYS_DISCOVER, 0);
	m.version = 1;
	m.u.discover.has_nonce = 1;
	memcpy(m.u.discover.nonce, nonce, sizeof(nonce));
	n = put(&m, buf, 0);
	vmac_board_receive(&board, buf, (size_t)n, 0, reply, sizeof(reply));
	request(&m, VMAC_CH_DEVICE, VMAC_OP_REGISTER, SESSION);
	m.u.reg.major = 3;
	m.u.reg.watchdog_ms = 60000;
	n = put(&m, buf, keyed);
	vmac_board_receive(&board, buf, (size_t)n, 0, reply, sizeof(reply));
	request(&m, VMAC_CH_DEVICE, VMAC_OP_OFFSET, SESSION);
	m.u.offset = OFFSET;
	n = put(&m, buf, keyed);
	vmac_board_receive(&board, buf, (size_t)n, 0, reply, sizeof(reply));
}

static void updates(int keyed)
{
	struct vmac_msg m;
	int i;
	for (i = 0; i < RUNS; i++) {
		request(&m, VMAC_CH_DEVICE, VMAC_OP_UPDATE, SESSION);
		m.u.outputs.digital = (uint8_t)i;
		lens[i] = put(&m, frames[i], keyed);
	}
}

static void cyclics(int keyed)
{
	struct vmac_outputs out = {0x03, 0};
	int i;
	for (i = 0; i < RUNS; i++) {
		if (keyed) {
			lens[i] = vmac_proto_cyclic_begin_auth(frames[i], sizeof(frames[i]), (uint16_t)i, OFFSET, 1,
			                                       ++host_counter);
			vmac_proto_cyclic_put(frames[i], 0, (uint16_t)(SESSION >> 16), VMAC_CYCLIC_DUE, &out);
			vmac_proto_cyclic_seal_record(frames[i], 0, to_board);
		} else {
			lens[i] = vmac_proto_cyclic_begin(frames[i], sizeof(frames[i]), (uint16_t)i, OFFSET, 1);
			vmac_proto_cyclic_put(frames[i], 0, (uint16_t)(SESSION >> 16), VMAC_CYCLIC_DUE, &out);
		}
	}
}

/* Phase p: RUNS frames received between bench_mark(p) and bench_mark(p + 100). */
static void run(int phase)
{
	int i;
	bench_mark(phase);
	for (i = 0; i < RUNS; i++)
		replied += vmac_board_receive(&board, frames[i], (size_t)lens[i], 1, reply, sizeof(reply)) > 0;
	bench_mark(phase + 100);
}

int main(void)
{
	int keyed;
	for (keyed = 0; keyed <= 1; keyed++) {
		session(keyed);
		updates(keyed);
		run(1 + 2 * keyed); /* 1: unkeyed UPDATE, 3: keyed */
		cyclics(keyed);
		run(2 + 2 * keyed); /* 2: unkeyed CYCLIC, 4: keyed */
	}
	bench_mark(0);
	semihosting_exit(replied == 4 * RUNS); /* every frame answered, or the count means nothing */
	for (;;)
		;
}
