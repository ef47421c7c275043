# core/loader: finding and loading a driver file the way the host does (the
# --drivers folder, the shipped scripts/drivers/, the programmes beside it).
# Slow, never on the bus thread. Uses config, driver, common.
loader_LIBS := -lpthread
