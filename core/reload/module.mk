# core/reload: hot reload's deploy (compile an upload off the bus thread, store
# the version, switch every machine through the bus's request slots). Uses
# host, loader, store, driver, config, common.
reload_LIBS := -lpthread
