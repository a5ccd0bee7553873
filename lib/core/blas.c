#include "core/blas.h"

#include <cblas.h> /* OpenBLAS's, with openblas_get/set_num_threads */

int fg_blas_single_begin(void) {
  const int prev = openblas_get_num_threads();
  if (prev != 1) openblas_set_num_threads(1);
  return prev;
}

void fg_blas_single_end(int prev) {
  if (prev != 1) openblas_set_num_threads(prev);
}
