/* What one step of a plant model in Lua costs (core/driver/luaplant.c
 * through core/sim/, as vmac-board steps it),
 * next to the C washer (firmware/plants/washer.c) stepped the same way in
 * the same run, both at 1 kHz (dt = 1 ms) of plant time:
 *
 *   c_washer   vmac_sim_step + vmac_sim_sense of the C washer, its drum
 *              driven and a valve open
 *   lua        the same of the Lua plant in FILE, its outputs all on
 *
 * Each figure is the median of REPEATS runs, each running STEPS steps of
 * each plant in turn, in us per step; the ratio is the median of the
 * runs' own ratios. --json prints one JSON object (bench.py --only plant):
 *
 *   make build/bench/plant_step && build/bench/plant_step FILE [--json] */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../core/sim/sim.h"

#define REPEATS 11
#define STEPS 20000
#define DT_S 0.001

static volatile unsigned sink; /* every result feeds it: no loop is optimised away */

static double now_us(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec * 1e6 + t.tv_nsec / 1e3;
}

/* us per step of STEPS steps of s. */
static double run(struct vmac_sim *s)
{
	struct vmac_inputs in;
	double t0 = now_us();
	int i;
	for (i = 0; i < STEPS; i++) {
		if (vmac_sim_step(s, DT_S) != 0) {
			fprintf(stderr, "plant_step: the plant failed: %s\n", vmac_sim_failure(s));
			exit(1);
		}
		vmac_sim_sense(s, &in);
		sink += in.analog[0] + in.digital;
	}
	return (now_us() - t0) / STEPS;
}

static int cmp(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

static double median(double *v, int n)
{
	qsort(v, (size_t)n, sizeof(*v), cmp);
	return v[n / 2];
}

int main(int argc, char **argv)
{
	struct vmac_sim c, lua;
	struct vmac_luaplant_limits lim;
	struct vmac_outputs drive;
	double c_us[REPEATS], lua_us[REPEATS], ratio[REPEATS];
	char err[512];
	int i, json = argc > 2 && strcmp(argv[2], "--json") == 0;

	if (argc < 2 || argv[1][0] == '-') {
		fprintf(stderr, "usage: plant_step FILE [--json]  (FILE: a plant model in Lua)\n");
		return 2;
	}
	memset(&lim, 0, sizeof(lim));
	lim.seed = 1;
	if (vmac_sim_init_c(&c, "washer") != 0 || vmac_sim_init_lua(&lua, argv[1], &lim, err, sizeof(err)) != 0) {
		fprintf(stderr, "plant_step: %s\n", err);
		return 2;
	}
	drive.digital = 0x7F; /* every output on: valves, heater, lock, whatever the plant has */
	drive.pwm = 400;
	vmac_sim_actuate(&c, &drive);
	vmac_sim_actuate(&lua, &drive);
	for (i = 0; i < REPEATS; i++) {
		c_us[i] = run(&c);
		lua_us[i] = run(&lua);
		ratio[i] = lua_us[i] / c_us[i];
	}
	if (json)
		printf("{\"steps\": %d, \"repeats\": %d, \"us_per_step\": {\"c_washer\": %.4f, \"lua\": %.4f}, "
		       "\"ratio_to_c_washer\": %.2f, \"plant\": \"%s\"}\n",
		       STEPS, REPEATS, median(c_us, REPEATS), median(lua_us, REPEATS), median(ratio, REPEATS),
		       vmac_sim_name(&lua));
	else
		printf("C washer %.4f us/step, Lua %s %.4f us/step, %.2f x the C washer (median of %d runs of %d "
		       "steps)\n",
		       median(c_us, REPEATS), vmac_sim_name(&lua), median(lua_us, REPEATS), median(ratio, REPEATS),
		       REPEATS, STEPS);
	vmac_sim_fini(&lua);
	vmac_sim_fini(&c);
	return 0;
}
