/* Plant models in Lua (docs/BOARD.md, "Plant models in Lua"): a user's
 * model of the machine behind one board, in a sandbox of its own built as
 * a driver's is (the same allow-list, memory cap, instruction budget and
 * guarded call), so a plant that raises, loops or eats memory fails alone.
 * Its owner steps it: core/sim/ for vmac-board (real time) and `vmac test`
 * (virtual time). Not thread-safe: one owner thread per plant. */
#ifndef VMAC_LUAPLANT_H
#define VMAC_LUAPLANT_H

#include <stddef.h>
#include <stdint.h>

#include "../common/value.h"
#include "../proto/proto.h"

#define VMAC_LUAPLANT_MEMORY (4u << 20)   /* bytes of the state's heap */
#define VMAC_LUAPLANT_INSTRUCTIONS 200000 /* VM instructions per load, step or action */
#define VMAC_LUAPLANT_BUTTON_S 0.5        /* a button action holds its input on this long */
#define VMAC_LUAPLANT_UNSAFE_MAX 120      /* bytes of an unsafe text kept */
#define VMAC_LUAPLANT_FILE_MAX (1u << 20) /* bytes of a plant file */

struct vmac_luaplant_limits {
	size_t memory_bytes;   /* 0: VMAC_LUAPLANT_MEMORY */
	uint64_t instructions; /* 0: VMAC_LUAPLANT_INSTRUCTIONS */
	uint32_t budget_us;    /* wall clock per call; 0: none (virtual time) */
	uint64_t seed;         /* math.random's seed */
	double time_scale;     /* plant seconds per real second (buttons hold in real time); 0: 1 */
};

struct vmac_luaplant; /* opaque */

/* Load a plant from text (file names it in messages, "plants/dryer.lua";
 * a path too long for Lua's messages by its tail after a '/';
 * default_name is its name when the file gives none). 0 and *out, or -1
 * with err ("plants/dryer.lua:12: ...", "plants/dryer.lua: plant: step
 * must be a function"). */
int vmac_luaplant_load(const char *file, const char *src, size_t len, const char *default_name,
                       const struct vmac_luaplant_limits *lim, struct vmac_luaplant **out, char *err, size_t errlen);
/* The same from a file; its name without ".lua" is the default name. */
int vmac_luaplant_load_file(const char *path, const struct vmac_luaplant_limits *lim, struct vmac_luaplant **out,
                            char *err, size_t errlen);
void vmac_luaplant_free(struct vmac_luaplant *p);

const char *vmac_luaplant_name(const struct vmac_luaplant *p);
const char *vmac_luaplant_driver(const struct vmac_luaplant *p);

/* Advance by dt_s seconds (0 < dt_s <= 0.1) under the outputs last
 * actuated, then read the inputs. 0, or -1 once it has failed (also every
 * call after): vmac_luaplant_failure says why. */
int vmac_luaplant_step(struct vmac_luaplant *p, double dt_s);
/* The inputs the last step (or action) left; a failed plant's hold. */
void vmac_luaplant_sense(const struct vmac_luaplant *p, struct vmac_inputs *in);
void vmac_luaplant_actuate(struct vmac_luaplant *p, const struct vmac_outputs *out);

/* An operator action: 0 done; 1 refused, why says so (nothing changed);
 * -1 the plant failed (now or before). */
int vmac_luaplant_set(struct vmac_luaplant *p, const char *name, double value, char *why, size_t whylen);
/* A field of the state p: 0 and *v (numbers, booleans, strings cut to
 * fit); -1 when there is no such field or it holds another kind, or the
 * plant has failed. "unsafe_episodes" is the count below. */
int vmac_luaplant_field(struct vmac_luaplant *p, const char *name, struct vmac_value *v);

/* Unsafe episodes since load, and the text the step that began the last
 * one returned (as the C washer's line gives the moment it began). */
uint32_t vmac_luaplant_unsafe_episodes(const struct vmac_luaplant *p);
const char *vmac_luaplant_unsafe_text(const struct vmac_luaplant *p);
/* Why it failed, or NULL while it runs. */
const char *vmac_luaplant_failure(const struct vmac_luaplant *p);
/* Wall-clock nanoseconds spent in its calls so far (the bench). */
uint64_t vmac_luaplant_call_ns(const struct vmac_luaplant *p);

#endif
