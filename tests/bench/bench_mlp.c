/* MLP throughput: forward and forward+backward rows/s and GFLOP/s of Instant-NGP's density
 * net {32, 64, 1, 16} and colour net {32, 64, 2, 3} at B = 2^18 and F3RM's feature net
 * {32, 64, 2, 512} at B = 2^16, on both fast paths (AVX-512 kernels and chunked
 * single-threaded OpenBLAS SGEMM), with OpenBLAS SGEMM 2048^3 (OpenBLAS threading it over
 * the same number of threads) for reference. The backward pass includes din, as a NeRF needs
 * it (the hash grid and the density net sit below these nets).
 *
 * Usage: bench_mlp [threads]   (default 2)
 *
 * FLOP counted: forward 2 * n_params per row, backward 4 * n_params per row (weight
 * gradient and input gradient). Each figure is the best of several runs after a warm-up.
 *
 * Output: one line, e.g.
 *   bench=mlp threads=2 kernel=avx512 openblas_core=Haswell sgemm2048_gflops=216 \
 *     density_fwd_rows_s=... density_fwd_gflops=... density_fwdbwd_rows_s=... ...
 * keys <net>_<pass>_{rows_s,gflops} for the automatic path and <net>_<pass>_blas_... for the
 * OpenBLAS path, then adam_params_s (fg_adam_step over 2^24 parameters, parameters/s) and
 * adam_<loop>_params_s for each of its loops this CPU runs (scalar, avx2, avx512). */
#include "field/adam.h"
#include "field/mlp.h"

#include <cblas.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

char *openblas_get_corename(void);

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static float *xmalloc_f(size_t n) {
  float *p = malloc(sizeof(float) * (n ? n : 1));
  if (!p) {
    fprintf(stderr, "bench_mlp: out of memory (%zu floats)\n", n);
    exit(1);
  }
  return p;
}

static float *random_f(size_t n, float scale, uint64_t seed) {
  float *p = xmalloc_f(n);
  for (size_t i = 0; i < n; i++) {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    p[i] = scale * ((float)(seed >> 40) * 0x1p-23f - 1.0f);
  }
  return p;
}

static double sgemm_gflops(int threads) {
  const int n = 2048;
  float *a = random_f((size_t)n * n, 1.0f, 1), *b = random_f((size_t)n * n, 1.0f, 2);
  float *c = xmalloc_f((size_t)n * n);
  openblas_set_num_threads(threads);
  double best = 1e30;
  for (int r = 0; r < 4; r++) {
    const double t0 = now_s();
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, n, n, 1.0f, a, n, b, n, 0.0f, c,
                n);
    const double t = now_s() - t0;
    if (r > 0 && t < best) best = t;
  }
  free(a), free(b), free(c);
  return 2.0 * n * n * (double)n / best * 1e-9;
}

/* Best-of timings of forward and forward+backward; results into rows/s and GFLOP/s. */
static void bench_net(const char *name, const fg_mlp_config *cfg, int B, int threads,
                      const char *suffix) {
  const size_t np = fg_mlp_n_params(cfg);
  float *W = xmalloc_f(np), *dW = xmalloc_f(np);
  fg_mlp_init(cfg, W, 5);
  memset(dW, 0, np * sizeof(float));
  float *in = random_f((size_t)B * cfg->n_in, 1.0f, 3);
  float *dout = random_f((size_t)B * cfg->n_out, 1e-3f, 4);
  float *acts = xmalloc_f(fg_mlp_acts_floats(cfg, B)), *out = xmalloc_f((size_t)B * cfg->n_out);
  float *din = xmalloc_f((size_t)B * cfg->n_in);
  float *scratch = xmalloc_f(fg_mlp_scratch_floats(cfg, B));
  const int reps = 7;
  double best_f = 1e30, best_fb = 1e30;
  for (int r = 0; r < reps; r++) {
    double t0 = now_s();
    fg_mlp_forward(cfg, W, in, B, acts, out, threads);
    const double tf = now_s() - t0;
    t0 = now_s();
    fg_mlp_forward(cfg, W, in, B, acts, out, threads);
    fg_mlp_backward(cfg, W, in, acts, dout, B, dW, din, scratch, threads);
    const double tfb = now_s() - t0;
    if (r > 0 && tf < best_f) best_f = tf;
    if (r > 0 && tfb < best_fb) best_fb = tfb;
  }
  printf(" %s_fwd%s_rows_s=%.0f %s_fwd%s_gflops=%.1f %s_fwdbwd%s_rows_s=%.0f"
         " %s_fwdbwd%s_gflops=%.1f",
         name, suffix, B / best_f, name, suffix, 2.0 * np * B / best_f * 1e-9, name, suffix,
         B / best_fb, name, suffix, 6.0 * np * B / best_fb * 1e-9);
  fflush(stdout);
  free(W), free(dW), free(in), free(dout), free(acts), free(out), free(din), free(scratch);
}

/* Adam over 2^24 parameters (a 16-level 2^19 x 2 hash grid's worth) with loop k
 * (FG_ADAM_AUTO: fg_adam_step's pick): parameters per second. */
static double adam_params_s(fg_adam_kernel k, int threads) {
  const size_t n = (size_t)1 << 24;
  float *p = random_f(n, 1e-4f, 6), *g = random_f(n, 1e-3f, 7);
  float *m = xmalloc_f(n), *v = xmalloc_f(n);
  memset(m, 0, n * sizeof(float)), memset(v, 0, n * sizeof(float));
  fg_adam_config cfg;
  fg_adam_config_default(&cfg);
  double best = 1e30;
  for (int t = 1; t <= 6; t++) {
    const double t0 = now_s();
    if (k == FG_ADAM_AUTO) fg_adam_step(&cfg, p, g, m, v, n, t, threads);
    else fg_adam_step_kernel(k, &cfg, p, g, m, v, n, t, threads);
    const double dt = now_s() - t0;
    if (t > 1 && dt < best) best = dt;
  }
  free(p), free(g), free(m), free(v);
  return (double)n / best;
}

int main(int argc, char **argv) {
  const int threads = argc > 1 ? atoi(argv[1]) : 2;
  if (threads < 1) {
    fprintf(stderr, "usage: bench_mlp [threads]\n");
    return 2;
  }
  const fg_mlp_config density = {32, 64, 1, 16}, colour = {32, 64, 2, 3},
                      feature = {32, 64, 2, 512};
  printf("bench=mlp threads=%d kernel=%s openblas_core=%s sgemm2048_gflops=%.1f", threads,
         fg_mlp_kernel_name(), openblas_get_corename(), sgemm_gflops(threads));
  fflush(stdout);
  for (int path = 0; path < 2; path++) {
    if (path == 1 && strcmp(fg_mlp_kernel_name(), "openblas") == 0) break;
    fg_mlp_set_kernel(path == 0 ? 0 : 1);
    const char *suffix = path == 0 ? "" : "_blas";
    bench_net("density", &density, 1 << 18, threads, suffix);
    bench_net("colour", &colour, 1 << 18, threads, suffix);
    bench_net("feature", &feature, 1 << 16, threads, suffix);
  }
  fg_mlp_set_kernel(0);
  printf(" adam_params_s=%.0f", adam_params_s(FG_ADAM_AUTO, threads));
  const char *const loops[] = {"scalar", "avx2", "avx512"};
  for (int k = FG_ADAM_SCALAR; k <= FG_ADAM_AVX512; k++)
    if (fg_adam_kernel_supported(k))
      printf(" adam_%s_params_s=%.0f", loops[k], adam_params_s(k, threads));
  printf("\n");
  return 0;
}
