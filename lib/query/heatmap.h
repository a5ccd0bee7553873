/* Open-vocabulary 3D heatmaps (API settled): "where is the mug?" over a scene's workspace, as
 * the scores of a query (query.h) at the voxels of a feature cache (voxfeat.h), and their
 * encodings as npy and PLY. The colours of a heatmap in a rendered view: colormap.h.
 *
 * Threads: n_threads <= 0 takes the OpenMP default; every result is bit-identical for any
 * thread count. */
#ifndef FG_QUERY_HEATMAP_H
#define FG_QUERY_HEATMAP_H

#include <stddef.h>
#include <stdint.h>

#include "query/voxfeat.h"

#define FG_QUERY_DEFAULT_ALPHA_THRESHOLD 0.1f

typedef struct fg_heatmap_options {
  float alpha_threshold; /* voxels with alpha >= this are occupied; >= FG_QUERY_ALPHA_FLOOR */
  float min_score;       /* points below this score are left out of the list (-INFINITY: none) */
  size_t max_points;     /* the list keeps the best max_points; 0: no limit */
  int want_dense;        /* 1: fill fg_heatmap.dense */
  int want_points;       /* 1: fill fg_heatmap.points */
  int n_threads;
} fg_heatmap_options;

/* alpha_threshold FG_QUERY_DEFAULT_ALPHA_THRESHOLD, min_score -INFINITY, max_points 0, both
 * outputs wanted, n_threads 0. */
void fg_heatmap_options_default(fg_heatmap_options *o);

typedef struct fg_heatmap_point {
  float p_world[3]; /* voxel centre, world frame, metres */
  float score;
  float alpha;
  uint32_t index;   /* flat voxel index */
} fg_heatmap_point;

typedef struct fg_heatmap {
  fg_voxel_grid grid;
  float alpha_threshold;
  float *dense;             /* (nz, ny, nx) scores, NaN where alpha < threshold; owned; NULL
                             * unless want_dense */
  fg_heatmap_point *points; /* (n_points) occupied voxels with score >= min_score, by score
                             * descending (ties: lower index first), cut to max_points; owned;
                             * NULL unless want_points or when empty. A voxel whose feature
                             * has zero length (NaN score) is never listed nor best. */
  size_t n_points;
  size_t n_occupied;        /* voxels with alpha >= threshold (before min_score/max_points) */
  int has_best;             /* 0 when no voxel is occupied (best_* then unset) */
  double best_p_world[3];   /* centre of the best-scoring occupied voxel, metres */
  float best_score;
  uint32_t best_index;
} fg_heatmap;

/* Scores the cache for query q with the options (NULL: defaults) into *out. On success the
 * caller owns what *out holds (fg_heatmap_release); on failure *out holds nothing to release.
 * Errors as fg_voxel_features_score, FG_EINVAL for a NaN min_score. Cost: one 64-d dot per
 * occupied voxel and query vector, a radix sort of the listed points; 14..32 ms for 220,500
 * occupied voxels (all of them listed) with D = 512 on a busy 2-core machine (bench_heatmap),
 * well under 1 ms for a grid that is nearly all free space. */
int fg_heatmap_compute(const fg_voxel_features *vf, const fg_query *q,
                       const fg_heatmap_options *opt, fg_heatmap *out);

/* Frees what *hm owns and zeroes it; accepts a zeroed struct. */
void fg_heatmap_release(fg_heatmap *hm);

/* The dense grid as a float32 .npy of shape [nz, ny, nx] (fg_npy_encode) into a malloc'd
 * buffer the caller owns. FG_EINVAL when hm->dense is NULL; FG_ENOMEM. */
int fg_heatmap_encode_npy(const fg_heatmap *hm, uint8_t **out, size_t *out_len);

/* The point list as a binary little-endian PLY ("format binary_little_endian 1.0"; vertex:
 * float x, y, z, uchar red, green, blue, float score; one vertex per point, in list order)
 * into a malloc'd buffer the caller owns. Colours come from the turbo map of
 * t = clamp((score - lo) / (hi - lo), 0, 1); when lo >= hi (or either is NaN), lo and hi are
 * the lowest and highest score in the list. An empty list gives a valid file of 0 vertices.
 * FG_ENOMEM. */
int fg_heatmap_encode_ply(const fg_heatmap *hm, float lo, float hi, uint8_t **out,
                          size_t *out_len);

#endif
