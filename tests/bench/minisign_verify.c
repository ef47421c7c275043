/* What checking a bundle's minisign signature costs (core/bundle/minisign.c),
 * per MiB of the file signed, next to the work it cannot avoid: BLAKE2b-512
 * (crypto_generichash, 64-byte output) over the same bytes, timed in the
 * same run:
 *
 *   blake2b    crypto_generichash over the file (the baseline)
 *   verify_ED  vmac_minisign_verify of a prehashed signature ("ED", what
 *              minisign -S makes by default): the hash, then two Ed25519
 *              checks (the signature, the global signature)
 *   verify_Ed  the same of a legacy signature ("Ed", minisign -S -l):
 *              Ed25519 over the whole file
 *   fixed      vmac_minisign_verify of an "ED" signature over 0 bytes: the
 *              parse and the two Ed25519 checks, paid once per bundle
 *
 * The signatures are made here as minisign -S makes them (its format in
 * minisign.c), by a key made here. Each figure is the median of REPEATS
 * runs, each running every op ROUNDS times in turn, in us per MiB (fixed:
 * us); each ratio is the median of the runs' own ratios, so that a
 * machine slowed for a while slows both sides of it. --json prints one
 * JSON object instead of the table (bench.py --only minisign):
 *
 *   make build/bench/minisign_verify && build/bench/minisign_verify [MiB] [--json] */
#include <sodium.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../../core/bundle/minisign.h"

#define REPEATS 15
#define ROUNDS 8
#define COMMENT "vmac-bundle name=washer version=1.2.0 counter=3"

static unsigned char pk[crypto_sign_PUBLICKEYBYTES], sk[crypto_sign_SECRETKEYBYTES];
static struct vmac_minisign_key key;
static unsigned char *data;
static size_t data_len;
static char sig_ed[VMAC_MINISIGN_SIG_MAX], sig_legacy[VMAC_MINISIGN_SIG_MAX], sig_empty[VMAC_MINISIGN_SIG_MAX];
static volatile unsigned sink; /* every result feeds it: no loop is optimised away */

static double now_us(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec * 1e6 + t.tv_nsec / 1e3;
}

/* A .minisig file's text over msg, as minisign -S writes it. */
static void sign(const unsigned char *msg, size_t len, int prehash, char *out, size_t cap)
{
	unsigned char bin[2 + 8 + crypto_sign_BYTES], hash[crypto_generichash_BYTES_MAX];
	unsigned char signed_text[crypto_sign_BYTES + sizeof(COMMENT) - 1], global[crypto_sign_BYTES];
	char b64_sig[sodium_base64_ENCODED_LEN(sizeof(bin), sodium_base64_VARIANT_ORIGINAL)];
	char b64_global[sodium_base64_ENCODED_LEN(sizeof(global), sodium_base64_VARIANT_ORIGINAL)];
	memcpy(bin, prehash ? "ED" : "Ed", 2);
	memcpy(bin + 2, key.id, 8);
	if (prehash) {
		crypto_generichash(hash, sizeof(hash), msg, len, NULL, 0);
		crypto_sign_detached(bin + 10, NULL, hash, sizeof(hash), sk);
	} else {
		crypto_sign_detached(bin + 10, NULL, msg, len, sk);
	}
	memcpy(signed_text, bin + 10, crypto_sign_BYTES);
	memcpy(signed_text + crypto_sign_BYTES, COMMENT, sizeof(COMMENT) - 1);
	crypto_sign_detached(global, NULL, signed_text, sizeof(signed_text), sk);
	sodium_bin2base64(b64_sig, sizeof(b64_sig), bin, sizeof(bin), sodium_base64_VARIANT_ORIGINAL);
	sodium_bin2base64(b64_global, sizeof(b64_global), global, sizeof(global), sodium_base64_VARIANT_ORIGINAL);
	snprintf(out, cap, "untrusted comment: signature from minisign secret key\n%s\ntrusted comment: %s\n%s\n",
	         b64_sig, COMMENT, b64_global);
}

static int check(const unsigned char *msg, size_t len, const char *sig)
{
	struct vmac_minisign_result r;
	char err[256];
	int rc = vmac_minisign_verify(&key, 1, msg, len, sig, strlen(sig), &r, err, sizeof(err));
	if (rc != 0)
		fprintf(stderr, "minisign_verify: a good signature refused: %s\n", err);
	return rc;
}

static void op_blake2b(void)
{
	unsigned char hash[crypto_generichash_BYTES_MAX];
	crypto_generichash_state state;
	crypto_generichash_init(&state, NULL, 0, sizeof(hash));
	crypto_generichash_update(&state, data, data_len);
	crypto_generichash_final(&state, hash, sizeof(hash));
	sink += hash[0];
}

static void op_verify_ed(void)
{
	sink += (unsigned)check(data, data_len, sig_ed);
}

static void op_verify_legacy(void)
{
	sink += (unsigned)check(data, data_len, sig_legacy);
}

static void op_fixed(void)
{
	sink += (unsigned)check(data, 0, sig_empty);
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

static double median(double *v, int n)
{
	qsort(v, (size_t)n, sizeof(v[0]), cmp_double);
	return v[n / 2];
}

static const struct {
	const char *name, *what;
	void (*fn)(void);
} ops[] = {
    {"blake2b", "crypto_generichash, BLAKE2b-512 (the baseline)", op_blake2b},
    {"verify_ED", "vmac_minisign_verify, ED (prehashed)", op_verify_ed},
    {"verify_Ed", "vmac_minisign_verify, Ed (legacy)", op_verify_legacy},
    {"fixed", "vmac_minisign_verify, ED over 0 bytes", op_fixed},
};
#define NOPS (int)(sizeof(ops) / sizeof(ops[0]))
#define FIXED (NOPS - 1)

/* Each op's us per MiB (fixed: per call) and its ratio to blake2b. */
static void measure(double mib, double us[NOPS], double ratio[NOPS])
{
	double runs[NOPS][REPEATS], ratios[NOPS][REPEATS], t0;
	int r, o, i;
	for (o = 0; o < NOPS; o++)
		ops[o].fn(); /* warm the caches */
	for (r = 0; r < REPEATS; r++) {
		for (o = 0; o < NOPS; o++) {
			t0 = now_us();
			for (i = 0; i < ROUNDS; i++)
				ops[o].fn();
			runs[o][r] = (now_us() - t0) / ROUNDS / (o == FIXED ? 1 : mib);
		}
		for (o = 0; o < NOPS; o++)
			ratios[o][r] = runs[o][r] / runs[0][r];
	}
	for (o = 0; o < NOPS; o++) {
		us[o] = median(runs[o], REPEATS);
		ratio[o] = median(ratios[o], REPEATS);
	}
}

int main(int argc, char **argv)
{
	double mib = 4, us[NOPS], ratio[NOPS];
	size_t i;
	int json = 0, a, o;
	for (a = 1; a < argc; a++) {
		if (!strcmp(argv[a], "--json"))
			json = 1;
		else
			mib = atof(argv[a]);
	}
	data_len = (size_t)(mib * (1 << 20));
	if (sodium_init() < 0 || data_len == 0 || !(data = malloc(data_len))) {
		fprintf(stderr, "minisign_verify: no libsodium, or no memory for %.1f MiB\n", mib);
		return 1;
	}
	for (i = 0; i < data_len; i++)
		data[i] = (unsigned char)((i * 2654435761u) >> 24);
	crypto_sign_keypair(pk, sk);
	randombytes_buf(key.id, sizeof(key.id));
	memcpy(key.pk, pk, sizeof(pk));
	sign(data, data_len, 1, sig_ed, sizeof(sig_ed));
	sign(data, data_len, 0, sig_legacy, sizeof(sig_legacy));
	sign(data, 0, 1, sig_empty, sizeof(sig_empty));
	if (check(data, data_len, sig_ed) || check(data, data_len, sig_legacy) || check(data, 0, sig_empty))
		return 1;
	measure(mib, us, ratio);
	if (json) {
		printf("{\"mib\": %g, \"repeats\": %d, \"rounds\": %d, \"us_per_mib\": {", mib, REPEATS, ROUNDS);
		for (o = 0; o < FIXED; o++)
			printf("%s\"%s\": %.2f", o ? ", " : "", ops[o].name, us[o]);
		printf("}, \"ratio_to_blake2b\": {");
		for (o = 1; o < FIXED; o++)
			printf("%s\"%s\": %.4f", o > 1 ? ", " : "", ops[o].name, ratio[o]);
		printf("}, \"fixed_us\": %.2f}\n", us[FIXED]);
		return 0;
	}
	printf("over %g MiB, median of %d runs of %d:\n", mib, REPEATS, ROUNDS);
	for (o = 0; o < FIXED; o++)
		printf("  %-48s %8.1f us/MiB %6.3f x BLAKE2b\n", ops[o].what, us[o], ratio[o]);
	printf("  %-48s %8.1f us\n", ops[FIXED].what, us[FIXED]);
	return 0;
}
