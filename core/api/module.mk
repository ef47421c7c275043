# core/api: the HTTP API (libmicrohttpd), the line console and the web UI built
# into the binary (docs/API.md, docs/UI.md). Uses mqtt (the site view),
# reload, host, store, common.
api_EXTRA := $(OBJ)/gen/ui_assets.o
api_LIBS  := $(call pkg_libs,libmicrohttpd jansson libsodium)
