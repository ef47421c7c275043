/* Host configuration: defaults, Lua config file, key=value overrides. The
 * config file runs in a Lua state of its own, all of it inside one
 * protected call (lua_cpcall) with an instruction limit and a memory cap,
 * so a broken, endless or greedy file is an error with its reason, never a
 * panic, a hang or the machine's memory. */
#include "config.h"

#include "../common/addr.h"
#include "../common/file.h"
#include "../common/paths.h"
#include "../transport/transport.h"

#include <arpa/inet.h>
#include <errno.h>
#include <lauxlib.h>
#include <lua.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum kind { STR, U32, BOOL };

struct key {
	const char *name;
	enum kind kind;
	size_t offset, size;
	uint32_t min, max;
};

#define S(f) #f, STR, offsetof(struct vmac_config, f), sizeof(((struct vmac_config *)0)->f), 0, 0
#define U(f, lo, hi) #f, U32, offsetof(struct vmac_config, f), sizeof(uint32_t), lo, hi
#define B(f) #f, BOOL, offsetof(struct vmac_config, f), sizeof(int), 0, 1

static const struct key keys[] = {
    {S(bus)},
    {S(iface)},
    {S(http)},
    {S(metrics_http)},
    {S(drivers_dir)},
    {S(scripts_dir)},
    {S(stdlib_dir)},
    {S(state_dir)},
    {S(tls_cert)},
    {S(tls_key)},
    {S(deploy_keys)},
    {S(deploy_require_signature)},
    {U(slice_us, 1, 1000000)},
    {U(slices_per_slot, 1, 256)},
    {U(max_level, 0, 12)},
    {U(default_level, 0, 12)},
    {U(reply_deadline_us, 50, 10000000)},
    {U(discovery_period_ms, 10, 600000)},
    {U(clock_sync_ms, 0, 40)},
    {U(timed_lead_us, 0, 10000000)},
    {U(watchdog_ms, 1, 60000)},
    {U(miss_limit, 1, 1000)},
    {U(sleep_s, 1, 3600)},
    {U(max_devices, 1, 4096)},
    {U(http_header_timeout_s, 1, 3600)},
    {U(http_body_timeout_s, 1, 3600)},
    {U(http_connections_per_address, 1, 256)},
    {U(attach_max, 1, 4096)},
    {U(attach_rate, 1, 100000)},
    {U(driver_memory_kib, 64, 1048576)},
    {U(driver_instructions, 1000, 1000000000)},
    {U(driver_budget_us, 0, 10000000)},
    {U(driver_threads, 0, 64)},
    {U(reload_probation_s, 0, 86400)},
    {U(checkpoint_s, 0, 3600)},
    {U(checkpoint_kib, 1, 1024)},
    {U(recorder_s, 0, 3600)},
    {U(recordings_max, 1, 10000)},
    {B(allow_jit)},
    {B(realtime)},
    {B(cpu_awake)},
    {B(cyclic)},
    {S(bus_trust)},
    {S(mqtt_url)},
    {S(ui_url)},
    {S(mqtt_client_id)},
    {S(mqtt_host_id)},
    {S(mqtt_user)},
    {S(mqtt_password)},
    {S(mqtt_password_file)},
    {S(mqtt_cafile)},
    {S(mqtt_certfile)},
    {S(mqtt_keyfile)},
    {S(mqtt_prefix)},
    {S(mqtt_discovery_prefix)},
    {S(mqtt_discovery_mode)},
    {B(mqtt_commands)},
    {B(mqtt_sparkplug)},
    {S(mqtt_sparkplug_group)},
    {S(mqtt_sparkplug_primary_host)},
    {U(mqtt_keepalive_s, 5, 3600)},
};

void vmac_config_shipped_dirs(struct vmac_config *c)
{
	char root[VMAC_PATH_MAX];
	vmac_root_dir(root, sizeof(root));
	snprintf(c->scripts_dir, sizeof(c->scripts_dir), "%.900s/scripts", root);
	snprintf(c->stdlib_dir, sizeof(c->stdlib_dir), "%.900s/stdlib", root);
}

void vmac_config_defaults(struct vmac_config *c)
{
	memset(c, 0, sizeof(*c));
	snprintf(c->bus, sizeof(c->bus), "239.255.86.77:5870");
	snprintf(c->iface, sizeof(c->iface), "127.0.0.1");
	snprintf(c->http, sizeof(c->http), "127.0.0.1:8080");
	snprintf(c->state_dir, sizeof(c->state_dir), "/var/lib/vmac");
	snprintf(c->deploy_require_signature, sizeof(c->deploy_require_signature), "auto");
	c->slice_us = 100;
	c->slices_per_slot = 10;
	c->max_level = 10;
	c->default_level = 4;
	c->reply_deadline_us = 4000;
	c->discovery_period_ms = 1000;
	c->watchdog_ms = 500;
	c->miss_limit = 1;
	c->sleep_s = 10;
	c->max_devices = 1024;
	c->http_header_timeout_s = 10;
	c->http_body_timeout_s = 60;
	c->http_connections_per_address = 64;
	c->attach_max = 32;
	c->attach_rate = 100;
	c->driver_memory_kib = 4096;
	c->driver_instructions = 200000;
	c->driver_budget_us = 2000;
	c->reload_probation_s = 30;
	c->checkpoint_s = 5;
	c->checkpoint_kib = 16;
	c->recorder_s = 60;
	c->recordings_max = 50;
	c->realtime = 1;
	c->cyclic = 1;
	snprintf(c->bus_trust, sizeof(c->bus_trust), "enrolled");
	snprintf(c->mqtt_prefix, sizeof(c->mqtt_prefix), "vmac");
	snprintf(c->mqtt_discovery_prefix, sizeof(c->mqtt_discovery_prefix), "homeassistant");
	snprintf(c->mqtt_discovery_mode, sizeof(c->mqtt_discovery_mode), "component");
	snprintf(c->mqtt_sparkplug_group, sizeof(c->mqtt_sparkplug_group), "vmac");
	c->mqtt_keepalive_s = 30;
}

static const struct key *find_key(const char *name)
{
	size_t i;
	for (i = 0; i < sizeof(keys) / sizeof(keys[0]); i++)
		if (strcmp(keys[i].name, name) == 0)
			return &keys[i];
	return NULL;
}

/* driver.NAME.KEY = VALUE: kept as text; the driver's loader checks KEY
 * and VALUE against the driver (docs/HOST.md). */
static int set_driver(struct vmac_config *c, const char *name, const char *value, char *err, size_t errlen)
{
	const char *drv = name + 7, *dot = strchr(drv, '.');
	struct vmac_config_driver_setting *x;
	size_t dlen = dot ? (size_t)(dot - drv) : 0;
	int i;
	if (!dot || dlen == 0 || dlen > VMAC_NAME_MAX || !dot[1] || strlen(dot + 1) >= sizeof(x->s.key)) {
		snprintf(err, errlen,
		         "'%s': expected driver.NAME.KEY (KEY: memory_kib, instructions, budget_us, "
		         "param.NAME, timing.pattern, timing.input_us, timing.output_us)",
		         name);
		return -EINVAL;
	}
	if (strlen(value) >= sizeof(x->s.value)) {
		snprintf(err, errlen, "%s: value too long", name);
		return -EINVAL;
	}
	for (i = 0; i < c->ndriver; i++) {
		x = &c->driver[i];
		if (strlen(x->driver) == dlen && strncmp(x->driver, drv, dlen) == 0 && strcmp(x->s.key, dot + 1) == 0)
			break;
	}
	if (i == c->ndriver) {
		if (c->ndriver == VMAC_CONFIG_DRIVER_SETTINGS) {
			snprintf(err, errlen, "%s: more than %d driver settings", name, VMAC_CONFIG_DRIVER_SETTINGS);
			return -ENOSPC;
		}
		c->ndriver++;
	}
	x = &c->driver[i];
	memcpy(x->driver, drv, dlen);
	x->driver[dlen] = 0;
	snprintf(x->s.key, sizeof(x->s.key), "%s", dot + 1);
	snprintf(x->s.value, sizeof(x->s.value), "%s", value);
	return 0;
}

int vmac_config_driver_settings(const struct vmac_config *c, const char *driver, struct vmac_driver_setting *out,
                                int max)
{
	int i, n = 0;
	for (i = 0; i < c->ndriver && n < max; i++)
		if (strcmp(c->driver[i].driver, driver) == 0)
			out[n++] = c->driver[i].s;
	return n;
}

int vmac_config_set(struct vmac_config *c, const char *name, const char *value, char *err, size_t errlen)
{
	const struct key *k = find_key(name);
	char *field, *end;
	unsigned long v;

	if (strncmp(name, "driver.", 7) == 0)
		return set_driver(c, name, value, err, errlen);
	if (!k) {
		snprintf(err, errlen, "unknown setting '%s' (see docs/HOST.md)", name);
		return -EINVAL;
	}
	field = (char *)c + k->offset;
	switch (k->kind) {
	case STR:
		if (strlen(value) >= k->size) {
			snprintf(err, errlen, "%s: value too long (at most %zu characters)", name, k->size - 1);
			return -EINVAL;
		}
		memcpy(field, value, strlen(value) + 1);
		return 0;
	case BOOL:
		if (strcmp(value, "true") == 0 || strcmp(value, "1") == 0)
			*(int *)field = 1;
		else if (strcmp(value, "false") == 0 || strcmp(value, "0") == 0)
			*(int *)field = 0;
		else {
			snprintf(err, errlen, "%s: expected true or false, got '%s'", name, value);
			return -EINVAL;
		}
		return 0;
	case U32:
		errno = 0;
		v = strtoul(value, &end, 10);
		if (errno || *end || end == value || value[0] == '-' || v < k->min || v > k->max) {
			snprintf(err, errlen, "%s: expected a whole number %u..%u, got '%s'", name, k->min, k->max,
			         value);
			return -EINVAL;
		}
		*(uint32_t *)field = (uint32_t)v;
		return 0;
	}
	return -EINVAL;
}

/* Apply the settings in the table on top; nested tables (only under
 * driver = {...}) become dotted keys: driver.washer.param.fill_l. */
static int apply_table(struct vmac_config *c, lua_State *L, const char *path, const char *prefix, int depth, char *err,
                       size_t errlen)
{
	lua_pushnil(L);
	while (lua_next(L, -2)) {
		char value[VMAC_PATH_MAX], key[200];
		const char *name = lua_type(L, -2) == LUA_TSTRING ? lua_tostring(L, -2) : NULL;
		if (!name) {
			snprintf(err, errlen, "%s: setting names must be strings", path);
			return -EINVAL;
		}
		snprintf(key, sizeof(key), "%s%s", prefix, name);
		if (lua_type(L, -1) == LUA_TBOOLEAN)
			snprintf(value, sizeof(value), "%s", lua_toboolean(L, -1) ? "true" : "false");
		else if (lua_type(L, -1) == LUA_TNUMBER || lua_type(L, -1) == LUA_TSTRING)
			snprintf(value, sizeof(value), "%s", lua_tostring(L, -1));
		else if (lua_istable(L, -1) && depth < 3 && strncmp(key, "driver", 6) == 0) {
			char sub[200];
			snprintf(sub, sizeof(sub), "%s.", key);
			int rc = apply_table(c, L, path, sub, depth + 1, err, errlen);
			if (rc != 0)
				return rc;
			lua_pop(L, 1);
			continue;
		} else {
			snprintf(err, errlen, "%s: %s must be a string, number or boolean", path, key);
			return -EINVAL;
		}
		if (vmac_config_set(c, key, value, err, errlen) != 0) {
			char msg[256];
			snprintf(msg, sizeof(msg), "%s", err);
			snprintf(err, errlen, "%s: %s", path, msg);
			return -EINVAL;
		}
		lua_pop(L, 1);
	}
	return 0;
}

/* A settings file needs a few thousand instructions and a few KiB; these
 * leave hundreds of times that, and a runaway file is refused in
 * milliseconds (docs/HOST.md, "Settings"). */
#define CONFIG_INSTRUCTIONS 1000000
#define CONFIG_MEMORY (1u << 20)    /* bytes of the file's Lua state */
#define CONFIG_ALLOCATED (4u << 20) /* bytes it may allocate in all, freed or not */
#define CONFIG_FILE_MAX (64 * 1024) /* bytes of the file; a settings file is a few hundred */

/* What the file's state has allocated: in use now, and in all; which
 * bound refused an allocation (0 none, 1 in use, 2 in all). */
struct config_heap {
	size_t used, total;
	int refused;
};

/* The state's allocator: refuses to grow past CONFIG_MEMORY in use or
 * CONFIG_ALLOCATED in all (LuaJIT then raises "not enough memory" inside
 * the protected call). Without the first `s = s .. s` forty times took all
 * the memory there was; without the second `for i = 1, 1e9 do s = 2 .. s
 * end` copied gigabytes within its instructions, for most of a second
 * (seconds and gigabytes of RSS under ASan; both found by
 * tests/fuzz/fuzz_config.c). */
static void *config_alloc(void *ud, void *ptr, size_t osize, size_t nsize)
{
	struct config_heap *h = ud;
	void *p;
	if (!ptr)
		osize = 0;
	if (nsize == 0) {
		free(ptr);
		h->used -= osize;
		return NULL;
	}
	if (nsize > osize && h->used - osize + nsize > CONFIG_MEMORY) {
		h->refused = 1;
		return NULL;
	}
	if (nsize > osize && h->total + (nsize - osize) > CONFIG_ALLOCATED) {
		h->refused = 2;
		return NULL;
	}
	p = realloc(ptr, nsize);
	if (p) {
		h->used = h->used - osize + nsize;
		h->total += nsize > osize ? nsize - osize : 0;
	}
	return p;
}

static void config_too_long(lua_State *L, lua_Debug *ar)
{
	(void)ar;
	luaL_error(L, "the file ran for more than %d instructions (settings are plain assignments)",
	           CONFIG_INSTRUCTIONS);
}

struct config_load {
	struct vmac_config *c;
	const char *name, *text;
	size_t len;
	char *err;
	size_t errlen;
	int rc;
};

/* The whole load, lua_cpcall'd: [-0, +0]; a raise is the file's error. */
static int config_load_protected(lua_State *L)
{
	struct config_load *a = lua_touserdata(L, 1);
	/* The file runs with an empty environment: plain assignments only.
	 * Text only: LuaJIT's bytecode loader trusts its input, and a damaged
	 * bytecode file would crash the host (found by tests/fuzz/fuzz_config.c). */
	lua_pushfstring(L, "@%s", a->name);
	if (luaL_loadbufferx(L, a->text, a->len, lua_tostring(L, -1), "t") != 0)
		return lua_error(L);
	lua_newtable(L);
	lua_pushvalue(L, -1);
	lua_insert(L, -3); /* env, chunk, env */
	lua_setfenv(L, -2);
	lua_sethook(L, config_too_long, LUA_MASKCOUNT, CONFIG_INSTRUCTIONS);
	lua_call(L, 0, 0);
	lua_sethook(L, NULL, 0, 0);
	a->rc = apply_table(a->c, L, a->name, "", 0, a->err, a->errlen);
	return 0;
}

int vmac_config_load_text(struct vmac_config *c, const char *name, const char *text, size_t len, char *err,
                          size_t errlen)
{
	struct config_heap heap = {0, 0, 0};
	lua_State *L = lua_newstate(config_alloc, &heap);
	struct config_load a = {c, name, text, len, err, errlen, -1};
	const char *msg;
	int rc;

	if (!L) {
		snprintf(err, errlen, "%s: cannot create Lua state", name);
		return -ENOMEM;
	}
	if ((rc = lua_cpcall(L, config_load_protected, &a)) != 0) {
		if (rc == LUA_ERRMEM && heap.refused == 2)
			msg = "the file allocated more than 4 MiB in all (settings are plain assignments)";
		else if (rc == LUA_ERRMEM)
			msg = "the file needs more than 1 MiB (settings are plain assignments)";
		else
			msg = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "error object is not a string";
		if (strncmp(msg, name, strlen(name)) == 0)
			snprintf(err, errlen, "%s", msg);
		else
			snprintf(err, errlen, "%s: %s", name, msg);
		a.rc = -1;
	}
	lua_close(L);
	return a.rc;
}

int vmac_config_load(struct vmac_config *c, const char *path, char *err, size_t errlen)
{
	size_t len;
	int rc, code;
	char *text = vmac_read_file(path, CONFIG_FILE_MAX, &len, err, errlen, &code);
	if (!text)
		return code;
	rc = vmac_config_load_text(c, path, text, len, err, errlen);
	free(text);
	return rc;
}

/* "IPv4:PORT" with port 0..65535. */
static int listen_ok(const char *text)
{
	struct in_addr a;
	uint16_t port;
	return vmac_addr_parse(text, &a, &port) == 0;
}

int vmac_config_trust_open(const struct vmac_config *c)
{
	return strcmp(c->bus_trust, "open") == 0;
}

int vmac_config_check(const struct vmac_config *c, char *err, size_t errlen)
{
	struct vmac_bus_spec spec;
	struct in_addr a;
	if (strcmp(c->bus_trust, "enrolled") != 0 && strcmp(c->bus_trust, "open") != 0) {
		snprintf(err, errlen,
		         "bus_trust '%s': expected enrolled (only boards whose key this host holds) or open (any "
		         "board; docs/SECURITY.md)",
		         c->bus_trust);
		return -EINVAL;
	}
	if (vmac_bus_spec_parse(c->bus, &spec) != 0) {
		snprintf(err, errlen,
		         "bus '%s': expected MULTICAST_GROUP:PORT (UDP, e.g. 239.255.86.77:5870) or eth:IFACE (raw "
		         "Ethernet, e.g. eth:eth0)",
		         c->bus);
		return -EINVAL;
	}
	if (spec.kind == VMAC_TRANSPORT_UDP && inet_pton(AF_INET, c->iface, &a) != 1) {
		snprintf(err, errlen, "iface '%s': expected an IPv4 address of this machine, e.g. 127.0.0.1", c->iface);
		return -EINVAL;
	}
	if (!listen_ok(c->http)) {
		snprintf(err, errlen, "http '%s': expected IPv4ADDR:PORT, e.g. 127.0.0.1:8080", c->http);
		return -EINVAL;
	}
	if (c->metrics_http[0] && !listen_ok(c->metrics_http)) {
		snprintf(err, errlen,
		         "metrics_http '%s': expected IPv4ADDR:PORT, e.g. 127.0.0.1:9108, or \"\" for none",
		         c->metrics_http);
		return -EINVAL;
	}
	if (c->default_level > c->max_level) {
		snprintf(err, errlen, "default_level (%u) must not exceed max_level (%u)", c->default_level,
		         c->max_level);
		return -EINVAL;
	}
	if ((uint64_t)c->slice_us * c->slices_per_slot > 10000000) {
		snprintf(err, errlen, "a slot (slice_us x slices_per_slot = %llu us) must not exceed 10 s",
		         (unsigned long long)c->slice_us * c->slices_per_slot);
		return -EINVAL;
	}
	if (strcmp(c->deploy_require_signature, "auto") != 0 && strcmp(c->deploy_require_signature, "yes") != 0 &&
	    strcmp(c->deploy_require_signature, "no") != 0) {
		snprintf(err, errlen, "deploy_require_signature '%s': expected auto, yes or no",
		         c->deploy_require_signature);
		return -EINVAL;
	}
	if (c->timed_lead_us >= vmac_config_slot_us(c)) {
		snprintf(err, errlen,
		         "timed_lead_us (%u) must be below a slot (%u us): a phase-aligned machine's instant is its "
		         "slot's start plus the lead (0: half a slot)",
		         c->timed_lead_us, vmac_config_slot_us(c));
		return -EINVAL;
	}
	if ((uint64_t)c->watchdog_ms * 1000 < 2ull * vmac_config_slot_us(c)) {
		snprintf(err, errlen, "watchdog_ms (%u) must be at least two slots (%u us)", c->watchdog_ms,
		         2 * vmac_config_slot_us(c));
		return -EINVAL;
	}
	return 0;
}
