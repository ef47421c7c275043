/* Checks of an upload before the deploy lock (accept.c); deploy.c's own. */
#ifndef VMAC_ACCEPT_H
#define VMAC_ACCEPT_H

#include <stddef.h>

#include "../bundle/bundle.h"
#include "deploy.h"

/* The signature sig over data (b's bytes) against t: 0 with signer (the
 * key id; "" unsigned and none needed), or -VMAC_ESIG* with err. */
int deploy_check_signature(const struct vmac_deploy_trust *t, const struct vmac_bundle *b, const char *data, size_t len,
                           const char *sig, size_t siglen, char signer[17], char *err, size_t errlen);

/* The HTTP status of a refusal's code. */
int deploy_status_of(int code);

#endif
