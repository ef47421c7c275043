/* Trust on the wire, the bus thread's side (docs/SECURITY.md, docs/
 * PROTOCOL.md "Authenticated frames"): the enrolled boards' keys by name,
 * the nonce of each discovery, a board's session keys, and what failed to
 * prove a key, said at most every AUTH_WARN_NS. The table is built by the
 * main thread (vmac_bus_keys_*) and handed over whole; the bus thread only
 * looks names up in it, without allocating. */
#include "bus_internal.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>

#include "../proto/auth.h"

#define AUTH_WARN_NS 10000000000LL /* failures are said at most this often */

struct key_slot {
	char board[VMAC_NAME_MAX + 1]; /* "" free */
	uint8_t key[VMAC_KEY_LEN];
};

struct vmac_bus_keys {
	uint32_t n, mask; /* keys in; slots - 1 (a power of two, at least twice n's room) */
	struct key_slot slot[];
};

static uint32_t hash_name(const char *s)
{
	uint32_t h = 2166136261u; /* FNV-1a: names are short, and who picks them is enrolled */
	for (; *s; s++)
		h = (h ^ (uint8_t)*s) * 16777619u;
	return h;
}

struct vmac_bus_keys *vmac_bus_keys_new(uint32_t n)
{
	uint32_t slots = 16;
	struct vmac_bus_keys *k;
	while (slots < 2 * n && slots < (1u << 24))
		slots <<= 1;
	k = calloc(1, sizeof(*k) + slots * sizeof(k->slot[0]));
	if (k)
		k->mask = slots - 1;
	return k;
}

static struct key_slot *find(const struct vmac_bus_keys *k, const char *board)
{
	uint32_t i = hash_name(board) & k->mask;
	for (;; i = (i + 1) & k->mask) {
		struct key_slot *s = (struct key_slot *)&k->slot[i];
		if (!s->board[0] || strcmp(s->board, board) == 0)
			return s;
	}
}

int vmac_bus_keys_add(struct vmac_bus_keys *k, const char *board, const uint8_t key[16])
{
	struct key_slot *s;
	if (!board[0] || strlen(board) > VMAC_NAME_MAX)
		return -EINVAL;
	s = find(k, board);
	if (!s->board[0]) {
		if (2 * (k->n + 1) > k->mask + 1)
			return -ENOSPC; /* half full at most: every probe ends at a free slot */
		snprintf(s->board, sizeof(s->board), "%s", board);
		k->n++;
	}
	memcpy(s->key, key, VMAC_KEY_LEN);
	return 0;
}

void vmac_bus_keys_free(struct vmac_bus_keys *k)
{
	if (!k)
		return;
	memset(k->slot, 0, (k->mask + 1) * sizeof(k->slot[0])); /* no key left behind in freed memory */
	free(k);
}

int vmac_bus_set_keys(struct vmac_bus *bus, struct vmac_bus_keys *keys)
{
	struct vmac_host_cmd c;
	memset(&c, 0, sizeof(c));
	c.kind = VMAC_CMD_KEYS;
	c.keys = keys;
	return vmac_bus_send_cmd(bus, &c);
}

const uint8_t *bus_key_of(const struct vmac_bus *bus, const char *board)
{
	const struct key_slot *s;
	if (!bus->keys)
		return NULL;
	s = find(bus->keys, board);
	return s->board[0] ? s->key : NULL;
}

uint32_t bus_keys_count(const struct vmac_bus *bus)
{
	return bus->keys ? bus->keys->n : 0;
}

void bus_keys_install(struct vmac_bus *bus, struct vmac_bus_keys *keys)
{
	struct vmac_bus_keys *old = bus->keys;
	uint32_t i;
	bus->keys = keys;
	if (old) {
		memset(old->slot, 0, (old->mask + 1) * sizeof(old->slot[0])); /* rare, and small: no key left behind */
		bus_unload_buffer(bus, old);
	}
	/* A board whose key was removed is no longer trusted: out of service
	 * now, not at its next announce. A changed key (rotation) takes effect
	 * at the next announce: the session's keys were made from the old one. */
	for (i = 0; i < bus->nused; i++) {
		struct device *d = &bus->dev[i];
		if (!d->keyed || bus_key_of(bus, d->ann.board))
			continue;
		/* d stays keyed: its SHUTDOWN is sealed, or the board would not obey
		 * it. Its machine goes with it (a driver being loaded included). */
		if (d->state == DEV_LOADING || d->state == DEV_REGISTERING || d->state == DEV_RUNNING ||
		    d->state == DEV_TO_SLEEP)
			bus_drop(bus, d, VMAC_SHUT_DROPPED, "dropped", "its key was removed (vmac board remove)");
	}
}

void bus_nonce_init(struct vmac_bus *bus)
{
	/* vmac test's runs repeat: its nonces are the same every run. */
	if (bus->virt || getrandom(bus->nonce_key, sizeof(bus->nonce_key), GRND_NONBLOCK) != sizeof(bus->nonce_key))
		memset(bus->nonce_key, 0x5a, sizeof(bus->nonce_key));
}

void bus_nonce_next(struct vmac_bus *bus)
{
	/* A keyed PRF of a counter: never repeats within a run, unknown to
	 * anyone without the key made at start (no system call per discovery). */
	uint8_t in[8];
	uint64_t c = ++bus->nonce_count;
	int i;
	for (i = 0; i < 8; i++)
		in[i] = (uint8_t)(c >> (8 * i));
	vmac_siphash24(bus->nonce_key, in, sizeof(in), bus->nonce);
}

void bus_session_keys(struct vmac_bus *bus, struct device *d, const uint8_t key[VMAC_KEY_LEN])
{
	vmac_proto_session_keys(key, bus->nonce, d->id, d->to_board, d->to_host);
	d->keyed = 1;
	d->tx_counter = 0;
	d->rx_counter = 0;
}

void bus_auth_failed(struct vmac_bus *bus, const struct vmac_packet *p, const char *board, const char *why)
{
	char addr[48];
	bus->counters.auth_failed++;
	if (bus->auth_said_ns && p->rx_ns - bus->auth_said_ns < AUTH_WARN_NS) {
		bus->auth_unsaid++;
		return;
	}
	bus_event(bus, NULL, "auth", "frame from %s claiming to be %s ignored: %s (%llu more since the last report)",
	          vmac_addr_format(&p->addr, addr, sizeof(addr)), board, why, (unsigned long long)bus->auth_unsaid);
	bus->auth_unsaid = 0;
	bus->auth_said_ns = p->rx_ns;
}
