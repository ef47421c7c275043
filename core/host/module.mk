# core/host: the bus thread (the tick, devices, jobs for the driver workers,
# the mailbox, status, hot reload's swap) and the main thread's event log.
# Uses config, driver, transport, recorder, sched, proto, common.
host_LIBS := -lpthread -lm
