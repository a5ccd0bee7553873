/* Order statistics shared by the benchmark programs. */
#ifndef FG_BENCH_BENCHSTAT_H
#define FG_BENCH_BENCHSTAT_H

#include <stdlib.h>

/* qsort's comparison for doubles, ascending. */
static inline int bench_cmp_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* The median of v (n >= 1), which it sorts. */
static inline double bench_median(double *v, int n) {
  qsort(v, (size_t)n, sizeof *v, bench_cmp_double);
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

#endif
