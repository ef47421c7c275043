/* vmac_read_file: see file.h. */
#include "file.h"

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

char *vmac_read_file(const char *path, size_t max, size_t *len, char *err, size_t errlen, int *code)
{
	FILE *f = fopen(path, "rb");
	struct stat st;
	size_t want = max + 1;
	char *buf;
	if (!f) {
		*code = -errno;
		snprintf(err, errlen, "%s: cannot open: %s", path, strerror(errno));
		return NULL;
	}
	/* As large as the file is now (one byte more shows it grew meanwhile),
	 * not the most it may take. */
	if (fstat(fileno(f), &st) == 0 && st.st_size >= 0 && (uint64_t)st.st_size < max)
		want = (size_t)st.st_size + 1;
	buf = malloc(want + 1); /* and a NUL */
	*len = buf ? fread(buf, 1, want, f) : 0;
	if (buf && *len == want && want <= max) {
		char *more = realloc(buf, max + 2);
		if (!more) {
			free(buf);
		} else {
			*len += fread(more + want, 1, max + 1 - want, f);
		}
		buf = more;
	}
	if (!buf) {
		fclose(f);
		*code = -ENOMEM;
		snprintf(err, errlen, "%s: out of memory", path);
		return NULL;
	}
	if (ferror(f) || *len > max) {
		*code = ferror(f) ? -EIO : -EFBIG;
		if (ferror(f))
			snprintf(err, errlen, "%s: read error", path);
		else if (max % (1 << 20) == 0)
			snprintf(err, errlen, "%s: larger than %zu MiB", path, max >> 20);
		else
			snprintf(err, errlen, "%s: larger than %zu KiB", path, max >> 10);
		fclose(f);
		free(buf);
		return NULL;
	}
	fclose(f);
	buf[*len] = 0;
	return buf;
}
