# The libFuzzer harnesses (included by the Makefile).
# docs/TESTING.md, "Fuzzing".
# One libFuzzer harness per parser, tests/fuzz/fuzz_NAME.c, its seeds in
# tests/fuzz/corpus-NAME/ (and a dictionary tests/fuzz/NAME.dict where one
# helps). Everything a harness links is built again with clang, libFuzzer's
# coverage and ASan+UBSan, under $(BUILD)/fuzz/obj; what the fuzzer finds
# goes to $(BUILD)/fuzz/work-NAME, never to the committed seeds.
FUZZ_TARGETS := proto config console manifest values http checkpoint bundle
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
$(BUILD)/fuzz/fuzz_proto: tests/fuzz/fuzz_proto.c core/proto/proto.c core/proto/auth.c core/proto/siphash.c firmware/board.c \
                          firmware/clock.c firmware/timed.c
	@mkdir -p $(dir $@)
	clang -std=c99 -g -O2 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all $^ -o $@

# The config file and key=value settings (vmac_config_load/set/check).
$(BUILD)/fuzz/fuzz_config: $(call fuzz_obj,tests/fuzz/fuzz_config.c core/config/config.c core/common/addr.c core/common/file.c core/common/paths.c \
                            core/transport/transport.c core/transport/transport_udp.c core/transport/transport_eth.c core/transport/tx_stamp.c \
                            core/proto/proto.c)
	$(FUZZ_LINK) $(PKG_LIBS)

# The line console's grammar (core/api/console.c), the host behind fakes.
$(BUILD)/fuzz/fuzz_console: $(call fuzz_obj,tests/fuzz/fuzz_console.c core/api/console.c)
	$(FUZZ_LINK)

# A driver's source through load and manifest validation, then one run.
# The stdlib's and the programmes' files read and compiled once
# (fuzz_hostfiles.c wraps vmac_read_file and luaL_loadbufferx).
$(BUILD)/fuzz/fuzz_manifest: $(call fuzz_obj,tests/fuzz/fuzz_manifest.c tests/fuzz/fuzz_arena.c tests/fuzz/fuzz_hostfiles.c \
                              $(driver_SRC) core/sched/timing.c core/common/file.c core/api/api_request.c core/api/console.c)
	$(FUZZ_LINK) -Wl,--wrap=vmac_read_file,--wrap=luaL_loadbufferx $(PKG_LIBS)

# Lua values to outputs, variables and params and back (core/driver/instance.c).
$(BUILD)/fuzz/fuzz_values: $(call fuzz_obj,tests/fuzz/fuzz_values.c tests/fuzz/fuzz_arena.c $(driver_SRC) core/sched/timing.c core/common/file.c)
	$(FUZZ_LINK) $(PKG_LIBS)

# The HTTP API's routing, request bodies and arguments, and the console's
# body (core/api/api_request.c), no sockets.
$(BUILD)/fuzz/fuzz_http: $(call fuzz_obj,tests/fuzz/fuzz_http.c core/api/api_request.c core/api/console.c)
	$(FUZZ_LINK) $(PKG_LIBS)

# A checkpoint of dev.state offered to a driver (core/driver/checkpoint.c).
$(BUILD)/fuzz/fuzz_checkpoint: $(call fuzz_obj,tests/fuzz/fuzz_checkpoint.c tests/fuzz/fuzz_arena.c $(driver_SRC) core/sched/timing.c core/common/file.c)
	$(FUZZ_LINK) $(PKG_LIBS)

# A bundle as a host reads an upload (core/bundle/bundle.c: libarchive,
# jansson, libsodium), written and read again.
$(BUILD)/fuzz/fuzz_bundle: $(call fuzz_obj,tests/fuzz/fuzz_bundle.c core/bundle/bundle.c)
	$(FUZZ_LINK) $(PKG_LIBS)

FUZZ_BINS := $(FUZZ_TARGETS:%=$(BUILD)/fuzz/fuzz_%)

# Every target FUZZ_JOBS processes at once (default: one per CPU), then the
# corpora of the Lua targets again in fresh sandboxes: tests/fuzz/run.sh.
FUZZ_JOBS ?= $(shell nproc 2>/dev/null || echo 1)
FUZZ_SECONDS ?= 60
FUZZ_TEST_SECONDS ?= 4

