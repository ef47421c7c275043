/* A CLOCK_MONOTONIC deadline some time from now, for the waits that take
 * an absolute time (sem_clockwait, pthread_cond_timedwait on a condition
 * set to the monotonic clock, pthread_clockjoin_np): a wall clock set
 * meanwhile (NTP at boot) neither ends them early nor makes them last. */
#ifndef VMAC_MONOTIME_H
#define VMAC_MONOTIME_H

#include <stdint.h>
#include <time.h>

static inline struct timespec vmac_mono_after_ns(int64_t ns)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	t.tv_sec += (time_t)(ns / 1000000000);
	t.tv_nsec += (long)(ns % 1000000000);
	if (t.tv_nsec >= 1000000000L) {
		t.tv_sec++;
		t.tv_nsec -= 1000000000L;
	}
	return t;
}

#endif
