# The unit tests (Check) and the programs the integration tests drive beside
# vmacd: each tests/unit/test_NAME.c is linked with the archives of the
# module it tests and every module below it (the Makefile's MODULES).
CHECK_LIBS = $(shell pkg-config --libs check 2>/dev/null)

# test NAME : the module it tests. test_isolation and test_checkpoint are
# white-box (core/driver/internal.h); test_transport's raw-Ethernet round
# trip runs over a veth pair in a network namespace of its own (root), else
# it is SKIPPED into $(SKIPPED); test_minisign signs and checks with the
# real minisign command (SKIPPED without it).
UNIT_TEST_MODULE := test_proto:proto test_proto_reject:proto test_proto_v2:proto test_cyclic:proto test_timed:proto \
                    test_board:board test_plant:board test_board_v2:board test_board_cyclic:board \
                    test_sched:sched test_timing:sched test_store:store test_recording:recorder test_transport:transport \
                    test_driver:driver test_driver_text:driver test_driver_timing:driver test_hints:driver test_isolation:driver test_checkpoint:driver test_luaplant:sim test_luaplant_run:sim test_host:host test_audit:host \
                    test_auth:proto test_board_auth:board test_report:board \
                    test_mqtt:mqtt test_paths:common test_prom:api test_minisign:bundle \
                    test_bundle:bundle test_bundle_folder:bundle test_clock:board test_sync:board test_sync_auth:board \
                    test_board_timed:board test_sync_twostep:board test_tx_stamp:transport
UNIT_TESTS := $(foreach t,$(UNIT_TEST_MODULE),$(BUILD)/tests/$(firstword $(subst :, ,$(t))))

# Libraries a test needs beyond its modules': libsodium is the reference
# test_auth checks the portable SipHash against.
test_auth_LIBS = $(call pkg_libs,libsodium)

# Objects a test links beyond its modules' archives: test_clock runs the
# board's clock against the simulator's oscillator, vmac-board's own file
# (in no archive: POSIX only, floating point).
test_clock_OBJ = $(OBJ)/firmware/posix/oscillator.o

# Every test program's main() is check_main.c's (check_main.h): it runs the
# suite test_NAME.c gives through vmac_test_suite().
UNIT_MAIN := $(OBJ)/tests/unit/check_main.o

define unit_test_rule
$(BUILD)/tests/$(1): $(OBJ)/tests/unit/$(1).o $(UNIT_MAIN) $($(1)_OBJ) $(call archives,$(call down_from,$(2))) $(BUILD)/layers.ok
	$$(call link,$(OBJ)/tests/unit/$(1).o $(UNIT_MAIN) $($(1)_OBJ),$(call down_from,$(2)),$$(CHECK_LIBS) $$($(1)_LIBS))
endef
$(foreach t,$(UNIT_TEST_MODULE),$(eval $(call unit_test_rule,$(firstword $(subst :, ,$(t))),$(lastword $(subst :, ,$(t))))))

# The stdlib's Lua tests, each case in a real driver sandbox (tests/lua/run.c;
# white-box: core/driver/internal.h).
$(BUILD)/tests/lua_tests: $(OBJ)/tests/lua/run.o $(call archives,$(call down_from,driver)) $(BUILD)/layers.ok
	$(call link,$<,$(call down_from,driver))

# The store killed mid-write (tests/integration/test_store.py).
$(BUILD)/tests/store_crash: $(OBJ)/tests/store/store_crash.o $(call archives,$(call down_from,store)) $(BUILD)/layers.ok
	$(call link,$<,$(call down_from,store))
