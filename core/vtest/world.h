/* The virtual world of `vmac test` (docs/TESTING.md): the real host bus
 * (discovery, schedule, deadlines, sandboxed drivers) and real board
 * firmware with simulated plants, in one process, on one virtual clock.
 * No sockets, no sleeping, no threads: frames travel through a queue ordered
 * by delivery time (ties in send order), so a run is a pure function of the
 * scene, the test's actions and the seed.
 *
 * Time in nanoseconds from the world's start. Each frame takes
 * VT_WIRE_NS to cross, plus any delay a fault adds; plants are stepped on a
 * fixed VT_PLANT_STEP_NS grid; the bus ticks on its own slot grid. */
#ifndef VMAC_VTEST_WORLD_H
#define VMAC_VTEST_WORLD_H

#include <stdint.h>
#include <stdio.h>

#include "../../firmware/board.h"
#include "../config/config.h"
#include "../host/bus.h"
#include "../host/events.h"
#include "../mainloop/mainloop.h"
#include "../sim/sim.h"
#include "../store/store.h"
#include "clocks.h"

#define VT_WIRE_NS 50000LL          /* one way, host <-> board */
#define VT_PLANT_STEP_NS 10000000LL /* physics and board watchdog grid: vmac-board's largest physics sub-step */
#define VT_HISTORY 32               /* services kept per board for failure reports */
#define VT_MAX_BOARDS 64

/* One service of a board as it saw it: inputs sensed, outputs applied. */
struct vt_service {
	int64_t t_ns;
	struct vmac_inputs in;
	struct vmac_outputs out;
};

/* A named I/O of a board, from its driver's manifest. */
struct vt_io {
	char name[VMAC_DRIVER_NAME_MAX + 1];
	enum vmac_io_kind kind;
	unsigned channel;
	double scale, offset;
};

struct vt_faults {
	double drop;           /* fraction of frames lost, both ways */
	double corrupt;        /* fraction of frames with one byte changed */
	double delay_fraction; /* fraction of frames delayed by delay_ns */
	int64_t delay_ns;
	int64_t late_ns; /* every answer of the board leaves this much later */
};

struct vt_board {
	struct vmac_board fw;
	struct vmac_sim sim;   /* the machine behind it: a C or a Lua plant */
	struct vmac_addr addr; /* synthetic, 10.77.0.N:5870 */
	int plugged;           /* 0: frames to and from it are lost (its watchdog runs on) */
	int powered;           /* 0: the board is off: silent, outputs off */
	struct vt_clock clock; /* its free-running counter (clocks.h) */
	/* Its last output change of time-triggered I/O (firmware/timed.c's
	 * `acted`): the true (world) time it was done at, the host instant
	 * the frame asked for, how (enum vmac_timed_how), and how many. */
	struct vt_acted {
		int64_t t_ns;
		uint64_t asked_ns;
		int how;
		unsigned count;
	} acted;
	struct vt_faults faults;
	struct vt_service hist[VT_HISTORY];
	unsigned nhist; /* services recorded so far (the last VT_HISTORY kept) */
	struct vt_io io[VMAC_DRIVER_MAX_IO];
	int nio;
	char io_note[200]; /* why there are no names (driver missing, failed to load) */
	/* The driver's variables declared `update = "timer:N"` (primary board
	 * only), for the failure report: their values are copies up to N s old. */
	struct vt_timer_var {
		char name[VMAC_DRIVER_NAME_MAX + 1];
		double every_s;
	} timers[VMAC_DRIVER_MAX_VARS];
	int ntimers;
};

struct vt_event {
	int64_t t_ns;
	char kind[24];
	char device[VMAC_NAME_MAX + 1];
	char text[VMAC_EVENT_TEXT];
};

struct vt_pkt; /* in flight */

struct vt_world {
	struct vmac_config cfg;
	struct vmac_bus *bus;
	struct vmac_addr bus_group; /* where DISCOVER goes: every board */
	int64_t now_ns;
	int64_t next_plant_ns;
	int64_t host_start_ns; /* when the running host started: its bus time 0 */
	struct vt_board *boards[VT_MAX_BOARDS];
	int nboards;
	struct vt_pkt *q; /* binary heap by (at, order) */
	size_t nq, capq;
	uint64_t order; /* send order, for ties */
	uint64_t rng;   /* xorshift64* state (the seed) */
	uint64_t seed;  /* the run's seed, as given */
	struct vt_event *events;
	size_t nevents, capevents;
	uint64_t frames; /* frames delivered, for the summary */
	/* When checks run (vt_run): `moved` is set by what can change any value a
	 * check reads (a frame delivered, an event, a board's watchdog trip);
	 * `plant_moved` by a plant step, which changes only plant-side values.
	 * A check that read none of those last time (reads_plant, set by the
	 * accessors during the check) cannot change its result on a plant step
	 * alone, so it is not run for one. */
	int moved, plant_moved;
	int reads_plant, check_reads_plant;
	char plant_failure[VMAC_DRIVER_ERR_MAX + 64]; /* a Lua plant failed: vt_run stopped (VT_PLANT_FAILED) */
	FILE *trace;                                  /* CSV of every service, or NULL */
	char trace_test[128];                         /* the running test's name, the CSV's first column */
	struct vmac_device_status status;             /* scratch for vt_device */
	/* The host's main thread (core/mainloop/, as in vmacd) and what it
	 * keeps: the store, in memory, outlives a host (crash_host). */
	struct vmac_mainloop *main;
	struct vmac_event_log log;
	struct vmac_store *store;
	struct { /* driver_cost: given to every host the world starts */
		char driver[VMAC_NAME_MAX + 1];
		int64_t cost_ns;
	} costs[VMAC_BUS_VIRTUAL_COSTS];
};

/* cfg: drivers_dir, scripts_dir, stdlib_dir and limits as the test wants. */
struct vt_world *vt_world_new(const struct vmac_config *cfg, uint64_t seed, char *err, size_t errlen);
void vt_world_free(struct vt_world *w);

/* A board running the firmware with plant `plant` behind it, announcing
 * `driver` (default: the plant's). The plant is a Lua plant when the
 * drivers folder has plants/PLANT.lua (seeded from the run's seed), else
 * the C plant of that name. Its I/O names come from
 * the driver's manifest (loaded once here; a driver that does not load
 * leaves io_note saying why). Returns the board, or NULL with err. */
struct vt_board *vt_board_add(struct vt_world *w, const char *name, const char *plant, const char *driver,
                              uint32_t major, uint32_t minor, char *err, size_t errlen);
struct vt_board *vt_board_find(struct vt_world *w, const char *name);
/* Power: off makes the board silent with outputs off; on starts it afresh
 * (unknown, answering discovery). */
void vt_board_power(struct vt_world *w, struct vt_board *b, int on);

/* vt_run's return when a Lua plant failed (plant_failure says which and why). */
#define VT_PLANT_FAILED (-100)

/* Called at each bus tick at which a frame has been delivered since the
 * last call; a non-zero return stops the run and is returned by vt_run. */
typedef int (*vt_check_fn)(void *ctx);

/* Advance the clock to until_ns (or until check stops it). */
int vt_run(struct vt_world *w, int64_t until_ns, vt_check_fn check, void *ctx);

/* Operator input to a device's driver (vmac_bus_input). */
int vt_input(struct vt_world *w, const char *device, const char *name, const struct vmac_value *value, char *reply,
             size_t replylen);
/* The device as the host sees it now, or NULL when the host has no such device. */
const struct vmac_device_status *vt_device(struct vt_world *w, const char *device);
/* A named I/O of board b now (the board's own view: outputs it drives,
 * inputs its plant gives). 0, or -1 when b's driver has no such name. */
int vt_io_value(struct vt_world *w, const struct vt_board *b, const char *name, double *value, int *is_bool);

/* A host crash: the host is gone at once, with no word to the boards
 * (their watchdogs turn the outputs off); the checkpoints it had handed
 * over stay. Until vt_start_host the world runs without a host (bus NULL). */
void vt_crash_host(struct vt_world *w);
/* Every call of driver `driver` takes cost_ns of virtual time, in this host
 * and the ones started after it. 0, or -1 with err. */
int vt_driver_cost(struct vt_world *w, const char *driver, int64_t cost_ns, char *err, size_t errlen);
/* A new host, its bus clock starting now (also at the world's start). 0, or
 * -1 with err. */
int vt_start_host(struct vt_world *w, char *err, size_t errlen);

/* Stop the host the way vmacd stops (every board told to go safe). */
void vt_stop_host(struct vt_world *w);

#endif
