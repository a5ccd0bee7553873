/* OpenBLAS's thread count around SGEMMs issued from OpenMP threads, or between OpenMP
 * regions.
 *
 * Debian's OpenBLAS is the pthread build: its thread count is process-wide and it knows
 * nothing of OpenMP, so SGEMMs issued from several OpenMP threads must each run on one
 * OpenBLAS thread (its own pool spinning beside OpenMP's costs a factor of two or more on a
 * machine with few cores). The same holds for an SGEMM issued from one thread between two
 * OpenMP regions: after each job OpenBLAS's worker keeps calling sched_yield for a while,
 * beside the next region's threads (a training with features alone on two cores took 1.3 to
 * 1.8 times as long; beside other load the worker's share of the cores costs little). */
#ifndef FG_CORE_BLAS_H
#define FG_CORE_BLAS_H

/* Sets OpenBLAS to one thread and returns the count it had, for fg_blas_single_end. */
int fg_blas_single_begin(void);

/* Puts back the count fg_blas_single_begin returned. */
void fg_blas_single_end(int prev);

#endif
