# core/recorder: the flight recorder's rings and its recordings as files
# (docs/RECORDING.md). Uses common, proto.
recorder_LIBS := $(call pkg_libs,jansson libsodium)
