/* A driver error's traceback made for people (docs/DRIVERS.md "The sandbox"):
 * the text LuaJIT's luaL_traceback builds, cleaned before it becomes the
 * err of a failed call and so the driver_error event. */
#include "internal.h"

#include <stdio.h>
#include <string.h>

/* Append n bytes of s to out (used bytes *len, room outlen), cut where it
 * no longer fits; out stays NUL-terminated. */
static void put(char *out, size_t outlen, size_t *len, const char *s, size_t n)
{
	if (*len + 1 >= outlen)
		return;
	if (n > outlen - 1 - *len)
		n = outlen - 1 - *len;
	memcpy(out + *len, s, n);
	*len += n;
	out[*len] = 0;
}

/* Whether frame line (n bytes, its tab included) is listed in out already. */
static int listed(const char *out, const char *line, size_t n)
{
	const char *at = out;
	while ((at = strstr(at, "\n")) != NULL) {
		at++;
		if (strncmp(at, line, n) == 0 && (at[n] == '\n' || at[n] == 0))
			return 1;
	}
	return 0;
}

/* A frame that tells a reader nothing: the host's C entry point, named only
 * by its address ("[C]: at 0x562db6e8f180"). */
static int host_frame(const char *line, size_t n)
{
	static const char addr[] = "\t[C]: at 0x";
	return n >= sizeof(addr) - 1 && strncmp(line, addr, sizeof(addr) - 1) == 0;
}

/* error() or assert() itself, above the driver's line that called it: the
 * message says what they were given. */
static int raise_frame(const char *line, size_t n)
{
	static const char *const names[] = {"\t[C]: in function 'error'", "\t[C]: in function 'assert'"};
	size_t i;
	for (i = 0; i < sizeof(names) / sizeof(names[0]); i++)
		if (n == strlen(names[i]) && strncmp(line, names[i], n) == 0)
			return 1;
	return 0;
}

/* See internal.h. */
void drv_traceback_clean(const char *text, char *out, size_t outlen)
{
	static const char head[] = "\nstack traceback:";
	const char *tb = strstr(text, head), *line;
	size_t len = 0;
	int frames = 0;
	if (outlen == 0)
		return;
	out[0] = 0;
	if (!tb) {
		put(out, outlen, &len, text, strlen(text));
		return;
	}
	put(out, outlen, &len, text, (size_t)(tb - text) + sizeof(head) - 1);
	for (line = strchr(tb + 1, '\n'); line; line = strchr(line, '\n')) {
		const char *end;
		size_t n;
		line++;
		end = strchr(line, '\n');
		n = end ? (size_t)(end - line) : strlen(line);
		if (n == 0 || host_frame(line, n) || (frames == 0 && raise_frame(line, n)) || listed(out, line, n))
			continue;
		put(out, outlen, &len, "\n", 1);
		put(out, outlen, &len, line, n);
		frames++;
	}
	if (frames == 0 && (size_t)(tb - text) < len) /* nothing left to show: no header either */
		out[tb - text] = 0;
}
