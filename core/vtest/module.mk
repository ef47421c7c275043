# core/vtest: `vmac test`, the bus and the board firmware on one virtual clock
# (docs/TESTING.md). Uses host, loader, config, driver, recorder, board, proto, common.
vtest_LIBS := $(call pkg_libs,luajit)
