/* What an upload must pass before any machine sees it (docs/SECURITY.md
 * "Signed bundles", docs/API.md "Drivers: hot reload"): it is a bundle of
 * the driver it is sent for, signed by a trusted key when one is needed,
 * with a trusted comment that agrees with it, and it compiles. The counter
 * and version rules need the store and run under the deploy lock
 * (deploy.c). */
#include "accept.h"

#include <stdio.h>
#include <string.h>

#include "../common/errors.h"
#include "../loader/loader.h"

int vmac_deploy_trust_load(const struct vmac_config *cfg, struct vmac_deploy_trust *t, char *err, size_t errlen)
{
	memset(t, 0, sizeof(*t));
	if (cfg->deploy_keys[0]) {
		int n = vmac_minisign_keys_load(cfg->deploy_keys, t->keys, VMAC_MINISIGN_KEYS, err, errlen);
		if (n < 0)
			return n;
		if (n == 0) {
			snprintf(err, errlen, "deploy_keys %s holds no minisign public key", cfg->deploy_keys);
			return -VMAC_EFAIL;
		}
		t->nkeys = n;
	}
	t->require = strcmp(cfg->deploy_require_signature, "yes") == 0 ||
	             (strcmp(cfg->deploy_require_signature, "auto") == 0 && t->nkeys > 0);
	return 0;
}

int deploy_check_signature(const struct vmac_deploy_trust *t, const struct vmac_bundle *b, const char *data, size_t len,
                           const char *sig, size_t siglen, char signer[17], char *err, size_t errlen)
{
	struct vmac_minisign_result r;
	int rc;
	signer[0] = 0;
	if (!sig || !siglen) {
		if (!t || !t->require)
			return 0;
		snprintf(err, errlen,
		         "this host takes signed bundles only (deploy_require_signature): sign %s %s with minisign -S "
		         "and send the .minisig with it",
		         b->name, b->version);
		return -VMAC_ESIGMISSING;
	}
	if (!t || t->nkeys == 0) {
		snprintf(err, errlen, "the bundle is signed, but this host has no deploy_keys to check it with");
		return -VMAC_ESIGKEY;
	}
	if ((rc = vmac_minisign_verify(t->keys, t->nkeys, data, len, sig, siglen, &r, err, errlen)) != 0)
		return rc;
	if ((rc = vmac_bundle_comment_check(b, r.trusted_comment, err, errlen)) != 0)
		return rc;
	snprintf(signer, 17, "%s", t->keys[r.key].id_hex);
	return 0;
}

int deploy_status_of(int code)
{
	switch (-code) {
	case VMAC_EBUNDLE: return 400;
	case VMAC_ESIGMISSING:
	case VMAC_ESIGKEY:
	case VMAC_ESIGBAD:
	case VMAC_ESIGCOMMENT:
	case VMAC_ESIGMETA: return 403;
	case VMAC_ESTOREFULL: return 507;
	case VMAC_ESTORE: return 500;
	default: return code == -VMAC_EFAIL ? 400 : 409;
	}
}
