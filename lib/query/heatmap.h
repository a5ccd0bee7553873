/* Open-vocabulary 3D heatmaps (API settled): "where is the mug?" over a scene's workspace and
 * in any rendered view, the scoring rule of SPEC.md "A query".
 *
 * Voxel grid. The workspace [ws_min, ws_max] (world frame, metres) is cut into voxels of side
 * voxel_size starting at ws_min: n_a = ceil((ws_max[a] - ws_min[a]) / voxel_size - 1e-9) per
 * axis (at least 1), voxel (ix, iy, iz) has its centre at ws_min + (i + 0.5) * voxel_size, so the
 * voxels cover the workspace and the last centre lies at most half a voxel beyond ws_max.
 * Dense arrays are [nz][ny][nx] (x fastest), flat index (iz * ny + iy) * nx + ix. At most
 * FG_QUERY_MAX_VOXELS voxels (256^3); larger grids are FG_ERANGE.
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
 * Scores. A resolved query holds a unit vector q (D), n_neg unit negatives (n_neg x D) and a
 * temperature T > 0. score(f) = cos(f, q) without negatives (in [-1, 1]); with negatives
 *   score(f) = min_n softmax([cos(f, q), cos(f, n)] / T)[0] = min_n 1 / (1 + exp((cos(f, n) -
 *   cos(f, q)) / T))
 * (F3RM's viewer rule, in [0, 1]). A feature of zero length has no direction and scores NaN.
 *
 * Threads: n_threads <= 0 takes the OpenMP default; every result is bit-identical for any
 * thread count. */
#ifndef FG_QUERY_HEATMAP_H
#define FG_QUERY_HEATMAP_H

#include <stddef.h>
#include <stdint.h>

struct fg_field;
struct fg_camera;

#define FG_QUERY_ALPHA_FLOOR 1e-3f /* voxels below this alpha keep no features */
#define FG_QUERY_MAX_VOXELS ((size_t)256 * 256 * 256)
#define FG_QUERY_MAX_NEGATIVES 64
#define FG_QUERY_DEFAULT_TEMPERATURE 0.1f
#define FG_QUERY_DEFAULT_ALPHA_THRESHOLD 0.1f
#define FG_QUERY_N_DEFAULT_NEGATIVES 4

/* The default negative texts of a text query: "object", "things", "stuff", "texture". */
extern const char *const fg_query_default_negatives[FG_QUERY_N_DEFAULT_NEGATIVES];

/* ---- voxel grid ----------------------------------------------------------------------- */

typedef struct fg_voxel_grid {
  double min[3];     /* ws_min, world frame, metres */
  double max[3];     /* ws_max, world frame, metres */
  double voxel_size; /* metres */
  int nx, ny, nz;
} fg_voxel_grid;

/* Fills *g for the workspace [ws_min, ws_max] (metres) at voxel_size (metres) as described
 * above. FG_EINVAL (with a detail) for non-finite values, ws_max <= ws_min on an axis or
 * voxel_size <= 0; FG_ERANGE when the grid would exceed FG_QUERY_MAX_VOXELS. */
int fg_voxel_grid_init(fg_voxel_grid *g, const double ws_min[3], const double ws_max[3],
                       double voxel_size);

/* nx * ny * nz. */
size_t fg_voxel_grid_count(const fg_voxel_grid *g);

/* Centre of voxel (ix, iy, iz) in the world frame, metres, into p_world (3). */
void fg_voxel_grid_centre(const fg_voxel_grid *g, int ix, int iy, int iz, double p_world[3]);

/* Centres of all voxels as float (nx*ny*nz, 3) in flat-index order into p_world, which the
 * caller allocates. */
void fg_voxel_grid_centres(const fg_voxel_grid *g, float *p_world);

/* ---- resolved queries ----------------------------------------------------------------- */

typedef struct fg_query {
  int dim;           /* D */
  float *q;          /* (D) unit positive, owned by the struct */
  int n_neg;         /* 0..FG_QUERY_MAX_NEGATIVES */
  float *neg;        /* (n_neg, D) unit negatives, owned by the struct; NULL when n_neg = 0 */
  float temperature; /* > 0, used only with negatives */
} fg_query;

/* Resolves a query from raw embeddings: pos (n_pos, D) positives, each normalised, averaged
 * and the mean renormalised (several positive texts); neg (n_neg, D) negatives, each
 * normalised (NULL when n_neg = 0); temperature > 0 and finite. On success *q owns its copies
 * (fg_query_release); the inputs stay with the caller. On failure *q holds nothing to
 * release. FG_EINVAL with a detail for D outside 1..FG_FIELD_MAX_FEATURE_DIM, n_pos < 1,
 * n_neg outside 0..FG_QUERY_MAX_NEGATIVES, a non-finite value, a zero vector (or positives
 * that cancel), a bad temperature; FG_ENOMEM. */
int fg_query_init(fg_query *q, int dim, const float *pos, int n_pos, const float *neg, int n_neg,
                  float temperature);

/* Frees what *q owns and zeroes it; accepts a zeroed struct. */
void fg_query_release(fg_query *q);

/* Checks a resolved query: dim in range, every vector finite and of unit length within 1e-3,
 * n_neg in range, temperature > 0 and finite. 0 or FG_EINVAL with a detail. */
int fg_query_check(const fg_query *q);

/* Scalar reference of the score rule for one feature f (D) of any length, in double:
 * NaN for a zero or non-finite f. */
double fg_query_score_ref(const fg_query *q, const float *f);

/* The score rule from cosines: cos_q = cos(f, q), cos_neg (n_neg) = cos(f, n). */
float fg_query_score_from_cos(const fg_query *q, float cos_q, const float *cos_neg);

/* Scores n features feat (n, D) (any length, e.g. a rendered feature image from
 * fg_field_render_camera in row-major pixel order) into scores (n). When opacity (n) is not
 * NULL, entries with opacity < min_opacity score NaN (empty pixels have no direction);
 * zero-length features score NaN. FG_EINVAL when D differs from q->dim or q fails
 * fg_query_check; FG_ENOMEM. */
int fg_query_score_features(const fg_query *q, const float *feat, int64_t n, int dim,
                            const float *opacity, float min_opacity, float *scores,
                            int n_threads);

/* ---- voxel feature cache -------------------------------------------------------------- */

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

/* ---- heatmaps ------------------------------------------------------------------------- */

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

/* ---- colour --------------------------------------------------------------------------- */

/* OpenCV's COLORMAP_TURBO as RGB (not OpenCV's BGR order): entry i is the colour of grey
 * level i. Generated from cv::applyColorMap; a test checks it against OpenCV. */
extern const uint8_t fg_turbo_rgb[256][3];

/* Turbo colour of t in [0, 1] (clamped; NaN -> entry 0): entry round(255 * t) into rgb (3). */
void fg_colormap_turbo(float t, uint8_t rgb[3]);

/* Blends a score image over a render into RGB8 for the PNG encoder: rgb (n, 3) sRGB in [0, 1],
 * scores (n), out (n, 3) uint8, the caller's buffers. With t = clamp((score - lo) / (hi - lo),
 * 0, 1) and c = fg_turbo(t) / 255, a pixel is (1 - a) * rgb + a * c with a = 0.25 + 0.6 * t
 * (so the whole view reads as a heatmap and the hottest parts are nearly opaque); a NaN score
 * (empty pixel) shows rgb unchanged. When lo >= hi (or either is NaN), lo and hi are the lowest
 * and highest finite score of the image. Values are rounded to nearest. */
void fg_heatmap_blend(const float *rgb, const float *scores, int64_t n, float lo, float hi,
                      uint8_t *out);

#endif
