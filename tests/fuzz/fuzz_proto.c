/* libFuzzer harness for the wire codec and the board state machine: any bytes
 * that decode must re-encode to the same bytes, and a board fed any bytes must
 * answer only with well-formed replies and never drive outputs outside a
 * session; a keyed board (docs/PROTOCOL.md, "Authenticated frames") fed the
 * same bytes never starts a session at all: no input can forge its MACs.
 * Every frame comes with a receive time, so SYNC frames of any host time
 * reach the board's clock (firmware/clock.c); a SYNC is never answered.
 * Build and run: see tests/fuzz/make_corpus.c (firmware/clock.c linked too). */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/proto/proto.h"
#include "../../firmware/board.h"
#include "fuzz_session.h"

struct fake_io {
	struct vmac_outputs driven; /* the last write_outputs */
};

static void fake_read_inputs(void *ctx, struct vmac_inputs *in)
{
	(void)ctx;
	in->digital = 0xA5;
	in->analog[0] = 0;
	in->analog[1] = VMAC_ANALOG_MAX;
	in->encoder = -1;
}

static void fake_write_outputs(void *ctx, const struct vmac_outputs *out)
{
	struct fake_io *io = ctx;
	io->driven = *out;
}

static const struct vmac_board_io fake_hal = {fake_read_inputs, fake_write_outputs};

static void board_start(struct vmac_board *b, struct fake_io *io, int keyed)
{
	struct vmac_board_identity id;
	memset(&id, 0, sizeof(id));
	strcpy(id.driver, "fuzz_motor");
	strcpy(id.board, "fuzz-board");
	id.major = FUZZ_BOARD_MAJOR;
	id.minor = FUZZ_BOARD_MINOR;
	id.caps.digital_inputs = VMAC_DIGITAL_INPUTS;
	id.caps.digital_outputs = VMAC_DIGITAL_OUTPUTS;
	id.caps.analog_inputs = VMAC_ANALOG_INPUTS;
	id.caps.pwm_outputs = 1;
	id.caps.encoders = 1;
	id.keyed = (uint8_t)keyed;
	memset(id.key, 0x5a, sizeof(id.key)); /* a key the fuzzer is not told */
	memset(io, 0, sizeof(*io));
	vmac_board_init(b, &id, &fake_hal, io, 0);
}

/* What must hold after every step, whatever the board was sent. */
static void check_board(const struct vmac_board *b, const struct fake_io *io)
{
	if (b->outputs.digital != io->driven.digital || b->outputs.pwm != io->driven.pwm)
		abort(); /* the board's idea of its outputs differs from the pins */
	if (b->state != VMAC_BOARD_KNOWN && (b->outputs.digital != 0 || b->outputs.pwm != 0))
		abort(); /* outputs on without a session */
	if ((b->state == VMAC_BOARD_KNOWN) != (b->device_id != 0))
		abort();
}

/* A decodable frame must re-encode byte for byte: one wire form per message.
 * A CYCLIC frame is built in place (vmac_proto_cyclic_begin/put), from the
 * records read back one by one; a record out of range is refused on reading
 * and copied raw. An authenticated frame is encoded plain and given its
 * trailer (or its records their MACs) from the input: the MACs themselves
 * are the auth tests' (tests/unit/test_auth.c), not the codec's. A TIMED
 * CYCLIC is begun with its instants; a TIMED UPDATE request or reply
 * re-encodes from the message, its instants or latch in it. The sealed
 * SYNC is built in place, as CYCLIC, its MACs copied. */
static void check_codec(const uint8_t *data, size_t size)
{
	struct vmac_msg msg;
	uint8_t again[VMAC_PACKET_MAX];
	int n, auth;

	if (vmac_proto_decode(data, size, &msg) != 0)
		return;
	auth = (msg.flags & VMAC_FLAG_AUTH) != 0;
	if (msg.channel == VMAC_CH_SYSTEM && msg.op == VMAC_SYS_CYCLIC) {
		size_t len = auth ? VMAC_CYCLIC_AUTH_RECORD_LEN : VMAC_CYCLIC_RECORD_LEN;
		unsigned i;
		if (msg.flags & VMAC_FLAG_TIMED) /* its instants before the records */
			n = vmac_proto_cyclic_begin_timed(again, sizeof(again), msg.seq, msg.u.cyclic.first,
			                                  msg.u.cyclic.count, auth, msg.counter, msg.u.cyclic.out_at,
			                                  msg.u.cyclic.in_at);
		else
			n = auth ? vmac_proto_cyclic_begin_auth(again, sizeof(again), msg.seq, msg.u.cyclic.first,
			                                        msg.u.cyclic.count, msg.counter)
			         : vmac_proto_cyclic_begin(again, sizeof(again), msg.seq, msg.u.cyclic.first,
			                                   msg.u.cyclic.count);
		if (n < 0 || (size_t)n != size)
			abort();
		for (i = 0; i < msg.u.cyclic.count; i++) {
			struct vmac_cyclic_record r;
			int rc = vmac_proto_cyclic_record(&msg, (uint16_t)(msg.u.cyclic.first + i), &r);
			size_t at = (size_t)(vmac_proto_cyclic_slot(again, i) - again);
			if (rc == 0)
				vmac_proto_cyclic_put(again, i, r.tag, r.flags, &r.outputs);
			else if (rc == VMAC_EPROTO_VALUE)
				memcpy(again + at, data + at, 6);
			else
				abort(); /* every offset of the frame holds a record */
			if (auth)
				memcpy(again + at + 6, data + at + 6, len - 6);
		}
		if (memcmp(again, data, size) != 0)
			abort();
		return;
	}
	if (auth && msg.channel == VMAC_CH_SYSTEM && msg.op == VMAC_SYS_SYNC) {
		/* the sealed SYNC: built in place too, its MACs copied */
		n = vmac_proto_sync_begin_auth(again, sizeof(again), msg.seq, msg.counter, msg.u.sync.first,
		                               msg.u.sync.count);
		if (n < 0 || (size_t)n != size)
			abort();
		vmac_proto_sync_stamp(again, msg.u.sync.host_ns);
		vmac_proto_sync_set_prev(again, msg.u.sync.prev_tx_ns);
		memcpy(again + VMAC_SYNC_AUTH_HEAD_LEN, data + VMAC_SYNC_AUTH_HEAD_LEN, size - VMAC_SYNC_AUTH_HEAD_LEN);
		if (memcmp(again, data, size) != 0)
			abort();
		return;
	}
	msg.flags &= (uint8_t)~VMAC_FLAG_AUTH;
	n = vmac_proto_encode(&msg, again, sizeof(again));
	if (n < 0 || (size_t)n + (auth ? VMAC_AUTH_TRAILER_LEN : 0) != size)
		abort();
	if (auth) {
		uint64_t counter = 0;
		int i;
		again[3] |= VMAC_FLAG_AUTH;
		memcpy(again + n, data + n, VMAC_AUTH_TRAILER_LEN);
		for (i = 0; i < VMAC_AUTH_COUNTER_LEN; i++)
			counter = counter << 8 | data[n + i];
		if (msg.counter != counter)
			abort(); /* the counter decoded is the trailer's, all 64 bits */
	}
	if (memcmp(again, data, size) != 0)
		abort();
}

static void deliver(struct vmac_board *b, struct fake_io *io, const uint8_t *frame, size_t len, uint64_t now_ms)
{
	uint8_t reply[VMAC_BOARD_REPLY_MAX]; /* exactly the documented bound, so ASan sees overflow */
	struct vmac_msg request, answer;
	int request_ok = vmac_proto_decode(frame, len, &request) == 0;
	int n = vmac_board_receive_at(b, frame, len, now_ms, now_ms * 1000000u, reply, sizeof(reply));

	if (n < 0 || n > VMAC_BOARD_REPLY_MAX)
		abort();
	if (n > 0 && request_ok && request.channel == VMAC_CH_SYSTEM && request.op == VMAC_SYS_SYNC)
		abort(); /* a SYNC is never answered */
	if ((unsigned)b->clock.state > VMAC_CLOCK_LOST)
		abort();
	if (b->id.keyed && (b->state == VMAC_BOARD_KNOWN || (n > 0 && request.channel != VMAC_CH_SYSTEM)))
		abort(); /* a keyed board obeyed or answered a frame no one could have sealed */
	if (n > 0) {
		if (!request_ok)
			abort(); /* answered a frame it could not decode */
		if (vmac_proto_decode(reply, (size_t)n, &answer) != 0)
			abort();
		if (!(answer.flags & VMAC_FLAG_REPLY) || answer.seq != request.seq)
			abort();
	}
	check_board(b, io);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct vmac_board board;
	struct fake_io io;
	uint64_t now_ms;
	size_t at;
	int keyed;

	check_codec(data, size);

	for (keyed = 0; keyed <= 1; keyed++) {
		/* The whole input as one datagram to a fresh board. */
		board_start(&board, &io, keyed);
		deliver(&board, &io, data, size, 0);

		/* The input as a timed session of datagrams, see fuzz_session.h. */
		board_start(&board, &io, keyed);
		for (at = 0, now_ms = 0; at + 2 <= size;) {
			size_t len = data[at + 1];
			now_ms += (uint64_t)data[at] * FUZZ_STEP_MS;
			at += 2;
			if (len > size - at)
				len = size - at;
			vmac_board_poll(&board, now_ms);
			vmac_board_clock_poll(&board, now_ms * 1000000u);
			check_board(&board, &io);
			deliver(&board, &io, data + at, len, now_ms);
			at += len;
		}
	}
	return 0;
}
