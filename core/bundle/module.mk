# core/bundle: a machine's software as one deterministic archive (libarchive)
# and minisign signatures checked with libsodium. Uses common.
bundle_LIBS := $(call pkg_libs,libarchive libsodium jansson)
