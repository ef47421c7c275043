/* Checking minisign signatures and reading the keys that may make them
 * (minisign.h): a .minisig file's text parsed strictly, then checked with
 * libsodium's Ed25519 as `minisign -V` checks it.
 *
 * FORMATS
 *
 * A public key is two lines: "untrusted comment: ..." and the base64 of
 * 42 bytes, "Ed" (the algorithm), the key id (8 random bytes) and the
 * Ed25519 public key (32). A keys file holds any number of them; a key's
 * comment line may be left out; blank lines and '#' lines are ignored.
 *
 * A signature is four lines, each ending in "\n" or "\r\n" (the last may
 * end the text instead):
 *   1  "untrusted comment: " and anything (not signed, never used)
 *   2  the base64 of 74 bytes: the algorithm, "Ed" (Ed25519 over the file)
 *      or "ED" (Ed25519 over the file's BLAKE2b-512 hash, unkeyed), the
 *      id of the key that signed, the signature (64)
 *   3  "trusted comment: " and the trusted comment
 *   4  the base64 of the global signature: Ed25519, by the same key, over
 *      the signature of line 2 followed by the trusted comment's bytes
 *
 * INVARIANTS
 *
 * Nothing past a bound is read: the whole text is at most
 * VMAC_MINISIGN_SIG_MAX bytes, each comment at most
 * VMAC_MINISIGN_COMMENT_MAX. Base64 is the standard alphabet, padded and
 * canonical, nothing around it. A trusted comment is printable UTF-8 (a
 * tab allowed), as minisign 0.12 requires, so it is safe in a log line or
 * a JSON string. A NUL byte anywhere makes the text malformed: the comment
 * handed back is then never a prefix of the one that was signed. */
#include "minisign.h"

#include <errno.h>
#include <sodium.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../common/errors.h"
#include "../common/file.h"

#define KEYS_FILE_MAX (64u << 10) /* bytes of a keys file */
#define UNTRUSTED_PREFIX "untrusted comment: "
#define TRUSTED_PREFIX "trusted comment: "
#define PREFIX_LEN(p) (sizeof(p) - 1)
#define ALG_LEN 2
#define ID_LEN 8
#define PK_LEN crypto_sign_PUBLICKEYBYTES        /* 32 */
#define SIG_LEN crypto_sign_BYTES                /* 64 */
#define PREHASH_LEN crypto_generichash_BYTES_MAX /* 64: BLAKE2b-512 */
#define KEY_BIN_LEN (ALG_LEN + ID_LEN + PK_LEN)  /* 42 */
#define SIG_BIN_LEN (ALG_LEN + ID_LEN + SIG_LEN) /* 74 */
#define SIG_LINES 4

/* A .minisig file's lines, decoded; comment points into the caller's text. */
struct sig_text {
	uint8_t alg[ALG_LEN], id[ID_LEN], sig[SIG_LEN], global[SIG_LEN];
	const char *comment;
	size_t comment_len;
};

/* Where a walk through a text's lines has got to. */
struct lines {
	const char *pos, *end;
	int number; /* of the line last taken, from 1 */
};

/* The next line at ls: its text and length without its "\n" (or "\r\n"):
 * 1, or 0 at the end of the text. A last line without "\n" is a line; a
 * '\r' not before a '\n' stays in the line. */
static int next_line(struct lines *ls, const char **line, size_t *len)
{
	const char *nl;
	if (ls->pos >= ls->end)
		return 0;
	nl = memchr(ls->pos, '\n', (size_t)(ls->end - ls->pos));
	*line = ls->pos;
	*len = (size_t)((nl ? nl : ls->end) - ls->pos);
	ls->pos = nl ? nl + 1 : ls->end;
	if (nl && *len > 0 && (*line)[*len - 1] == '\r')
		(*len)--;
	ls->number++;
	return 1;
}

static int starts_with(const char *line, size_t len, const char *prefix, size_t prefix_len)
{
	return len >= prefix_len && memcmp(line, prefix, prefix_len) == 0;
}

/* Exactly len bytes from b64 (standard alphabet, padded, canonical,
 * nothing else): 0, or -1. The alphabet is checked here because
 * sodium_base642bin (libsodium 1.0.18) reads a byte of 0x80 or more as a
 * digit ('/'). */
static int decode_exact(const char *b64, size_t b64_len, uint8_t *bin, size_t len)
{
	size_t got = 0, i;
	for (i = 0; i < b64_len; i++) {
		char c = b64[i];
		if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '+' ||
		      c == '/' || c == '='))
			return -1;
	}
	if (sodium_base642bin(bin, len, b64, b64_len, NULL, &got, NULL, sodium_base64_VARIANT_ORIGINAL) != 0)
		return -1;
	return got == len ? 0 : -1;
}

/* A key id as minisign prints it (its "%016" PRIX64 of the id read as a
 * little-endian number): the 8 bytes last to first, uppercase hex. */
static void id_to_hex(const uint8_t id[ID_LEN], char hex[2 * ID_LEN + 1])
{
	static const char digits[] = "0123456789ABCDEF";
	int i;
	for (i = 0; i < ID_LEN; i++) {
		hex[2 * i] = digits[id[ID_LEN - 1 - i] >> 4];
		hex[2 * i + 1] = digits[id[ID_LEN - 1 - i] & 15];
	}
	hex[2 * ID_LEN] = 0;
}

/* UTF-8 without control characters (C0 but tab, DEL, C1), overlong forms,
 * surrogates or code points past U+10FFFF: what minisign 0.12 accepts in
 * a trusted comment. */
static int printable_utf8(const unsigned char *s, size_t len)
{
	size_t i = 0, need, k;
	uint32_t cp;
	while (i < len) {
		unsigned c = s[i++];
		if (c == '\t' || (c >= 0x20 && c < 0x7f))
			continue;
		if (c >= 0xc2 && c <= 0xdf)
			need = 1;
		else if (c >= 0xe0 && c <= 0xef)
			need = 2;
		else if (c >= 0xf0 && c <= 0xf4)
			need = 3;
		else
			return 0;
		cp = c & (0x3f >> need);
		if (len - i < need)
			return 0;
		for (k = 0; k < need; k++, i++) {
			if ((s[i] & 0xc0) != 0x80)
				return 0;
			cp = cp << 6 | (s[i] & 0x3f);
		}
		if (cp <= 0x9f || (need == 2 && cp < 0x800) || (cp >= 0xd800 && cp <= 0xdfff) ||
		    (need == 3 && (cp < 0x10000 || cp > 0x10ffff)))
			return 0;
	}
	return 1;
}

__attribute__((format(printf, 3, 4))) static int fail(char *err, size_t errlen, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(err, errlen, fmt, ap);
	va_end(ap);
	return -1;
}

/* ---- keys ---- */

/* One key line's base64 into keys[*n] (not added again when the same key is
 * there already): 0, or -1 with err. */
static int add_key(const char *line, size_t len, int number, struct vmac_minisign_key *keys, int *n, int max, char *err,
                   size_t errlen)
{
	uint8_t bin[KEY_BIN_LEN];
	struct vmac_minisign_key k;
	int i;
	if (decode_exact(line, len, bin, sizeof(bin)) != 0 || memcmp(bin, "Ed", ALG_LEN) != 0)
		return fail(err, errlen,
		            "line %d: not a minisign public key (the base64 of \"Ed\", a key id and an Ed25519 key, "
		            "as the second line of a file `minisign -G` writes)",
		            number);
	memcpy(k.id, bin + ALG_LEN, ID_LEN);
	memcpy(k.pk, bin + ALG_LEN + ID_LEN, PK_LEN);
	id_to_hex(k.id, k.id_hex);
	for (i = 0; i < *n; i++) {
		if (memcmp(keys[i].id, k.id, ID_LEN) != 0)
			continue;
		if (memcmp(keys[i].pk, k.pk, PK_LEN) != 0)
			return fail(err, errlen, "line %d: key id %s is already another key's", number, k.id_hex);
		return 0;
	}
	if (*n >= max)
		return fail(err, errlen, "line %d: one key more than the %d allowed", number, max);
	keys[(*n)++] = k;
	return 0;
}

/* A line of spaces and tabs only, or none. */
static int is_blank(const char *line, size_t len)
{
	size_t i;
	for (i = 0; i < len; i++)
		if (line[i] != ' ' && line[i] != '\t')
			return 0;
	return 1;
}

int vmac_minisign_keys_parse(const char *text, size_t len, struct vmac_minisign_key *keys, int max, char *err,
                             size_t errlen)
{
	struct lines ls = {text, text ? text + len : text, 0};
	const char *line;
	size_t line_len;
	int n = 0, comment_line = 0; /* the "untrusted comment:" line waiting for its key */
	while (next_line(&ls, &line, &line_len)) {
		if (comment_line && (is_blank(line, line_len) || line[0] == '#' ||
		                     starts_with(line, line_len, UNTRUSTED_PREFIX, PREFIX_LEN(UNTRUSTED_PREFIX))))
			break;
		if (is_blank(line, line_len) || line[0] == '#')
			continue;
		if (starts_with(line, line_len, UNTRUSTED_PREFIX, PREFIX_LEN(UNTRUSTED_PREFIX))) {
			comment_line = ls.number;
			continue;
		}
		if (add_key(line, line_len, ls.number, keys, &n, max, err, errlen) != 0)
			return -EINVAL;
		comment_line = 0;
	}
	if (comment_line) {
		fail(err, errlen, "line %d: an \"untrusted comment:\" line without its key on the next line",
		     comment_line);
		return -EINVAL;
	}
	return n;
}

int vmac_minisign_keys_load(const char *path, struct vmac_minisign_key *keys, int max, char *err, size_t errlen)
{
	char why[256];
	size_t len;
	int code = 0, n;
	char *text = vmac_read_file(path, KEYS_FILE_MAX, &len, err, errlen, &code);
	if (!text)
		return code;
	n = vmac_minisign_keys_parse(text, len, keys, max, why, sizeof(why));
	free(text);
	if (n < 0)
		snprintf(err, errlen, "%s: %s", path, why);
	return n;
}

/* ---- signatures ---- */

/* Lines 2 to 4 of a signature (lines[1..3]) into st: 0, or -1 with err. */
static int sig_decode(const char *lines[SIG_LINES], const size_t lens[SIG_LINES], struct sig_text *st, char *err,
                      size_t errlen)
{
	uint8_t bin[SIG_BIN_LEN];
	if (decode_exact(lines[1], lens[1], bin, sizeof(bin)) != 0)
		return fail(err, errlen, "line 2 is not the base64 of a signature (74 bytes)");
	if (memcmp(bin, "Ed", ALG_LEN) != 0 && memcmp(bin, "ED", ALG_LEN) != 0)
		return fail(err, errlen, "line 2: an algorithm other than Ed and ED");
	memcpy(st->alg, bin, ALG_LEN);
	memcpy(st->id, bin + ALG_LEN, ID_LEN);
	memcpy(st->sig, bin + ALG_LEN + ID_LEN, SIG_LEN);
	if (!starts_with(lines[2], lens[2], TRUSTED_PREFIX, PREFIX_LEN(TRUSTED_PREFIX)))
		return fail(err, errlen, "line 3 does not start with \"" TRUSTED_PREFIX "\"");
	st->comment = lines[2] + PREFIX_LEN(TRUSTED_PREFIX);
	st->comment_len = lens[2] - PREFIX_LEN(TRUSTED_PREFIX);
	if (st->comment_len > VMAC_MINISIGN_COMMENT_MAX)
		return fail(err, errlen, "the trusted comment is %zu bytes, more than %d", st->comment_len,
		            VMAC_MINISIGN_COMMENT_MAX);
	if (!printable_utf8((const unsigned char *)st->comment, st->comment_len))
		return fail(err, errlen, "the trusted comment is not printable UTF-8 text");
	if (decode_exact(lines[3], lens[3], st->global, SIG_LEN) != 0)
		return fail(err, errlen, "line 4 is not the base64 of a global signature (64 bytes)");
	return 0;
}

/* A .minisig file's text into st: 0, or -1 with err (what is wrong). */
static int sig_parse(const char *text, size_t len, struct sig_text *st, char *err, size_t errlen)
{
	struct lines ls = {text, text, 0};
	const char *lines[SIG_LINES];
	size_t lens[SIG_LINES];
	int n;
	if (!text || len == 0)
		return fail(err, errlen, "it is empty");
	ls.end = text + len;
	if (len > VMAC_MINISIGN_SIG_MAX)
		return fail(err, errlen, "it is %zu bytes, more than the %d a .minisig file may have", len,
		            VMAC_MINISIGN_SIG_MAX);
	if (memchr(text, 0, len))
		return fail(err, errlen, "it holds a NUL byte: not text");
	for (n = 0; n < SIG_LINES && next_line(&ls, &lines[n], &lens[n]); n++)
		if (memchr(lines[n], '\r', lens[n]))
			return fail(err, errlen, "line %d holds a carriage return", n + 1);
	if (n < SIG_LINES)
		return fail(err, errlen, "it has %d line%s, a .minisig file has 4", n, n == 1 ? "" : "s");
	if (ls.pos != ls.end)
		return fail(err, errlen, "there is more after its 4th line");
	if (!starts_with(lines[0], lens[0], UNTRUSTED_PREFIX, PREFIX_LEN(UNTRUSTED_PREFIX)))
		return fail(err, errlen, "line 1 does not start with \"" UNTRUSTED_PREFIX "\"");
	if (lens[0] > VMAC_MINISIGN_COMMENT_MAX)
		return fail(err, errlen, "line 1 is %zu bytes, more than %d", lens[0], VMAC_MINISIGN_COMMENT_MAX);
	return sig_decode(lines, lens, st, err, errlen);
}

/* What the signature of st is over: data itself ("Ed"), or its
 * BLAKE2b-512 hash ("ED"), put in hash; *len its length. */
static const unsigned char *signed_message(const struct sig_text *st, const void *data, size_t *len,
                                           unsigned char hash[PREHASH_LEN])
{
	static const unsigned char nothing[1];
	const unsigned char *msg = *len ? data : nothing;
	crypto_generichash_state state;
	if (memcmp(st->alg, "Ed", ALG_LEN) == 0)
		return msg;
	crypto_generichash_init(&state, NULL, 0, PREHASH_LEN);
	crypto_generichash_update(&state, msg, *len);
	crypto_generichash_final(&state, hash, PREHASH_LEN);
	*len = PREHASH_LEN;
	return hash;
}

/* The global signature of st by key: over the signature, then the trusted
 * comment. 0 when it holds. */
static int comment_verify(const struct sig_text *st, const uint8_t pk[PK_LEN])
{
	unsigned char signed_text[SIG_LEN + VMAC_MINISIGN_COMMENT_MAX];
	memcpy(signed_text, st->sig, SIG_LEN);
	memcpy(signed_text + SIG_LEN, st->comment, st->comment_len);
	return crypto_sign_verify_detached(st->global, signed_text, SIG_LEN + st->comment_len, pk);
}

int vmac_minisign_verify(const struct vmac_minisign_key *keys, int nkeys, const void *data, size_t len, const char *sig,
                         size_t siglen, struct vmac_minisign_result *r, char *err, size_t errlen)
{
	struct sig_text st;
	char why[256], id_hex[2 * ID_LEN + 1];
	unsigned char hash[PREHASH_LEN];
	const unsigned char *msg;
	size_t msg_len = len;
	int i;
	if (sodium_init() < 0) {
		snprintf(err, errlen, "libsodium could not start");
		return -VMAC_EFAIL;
	}
	if (sig_parse(sig, siglen, &st, why, sizeof(why)) != 0) {
		snprintf(err, errlen, "not a minisign signature: %s", why);
		return -VMAC_EBUNDLE;
	}
	for (i = 0; i < nkeys && memcmp(keys[i].id, st.id, ID_LEN) != 0; i++)
		;
	id_to_hex(st.id, id_hex);
	if (i == nkeys) {
		snprintf(err, errlen, "signed by key %s, which is not one of deploy_keys", id_hex);
		return -VMAC_ESIGKEY;
	}
	/* Every key of that id (one, from vmac_minisign_keys_parse) is tried. */
	msg = signed_message(&st, data, &msg_len, hash);
	for (; i < nkeys; i++)
		if (memcmp(keys[i].id, st.id, ID_LEN) == 0 &&
		    crypto_sign_verify_detached(st.sig, msg, msg_len, keys[i].pk) == 0)
			break;
	if (i == nkeys) {
		snprintf(err, errlen, "the signature does not match the file (changed after it was signed?)");
		return -VMAC_ESIGBAD;
	}
	if (comment_verify(&st, keys[i].pk) != 0) {
		snprintf(err, errlen, "the trusted comment was changed after signing (key %s)", id_hex);
		return -VMAC_ESIGCOMMENT;
	}
	if (r) {
		r->key = i;
		r->prehash = memcmp(st.alg, "ED", ALG_LEN) == 0;
		memcpy(r->trusted_comment, st.comment, st.comment_len);
		r->trusted_comment[st.comment_len] = 0;
	}
	return 0;
}
