/* The communication scheduler: which device the bus services in which time
 * slice of which slot (thesis 4.1.3, Appendix I). Portable C11, no OS calls;
 * every byte it uses is allocated by vmac_sched_new, so the bus thread can
 * call everything else. docs/SCHEDULER.md explains the model, the switch-over
 * rule and why it is safe.
 *
 * Model: time is cut into slices, S slices make a slot, 2^K slots make a
 * block. A device at level n (0 <= n <= K) is serviced once every 2^n slots,
 * always in the same slice, at slots offset, offset + 2^n, ... A device needs
 * 2^(K-n) of the S * 2^K slice-slots of a block; a device is admitted if the
 * sum over all admitted devices stays within S * 2^K.
 *
 * Guarantees, for a caller that calls vmac_sched_slot for every slot:
 *   - every table in force is even: the fullest slot holds at most one device
 *     more than the emptiest (Appendix I), and no two devices share a slice;
 *   - a change never postpones a running device: after a switch of tables its
 *     next service comes no later than the old table would have given it, so
 *     no device ever waits longer than the period it had at its last service
 *     (an extra, earlier service can happen);
 *   - changes take effect at a slot boundary the scheduler picks, normally at
 *     once, at worst after a wait (see vmac_sched_pending). Until then the old
 *     table runs unchanged, minus removed devices. */
#ifndef VMAC_SCHED_H
#define VMAC_SCHED_H

#include <stddef.h>
#include <stdint.h>

#define VMAC_SCHED_MAX_LEVEL 12   /* 4096 slots per block */
#define VMAC_SCHED_MAX_SLICES 256 /* slices per slot */

struct vmac_sched;

/* One service in a slot: slice index (0 = first in the slot) and the level
 * the device is serviced at (its period is 1 << level slots). */
struct vmac_sched_entry {
	uint32_t device;
	uint16_t slice;
	uint8_t level;
};

enum vmac_sched_state {
	VMAC_SCHED_WAITING = 1, /* admitted, not in the table yet: not serviced */
	VMAC_SCHED_RUNNING = 2, /* in the table; level may differ from want_level */
};

/* A device as status shows it. level/offset/slice describe the table in
 * force (valid when state is RUNNING); want_level is what was asked for. */
struct vmac_sched_device {
	uint32_t device;
	enum vmac_sched_state state;
	unsigned level, offset, slice;
	unsigned want_level;
};

/* A scheduler for slices_per_slot (1..VMAC_SCHED_MAX_SLICES) slices per slot,
 * levels 0..max_level (max_level <= VMAC_SCHED_MAX_LEVEL: a block is
 * 1 << max_level slots) and at most max_devices devices (1..65535; more than
 * slices_per_slot << max_level can never fit and are not reserved).
 * Returns NULL on bad arguments or out of memory. */
struct vmac_sched *vmac_sched_new(unsigned slices_per_slot, unsigned max_level, unsigned max_devices);
void vmac_sched_free(struct vmac_sched *s);

/* Admit `device` (any id the caller likes) at `level`. It is serviced from
 * the slot at which the scheduler switches it in (normally the next one).
 * Returns 0, or with a text in err:
 *   -EINVAL  level out of range
 *   -EEXIST  device already admitted
 *   -ENOSPC  not enough free capacity, or max_devices reached
 *            ("schedule full: need level 3 (1 slice every 8 slots, 16
 *            slice-slots per block), free capacity 2 of 1280 slice-slots per
 *            block"); nothing changes. */
int vmac_sched_add(struct vmac_sched *s, uint32_t device, unsigned level, char *err, size_t errlen);

/* Forget `device`: it is not serviced from the next vmac_sched_slot on; its
 * capacity is free at once. Returns 0 or -ENOENT. */
int vmac_sched_remove(struct vmac_sched *s, uint32_t device);

/* Ask for a new level. Admission is checked as for add with the device's
 * current share counted as free; on -ENOSPC or -EINVAL nothing changes and
 * the device keeps running at its level. The new level is in force from the
 * switch on; until then the device runs at its old one. Returns 0, -EINVAL,
 * -ENOENT or -ENOSPC (text in err). */
int vmac_sched_set_level(struct vmac_sched *s, uint32_t device, unsigned level, char *err, size_t errlen);

/* The services of absolute slot number `slot` (the caller's slot counter,
 * slot % (1 << max_level) is the row of the table). Call once per slot with
 * strictly increasing numbers; this is where pending changes are switched in
 * (before the slot's services are listed). Writes the entries in slice order
 * to out and returns their count (at most slices_per_slot); -ENOBUFS if max
 * is smaller than the count (nothing written, the switch still happened);
 * -EINVAL if slot is not greater than the previous call's. */
int vmac_sched_slot(struct vmac_sched *s, uint64_t slot, struct vmac_sched_entry *out, int max);

/* ---- read access for status (any time, no side effects) ---- */

unsigned vmac_sched_slices(const struct vmac_sched *s);    /* S */
unsigned vmac_sched_max_level(const struct vmac_sched *s); /* K; a block is 1 << K slots */

/* Devices serviced in row `row` (0 .. (1 << K) - 1) of the table in force. */
unsigned vmac_sched_load(const struct vmac_sched *s, unsigned row);

/* Slice-slots per block: *used by admitted devices (at their wanted levels),
 * *total = S << K. */
void vmac_sched_capacity(const struct vmac_sched *s, unsigned *used, unsigned *total);

/* One device's state; 0 or -ENOENT. */
int vmac_sched_device(const struct vmac_sched *s, uint32_t device, struct vmac_sched_device *out);

/* Every admitted device, in admission order; returns how many there are
 * (fills at most max). */
int vmac_sched_devices(const struct vmac_sched *s, struct vmac_sched_device *out, int max);

/* Changes not yet in force (waiting adds, level changes, removals whose
 * slices are still reserved), and for how many slots the oldest of them has
 * waited (0 when none). */
unsigned vmac_sched_pending(const struct vmac_sched *s, uint64_t *waited_slots);

#endif
