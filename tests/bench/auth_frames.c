/* What authenticated frames cost the host's CPU per frame and per board
 * record (docs/PERFORMANCE.md, "Authenticated frames on the host"): the
 * codec calls core/host/bus.c makes, each timed alone on this machine and
 * set beside vmac_proto_encode of the same UPDATE request, the work every
 * request costs with or without a key:
 *
 *   encode        vmac_proto_encode of an UPDATE request (the baseline)
 *   encode+seal   the same, then vmac_proto_seal (bus_queue, keyed board)
 *   decode        vmac_proto_decode of a sealed UPDATE reply
 *   open          vmac_proto_open of that reply (handle_packet, keyed board)
 *   record        vmac_proto_cyclic_put of one record of a CYCLIC frame
 *                 (cyclic_put, a board without a key)
 *   record+seal   the same in a sealed frame, then
 *                 vmac_proto_cyclic_seal_record (cyclic_put, keyed board)
 *   session keys  vmac_proto_session_keys (once a REGISTER, not a tick)
 *   sync          a plain SYNC: vmac_proto_encode and vmac_proto_sync_stamp
 *                 (send_sync and bus_flush, once per clock_sync_ms)
 *   sync sealed   a sealed SYNC for SYNC_BOARDS keyed boards: begin, stamp
 *                 and a MAC per board (send_sync_sealed and sync_stamp):
 *                 what the stamp-to-send delay grows by
 *   sync open     a board's side: vmac_proto_decode of that sealed SYNC and
 *                 vmac_proto_sync_open of its own MAC (O(1))
 *
 * Each figure is the median of REPEATS runs of N operations, in ns per
 * operation. --json prints one JSON object instead of the table (bench.py
 * --only auth reads it):
 *
 *   make build/bench/auth_frames && build/bench/auth_frames [N] [--json] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../core/proto/auth.h"

#define REPEATS 7
#define RECORDS VMAC_CYCLIC_AUTH_RECORDS_MAX /* one full sealed chunk, as 100 boards make */
#define SESSION 0x00030025u
#define SYNC_BOARDS VMAC_SYNC_AUTH_MACS_MAX /* one full sealed SYNC: 100 keyed boards */

static const uint8_t key[VMAC_KEY_LEN] = {0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77,
                                          0x88, 0x99, 0xaa, 0xbb, 0xcc, 0xdd, 0xee, 0xff};
static const uint8_t nonce[VMAC_NONCE_LEN] = {1, 2, 3, 4, 5, 6, 7, 8};
static uint8_t to_board[VMAC_KEY_LEN], to_host[VMAC_KEY_LEN];
static uint8_t reply[VMAC_FRAME_MAX + VMAC_AUTH_TRAILER_LEN];
static size_t reply_len;
static volatile unsigned sink; /* every result feeds it: no loop is optimised away */

static double now_ns(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec * 1e9 + t.tv_nsec;
}

static void update_request(struct vmac_msg *m, unsigned i)
{
	memset(m, 0, sizeof(*m));
	m->version = 2;
	m->seq = (uint16_t)i;
	m->device_id = SESSION;
	m->channel = VMAC_CH_DEVICE;
	m->op = VMAC_OP_UPDATE;
	m->u.outputs.digital = (uint8_t)(i & 0x7f);
	m->u.outputs.pwm = (int16_t)(i % 1000);
}

static void op_encode(unsigned n)
{
	struct vmac_msg m;
	uint8_t buf[VMAC_FRAME_MAX + VMAC_AUTH_TRAILER_LEN];
	unsigned i;
	for (i = 0; i < n; i++) {
		update_request(&m, i);
		sink += (unsigned)vmac_proto_encode(&m, buf, sizeof(buf)) + buf[5];
	}
}

static void op_encode_seal(unsigned n)
{
	struct vmac_msg m;
	uint8_t buf[VMAC_FRAME_MAX + VMAC_AUTH_TRAILER_LEN];
	unsigned i;
	int len;
	for (i = 0; i < n; i++) {
		update_request(&m, i);
		len = vmac_proto_encode(&m, buf, sizeof(buf));
		len = vmac_proto_seal(buf, (size_t)len, sizeof(buf), i + 1, to_board, NULL, 0);
		sink += (unsigned)len + buf[len - 1];
	}
}

static void op_decode(unsigned n)
{
	struct vmac_msg m;
	unsigned i;
	for (i = 0; i < n; i++)
		sink += (unsigned)vmac_proto_decode(reply, reply_len, &m) + m.counter;
}

static void op_open(unsigned n)
{
	unsigned i;
	for (i = 0; i < n; i++)
		sink += (unsigned)vmac_proto_open(reply, reply_len, to_host, NULL, 0);
}

/* n records: frames of RECORDS, each begun then filled, as cyclic_put does. */
static void records(unsigned n, int sealed)
{
	static uint8_t frame[VMAC_PACKET_MAX];
	struct vmac_outputs out = {0x03, 250};
	unsigned i, r;
	for (i = 0; i < n; i += RECORDS) {
		if (sealed)
			vmac_proto_cyclic_begin_auth(frame, sizeof(frame), (uint16_t)i, 0, RECORDS, i + 1);
		else
			vmac_proto_cyclic_begin(frame, sizeof(frame), (uint16_t)i, 0, RECORDS);
		for (r = 0; r < RECORDS; r++) {
			vmac_proto_cyclic_put(frame, r, (uint16_t)(r + 1), VMAC_CYCLIC_DUE, &out);
			if (sealed)
				vmac_proto_cyclic_seal_record(frame, r, to_board);
		}
		sink += frame[VMAC_PACKET_MAX / 2];
	}
}

static void op_record(unsigned n)
{
	records(n, 0);
}

static void op_record_seal(unsigned n)
{
	records(n, 1);
}

static void op_session_keys(unsigned n)
{
	uint8_t tb[VMAC_KEY_LEN], th[VMAC_KEY_LEN];
	unsigned i;
	for (i = 0; i < n; i++) {
		vmac_proto_session_keys(key, nonce, SESSION + i, tb, th);
		sink += tb[0] + th[15];
	}
}

static void op_sync(unsigned n)
{
	static uint8_t frame[VMAC_FRAME_MAX];
	struct vmac_msg m;
	unsigned i;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.channel = VMAC_CH_SYSTEM;
	m.op = VMAC_SYS_SYNC;
	for (i = 0; i < n; i++) {
		m.seq = (uint16_t)i;
		sink += (unsigned)vmac_proto_encode(&m, frame, sizeof(frame));
		vmac_proto_sync_stamp(frame, 5000000000ull + i);
		sink += frame[20];
	}
}

static uint8_t sync_frame[VMAC_PACKET_MAX];
static int sync_len;

static void op_sync_sealed(unsigned n)
{
	unsigned i, b;
	for (i = 0; i < n; i++) {
		sync_len =
		    vmac_proto_sync_begin_auth(sync_frame, sizeof(sync_frame), (uint16_t)i, i + 1, 0, SYNC_BOARDS);
		vmac_proto_sync_stamp(sync_frame, 5000000000ull + i);
		for (b = 0; b < SYNC_BOARDS; b++)
			vmac_proto_sync_seal(sync_frame, b, to_board); /* one key for all: the same work as 100 */
		sink += sync_frame[VMAC_SYNC_AUTH_HEAD_LEN + 8 * (SYNC_BOARDS - 1)];
	}
}

static void op_sync_open(unsigned n)
{
	struct vmac_msg m;
	unsigned i;
	for (i = 0; i < n; i++) {
		sink += (unsigned)vmac_proto_decode(sync_frame, (size_t)sync_len, &m);
		sink += (unsigned)vmac_proto_sync_open(&m, (uint16_t)(i % SYNC_BOARDS), to_board);
	}
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* Median over REPEATS runs of fn(n), in ns per operation. */
static double time_op(void (*fn)(unsigned), unsigned n)
{
	double runs[REPEATS], t0;
	int r;
	fn(n / 10 ? n / 10 : 1); /* warm the caches and the branch predictors */
	for (r = 0; r < REPEATS; r++) {
		t0 = now_ns();
		fn(n);
		runs[r] = (now_ns() - t0) / n;
	}
	qsort(runs, REPEATS, sizeof(runs[0]), cmp_double);
	return runs[REPEATS / 2];
}

/* A sealed UPDATE reply of the session, as a keyed board sends it. */
static int make_reply(void)
{
	struct vmac_msg m;
	int n;
	memset(&m, 0, sizeof(m));
	m.version = 2;
	m.flags = VMAC_FLAG_REPLY;
	m.seq = 7;
	m.device_id = SESSION;
	m.channel = VMAC_CH_DEVICE;
	m.op = VMAC_OP_UPDATE;
	m.u.inputs.digital = 0x81;
	m.u.inputs.analog[0] = 1234;
	m.u.inputs.encoder = -5;
	m.u.inputs.applied.digital = 0x03;
	n = vmac_proto_encode(&m, reply, sizeof(reply));
	if (n > 0)
		n = vmac_proto_seal(reply, (size_t)n, sizeof(reply), 7, to_host, NULL, 0);
	if (n <= 0 || vmac_proto_decode(reply, (size_t)n, &m) != 0 ||
	    vmac_proto_open(reply, (size_t)n, to_host, NULL, 0))
		return -1;
	reply_len = (size_t)n;
	return 0;
}

static const struct {
	const char *name, *what;
	void (*fn)(unsigned);
	unsigned per; /* operations per n: session keys are 100 times slower than a record */
} ops[] = {
    {"encode", "vmac_proto_encode, UPDATE request (the baseline)", op_encode, 1},
    {"encode_seal", "encode + vmac_proto_seal, UPDATE request", op_encode_seal, 1},
    {"decode", "vmac_proto_decode, sealed UPDATE reply", op_decode, 1},
    {"open", "vmac_proto_open, sealed UPDATE reply", op_open, 1},
    {"record", "vmac_proto_cyclic_put, one CYCLIC record", op_record, 1},
    {"record_seal", "cyclic_put + vmac_proto_cyclic_seal_record, one record", op_record_seal, 1},
    {"session_keys", "vmac_proto_session_keys (once a REGISTER)", op_session_keys, 4},
    {"sync", "plain SYNC: encode + vmac_proto_sync_stamp", op_sync, 1},
    {"sync_sealed", "sealed SYNC, 100 keyed boards: begin, stamp, 100 MACs", op_sync_sealed, 100},
    {"sync_open", "a board: decode + vmac_proto_sync_open, sealed SYNC", op_sync_open, 1},
};
#define NOPS (sizeof(ops) / sizeof(ops[0]))

int main(int argc, char **argv)
{
	unsigned n = 1000000, i;
	int json = 0, a;
	double ns[NOPS];
	for (a = 1; a < argc; a++) {
		if (!strcmp(argv[a], "--json"))
			json = 1;
		else
			n = (unsigned)atoi(argv[a]);
	}
	n = n < RECORDS ? RECORDS : n / RECORDS * RECORDS; /* whole CYCLIC frames */
	vmac_proto_session_keys(key, nonce, SESSION, to_board, to_host);
	if (make_reply()) {
		fprintf(stderr, "auth_frames: the sealed reply does not decode and open\n");
		return 1;
	}
	for (i = 0; i < NOPS; i++)
		ns[i] = time_op(ops[i].fn, n / ops[i].per);
	if (json) {
		printf("{\"n\": %u, \"repeats\": %d, \"ns_per_op\": {", n, REPEATS);
		for (i = 0; i < NOPS; i++)
			printf("%s\"%s\": %.2f", i ? ", " : "", ops[i].name, ns[i]);
		printf("}}\n");
		return 0;
	}
	printf("%-58s %9s %9s\n", "", "ns/op", "/ encode");
	for (i = 0; i < NOPS; i++)
		printf("%-58s %9.1f %9.2f\n", ops[i].what, ns[i], ns[i] / ns[0]);
	printf("the MAC alone: seal %.1f ns a request, open %.1f ns a reply, %.1f ns a record\n", ns[1] - ns[0], ns[3],
	       ns[5] - ns[4]);
	printf("a SYNC with %d keyed boards: %.1f ns, %.1f x the plain SYNC; %.1f ns a keyed board\n", SYNC_BOARDS,
	       ns[8], ns[8] / ns[7], (ns[8] - ns[7]) / SYNC_BOARDS);
	return 0;
}
