/* vmac-board's real-time set-up: SCHED_FIFO and mlockall, as vmacd's bus
 * thread asks for them (core/host/realtime.c). A simulated board is an
 * ordinary process that a busy machine holds off the CPU for milliseconds,
 * now and then tens of them: replies miss the host's deadline, watchdogs
 * trip late. A microcontroller is never held off; the simulator should not
 * be either, where the machine allows it (docs/BOARD.md, "Real-time
 * scheduling"). */
#include "realtime.h"

#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>

/* No mlockall under AddressSanitizer: its shadow memory is terabytes of
 * address space (GCC says so with __SANITIZE_ADDRESS__, clang with
 * __has_feature). */
#if defined(__SANITIZE_ADDRESS__)
#define LOCK_MEMORY 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LOCK_MEMORY 0
#endif
#endif
#ifndef LOCK_MEMORY
#define LOCK_MEMORY 1
#endif

void boards_try_realtime(void)
{
	struct sched_param sp;
	const char *what = NULL, *needs = "";
	int err = 0;

	memset(&sp, 0, sizeof(sp));
	sp.sched_priority = BOARDS_REALTIME_PRIORITY;
	if (sched_setscheduler(0, SCHED_FIFO | SCHED_RESET_ON_FORK, &sp) != 0) {
		err = errno;
		what = "SCHED_FIFO";
		needs = "root, CAP_SYS_NICE or an RLIMIT_RTPRIO of at least 30";
	} else if (LOCK_MEMORY && mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
		err = errno;
		what = "mlockall";
		needs = "root, CAP_IPC_LOCK or a larger RLIMIT_MEMLOCK";
	}
	if (what)
		fprintf(stderr,
		        "vmac-board: real-time setup refused (%s: %s; needs %s); running with normal scheduling, "
		        "replies may be late on a busy machine (--no-realtime: do not ask)\n",
		        what, strerror(err), needs);
}
