/* The board's identity block in flash: which board this is (name, driver,
 * plant, MAC, ids, and its key when keyed), at a fixed address so that a programmer, or
 * scripts/qemu-board-config.py for a copy of the image, can set it without
 * building again. docs/BOARD.md, "Firmware on a microcontroller", is the
 * contract; keep the two and the script in step. */
#ifndef VMAC_MCU_CONFIG_H
#define VMAC_MCU_CONFIG_H

#include <stdint.h>

#include "../../board.h"
#include "../../plant.h"

/* Flash address of the block: right after the vector table, in the first
 * flash page (lm3s6965.ld places the section .vmac_config there). */
#define VMAC_MCU_CONFIG_ADDR 0x00000100u
/* Version 2 added the key, in bytes that version 1 reserved (0): a block of
 * version 1 still loads, unkeyed; firmware that knows only version 1
 * refuses a block of version 2 rather than run a keyed board unkeyed. */
#define VMAC_MCU_CONFIG_VERSION 2
#define VMAC_MCU_CONFIG_VERSION_MIN 1
#define VMAC_MCU_CONFIG_SIZE 128

/* flags */
#define VMAC_MCU_CONFIG_MAJOR_SET 0x01 /* use major; else the FNV-1a hash of the board name */
#define VMAC_MCU_CONFIG_QUIET 0x02     /* log only state changes other than "known" and safety events */
#define VMAC_MCU_CONFIG_KEYED 0x04     /* version 2: keyed with key (docs/PROTOCOL.md, "Authenticated frames") */

/* 128 bytes; multi-byte numbers little-endian (the CPU's order). Names are
 * NUL-terminated and NUL-padded. */
struct vmac_mcu_config {
	char magic[4];       /* "VMCF" */
	uint16_t version;    /* VMAC_MCU_CONFIG_VERSION */
	uint16_t size;       /* VMAC_MCU_CONFIG_SIZE */
	char board[32];      /* 1..31 of [A-Za-z0-9_-] */
	char driver[32];     /* the driver it announces, same rule */
	char plant[16];      /* washer, dishwasher, lights or generic */
	uint8_t mac[6];      /* all zero: 02:h1:h2:h3:00:01 from the name's hash, as vmac-board */
	uint8_t protocol;    /* highest protocol version spoken: 1 or 2 (0 means 2) */
	uint8_t flags;       /* VMAC_MCU_CONFIG_* */
	uint32_t major;      /* with VMAC_MCU_CONFIG_MAJOR_SET */
	uint32_t minor;      /* the minor id */
	uint8_t key[16];     /* version 2, with VMAC_MCU_CONFIG_KEYED: the board's key; else 0 */
	uint8_t reserved[8]; /* 0 */
};

/* What the firmware runs with, checked and completed from the block. */
struct vmac_mcu_settings {
	struct vmac_board_identity id;
	enum vmac_plant_kind kind;
	uint8_t mac[6];
	int quiet;
};

/* Read the block in flash, check every field and derive what it leaves to
 * the firmware (MAC, major). Returns 0, or -1 with *why saying which field
 * is wrong (the board then stays off the bus). */
int vmac_mcu_config_load(struct vmac_mcu_settings *s, const char **why);

#endif
