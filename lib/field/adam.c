/* Adam optimiser step and learning-rate schedule (see adam.h).
 *
 * The step is memory-bound once vectorised (it reads four arrays and writes three: 28 bytes a
 * parameter, some 450 MB a step for a 16-level 2^19 hash grid). The build targets baseline
 * x86-64 and sqrtf sets errno, so GCC leaves the plain loop scalar (about 0.3-0.4 G params/s
 * on the 2-core CI machine); the AVX2 and AVX-512 loops below, picked at run time, were 3.6x
 * and 4.6x faster on 2 threads of a 2-core AMD EPYC VM (bench_mlp). Neither uses FMA, so
 * all three round alike. */
#include "field/adam.h"

#include "core/error.h"
#include "core/threads.h"

#include <math.h>
#include <omp.h>

void fg_adam_config_default(fg_adam_config *cfg) {
  cfg->lr = 1e-2f;
  cfg->beta1 = 0.9f;
  cfg->beta2 = 0.99f;
  cfg->eps = 1e-15f;
  cfg->l2 = 1e-6f;
  cfg->skip_zero_grad = 0;
}

int fg_adam_config_check(const fg_adam_config *cfg) {
  if (!cfg) return fg_fail(FG_EINVAL, "adam config is NULL");
  if (!(cfg->lr >= 0.0f) || !isfinite(cfg->lr))
    return fg_fail(FG_EINVAL, "adam lr must be finite and >= 0, got %g", (double)cfg->lr);
  if (!(cfg->beta1 >= 0.0f && cfg->beta1 < 1.0f))
    return fg_fail(FG_EINVAL, "adam beta1 must be in [0, 1), got %g", (double)cfg->beta1);
  if (!(cfg->beta2 >= 0.0f && cfg->beta2 < 1.0f))
    return fg_fail(FG_EINVAL, "adam beta2 must be in [0, 1), got %g", (double)cfg->beta2);
  if (!(cfg->eps >= 0.0f) || !isfinite(cfg->eps))
    return fg_fail(FG_EINVAL, "adam eps must be finite and >= 0, got %g", (double)cfg->eps);
  if (!(cfg->l2 >= 0.0f) || !isfinite(cfg->l2))
    return fg_fail(FG_EINVAL, "adam l2 must be finite and >= 0, got %g", (double)cfg->l2);
  return 0;
}

/* Bias-corrected learning rate lr * sqrt(1 - beta2^t) / (1 - beta1^t), in double. */
static float corrected_lr(const fg_adam_config *cfg, int step) {
  const double t = step > 0 ? (double)step : 1.0;
  const double c2 = 1.0 - pow((double)cfg->beta2, t), c1 = 1.0 - pow((double)cfg->beta1, t);
  return (float)((double)cfg->lr * sqrt(c2) / c1);
}

/* One parameter; shared by the fast loop and the reference so that both round alike. */
static inline void adam_one(float *p, float g, float *m, float *v, float b1, float b2,
                            float eps, float l2, float lr_t) {
  g += l2 * *p;
  const float mi = b1 * *m + (1.0f - b1) * g;
  const float vi = b2 * *v + (1.0f - b2) * g * g;
  *m = mi;
  *v = vi;
  *p -= lr_t * mi / (sqrtf(vi) + eps);
}

void fg_adam_step_ref(const fg_adam_config *cfg, float *params, const float *grads, float *m,
                      float *v, size_t n, int step) {
  const float lr_t = corrected_lr(cfg, step);
  for (size_t i = 0; i < n; i++) {
    if (cfg->skip_zero_grad && grads[i] == 0.0f) continue;
    adam_one(&params[i], grads[i], &m[i], &v[i], cfg->beta1, cfg->beta2, cfg->eps, cfg->l2,
             lr_t);
  }
}

/* Elements [i0, i1) in scalar code (any CPU; also the tails of the vector loop). */
static void adam_range(const fg_adam_config *cfg, float *params, const float *grads, float *m,
                       float *v, size_t i0, size_t i1, float lr_t) {
  const float b1 = cfg->beta1, b2 = cfg->beta2, eps = cfg->eps, l2 = cfg->l2;
  for (size_t i = i0; i < i1; i++) {
    if (cfg->skip_zero_grad && grads[i] == 0.0f) continue;
    adam_one(&params[i], grads[i], &m[i], &v[i], b1, b2, eps, l2, lr_t);
  }
}

/* The kernels rely on GCC's target pragma, which clang ignores (it then refuses the
 * intrinsics); a clang build (the libFuzzer one) takes the portable path. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#include <immintrin.h>
#pragma GCC push_options
#pragma GCC target("avx512f")
/* The same arithmetic as adam_one, 16 lanes at a time and in the same order of operations
 * (no FMA), so that the result is bit-identical to the scalar code. Without this the loop
 * stays scalar: sqrtf sets errno and the build targets baseline x86-64. */
static void adam_range_avx512(const fg_adam_config *cfg, float *params, const float *grads,
                              float *m, float *v, size_t i0, size_t i1, float lr_t) {
  const __m512 b1 = _mm512_set1_ps(cfg->beta1), c1 = _mm512_set1_ps(1.0f - cfg->beta1);
  const __m512 b2 = _mm512_set1_ps(cfg->beta2), c2 = _mm512_set1_ps(1.0f - cfg->beta2);
  const __m512 eps = _mm512_set1_ps(cfg->eps), l2 = _mm512_set1_ps(cfg->l2);
  const __m512 lr = _mm512_set1_ps(lr_t), zero = _mm512_setzero_ps();
  size_t i = i0;
  for (; i + 16 <= i1; i += 16) {
    const __m512 p = _mm512_loadu_ps(params + i);
    __m512 g = _mm512_loadu_ps(grads + i);
    const __mmask16 k = cfg->skip_zero_grad ? _mm512_cmp_ps_mask(g, zero, _CMP_NEQ_UQ)
                                            : (__mmask16)0xffff;
    g = _mm512_add_ps(g, _mm512_mul_ps(l2, p));
    const __m512 mi = _mm512_add_ps(_mm512_mul_ps(b1, _mm512_loadu_ps(m + i)),
                                    _mm512_mul_ps(c1, g));
    const __m512 vi = _mm512_add_ps(_mm512_mul_ps(b2, _mm512_loadu_ps(v + i)),
                                    _mm512_mul_ps(_mm512_mul_ps(c2, g), g));
    const __m512 step = _mm512_div_ps(_mm512_mul_ps(lr, mi),
                                      _mm512_add_ps(_mm512_sqrt_ps(vi), eps));
    _mm512_mask_storeu_ps(m + i, k, mi);
    _mm512_mask_storeu_ps(v + i, k, vi);
    _mm512_mask_storeu_ps(params + i, k, _mm512_sub_ps(p, step));
  }
  adam_range(cfg, params, grads, m, v, i, i1, lr_t);
}
#pragma GCC pop_options

#pragma GCC push_options
#pragma GCC target("avx2")
/* The AVX-512 loop's arithmetic 8 lanes at a time, for CPUs without AVX-512. "avx2" alone
 * (not "fma") keeps GCC from fusing the multiplies and adds. A skipped lane stores its old
 * values back (each thread owns its range). */
static void adam_range_avx2(const fg_adam_config *cfg, float *params, const float *grads,
                            float *m, float *v, size_t i0, size_t i1, float lr_t) {
  const __m256 b1 = _mm256_set1_ps(cfg->beta1), c1 = _mm256_set1_ps(1.0f - cfg->beta1);
  const __m256 b2 = _mm256_set1_ps(cfg->beta2), c2 = _mm256_set1_ps(1.0f - cfg->beta2);
  const __m256 eps = _mm256_set1_ps(cfg->eps), l2 = _mm256_set1_ps(cfg->l2);
  const __m256 lr = _mm256_set1_ps(lr_t), zero = _mm256_setzero_ps();
  const __m256 all = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
  size_t i = i0;
  for (; i + 8 <= i1; i += 8) {
    const __m256 p = _mm256_loadu_ps(params + i), m0 = _mm256_loadu_ps(m + i);
    const __m256 v0 = _mm256_loadu_ps(v + i);
    __m256 g = _mm256_loadu_ps(grads + i);
    const __m256 k = cfg->skip_zero_grad ? _mm256_cmp_ps(g, zero, _CMP_NEQ_UQ) : all;
    g = _mm256_add_ps(g, _mm256_mul_ps(l2, p));
    const __m256 mi = _mm256_add_ps(_mm256_mul_ps(b1, m0), _mm256_mul_ps(c1, g));
    const __m256 vi = _mm256_add_ps(_mm256_mul_ps(b2, v0),
                                    _mm256_mul_ps(_mm256_mul_ps(c2, g), g));
    const __m256 step = _mm256_div_ps(_mm256_mul_ps(lr, mi),
                                      _mm256_add_ps(_mm256_sqrt_ps(vi), eps));
    _mm256_storeu_ps(m + i, _mm256_blendv_ps(m0, mi, k));
    _mm256_storeu_ps(v + i, _mm256_blendv_ps(v0, vi, k));
    _mm256_storeu_ps(params + i, _mm256_blendv_ps(p, _mm256_sub_ps(p, step), k));
  }
  adam_range(cfg, params, grads, m, v, i, i1, lr_t);
}
#pragma GCC pop_options
#define HAVE_ADAM_SIMD 1
#else
#define HAVE_ADAM_SIMD 0
#endif

int fg_adam_kernel_supported(fg_adam_kernel k) {
  switch (k) {
  case FG_ADAM_SCALAR: return 1;
#if HAVE_ADAM_SIMD
  case FG_ADAM_AVX2: return __builtin_cpu_supports("avx2");
  case FG_ADAM_AVX512: return __builtin_cpu_supports("avx512f");
#endif
  default: return 0;
  }
}

static fg_adam_kernel widest_kernel(void) {
  if (fg_adam_kernel_supported(FG_ADAM_AVX512)) return FG_ADAM_AVX512;
  if (fg_adam_kernel_supported(FG_ADAM_AVX2)) return FG_ADAM_AVX2;
  return FG_ADAM_SCALAR;
}

void fg_adam_step_kernel(fg_adam_kernel k, const fg_adam_config *cfg, float *params,
                         const float *grads, float *m, float *v, size_t n, int step,
                         int n_threads) {
  const float lr_t = corrected_lr(cfg, step);
  int nt = fg_threads(n_threads);
  if (n < 65536) nt = 1;
  /* Fixed ranges per thread, cut at multiples of 16 elements. */
#pragma omp parallel num_threads(nt) if (nt > 1)
  {
    const int t = omp_get_thread_num(), T = omp_get_num_threads();
    const size_t blocks = (n + 15) / 16;
    size_t i0 = blocks * (size_t)t / (size_t)T * 16, i1 = blocks * (size_t)(t + 1) / (size_t)T * 16;
    if (i1 > n) i1 = n;
    if (i0 > n) i0 = n;
    switch (k) {
#if HAVE_ADAM_SIMD
    case FG_ADAM_AVX512: adam_range_avx512(cfg, params, grads, m, v, i0, i1, lr_t); break;
    case FG_ADAM_AVX2: adam_range_avx2(cfg, params, grads, m, v, i0, i1, lr_t); break;
#endif
    default: adam_range(cfg, params, grads, m, v, i0, i1, lr_t); break;
    }
  }
}

void fg_adam_step(const fg_adam_config *cfg, float *params, const float *grads, float *m,
                  float *v, size_t n, int step, int n_threads) {
  fg_adam_step_kernel(widest_kernel(), cfg, params, grads, m, v, n, step, n_threads);
}

float fg_lr_exponential(float lr0, int step, int decay_start, int decay_interval,
                        float decay_base) {
  const long long s = (long long)step - 1;
  if (decay_interval <= 0 || s < decay_start) return lr0;
  const long long k = (s - decay_start) / decay_interval + 1;
  return (float)((double)lr0 * pow((double)decay_base, (double)k));
}
