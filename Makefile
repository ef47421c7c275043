# vmac: one Makefile, meant to be read top to bottom.
#
#   make            build build/bin/{vmacd,vmac,vmac-board}
#   make firmware   the board firmware for a Cortex-M3 (LM3S6965): build/firmware/vmac-board-lm3s6965.{elf,bin}
#   make deps       install missing Debian packages (apt-get; sudo when not root)
#   make run        deps + build + the demo kitchen (host and three mock boards)
#   make run-qemu   deps + build + firmware + the kitchen with boards in QEMU on raw Ethernet (root)
#   make test       deps + build + every test (unit, fuzz, integration, the web UI in chromium,
#                   then again under ASan+UBSan)
#   make fuzz       every libFuzzer harness FUZZ_SECONDS each (default 60) in FUZZ_JOBS processes
#                   (default nproc), executions per target
#   make bench      timing figures as ratios to baselines run alongside (BENCH_SECONDS=60)
#   make soak       one host under every fault at once for SOAK_MINUTES (default 60), its resources
#                   sampled every 10 s; make test-soak: the same for 2 minutes
#   make clean

BUILD   ?= build
CC      ?= cc
CFLAGS  ?= -O2 -g
SAN     ?=
SUDO    := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

# Debian packages: compiler and pkg-config, the libraries the host links
# (LuaJIT, libev, libmicrohttpd, jansson, libcurl, SQLite, libsodium), Check for unit tests,
# clang + its runtime for the libFuzzer harness, python3 for integration tests,
# luajit for the escape corpus's bytecode driver, lua-check for vmac lint, openssl for the
# TLS test's certificate; the Arm cross compiler, picolibc and QEMU for the firmware on a
# microcontroller and its tests (make firmware, tests/integration/test_qemu.py); libmosquitto for
# vmacd's MQTT client, and the mosquitto broker and python3-paho-mqtt for its tests (test_mqtt.py,
# test_sparkplug.py); protoc-c and libprotobuf-c for its Sparkplug B payloads (core/mqtt/sparkplug_b.proto).
DEBS := build-essential pkg-config libluajit-5.1-dev libev-dev libmicrohttpd-dev libjansson-dev \
        libcurl4-openssl-dev libsqlite3-dev libsodium-dev check clang libclang-rt-dev python3 lua-check luajit \
        openssl clang-format iproute2 util-linux gcc-arm-none-eabi picolibc-arm-none-eabi qemu-system-arm \
        libmosquitto-dev mosquitto python3-paho-mqtt protobuf-c-compiler libprotobuf-c-dev

# make bench also needs cyclictest, its lateness baseline.
BENCH_DEBS := rt-tests

PKGS := luajit libmicrohttpd jansson libcurl sqlite3 libsodium
PKG_CFLAGS = $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
PKG_LIBS   = $(shell pkg-config --libs $(PKGS) 2>/dev/null) -lev -lpthread -lm
# vmacd links the MQTT client (core/mqtt/, docs/MQTT.md), and protobuf-c for Sparkplug B; vmac links
# libmosquitto alone, for `vmac site` (core/cli/site.c).
MQTT_LIBS  = $(shell pkg-config --libs libmosquitto 2>/dev/null || echo -lmosquitto) \
             $(shell pkg-config --libs libprotobuf-c 2>/dev/null || echo -lprotobuf-c)
SITE_LIBS  = $(shell pkg-config --libs libmosquitto 2>/dev/null || echo -lmosquitto)

# Strict warnings everywhere. -Wno-format-truncation: snprintf truncation
# into fixed buffers is the intended behaviour (names and texts are capped).
WARN := -Wall -Wextra -Werror -Wshadow -Wstrict-prototypes -Wmissing-prototypes -Wpointer-arith \
        -Wwrite-strings -Wundef -Wvla -Wformat=2 -Wno-format-nonliteral -Wno-format-truncation
# The board firmware and the wire codec are portable C99 (no heap, no OS headers).
PORTABLE_CFLAGS = -std=c99 -pedantic $(WARN) $(CFLAGS) $(SAN)
HOST_CFLAGS     = -std=c11 -D_GNU_SOURCE $(WARN) $(CFLAGS) $(SAN) $(PKG_CFLAGS)
LDFLAGS_ALL     = $(SAN) $(LDFLAGS)

PORTABLE_SRC := core/proto/proto.c firmware/board.c firmware/plant.c \
                firmware/plants/washer.c firmware/plants/dishwasher.c firmware/plants/lights.c firmware/plants/generic.c
# The driver sandbox (core/driver/internal.h says which file owns what) and
# the bounded file reader (core/common/file.c) every whole-file read uses.
DRIVER_SRC   := core/driver/protect.c core/driver/sandbox.c core/driver/bounded.c core/driver/manifest.c core/driver/load.c \
                core/driver/instance.c core/driver/takeover.c core/driver/checkpoint.c core/common/file.c
HOST_SRC     := core/common/paths.c core/common/addr.c core/transport/transport.c core/transport/transport_udp.c \
                core/transport/transport_eth.c $(DRIVER_SRC) core/host/bus.c core/host/wait.c core/host/realtime.c core/host/devices.c core/host/mailbox.c core/host/status.c core/host/jobs.c core/host/workers.c core/host/checkpoint.c core/host/record.c core/recorder/recorder.c core/recorder/recording.c core/reload/swap.c core/host/config.c core/reload/deploy.c \
                core/host/events.c core/host/hist.c core/reload/loader.c core/host/ring.c core/api/http.c core/api/api_request.c core/api/api_devices.c core/api/api_drivers.c core/api/api_events.c core/api/api_recordings.c core/api/api_site.c core/mqtt/site.c core/api/console.c core/sched/sched.c core/sched/search.c \
                core/store/store.c core/store/store_checkpoint.c core/store/store_recording.c
# vmacd's MQTT client (core/mqtt/mqtt_internal.h says which file owns what).
MQTT_SRC     := core/mqtt/mqtt_settings.c core/mqtt/mqtt_client.c core/mqtt/mqtt_devices.c core/mqtt/mqtt_native.c \
                core/mqtt/mqtt_ha.c core/mqtt/mqtt_sparkplug.c core/mqtt/mqtt_site.c
# vmac test: the host core and the board firmware on one virtual clock.
VTEST_SRC    := core/vtest/world.c core/vtest/vtest.c core/vtest/replay.c
OBJ = $(BUILD)/obj

portable_obj = $(PORTABLE_SRC:%.c=$(OBJ)/%.o)
driver_obj   = $(DRIVER_SRC:%.c=$(OBJ)/%.o)
host_obj     = $(HOST_SRC:%.c=$(OBJ)/%.o) $(OBJ)/gen/ui_assets.o
vtest_obj    = $(VTEST_SRC:%.c=$(OBJ)/%.o)
mqtt_obj     = $(MQTT_SRC:%.c=$(OBJ)/%.o) $(OBJ)/gen/sparkplug_b.pb-c.o

BINS := $(BUILD)/bin/vmacd $(BUILD)/bin/vmac $(BUILD)/bin/vmac-board
UNIT_TESTS := $(BUILD)/tests/test_proto $(BUILD)/tests/test_proto_reject $(BUILD)/tests/test_board $(BUILD)/tests/test_plant \
              $(BUILD)/tests/test_host \
              $(BUILD)/tests/test_driver $(BUILD)/tests/test_isolation $(BUILD)/tests/test_sched $(BUILD)/tests/test_store \
              $(BUILD)/tests/test_proto_v2 $(BUILD)/tests/test_cyclic $(BUILD)/tests/test_board_v2 $(BUILD)/tests/test_board_cyclic \
              $(BUILD)/tests/test_transport $(BUILD)/tests/test_checkpoint $(BUILD)/tests/test_recording


.PHONY: format format-check test-build asan-build
.PHONY: all deps run test test-unit test-lua test-drivers test-fuzz fuzz test-integration test-ui test-asan bench clean
.PHONY: firmware run-qemu soak test-soak tahu-deps
all: $(BINS)

$(portable_obj): $(OBJ)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(PORTABLE_CFLAGS) -MMD -MP -c $< -o $@

$(OBJ)/%.o: %.c
	@mkdir -p $(dir $@)
	$(CC) $(HOST_CFLAGS) -MMD -MP -c $< -o $@

# The web UI's files, built into vmacd (core/api/ui/embed.py).
UI_FILES := $(sort $(wildcard core/api/ui/*.html core/api/ui/*.js core/api/ui/*.css))
$(BUILD)/gen/ui_assets.c: core/api/ui/embed.py $(UI_FILES)
	@mkdir -p $(dir $@)
	python3 core/api/ui/embed.py $@ $(UI_FILES)

$(OBJ)/gen/ui_assets.o: $(BUILD)/gen/ui_assets.c core/api/ui_assets.h
	@mkdir -p $(dir $@)
	$(CC) $(HOST_CFLAGS) -Icore/api -c $< -o $@

# Sparkplug B's payload (core/mqtt/sparkplug_b.proto, from the specification) in C, made by protoc-c.
SPB_GEN := $(BUILD)/gen/sparkplug_b.pb-c
$(SPB_GEN).c: core/mqtt/sparkplug_b.proto
	@mkdir -p $(dir $@)
	protoc-c --proto_path=core/mqtt --c_out=$(BUILD)/gen $<
$(SPB_GEN).h: $(SPB_GEN).c

$(OBJ)/gen/sparkplug_b.pb-c.o: $(SPB_GEN).c $(SPB_GEN).h
	@mkdir -p $(dir $@)
	$(CC) $(HOST_CFLAGS) -I$(BUILD)/gen -c $< -o $@

$(OBJ)/core/mqtt/mqtt_sparkplug.o: $(SPB_GEN).h
$(OBJ)/core/mqtt/mqtt_sparkplug.o: HOST_CFLAGS += -I$(BUILD)/gen

$(BUILD)/bin/vmacd: $(OBJ)/core/vmacd/main.o $(mqtt_obj) $(host_obj) $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(PKG_LIBS) $(MQTT_LIBS)

$(BUILD)/bin/vmac: $(OBJ)/core/cli/vmac.o $(OBJ)/core/cli/token.o $(OBJ)/core/cli/client.o \
                   $(OBJ)/core/cli/console.o $(OBJ)/core/cli/events.o $(OBJ)/core/cli/reload.o $(OBJ)/core/cli/command.o $(OBJ)/core/cli/recordings.o $(OBJ)/core/cli/lint.o \
                   $(OBJ)/core/cli/site.o $(OBJ)/core/mqtt/mqtt_settings.o \
                   $(vtest_obj) $(host_obj) $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(PKG_LIBS) $(SITE_LIBS)

$(BUILD)/bin/vmac-board: $(OBJ)/firmware/posix/main.o $(OBJ)/firmware/posix/boards.o $(OBJ)/firmware/posix/dispatch.o \
                          $(OBJ)/core/transport/transport.o $(OBJ)/core/transport/transport_udp.o \
                          $(OBJ)/core/transport/transport_eth.o $(OBJ)/core/common/addr.o \
                          $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) -lm

# ---- the board firmware on a microcontroller ----
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

# ---- tests ----
CHECK_LIBS = $(shell pkg-config --libs check 2>/dev/null)

$(BUILD)/tests/test_proto: $(OBJ)/tests/unit/test_proto.o $(OBJ)/core/proto/proto.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS)

$(BUILD)/tests/test_board: $(OBJ)/tests/unit/test_board.o $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) -lm

$(BUILD)/tests/test_plant: $(OBJ)/tests/unit/test_plant.o $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) -lm

$(BUILD)/tests/test_proto_reject: $(OBJ)/tests/unit/test_proto_reject.o $(OBJ)/core/proto/proto.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS)

$(BUILD)/tests/test_proto_v2: $(OBJ)/tests/unit/test_proto_v2.o $(OBJ)/core/proto/proto.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS)

$(BUILD)/tests/test_cyclic: $(OBJ)/tests/unit/test_cyclic.o $(OBJ)/core/proto/proto.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS)

$(BUILD)/tests/test_board_v2: $(OBJ)/tests/unit/test_board_v2.o $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) -lm

$(BUILD)/tests/test_board_cyclic: $(OBJ)/tests/unit/test_board_cyclic.o $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) -lm

$(BUILD)/tests/test_host: $(OBJ)/tests/unit/test_host.o $(host_obj) $(portable_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) $(PKG_LIBS)

$(BUILD)/tests/test_driver: $(OBJ)/tests/unit/test_driver.o $(driver_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) $(PKG_LIBS)

# White-box: reaches the driver's insides (core/driver/internal.h).
$(BUILD)/tests/test_isolation: $(OBJ)/tests/unit/test_isolation.o $(driver_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) $(PKG_LIBS)

$(BUILD)/tests/test_sched: $(OBJ)/tests/unit/test_sched.o $(OBJ)/core/sched/sched.o $(OBJ)/core/sched/search.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS)

$(BUILD)/tests/test_store: $(OBJ)/tests/unit/test_store.o $(OBJ)/core/store/store.o $(OBJ)/core/store/store_checkpoint.o $(OBJ)/core/store/store_recording.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) $(PKG_LIBS)

# Checkpoints: dev.state through the driver's encoder and decoder, and the
# store's table of them (white-box: core/driver/internal.h).
$(BUILD)/tests/test_checkpoint: $(OBJ)/tests/unit/test_checkpoint.o $(driver_obj) $(OBJ)/core/store/store.o \
                                $(OBJ)/core/store/store_checkpoint.o $(OBJ)/core/store/store_recording.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) $(PKG_LIBS)

# The flight recorder's rings and its recordings as files.
$(BUILD)/tests/test_recording: $(OBJ)/tests/unit/test_recording.o $(OBJ)/core/recorder/recorder.o \
                               $(OBJ)/core/recorder/recording.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS) $(PKG_LIBS)

# The transports; the raw-Ethernet round trip runs over a veth pair in a
# network namespace of its own (root), else it is SKIPPED into $(SKIPPED).
TRANSPORT_OBJ := $(OBJ)/core/transport/transport.o $(OBJ)/core/transport/transport_udp.o \
                 $(OBJ)/core/transport/transport_eth.o $(OBJ)/core/common/addr.o $(OBJ)/core/proto/proto.o
$(BUILD)/tests/test_transport: $(OBJ)/tests/unit/test_transport.o $(TRANSPORT_OBJ)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(CHECK_LIBS)

# The stdlib's Lua tests, each case in a real driver sandbox (tests/lua/run.c;
# white-box: core/driver/internal.h).
$(BUILD)/tests/lua_tests: $(OBJ)/tests/lua/run.o $(driver_obj)
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(PKG_LIBS)

# The store killed mid-write (tests/integration/test_store.py).
$(BUILD)/tests/store_crash: $(OBJ)/tests/store/store_crash.o $(OBJ)/core/store/store.o $(OBJ)/core/store/store_checkpoint.o $(OBJ)/core/store/store_recording.o
	@mkdir -p $(dir $@)
	$(CC) $^ -o $@ $(LDFLAGS_ALL) $(PKG_LIBS)

# ---- fuzzing (docs/TESTING.md, "Fuzzing") ----
# One libFuzzer harness per parser, tests/fuzz/fuzz_NAME.c, its seeds in
# tests/fuzz/corpus-NAME/ (and a dictionary tests/fuzz/NAME.dict where one
# helps). Everything a harness links is built again with clang, libFuzzer's
# coverage and ASan+UBSan, under $(BUILD)/fuzz/obj; what the fuzzer finds
# goes to $(BUILD)/fuzz/work-NAME, never to the committed seeds.
FUZZ_TARGETS := proto config console manifest values http checkpoint
FUZZ_SAN     := -fsanitize=address,undefined -fno-sanitize-recover=all
FUZZ_CFLAGS   = -std=c11 -D_GNU_SOURCE -g -O2 -fno-omit-frame-pointer $(WARN) -Wno-unknown-warning-option $(FUZZ_SAN) \
                -fsanitize=fuzzer-no-link $(PKG_CFLAGS)
FUZZ_LINK     = clang $(FUZZ_SAN) -fsanitize=fuzzer $^ -o $@
FOBJ          = $(BUILD)/fuzz/obj
fuzz_obj      = $(1:%.c=$(FOBJ)/%.o)

$(FOBJ)/%.o: %.c
	@mkdir -p $(dir $@)
	clang $(FUZZ_CFLAGS) -MMD -MP -c $< -o $@

# The arena is the harnesses' heap, and fuzz_hostfiles.c the manifest
# target's reader and compiler of the host's own Lua files, not code under
# test: no coverage of them.
$(FOBJ)/tests/fuzz/fuzz_arena.o $(FOBJ)/tests/fuzz/fuzz_hostfiles.o: $(FOBJ)/%.o: %.c
	@mkdir -p $(dir $@)
	clang $(filter-out -fsanitize=fuzzer-no-link,$(FUZZ_CFLAGS)) -MMD -MP -c $< -o $@

# The wire codec and the board (portable C99).
$(BUILD)/fuzz/fuzz_proto: tests/fuzz/fuzz_proto.c core/proto/proto.c firmware/board.c
	@mkdir -p $(dir $@)
	clang -std=c99 -g -O2 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all $^ -o $@

# The config file and key=value settings (vmac_config_load/set/check).
$(BUILD)/fuzz/fuzz_config: $(call fuzz_obj,tests/fuzz/fuzz_config.c core/host/config.c core/common/addr.c core/common/file.c \
                            core/transport/transport.c core/transport/transport_udp.c core/transport/transport_eth.c \
                            core/proto/proto.c)
	$(FUZZ_LINK) $(PKG_LIBS)

# The line console's grammar (core/api/console.c), the host behind fakes.
$(BUILD)/fuzz/fuzz_console: $(call fuzz_obj,tests/fuzz/fuzz_console.c core/api/console.c)
	$(FUZZ_LINK)

# A driver's source through load and manifest validation, then one run.
# The stdlib's and the programmes' files read and compiled once
# (fuzz_hostfiles.c wraps vmac_read_file and luaL_loadbufferx).
$(BUILD)/fuzz/fuzz_manifest: $(call fuzz_obj,tests/fuzz/fuzz_manifest.c tests/fuzz/fuzz_arena.c tests/fuzz/fuzz_hostfiles.c \
                              $(DRIVER_SRC) core/api/api_request.c core/api/console.c)
	$(FUZZ_LINK) -Wl,--wrap=vmac_read_file,--wrap=luaL_loadbufferx $(PKG_LIBS)

# Lua values to outputs, variables and params and back (core/driver/instance.c).
$(BUILD)/fuzz/fuzz_values: $(call fuzz_obj,tests/fuzz/fuzz_values.c tests/fuzz/fuzz_arena.c $(DRIVER_SRC))
	$(FUZZ_LINK) $(PKG_LIBS)

# The HTTP API's routing, request bodies and arguments, and the console's
# body (core/api/api_request.c), no sockets.
$(BUILD)/fuzz/fuzz_http: $(call fuzz_obj,tests/fuzz/fuzz_http.c core/api/api_request.c core/api/console.c)
	$(FUZZ_LINK) $(PKG_LIBS)

# A checkpoint of dev.state offered to a driver (core/driver/checkpoint.c).
$(BUILD)/fuzz/fuzz_checkpoint: $(call fuzz_obj,tests/fuzz/fuzz_checkpoint.c tests/fuzz/fuzz_arena.c $(DRIVER_SRC))
	$(FUZZ_LINK) $(PKG_LIBS)

FUZZ_BINS := $(FUZZ_TARGETS:%=$(BUILD)/fuzz/fuzz_%)

# Every target FUZZ_JOBS processes at once (default: one per CPU), then the
# corpora of the Lua targets again in fresh sandboxes: tests/fuzz/run.sh.
FUZZ_JOBS ?= $(shell nproc 2>/dev/null || echo 1)
FUZZ_SECONDS ?= 60
FUZZ_TEST_SECONDS ?= 4

deps:
	@if ! command -v dpkg-query >/dev/null; then \
		echo "not a Debian system: install by hand the equivalents of: $(DEBS) $(EXTRA_DEBS)"; exit 0; fi; \
	missing=$$(for p in $(DEBS) $(EXTRA_DEBS); do dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q '^install ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		echo "make deps: installing" $$missing; \
		$(SUDO) apt-get update -qq && \
		$(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	else echo "make deps: all packages present"; fi

run: deps
	@$(MAKE) --no-print-directory all
	@exec ./scripts/run-kitchen.sh $(BUILD)/bin

test-unit: $(UNIT_TESTS)
	@for t in $(UNIT_TESTS); do echo "== $$t"; VMAC_SKIP_FILE=$(SKIPPED) CK_FORK=yes $$t || exit 1; done

# The stdlib's own tests, in the driver sandbox itself (tests/lua/run.c), and
# luacheck with the sandbox's globals over every shipped script.
test-lua: $(BUILD)/bin/vmac $(BUILD)/tests/lua_tests
	@echo "== Lua tests of stdlib/, in the driver sandbox"
	@$(BUILD)/tests/lua_tests
	@echo "== vmac lint over stdlib/, scripts/ and the driver tests"
	@$(BUILD)/bin/vmac lint stdlib/*.lua $$(find scripts -name '*.lua') $$(find tests -name '*_test.lua')

# The shipped drivers against mock boards in virtual time (docs/TESTING.md).
test-drivers: $(BUILD)/bin/vmac
	@echo "== vmac test: the shipped drivers in virtual time"
	@$(BUILD)/bin/vmac test

# Every fuzz target for a few seconds (make fuzz for longer runs).
test-fuzz: $(FUZZ_BINS)
	@echo "== fuzzing every parser $(FUZZ_TEST_SECONDS) s each, $(FUZZ_JOBS) processes ($(FUZZ_TARGETS))"
	@tests/fuzz/run.sh $(BUILD) $(FUZZ_TEST_SECONDS) $(FUZZ_JOBS) $(FUZZ_TARGETS)

# Every fuzz target FUZZ_SECONDS each (default 60).
fuzz: $(FUZZ_BINS)
	@echo "== fuzzing every parser $(FUZZ_SECONDS) s each, $(FUZZ_JOBS) processes ($(FUZZ_TARGETS))"
	@tests/fuzz/run.sh $(BUILD) $(FUZZ_SECONDS) $(FUZZ_JOBS) $(FUZZ_TARGETS)

# A suite (or test) that cannot run on this machine (no chromium, no root
# for a mount namespace) appends its reason to SKIPPED and passes; make test
# prints that file at its end. With CI=true in the environment such a suite
# fails instead (tests/ui/run.sh, tests/integration/run.py).
SKIPPED ?= $(BUILD)/skipped

# The web UI in headless chromium (installs chromium and playwright-core).
test-ui: $(BINS)
	@VMAC_SKIP_FILE=$(SKIPPED) tests/ui/run.sh $(BUILD)/bin $(BUILD)/ui

# Eclipse Tahu's Sparkplug codec from npm, pinned by its package-lock.json:
# test_sparkplug.py decodes vmacd's payloads with it (SKIPPED without it,
# a failure under CI=true).
tahu-deps:
	@tests/npm_ci.sh tests/mqtt/tahu 12 || echo "tahu-deps: Eclipse Tahu's codec not installed: test_sparkplug.py will not run"

test-integration: $(BINS) $(BUILD)/tests/store_crash $(FIRMWARE_IF_TOOLS) tahu-deps
	VMAC_SKIP_FILE=$(SKIPPED) python3 tests/integration/run.py --bin $(BUILD)/bin

# The whole unit and integration suite again, built with AddressSanitizer
# and UndefinedBehaviorSanitizer, any report fatal. asan-build builds that
# tree quietly (its log in build/asan-build.log), so make test can run it
# beside the plain integration tests, which mostly wait.
ASAN := BUILD=build/asan CFLAGS="-O1 -g -fno-omit-frame-pointer -DVMAC_CHECK_THREADS" SAN="-fsanitize=address,undefined -fno-sanitize-recover=all"
test-build: $(BINS) $(UNIT_TESTS) $(BUILD)/tests/store_crash $(FIRMWARE_IF_TOOLS)

asan-build:
	@mkdir -p build
	@if $(MAKE) --no-print-directory -j2 $(ASAN) test-build > build/asan-build.log 2>&1; then \
		echo "== the AddressSanitizer build is ready (build/asan)"; \
	else tail -40 build/asan-build.log; echo "the AddressSanitizer build failed: build/asan-build.log"; exit 1; fi

test-asan: asan-build
	@$(MAKE) --no-print-directory $(ASAN) test-unit
	@$(MAKE) --no-print-directory $(ASAN) test-drivers
	@$(MAKE) --no-print-directory $(ASAN) test-integration

# Every suite, each timed: $(TIMES) lists how long each took, printed at
# the end with what was skipped (if anything): what did not run did not pass.
TIMES ?= $(BUILD)/times
timed = t0=$$(date +%s); $(MAKE) --no-print-directory SKIPPED=$(abspath $(SKIPPED)) $(2) $(1) || exit 1; \
	echo "$(1): $$(( $$(date +%s) - t0 )) s" >> $(abspath $(TIMES))

test: deps
	@mkdir -p $(BUILD) && rm -f $(SKIPPED) $(TIMES)
	@$(call timed,format-check)
	@$(call timed,test-build,-j2)
	@$(call timed,test-unit)
	@$(call timed,test-lua)
	@$(call timed,test-drivers)
	@$(call timed,test-fuzz)
	@$(call timed,test-integration asan-build test-soak,-j3)
	@$(call timed,test-ui)
	@$(call timed,test-asan,VMAC_SCHED_PROPERTY_RUNS=10000)
	@echo "== how long each suite took"; sed 's/^/  /' $(TIMES)
	@if [ -s $(SKIPPED) ]; then \
		echo "################################################################################"; \
		echo "make test: every suite that ran passed, but these were SKIPPED (not run, not passed):"; \
		sed 's/^/  /' $(SKIPPED); \
		echo "################################################################################"; \
	else echo "make test: every suite passed"; fi

$(BUILD)/bench/bare_loop: tests/bench/bare_loop.c $(OBJ)/core/transport/transport.o $(OBJ)/core/transport/transport_udp.o \
                          $(OBJ)/core/transport/transport_eth.o $(OBJ)/core/common/addr.o \
                          $(OBJ)/core/proto/proto.o
	@mkdir -p $(dir $@)
	$(CC) $(HOST_CFLAGS) $^ -o $@ $(LDFLAGS_ALL)

# How late a real-time thread wakes, by the way it waits (tests/bench/wakeup.c).
$(BUILD)/bench/wakeup: tests/bench/wakeup.c
	@mkdir -p $(dir $@)
	$(CC) $(HOST_CFLAGS) $< -o $@

# One driver tick through the driver API, in microseconds (tests/bench/driver_tick.c).
$(BUILD)/bench/driver_tick: tests/bench/driver_tick.c $(driver_obj)
	@mkdir -p $(dir $@)
	$(CC) $(HOST_CFLAGS) $^ -o $@ $(LDFLAGS_ALL) $(PKG_LIBS)

BENCH_SECONDS ?= 60
bench:
	@$(MAKE) --no-print-directory deps EXTRA_DEBS="$(BENCH_DEBS)"
	@$(MAKE) --no-print-directory all $(BUILD)/bench/bare_loop
	python3 tests/bench/bench.py --bin $(BUILD)/bin --bare $(BUILD)/bench/bare_loop --seconds $(BENCH_SECONDS) \
		--out $(BUILD)/bench/results.json

# The soak (tests/soak/soak.py, docs/RELIABILITY.md "Soak"): boards killed
# and restarted, a driver reloaded every 10 s, 20 web UI clients, 1,000
# malformed datagrams a second, bad tokens and a nearly full store, all at
# once; the host's RSS, descriptors, threads and store size every 10 s.
# Exits non-zero saying what broke. test-soak is the 2-minute version for CI.
SOAK_MINUTES ?= 60
soak: $(BINS)
	python3 tests/soak/soak.py --bin $(BUILD)/bin --minutes $(SOAK_MINUTES) --out $(BUILD)/soak

test-soak: $(BINS)
	@$(MAKE) --no-print-directory soak SOAK_MINUTES=2

# The committed .clang-format, enforced: a C file that is not formatted
# fails (make format rewrites them in place).
C_FILES = $(shell git ls-files '*.c' '*.h' 2>/dev/null | grep -v '^core/api/ui/' || true)
format-check:
	@echo "== clang-format: every C file as .clang-format says"
	@bad=$$(for f in $(C_FILES); do clang-format --style=file "$$f" | cmp -s - "$$f" || echo "$$f"; done); \
	if [ -n "$$bad" ]; then echo "not formatted (run make format): $$bad"; exit 1; fi

format:
	@clang-format -i --style=file $(C_FILES)

clean:
	rm -rf $(BUILD)

-include $(shell find $(BUILD)/obj $(BUILD)/fuzz/obj -name '*.d' 2>/dev/null)
