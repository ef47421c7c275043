# core/recorder: the flight recorder's rings and its recordings as files
# (docs/RECORDER.md). Uses common, proto.
recorder_LIBS := $(call pkg_libs,jansson libsodium)
