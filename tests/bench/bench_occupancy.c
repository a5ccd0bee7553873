/* Occupancy-grid ray marching throughput: 2^14 rays (default) from 16 pinhole cameras on a
 * sphere of radius 1.5 around the cube (32 x 32 rays each, 50 degree field of view, looking
 * at the centre) into a 128^3 grid where a ball of radius 0.25 is occupied, Instant-NGP's
 * step sqrt(3)/1024, at most 1024 samples per ray.
 *
 * Usage: bench_occupancy [threads [log2_rays]]   (threads defaults to 2)
 * One line:
 *   bench=occupancy rays=16384 threads=2 N=128 samples=... lattice_steps=... skipped_frac=...
 *   rays_per_s=... samples_per_s=... march_ms=... ref_ms=... update_points_ms=...
 *   update_density_ms=...
 * skipped_frac is 1 - samples / lattice_steps, lattice_steps being the samples the same rays
 * get from an all-occupied grid (what a marcher without a grid would evaluate); ref_ms is the
 * brute-force reference marcher (1 thread), update_* one grid update of N^3/4 points.
 * Best of several repetitions. */
#include "field/occupancy.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void normalize(float *v) {
  const float n = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int i = 0; i < 3; i++) v[i] /= n;
}

static void cross(const float *a, const float *b, float *out) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

/* n_cams cameras on a Fibonacci sphere, side x side rays each. */
static void make_rays(int32_t n_cams, int32_t side, float *o, float *d) {
  const float golden = 2.39996323f, half_fov = tanf(25.0f * 3.14159265f / 180.0f);
  int32_t r = 0;
  for (int32_t c = 0; c < n_cams; c++) {
    const float z = 1.0f - 2.0f * ((float)c + 0.5f) / (float)n_cams, rho = sqrtf(1 - z * z);
    const float dir[3] = {rho * cosf(golden * (float)c), rho * sinf(golden * (float)c), z};
    const float pos[3] = {0.5f + 1.5f * dir[0], 0.5f + 1.5f * dir[1], 0.5f + 1.5f * dir[2]};
    const float fwd[3] = {-dir[0], -dir[1], -dir[2]};
    const float helper[3] = {fabsf(fwd[2]) < 0.9f ? 0.0f : 1.0f, 0.0f,
                             fabsf(fwd[2]) < 0.9f ? 1.0f : 0.0f};
    float right[3], up[3];
    cross(fwd, helper, right);
    normalize(right);
    cross(right, fwd, up);
    for (int32_t v = 0; v < side; v++)
      for (int32_t u = 0; u < side; u++, r++) {
        const float a = half_fov * (2.0f * ((float)u + 0.5f) / (float)side - 1.0f);
        const float b = half_fov * (2.0f * ((float)v + 0.5f) / (float)side - 1.0f);
        for (int i = 0; i < 3; i++) {
          o[3 * r + i] = pos[i];
          d[3 * r + i] = fwd[i] + a * right[i] + b * up[i];
        }
        normalize(d + 3 * r);
      }
  }
}

int main(int argc, char **argv) {
  const int threads = argc > 1 ? atoi(argv[1]) : 2;
  const int log2_rays = argc > 2 ? atoi(argv[2]) : 14;
  const int32_t side = 32, n_cams = (int32_t)((1 << log2_rays) / (side * side));
  const int32_t R = n_cams * side * side, N = FG_OCCGRID_DEFAULT_RES, max_n = 1024;
  const float dt = FG_OCCGRID_DEFAULT_DT;
  if (n_cams < 1) {
    fprintf(stderr, "bench_occupancy: log2_rays must be at least 10\n");
    return 1;
  }
  fg_occgrid *full = NULL, *g = NULL;
  if (fg_occgrid_new(&full, N) < 0 || fg_occgrid_new(&g, N) < 0) return 1;
  float *dens = fg_occgrid_density(g);
  for (int32_t c = 0; c < N * N * N; c++) {
    const float x = ((float)(c % N) + 0.5f) / (float)N - 0.5f;
    const float y = ((float)((c / N) % N) + 0.5f) / (float)N - 0.5f;
    const float z = ((float)(c / (N * N)) + 0.5f) / (float)N - 0.5f;
    dens[c] = x * x + y * y + z * z < 0.25f * 0.25f ? 100.0f : 0.0f;
  }
  fg_occgrid_update_bits(g, 1.0f, threads);

  const int32_t cap = R * max_n;
  float *o = malloc((size_t)R * 12), *d = malloc((size_t)R * 12);
  int32_t *offset = malloc((size_t)R * 4), *count = malloc((size_t)R * 4);
  float *x = malloc((size_t)cap * 12), *dto = malloc((size_t)cap * 4), *to = malloc((size_t)cap * 4);
  const int32_t M = N * N * N / 4;
  int32_t *cells = malloc((size_t)M * 4);
  float *px = malloc((size_t)M * 12), *sigma = malloc((size_t)M * 4);
  if (!o || !d || !offset || !count || !x || !dto || !to || !cells || !px || !sigma) {
    fprintf(stderr, "bench_occupancy: out of memory\n");
    return 1;
  }
  make_rays(n_cams, side, o, d);

  int32_t lattice = 0, S = 0;
  if (fg_occgrid_march(full, R, o, d, dt, max_n, 1, 0, cap, offset, count, x, dto, to,
                       &lattice, threads) < 0)
    return 1;
  double best = 1e30, best_ref = 1e30, best_pts = 1e30, best_dens = 1e30;
  for (int rep = 0; rep <= 10; rep++) { /* rep 0 warms up */
    double t0 = now_s();
    if (fg_occgrid_march(g, R, o, d, dt, max_n, 1, rep, cap, offset, count, x, dto, to, &S,
                         threads) < 0)
      return 1;
    double t1 = now_s();
    if (rep > 0 && t1 - t0 < best) best = t1 - t0;
  }
  for (int rep = 0; rep <= 2; rep++) {
    int32_t S_ref = 0;
    double t0 = now_s();
    if (fg_occgrid_march_ref(g, R, o, d, dt, max_n, 1, rep, cap, offset, count, x, dto, to,
                             &S_ref) < 0)
      return 1;
    double t1 = now_s();
    if (rep > 0 && t1 - t0 < best_ref) best_ref = t1 - t0;
  }
  for (int rep = 0; rep <= 5; rep++) {
    int32_t m = 0;
    double t0 = now_s();
    if (fg_occgrid_update_points(g, 1000 + rep, 1, FG_OCCGRID_DEFAULT_WARMUP_STEPS, 0, cells, px,
                                 M, &m, threads) < 0)
      return 1;
    double t1 = now_s();
    for (int32_t i = 0; i < m; i++) sigma[i] = dens[cells[i]]; /* the same ball */
    double t2 = now_s();
    if (fg_occgrid_update_density(g, cells, sigma, m, FG_OCCGRID_DEFAULT_DECAY, 1.0f,
                                  threads) < 0)
      return 1;
    double t3 = now_s();
    if (rep > 0 && t1 - t0 < best_pts) best_pts = t1 - t0;
    if (rep > 0 && t3 - t2 < best_dens) best_dens = t3 - t2;
  }
  printf("bench=occupancy rays=%d threads=%d N=%d samples=%d lattice_steps=%d "
         "skipped_frac=%.4f rays_per_s=%.4g samples_per_s=%.4g march_ms=%.3f ref_ms=%.3f "
         "update_points_ms=%.3f update_density_ms=%.3f\n",
         (int)R, threads, (int)N, (int)S, (int)lattice, 1.0 - (double)S / (double)lattice,
         (double)R / best, (double)S / best, 1e3 * best, 1e3 * best_ref, 1e3 * best_pts,
         1e3 * best_dens);
  void *ps[] = {o, d, offset, count, x, dto, to, cells, px, sigma};
  for (size_t i = 0; i < sizeof ps / sizeof ps[0]; i++) free(ps[i]);
  fg_occgrid_free(g);
  fg_occgrid_free(full);
  return 0;
}
