/* The bus thread's real-time set-up (docs/HOST.md, "realtime" and
 * "cpu_awake"): SCHED_FIFO and mlockall, and keeping the CPUs out of deep
 * idle states. Refusals are warnings: the host runs on with higher tick
 * lateness. */
#include "bus_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

/* AddressSanitizer's shadow memory cannot be locked: GCC says it is on
 * with __SANITIZE_ADDRESS__, clang with __has_feature. */
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VMAC_ASAN 1
#endif
#endif

void bus_try_realtime(struct vmac_bus *bus)
{
	struct sched_param sp;
	const char *what = NULL;
	int rc;
	if (!bus->cfg.realtime)
		return;
	memset(&sp, 0, sizeof(sp));
	sp.sched_priority = 50;
	rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
	if (rc != 0)
		what = "SCHED_FIFO";
	else
		bus->realtime = 1;
#if !defined(__SANITIZE_ADDRESS__) && !defined(VMAC_ASAN)
	if (!what && mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
		rc = errno;
		what = "mlockall";
	}
#endif
	if (what)
		bus_event(bus, NULL, "warning",
		          "real-time setup refused (%s: %s); running with normal scheduling, "
		          "tick lateness will be higher",
		          what, strerror(rc));
}

/* cpu_awake: a PM QoS request of 0 us, held while /dev/cpu_dma_latency stays
 * open, keeps every CPU out of deep idle states, as cyclictest does: waking
 * one from them costs tens of microseconds (on a VM, a halt and the host's
 * wake-up: docs/PERFORMANCE.md, "Tick lateness"), for more power. */
void bus_try_cpu_awake(struct vmac_bus *bus)
{
	int32_t zero = 0;
	if (!bus->cfg.cpu_awake || bus->virt)
		return;
	bus->cpu_awake_fd = open("/dev/cpu_dma_latency", O_WRONLY | O_CLOEXEC);
	if (bus->cpu_awake_fd >= 0 && write(bus->cpu_awake_fd, &zero, sizeof(zero)) == sizeof(zero))
		return;
	bus_event(bus, NULL, "warning", "cpu_awake refused (/dev/cpu_dma_latency: %s); tick lateness will be higher",
	          strerror(errno));
	if (bus->cpu_awake_fd >= 0)
		close(bus->cpu_awake_fd);
	bus->cpu_awake_fd = -1;
}
