/* The cost of one driver tick through the driver API (vmac_driver_tick):
 * a small driver reading an analog and a digital input and setting two
 * outputs and a variable, N times. Prints microseconds per tick, and then
 * what loading the same driver into a fresh sandbox and freeing it costs
 * (vmac_driver_load_source + vmac_driver_free, N / 100 times: what every
 * input of a fuzz target that runs Lua pays, docs/RELIABILITY.md); compare
 * two builds of core/driver/ in the same run to see what a change costs:
 *
 *   make build/bench/driver_tick && build/bench/driver_tick 300000 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../core/driver/driver.h"

int main(int argc, char **argv)
{
	struct vmac_driver_limits l;
	memset(&l, 0, sizeof l);
	l.memory_bytes = 4 << 20;
	l.instructions = 200000;
	l.budget_us = 2000;
	l.max_level = 10;
	l.default_level = 4;
	l.expect_name = "t";
	const char *src = "return { name = 't', version = '1', io = { a = 'ai0', b = 'di1', lamp = 'do0', m = 'pwm' }, "
	                  "variables = { v = {} },\n"
	                  "tick = function(dev, inputs) dev.out.lamp = inputs.b; dev.out.m = inputs.a > 10 and 100 or "
	                  "0; dev.vars.v = inputs.a end }";
	struct vmac_driver *d;
	char err[512];
	if (vmac_driver_load_source("t.lua", src, strlen(src), &l, &d, err, sizeof err)) {
		puts(err);
		return 1;
	}
	vmac_driver_add_board(d, 0, "b0");
	struct vmac_inputs in;
	memset(&in, 0, sizeof in);
	struct vmac_outputs o;
	const struct vmac_inputs *ins[1] = {&in};
	struct vmac_outputs *outs[1] = {&o};
	int n = argc > 1 ? atoi(argv[1]) : 300000;
	struct timespec a, b;
	clock_gettime(CLOCK_MONOTONIC, &a);
	for (int i = 0; i < n; i++) {
		in.analog[0] = i & 31;
		in.digital = i & 2;
		if (vmac_driver_tick(d, i * 0.001, ins, outs, err, sizeof err)) {
			puts(err);
			return 1;
		}
	}
	clock_gettime(CLOCK_MONOTONIC, &b);
	printf("%.3f us/tick\n", ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / n / 1000.0);
	vmac_driver_free(d);
	n = n / 100 > 0 ? n / 100 : 1;
	clock_gettime(CLOCK_MONOTONIC, &a);
	for (int i = 0; i < n; i++) {
		if (vmac_driver_load_source("t.lua", src, strlen(src), &l, &d, err, sizeof err)) {
			puts(err);
			return 1;
		}
		vmac_driver_free(d);
	}
	clock_gettime(CLOCK_MONOTONIC, &b);
	printf("%.1f us per load and free of a sandboxed driver\n",
	       ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / n / 1000.0);
	return 0;
}
