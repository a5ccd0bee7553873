/* Heatmaps from the voxel feature cache: the dense score grid, the sorted list of occupied
 * voxels and the best one, and their npy and PLY encodings (heatmap.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "io/npy.h"
#include "query/colormap.h"
#include "query/heatmap.h"

void fg_heatmap_options_default(fg_heatmap_options *o) {
  memset(o, 0, sizeof *o);
  o->alpha_threshold = FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
  o->min_score = -INFINITY;
  o->max_points = 0;
  o->want_dense = 1;
  o->want_points = 1;
  o->n_threads = 0;
}

void fg_heatmap_release(fg_heatmap *hm) {
  if (!hm) return;
  free(hm->dense);
  free(hm->points);
  memset(hm, 0, sizeof *hm);
}

/* Order-preserving map of a finite float to uint32 (larger float, larger key). */
static uint32_t float_key(float s) {
  uint32_t u;
  memcpy(&u, &s, sizeof u);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

/* LSD radix sort of n uint64 keys ascending, tmp (n) scratch; the sorted keys end in keys. */
static void radix_sort_u64(uint64_t *keys, uint64_t *tmp, size_t n) {
  size_t count[256];
  for (int pass = 0; pass < 8; pass++) {
    const int sh = pass * 8;
    memset(count, 0, sizeof count);
    for (size_t i = 0; i < n; i++) count[(keys[i] >> sh) & 0xff]++;
    if (count[keys[0] >> sh & 0xff] == n) continue; /* one digit value: nothing to move */
    size_t pos = 0;
    for (int d = 0; d < 256; d++) {
      size_t c = count[d];
      count[d] = pos;
      pos += c;
    }
    for (size_t i = 0; i < n; i++) tmp[count[(keys[i] >> sh) & 0xff]++] = keys[i];
    memcpy(keys, tmp, n * sizeof *keys);
  }
}

int fg_heatmap_compute(const fg_voxel_features *vf, const fg_query *q,
                       const fg_heatmap_options *opt, fg_heatmap *out) {
  if (!vf || !out) return fg_fail(FG_EINVAL, "heatmap: NULL argument");
  memset(out, 0, sizeof *out);
  fg_heatmap_options def;
  if (!opt) {
    fg_heatmap_options_default(&def);
    opt = &def;
  }
  if (isnan(opt->min_score)) return fg_fail(FG_EINVAL, "heatmap: min_score must be a number");
  const fg_voxel_grid *g = fg_voxel_features_grid(vf);
  const size_t N = fg_voxel_grid_count(g);
  float *dense = malloc(N * sizeof *dense);
  if (!dense) return fg_fail(FG_ENOMEM, "heatmap: out of memory for %zu voxels", N);
  int rc = fg_voxel_features_score(vf, q, opt->alpha_threshold, dense, opt->n_threads);
  if (rc < 0) {
    free(dense);
    return rc;
  }
  out->grid = *g;
  out->alpha_threshold = opt->alpha_threshold;

  /* occupied voxels and the best one; ties go to the lower index */
  const float *alpha = fg_voxel_features_alpha(vf);
  size_t n_occ = 0, n_list = 0;
  float best = -INFINITY;
  size_t best_i = 0;
  int has_best = 0;
  for (size_t i = 0; i < N; i++) {
    if (!(alpha[i] >= opt->alpha_threshold)) continue;
    n_occ++;
    const float s = dense[i];
    if (isnan(s)) continue;
    if (!has_best || s > best) {
      best = s;
      best_i = i;
      has_best = 1;
    }
    if (s >= opt->min_score) n_list++;
  }
  out->n_occupied = n_occ;
  if (has_best) {
    const size_t nx = (size_t)g->nx, ny = (size_t)g->ny;
    out->has_best = 1;
    out->best_score = best;
    out->best_index = (uint32_t)best_i;
    fg_voxel_grid_centre(g, (int)(best_i % nx), (int)((best_i / nx) % ny),
                         (int)(best_i / (nx * ny)), out->best_p_world);
  }

  if (opt->want_points && n_list > 0) {
    uint64_t *keys = malloc(n_list * sizeof *keys);
    uint64_t *tmp = malloc(n_list * sizeof *tmp);
    size_t keep = opt->max_points > 0 && opt->max_points < n_list ? opt->max_points : n_list;
    fg_heatmap_point *pts = malloc(keep * sizeof *pts);
    if (!keys || !tmp || !pts) {
      free(keys);
      free(tmp);
      free(pts);
      free(dense);
      memset(out, 0, sizeof *out);
      return fg_fail(FG_ENOMEM, "heatmap: out of memory for %zu points", n_list);
    }
    size_t k = 0;
    for (size_t i = 0; i < N; i++) {
      if (!(alpha[i] >= opt->alpha_threshold)) continue;
      const float s = dense[i];
      if (isnan(s) || !(s >= opt->min_score)) continue;
      /* ascending keys: score descending, then index ascending */
      keys[k++] = ((uint64_t)(~float_key(s)) << 32) | (uint64_t)i;
    }
    radix_sort_u64(keys, tmp, n_list);
    const size_t nx = (size_t)g->nx, ny = (size_t)g->ny;
    for (size_t j = 0; j < keep; j++) {
      const size_t i = (size_t)(keys[j] & 0xffffffffu);
      double p[3];
      fg_voxel_grid_centre(g, (int)(i % nx), (int)((i / nx) % ny), (int)(i / (nx * ny)), p);
      pts[j].p_world[0] = (float)p[0];
      pts[j].p_world[1] = (float)p[1];
      pts[j].p_world[2] = (float)p[2];
      pts[j].score = dense[i];
      pts[j].alpha = alpha[i];
      pts[j].index = (uint32_t)i;
    }
    free(keys);
    free(tmp);
    out->points = pts;
    out->n_points = keep;
  }
  if (opt->want_dense)
    out->dense = dense;
  else
    free(dense);
  return 0;
}

int fg_heatmap_encode_npy(const fg_heatmap *hm, uint8_t **out, size_t *out_len) {
  if (!hm || !out || !out_len) return fg_fail(FG_EINVAL, "heatmap npy: NULL argument");
  if (!hm->dense)
    return fg_fail(FG_EINVAL, "heatmap npy: the heatmap was computed without its dense grid");
  const size_t shape[3] = {(size_t)hm->grid.nz, (size_t)hm->grid.ny, (size_t)hm->grid.nx};
  return fg_npy_encode(FG_DTYPE_F32, 3, shape, hm->dense, out, out_len);
}

/* Writes v as 4 little-endian bytes at p. */
static void put_f32_le(uint8_t *p, float v) {
  uint32_t u;
  memcpy(&u, &v, sizeof u);
  p[0] = (uint8_t)u;
  p[1] = (uint8_t)(u >> 8);
  p[2] = (uint8_t)(u >> 16);
  p[3] = (uint8_t)(u >> 24);
}

#define PLY_VERTEX_BYTES 19 /* 3 float + 3 uchar + 1 float */

int fg_heatmap_encode_ply(const fg_heatmap *hm, float lo, float hi, uint8_t **out,
                          size_t *out_len) {
  if (!hm || !out || !out_len) return fg_fail(FG_EINVAL, "heatmap ply: NULL argument");
  *out = NULL;
  *out_len = 0;
  const size_t n = hm->points ? hm->n_points : 0;
  char header[512];
  int hl = snprintf(header, sizeof header,
                    "ply\n"
                    "format binary_little_endian 1.0\n"
                    "comment fieldgrip heatmap, voxel_size %.9g m, world frame\n"
                    "element vertex %zu\n"
                    "property float x\n"
                    "property float y\n"
                    "property float z\n"
                    "property uchar red\n"
                    "property uchar green\n"
                    "property uchar blue\n"
                    "property float score\n"
                    "end_header\n",
                    hm->grid.voxel_size, n);
  if (hl < 0 || (size_t)hl >= sizeof header) return fg_fail(FG_EINVAL, "heatmap ply: header");
  if (!(lo < hi)) { /* auto range over the listed scores */
    lo = INFINITY;
    hi = -INFINITY;
    for (size_t i = 0; i < n; i++) {
      if (hm->points[i].score < lo) lo = hm->points[i].score;
      if (hm->points[i].score > hi) hi = hm->points[i].score;
    }
    if (!(lo < hi)) {
      lo = n > 0 ? lo : 0.0f;
      hi = lo + 1.0f;
    }
  }
  const size_t len = (size_t)hl + n * PLY_VERTEX_BYTES;
  uint8_t *buf = malloc(len);
  if (!buf) return fg_fail(FG_ENOMEM, "heatmap ply: out of memory for %zu points", n);
  memcpy(buf, header, (size_t)hl);
  uint8_t *p = buf + hl;
  const float inv = 1.0f / (hi - lo);
  for (size_t i = 0; i < n; i++, p += PLY_VERTEX_BYTES) {
    const fg_heatmap_point *pt = &hm->points[i];
    put_f32_le(p + 0, pt->p_world[0]);
    put_f32_le(p + 4, pt->p_world[1]);
    put_f32_le(p + 8, pt->p_world[2]);
    fg_colormap_turbo((pt->score - lo) * inv, p + 12);
    put_f32_le(p + 15, pt->score);
  }
  *out = buf;
  *out_len = len;
  return 0;
}
