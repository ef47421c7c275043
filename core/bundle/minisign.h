/* Checking minisign signatures (https://jedisct1.github.io/minisign/),
 * made with the standard `minisign -S` command, with libsodium: Ed25519
 * over the file ("Ed") or over its BLAKE2b-512 hash ("ED", minisign's
 * default since 0.11), and the global signature over the signature and
 * the trusted comment. docs/SECURITY.md "Signed bundles".
 *
 * A public key file is what `minisign -G` writes (an "untrusted comment:"
 * line, then base64 of "Ed", the 8-byte key id and the 32-byte key); a
 * keys file (vmacd's deploy_keys) holds any number of them, blank lines
 * and lines starting with '#' ignored. A signature is the .minisig file's
 * text. Any thread; no global state. */
#ifndef VMAC_MINISIGN_H
#define VMAC_MINISIGN_H

#include <stddef.h>
#include <stdint.h>

#define VMAC_MINISIGN_KEYS 32
#define VMAC_MINISIGN_COMMENT_MAX 1024
#define VMAC_MINISIGN_SIG_MAX 4096 /* bytes of a .minisig file's text */

struct vmac_minisign_key {
	uint8_t id[8];
	uint8_t pk[32];
	char id_hex[17]; /* the key id as minisign prints it: 16 uppercase hex digits (0.11 leaves out leading zeros) */
};

/* Every key of keys file path into keys (at most max): how many (0: a file
 * without keys), or < 0 with err naming the file and line (not readable,
 * a line that is not a key). */
int vmac_minisign_keys_load(const char *path, struct vmac_minisign_key *keys, int max, char *err, size_t errlen);
/* The same from text in memory (one key file's text, or several). */
int vmac_minisign_keys_parse(const char *text, size_t len, struct vmac_minisign_key *keys, int max, char *err,
                             size_t errlen);

struct vmac_minisign_result {
	int key;     /* index in keys of the key that signed */
	int prehash; /* 1: "ED" (BLAKE2b-512 prehashed), 0: "Ed" */
	char trusted_comment[VMAC_MINISIGN_COMMENT_MAX + 1];
};

/* Check sig (a .minisig file's text, siglen bytes) over data with keys.
 * 0 and *r; else err says why and the code says which:
 *   -VMAC_EBUNDLE     not a minisign signature (malformed text, base64)
 *   -VMAC_ESIGKEY     its key id is none of keys (the id is in err)
 *   -VMAC_ESIGBAD     data is not what was signed
 *   -VMAC_ESIGCOMMENT the trusted comment is not what was signed */
int vmac_minisign_verify(const struct vmac_minisign_key *keys, int nkeys, const void *data, size_t len, const char *sig,
                         size_t siglen, struct vmac_minisign_result *r, char *err, size_t errlen);

#endif
