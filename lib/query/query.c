/* Voxel grids over the workspace and resolved queries: the score rule of SPEC.md "A query"
 * (grid.h, query.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <omp.h>

#include "core/error.h"
#include "core/threads.h"
#include "field/model.h"
#include "query/grid.h"
#include "query/query.h"
#include "query/internal.h"

const char *const fg_query_default_negatives[FG_QUERY_N_DEFAULT_NEGATIVES] = {
    "object", "things", "stuff", "texture"};

/* ---- voxel grid ----------------------------------------------------------------------- */

int fg_voxel_grid_init(fg_voxel_grid *g, const double ws_min[3], const double ws_max[3],
                       double voxel_size) {
  if (!g || !ws_min || !ws_max) return fg_fail(FG_EINVAL, "voxel grid: NULL argument");
  if (!isfinite(voxel_size) || !(voxel_size > 0.0))
    return fg_fail(FG_EINVAL, "voxel_size must be a positive number of metres, got %g",
                   voxel_size);
  int n[3];
  double total = 1.0;
  for (int a = 0; a < 3; a++) {
    if (!isfinite(ws_min[a]) || !isfinite(ws_max[a]) || !(ws_max[a] > ws_min[a]))
      return fg_fail(FG_EINVAL,
                     "workspace axis %c: max (%g) must be finite and greater than min (%g)",
                     "xyz"[a], ws_max[a], ws_min[a]);
    double cells = ceil((ws_max[a] - ws_min[a]) / voxel_size - 1e-9);
    if (cells < 1.0) cells = 1.0;
    total *= cells;
    if (cells > (double)FG_QUERY_MAX_VOXELS || total > (double)FG_QUERY_MAX_VOXELS)
      return fg_fail(FG_ERANGE,
                     "a voxel grid of %g m over this workspace has more than %zu voxels "
                     "(256^3); use a larger voxel_size",
                     voxel_size, FG_QUERY_MAX_VOXELS);
    n[a] = (int)cells;
  }
  memset(g, 0, sizeof *g);
  for (int a = 0; a < 3; a++) {
    g->min[a] = ws_min[a];
    g->max[a] = ws_max[a];
  }
  g->voxel_size = voxel_size;
  g->nx = n[0];
  g->ny = n[1];
  g->nz = n[2];
  return 0;
}

size_t fg_voxel_grid_count(const fg_voxel_grid *g) {
  return (size_t)g->nx * (size_t)g->ny * (size_t)g->nz;
}

void fg_voxel_grid_centre(const fg_voxel_grid *g, int ix, int iy, int iz, double p_world[3]) {
  p_world[0] = g->min[0] + (ix + 0.5) * g->voxel_size;
  p_world[1] = g->min[1] + (iy + 0.5) * g->voxel_size;
  p_world[2] = g->min[2] + (iz + 0.5) * g->voxel_size;
}

/* Centres of flat indices [i0, i0 + n) as float into p_world (n, 3). */
void fg_query_grid_centres_range(const fg_voxel_grid *g, size_t i0, size_t n, float *p_world) {
  const size_t nx = (size_t)g->nx, ny = (size_t)g->ny;
  for (size_t k = 0; k < n; k++) {
    size_t i = i0 + k;
    int ix = (int)(i % nx), iy = (int)((i / nx) % ny), iz = (int)(i / (nx * ny));
    double p[3];
    fg_voxel_grid_centre(g, ix, iy, iz, p);
    p_world[3 * k + 0] = (float)p[0];
    p_world[3 * k + 1] = (float)p[1];
    p_world[3 * k + 2] = (float)p[2];
  }
}

void fg_voxel_grid_centres(const fg_voxel_grid *g, float *p_world) {
  fg_query_grid_centres_range(g, 0, fg_voxel_grid_count(g), p_world);
}

/* ---- resolved queries ----------------------------------------------------------------- */

/* Euclidean length of v (D) in double; NaN when a value is not finite. */
static double norm_d(const float *v, int D) {
  double s = 0.0;
  for (int i = 0; i < D; i++) {
    if (!isfinite(v[i])) return NAN;
    s += (double)v[i] * v[i];
  }
  return sqrt(s);
}

int fg_query_init(fg_query *q, int dim, const float *pos, int n_pos, const float *neg, int n_neg,
                  float temperature) {
  if (!q) return fg_fail(FG_EINVAL, "query: NULL output");
  memset(q, 0, sizeof *q);
  if (dim < 1 || dim > FG_FIELD_MAX_FEATURE_DIM)
    return fg_fail(FG_EINVAL, "query: embedding dimension %d is outside 1..%d", dim,
                   FG_FIELD_MAX_FEATURE_DIM);
  if (n_pos < 1 || !pos) return fg_fail(FG_EINVAL, "query: at least one positive embedding");
  if (n_neg < 0 || n_neg > FG_QUERY_MAX_NEGATIVES || (n_neg > 0 && !neg))
    return fg_fail(FG_EINVAL, "query: %d negatives; give 0..%d", n_neg, FG_QUERY_MAX_NEGATIVES);
  if (!isfinite(temperature) || !(temperature > 0.0f))
    return fg_fail(FG_EINVAL, "query: temperature must be a positive number, got %g",
                   (double)temperature);
  double *acc = calloc((size_t)dim, sizeof *acc);
  q->q = malloc((size_t)dim * sizeof *q->q);
  q->neg = n_neg > 0 ? malloc((size_t)n_neg * dim * sizeof *q->neg) : NULL;
  int rc = 0;
  if (!acc || !q->q || (n_neg > 0 && !q->neg)) {
    rc = fg_fail(FG_ENOMEM, "query: out of memory");
    goto error;
  }
  for (int p = 0; p < n_pos; p++) {
    const float *v = pos + (size_t)p * dim;
    double len = norm_d(v, dim);
    if (!isfinite(len) || len <= 0.0) {
      rc = fg_fail(FG_EINVAL, "query: positive embedding %d is %s", p,
                   isfinite(len) ? "all zeros" : "not finite");
      goto error;
    }
    for (int i = 0; i < dim; i++) acc[i] += v[i] / len;
  }
  double len = 0.0;
  for (int i = 0; i < dim; i++) len += acc[i] * acc[i];
  len = sqrt(len);
  if (!(len > 1e-6 * n_pos)) {
    rc = fg_fail(FG_EINVAL, "query: the positive embeddings cancel out (their mean is zero)");
    goto error;
  }
  for (int i = 0; i < dim; i++) q->q[i] = (float)(acc[i] / len);
  for (int n = 0; n < n_neg; n++) {
    const float *v = neg + (size_t)n * dim;
    double l = norm_d(v, dim);
    if (!isfinite(l) || l <= 0.0) {
      rc = fg_fail(FG_EINVAL, "query: negative embedding %d is %s", n,
                   isfinite(l) ? "all zeros" : "not finite");
      goto error;
    }
    for (int i = 0; i < dim; i++) q->neg[(size_t)n * dim + i] = (float)(v[i] / l);
  }
  free(acc);
  q->dim = dim;
  q->n_neg = n_neg;
  q->temperature = temperature;
  return 0;
error:
  free(acc);
  fg_query_release(q);
  return rc;
}

void fg_query_release(fg_query *q) {
  if (!q) return;
  free(q->q);
  free(q->neg);
  memset(q, 0, sizeof *q);
}

/* 0 when v (D) is finite and of unit length within 1e-3, else FG_EINVAL naming what. */
static int check_unit(const float *v, int D, const char *what, int k) {
  double len = norm_d(v, D);
  if (!isfinite(len) || fabs(len - 1.0) > 1e-3)
    return fg_fail(FG_EINVAL, "query: %s %d must be a finite unit vector (length %g)", what, k,
                   len);
  return 0;
}

int fg_query_check(const fg_query *q) {
  if (!q || !q->q) return fg_fail(FG_EINVAL, "query: NULL or unresolved query");
  if (q->dim < 1 || q->dim > FG_FIELD_MAX_FEATURE_DIM)
    return fg_fail(FG_EINVAL, "query: dimension %d is outside 1..%d", q->dim,
                   FG_FIELD_MAX_FEATURE_DIM);
  if (q->n_neg < 0 || q->n_neg > FG_QUERY_MAX_NEGATIVES || (q->n_neg > 0 && !q->neg))
    return fg_fail(FG_EINVAL, "query: %d negatives; 0..%d allowed", q->n_neg,
                   FG_QUERY_MAX_NEGATIVES);
  if (q->n_neg > 0 && (!isfinite(q->temperature) || !(q->temperature > 0.0f)))
    return fg_fail(FG_EINVAL, "query: temperature must be a positive number, got %g",
                   (double)q->temperature);
  FG_TRY(check_unit(q->q, q->dim, "positive", 0));
  for (int n = 0; n < q->n_neg; n++)
    FG_TRY(check_unit(q->neg + (size_t)n * q->dim, q->dim, "negative", n));
  return 0;
}

double fg_query_score_ref(const fg_query *q, const float *f) {
  const int D = q->dim;
  double len = norm_d(f, D);
  if (!isfinite(len) || len <= 0.0) return NAN;
  double cq = 0.0;
  for (int i = 0; i < D; i++) cq += (double)f[i] * q->q[i];
  cq /= len;
  if (q->n_neg == 0) return cq;
  double best = INFINITY;
  for (int n = 0; n < q->n_neg; n++) {
    const float *v = q->neg + (size_t)n * D;
    double cn = 0.0;
    for (int i = 0; i < D; i++) cn += (double)f[i] * v[i];
    cn /= len;
    /* softmax([cq, cn] / T)[0] */
    double eq = exp(cq / q->temperature), en = exp(cn / q->temperature);
    double s = eq / (eq + en);
    if (s < best) best = s;
  }
  return best;
}

float fg_query_score_from_cos(const fg_query *q, float cos_q, const float *cos_neg) {
  if (q->n_neg == 0) return cos_q;
  float worst = cos_neg[0];
  for (int n = 1; n < q->n_neg; n++)
    if (cos_neg[n] > worst) worst = cos_neg[n];
  /* min over n of 1 / (1 + exp((cn - cq) / T)) is reached at the largest cn */
  return 1.0f / (1.0f + expf((worst - cos_q) / q->temperature));
}

float fg_query_dot(const float *a, const float *b, int n) {
  float acc[8] = {0};
  int i = 0;
  for (; i + 8 <= n; i += 8)
    for (int k = 0; k < 8; k++) acc[k] += a[i + k] * b[i + k];
  for (; i < n; i++) acc[0] += a[i] * b[i];
  return ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]));
}

int fg_query_score_features(const fg_query *q, const float *feat, int64_t n, int dim,
                            const float *opacity, float min_opacity, float *scores,
                            int n_threads) {
  FG_TRY(fg_query_check(q));
  if (dim != q->dim)
    return fg_fail(FG_EINVAL, "query has %d dimensions but the features have %d", q->dim, dim);
  if (n < 0 || (n > 0 && (!feat || !scores)))
    return fg_fail(FG_EINVAL, "score features: NULL arrays or negative count");
  const int nt = fg_threads(n_threads);
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int64_t i = 0; i < n; i++) {
    const float *f = feat + (size_t)i * dim;
    if (opacity && !(opacity[i] >= min_opacity)) {
      scores[i] = NAN;
      continue;
    }
    float len = sqrtf(fg_query_dot(f, f, dim));
    if (!(len > 0.0f) || !isfinite(len)) {
      scores[i] = NAN;
      continue;
    }
    float inv = 1.0f / len;
    float cq = fg_query_dot(f, q->q, dim) * inv;
    float cn[FG_QUERY_MAX_NEGATIVES];
    for (int k = 0; k < q->n_neg; k++) cn[k] = fg_query_dot(f, q->neg + (size_t)k * dim, dim) * inv;
    scores[i] = fg_query_score_from_cos(q, cq, cn);
  }
  return 0;
}
