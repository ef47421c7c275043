# core/vtest: `vmac test`, the bus and the board firmware on one virtual clock
# (docs/TESTING.md). Uses host, loader, config, driver, recorder, board, proto, common.
vtest_LIBS := $(call pkg_libs,luajit) -lm
# The simulator's oscillator (firmware/posix/oscillator.c: POSIX, double, no
# other dependency) models the boards' counters (clocks.c), as in vmac-board.
vtest_EXTRA := $(OBJ)/firmware/posix/oscillator.o
