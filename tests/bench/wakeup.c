/* How late a SCHED_FIFO thread wakes for a 1 kHz period, by the way it
 * waits: clock_nanosleep to an absolute time (as cyclictest does), an
 * absolute periodic timerfd read after epoll_wait (as vmacd's bus thread
 * does, through libev), and epoll_pwait2 with a timeout (an epoll loop that
 * needs no timerfd). One mechanism per run, N periods (default 10,000);
 * prints p50, p99 and max lateness in microseconds. For issue 17's lateness
 * (docs/PERFORMANCE.md, "Tick lateness"): run them in turn, as root:
 *
 *   make build/bench/wakeup
 *   for m in nanosleep timerfd pwait2; do build/bench/wakeup $m; done */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE
#endif
#include <errno.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <sys/timerfd.h>
#include <time.h>
#include <unistd.h>

#ifndef SYS_epoll_pwait2
#define SYS_epoll_pwait2 441
#endif

#define PERIOD_NS 1000000

static int64_t now_ns(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (int64_t)t.tv_sec * 1000000000 + t.tv_nsec;
}

static int cmp(const void *a, const void *b)
{
	int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
	return x < y ? -1 : x > y;
}

int main(int argc, char **argv)
{
	const char *mode = argc > 1 ? argv[1] : "";
	int n = argc > 2 ? atoi(argv[2]) : 10000, i, ep, tfd;
	struct sched_param sp = {.sched_priority = 50};
	struct epoll_event ev = {.events = EPOLLIN};
	int64_t start, *late;
	if (strcmp(mode, "nanosleep") != 0 && strcmp(mode, "timerfd") != 0 && strcmp(mode, "pwait2") != 0) {
		fprintf(stderr, "usage: wakeup nanosleep|timerfd|pwait2 [PERIODS]\n");
		return 2;
	}
	if (n < 100 || !(late = malloc((size_t)n * sizeof(*late)))) {
		fprintf(stderr, "wakeup: PERIODS must be at least 100\n");
		return 2;
	}
	if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
		fprintf(stderr, "wakeup: SCHED_FIFO refused (%s): figures of a normal thread\n", strerror(errno));
	mlockall(MCL_CURRENT | MCL_FUTURE);
	ep = epoll_create1(0);
	tfd = timerfd_create(CLOCK_MONOTONIC, 0);
	epoll_ctl(ep, EPOLL_CTL_ADD, tfd, &ev);
	start = now_ns() + PERIOD_NS;
	if (strcmp(mode, "timerfd") == 0) {
		struct itimerspec its = {{0, PERIOD_NS}, {start / 1000000000, start % 1000000000}};
		timerfd_settime(tfd, TFD_TIMER_ABSTIME, &its, NULL);
	}
	for (i = 0; i < n; i++) {
		int64_t target;
		struct epoll_event got;
		target = start + (int64_t)i * PERIOD_NS;
		if (mode[0] == 'n') {
			struct timespec ts = {target / 1000000000, target % 1000000000};
			clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
		} else if (mode[0] == 't') {
			uint64_t x;
			if (epoll_wait(ep, &got, 1, -1) != 1 || read(tfd, &x, sizeof(x)) != sizeof(x))
				return 1;
			for (; x > 1 && i < n - 1; x--) /* periods missed: each as late as this one, at most */
				late[i++] = (now_ns() - target) / 1000;
			target = start + (int64_t)i * PERIOD_NS;
		} else {
			int64_t d = target - now_ns();
			struct timespec ts = {d > 0 ? d / 1000000000 : 0, d > 0 ? d % 1000000000 : 0};
			if (syscall(SYS_epoll_pwait2, ep, &got, 1, &ts, NULL, 0) < 0) {
				fprintf(stderr, "wakeup: epoll_pwait2: %s (Linux 5.11 or later)\n", strerror(errno));
				return 1;
			}
		}
		late[i] = (now_ns() - target) / 1000;
	}
	qsort(late, (size_t)n, sizeof(*late), cmp);
	printf("%-9s p50 %lld us, p99 %lld us, max %lld us (%d periods of 1 ms)\n", mode, (long long)late[n / 2],
	       (long long)late[(size_t)n * 99 / 100], (long long)late[n - 1], n);
	return 0;
}
