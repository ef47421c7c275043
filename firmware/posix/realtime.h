/* vmac-board's real-time set-up (realtime.c): the process behaves like the
 * microcontroller it simulates, answering when a frame comes whatever else
 * the machine runs. POSIX only. */
#ifndef VMAC_POSIX_REALTIME_H
#define VMAC_POSIX_REALTIME_H

/* SCHED_FIFO priority: above every ordinary process, below vmacd's bus
 * thread (50) and its driver workers (40), so that boards on the host's
 * machine never hold off the host they answer (docs/HOST.md, "realtime"). */
#define BOARDS_REALTIME_PRIORITY 30

/* Ask for SCHED_FIFO at BOARDS_REALTIME_PRIORITY and for every page of the
 * process locked in memory (no page fault in a reply). Call once, after
 * every allocation of the set-up: with MCL_FUTURE, a later allocation over
 * RLIMIT_MEMLOCK would fail. Refused (not root, no CAP_SYS_NICE, a low
 * RLIMIT_RTPRIO; for the lock no CAP_IPC_LOCK and a small RLIMIT_MEMLOCK),
 * one line on stderr says what and what it needs, and the process runs on
 * with what it got: never an error. */
void boards_try_realtime(void);

#endif
