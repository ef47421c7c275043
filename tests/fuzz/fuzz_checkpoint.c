/* libFuzzer harness for checkpoints (core/driver/checkpoint.c): any bytes
 * offered to a driver as its checkpoint, as a damaged or hostile store
 * could hold them. What must hold: the offer is taken or refused with a
 * reason, never a crash; a taken one reaches recover(dev, saved), whose
 * dev.state then encodes again into no more bytes than it came in (the
 * encoding of what was decoded: entries given twice count once); and the
 * driver ticks on afterwards. Seeds: tests/fuzz/corpus-checkpoint/ (made
 * by make_checkpoint_corpus in the same way: real encodings of dev.state). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../core/driver/driver.h"
#include "fuzz.h"
#include "fuzz_arena.h"

/* recover walks what it got (every key and value, nested), then keeps it
 * as its own dev.state; tick counts. */
static const char DRIVER[] = "local function walk(t, seen, depth)\n"
                             "  if seen[t] or depth > 40 then return 0 end\n"
                             "  seen[t] = true\n"
                             "  local n = 0\n"
                             "  for k, v in pairs(t) do\n"
                             "    n = n + 1\n"
                             "    if type(k) == 'table' then n = n + walk(k, seen, depth + 1) end\n"
                             "    if type(v) == 'table' then n = n + walk(v, seen, depth + 1) end\n"
                             "  end\n"
                             "  return n\n"
                             "end\n"
                             "return { name = 'fuzz', version = '1.0', io = { lamp = 'do0' },\n"
                             "  variables = { n = {} },\n"
                             "  tick = function(dev) dev.out.lamp = not dev.out.lamp end,\n"
                             "  recover = function(dev, saved)\n"
                             "    assert(type(saved.age_s) == 'number' and type(saved.version) == 'string')\n"
                             "    dev.vars.n = walk(saved.state, {}, 0)\n"
                             "    dev.state = saved.state\n"
                             "  end }\n";

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct vmac_checkpoint_info info = {1.7e9, 3.5, "1.0", 1};
	struct vmac_driver *d = NULL;
	struct vmac_inputs in;
	struct vmac_outputs out;
	const struct vmac_inputs *inp[1] = {&in};
	struct vmac_outputs *outp[1] = {&out};
	char err[VMAC_DRIVER_ERR_MAX];
	uint8_t *again;
	size_t len;
	int offered, rc;

	if (size > 65536)
		return 0;
	d = fuzz_arena_fixed_driver("fuzz_checkpoint", DRIVER, sizeof(DRIVER) - 1, 4 << 20, 1000000);
	if (vmac_driver_add_board(d, 0, "primary") != 0)
		abort();
	offered = vmac_driver_offer_checkpoint(d, data, size, &info, err, sizeof(err)) == 0;
	if (!offered && !err[0])
		abort(); /* a refusal says why */
	if (vmac_driver_attach(d, 1, err, sizeof(err)) != 0)
		abort();
	rc = vmac_driver_recover(d, 1, err, sizeof(err));
	if (rc != (offered ? VMAC_RECOVER_DONE : VMAC_RECOVER_NONE)) {
		/* recover may only fail by the walk's budget or the cap, on a huge state */
		if (!(offered && rc < 0 &&
		      (strstr(err, "budget") || strstr(err, "memory") || strstr(err, "instruction"))))
			abort();
		fuzz_arena_done(d);
		return 0;
	}
	if (offered) {
		again = malloc(size);
		if (!again || vmac_driver_checkpoint(d, again, size, &len, err, sizeof(err)) != 0 || len > size) {
			fprintf(stderr, "fuzz_checkpoint: a checkpoint taken does not encode again in %zu bytes: %s\n",
			        size, err);
			abort();
		}
		free(again);
	}
	memset(&in, 0, sizeof(in));
	if (vmac_driver_tick(d, 2, inp, outp, err, sizeof(err)) != 0) {
		fprintf(stderr, "fuzz_checkpoint: the driver does not tick after recover: %s\n", err);
		abort();
	}
	fuzz_arena_done(d);
	return 0;
}
