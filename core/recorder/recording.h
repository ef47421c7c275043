/* A recording: a captured flight recorder as a file (docs/RECORDING.md,
 * format version 1: JSON lines, a header, one line per tick or event in
 * time order, an end line with the counts and a BLAKE2b hash of all before
 * it). Written by the main thread of vmacd, read by `vmac test --replay`. */
#ifndef VMAC_RECORDING_H
#define VMAC_RECORDING_H

#include <stddef.h>

#include "recorder.h"

#define VMAC_RECORDING_FORMAT 1

/* The text of recorder r, with the driver's source (src, srclen; NULL when
 * unknown), the bundle it came in (bundle, bundlelen; NULL when unknown or
 * none: docs/DRIVERS.md "Bundles") and when it was captured (Unix time):
 * malloc'd, *len bytes, or NULL (out of memory). */
char *vmac_recording_write(const struct vmac_recorder *r, const char *src, size_t srclen, const char *bundle,
                           size_t bundlelen, double captured, size_t *len);

/* A recording read back: the header's fields and the records in order. */
struct vmac_recording_line {
	int64_t t_ns;
	int is_tick;
	int nboards; /* ticks */
	struct vmac_inputs in[VMAC_REC_BOARDS];
	struct vmac_outputs out[VMAC_REC_BOARDS];
	unsigned has_at;                /* bit i: board i's line has its "at" */
	int64_t at_ns[VMAC_REC_BOARDS]; /* its inputs' instant, bus time (dev.boards[i].t x 1e9) */
	struct vmac_rec_event ev;       /* events */
};

struct vmac_recording {
	char machine[VMAC_REC_NAME_MAX + 1], driver[VMAC_REC_NAME_MAX + 1], version[VMAC_REC_NAME_MAX + 1];
	char reason[VMAC_REC_TEXT_MAX + 1];
	double captured, period_s;
	unsigned level;
	int64_t attach_ns;
	int complete; /* every tick since attach is in it */
	int nboards;
	struct {
		char name[VMAC_REC_NAME_MAX + 1];
		uint32_t minor;
	} boards[VMAC_REC_BOARDS];
	char *source; /* malloc'd, NUL-terminated; NULL when the recording has none */
	size_t source_len;
	/* The bus time the recorded version took over from another at a hot
	 * reload (0: it ran since attach): the ticks before ran the other. */
	int64_t took_over_ns;
	char *bundle; /* the bundle's bytes (malloc'd; NULL when the recording has none), its hash checked */
	size_t bundle_len;
	/* Not complete: dev.state after the machine's tick at state_t_ns, as a
	 * checkpoint encodes it (malloc'd; NULL when the recording has none). */
	uint8_t *state;
	size_t state_len;
	int64_t state_t_ns;
	struct vmac_recording_line *lines; /* malloc'd */
	size_t nlines, nticks, nevents;
};

/* Parse text (len bytes). 0, or -1 with err: "recording truncated: ...",
 * "recording damaged: ...", "not a vmac recording", "recording in format N,
 * this vmac reads 1". */
int vmac_recording_read(const char *text, size_t len, struct vmac_recording *out, char *err, size_t errlen);
void vmac_recording_free(struct vmac_recording *r);

/* The name of an event kind in the file ("input", "miss", ...), or NULL. */
const char *vmac_rec_kind_name(int kind);

#endif
