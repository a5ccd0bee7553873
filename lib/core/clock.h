/* Seconds as doubles, for timeouts, deadlines and timestamps. */
#ifndef FG_CORE_CLOCK_H
#define FG_CORE_CLOCK_H

/* CLOCK_MONOTONIC seconds: for durations and deadlines (never jumps). */
double fg_mono_s(void);

/* CLOCK_REALTIME seconds since the epoch: for timestamps shown to users. */
double fg_real_s(void);

#endif
