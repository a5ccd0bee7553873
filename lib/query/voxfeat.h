/* The voxel feature cache: a trained field sampled once per voxel of a grid, which heatmaps
 * and grasps read.
 *
 * Voxel features (F3RM). The trained field is sampled once per voxel: its opacity alpha =
 * 1 - exp(-mean sigma * voxel_size), the density sigma (1/m) averaged over 4^3 sub-samples
 * (a surface thinner than a voxel still counts; 0 where the field's occupancy grid is empty,
 * where the renderer never looks), and the 64-d hidden vector h of the feature branch at the
 * voxel's centre. The feature head has no bias, f = W_out h, so
 *   cos(f, q) = (W_out^T q) . h / |W_out h|
 * and the cache keeps, for every voxel with alpha >= FG_QUERY_ALPHA_FLOOR, h in float16 and
 * 1 / |W_out h| (computed from the float16 h, so the fast path is the exact cosine of the
 * stored vector), plus alpha (float) for every voxel and its own copy of W_out. A heatmap then
 * costs one (64 x D) mat-vec per query vector and a 64-d dot per kept voxel. The F3RM
 * alpha-weighted feature alpha * f has the same direction as f, so cosine scores do not
 * depend on the weighting; grasp inference reads alpha and the features from the same cache.
 * Features are not kept below the floor, so an alpha_threshold below FG_QUERY_ALPHA_FLOOR is
 * refused (FG_EINVAL). A cache is immutable once built: any number of threads may compute
 * heatmaps from one cache at once. It does not refer to the field it came from (it may
 * outlive it); trained_steps records which field state it reflects, and the owner rebuilds it
 * when the field changes.
 *
 * Threads: n_threads <= 0 takes the OpenMP default; every result is bit-identical for any
 * thread count. */
#ifndef FG_QUERY_VOXFEAT_H
#define FG_QUERY_VOXFEAT_H

#include <stddef.h>
#include <stdint.h>

#include "query/grid.h"
#include "query/query.h"

struct fg_field;

#define FG_QUERY_ALPHA_FLOOR 1e-3f /* voxels below this alpha keep no features */

typedef struct fg_voxel_features fg_voxel_features; /* opaque, immutable once built */

/* Samples field f (which must have a feature branch) at every centre of grid g and builds the
 * cache described above. The caller owns *out (fg_voxel_features_free); f and g stay with the
 * caller and may be freed afterwards. FG_EINVAL (no feature branch, a bad grid), FG_ERANGE,
 * FG_ENOMEM. */
int fg_voxel_features_build(fg_voxel_features **out, const struct fg_field *f,
                            const fg_voxel_grid *g, int n_threads);

/* A cache from given arrays instead of a field, for synthetic scenes in tests and tools:
 * grid g, alpha (nz, ny, nx) in [0, 1], hidden vectors h (nz, ny, nx, 64) (read only where
 * alpha >= FG_QUERY_ALPHA_FLOOR; may be NULL only if no voxel reaches it) and the feature
 * head W (D, 64). Stored exactly as fg_voxel_features_build stores a field's samples
 * (float16 h); trained_steps is 0. The arrays stay the caller's; the caller owns *out.
 * FG_EINVAL (NULL, a bad grid, D outside 1..FG_FIELD_MAX_FEATURE_DIM, alpha not in [0, 1]),
 * FG_ENOMEM. */
int fg_voxel_features_from_arrays(fg_voxel_features **out, const fg_voxel_grid *g, int dim,
                                  const float *alpha, const float *h, const float *W);

/* Accepts NULL. */
void fg_voxel_features_free(fg_voxel_features *vf);

/* Accessors; the pointers stay owned by vf and live as long as it does. */
const fg_voxel_grid *fg_voxel_features_grid(const fg_voxel_features *vf);
int fg_voxel_features_dim(const fg_voxel_features *vf);          /* D */
const float *fg_voxel_features_alpha(const fg_voxel_features *vf); /* (nz, ny, nx) */
size_t fg_voxel_features_n_kept(const fg_voxel_features *vf); /* voxels with alpha >= floor */
int64_t fg_voxel_features_trained_steps(const fg_voxel_features *vf); /* f->trained_steps */
size_t fg_voxel_features_bytes(const fg_voxel_features *vf); /* heap bytes the cache holds */
double fg_voxel_features_build_seconds(const fg_voxel_features *vf); /* wall time of build */

/* Full D-dim feature W_out h of voxel flat index idx (from the float16 h) into feat (D), for
 * grasp inference and tests. FG_ENOENT when the voxel keeps no features (alpha below the
 * floor), FG_EINVAL for idx out of range. */
int fg_voxel_features_feature(const fg_voxel_features *vf, size_t idx, float *feat);

/* The cache's arrays for grasp inference (grasp/grasp.h), owned by vf: kept (n_kept) flat
 * indices of the voxels that keep features, ascending; h16 (n_kept, 64) their float16 hidden
 * vectors; W (D, 64) the feature head. Any pointer argument may be NULL. */
void fg_voxel_features_raw(const fg_voxel_features *vf, const uint32_t **kept,
                           const uint16_t **h16, const float **W);

/* Writes the cache to path atomically (temp file, fsync, rename; fsutil.h) so that a daemon
 * can keep it beside the field: "FGVOXF01", version (2), D, grid, trained_steps, the kept count,
 * then alpha, the kept indices, float16 h, 1/|W h| and W_out in host (little-endian) order,
 * ending in a CRC-32 of everything before. vf stays with the caller. FG_EIO, FG_ENOMEM. */
int fg_voxel_features_save(const fg_voxel_features *vf, const char *path);

/* Reads a cache written by fg_voxel_features_save into *out, which the caller owns
 * (fg_voxel_features_free); *out is NULL on failure. FG_ENOENT, FG_EIO, FG_ERANGE (over 8 GB),
 * FG_EFORMAT with a detail (bad magic, header (a version other than 2 included), length,
 * checksum or indices), FG_ENOMEM. The caller compares fg_voxel_features_trained_steps()
 * and the grid with its field to decide whether the file is current. */
int fg_voxel_features_load(const char *path, fg_voxel_features **out);

/* Scores every voxel through the 64-d fast path into scores (nz, ny, nx), the caller's
 * buffer: NaN where alpha < alpha_threshold. FG_EINVAL for a query of another D, a query
 * that fails fg_query_check, or alpha_threshold below FG_QUERY_ALPHA_FLOOR or above 1 or not
 * finite; FG_ENOMEM. */
int fg_voxel_features_score(const fg_voxel_features *vf, const fg_query *q,
                            float alpha_threshold, float *scores, int n_threads);

/* Scalar reference of the same grid of scores, straight from the field: full D-dim features
 * W_out h at every voxel centre (no float16), alpha as the cache's, fg_query_score_ref. For
 * tests; slow. Same errors as fg_voxel_features_score plus those of the field. */
int fg_heatmap_score_grid_ref(const struct fg_field *f, const fg_voxel_grid *g,
                              const fg_query *q, float alpha_threshold, float *scores,
                              int n_threads);

#endif
