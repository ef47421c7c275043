# core/mainloop: the host's main thread, shared by vmacd and `vmac test`.
# Uses reload (loading a driver's active version), host, loader, config,
# driver, store, recorder, common.
mainloop_LIBS := $(call pkg_libs,libsodium)
