/* The grasp field (grasp.h): per-voxel alpha R h vectors, the F3RM samples at query points,
 * and the cost of a pose with its analytic gradient. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <cblas.h>
#include <omp.h>

#include "core/blas.h"
#include "core/error.h"
#include "core/half.h"
#include "core/pose.h"
#include "core/rng.h"
#include "core/threads.h"
#include "grasp/grasp.h"
#include "grasp/internal.h"

#define H FG_GRASP_HIDDEN
#define BUILD_CHUNK 4096 /* kept voxels per SGEMM */

/* ---------------------------------------------------------------- query points */

int fg_grasp_query_points(int n, const double mean_m[3], double std_m, float *p_gripper) {
  if (!mean_m || !p_gripper) return fg_fail(FG_EINVAL, "query points: NULL argument");
  if (n < 1 || n > FG_GRASP_MAX_QUERY_POINTS)
    return fg_fail(FG_EINVAL, "query_points.n must be in 1..%d, got %d",
                   FG_GRASP_MAX_QUERY_POINTS, n);
  if (!isfinite(std_m) || std_m <= 0 || std_m > 1.0)
    return fg_fail(FG_EINVAL, "query_points.std must be a length in metres in (0, 1], got %g",
                   std_m);
  for (int a = 0; a < 3; a++)
    if (!isfinite(mean_m[a]) || fabs(mean_m[a]) > 1.0)
      return fg_fail(FG_EINVAL, "query_points.mean must be 3 finite values within 1 m of the "
                     "TCP (metres, gripper frame)");
  /* Box-Muller on pairs of counter-based uniforms: draws 2k and 2k + 1 give normals 2k and
   * 2k + 1, so point i uses normals 3i .. 3i + 2. */
  for (int i = 0; i < 3 * n; i++) {
    const uint64_t pair = (uint64_t)i / 2;
    const double u1 = 1.0 - fg_rng_uniform(FG_GRASP_QUERY_SEED, 2 * pair); /* (0, 1] */
    const double u2 = fg_rng_uniform(FG_GRASP_QUERY_SEED, 2 * pair + 1);
    const double r = sqrt(-2.0 * log(u1));
    const double g = (i % 2 == 0) ? r * cos(2 * M_PI * u2) : r * sin(2 * M_PI * u2);
    p_gripper[i] = (float)(mean_m[i % 3] + std_m * g);
  }
  return 0;
}

/* The radical inverse of k in base b: k's digits mirrored behind the point. */
static double radical_inverse(uint64_t k, unsigned b) {
  double r = 0.0, f = 1.0 / b;
  for (; k; k /= b, f /= b) r += f * (double)(k % b);
  return r;
}

int fg_grasp_query_points_box(int n, const double mean_m[3], const double size_m[3],
                              float *p_gripper) {
  if (!mean_m || !size_m || !p_gripper) return fg_fail(FG_EINVAL, "query points: NULL argument");
  if (n < 1 || n > FG_GRASP_MAX_QUERY_POINTS)
    return fg_fail(FG_EINVAL, "query_points.n must be in 1..%d, got %d",
                   FG_GRASP_MAX_QUERY_POINTS, n);
  for (int a = 0; a < 3; a++) {
    if (!isfinite(size_m[a]) || size_m[a] <= 0 || size_m[a] > 1.0)
      return fg_fail(FG_EINVAL, "query_points.size must be 3 lengths in metres in (0, 1], got "
                     "[%g, %g, %g]", size_m[0], size_m[1], size_m[2]);
    if (!isfinite(mean_m[a]) || fabs(mean_m[a]) > 1.0)
      return fg_fail(FG_EINVAL, "query_points.mean must be 3 finite values within 1 m of the "
                     "TCP (metres, gripper frame)");
  }
  static const unsigned base[3] = {2, 3, 5};
  for (int i = 0; i < n; i++)
    for (int a = 0; a < 3; a++)
      p_gripper[3 * i + a] =
          (float)(mean_m[a] + size_m[a] * (radical_inverse((uint64_t)i + 1, base[a]) - 0.5));
  return 0;
}

int fg_grasp_query_points_layout(fg_grasp_qp_layout layout, int n, const double mean_m[3],
                                 double std_m, const double size_m[3], float *p_gripper) {
  return layout == FG_GRASP_QP_BOX ? fg_grasp_query_points_box(n, mean_m, size_m, p_gripper)
                                   : fg_grasp_query_points(n, mean_m, std_m, p_gripper);
}

int fg_grasp_query_box_default(fg_gripper_model m, double width_m, double mean_m[3],
                               double size_m[3]) {
  fg_gripper_box b[FG_GRIPPER_N_BOXES];
  FG_TRY(fg_gripper_boxes(m, width_m, b));
  if (!(width_m > 0))
    return fg_fail(FG_EINVAL, "the query points' default box needs a width above 0, got %g m",
                   width_m);
  const fg_gripper_box *pad = &b[FG_GRIPPER_BOX_PAD_PLUS_Y];
  mean_m[0] = 0.0;
  mean_m[1] = 0.0;
  mean_m[2] = pad->centre_m[2];
  size_m[0] = 2.0 * pad->half_m[0];
  size_m[1] = width_m;
  size_m[2] = 2.0 * pad->half_m[2];
  return 0;
}

/* ---------------------------------------------------------------- building */

/* W (D, 64) = Q R by modified Gram-Schmidt, applied twice for orthogonality, in double.
 * Q (D, 64) is stored column-major by column j at Q + j * D; a column that W does not span
 * (a rank-deficient head) is left zero with R_jj = 0. R (64, 64) upper triangular, row-major. */
static void qr64(const float *W, int D, double *Q, double *R) {
  memset(R, 0, (size_t)H * H * sizeof *R);
  for (int j = 0; j < H; j++) {
    double *q = Q + (size_t)j * D;
    for (int d = 0; d < D; d++) q[d] = W[(size_t)d * H + j];
    double norm0 = 0.0;
    for (int d = 0; d < D; d++) norm0 += q[d] * q[d];
    for (int pass = 0; pass < 2; pass++)
      for (int k = 0; k < j; k++) {
        const double *qk = Q + (size_t)k * D;
        double s = 0.0;
        for (int d = 0; d < D; d++) s += qk[d] * q[d];
        R[k * H + j] += s;
        for (int d = 0; d < D; d++) q[d] -= s * qk[d];
      }
    double norm = 0.0;
    for (int d = 0; d < D; d++) norm += q[d] * q[d];
    norm = sqrt(norm);
    if (norm <= 1e-10 * sqrt(norm0) || norm == 0.0) {
      memset(q, 0, (size_t)D * sizeof *q);
      R[j * H + j] = 0.0;
      continue;
    }
    R[j * H + j] = norm;
    for (int d = 0; d < D; d++) q[d] /= norm;
  }
}

int fg_grasp_field_new(fg_grasp_field **out, const fg_voxel_features *vf, int n_threads) {
  if (!out || !vf) return fg_fail(FG_EINVAL, "grasp field: NULL argument");
  *out = NULL;
  const fg_voxel_grid *g = fg_voxel_features_grid(vf);
  const int D = fg_voxel_features_dim(vf);
  const size_t N = fg_voxel_grid_count(g), n_kept = fg_voxel_features_n_kept(vf);
  const float *alpha = fg_voxel_features_alpha(vf);
  const uint32_t *kept;
  const uint16_t *h16;
  const float *W;
  fg_voxel_features_raw(vf, &kept, &h16, &W);

  fg_grasp_field *gf = calloc(1, sizeof *gf);
  double *Qd = malloc((size_t)D * H * sizeof *Qd);
  double *Rd = malloc((size_t)H * H * sizeof *Rd);
  if (!gf || !Qd || !Rd) goto nomem;
  gf->vf = vf;
  gf->grid = *g;
  gf->dim = D;
  gf->alpha = alpha;
  gf->n_vox = N;
  gf->slot = malloc(N * sizeof *gf->slot);
  gf->y = malloc((n_kept > 0 ? n_kept : 1) * H * sizeof *gf->y);
  gf->Q = malloc((size_t)D * H * sizeof *gf->Q);
  if (!gf->slot || !gf->y || !gf->Q) goto nomem;
  qr64(W, D, Qd, Rd);
  for (int j = 0; j < H; j++)
    for (int d = 0; d < D; d++) gf->Q[(size_t)d * H + j] = (float)Qd[(size_t)j * D + d];
  float Rf[H * H];
  for (int k = 0; k < H * H; k++) Rf[k] = (float)Rd[k];
  for (size_t i = 0; i < N; i++) gf->slot[i] = -1;
  for (size_t k = 0; k < n_kept; k++) gf->slot[kept[k]] = (int32_t)k;
  /* y (m, 64) = alpha * (h (m, 64) R^T), one SGEMM per chunk of kept voxels */
  const int nt = fg_threads(n_threads);
  const int64_t n_chunks = (int64_t)((n_kept + BUILD_CHUNK - 1) / BUILD_CHUNK);
  const int blas = fg_blas_single_begin();
  int nomem = 0;
#pragma omp parallel num_threads(nt)
  {
    float *h = malloc((size_t)BUILD_CHUNK * H * sizeof *h);
    if (!h) {
#pragma omp atomic write
      nomem = 1;
    }
#pragma omp for schedule(static)
    for (int64_t b = 0; b < n_chunks; b++) {
      if (!h) continue;
      const size_t k0 = (size_t)b * BUILD_CHUNK;
      const size_t m = n_kept - k0 < BUILD_CHUNK ? n_kept - k0 : BUILD_CHUNK;
      fg_half_to_float_n(h16 + k0 * H, h, m * H);
      float *y = gf->y + k0 * H;
      cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)m, H, H, 1.0f, h, H, Rf, H,
                  0.0f, y, H);
      for (size_t k = 0; k < m; k++) {
        const float a = alpha[kept[k0 + k]];
        for (int j = 0; j < H; j++) y[k * H + j] *= a;
      }
    }
    free(h);
  }
  fg_blas_single_end(blas);
  if (nomem) goto nomem;
  gf->n_kept = n_kept;
  free(Qd);
  free(Rd);
  *out = gf;
  return 0;
nomem:
  free(Qd);
  free(Rd);
  fg_grasp_field_free(gf);
  return fg_fail(FG_ENOMEM, "grasp field: out of memory for %zu voxels", N);
}

void fg_grasp_field_free(fg_grasp_field *gf) {
  if (!gf) return;
  free(gf->slot);
  free(gf->y);
  free(gf->Q);
  free(gf);
}

size_t fg_grasp_field_bytes(const fg_grasp_field *gf) {
  return sizeof *gf + gf->n_vox * sizeof(int32_t) + gf->n_kept * H * sizeof(float) +
         (size_t)gf->dim * H * sizeof(float);
}

/* ---------------------------------------------------------------- trilinear sampling */

static inline int corners_at(const fg_voxel_grid *g, const int32_t *slot, const float x[3],
                             fg_grasp_corner c[8]) {
  const float inv = (float)(1.0 / g->voxel_size);
  const int n[3] = {g->nx, g->ny, g->nz};
  int i0[3];
  float f[3];
  for (int a = 0; a < 3; a++) {
    const float u = (x[a] - (float)g->min[a]) * inv - 0.5f;
    if (!(u > -1.0f && u < (float)n[a])) return 0; /* no corner inside the grid */
    const float fl = floorf(u);
    i0[a] = (int)fl;
    f[a] = u - fl;
  }
  const size_t sx = 1, sy = (size_t)n[0], sz = (size_t)n[0] * (size_t)n[1];
  const int interior = i0[0] >= 0 && i0[0] + 1 < n[0] && i0[1] >= 0 && i0[1] + 1 < n[1] &&
                       i0[2] >= 0 && i0[2] + 1 < n[2];
  const float w0[3] = {1.0f - f[0], 1.0f - f[1], 1.0f - f[2]};
  int m = 0;
  for (int k = 0; k < 8; k++) {
    const int dx = k & 1, dy = (k >> 1) & 1, dz = (k >> 2) & 1;
    if (!interior && (i0[0] + dx < 0 || i0[0] + dx >= n[0] || i0[1] + dy < 0 ||
                      i0[1] + dy >= n[1] || i0[2] + dz < 0 || i0[2] + dz >= n[2]))
      continue;
    const int32_t s = slot[(size_t)(i0[2] + dz) * sz + (size_t)(i0[1] + dy) * sy +
                           (size_t)(i0[0] + dx) * sx];
    if (s < 0) continue;
    const float wx = dx ? f[0] : w0[0], wy = dy ? f[1] : w0[1], wz = dz ? f[2] : w0[2];
    const float gx = dx ? inv : -inv, gy = dy ? inv : -inv, gz = dz ? inv : -inv;
    c[m].slot = s;
    c[m].w = wx * wy * wz;
    c[m].dw[0] = gx * wy * wz;
    c[m].dw[1] = wx * gy * wz;
    c[m].dw[2] = wx * wy * gz;
    m++;
  }
  return m;
}

int fg_grasp_corners(const fg_voxel_grid *g, const int32_t *slot, const float x[3],
                     fg_grasp_corner c[8]) {
  return corners_at(g, slot, x, c);
}

int fg_grasp_sample(const fg_grasp_field *gf, const double T_world_gripper[16],
                    const float *p_gripper, int n, float *z) {
  if (!gf || !T_world_gripper || !p_gripper || !z)
    return fg_fail(FG_EINVAL, "grasp sample: NULL argument");
  if (n < 1 || n > FG_GRASP_MAX_QUERY_POINTS)
    return fg_fail(FG_EINVAL, "grasp sample: n must be in 1..%d", FG_GRASP_MAX_QUERY_POINTS);
  const int D = gf->dim;
  for (int i = 0; i < n; i++) {
    float x[3], u[H] = {0};
    fg_pose_apply_points(T_world_gripper, p_gripper + 3 * i, 1, x);
    fg_grasp_corner c[8];
    const int m = fg_grasp_corners(&gf->grid, gf->slot, x, c);
    for (int k = 0; k < m; k++) {
      const float *y = gf->y + (size_t)c[k].slot * H;
      for (int j = 0; j < H; j++) u[j] += c[k].w * y[j];
    }
    /* alpha f = W u_h = Q (R u_h) = Q u */
    for (int d = 0; d < D; d++) {
      const float *q = gf->Q + (size_t)d * H;
      float s = 0.0f;
      for (int j = 0; j < H; j++) s += q[j] * u[j];
      z[(size_t)i * D + d] = s;
    }
  }
  return 0;
}

/* ---------------------------------------------------------------- cost */

int fg_grasp_prepare(const fg_grasp_field *gf, const fg_grasp_target *t, fg_grasp_prepared *p) {
  memset(p, 0, sizeof *p);
  if (!gf || !t || !t->p_gripper || !t->Z) return fg_fail(FG_EINVAL, "grasp: NULL target");
  if (t->n_points < 1 || t->n_points > FG_GRASP_MAX_QUERY_POINTS)
    return fg_fail(FG_EINVAL, "the task has %d query points; 1..%d are allowed", t->n_points,
                   FG_GRASP_MAX_QUERY_POINTS);
  if (t->dim != gf->dim)
    return fg_fail(FG_EINVAL, "the task's features have D = %d but the scene's have D = %d",
                   t->dim, gf->dim);
  const int n = t->n_points, D = t->dim;
  p->n = n;
  p->p = t->p_gripper;
  p->C = malloc((size_t)n * H * sizeof *p->C);
  if (!p->C) return fg_fail(FG_ENOMEM, "grasp: out of memory");
  double z2 = 0.0;
  for (int i = 0; i < n; i++) {
    const float *Zi = t->Z + (size_t)i * D;
    for (int d = 0; d < D; d++) {
      if (!isfinite(Zi[d])) {
        fg_grasp_prepared_release(p);
        return fg_fail(FG_EINVAL, "the task embedding holds a value that is not finite");
      }
      z2 += (double)Zi[d] * Zi[d];
    }
    for (int j = 0; j < H; j++) {
      double s = 0.0;
      for (int d = 0; d < D; d++) s += (double)gf->Q[(size_t)d * H + j] * Zi[d];
      p->C[i * H + j] = (float)s;
    }
  }
  if (!(z2 > 0.0)) {
    fg_grasp_prepared_release(p);
    return fg_fail(FG_EINVAL, "the task embedding is zero: its demos saw only free space");
  }
  p->z_norm = sqrt(z2);
  if (t->q) {
    for (int j = 0; j < H; j++) {
      double s = 0.0;
      for (int d = 0; d < D; d++) {
        if (!isfinite(t->q[d])) {
          fg_grasp_prepared_release(p);
          return fg_fail(FG_EINVAL, "the language query holds a value that is not finite");
        }
        s += (double)gf->Q[(size_t)d * H + j] * t->q[d];
      }
      p->cq[j] = (float)s;
    }
    p->has_q = 1;
  }
  return 0;
}

void fg_grasp_prepared_release(fg_grasp_prepared *p) {
  free(p->C);
  memset(p, 0, sizeof *p);
}

/* Compiled for AVX-512, AVX2 and the baseline and picked at load time: the 64-wide loops are
 * the whole cost. None of the clones contracts to FMA (ISO C11 mode), but the lane count fixes
 * the order of the sums, so results are identical on one machine, not across processors.
 * GCC only: clang 14 names the resolver of an exported clone "fg_grasp_cost_fast.ifunc", so
 * its callers in search.c would not link (a clang build is the libFuzzer one). */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
double fg_grasp_cost_fast(const fg_grasp_field *gf, const fg_grasp_prepared *p,
                          const double T[16], double d_t[3], double d_w[3], double *cos_out,
                          double *weight_out, fg_grasp_scratch *s) {
  const int n = p->n;
  const int want_grad = d_t || d_w;
  double num = 0.0, den2 = 0.0, wsum = 0.0, nsum = 0.0;
  fg_pose_apply_points(T, p->p, (size_t)n, s->x);
  for (int i = 0; i < n; i++) {
    float *u = s->u + (size_t)i * H;
    fg_grasp_corner *c = s->c + (size_t)i * 8;
    const int m = corners_at(&gf->grid, gf->slot, s->x + 3 * i, c);
    s->m[i] = m;
    if (m == 0) { /* free space: u = 0 adds nothing */
      for (int j = 0; j < H; j++) u[j] = 0.0f;
      s->nrm[i] = 0.0f;
      continue;
    }
    {
      const float *y = gf->y + (size_t)c[0].slot * H;
      const float w = c[0].w;
#pragma omp simd
      for (int j = 0; j < H; j++) u[j] = w * y[j];
    }
    for (int k = 1; k < m; k++) {
      const float *y = gf->y + (size_t)c[k].slot * H;
      const float w = c[k].w;
#pragma omp simd
      for (int j = 0; j < H; j++) u[j] += w * y[j];
    }
    const float *Ci = p->C + (size_t)i * H;
    float a = 0.0f, b = 0.0f, e = 0.0f;
#pragma omp simd reduction(+ : a, b, e)
    for (int j = 0; j < H; j++) {
      a += u[j] * Ci[j];
      b += u[j] * u[j];
      e += u[j] * p->cq[j];
    }
    num += a;
    den2 += b;
    wsum += e;
    s->nrm[i] = sqrtf(b);
    nsum += s->nrm[i];
  }
  const double weight = !p->has_q ? 1.0 : nsum > 1e-30 ? wsum / nsum : 0.0;
  double cosv = 0.0;
  if (den2 > 1e-30) cosv = num / (sqrt(den2) * p->z_norm);
  if (cos_out) *cos_out = cosv;
  if (weight_out) *weight_out = weight;
  const double J = -weight * cosv;
  if (!want_grad) return J;
  double gt[3] = {0, 0, 0}, gw[3] = {0, 0, 0};
  if (den2 > 1e-30) {
    /* dJ/du_i = -weight (C_i - (num / den2) u_i) / (|u| |Z|) - cos dw/du_i with
     * dw/du_i = cq / S - (E / S^2) u_i / |u_i| (E = sum q.z_i, S = sum |z_i|) */
    const float a = (float)(-weight / (sqrt(den2) * p->z_norm));
    const float b = (float)(-(num / den2) * -weight / (sqrt(den2) * p->z_norm));
    const int lang = p->has_q && nsum > 1e-30;
    const float e = lang ? (float)(-cosv / nsum) : 0.0f;
    const double f0 = lang ? cosv * wsum / (nsum * nsum) : 0.0;
    float gu[H];
    for (int i = 0; i < n; i++) {
      const float *u = s->u + (size_t)i * H;
      const float *Ci = p->C + (size_t)i * H;
      const float bi = b + (lang && s->nrm[i] > 0.0f ? (float)(f0 / s->nrm[i]) : 0.0f);
#pragma omp simd
      for (int j = 0; j < H; j++) gu[j] = a * Ci[j] + bi * u[j] + e * p->cq[j];
      const fg_grasp_corner *c = s->c + (size_t)i * 8;
      double gx[3] = {0, 0, 0};
      for (int k = 0; k < s->m[i]; k++) {
        const float *y = gf->y + (size_t)c[k].slot * H;
        float sc = 0.0f;
#pragma omp simd reduction(+ : sc)
        for (int j = 0; j < H; j++) sc += y[j] * gu[j];
        for (int q = 0; q < 3; q++) gx[q] += (double)sc * c[k].dw[q];
      }
      /* x_i = exp([w]) r_i + t with r_i = x_i - t: dJ/dw += r_i x g_x */
      const double r[3] = {s->x[3 * i] - T[3], s->x[3 * i + 1] - T[7], s->x[3 * i + 2] - T[11]};
      gw[0] += r[1] * gx[2] - r[2] * gx[1];
      gw[1] += r[2] * gx[0] - r[0] * gx[2];
      gw[2] += r[0] * gx[1] - r[1] * gx[0];
      for (int q = 0; q < 3; q++) gt[q] += gx[q];
    }
  }
  if (d_t) memcpy(d_t, gt, sizeof gt);
  if (d_w) memcpy(d_w, gw, sizeof gw);
  return J;
}

int fg_grasp_scratch_init(fg_grasp_scratch *s, int n) {
  s->x = malloc((size_t)n * 3 * sizeof *s->x);
  s->u = malloc((size_t)n * H * sizeof *s->u);
  s->c = malloc((size_t)n * 8 * sizeof *s->c);
  s->m = malloc((size_t)n * sizeof *s->m);
  s->nrm = malloc((size_t)n * sizeof *s->nrm);
  if (s->x && s->u && s->c && s->m && s->nrm) return 0;
  fg_grasp_scratch_release(s);
  return fg_fail(FG_ENOMEM, "grasp: out of memory");
}

void fg_grasp_scratch_release(fg_grasp_scratch *s) {
  free(s->x);
  free(s->u);
  free(s->c);
  free(s->m);
  free(s->nrm);
  memset(s, 0, sizeof *s);
}

double fg_grasp_cost(const fg_grasp_field *gf, const fg_grasp_target *t,
                     const double T_world_gripper[16], double d_t[3], double d_w[3],
                     double *cos_out, double *weight_out) {
  fg_grasp_prepared p;
  fg_grasp_scratch s = {0};
  if (fg_grasp_prepare(gf, t, &p) < 0) return NAN;
  double J = NAN;
  if (fg_grasp_scratch_init(&s, t->n_points) == 0)
    J = fg_grasp_cost_fast(gf, &p, T_world_gripper, d_t, d_w, cos_out, weight_out, &s);
  fg_grasp_scratch_release(&s);
  fg_grasp_prepared_release(&p);
  return J;
}

double fg_grasp_task_similarity(const float *Z, int n_points, int dim, const float *q) {
  if (!Z || !q || n_points < 1 || dim < 1) return NAN;
  double dot = 0.0, mm = 0.0, qq = 0.0;
  for (int d = 0; d < dim; d++) {
    double m = 0.0;
    for (int i = 0; i < n_points; i++) m += Z[(size_t)i * dim + d];
    m /= n_points;
    dot += m * q[d];
    mm += m * m;
    qq += (double)q[d] * q[d];
  }
  if (!(mm > 0.0) || !(qq > 0.0) || !isfinite(dot)) return NAN;
  return dot / sqrt(mm * qq);
}

/* ---------------------------------------------------------------- reference */

double fg_grasp_cost_ref(const fg_voxel_features *vf, const fg_grasp_target *t,
                         const double T[16]) {
  const fg_voxel_grid *g = fg_voxel_features_grid(vf);
  const int D = fg_voxel_features_dim(vf);
  if (!t || t->dim != D) return NAN;
  const float *alpha = fg_voxel_features_alpha(vf);
  double *z = calloc((size_t)D, sizeof *z);
  float *f = malloc((size_t)D * sizeof *f);
  if (!z || !f) {
    free(z);
    free(f);
    return NAN;
  }
  double num = 0.0, den2 = 0.0, z2 = 0.0, wsum = 0.0, nsum = 0.0;
  const int n[3] = {g->nx, g->ny, g->nz};
  for (int i = 0; i < t->n_points; i++) {
    const float *p = t->p_gripper + 3 * i;
    double x[3];
    for (int a = 0; a < 3; a++)
      x[a] = T[4 * a] * p[0] + T[4 * a + 1] * p[1] + T[4 * a + 2] * p[2] + T[4 * a + 3];
    memset(z, 0, (size_t)D * sizeof *z);
    double uu[3];
    int i0[3], inside = 1;
    for (int a = 0; a < 3; a++) {
      uu[a] = (x[a] - g->min[a]) / g->voxel_size - 0.5;
      i0[a] = (int)floor(uu[a]);
    }
    for (int k = 0; k < 8 && inside; k++) {
      const int d[3] = {k & 1, (k >> 1) & 1, (k >> 2) & 1};
      int idx[3], ok = 1;
      double w = 1.0;
      for (int a = 0; a < 3; a++) {
        idx[a] = i0[a] + d[a];
        if (idx[a] < 0 || idx[a] >= n[a]) ok = 0;
        const double fr = uu[a] - i0[a];
        w *= d[a] ? fr : 1.0 - fr;
      }
      if (!ok) continue;
      const size_t flat =
          ((size_t)idx[2] * (size_t)g->ny + (size_t)idx[1]) * (size_t)g->nx + (size_t)idx[0];
      if (fg_voxel_features_feature(vf, flat, f) < 0) continue; /* keeps no features */
      for (int dd = 0; dd < D; dd++) z[dd] += w * alpha[flat] * f[dd];
    }
    const float *Zi = t->Z + (size_t)i * D;
    double zz = 0.0;
    for (int dd = 0; dd < D; dd++) {
      num += z[dd] * Zi[dd];
      zz += z[dd] * z[dd];
      z2 += (double)Zi[dd] * Zi[dd];
      if (t->q) wsum += z[dd] * t->q[dd];
    }
    den2 += zz;
    nsum += sqrt(zz);
  }
  free(z);
  free(f);
  const double cosv = den2 > 1e-30 ? num / (sqrt(den2) * sqrt(z2)) : 0.0;
  const double weight = !t->q ? 1.0 : nsum > 1e-30 ? wsum / nsum : 0.0;
  return -weight * cosv;
}
