# core/driver: the Lua sandbox, one LuaJIT state per machine (docs/DRIVERS.md;
# internal.h says which file owns what). Uses common, proto.
driver_LIBS := $(call pkg_libs,luajit jansson) -lm
