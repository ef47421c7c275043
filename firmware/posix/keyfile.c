/* A board's key file: see keyfile.h. */
#include "keyfile.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define KEY_HEX_LEN (2 * VMAC_KEY_LEN)

static int hex_digit(char c)
{
	if (c >= '0' && c <= '9')
		return c - '0';
	if (c >= 'a' && c <= 'f')
		return c - 'a' + 10;
	if (c >= 'A' && c <= 'F')
		return c - 'A' + 10;
	return -1;
}

/* The n bytes read (at most one more than a valid file holds) into key:
 * 0, or -1 with what is wrong in err. */
static int parse(const char *path, const char *text, size_t n, uint8_t key[VMAC_KEY_LEN], char *err, size_t errlen)
{
	size_t i;
	for (i = 0; i < n && i < KEY_HEX_LEN; i++) {
		if (hex_digit(text[i]) < 0) {
			snprintf(err, errlen,
			         "key file %s: character %zu is not a hex digit (want 32 hex digits, then at most "
			         "one newline)",
			         path, i + 1);
			return -1;
		}
	}
	if (n < KEY_HEX_LEN || n > KEY_HEX_LEN + 1 || (n == KEY_HEX_LEN + 1 && text[KEY_HEX_LEN] != '\n')) {
		snprintf(err, errlen, "key file %s: %s (want 32 hex digits, the 16-byte key, then at most one newline)",
		         path, n < KEY_HEX_LEN ? "too short" : "more than the key and one newline");
		return -1;
	}
	for (i = 0; i < VMAC_KEY_LEN; i++)
		key[i] = (uint8_t)(hex_digit(text[2 * i]) << 4 | hex_digit(text[2 * i + 1]));
	return 0;
}

int keyfile_read(const char *path, uint8_t key[VMAC_KEY_LEN], char *err, size_t errlen)
{
	/* Room for one byte more than a valid file: a longer one is refused
	 * without reading it all. */
	char text[KEY_HEX_LEN + 2];
	size_t n = 0;
	struct stat st;
	int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOCTTY), rc = -1;

	if (fd < 0) {
		snprintf(err, errlen, "key file %s: %s", path, strerror(errno));
		return -1;
	}
	if (fstat(fd, &st) != 0) {
		snprintf(err, errlen, "key file %s: %s", path, strerror(errno));
		goto out;
	}
	if (!S_ISREG(st.st_mode)) {
		snprintf(err, errlen, "key file %s: not a regular file", path);
		goto out;
	}
	while (n < sizeof(text)) {
		ssize_t got = read(fd, text + n, sizeof(text) - n);
		if (got < 0 && errno == EINTR)
			continue;
		if (got < 0) {
			snprintf(err, errlen, "key file %s: %s", path, strerror(errno));
			goto out;
		}
		if (got == 0)
			break;
		n += (size_t)got;
	}
	if (parse(path, text, n, key, err, errlen) != 0)
		goto out;
	if (st.st_mode & (S_IRWXG | S_IRWXO))
		fprintf(stderr,
		        "vmac-board: warning: key file %s has mode %04o: group or others may read or change the "
		        "board's key (chmod 600 %s)\n",
		        path, (unsigned)(st.st_mode & 07777), path);
	rc = 0;
out:
	explicit_bzero(text, sizeof(text));
	close(fd);
	return rc;
}
