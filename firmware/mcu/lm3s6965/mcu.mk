# The board firmware on a microcontroller (included by the Makefile).
# The same portable files (PORTABLE_SRC, unchanged) on a Cortex-M3, the TI
# Stellaris LM3S6965 (QEMU's lm3s6965evb), with its HAL in MCU_DIR; picolibc
# for memcpy and the plants' exp/expm1/floor, double precision in software
# (the M3 has no FPU). docs/BOARD.md, "Firmware on a microcontroller".
MCU_CC      := arm-none-eabi-gcc
MCU_DIR     := firmware/mcu/lm3s6965
MCU_ARCH    := -mcpu=cortex-m3 -mthumb -mfloat-abi=soft --specs=picolibc.specs --picolibc-buildtype=release
MCU_CFLAGS  := $(MCU_ARCH) -std=c99 -pedantic $(WARN) -Os -g -ffunction-sections -fdata-sections
MCU_SRC     := $(PORTABLE_SRC) $(MCU_DIR)/startup.c $(MCU_DIR)/clock.c $(MCU_DIR)/uart.c $(MCU_DIR)/enet.c \
               $(MCU_DIR)/config.c $(MCU_DIR)/main.c
mcu_obj     = $(MCU_SRC:%.c=$(OBJ)/mcu/%.o)
FIRMWARE    = $(BUILD)/firmware/vmac-board-lm3s6965
# The tests boot the firmware in QEMU; without the cross compiler they say SKIPPED.
FIRMWARE_IF_TOOLS = $(if $(shell command -v $(MCU_CC)),$(FIRMWARE).elf $(FIRMWARE).bin)

$(mcu_obj): $(OBJ)/mcu/%.o: %.c
	@mkdir -p $(dir $@)
	$(MCU_CC) $(MCU_CFLAGS) -MMD -MP -c $< -o $@

$(FIRMWARE).elf: $(mcu_obj) $(MCU_DIR)/lm3s6965.ld
	@mkdir -p $(dir $@)
	$(MCU_CC) $(MCU_ARCH) -nostartfiles -T $(MCU_DIR)/lm3s6965.ld -Wl,--gc-sections -Wl,-Map=$(FIRMWARE).map \
		$(mcu_obj) -lm -o $@

$(FIRMWARE).bin: $(FIRMWARE).elf
	arm-none-eabi-objcopy -O binary $< $@

# Flash: code, constants and the initial values of .data; RAM: .data, .bss
# and the stack (lm3s6965.ld), all of it, no heap.
firmware: $(FIRMWARE).elf $(FIRMWARE).bin
	@arm-none-eabi-size $(FIRMWARE).elf
	@stack=$$(arm-none-eabi-size -A $(FIRMWARE).elf | awk '$$1 == ".stack" { print $$2 }'); \
	arm-none-eabi-size $(FIRMWARE).elf | awk -v stack=$$stack 'NR == 2 { \
		printf "firmware: %s.elf: flash %d bytes (%.1f KiB), RAM %d bytes (%.1f KiB, %d of them stack)\n", \
		"$(FIRMWARE)", $$1 + $$2, ($$1 + $$2) / 1024, $$2 + $$3, ($$2 + $$3) / 1024, stack }'

# The kitchen with its boards in QEMU on raw Ethernet (root: tap devices, a bridge).
run-qemu: deps
	@$(MAKE) --no-print-directory all firmware
	@exec ./scripts/run-qemu-kitchen.sh $(BUILD)/bin $(FIRMWARE).elf


# The cost of authenticated frames (tests/bench/mcu_auth.c, run by
# tests/bench/mcu_auth.py): the firmware's objects with a bench in main's
# place, so the code measured is the code that ships.
MCU_BENCH_SRC := $(filter-out $(MCU_DIR)/main.c,$(MCU_SRC)) tests/bench/mcu_auth.c
MCU_BENCH     := $(BUILD)/firmware/mcu-auth-bench.elf

$(OBJ)/mcu/tests/bench/mcu_auth.o: tests/bench/mcu_auth.c
	@mkdir -p $(dir $@)
	$(MCU_CC) $(MCU_CFLAGS) -MMD -MP -c $< -o $@

$(MCU_BENCH): $(MCU_BENCH_SRC:%.c=$(OBJ)/mcu/%.o) $(MCU_DIR)/lm3s6965.ld
	@mkdir -p $(dir $@)
	$(MCU_CC) $(MCU_ARCH) -nostartfiles -T $(MCU_DIR)/lm3s6965.ld -Wl,--gc-sections \
		$(MCU_BENCH_SRC:%.c=$(OBJ)/mcu/%.o) -lm -o $@

mcu-auth-bench: $(MCU_BENCH)
	@python3 tests/bench/mcu_auth.py $(MCU_BENCH)
