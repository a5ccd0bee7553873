/* Hash-grid encoding throughput: forward and forward+backward samples/s at B samples.
 *
 * Usage: bench_hashgrid [threads [log2_B]]   (defaults: 2 threads, B = 2^18)
 *
 * Two grids: Instant-NGP's NeRF grid (L=16, F=2, T=2^19, N_min=16, N_max=2048) and a
 * feature-field grid (L=12, F=4, T=2^19, N_min=16, N_max=128). Two sample sets: points uniform
 * in the cube (every fine-level corner a cache miss: the worst case) and points along rays
 * (rays of 128 samples at Instant-NGP's step sqrt(3)/1024, consecutive in the batch as a
 * training step has them). Each figure is the best of 10 runs after a warm-up: the best, not
 * the mean, filters out the load of other processes. The backward pass accumulates into a
 * gradient array that is not cleared between runs (clearing it is the optimiser's job).
 * Arrays come from plain malloc (no huge pages), as a caller that does nothing special has.
 *
 * Output: one line, e.g.
 *   bench=hashgrid threads=2 B=262144 ngp_fwd_uniform=... ngp_fwdbwd_uniform=... ...
 * values in samples per second. */
#include "core/error.h"
#include "field/hashgrid.h"
#include "field/sh.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static uint64_t rng_state = 1234;

static double urand(void) {
  uint64_t z = (rng_state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  return (double)(z >> 11) * 0x1p-53;
}

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void *xmalloc(size_t n) {
  void *p = malloc(n);
  if (!p) {
    fprintf(stderr, "bench_hashgrid: out of memory (%zu bytes)\n", n);
    exit(1);
  }
  return p;
}

static void make_uniform(float *x, int B) {
  for (size_t i = 0; i < (size_t)B * 3; i++) x[i] = (float)urand();
}

/* Rays of 128 samples: origin in [0.2, 0.8]^3, uniform direction, step sqrt(3)/1024; samples
 * that leave the cube are clamped to it by the encoder. */
static void make_rays(float *x, int B) {
  const int per_ray = 128;
  const double step = sqrt(3.0) / 1024.0;
  for (int r = 0; r * per_ray < B; r++) {
    double o[3], d[3];
    const double z = 2.0 * urand() - 1.0, phi = 2.0 * M_PI * urand(), s = sqrt(1.0 - z * z);
    d[0] = s * cos(phi);
    d[1] = s * sin(phi);
    d[2] = z;
    for (int k = 0; k < 3; k++) o[k] = 0.2 + 0.6 * urand();
    for (int j = 0; j < per_ray && r * per_ray + j < B; j++)
      for (int k = 0; k < 3; k++)
        x[(size_t)(r * per_ray + j) * 3 + k] = (float)(o[k] + d[k] * step * (j - per_ray / 2));
  }
}

typedef struct result {
  double fwd, fwdbwd; /* samples per second */
} result;

static result run(const fg_hashgrid_config *cfg, const float *x, int B, int threads) {
  size_t n = 0;
  if (fg_hashgrid_layout(cfg, NULL, &n) != 0) {
    fprintf(stderr, "bench_hashgrid: %s\n", fg_error_detail());
    exit(1);
  }
  const size_t LF = (size_t)cfg->n_levels * cfg->n_features;
  float *params = xmalloc(n * sizeof(float)), *grad = xmalloc(n * sizeof(float));
  float *out = xmalloc((size_t)B * LF * sizeof(float));
  fg_hashgrid_init(cfg, params, 1);
  memset(grad, 0, n * sizeof(float));
  result r = {0, 0};
  double best_f = 1e30, best_b = 1e30;
  for (int rep = 0; rep < 11; rep++) {
    double t0 = now_s();
    fg_hashgrid_forward(cfg, params, x, B, out, threads);
    double t1 = now_s();
    /* out doubles as dout: the values do not change the memory traffic */
    fg_hashgrid_backward(cfg, x, B, out, grad, threads);
    double t2 = now_s();
    if (rep == 0) continue; /* warm-up: page faults of the fresh arrays */
    if (t1 - t0 < best_f) best_f = t1 - t0;
    if (t2 - t1 < best_b) best_b = t2 - t1;
  }
  r.fwd = B / best_f;
  r.fwdbwd = B / (best_f + best_b);
  free(params);
  free(grad);
  free(out);
  return r;
}

int main(int argc, char **argv) {
  const int threads = argc > 1 ? atoi(argv[1]) : 2;
  const int log2_B = argc > 2 ? atoi(argv[2]) : 18;
  if (threads < 1 || log2_B < 8 || log2_B > 24) {
    fprintf(stderr, "usage: bench_hashgrid [threads [log2_B (8..24)]]\n");
    return 2;
  }
  const int B = 1 << log2_B;
  fg_hashgrid_config ngp, feat = {12, 4, 19, 16, 128};
  fg_hashgrid_config_default(&ngp);
  float *xu = xmalloc((size_t)B * 3 * sizeof(float)), *xr = xmalloc((size_t)B * 3 * sizeof(float));
  make_uniform(xu, B);
  make_rays(xr, B);

  result ngp_u = run(&ngp, xu, B, threads), ngp_r = run(&ngp, xr, B, threads);
  result feat_u = run(&feat, xu, B, threads), feat_r = run(&feat, xr, B, threads);

  /* SH-4 of B unit directions (single-threaded by design) */
  float *sh = xmalloc((size_t)B * FG_SH4_DIM * sizeof(float));
  for (int i = 0; i < B; i++) {
    float *d = xu + (size_t)i * 3;
    const float nx = d[0] - 0.5f, ny = d[1] - 0.5f, nz = d[2] - 0.5f;
    const float inv = 1.0f / sqrtf(nx * nx + ny * ny + nz * nz + 1e-12f);
    d[0] = nx * inv;
    d[1] = ny * inv;
    d[2] = nz * inv;
  }
  double best_sh = 1e30;
  for (int rep = 0; rep < 6; rep++) {
    double t0 = now_s();
    fg_sh4_encode(xu, B, sh);
    double t = now_s() - t0;
    if (rep > 0 && t < best_sh) best_sh = t;
  }

  printf("bench=hashgrid threads=%d B=%d ngp_fwd_uniform=%.0f ngp_fwdbwd_uniform=%.0f "
         "ngp_fwd_rays=%.0f ngp_fwdbwd_rays=%.0f feat_fwd_uniform=%.0f feat_fwdbwd_uniform=%.0f "
         "feat_fwd_rays=%.0f feat_fwdbwd_rays=%.0f sh4=%.0f\n",
         threads, B, ngp_u.fwd, ngp_u.fwdbwd, ngp_r.fwd, ngp_r.fwdbwd, feat_u.fwd, feat_u.fwdbwd,
         feat_r.fwd, feat_r.fwdbwd, B / best_sh);
  free(xu);
  free(xr);
  free(sh);
  return 0;
}
