/* The one rule for how many threads a parallel kernel uses. */
#ifndef FG_CORE_THREADS_H
#define FG_CORE_THREADS_H

/* n_threads when it is positive; otherwise OpenMP's default team size
 * (omp_get_max_threads(), which honours OMP_NUM_THREADS), and 1 in a build without OpenMP.
 * Every kernel that takes an n_threads option resolves it here. */
int fg_threads(int n_threads);

#endif
