# core/sched: the periodic 2^n slot schedule (docs/SCHEDULER.md): pure
# computation, no OS call. Ground.
sched_LIBS :=
