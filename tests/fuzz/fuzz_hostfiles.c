/* The host's own Lua files in the manifest target (tests/fuzz/
 * fuzz_manifest.c), read and compiled once. Linked with
 * -Wl,--wrap=vmac_read_file,--wrap=luaL_loadbufferx, so every file the
 * sandbox reads and every chunk it loads come here first. In that target
 * the sandbox reads only the host's files, which no input changes (the
 * stdlib modules a driver requires, the programmes vmac.cycles() finds;
 * the driver's text, the input, comes in memory): each is read once and
 * handed out again as a copy, without the five system calls of every
 * read, a large share of the target's time. And a chunk of those
 * files (chunk names "@stdlib/..." and "@cycles/...";
 * core/driver/sandbox.c) is compiled once, in a Lua state of its own, and
 * from then on loaded from its bytecode: the same functions, line numbers
 * and names, without parsing the washer's stdlib modules and programmes
 * again for every input that loads the washer (bytecode loads several
 * times faster than text). Anything else, the driver's own text, is
 * parsed as the host parses it. With the arena off (VMAC_FUZZ_FRESH=1, the
 * replay in fresh sandboxes) every file is read and every chunk parsed.
 * docs/TESTING.md, "Fuzzing". */
#include <lauxlib.h>
#include <lua.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_arena.h"

int __real_luaL_loadbufferx(lua_State *L, const char *buf, size_t size, const char *name, const char *mode);
int __wrap_luaL_loadbufferx(lua_State *L, const char *buf, size_t size, const char *name, const char *mode);
char *__real_vmac_read_file(const char *path, size_t max, size_t *len, char *err, size_t errlen, int *code);
char *__wrap_vmac_read_file(const char *path, size_t max, size_t *len, char *err, size_t errlen, int *code);

#define FILES 32

/* The files read so far, as they were read: their text, or the error. */
struct file {
	char *path;
	size_t max;
	char *text; /* NULL: the read failed with err and code */
	size_t len;
	char err[600];
	int code;
};

static struct file files[FILES];
static int nfiles;

char *__wrap_vmac_read_file(const char *path, size_t max, size_t *len, char *err, size_t errlen, int *code)
{
	struct file *f = NULL;
	char *copy;
	int i;
	if (!fuzz_arena_on())
		return __real_vmac_read_file(path, max, len, err, errlen, code);
	for (i = 0; i < nfiles && !f; i++)
		if (files[i].max == max && strcmp(files[i].path, path) == 0)
			f = &files[i];
	if (!f) {
		if (nfiles == FILES || !(files[nfiles].path = strdup(path)))
			return __real_vmac_read_file(path, max, len, err, errlen, code);
		f = &files[nfiles++];
		f->max = max;
		f->text = __real_vmac_read_file(path, max, &f->len, f->err, sizeof(f->err), &f->code);
	}
	if (!f->text) {
		snprintf(err, errlen, "%s", f->err);
		*code = f->code;
		return NULL;
	}
	copy = malloc(f->len + 1); /* the caller frees it, as it frees a read */
	if (!copy)
		return __real_vmac_read_file(path, max, len, err, errlen, code);
	memcpy(copy, f->text, f->len + 1);
	*len = f->len;
	return copy;
}

#define CHUNKS 32

struct chunk {
	char *name;
	char *text; /* the text it was compiled from: a chunk is reused only for the same text */
	size_t text_len;
	char *code;
	size_t code_len;
};

static struct chunk chunks[CHUNKS];
static int nchunks;

static int host_file(const char *name)
{
	return name && (strncmp(name, "@stdlib/", 8) == 0 || strncmp(name, "@cycles/", 8) == 0);
}

static int append(lua_State *L, const void *p, size_t n, void *ud)
{
	struct chunk *c = ud;
	char *grown = realloc(c->code, c->code_len + n);
	(void)L;
	if (!grown)
		return 1;
	memcpy(grown + c->code_len, p, n);
	c->code = grown;
	c->code_len += n;
	return 0;
}

static void drop(struct chunk *c)
{
	free(c->name);
	free(c->text);
	free(c->code);
	memset(c, 0, sizeof(*c));
}

/* The chunk compiled from this name and text: found, compiled now, or NULL
 * (the text does not compile, or no room: the caller parses it). */
static const struct chunk *compiled(const char *buf, size_t size, const char *name)
{
	struct chunk *c;
	lua_State *own;
	int i, ok;
	for (i = 0; i < nchunks; i++)
		if (strcmp(chunks[i].name, name) == 0 && chunks[i].text_len == size &&
		    memcmp(chunks[i].text, buf, size) == 0)
			return &chunks[i];
	if (nchunks == CHUNKS)
		return NULL;
	c = &chunks[nchunks];
	c->name = strdup(name);
	c->text = malloc(size ? size : 1);
	own = luaL_newstate();
	if (!c->name || !c->text || !own) {
		if (own)
			lua_close(own);
		drop(c);
		return NULL;
	}
	memcpy(c->text, buf, size);
	c->text_len = size;
	ok = __real_luaL_loadbufferx(own, buf, size, name, "t") == 0 && lua_dump(own, append, c) == 0;
	lua_close(own);
	if (!ok) {
		drop(c);
		return NULL;
	}
	nchunks++;
	return c;
}

int __wrap_luaL_loadbufferx(lua_State *L, const char *buf, size_t size, const char *name, const char *mode)
{
	const struct chunk *c;
	if (!fuzz_arena_on() || !host_file(name) || !mode || strcmp(mode, "t") != 0)
		return __real_luaL_loadbufferx(L, buf, size, name, mode);
	c = compiled(buf, size, name);
	if (!c)
		return __real_luaL_loadbufferx(L, buf, size, name, mode);
	return __real_luaL_loadbufferx(L, c->code, c->code_len, name, "b");
}
