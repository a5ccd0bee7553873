/* Resident memory of the benchmark's own process, from /proc/self (Linux): shared by the
 * benchmark programs that report a peak. */
#ifndef FG_BENCH_BENCHMEM_H
#define FG_BENCH_BENCHMEM_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* kB of a /proc/self/status field ("VmHWM:" the peak resident set, "VmRSS:" the current one),
 * or -1 when it cannot be read. */
static inline long bench_status_kb(const char *key) {
  FILE *f = fopen("/proc/self/status", "r");
  char line[256];
  long v = -1;
  while (f && fgets(line, sizeof line, f))
    if (strncmp(line, key, strlen(key)) == 0) v = strtol(line + strlen(key), NULL, 10);
  if (f) fclose(f);
  return v;
}

/* Resets VmHWM to the current RSS (writing 5 to /proc/self/clear_refs), so that a peak read
 * afterwards is that of what ran since. 1 when the kernel took it, 0 when not (the peak then
 * includes everything before). */
static inline int bench_reset_peak(void) {
  FILE *f = fopen("/proc/self/clear_refs", "w");
  if (!f) return 0;
  const int ok = fputs("5", f) >= 0;
  return fclose(f) == 0 && ok;
}

#endif
