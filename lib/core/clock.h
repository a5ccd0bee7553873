/* Seconds as doubles, for timeouts, deadlines and timestamps. */
#ifndef FG_CORE_CLOCK_H
#define FG_CORE_CLOCK_H

#include <stdint.h>
#include <time.h>

/* CLOCK_MONOTONIC seconds: for durations and deadlines (never jumps). */
double fg_mono_s(void);

/* CLOCK_REALTIME seconds since the epoch: for timestamps shown to users. */
double fg_real_s(void);

/* CLOCK_REALTIME milliseconds since the epoch, truncated: the timestamps the state keeps. */
int64_t fg_real_ms(void);

/* *ts = now on clock (CLOCK_MONOTONIC or CLOCK_REALTIME, as the condition variable it is
 * for waits on) plus ms milliseconds (>= 0): an absolute deadline for
 * pthread_cond_timedwait. */
void fg_deadline_after_ms(struct timespec *ts, clockid_t clock, long ms);

#endif
