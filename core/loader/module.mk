# core/loader: finding and loading a driver file the way the host does (the
# --drivers folder DIR, then the shipped scripts/drivers/; the programmes in
# DIR/cycles/NAME/, else in scripts/cycles/NAME/).
# Slow, never on the bus thread. Uses config, driver, common.
loader_LIBS := -lpthread
