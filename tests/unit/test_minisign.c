/* Unit tests of minisign signatures (core/bundle/minisign.c), made by the
 * real `minisign` command at test time: prehashed (ED) and legacy (Ed)
 * signatures hold and give back their trusted comment exactly, "\r\n"
 * line ends too; any of several keys in a keys file may sign; an unknown
 * key, a changed byte of the file and an edited trusted comment are each
 * told by their own code, and `minisign -V` agrees with every verdict on
 * a real signature; malformed, truncated and over-long signatures are
 * refused as malformed; each byte of a signature changed to each other
 * value never passes (but in the unsigned comment) nor crashes; a keys
 * file's bad line is named by its number. Without minisign the tests
 * cannot run: SKIPPED, or a failure under CI=true (vmac_test_cannot_run). */
#include <check.h>
#include <errno.h>
#include <sodium.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include "../../core/bundle/minisign.h"
#include "../../core/common/errors.h"
#include "../../core/common/file.h"
#include "check_main.h"

#define COMMENT "vmac-bundle name=washer version=1.2.0 counter=3"
#define DATA_LEN (256u << 10)

static char dir[] = "/tmp/vmac-test-minisign-XXXXXX";
static struct vmac_minisign_key keys[VMAC_MINISIGN_KEYS];
static int nkeys;

static void setup(void)
{
	snprintf(dir, sizeof(dir), "/tmp/vmac-test-minisign-XXXXXX");
	ck_assert_msg(mkdtemp(dir) != NULL, "mkdtemp failed");
	nkeys = 0;
}

static void teardown(void)
{
	char cmd[128];
	snprintf(cmd, sizeof(cmd), "rm -rf %s", dir);
	ck_assert_int_eq(system(cmd), 0);
}

/* The exit status of a shell command run in dir (-1: it did not exit). */
__attribute__((format(printf, 1, 2))) static int sh(const char *fmt, ...)
{
	char cmd[4096];
	int n, status;
	va_list ap;
	n = snprintf(cmd, sizeof(cmd), "cd %s && ", dir);
	va_start(ap, fmt);
	vsnprintf(cmd + n, sizeof(cmd) - (size_t)n, fmt, ap);
	va_end(ap);
	status = system(cmd);
	return status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* 1 when the minisign command is here; else the test cannot run. */
static int have_minisign(void)
{
	if (system("command -v minisign >/dev/null 2>&1") == 0)
		return 1;
	vmac_test_cannot_run("signatures made and checked by the real minisign command",
	                     "minisign is not installed (apt-get install minisign)");
	return 0;
}

static void make_key(const char *name)
{
	ck_assert_msg(sh("minisign -G -W -p %s.pub -s %s.key >/dev/null", name, name) == 0, "minisign -G %s failed",
	              name);
}

/* minisign -S of file by key into sig (legacy: the "Ed" form). */
static void sign(const char *key, const char *file, const char *sig, int legacy, const char *comment)
{
	ck_assert_msg(sh("minisign -S %s -s %s.key -m %s -x %s -t '%s' >/dev/null", legacy ? "-l" : "", key, file, sig,
	                 comment) == 0,
	              "minisign -S of %s by %s failed", file, key);
}

/* What the real tool says of sig over file with pub: 1 when it holds. */
static int minisign_accepts(const char *pub, const char *file, const char *sig)
{
	return sh("minisign -V -q -p %s -m %s -x %s >/dev/null 2>&1", pub, file, sig) == 0;
}

static char *slurp(const char *name, size_t *len)
{
	char path[512], err[512] = "";
	int code = 0;
	char *text;
	snprintf(path, sizeof(path), "%s/%s", dir, name);
	text = vmac_read_file(path, 8u << 20, len, err, sizeof(err), &code);
	ck_assert_msg(text != NULL, "reading %s: %s", name, err);
	return text;
}

static void put(const char *name, const void *data, size_t len)
{
	char path[512];
	FILE *f;
	snprintf(path, sizeof(path), "%s/%s", dir, name);
	f = fopen(path, "wb");
	ck_assert_msg(f != NULL, "cannot write %s", path);
	ck_assert_uint_eq(fwrite(data, 1, len, f), len);
	ck_assert_int_eq(fclose(f), 0);
}

/* A file to sign: DATA_LEN bytes that are not all alike. */
static void put_data(const char *name)
{
	static unsigned char data[DATA_LEN];
	size_t i;
	for (i = 0; i < DATA_LEN; i++)
		data[i] = (unsigned char)((i * 2654435761u) >> 24);
	put(name, data, DATA_LEN);
}

static void load_keys(const char *name)
{
	char path[512], err[512] = "";
	snprintf(path, sizeof(path), "%s/%s", dir, name);
	nkeys = vmac_minisign_keys_load(path, keys, VMAC_MINISIGN_KEYS, err, sizeof(err));
	ck_assert_msg(nkeys > 0, "loading %s: %d keys: %s", name, nkeys, err);
}

/* vmac_minisign_verify of sig (text in memory) over file with keys. */
static int verify_text(const char *file, const char *sig, size_t siglen, struct vmac_minisign_result *r, char *err,
                       size_t errlen)
{
	size_t len;
	char *data = slurp(file, &len);
	int rc = vmac_minisign_verify(keys, nkeys, data, len, sig, siglen, r, err, errlen);
	free(data);
	return rc;
}

/* The same with the signature in file sig. */
static int verify(const char *file, const char *sig, struct vmac_minisign_result *r, char *err, size_t errlen)
{
	size_t siglen;
	char *text = slurp(sig, &siglen);
	int rc = verify_text(file, text, siglen, r, err, errlen);
	free(text);
	return rc;
}

/* The key id in the comment line minisign -G wrote: what people see. */
/* The key id minisign wrote into pub's comment, as 16 hex digits: minisign
 * 0.11 (Debian's) leaves out leading zeros, later versions print all 16. */
static void printed_id(const char *pub, char id[17])
{
	size_t len;
	char *text = slurp(pub, &len);
	unsigned long long n;
	ck_assert_msg(sscanf(text, "untrusted comment: minisign public key %16llX", &n) == 1, "%s: %s", pub, text);
	snprintf(id, 17, "%016llX", n);
	free(text);
}

START_TEST(a_prehashed_signature_holds_and_gives_its_comment)
{
	struct vmac_minisign_result r;
	char err[512] = "", id[17];
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	sign("a", "washer.vmb", "washer.vmb.minisig", 0, COMMENT);
	load_keys("a.pub");
	ck_assert_int_eq(nkeys, 1);
	memset(&r, 0x55, sizeof(r));
	ck_assert_msg(verify("washer.vmb", "washer.vmb.minisig", &r, err, sizeof(err)) == 0, "refused: %s", err);
	ck_assert_int_eq(r.key, 0);
	ck_assert_msg(r.prehash == 1, "minisign 0.11 signs prehashed (ED) by default; read as Ed");
	ck_assert_str_eq(r.trusted_comment, COMMENT);
	printed_id("a.pub", id);
	ck_assert_str_eq(keys[0].id_hex, id);
	ck_assert_msg(minisign_accepts("a.pub", "washer.vmb", "washer.vmb.minisig"), "minisign -V refuses it");
}
END_TEST

START_TEST(a_legacy_signature_holds)
{
	struct vmac_minisign_result r;
	char err[512] = "";
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	sign("a", "washer.vmb", "legacy.minisig", 1, COMMENT);
	load_keys("a.pub");
	ck_assert_msg(verify("washer.vmb", "legacy.minisig", &r, err, sizeof(err)) == 0, "refused: %s", err);
	ck_assert_msg(r.prehash == 0, "minisign -S -l signs the file itself (Ed); read as ED");
	ck_assert_str_eq(r.trusted_comment, COMMENT);
	ck_assert_msg(minisign_accepts("a.pub", "washer.vmb", "legacy.minisig"), "minisign -V refuses it");
}
END_TEST

START_TEST(crlf_line_ends_and_no_final_newline_are_accepted)
{
	struct vmac_minisign_result r;
	char err[512] = "", crlf[VMAC_MINISIGN_SIG_MAX];
	size_t len, i, n = 0;
	char *text;
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	sign("a", "washer.vmb", "washer.vmb.minisig", 0, COMMENT);
	load_keys("a.pub");
	text = slurp("washer.vmb.minisig", &len);
	for (i = 0; i < len && n + 2 < sizeof(crlf); i++) {
		if (text[i] == '\n')
			crlf[n++] = '\r';
		crlf[n++] = text[i];
	}
	put("crlf.minisig", crlf, n);
	ck_assert_msg(verify_text("washer.vmb", crlf, n, &r, err, sizeof(err)) == 0, "CRLF refused: %s", err);
	ck_assert_str_eq(r.trusted_comment, COMMENT);
	ck_assert_msg(minisign_accepts("a.pub", "washer.vmb", "crlf.minisig"), "minisign -V refuses CRLF");
	ck_assert_msg(verify_text("washer.vmb", text, len - 1, &r, err, sizeof(err)) == 0, "no final newline: %s", err);
	ck_assert_msg(verify_text("washer.vmb", crlf, n - 2, &r, err, sizeof(err)) == 0, "no final CRLF: %s", err);
	free(text);
}
END_TEST

START_TEST(any_of_several_keys_may_sign)
{
	struct vmac_minisign_result r;
	char err[512] = "", file[2048], b64[128];
	size_t len;
	char *pub_a, *pub_b, *pub_c;
	if (!have_minisign())
		return;
	make_key("a");
	make_key("b");
	make_key("c");
	pub_a = slurp("a.pub", &len);
	pub_b = slurp("b.pub", &len);
	pub_c = slurp("c.pub", &len);
	ck_assert_int_eq(sscanf(pub_b, "%*[^\n]\n%127s", b64), 1);
	/* a as minisign wrote it, b its base64 alone, c after a blank line. */
	snprintf(file, sizeof(file), "# deploy keys\n%s# the second, its key line alone\n%s\n\n   \n%s", pub_a, b64,
	         pub_c);
	put("deploy_keys", file, strlen(file));
	load_keys("deploy_keys");
	ck_assert_int_eq(nkeys, 3);
	put_data("washer.vmb");
	sign("b", "washer.vmb", "b.minisig", 0, COMMENT);
	ck_assert_msg(verify("washer.vmb", "b.minisig", &r, err, sizeof(err)) == 0, "refused: %s", err);
	ck_assert_int_eq(r.key, 1);
	sign("c", "washer.vmb", "c.minisig", 1, COMMENT);
	ck_assert_msg(verify("washer.vmb", "c.minisig", &r, err, sizeof(err)) == 0, "refused: %s", err);
	ck_assert_int_eq(r.key, 2);
	free(pub_a);
	free(pub_b);
	free(pub_c);
}
END_TEST

START_TEST(an_unknown_key_is_named_as_minisign_names_it)
{
	struct vmac_minisign_result r;
	char err[512] = "", id[17], cmd[512], said[512] = "";
	const char *at;
	unsigned long long minisign_id, our_id;
	FILE *p;
	if (!have_minisign())
		return;
	make_key("a");
	make_key("b");
	put_data("washer.vmb");
	sign("b", "washer.vmb", "washer.vmb.minisig", 0, COMMENT);
	load_keys("a.pub");
	ck_assert_int_eq(verify("washer.vmb", "washer.vmb.minisig", &r, err, sizeof(err)), -VMAC_ESIGKEY);
	printed_id("b.pub", id);
	ck_assert_msg(strstr(err, id) && strstr(err, "not one of deploy_keys"), "the key id %s not in: %s", id, err);
	nkeys = 0;
	ck_assert_int_eq(verify("washer.vmb", "washer.vmb.minisig", &r, err, sizeof(err)), -VMAC_ESIGKEY);
	/* minisign -V with the wrong key names the signature's id the same way. */
	snprintf(cmd, sizeof(cmd), "cd %s && minisign -V -p a.pub -m washer.vmb 2>&1", dir);
	p = popen(cmd, "r");
	ck_assert_msg(p != NULL, "popen failed");
	ck_assert_uint_gt(fread(said, 1, sizeof(said) - 1, p), 0);
	ck_assert_int_ne(pclose(p), 0);
	/* The same number: minisign 0.11 prints it without leading zeros
	 * ("%" PRIX64), 0.12 and vmac with them ("%016" PRIX64), so an id
	 * whose first digit is 0 (one key in 16) reads shorter there. */
	ck_assert_msg((at = strstr(said, "key id in washer.vmb.minisig is ")) != NULL &&
	                  sscanf(at + strlen("key id in washer.vmb.minisig is "), "%llX", &minisign_id) == 1 &&
	                  sscanf(id, "%llX", &our_id) == 1 && minisign_id == our_id,
	              "minisign printed another id than %s: %s", id, said);
}
END_TEST

START_TEST(a_changed_byte_of_the_file_is_caught)
{
	static const char *const sigs[] = {"prehashed.minisig", "legacy.minisig"};
	struct vmac_minisign_result r;
	char err[512] = "";
	size_t len, i;
	char *data;
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	sign("a", "washer.vmb", sigs[0], 0, COMMENT);
	sign("a", "washer.vmb", sigs[1], 1, COMMENT);
	load_keys("a.pub");
	data = slurp("washer.vmb", &len);
	data[len / 2] ^= 0x01;
	put("washer.vmb", data, len);
	free(data);
	for (i = 0; i < 2; i++) {
		ck_assert_msg(verify("washer.vmb", sigs[i], &r, err, sizeof(err)) == -VMAC_ESIGBAD, "%s: %s", sigs[i],
		              err);
		ck_assert_str_eq(err, "the signature does not match the file (changed after it was signed?)");
		ck_assert_msg(!minisign_accepts("a.pub", "washer.vmb", sigs[i]), "minisign -V accepts %s", sigs[i]);
	}
}
END_TEST

START_TEST(an_edited_trusted_comment_is_caught)
{
	struct vmac_minisign_result r;
	char err[512] = "";
	size_t len;
	char *text, *at;
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	sign("a", "washer.vmb", "washer.vmb.minisig", 0, COMMENT);
	load_keys("a.pub");
	text = slurp("washer.vmb.minisig", &len);
	/* The untrusted comment is not signed: changing it changes nothing. */
	at = strstr(text, "signature from");
	ck_assert_ptr_nonnull(at);
	at[0] = 'S';
	put("untrusted.minisig", text, len);
	ck_assert_msg(verify("washer.vmb", "untrusted.minisig", &r, err, sizeof(err)) == 0, "refused: %s", err);
	ck_assert_msg(minisign_accepts("a.pub", "washer.vmb", "untrusted.minisig"), "minisign -V refuses it");
	at = strstr(text, "counter=3");
	ck_assert_ptr_nonnull(at);
	at[8] = '9';
	put("edited.minisig", text, len);
	free(text);
	ck_assert_int_eq(verify("washer.vmb", "edited.minisig", &r, err, sizeof(err)), -VMAC_ESIGCOMMENT);
	ck_assert_msg(strstr(err, "the trusted comment was changed after signing") != NULL, "%s", err);
	ck_assert_msg(!minisign_accepts("a.pub", "washer.vmb", "edited.minisig"), "minisign -V accepts the edit");
}
END_TEST

/* A signature's four lines, each without its "\n", with room to grow. */
struct sig_lines {
	char l[4][2 * VMAC_MINISIGN_SIG_MAX];
};

static void split(const char *text, struct sig_lines *s)
{
	ck_assert_int_eq(
	    sscanf(text, "%4095[^\n]\n%4095[^\n]\n%4095[^\n]\n%4095[^\n]", s->l[0], s->l[1], s->l[2], s->l[3]), 4);
}

/* Line 2 (base64) with its algorithm bytes replaced by alg. */
static void set_algorithm(char *line, const char *alg)
{
	unsigned char bin[74];
	size_t n = 0;
	ck_assert_int_eq(
	    sodium_base642bin(bin, sizeof(bin), line, strlen(line), NULL, &n, NULL, sodium_base64_VARIANT_ORIGINAL), 0);
	ck_assert_uint_eq(n, sizeof(bin));
	memcpy(bin, alg, 2);
	sodium_bin2base64(line, 2 * VMAC_MINISIGN_SIG_MAX, bin, sizeof(bin), sodium_base64_VARIANT_ORIGINAL);
}

/* A comment line's text made n bytes longer. */
static void lengthen(char *line, size_t n)
{
	size_t len = strlen(line);
	memset(line + len, 'x', n);
	line[len + n] = 0;
}

#define MALFORMED 20
#define A_NUL 18 /* a NUL byte in the trusted comment */

/* Malformed signature number i, made from the good lines g, into out: its
 * length, and *what says what is wrong with it. */
static size_t malformed(int i, const struct sig_lines *g, char *out, size_t cap, const char **what)
{
	static struct sig_lines v;
	const char *tail = "\n";
	size_t len;
	v = *g;
	switch (i) {
	case 0: *what = "empty"; return 0;
	case 1: *what = "garbage"; return (size_t)snprintf(out, cap, "hello, world\n");
	case 2: *what = "two lines"; return (size_t)snprintf(out, cap, "%s\n%s\n", v.l[0], v.l[1]);
	case 3: *what = "three lines"; return (size_t)snprintf(out, cap, "%s\n%s\n%s\n", v.l[0], v.l[1], v.l[2]);
	case 4:
		*what = "line 2 damaged";
		v.l[1][20] = '!';
		break;
	case 5:
		*what = "line 2 short by 2 bytes";
		v.l[1][strlen(v.l[1]) - 4] = 0;
		break;
	case 6:
		*what = "line 4 cut";
		v.l[3][40] = 0;
		break;
	case 7:
		*what = "more after line 4's padding";
		strcat(v.l[3], "AAAA");
		break;
	case 8:
		*what = "algorithm Ex";
		set_algorithm(v.l[1], "Ex");
		break;
	case 9:
		*what = "line 3 not \"trusted comment: \"";
		v.l[2][7] = '_';
		break;
	case 10:
		*what = "a control character in the comment";
		strcat(v.l[2], "\001");
		break;
	case 11:
		*what = "not UTF-8 in the comment";
		strcat(v.l[2], "\xff");
		break;
	case 12:
		*what = "an overlong UTF-8 '/' in the comment";
		strcat(v.l[2], "\xc0\xaf");
		break;
	case 13:
		*what = "a fifth line";
		tail = "\nuntrusted comment: more\n";
		break;
	case 14:
		*what = "a blank fifth line";
		tail = "\n\n";
		break;
	case 15:
		*what = "a space after line 2";
		strcat(v.l[1], " ");
		break;
	case 16:
		*what = "a lone CR in line 1";
		strcat(v.l[0], "\rx");
		break;
	case 17:
		*what = "line 1 over VMAC_MINISIGN_COMMENT_MAX";
		lengthen(v.l[0], VMAC_MINISIGN_COMMENT_MAX);
		break;
	case A_NUL: *what = "a NUL in the trusted comment"; break;
	case 19:
		*what = "over VMAC_MINISIGN_SIG_MAX";
		lengthen(v.l[0], VMAC_MINISIGN_SIG_MAX);
		break;
	}
	len = (size_t)snprintf(out, cap, "%s\n%s\n%s\n%s%s", v.l[0], v.l[1], v.l[2], v.l[3], tail);
	if (i == A_NUL)
		out[strlen(v.l[0]) + 1 + strlen(v.l[1]) + 1 + 20] = 0;
	return len;
}

START_TEST(malformed_signatures_are_refused)
{
	static char bad[8 * VMAC_MINISIGN_SIG_MAX];
	static struct sig_lines g;
	struct vmac_minisign_result r;
	char err[512];
	const char *what = "";
	size_t len;
	char *text;
	int i, rc;
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	sign("a", "washer.vmb", "washer.vmb.minisig", 0, COMMENT);
	load_keys("a.pub");
	text = slurp("washer.vmb.minisig", &len);
	split(text, &g);
	free(text);
	for (i = 0; i < MALFORMED; i++) {
		len = malformed(i, &g, bad, sizeof(bad), &what);
		snprintf(err, sizeof(err), "(nothing)");
		rc = verify_text("washer.vmb", bad, len, &r, err, sizeof(err));
		ck_assert_msg(rc == -VMAC_EBUNDLE, "%s: %d (%s), not -VMAC_EBUNDLE", what, rc, err);
		ck_assert_msg(strncmp(err, "not a minisign signature: ", 26) == 0, "%s: %s", what, err);
	}
	ck_assert_int_eq(vmac_minisign_verify(keys, nkeys, "", 0, NULL, 0, &r, err, sizeof(err)), -VMAC_EBUNDLE);
}
END_TEST

/* minisign signs trusted comments up to 8 KiB; vmac reads 1 KiB. */
START_TEST(a_huge_trusted_comment_is_refused)
{
	static char comment[2 * VMAC_MINISIGN_COMMENT_MAX + 1];
	struct vmac_minisign_result r;
	char err[512] = "";
	if (!have_minisign())
		return;
	make_key("a");
	put_data("washer.vmb");
	load_keys("a.pub");
	memset(comment, 'c', VMAC_MINISIGN_COMMENT_MAX);
	sign("a", "washer.vmb", "at-bound.minisig", 0, comment);
	ck_assert_msg(verify("washer.vmb", "at-bound.minisig", &r, err, sizeof(err)) == 0, "refused: %s", err);
	ck_assert_uint_eq(strlen(r.trusted_comment), VMAC_MINISIGN_COMMENT_MAX);
	memset(comment, 'c', sizeof(comment) - 1);
	sign("a", "washer.vmb", "huge.minisig", 0, comment);
	ck_assert_msg(minisign_accepts("a.pub", "washer.vmb", "huge.minisig"), "minisign -V refuses a 2 KiB comment");
	ck_assert_int_eq(verify("washer.vmb", "huge.minisig", &r, err, sizeof(err)), -VMAC_EBUNDLE);
	ck_assert_msg(strstr(err, "more than 1024") != NULL, "%s", err);
}
END_TEST

/* Every byte of a real signature changed to each of the 255 other values,
 * and every truncation: a code among the four, never a crash, and 0 only
 * when the change was in the untrusted comment (line 1), which is not
 * signed. The file signed is small, so the checks that parse are fast. */
START_TEST(damaged_signatures_never_pass_or_crash)
{
	static const int codes[] = {0, -VMAC_EBUNDLE, -VMAC_ESIGKEY, -VMAC_ESIGBAD, -VMAC_ESIGCOMMENT};
	static const char data[] = "a small file, signed";
	struct vmac_minisign_result r;
	char err[512], copy[VMAC_MINISIGN_SIG_MAX];
	size_t len, line1, at, k;
	char *text;
	int value, rc, known;
	if (!have_minisign())
		return;
	make_key("a");
	put("small", data, sizeof(data));
	sign("a", "small", "small.minisig", 0, COMMENT);
	load_keys("a.pub");
	text = slurp("small.minisig", &len);
	line1 = (size_t)(strchr(text, '\n') - text);
	for (at = 0; at < len; at++) {
		for (value = 1; value < 256; value++) {
			memcpy(copy, text, len);
			copy[at] = (char)((unsigned char)text[at] + value);
			rc = vmac_minisign_verify(keys, nkeys, data, sizeof(data), copy, len, &r, err, sizeof(err));
			for (known = 0, k = 0; k < sizeof(codes) / sizeof(codes[0]); k++)
				known |= rc == codes[k];
			ck_assert_msg(known, "byte %zu changed to 0x%02x: code %d", at, (unsigned char)copy[at], rc);
			ck_assert_msg(rc != 0 || at < line1, "byte %zu changed to 0x%02x passes", at,
			              (unsigned char)copy[at]);
		}
	}
	for (at = 0; at < len - 1; at++)
		ck_assert_int_ne(vmac_minisign_verify(keys, nkeys, data, sizeof(data), text, at, &r, err, sizeof(err)),
		                 0);
	free(text);
}
END_TEST

/* vmac_minisign_keys_parse of text: the count, or < 0 with err. */
static int parse(const char *text, int max, char *err, size_t errlen)
{
	return vmac_minisign_keys_parse(text, strlen(text), keys, max, err, errlen);
}

START_TEST(a_bad_line_of_a_keys_file_is_named)
{
	char err[512] = "", text[4096], b64[128], other[128], path[512];
	unsigned char bin[42];
	size_t len, n = 0;
	char *pub, *sec;
	if (!have_minisign())
		return;
	make_key("a");
	make_key("b");
	pub = slurp("a.pub", &len);
	sec = slurp("a.key", &len);
	ck_assert_int_eq(sscanf(pub, "%*[^\n]\n%127s", b64), 1);
	ck_assert_int_eq(parse("", 4, err, sizeof(err)), 0);
	ck_assert_int_eq(parse("# none yet\n\n", 4, err, sizeof(err)), 0);
	snprintf(text, sizeof(text), "# keys\n%snot a key\n", pub);
	ck_assert_int_eq(parse(text, 4, err, sizeof(err)), -EINVAL);
	ck_assert_msg(strstr(err, "line 4: not a minisign public key") != NULL, "%s", err);
	snprintf(text, sizeof(text), "%s\n%s", pub, sec);
	ck_assert_int_lt(parse(text, 4, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "line 5:") != NULL, "the secret key's line not named: %s", err);
	snprintf(text, sizeof(text), "untrusted comment: a key\n\n%s\n", b64);
	ck_assert_int_lt(parse(text, 4, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "line 1: an \"untrusted comment:\" line without its key") != NULL, "%s", err);
	snprintf(text, sizeof(text), "%s%s", pub, pub);
	ck_assert_int_eq(parse(text, 4, err, sizeof(err)), 1);
	/* The same id with another key: which one is meant? */
	ck_assert_int_eq(
	    sodium_base642bin(bin, sizeof(bin), b64, strlen(b64), NULL, &n, NULL, sodium_base64_VARIANT_ORIGINAL), 0);
	bin[41] ^= 1;
	sodium_bin2base64(other, sizeof(other), bin, sizeof(bin), sodium_base64_VARIANT_ORIGINAL);
	snprintf(text, sizeof(text), "%s%s\n", pub, other);
	ck_assert_int_lt(parse(text, 4, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "line 3: key id") != NULL, "%s", err);
	free(pub);
	free(sec);
	pub = slurp("b.pub", &len);
	snprintf(text, sizeof(text), "%s\n%s", b64, pub);
	ck_assert_int_lt(parse(text, 1, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "line 3: one key more than the 1 allowed") != NULL, "%s", err);
	/* From a file, the error names the file too. */
	put("deploy_keys", text, strlen(text));
	snprintf(path, sizeof(path), "%s/deploy_keys", dir);
	ck_assert_int_lt(vmac_minisign_keys_load(path, keys, 1, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, path) && strstr(err, "line 3"), "%s", err);
	free(pub);
}
END_TEST

START_TEST(a_missing_or_huge_keys_file_is_an_error)
{
	static char big[(64u << 10) + 1];
	char err[512] = "", path[512];
	snprintf(path, sizeof(path), "%s/none", dir);
	ck_assert_int_eq(vmac_minisign_keys_load(path, keys, 4, err, sizeof(err)), -ENOENT);
	ck_assert_msg(strstr(err, path) != NULL, "the file not named: %s", err);
	memset(big, '#', sizeof(big));
	put("big", big, sizeof(big));
	snprintf(path, sizeof(path), "%s/big", dir);
	ck_assert_int_eq(vmac_minisign_keys_load(path, keys, 4, err, sizeof(err)), -EFBIG);
	put("big", big, sizeof(big) - 1);
	ck_assert_int_eq(vmac_minisign_keys_load(path, keys, 4, err, sizeof(err)), 0);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("minisign");
	TCase *tc = tcase_create("minisign");
	tcase_add_checked_fixture(tc, setup, teardown);
	tcase_add_test(tc, a_prehashed_signature_holds_and_gives_its_comment);
	tcase_add_test(tc, a_legacy_signature_holds);
	tcase_add_test(tc, crlf_line_ends_and_no_final_newline_are_accepted);
	tcase_add_test(tc, any_of_several_keys_may_sign);
	tcase_add_test(tc, an_unknown_key_is_named_as_minisign_names_it);
	tcase_add_test(tc, a_changed_byte_of_the_file_is_caught);
	tcase_add_test(tc, an_edited_trusted_comment_is_caught);
	tcase_add_test(tc, malformed_signatures_are_refused);
	tcase_add_test(tc, a_huge_trusted_comment_is_refused);
	tcase_add_test(tc, damaged_signatures_never_pass_or_crash);
	tcase_add_test(tc, a_bad_line_of_a_keys_file_is_named);
	tcase_add_test(tc, a_missing_or_huge_keys_file_is_an_error);
	tcase_set_timeout(tc, 60);
	suite_add_tcase(s, tc);
	return s;
}
