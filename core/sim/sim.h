/* The simulated machine behind one board (docs/BOARD.md): a C plant of
 * firmware/plants/ (washer, dishwasher, lights, generic) or a user's plant
 * model in Lua (core/driver/luaplant.h), behind one interface, so that
 * vmac-board (real time) and `vmac test` (virtual time) treat both alike:
 * the board's I/O, steps, operator actions, fields for tests, the safety
 * monitor and, for a Lua plant, a failure that stops it alone. */
#ifndef VMAC_SIM_H
#define VMAC_SIM_H

#include <stddef.h>
#include <stdint.h>

#include "../../firmware/board.h"
#include "../../firmware/plant.h"
#include "../common/value.h"
#include "../driver/luaplant.h"

#define VMAC_SIM_MAX_STEP_S 0.1 /* a longer step is taken in pieces of this */

struct vmac_sim {
	struct vmac_plant c;       /* a C plant, when lua is NULL */
	struct vmac_luaplant *lua; /* a Lua plant */
	int failure_told;          /* vmac_sim_step returned -2 for the failure */
};

/* A C plant by name ("washer"): 0, or -1 for no such C plant. */
int vmac_sim_init_c(struct vmac_sim *s, const char *kind);
/* A Lua plant from its file: 0, or -1 with err. */
int vmac_sim_init_lua(struct vmac_sim *s, const char *path, const struct vmac_luaplant_limits *lim, char *err,
                      size_t errlen);
void vmac_sim_fini(struct vmac_sim *s);

/* Its name ("washer", "dryer") and the driver its board announces by default. */
const char *vmac_sim_name(const struct vmac_sim *s);
const char *vmac_sim_driver(const struct vmac_sim *s);
/* The capabilities its board announces (every plant sits on the generic board). */
struct vmac_caps vmac_sim_caps(const struct vmac_sim *s);

/* Advance by dt_s seconds (longer steps in VMAC_SIM_MAX_STEP_S pieces).
 * 0; -2 the first time a Lua plant has failed (vmac_sim_failure says why;
 * its inputs hold from then on); -1 on each later call. */
int vmac_sim_step(struct vmac_sim *s, double dt_s);
void vmac_sim_sense(const struct vmac_sim *s, struct vmac_inputs *in);
void vmac_sim_actuate(struct vmac_sim *s, const struct vmac_outputs *out);

/* An operator action: 0 done, or -1 refused with why (also: the plant has failed). */
int vmac_sim_set(struct vmac_sim *s, const char *name, double value, char *why, size_t whylen);
/* A field of the plant's state for tests (docs/TESTING.md, `b.plant`):
 * 0 and *v, or -1 when it has none of that name. */
int vmac_sim_field(struct vmac_sim *s, const char *name, struct vmac_value *v);
/* The C plant's field names, for messages ("drum_rpm water_l ..."). */
const char *vmac_sim_fields_text(const struct vmac_sim *s);

/* Its safety monitor as the report reads it (s must outlive the view). */
struct vmac_plant_safety vmac_sim_safety(const struct vmac_sim *s);
uint32_t vmac_sim_unsafe_episodes(const struct vmac_sim *s);
/* Why a Lua plant failed, or NULL. */
const char *vmac_sim_failure(const struct vmac_sim *s);

/* The board's I/O adapters (struct vmac_board_io): ctx is a struct vmac_sim *. */
extern const struct vmac_board_io vmac_sim_io;

#endif
