#include "core/threads.h"

#ifdef _OPENMP
#include <omp.h>
#endif

int fg_threads(int n_threads) {
  if (n_threads > 0) return n_threads;
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}
