/* The voxel feature cache (voxfeat.h): the trained field sampled once on the workspace grid,
 * kept as float16 hidden vectors so that every heatmap is a 64-d dot per voxel. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <cblas.h>
#include <zlib.h>
#include <omp.h>

#include "core/error.h"
#include "core/clock.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "core/threads.h"
#include "field/model.h"
#include "query/voxfeat.h"
#include "query/internal.h"

#define H FG_FIELD_FEATURE_HIDDEN
#define BUILD_CHUNK 32768 /* points per field evaluation */
#define SCORE_BLOCK 256   /* kept voxels converted from float16 at a time */

struct fg_voxel_features {
  fg_voxel_grid grid;
  int dim;                 /* D */
  int64_t trained_steps;   /* the field's trained_steps when built */
  double build_seconds;
  size_t n_vox, n_kept;
  float *alpha;            /* (n_vox) */
  uint32_t *kept;          /* (n_kept) flat indices, ascending */
  uint16_t *h16;           /* (n_kept, 64) float16 hidden vectors */
  float *inv_norm;         /* (n_kept) 1 / |W_out h|; NaN for a zero feature */
  float *W;                /* (D, 64) copy of W_out */
};

void fg_voxel_features_free(fg_voxel_features *vf) {
  if (!vf) return;
  free(vf->alpha);
  free(vf->kept);
  free(vf->h16);
  free(vf->inv_norm);
  free(vf->W);
  free(vf);
}

/* G (64, 64) = W^T W of W (D, 64), in double and rounded once. */
static void gram(const float *W, int D, float *G) {
  for (int a = 0; a < H; a++)
    for (int b = a; b < H; b++) {
      double s = 0.0;
      for (int d = 0; d < D; d++) s += (double)W[(size_t)d * H + a] * W[(size_t)d * H + b];
      G[a * H + b] = G[b * H + a] = (float)s;
    }
}

/* Appends the voxels of flat indices [i0, i0 + n) whose alpha (already in vf->alpha) reaches
 * the floor to the kept arrays at *nk: h from hid (n, 64), which is compacted in place; hg
 * (n, 64) is scratch; G = W^T W. */
static void keep_chunk(fg_voxel_features *vf, const float *G, size_t i0, size_t n, float *hid,
                       float *hg, size_t *nk) {
  size_t m = 0; /* compact the kept voxels of this chunk to the front of hid, as float16 */
  for (size_t k = 0; k < n; k++) {
    if (!(vf->alpha[i0 + k] >= FG_QUERY_ALPHA_FLOOR)) continue;
    vf->kept[*nk + m] = (uint32_t)(i0 + k);
    fg_float_to_half_n(hid + k * H, vf->h16 + (*nk + m) * H, H);
    fg_half_to_float_n(vf->h16 + (*nk + m) * H, hid + m * H, H); /* the stored h */
    m++;
  }
  if (m > 0) { /* |W h|^2 = h^T G h for the stored h */
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)m, H, H, 1.0f, hid, H, G, H,
                0.0f, hg, H);
    for (size_t k = 0; k < m; k++) {
      double s = 0.0;
      for (int j = 0; j < H; j++) s += (double)hid[k * H + j] * hg[k * H + j];
      vf->inv_norm[*nk + k] = s > 1e-30 ? (float)(1.0 / sqrt(s)) : NAN;
    }
  }
  *nk += m;
}

/* Sets the kept count and gives back what the empty voxels did not use. */
static void finish_kept(fg_voxel_features *vf, size_t nk) {
  vf->n_kept = nk;
  if (nk < vf->n_vox) {
    size_t keep = nk > 0 ? nk : 1;
    uint32_t *k2 = realloc(vf->kept, keep * sizeof *k2);
    uint16_t *h2 = realloc(vf->h16, keep * H * sizeof *h2);
    float *i2 = realloc(vf->inv_norm, keep * sizeof *i2);
    if (k2) vf->kept = k2;
    if (h2) vf->h16 = h2;
    if (i2) vf->inv_norm = i2;
  }
}

/* A cache of D = dim for grid g with every array allocated for all N voxels (kept ones too),
 * W copied and G = W^T W; NULL when out of memory. */
static fg_voxel_features *cache_alloc(const fg_voxel_grid *g, int dim, const float *W, float *G) {
  const size_t N = fg_voxel_grid_count(g);
  fg_voxel_features *vf = calloc(1, sizeof *vf);
  if (!vf) return NULL;
  vf->grid = *g;
  vf->dim = dim;
  vf->n_vox = N;
  vf->alpha = malloc(N * sizeof *vf->alpha);
  vf->kept = malloc(N * sizeof *vf->kept);
  vf->h16 = malloc(N * H * sizeof *vf->h16);
  vf->inv_norm = malloc(N * sizeof *vf->inv_norm);
  vf->W = malloc((size_t)dim * H * sizeof *vf->W);
  if (!vf->alpha || !vf->kept || !vf->h16 || !vf->inv_norm || !vf->W) {
    fg_voxel_features_free(vf);
    return NULL;
  }
  memcpy(vf->W, W, (size_t)dim * H * sizeof(float));
  gram(vf->W, dim, G);
  return vf;
}

int fg_voxel_features_from_arrays(fg_voxel_features **out, const fg_voxel_grid *g, int dim,
                                  const float *alpha, const float *h, const float *W) {
  if (!out || !g || !alpha || !W) return fg_fail(FG_EINVAL, "voxel features: NULL argument");
  *out = NULL;
  if (dim < 1 || dim > FG_FIELD_MAX_FEATURE_DIM)
    return fg_fail(FG_EINVAL, "voxel features: D must be in 1..%d, got %d",
                   FG_FIELD_MAX_FEATURE_DIM, dim);
  {
    fg_voxel_grid chk;
    FG_TRY(fg_voxel_grid_init(&chk, g->min, g->max, g->voxel_size));
    if (chk.nx != g->nx || chk.ny != g->ny || chk.nz != g->nz)
      return fg_fail(FG_EINVAL, "voxel features: the grid's sizes do not match its workspace");
  }
  const size_t N = fg_voxel_grid_count(g);
  for (size_t i = 0; i < N; i++) {
    if (!(alpha[i] >= 0.0f && alpha[i] <= 1.0f))
      return fg_fail(FG_EINVAL, "voxel features: alpha[%zu] = %g is not in [0, 1]", i,
                     (double)alpha[i]);
    if (alpha[i] >= FG_QUERY_ALPHA_FLOOR && !h)
      return fg_fail(FG_EINVAL, "voxel features: occupied voxels need hidden vectors");
  }
  float G[H * H];
  fg_voxel_features *vf = cache_alloc(g, dim, W, G);
  float *hid = malloc((size_t)BUILD_CHUNK * H * sizeof *hid);
  float *hg = malloc((size_t)BUILD_CHUNK * H * sizeof *hg);
  if (!vf || !hid || !hg) {
    fg_voxel_features_free(vf);
    free(hid);
    free(hg);
    return fg_fail(FG_ENOMEM, "voxel features: out of memory for %zu voxels", N);
  }
  memcpy(vf->alpha, alpha, N * sizeof *alpha);
  size_t nk = 0;
  for (size_t i0 = 0; i0 < N; i0 += BUILD_CHUNK) {
    const size_t n = N - i0 < BUILD_CHUNK ? N - i0 : BUILD_CHUNK;
    if (h)
      memcpy(hid, h + i0 * H, n * H * sizeof *hid);
    keep_chunk(vf, G, i0, n, hid, hg, &nk);
  }
  finish_kept(vf, nk);
  free(hid);
  free(hg);
  *out = vf;
  return 0;
}

int fg_voxel_features_build(fg_voxel_features **out, const fg_field *f, const fg_voxel_grid *g,
                            int n_threads) {
  if (!out || !f || !g) return fg_fail(FG_EINVAL, "voxel features: NULL argument");
  *out = NULL;
  if (f->cfg.feature_dim <= 0)
    return fg_fail(FG_EINVAL, "the field has no feature branch (its frames had no features)");
  {
    fg_voxel_grid chk;
    FG_TRY(fg_voxel_grid_init(&chk, g->min, g->max, g->voxel_size));
    if (chk.nx != g->nx || chk.ny != g->ny || chk.nz != g->nz)
      return fg_fail(FG_EINVAL, "voxel features: the grid's sizes do not match its workspace");
  }
  const double t0 = fg_mono_s();
  const int D = f->cfg.feature_dim;
  const size_t N = fg_voxel_grid_count(g);
  float G[H * H];
  fg_voxel_features *vf = cache_alloc(g, D, fg_field_group_const(f, FG_FIELD_FEAT_OUT, NULL), G);
  float *x = malloc((size_t)BUILD_CHUNK * 3 * sizeof *x);
  float *sigma = malloc((size_t)BUILD_CHUNK * sizeof *sigma);
  float *hid = malloc((size_t)BUILD_CHUNK * H * sizeof *hid);
  float *hg = malloc((size_t)BUILD_CHUNK * H * sizeof *hg);
  int rc = 0;
  if (!vf || !x || !sigma || !hid || !hg) goto nomem;
  vf->trained_steps = f->trained_steps;

  size_t nk = 0;
  for (size_t i0 = 0; i0 < N; i0 += BUILD_CHUNK) {
    const size_t n = N - i0 < BUILD_CHUNK ? N - i0 : BUILD_CHUNK;
    rc = fg_query_voxel_sample(f, g, i0, n, vf->alpha + i0, n_threads);
    if (rc < 0) goto error;
    /* features only where they are kept, at the voxel centres; then each row moves to its
     * voxel's place in hid (rows only move down, so from the last one) */
    size_t m = 0;
    for (size_t k = 0; k < n; k++)
      if (vf->alpha[i0 + k] >= FG_QUERY_ALPHA_FLOOR)
        fg_query_grid_centres_range(g, i0 + k, 1, x + 3 * m++);
    if (m) rc = fg_field_features(f, x, (int64_t)m, sigma, hid, NULL, n_threads);
    if (rc < 0) goto error;
    for (size_t k = n; m > 0 && k-- > 0;)
      if (vf->alpha[i0 + k] >= FG_QUERY_ALPHA_FLOOR && --m != k)
        memcpy(hid + k * H, hid + m * H, H * sizeof *hid);
    keep_chunk(vf, G, i0, n, hid, hg, &nk);
  }
  finish_kept(vf, nk);
  free(x);
  free(sigma);
  free(hid);
  free(hg);
  vf->build_seconds = fg_mono_s() - t0;
  *out = vf;
  return 0;
nomem:
  rc = fg_fail(FG_ENOMEM, "voxel features: out of memory for %zu voxels", N);
error:
  free(x);
  free(sigma);
  free(hid);
  free(hg);
  fg_voxel_features_free(vf);
  return rc;
}

const fg_voxel_grid *fg_voxel_features_grid(const fg_voxel_features *vf) { return &vf->grid; }
int fg_voxel_features_dim(const fg_voxel_features *vf) { return vf->dim; }
const float *fg_voxel_features_alpha(const fg_voxel_features *vf) { return vf->alpha; }
size_t fg_voxel_features_n_kept(const fg_voxel_features *vf) { return vf->n_kept; }
int64_t fg_voxel_features_trained_steps(const fg_voxel_features *vf) {
  return vf->trained_steps;
}
double fg_voxel_features_build_seconds(const fg_voxel_features *vf) {
  return vf->build_seconds;
}

size_t fg_voxel_features_bytes(const fg_voxel_features *vf) {
  size_t kept = vf->n_kept > 0 ? vf->n_kept : 1;
  return sizeof *vf + vf->n_vox * sizeof(float) + kept * (sizeof(uint32_t) + H * 2 + 4) +
         (size_t)vf->dim * H * sizeof(float);
}

void fg_voxel_features_raw(const fg_voxel_features *vf, const uint32_t **kept,
                           const uint16_t **h16, const float **W) {
  if (kept) *kept = vf->kept;
  if (h16) *h16 = vf->h16;
  if (W) *W = vf->W;
}

/* Slot of flat index idx among the kept voxels, or -1. */
static int64_t kept_slot(const fg_voxel_features *vf, size_t idx) {
  size_t lo = 0, hi = vf->n_kept;
  while (lo < hi) {
    size_t mid = lo + (hi - lo) / 2;
    if (vf->kept[mid] < idx)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo < vf->n_kept && vf->kept[lo] == idx ? (int64_t)lo : -1;
}

int fg_voxel_features_feature(const fg_voxel_features *vf, size_t idx, float *feat) {
  if (!vf || !feat) return fg_fail(FG_EINVAL, "voxel feature: NULL argument");
  if (idx >= vf->n_vox)
    return fg_fail(FG_EINVAL, "voxel index %zu is outside the grid of %zu voxels", idx,
                   vf->n_vox);
  int64_t s = kept_slot(vf, idx);
  if (s < 0)
    return fg_fail(FG_ENOENT, "voxel %zu is empty (alpha below %g keeps no features)", idx,
                   (double)FG_QUERY_ALPHA_FLOOR);
  float h[H];
  fg_half_to_float_n(vf->h16 + (size_t)s * H, h, H);
  for (int d = 0; d < vf->dim; d++) feat[d] = fg_query_dot(vf->W + (size_t)d * H, h, H);
  return 0;
}

/* a . b over 64 floats; the vector lanes fix the order of the sum, the same for any thread
 * count. */
static float dot64(const float *restrict a, const float *restrict b) {
  float s = 0.0f;
#pragma omp simd reduction(+ : s)
  for (int j = 0; j < H; j++) s += a[j] * b[j];
  return s;
}

/* Checks the arguments every scoring entry point shares. */
static int check_score_args(const fg_query *q, int D, float alpha_threshold, const float *scores) {
  if (!scores) return fg_fail(FG_EINVAL, "heatmap: NULL score buffer");
  FG_TRY(fg_query_check(q));
  if (q->dim != D)
    return fg_fail(FG_EINVAL,
                   "the query embedding has %d dimensions but the scene's features have %d",
                   q->dim, D);
  if (!isfinite(alpha_threshold) || alpha_threshold < FG_QUERY_ALPHA_FLOOR ||
      alpha_threshold > 1.0f)
    return fg_fail(FG_EINVAL,
                   "alpha_threshold must be in [%g, 1] (voxels below %g keep no features), "
                   "got %g",
                   (double)FG_QUERY_ALPHA_FLOOR, (double)FG_QUERY_ALPHA_FLOOR,
                   (double)alpha_threshold);
  return 0;
}

int fg_voxel_features_score(const fg_voxel_features *vf, const fg_query *q,
                            float alpha_threshold, float *scores, int n_threads) {
  if (!vf) return fg_fail(FG_EINVAL, "heatmap: NULL voxel features");
  FG_TRY(check_score_args(q, vf->dim, alpha_threshold, scores));
  const int D = vf->dim, nq = 1 + q->n_neg;
  /* U (nq, 64): row 0 = W^T q, row 1 + n = W^T neg_n */
  float *U = malloc((size_t)nq * H * sizeof *U);
  if (!U) return fg_fail(FG_ENOMEM, "heatmap: out of memory");
  for (int r = 0; r < nq; r++) {
    const float *v = r == 0 ? q->q : q->neg + (size_t)(r - 1) * D;
    for (int j = 0; j < H; j++) {
      double s = 0.0;
      for (int d = 0; d < D; d++) s += (double)vf->W[(size_t)d * H + j] * v[d];
      U[r * H + j] = (float)s;
    }
  }
  for (size_t i = 0; i < vf->n_vox; i++) scores[i] = NAN;
  const int nt = fg_threads(n_threads);
  const int64_t n_blocks = (int64_t)((vf->n_kept + SCORE_BLOCK - 1) / SCORE_BLOCK);
#pragma omp parallel num_threads(nt)
  {
    float h[H];
    float cn[FG_QUERY_MAX_NEGATIVES];
#pragma omp for schedule(static)
    for (int64_t b = 0; b < n_blocks; b++) {
      const size_t s0 = (size_t)b * SCORE_BLOCK;
      const size_t m = vf->n_kept - s0 < SCORE_BLOCK ? vf->n_kept - s0 : SCORE_BLOCK;
      for (size_t k = s0; k < s0 + m; k++) {
        const uint32_t idx = vf->kept[k];
        if (!(vf->alpha[idx] >= alpha_threshold)) continue; /* free: no conversion */
        fg_half_to_float_n(vf->h16 + k * H, h, H);
        const float inv = vf->inv_norm[k];
        float cq = dot64(U, h) * inv;
        for (int r = 1; r < nq; r++) cn[r - 1] = dot64(U + r * H, h) * inv;
        scores[idx] = fg_query_score_from_cos(q, cq, cn);
      }
    }
  }
  free(U);
  return 0;
}

int fg_heatmap_score_grid_ref(const fg_field *f, const fg_voxel_grid *g, const fg_query *q,
                              float alpha_threshold, float *scores, int n_threads) {
  if (!f || !g) return fg_fail(FG_EINVAL, "heatmap reference: NULL argument");
  if (f->cfg.feature_dim <= 0)
    return fg_fail(FG_EINVAL, "the field has no feature branch (its frames had no features)");
  const int D = f->cfg.feature_dim;
  FG_TRY(check_score_args(q, D, alpha_threshold, scores));
  const size_t N = fg_voxel_grid_count(g);
  const size_t chunk = 4096;
  float *x = malloc(chunk * 3 * sizeof *x);
  float *sigma = malloc(chunk * sizeof *sigma);
  float *feat = malloc(chunk * (size_t)D * sizeof *feat);
  float *alpha = malloc(chunk * sizeof *alpha);
  int rc = 0;
  if (!x || !sigma || !feat || !alpha) {
    rc = fg_fail(FG_ENOMEM, "heatmap reference: out of memory");
    goto done;
  }
  for (size_t i0 = 0; i0 < N; i0 += chunk) {
    const size_t n = N - i0 < chunk ? N - i0 : chunk;
    fg_query_grid_centres_range(g, i0, n, x);
    rc = fg_query_voxel_sample(f, g, i0, n, alpha, n_threads);
    if (rc == 0) rc = fg_field_features(f, x, (int64_t)n, sigma, NULL, feat, n_threads);
    if (rc < 0) goto done;
    for (size_t k = 0; k < n; k++)
      scores[i0 + k] =
          alpha[k] >= alpha_threshold ? (float)fg_query_score_ref(q, feat + k * D) : NAN;
  }
done:
  free(x);
  free(sigma);
  free(feat);
  free(alpha);
  return rc;
}

/* ---- on disk ---------------------------------------------------------------------------- */

#define VOXF_MAGIC "FGVOXF01"
#define VOXF_HEADER 104 /* bytes before the arrays */
/* 2: alpha from the mean density over sub-samples (voxsample.c); 1 held the centre's alpha,
 * which a reader of today must not take for the same thing. */
#define VOXF_VERSION 2

/* zlib's CRC-32 of n bytes, fed in pieces that fit its uInt. */
static unsigned long fg_query_crc32(const void *data, size_t n) {
  const unsigned char *p = data;
  unsigned long c = crc32(0L, Z_NULL, 0);
  while (n > 0) {
    const size_t m = n > (1u << 30) ? (1u << 30) : n;
    c = crc32(c, p, (uInt)m);
    p += m;
    n -= m;
  }
  return c;
}

/* Bytes of the arrays of a cache of n_vox voxels, n_kept kept, dimension D. */
static size_t voxf_array_bytes(size_t n_vox, size_t n_kept, int D) {
  return n_vox * 4 + n_kept * (4 + H * 2 + 4) + (size_t)D * H * 4;
}

int fg_voxel_features_save(const fg_voxel_features *vf, const char *path) {
  if (!vf || !path) return fg_fail(FG_EINVAL, "voxel features save: NULL argument");
  const size_t len = VOXF_HEADER + voxf_array_bytes(vf->n_vox, vf->n_kept, vf->dim) + 4;
  uint8_t *buf = calloc(1, len);
  if (!buf) return fg_fail(FG_ENOMEM, "voxel features save: out of memory (%zu bytes)", len);
  uint8_t *p = buf;
  const uint32_t version = VOXF_VERSION, dim = (uint32_t)vf->dim;
  const int32_t n3[3] = {vf->grid.nx, vf->grid.ny, vf->grid.nz};
  const uint64_t nk = vf->n_kept;
  memcpy(p, VOXF_MAGIC, 8);
  memcpy(p + 8, &version, 4);
  memcpy(p + 12, &dim, 4);
  memcpy(p + 16, n3, 12);
  memcpy(p + 32, vf->grid.min, 24);
  memcpy(p + 56, vf->grid.max, 24);
  memcpy(p + 80, &vf->grid.voxel_size, 8);
  memcpy(p + 88, &vf->trained_steps, 8);
  memcpy(p + 96, &nk, 8);
  p += VOXF_HEADER;
  memcpy(p, vf->alpha, vf->n_vox * 4);
  p += vf->n_vox * 4;
  memcpy(p, vf->kept, vf->n_kept * 4);
  p += vf->n_kept * 4;
  memcpy(p, vf->h16, vf->n_kept * H * 2);
  p += vf->n_kept * H * 2;
  memcpy(p, vf->inv_norm, vf->n_kept * 4);
  p += vf->n_kept * 4;
  memcpy(p, vf->W, (size_t)vf->dim * H * 4);
  p += (size_t)vf->dim * H * 4;
  const uint32_t crc = (uint32_t)fg_query_crc32(buf, (size_t)(p - buf));
  memcpy(p, &crc, 4);
  int rc = fg_write_file_atomic(path, buf, len);
  free(buf);
  return rc;
}

int fg_voxel_features_load(const char *path, fg_voxel_features **out) {
  if (!path || !out) return fg_fail(FG_EINVAL, "voxel features load: NULL argument");
  *out = NULL;
  char *buf = NULL;
  size_t len = 0;
  FG_TRY(fg_read_file(path, (size_t)1 << 33, &buf, &len));
  const uint8_t *p = (const uint8_t *)buf;
  int rc = 0;
  fg_voxel_features *vf = NULL;
  uint32_t version, dim, crc;
  int32_t n3[3];
  uint64_t nk;
  double mn[3], mx[3], vs;
  int64_t steps;
  if (len < VOXF_HEADER + 4 || memcmp(p, VOXF_MAGIC, 8) != 0) {
    rc = fg_fail(FG_EFORMAT, "%s is not a voxel feature cache (bad magic or too short)", path);
    goto error;
  }
  memcpy(&version, p + 8, 4);
  memcpy(&dim, p + 12, 4);
  memcpy(n3, p + 16, 12);
  memcpy(mn, p + 32, 24);
  memcpy(mx, p + 56, 24);
  memcpy(&vs, p + 80, 8);
  memcpy(&steps, p + 88, 8);
  memcpy(&nk, p + 96, 8);
  fg_voxel_grid g;
  if (version != VOXF_VERSION || dim < 1 || dim > FG_FIELD_MAX_FEATURE_DIM ||
      fg_voxel_grid_init(&g, mn, mx, vs) < 0 || g.nx != n3[0] || g.ny != n3[1] ||
      g.nz != n3[2] || nk > fg_voxel_grid_count(&g)) {
    rc = fg_fail(FG_EFORMAT, "voxel feature cache %s: bad header (version, D or grid)", path);
    goto error;
  }
  const size_t N = fg_voxel_grid_count(&g);
  if (len != VOXF_HEADER + voxf_array_bytes(N, (size_t)nk, (int)dim) + 4) {
    rc = fg_fail(FG_EFORMAT, "voxel feature cache %s: %zu bytes, its header says otherwise",
                 path, len);
    goto error;
  }
  memcpy(&crc, p + len - 4, 4);
  if (crc != (uint32_t)fg_query_crc32(p, len - 4)) {
    rc = fg_fail(FG_EFORMAT, "voxel feature cache %s: checksum mismatch (corrupt file)", path);
    goto error;
  }
  vf = calloc(1, sizeof *vf);
  if (!vf) goto nomem;
  vf->grid = g;
  vf->dim = (int)dim;
  vf->trained_steps = steps;
  vf->n_vox = N;
  vf->n_kept = (size_t)nk;
  const size_t keep = nk > 0 ? (size_t)nk : 1;
  vf->alpha = malloc(N * 4);
  vf->kept = malloc(keep * 4);
  vf->h16 = malloc(keep * H * 2);
  vf->inv_norm = malloc(keep * 4);
  vf->W = malloc((size_t)dim * H * 4);
  if (!vf->alpha || !vf->kept || !vf->h16 || !vf->inv_norm || !vf->W) goto nomem;
  p += VOXF_HEADER;
  memcpy(vf->alpha, p, N * 4);
  p += N * 4;
  memcpy(vf->kept, p, vf->n_kept * 4);
  p += vf->n_kept * 4;
  memcpy(vf->h16, p, vf->n_kept * H * 2);
  p += vf->n_kept * H * 2;
  memcpy(vf->inv_norm, p, vf->n_kept * 4);
  p += vf->n_kept * 4;
  memcpy(vf->W, p, (size_t)dim * H * 4);
  for (size_t k = 0; k < vf->n_kept; k++)
    if (vf->kept[k] >= N || (k > 0 && vf->kept[k] <= vf->kept[k - 1])) {
      rc = fg_fail(FG_EFORMAT, "voxel feature cache %s: voxel indices out of order", path);
      goto error;
    }
  free(buf);
  *out = vf;
  return 0;
nomem:
  rc = fg_fail(FG_ENOMEM, "voxel features load: out of memory");
error:
  free(buf);
  fg_voxel_features_free(vf);
  return rc;
}
