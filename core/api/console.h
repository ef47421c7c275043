/* The line console of docs/CLI.md ("Console"), after Olsen and Heyerdahl,
 * "Symbolic Access To Embedded Controllers" (1994), on the host: a line of
 * submessages
 *   DEVICE.NAME?  DEVICE.NAME:VALUE  DEVICE.NAME>VALUE  DEVICE.NAME!
 * answered on one line, DEVICE.NAME:VALUE (or > or !) or DEVICE.NAME#CODE.
 * Served as POST /api/console (docs/API.md); `vmac console` is its client.
 * The host's side is reached through ops, so this file knows no HTTP. */
#ifndef VMAC_API_CONSOLE_H
#define VMAC_API_CONSOLE_H

#include <stddef.h>

#include "../host/bus.h"

/* Error codes of a `#` answer (docs/CLI.md, "Console"). */
enum vmac_console_code {
	VMAC_CON_SYNTAX = 1,    /* the submessage does not parse */
	VMAC_CON_DEVICE = 2,    /* no running device of that name */
	VMAC_CON_NAME = 3,      /* no such variable or param (?), or no such variable, param or command */
	VMAC_CON_REFUSED = 4,   /* the driver refused the value */
	VMAC_CON_READ_ONLY = 5, /* a published variable an operator may not set */
	VMAC_CON_PERSIST = 6,   /* > on what is not a persist = true param, or the store could not keep it */
	VMAC_CON_ACCESS = 7,    /* the token lacks the scope (operate for : > !) */
	VMAC_CON_HOST = 8,      /* the host is busy or could not do it */
};

struct vmac_console_ops {
	/* The running device called name, from a status at most 100 ms old
	 * (one per line), or NULL; valid until the next call. */
	const struct vmac_device_status *(*device)(void *ctx, const char *name);
	/* Operator input (with req->persist: set and keep). Returns an HTTP
	 * status as POST /api/devices/NAME/input answers it; msg says why on
	 * anything but 200. */
	unsigned (*input)(void *ctx, struct vmac_bus_input_request *req, char *msg, size_t msglen);
	void *ctx;
	int may_operate; /* the caller's token has scope operate */
	/* Each submessage that writes (:, > or !) as it was answered,
	 * DEVICE.NAME:VALUE or DEVICE.NAME#CODE, and its device, for the audit
	 * trail; NULL: not told. */
	void (*wrote)(void *ctx, const char *device, const char *answer);
};

/* Answer one line (without its newline) into answer (one line, no newline)
 * and each error's message for people, "DEVICE.NAME: why\n", into errors.
 * Returns the number of # answers. */
int vmac_console_line(const struct vmac_console_ops *ops, const char *line, char *answer, size_t answerlen,
                      char *errors, size_t errorslen);

#endif
