/* Error codes that cross modules: what a caller branches on (a full disk
 * is a 507, a device that is not running a 404) instead of matching the
 * English text meant for people. A function returns 0, or a negative code:
 * a negated errno (ENOENT: no such file), or a negated VMAC_E* below. Its
 * message, for people, goes in its err or reply buffer; vmac_strerror()
 * names a code of either kind.
 *
 * One int carries three kinds, in ranges that never meet:
 *   -1 .. -4095              a negated errno (Linux's are all below 4096)
 *   -10001 .. -10099         a negated VMAC_E* (this file)
 *   -20001 .. -20099         a wire-codec error, VMAC_EPROTO_* (core/proto/proto.h),
 *                            seen only by the codec's callers
 *   1 .. 99                  a refusal of operator input, vmac_refusal
 *                            (core/driver/driver.h): the driver said no
 * Header only. */
#ifndef VMAC_ERRORS_H
#define VMAC_ERRORS_H

#include <string.h>

#define VMAC_ERR_BASE 10000

/* Each code and its text. */
#define VMAC_ERRORS(X)                                                                                                 \
	X(VMAC_EFAIL, "failed")                        /* without a code of its own: the message says what */          \
	X(VMAC_ENOTRUNNING, "not running")             /* no running machine of that name (or the host is stopping) */ \
	X(VMAC_EDRIVER, "the driver failed")           /* in the call: its machine was dropped or rolled back */       \
	X(VMAC_EREFUSED, "refused")                    /* a new version a machine would not take over */               \
	X(VMAC_EBUSY, "the host is busy")              /* the bus thread took no request, or not in time */            \
	X(VMAC_ESTORE, "the store failed")             /* the store could not read or write (not a full disk) */       \
	X(VMAC_ESTOREFULL, "the store's disk is full") /* the store could not write: its disk is full */               \
	X(VMAC_EBUNDLE, "not a valid bundle")          /* an archive that is not a bundle, or a damaged one */         \
	X(VMAC_ESIGMISSING, "no signature")            /* a signature is required and none came */                     \
	X(VMAC_ESIGKEY, "signed by an unknown key")    /* its key id is none of deploy_keys */                         \
	X(VMAC_ESIGBAD, "the signature does not match") /* the file is not what was signed (tampered) */               \
	X(VMAC_ESIGCOMMENT, "trusted comment altered")  /* the trusted comment is not what was signed */               \
	X(VMAC_ESIGMETA, "signed for another bundle")   /* the trusted comment disagrees with the metadata */          \
	X(VMAC_ECOUNTER, "security counter too low")    /* lower than the highest accepted for that driver */

#define VMAC_ERR_ENUM(name, text) name,
enum vmac_err { VMAC_OK = 0, VMAC_ERR_FIRST_ = VMAC_ERR_BASE, VMAC_ERRORS(VMAC_ERR_ENUM) VMAC_ERR_END_ };
#undef VMAC_ERR_ENUM

/* A short text for code (or -code), for people: a VMAC_E* code's, or
 * strerror's for an errno. */
static inline const char *vmac_strerror(int code)
{
#define VMAC_ERR_TEXT(name, text)                                                                                      \
	case name: return text;
	int c = code < 0 ? -code : code;
	switch (c) {
	case VMAC_OK: return "no error"; VMAC_ERRORS(VMAC_ERR_TEXT)
	default: return c < VMAC_ERR_BASE ? strerror(c) : "unknown error";
	}
#undef VMAC_ERR_TEXT
}

/* A VMAC_E* code's name without "VMAC_" ("ESIGKEY"), what JSON answers
 * carry for programs to branch on; "EFAIL" for any other code. */
static inline const char *vmac_err_name(int code)
{
#define VMAC_ERR_NAME(name, text)                                                                                      \
	case name: return &#name[5]; /* past "VMAC_" */
	switch (code < 0 ? -code : code) {
		VMAC_ERRORS(VMAC_ERR_NAME)
	default: return "EFAIL";
	}
#undef VMAC_ERR_NAME
}

#endif
