/* Error codes that cross modules: what a caller branches on (a full disk
 * is a 507, a device that is not running a 404) instead of matching the
 * English text meant for people. A function returns 0 or one of these
 * negated; its message, for people, still goes in its err or reply buffer,
 * and vmac_strerror() names a code. -1 is VMAC_EFAIL, so a function that
 * returned -1 before still reads the same. Header only. */
#ifndef VMAC_ERRORS_H
#define VMAC_ERRORS_H

enum vmac_err {
	VMAC_OK = 0,
	VMAC_EFAIL = 1,   /* anything without a code of its own: the message says what */
	VMAC_ENOTRUNNING, /* no running machine of that name (or the host is stopping) */
	VMAC_EDRIVER,     /* the driver failed in the call: its machine was dropped or rolled back */
	VMAC_EREFUSED,    /* refused: a new version a machine would not take over */
	VMAC_EBUSY,       /* the bus thread took no request, or did not take it in time */
	VMAC_ESTORE,      /* the store could not read or write (not a full disk) */
	VMAC_ESTOREFULL,  /* the store could not write: its disk is full */
};

/* A short text for code (or -code), for people. */
static inline const char *vmac_strerror(int code)
{
	switch (code < 0 ? -code : code) {
	case VMAC_OK: return "no error";
	case VMAC_EFAIL: return "failed";
	case VMAC_ENOTRUNNING: return "not running";
	case VMAC_EDRIVER: return "the driver failed";
	case VMAC_EREFUSED: return "refused";
	case VMAC_EBUSY: return "the host is busy";
	case VMAC_ESTORE: return "the store failed";
	case VMAC_ESTOREFULL: return "the store's disk is full";
	default: return "unknown error";
	}
}

#endif
