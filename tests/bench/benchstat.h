/* Order statistics shared by the benchmark programs. */
#ifndef FG_BENCH_BENCHSTAT_H
#define FG_BENCH_BENCHSTAT_H

#include <math.h>
#include <stdlib.h>

/* qsort's comparison for doubles, ascending. */
static inline int bench_cmp_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* The benchmarks' one percentile rule, nearest rank: the q-quantile (0 < q <= 1) of v[0, n)
 * is the ceil(q * n)-th smallest value. Sorts v in place; NAN when n is 0. */
static inline double bench_percentile(double *v, int n, double q) {
  if (n <= 0) return NAN;
  qsort(v, (size_t)n, sizeof *v, bench_cmp_double);
  int k = (int)ceil(q * n) - 1;
  if (k < 0) k = 0;
  if (k >= n) k = n - 1;
  return v[k];
}

/* p50 by the same rule. */
static inline double bench_median(double *v, int n) { return bench_percentile(v, n, 0.5); }

#endif
