/* The bus thread's wait (docs/HOST.md, "Threads"): one epoll set holding
 * the bus socket and an eventfd the other threads write to wake it
 * (bus_wake), waited on with epoll_pwait2 and a timeout to the next tick,
 * or, on a kernel before 5.11, with the absolute periodic timerfd in the
 * set. The loop runs ticks, replies as they arrive (gathered: see
 * gather), and the main thread's commands and requests. */
#include "bus_internal.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

/* epoll_pwait2 (Linux 5.11): epoll_wait with a timeout in nanoseconds. -1
 * with errno ENOSYS on an older kernel. */
static int pwait2(int epfd, struct epoll_event *ev, int max, int64_t timeout_ns)
{
	struct timespec ts = {(time_t)(timeout_ns / 1000000000), (long)(timeout_ns % 1000000000)};
	return (int)syscall(SYS_epoll_pwait2, epfd, ev, max, &ts, NULL, (size_t)0);
}

/* After a drain, the bus thread leaves the socket alone for GATHER_NS (at
 * most an eighth of a slot, and never into the 2 x GATHER_NS before the
 * next tick), still woken by the main thread: the replies that trickle in
 * meanwhile (a board program answers its boards one after another) are
 * read by one drain, not each by a wake-up of its own. Since the drivers
 * left this thread it keeps up with every reply, and waking for each cost
 * more than the drivers did (docs/PERFORMANCE.md, "Drivers on driver
 * workers"); every wake-up also woke a worker. A reply's deadline is
 * judged by its kernel time stamp, and its machine's tick job is due one
 * period later: neither moves. */
#define GATHER_NS 30000
static void gather(struct vmac_bus *bus, int64_t next)
{
	int64_t c = bus->slot_ns / 8 < GATHER_NS ? bus->slot_ns / 8 : GATHER_NS;
	struct pollfd p;
	struct timespec ts;
	if (bus->timerfd_wait || next - vmac_now_ns() <= 2 * c)
		return;
	p.fd = bus->wakefd;
	p.events = POLLIN;
	p.revents = 0;
	ts.tv_sec = 0;
	ts.tv_nsec = (long)c;
	ppoll(&p, 1, &ts, NULL); /* woken: the loop reads wakefd next */
}

/* The jobs a drain queued (bus_worker_push noted when, in held_ns) wake
 * their workers when the replies pause: at
 * the first look after a gather that finds nothing more on the socket,
 * after HOLD_SLOTS of a slot at most, and at the next tick (bus_collect).
 * A board program answers a slot's boards in a burst; a worker woken
 * after each gathered drain woke some five times a slot, each wake-up on
 * the driver's core costing more than the light drivers' ticks it ran
 * (docs/PERFORMANCE.md, "Drivers on driver workers"). A tick's job is due
 * at its machine's next service, a period (at least a slot) after the
 * reply: it still has three quarters of a slot. Drains from the tick and
 * the main thread's commands wake at once. Returns the wait's timeout. */
#define HOLD_SLOTS(slot_ns) ((slot_ns) / 4)
static int64_t hold(struct vmac_bus *bus, int64_t now, int64_t next)
{
	int64_t c = bus->slot_ns / 8 < GATHER_NS ? bus->slot_ns / 8 : GATHER_NS;
	if (!bus->held_ns)
		return next - now;
	if (bus->timerfd_wait || now - bus->held_ns >= HOLD_SLOTS(bus->slot_ns) || next - now <= 2 * c) {
		bus_workers_kick(bus);
		return next - now;
	}
	return 0; /* a look: nothing there, and the kick goes (bus_loop) */
}

/* The bus thread's loop: the tick when its time has come (before anything
 * else that is ready: a flood on the socket must not starve the schedule),
 * replies as they arrive, and the main thread's commands and requests when
 * it wakes the thread. It waits with epoll_pwait2 and a timeout to the next
 * tick, which wakes it closer to the tick than a wait on a timerfd does
 * (docs/PERFORMANCE.md, "Tick lateness"); on a kernel without epoll_pwait2
 * the absolute timerfd is in the set instead. Ticks fall on start + k x
 * slot however late any one of them was handled. Returns when the bus has
 * stopped. */
void bus_loop(struct vmac_bus *bus)
{
	struct epoll_event ev[4];
	uint64_t count;
	int n, i;
	for (;;) {
		int64_t now = vmac_now_ns(), next = bus->start_ns + (int64_t)(bus->tick_index + 1) * bus->slot_ns,
		        wait_ns;
		if (!bus->timerfd_wait && now >= next) {
			if (bus_tick(bus, now, (uint64_t)((now - bus->start_ns) / bus->slot_ns) - bus->tick_index))
				return;
			continue;
		}
		wait_ns = hold(bus, now, next);
		n = bus->timerfd_wait ? epoll_wait(bus->epfd, ev, 4, -1) : pwait2(bus->epfd, ev, 4, wait_ns);
		if (n == 0 && bus->held_ns) {
			bus_workers_kick(bus); /* the replies have paused */
			continue;
		}
		if (n < 0)
			continue; /* EINTR */
		for (i = 0; i < n; i++)
			if (ev[i].data.fd == bus->tfd && read(bus->tfd, &count, sizeof(count)) == sizeof(count) &&
			    count && bus_tick(bus, vmac_now_ns(), count))
				return;
		if (!bus->timerfd_wait && vmac_now_ns() >= next)
			continue; /* the tick first: what else is ready is still ready after it */
		for (i = 0; i < n; i++) {
			if (ev[i].data.fd == bus->tr.fd) {
				/* EPOLLERR: the error queue holds something (the
				 * transmit stamps of SYNC), said until it is read */
				if (ev[i].events & EPOLLERR)
					bus_sync_read_stamps(bus, 1);
				bus_drain(bus);
				gather(bus, next);
			} else if (ev[i].data.fd == bus->wakefd) {
				if (read(bus->wakefd, &count, sizeof(count)) != sizeof(count))
					continue;
				bus_commands(bus);
				bus_requests(bus);
			}
		}
	}
}

static int watch(struct vmac_bus *bus, int fd)
{
	struct epoll_event e;
	memset(&e, 0, sizeof(e));
	e.events = EPOLLIN;
	e.data.fd = fd;
	return epoll_ctl(bus->epfd, EPOLL_CTL_ADD, fd, &e);
}

int bus_wait_init(struct vmac_bus *bus, char *err, size_t errlen)
{
	struct epoll_event e;
	bus->epfd = epoll_create1(EPOLL_CLOEXEC);
	bus->wakefd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	if (bus->epfd < 0 || bus->wakefd < 0 || watch(bus, bus->tr.fd) != 0 || watch(bus, bus->wakefd) != 0)
		goto fail;
	if (pwait2(bus->epfd, &e, 1, 0) < 0 && errno == ENOSYS) {
		bus->timerfd_wait = 1; /* Linux before 5.11 */
		if (watch(bus, bus->tfd) != 0)
			goto fail;
	}
	return 0;
fail:
	snprintf(err, errlen, "cannot create the bus event loop: %s", strerror(errno));
	return -1;
}

void bus_wait_fini(struct vmac_bus *bus)
{
	if (bus->epfd >= 0)
		close(bus->epfd);
	if (bus->wakefd >= 0)
		close(bus->wakefd);
	bus->epfd = bus->wakefd = -1;
}

void bus_wake(struct vmac_bus *bus)
{
	uint64_t one = 1;
	if (write(bus->wakefd, &one, sizeof(one)) != sizeof(one)) {
		/* the counter is full: a wake-up is pending anyway */
	}
}
