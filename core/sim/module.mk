# core/sim: the simulated machine behind a board, a C plant (firmware/plants/)
# or a Lua plant (core/driver/luaplant.c) behind one interface, for
# vmac-board and `vmac test` (docs/BOARD.md). Uses driver, board, proto, common.
sim_LIBS := $(call pkg_libs,luajit) -lm
