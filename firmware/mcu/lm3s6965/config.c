/* The identity block in flash (config.h): the block as built (a washer,
 * "washer-1"), and its reading and checking at start. */
#include "config.h"

#include <string.h>

/* The block as built; scripts/qemu-board-config.py rewrites it in a copy of
 * the image. */
__attribute__((section(".vmac_config"), used)) const struct vmac_mcu_config vmac_mcu_config_block = {
    .magic = {'V', 'M', 'C', 'F'},
    .version = VMAC_MCU_CONFIG_VERSION,
    .size = VMAC_MCU_CONFIG_SIZE,
    .board = "washer-1",
    .driver = "washer",
    .plant = "washer",
    .protocol = VMAC_PROTO_VERSION, /* the MAC and the major from the name */
};

/* The layout is a contract with the script: a compiler that laid it out
 * otherwise fails here. */
typedef char config_size_check[sizeof(struct vmac_mcu_config) == VMAC_MCU_CONFIG_SIZE ? 1 : -1];
typedef char config_mac_check[offsetof(struct vmac_mcu_config, mac) == 88 ? 1 : -1];
typedef char config_major_check[offsetof(struct vmac_mcu_config, major) == 96 ? 1 : -1];
typedef char config_key_check[offsetof(struct vmac_mcu_config, key) == 104 ? 1 : -1];

/* The block as the flash holds it now: hidden from the optimiser, which
 * would otherwise read the values built in and never the patched ones. */
static const struct vmac_mcu_config *flash_block(void)
{
	const struct vmac_mcu_config *p = &vmac_mcu_config_block;
	__asm__("" : "+r"(p));
	return p;
}

/* A NUL-terminated text of at most cap - 1 characters copied into out. */
static int copy_text(char *out, const char *field, size_t cap)
{
	size_t n = 0;
	while (n < cap && field[n] != '\0')
		n++;
	if (n == 0 || n == cap)
		return -1;
	memcpy(out, field, n);
	out[n] = '\0';
	return 0;
}

int vmac_mcu_config_load(struct vmac_mcu_settings *s, const char **why)
{
	static const uint8_t no_mac[6] = {0, 0, 0, 0, 0, 0};
	const struct vmac_mcu_config *c = flash_block();
	char plant[sizeof(c->plant)];
	uint32_t hash;

	memset(s, 0, sizeof(*s));
	if (memcmp(c->magic, "VMCF", 4) != 0 || c->version < VMAC_MCU_CONFIG_VERSION_MIN ||
	    c->version > VMAC_MCU_CONFIG_VERSION || c->size != VMAC_MCU_CONFIG_SIZE) {
		*why = "no identity block of version 1 or 2 at 0x00000100 (magic VMCF)";
		return -1;
	}
	if (copy_text(s->id.board, c->board, sizeof(c->board)) != 0 ||
	    copy_text(s->id.driver, c->driver, sizeof(c->driver)) != 0) {
		*why = "board or driver name empty or not terminated";
		return -1;
	}
	if (copy_text(plant, c->plant, sizeof(c->plant)) != 0 || vmac_plant_kind_from_name(plant, &s->kind) != 0) {
		*why = "unknown plant (washer, dishwasher, lights, generic)";
		return -1;
	}
	s->id.caps = vmac_plant_caps(s->kind);
	if (!vmac_board_identity_valid(&s->id)) {
		*why = "board or driver name not 1..31 of A-Z a-z 0-9 _ -";
		return -1;
	}
	if (c->protocol > VMAC_PROTO_VERSION) {
		*why = "protocol version not 1 or 2";
		return -1;
	}
	s->id.protocol = c->protocol ? c->protocol : VMAC_PROTO_VERSION;
	hash = vmac_proto_default_major(s->id.board);
	s->id.major = (c->flags & VMAC_MCU_CONFIG_MAJOR_SET) ? c->major : hash;
	s->id.minor = c->minor;
	if (memcmp(c->mac, no_mac, sizeof(no_mac)) == 0) {
		/* vmac-board's rule for a single board of this name */
		s->mac[0] = 0x02;
		s->mac[1] = (uint8_t)(hash >> 16);
		s->mac[2] = (uint8_t)(hash >> 8);
		s->mac[3] = (uint8_t)hash;
		s->mac[4] = 0;
		s->mac[5] = 1;
	} else if (c->mac[0] & 1) {
		*why = "MAC is a group address";
		return -1;
	} else {
		memcpy(s->mac, c->mac, sizeof(s->mac));
	}
	s->quiet = (c->flags & VMAC_MCU_CONFIG_QUIET) != 0;
	/* Version 1 had no key: its flag bit and bytes are reserved, unkeyed. */
	if (c->version >= 2 && (c->flags & VMAC_MCU_CONFIG_KEYED)) {
		s->id.keyed = 1;
		memcpy(s->id.key, c->key, sizeof(s->id.key));
	}
	return 0;
}
