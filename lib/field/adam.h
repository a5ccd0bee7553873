/* Adam, as tiny-cuda-nn implements it for Instant-NGP, and its learning-rate schedule.
 *
 * One step over n parameters, t = step (1-based):
 *   g  = grad + l2 * param                     (L2 regularisation added to the gradient)
 *   m  = beta1 * m + (1 - beta1) * g
 *   v  = beta2 * v + (1 - beta2) * g^2
 *   lr_t = lr * sqrt(1 - beta2^t) / (1 - beta1^t)       (bias correction, in double)
 *   param -= lr_t * m / (sqrt(v) + eps)
 * eps is added to sqrt(v) before the bias correction is applied to the learning rate, as in
 * tiny-cuda-nn (PyTorch adds it to sqrt(v_hat)); with Instant-NGP's eps = 1e-15 the two agree.
 * Instant-NGP uses lr 1e-2, beta1 0.9, beta2 0.99, eps 1e-15, l2 1e-6 for the MLPs and 0 for
 * the hash tables.
 *
 * skip_zero_grad. tiny-cuda-nn skips hash-table entries whose gradient is exactly 0 (an entry
 * no sample touched this step): neither the entry nor its moments change, so untouched entries
 * keep their momentum instead of decaying. Set it for hash tables to get that behaviour.
 * tiny-cuda-nn also keeps one step counter per such entry for the bias correction; here the
 * global step is used. The first step of an entry is lr * sign(g) either way, but under a
 * constant gradient a young entry's later steps are then up to 2.13x larger (at its 13th
 * update with beta1 0.9, beta2 0.99; back to 1.03x by its 300th) than with its own counter,
 * because sqrt(1 - beta2^k) / (1 - beta1^k) < 1 for small k. Per-entry counters would cost 4
 * more bytes a parameter; an open point if hash-table training turns out to need them.
 *
 * Elementwise; split across OpenMP threads in fixed ranges, so bit-identical for any thread
 * count. Instant-NGP also keeps an EMA of the weights for rendering (its "Ema" optimiser
 * wrapper); that is a separate, caller-side average, not done here. */
#ifndef FG_FIELD_ADAM_H
#define FG_FIELD_ADAM_H

#include <stddef.h>

typedef struct fg_adam_config {
  float lr;           /* learning rate (Instant-NGP: 1e-2) */
  float beta1;        /* 0.9 */
  float beta2;        /* 0.99 */
  float eps;          /* 1e-15 */
  float l2;           /* L2 weight decay added to the gradient: 1e-6 for MLPs, 0 for tables */
  int skip_zero_grad; /* 1: leave entries with a zero gradient untouched (hash tables) */
} fg_adam_config;

/* Fills cfg with Instant-NGP's settings for an MLP: lr 1e-2, beta1 0.9, beta2 0.99,
 * eps 1e-15, l2 1e-6, skip_zero_grad 0. */
void fg_adam_config_default(fg_adam_config *cfg);

/* Checks cfg: lr >= 0, beta1 and beta2 in [0, 1), eps >= 0, l2 >= 0, all finite. Returns 0 or
 * FG_EINVAL with a detail naming the bad field. */
int fg_adam_config_check(const fg_adam_config *cfg);

/* One Adam step over n parameters at 1-based step number `step` (>= 1). params, m and v are
 * updated in place (m and v start at zero); grads is read only. All arrays are caller-owned
 * and n floats long. cfg must have passed fg_adam_config_check. */
void fg_adam_step(const fg_adam_config *cfg, float *params, const float *grads, float *m,
                  float *v, size_t n, int step, int n_threads);

/* The loops behind fg_adam_step, which runs the widest one this CPU supports. They give the
 * same bits (no FMA, the reference's order of operations); x86-64 GCC builds have the two
 * vector loops, others only the scalar one. */
typedef enum fg_adam_kernel {
  FG_ADAM_AUTO = -1,
  FG_ADAM_SCALAR = 0,
  FG_ADAM_AVX2,
  FG_ADAM_AVX512,
} fg_adam_kernel;

/* 1 if this build and CPU can run loop k, else 0 (also for FG_ADAM_AUTO). */
int fg_adam_kernel_supported(fg_adam_kernel k);

/* fg_adam_step with loop k (for tests and benchmarks); k must be supported. */
void fg_adam_step_kernel(fg_adam_kernel k, const fg_adam_config *cfg, float *params,
                         const float *grads, float *m, float *v, size_t n, int step,
                         int n_threads);

/* Scalar reference of fg_adam_step (one thread, plain loop). For tests. */
void fg_adam_step_ref(const fg_adam_config *cfg, float *params, const float *grads, float *m,
                      float *v, size_t n, int step);

/* Learning rate of 1-based step `step` under tiny-cuda-nn's ExponentialDecay optimiser with
 * Instant-NGP's settings (decay_start 20000, decay_interval 10000, decay_base 0.33). That
 * wrapper multiplies its rate by decay_base before the Adam step whose 0-based index
 * s = step - 1 satisfies s >= decay_start and (s - decay_start) % decay_interval == 0, so
 *   lr = lr0                                                               if s < decay_start
 *   lr = lr0 * decay_base^(floor((s - decay_start) / decay_interval) + 1)  otherwise
 * (steps 1..20000 at lr0, 20001..30000 at 0.33 lr0, ...). decay_interval <= 0 means no decay.
 * tiny-cuda-nn's decay_end (10^7 by default) is not modelled. */
float fg_lr_exponential(float lr0, int step, int decay_start, int decay_interval,
                        float decay_base);

#endif
