# core/config: the host's settings, from the config file and --set (docs/HOST.md).
# Uses driver (its limits and settings types), transport (bus specs), common.
config_LIBS := $(call pkg_libs,luajit)
