# core/store: the SQLite store (tokens, params, driver versions, checkpoints,
# events, recordings), never used on the bus thread. Uses common.
store_LIBS := $(call pkg_libs,sqlite3 libsodium) -lpthread
