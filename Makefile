# vmac: the build, meant to be read top to bottom. Each module's fragment
# (core/*/module.mk, firmware/module.mk) says what it is, what it uses and
# what it links; tests/unit/unit.mk, tests/fuzz/fuzz.mk and
# firmware/mcu/lm3s6965/mcu.mk hold the unit tests', the fuzzers' and the
# Cortex-M3 firmware's rules.
#
#   make            build build/bin/{vmacd,vmac,vmac-board}
#   make firmware   the board firmware for a Cortex-M3 (LM3S6965): build/firmware/vmac-board-lm3s6965.{elf,bin}
#   make deps       install missing Debian packages (apt-get; sudo when not root)
#   make run        deps + build + the demo kitchen (host and four mock boards)
#   make run-qemu   deps + build + firmware + the kitchen with boards in QEMU on raw Ethernet (root)
#   make test       deps + build + every test (unit, fuzz, the web UI in chromium, and under
#                   ASan+UBSan: make test-asan; each integration test once, under ASan, but for those
#                   that judge the plain build: make test-integration-plain)
#   make test-integration  every integration test on the plain build
#   make fuzz       every libFuzzer harness FUZZ_SECONDS each (default 60) in FUZZ_JOBS processes
#                   (default nproc), executions per target
#   make bench      timing figures as ratios to baselines run alongside (BENCH_SECONDS=60)
#   make soak       one host under every fault at once for SOAK_MINUTES (default 60), its resources
#                   sampled every 10 s; make test-soak: the same for 2 minutes
#   make install    the programs and their files under PREFIX (default /usr/local), DESTDIR; make deb: the
#                   Debian package; make test-package: it installed and purged (packaging/package.mk)
#   make clean

.DEFAULT_GOAL := all # plain make builds the programs, not the first archive a fragment defines
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
# test_sparkplug.py); protoc-c and libprotobuf-c for its Sparkplug B payloads (core/mqtt/sparkplug_b.proto);
# python3-nacl (libsodium's SipHash) for the integration tests' own sealed frames (test_trust.py);
# libsystemd for vmacd's sd_notify and journal fields (core/vmacd/service.c), and systemd's
# journald and journalctl for the journal test (test_service.py); prometheus (the server, and
# promtool) to scrape GET /metrics in test_metrics.py; libarchive-dev for bundles
# (core/bundle) and minisign, the signing tool the bundle tests sign with.
DEBS := build-essential pkg-config libluajit-5.1-dev libev-dev libmicrohttpd-dev libjansson-dev \
        libcurl4-openssl-dev libsqlite3-dev libsodium-dev check clang libclang-rt-dev python3 lua-check luajit \
        openssl clang-format iproute2 util-linux gcc-arm-none-eabi picolibc-arm-none-eabi qemu-system-arm \
        libmosquitto-dev mosquitto python3-paho-mqtt protobuf-c-compiler libprotobuf-c-dev python3-nacl \
        libsystemd-dev systemd prometheus libarchive-dev minisign

# make bench also needs cyclictest, its lateness baseline.
BENCH_DEBS := rt-tests

PKGS := luajit libmicrohttpd jansson libcurl sqlite3 libsodium libarchive
PKG_CFLAGS = $(shell pkg-config --cflags $(PKGS) 2>/dev/null)
# The fuzz harnesses and benchmarks link these; programs and unit tests link
# what their modules' fragments (MODULE_LIBS) name.
PKG_LIBS   = $(shell pkg-config --libs $(PKGS) 2>/dev/null) -lpthread -lm

# Strict warnings everywhere. -Wno-format-truncation: snprintf truncation
# into fixed buffers is the intended behaviour (names and texts are capped).
WARN := -Wall -Wextra -Werror -Wshadow -Wstrict-prototypes -Wmissing-prototypes -Wpointer-arith \
        -Wwrite-strings -Wundef -Wvla -Wformat=2 -Wno-format-nonliteral -Wno-format-truncation
# The board firmware and the wire codec are portable C99 (no heap, no OS headers).
PORTABLE_CFLAGS = -std=c99 -pedantic $(WARN) $(CFLAGS) $(SAN)
HOST_CFLAGS     = -std=c11 -D_GNU_SOURCE $(WARN) $(CFLAGS) $(SAN) $(PKG_CFLAGS)
LDFLAGS_ALL     = $(SAN) $(LDFLAGS)

# ---- the layers (docs/ARCHITECTURE.md) ----
# Each module is a folder with a make fragment (module.mk: what it is, what
# it uses, the libraries it needs) and is built as one static archive,
# build/lib/libMODULE.a. MODULES lists them top to bottom: a module may use
# the ones after it, never one before. Programs and tests link archives in
# this order, each once, and scripts/check-layers.py reads every archive's
# symbols (nm) and every include before anything links: an arrow upward is
# a build error.
MODULES := api mqtt vtest mainloop reload host loader bundle config sim driver transport store recorder board sched proto common
MODULE_DIR = $(if $(filter board,$(1)),firmware,core/$(1))
pkg_libs = $(shell pkg-config --libs $(1) 2>/dev/null)
OBJ = $(BUILD)/obj
LIB = $(BUILD)/lib
include $(foreach m,$(MODULES),$(call MODULE_DIR,$(m))/module.mk)

# A module's sources: its folder's .c files (board names its own).
$(foreach m,$(filter-out board,$(MODULES)),$(eval $(m)_SRC ?= $$(sort $$(wildcard core/$(m)/*.c))))
$(foreach m,$(MODULES),$(eval $(m)_OBJ = $$($(m)_SRC:%.c=$$(OBJ)/%.o) $$($(m)_EXTRA)))

define archive_rule
$(LIB)/lib$(1).a: $$($(1)_OBJ)
	@mkdir -p $$(dir $$@)
	@rm -f $$@ && $$(AR) rcs $$@ $$^
endef
$(foreach m,$(MODULES),$(eval $(call archive_rule,$(m))))

# down_from(M): module M and every module below it, in link order;
# archives(Ms) their archives; libs_of(Ms) the libraries they need.
down_from = $(strip $(eval _on :=)$(foreach x,$(MODULES),$(if $(filter $(1),$(x)),$(eval _on := y))$(if $(_on),$(x))))
archives  = $(foreach m,$(1),$(LIB)/lib$(m).a)
libs_of   = $(sort $(foreach m,$(1),$($(m)_LIBS)))

# Every archive's symbols and every include checked against MODULES.
$(BUILD)/layers.ok: scripts/check-layers.py $(call archives,$(MODULES))
	@python3 scripts/check-layers.py --lib $(LIB) --modules "$(MODULES)" && touch $@

# The board firmware and the wire codec are portable C99 (no heap, no OS
# header): the same files build for the Cortex-M3 (firmware/mcu/lm3s6965/mcu.mk).
PORTABLE_SRC := $(proto_SRC) $(board_SRC)
portable_obj  = $(PORTABLE_SRC:%.c=$(OBJ)/%.o)

BINS := $(BUILD)/bin/vmacd $(BUILD)/bin/vmac $(BUILD)/bin/vmac-board

.PHONY: format format-check test-build asan-build
.PHONY: all deps run test test-unit test-lua test-drivers test-fuzz fuzz test-integration test-integration-plain
.PHONY: test-ui test-asan bench clean
.PHONY: test-asan-unit test-asan-integration
.PHONY: firmware run-qemu soak test-soak tahu-deps mcu-auth-bench
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

$(OBJ)/core/mqtt/mqtt_sparkplug.o $(OBJ)/core/mqtt/mqtt_spb_dcmd.o: $(SPB_GEN).h
$(OBJ)/core/mqtt/mqtt_sparkplug.o $(OBJ)/core/mqtt/mqtt_spb_dcmd.o: HOST_CFLAGS += -I$(BUILD)/gen

# link(OBJECTS, MODULES, LIBS): a program or test from its own objects and
# the archives of MODULES, in layer order; --as-needed keeps a library out
# of a program that uses none of it (vmac has no HTTP server in it).
in_order = $(filter $(1),$(MODULES))
define link
	@mkdir -p $(dir $@)
	$(CC) $(1) $(call archives,$(call in_order,$(2))) -o $@ $(LDFLAGS_ALL) -Wl,--as-needed \
		$(call libs_of,$(2)) $(3)
endef

# vmacd: every module; vmac: every module below the HTTP API (its commands,
# `vmac test`, `vmac site`); vmac-board: the board and the transports.
VMACD_MODULES      := $(MODULES)
VMAC_MODULES       := $(call down_from,mqtt)
VMAC_BOARD_MODULES := sim driver transport board sched proto common
VMACD_OBJ          := $(patsubst %.c,$(OBJ)/%.o,$(wildcard core/vmacd/*.c))
VMAC_OBJ           := $(patsubst %.c,$(OBJ)/%.o,$(wildcard core/cli/*.c))
VMAC_BOARD_OBJ     := $(patsubst %.c,$(OBJ)/%.o,$(wildcard firmware/posix/*.c))

$(BUILD)/bin/vmacd: $(VMACD_OBJ) $(call archives,$(VMACD_MODULES)) $(BUILD)/layers.ok
	$(call link,$(VMACD_OBJ),$(VMACD_MODULES),-lev $(call pkg_libs,libsystemd))

$(BUILD)/bin/vmac: $(VMAC_OBJ) $(call archives,$(VMAC_MODULES)) $(BUILD)/layers.ok
	$(call link,$(VMAC_OBJ),$(VMAC_MODULES),$(call pkg_libs,libcurl libmosquitto jansson))

$(BUILD)/bin/vmac-board: $(VMAC_BOARD_OBJ) $(call archives,$(VMAC_BOARD_MODULES)) $(BUILD)/layers.ok
	$(call link,$(VMAC_BOARD_OBJ),$(VMAC_BOARD_MODULES))

include firmware/mcu/lm3s6965/mcu.mk tests/unit/unit.mk tests/fuzz/fuzz.mk
include packaging/package.mk

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

# Check's timeout, 4 s a test, is a guard against a hang: five times that,
# for the sanitizer build on a loaded machine (make test).
test-unit: $(UNIT_TESTS)
	@for t in $(UNIT_TESTS); do echo "== $$t"; VMAC_SKIP_FILE=$(SKIPPED) CK_FORK=yes CK_TIMEOUT_MULTIPLIER=5 $$t || exit 1; done

# The stdlib's own tests, in the driver sandbox itself (tests/lua/run.c), and
# luacheck with the sandbox's globals over every shipped script and the
# kitchen's user content (examples/); not over scripts/types/, declarations
# for editors (LuaLS) that no sandbox runs.
test-lua: $(BUILD)/bin/vmac $(BUILD)/tests/lua_tests
	@echo "== Lua tests of stdlib/, in the driver sandbox"
	@$(BUILD)/tests/lua_tests
	@echo "== vmac lint over stdlib/, scripts/, examples/ and the driver tests"
	@$(BUILD)/bin/vmac lint stdlib/*.lua $$(find scripts -name '*.lua' -not -path 'scripts/types/*') \
		$$(find examples -name '*.lua') $$(find tests -name '*_test.lua')

# The shipped drivers against mock boards in virtual time (docs/TESTING.md),
# then the kitchen's dryer, user content with its Lua plant, from its own
# drivers folder as a user runs it (docs/NEW_MACHINE.md).
test-drivers: $(BUILD)/bin/vmac
	@echo "== vmac test: the shipped drivers in virtual time"
	@$(BUILD)/bin/vmac test
	@echo "== vmac test: the kitchen's dryer (examples/kitchen) in virtual time"
	@$(BUILD)/bin/vmac test --drivers examples/kitchen examples/kitchen/tests

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

# make test's plain pass: the integration tests whose run on the plain
# build judges what the sanitizer pass cannot (its memory, its timing,
# the full count of trials) or that the sanitizer pass leaves out
# (harness.plain_pass_too and plain_pass_only). Every other one runs once,
# under the sanitizers, which check all a plain run does: make test's last
# step is bound by the CPU (docs/TESTING.md, "What make test costs").
test-integration-plain: $(BINS) $(BUILD)/tests/store_crash $(FIRMWARE_IF_TOOLS) tahu-deps
	VMAC_SKIP_FILE=$(SKIPPED) python3 tests/integration/run.py --bin $(BUILD)/bin --plain-pass

# The whole unit and integration suite again, built with AddressSanitizer
# and UndefinedBehaviorSanitizer, any report fatal. asan-build builds that
# tree quietly (its log in build/asan-build.log), so make test can build it
# beside the plain unit tests and the fuzzers; then its unit and driver
# tests (a minute of CPU) beside its own integration tests.
ASAN := BUILD=build/asan CFLAGS="-O1 -g -fno-omit-frame-pointer -DVMAC_CHECK_THREADS" SAN="-fsanitize=address,undefined -fno-sanitize-recover=all"
test-build: $(BINS) $(UNIT_TESTS) $(BUILD)/tests/store_crash $(FIRMWARE_IF_TOOLS)

asan-build:
	@mkdir -p build
	@if $(MAKE) --no-print-directory -j2 $(ASAN) test-build > build/asan-build.log 2>&1; then \
		echo "== the AddressSanitizer build is ready (build/asan)"; \
	else tail -40 build/asan-build.log; echo "the AddressSanitizer build failed: build/asan-build.log"; exit 1; fi

test-asan-unit: asan-build
	@$(MAKE) --no-print-directory $(ASAN) test-unit
	@$(MAKE) --no-print-directory $(ASAN) test-drivers

test-asan-integration: asan-build
	@$(MAKE) --no-print-directory $(ASAN) test-integration

# The whole second pass: the build, then its unit and driver tests beside
# its integration tests (one after the other without make -j).
test-asan: asan-build
	@$(MAKE) --no-print-directory test-asan-unit test-asan-integration

# Every suite, each timed: $(TIMES) lists how long each step of make test
# (suites run at once) took and, for a step of several, each of its suites
# (the longest is the one the step waited for), printed at the end with
# what was skipped (if anything): what did not run did not pass.
# timed-SUITE makes SUITE and notes its time in $(TIMES).each, with the
# CPU time (user and system) of the processes it waited for (the shell's
# times, into a file: in a pipe it would be a subshell's): the last step
# is bound by the CPU, so less CPU is what shortens it.
TIMES ?= $(BUILD)/times
timed = t0=$$(date +%s); rm -f $(abspath $(TIMES)).each; \
	$(MAKE) --no-print-directory SKIPPED=$(abspath $(SKIPPED)) $(2) $(addprefix timed-,$(1)) || exit 1; \
	echo "$(1): $$(( $$(date +%s) - t0 )) s$(if $(word 2,$(1)), ($$(paste -sd, $(abspath $(TIMES)).each | sed 's/,/, /g')),$$(sed -n 's/.* s\( using .*\)/\1/p' $(abspath $(TIMES)).each))" \
		>> $(abspath $(TIMES))

timed-%:
	@t0=$$(date +%s); $(MAKE) --no-print-directory $* || exit 1; \
	times > $(abspath $(TIMES)).$*; \
	cpu=$$(awk 'NR == 2 { for (i = 1; i <= 2; i++) { split($$i, t, "m"); n += t[1] * 60 + t[2] } \
		printf "%.0f", n }' $(abspath $(TIMES)).$*); rm -f $(abspath $(TIMES)).$*; \
	echo "$* $$(( $$(date +%s) - t0 )) s using $$cpu CPU s" >> $(abspath $(TIMES)).each

# The steps of make test, the suites of a step at once. The integration
# tests mostly wait on real time (plant physics, watchdogs, restarts). So
# the last step runs them (under ASan, and the plain pass's few) beside
# what needs the CPU (the ASan unit tests, the package's build and test,
# the web UI in chromium) and the soak, which waits too. -j6: one job a
# suite, and one for the ASan pass's second half. The ASan build is made
# the step before, beside the plain unit tests and the fuzzers (which
# fuzz for a fixed time), so that the ASan pass, the longest suite, starts
# its tests with the step. Its integration tests run four at a time, as
# run.py's default: more starve the other suites of the step.
test: deps
	@mkdir -p $(BUILD) && rm -f $(SKIPPED) $(TIMES)
	@$(call timed,format-check)
	@$(call timed,test-build,-j2)
	@$(call timed,test-unit test-lua test-drivers test-fuzz asan-build,-j3)
	@$(call timed,test-integration-plain test-asan test-package test-soak test-ui,-j6 VMAC_SCHED_PROPERTY_RUNS=10000)
	@rm -f $(TIMES).each; echo "== how long each suite took"; sed 's/^/  /' $(TIMES)
	@if [ -s $(SKIPPED) ]; then \
		echo "################################################################################"; \
		echo "make test: every suite that ran passed, but these were SKIPPED (not run, not passed):"; \
		sed 's/^/  /' $(SKIPPED); \
		echo "################################################################################"; \
	else echo "make test: every suite passed"; fi

$(BUILD)/bench/bare_loop: $(OBJ)/tests/bench/bare_loop.o $(call archives,transport proto common)
	$(call link,$<,transport proto common)

# How late a real-time thread wakes, by the way it waits (tests/bench/wakeup.c).
$(BUILD)/bench/wakeup: $(OBJ)/tests/bench/wakeup.o
	$(call link,$<,)

# One driver tick through the driver API, in microseconds (tests/bench/driver_tick.c).
$(BUILD)/bench/driver_tick: $(OBJ)/tests/bench/driver_tick.o $(call archives,$(call down_from,driver))
	$(call link,$<,$(call down_from,driver))

# What sealing and opening frames costs per frame and per CYCLIC record, in
# ns, next to encoding the same request (tests/bench/auth_frames.c).
$(BUILD)/bench/auth_frames: $(OBJ)/tests/bench/auth_frames.o $(call archives,proto common)
	$(call link,$<,proto common)

# What checking a bundle's minisign signature costs per MiB, next to
# BLAKE2b-512 alone over the same bytes (tests/bench/minisign_verify.c).
$(BUILD)/bench/minisign_verify: $(OBJ)/tests/bench/minisign_verify.o $(call archives,bundle common)
	$(call link,$<,bundle common)

# One step of a plant model in Lua, next to the C washer's, in us
# (tests/bench/plant_step.c).
$(BUILD)/bench/plant_step: $(OBJ)/tests/bench/plant_step.o $(call archives,$(call down_from,sim))
	$(call link,$<,$(call down_from,sim))

# Ten boards acting on one host instant by their disciplined clocks, next to
# acting on arrival, simulated on the oscillator model (tests/bench/clock_sync.c,
# docs/TIME.md).
$(BUILD)/bench/clock_sync: $(OBJ)/tests/bench/clock_sync.o $(OBJ)/firmware/posix/oscillator.o $(call archives,board proto common)
	$(call link,$< $(OBJ)/firmware/posix/oscillator.o,board proto common)

BENCH_SECONDS ?= 60
bench:
	@$(MAKE) --no-print-directory deps EXTRA_DEBS="$(BENCH_DEBS)"
	@$(MAKE) --no-print-directory all $(BUILD)/bench/bare_loop $(BUILD)/bench/auth_frames \
		$(BUILD)/bench/minisign_verify $(BUILD)/bench/plant_step $(BUILD)/bench/clock_sync
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
# One clang-format a batch of files, two at once (a process a file took
# 30 s); its errors name each file and line that is not formatted.
format-check:
	@echo "== clang-format: every C file as .clang-format says"
	@out=$$(printf '%s\n' $(C_FILES) | xargs -n 40 -P 2 clang-format --style=file --dry-run --Werror 2>&1); rc=$$?; \
	bad=$$(printf '%s\n' "$$out" | sed -n 's/^\([^: ]*\):[0-9]*:[0-9]*: error: code should be clang-formatted.*/\1/p' | \
		sort -u); \
	if [ -n "$$bad" ]; then echo "not formatted (run make format):" $$bad; exit 1; fi; \
	if [ $$rc -ne 0 ]; then printf '%s\n' "$$out" | tail -20; echo "clang-format failed (exit $$rc)"; exit 1; fi

format:
	@clang-format -i --style=file $(C_FILES)

clean:
	rm -rf $(BUILD)

-include $(shell find $(BUILD)/obj $(BUILD)/fuzz/obj -name '*.d' 2>/dev/null)
