/* The feature field: an Instant-NGP radiance field with an F3RM feature branch, in the world
 * frame of SPEC.md (metres), and the inference passes that renders and queries use.
 *
 * Box. The field lives in an axis-aligned cube of side `box_size` metres whose lowest corner is
 * `box_min`; a world point x maps to the unit cube as (x - box_min) / box_size, so distances
 * scale by one factor and ray directions keep unit length. fg_field_config_for_workspace()
 * centres a cube of side field_scale * (largest workspace extent) on the workspace: a scan of
 * a room sees walls and floor outside the workspace, and the field may put what explains
 * them near the cube's faces, outside the workspace, instead of floaters inside it. Rays that
 * leave the cube see the scene's background colour.
 *
 * Networks (Instant-NGP / F3RM):
 *   density:  hash grid (16 x 2, 2^18 entries, 16..2048) -> MLP {32, 64, 1 hidden, 16};
 *             sigma = trunc_exp(out[0]) (in 1/m), geo = out[0..15]
 *   colour:   [SH4(d) (16), geo (16)] -> MLP {32, 64, 2 hidden, 3}, sigmoid -> sRGB
 *   feature:  hash grid (12 x 4, 2^18 entries, 16..128) -> MLP {48, 64, 1 hidden, 64}, ReLU
 *             -> h (64); feature = W_out h with W_out (D, 64).
 *   background, optional (learn_background; off by default): bg(d) = sigmoid(W_bg SH4(d)),
 *             W_bg (3, 16), learned in training. Off by default because it learns faster
 *             than the density: on a tabletop scan it absorbed the table as a direction-
 *             dependent colour and the density never formed (26 dB without it at 20 s on a
 *             scenegen scene, a flat grey-white render with it).
 * The last feature layer is linear and has no bias, so a ray's composited feature is
 * W_out (sum_i w_i h_i): the 64-d hidden vectors are composited per ray and the D-wide layer
 * is applied once per ray, which keeps a 512-d feature head as cheap as a 64-d one.
 *
 * Samples. Rays march through the occupancy grid (occupancy.h) at a fixed step of dt cube
 * units (max samples per ray 1024); a sample's density is in 1/m and its segment in metres.
 *
 * Parameters live in one 2 MB-aligned float array (huge pages), the groups of
 * fg_field_param_group in that order, each starting on a 64-byte boundary (the padding is
 * zero); fg_field_group() tells where each group starts and how long it is. */
#ifndef FG_FIELD_MODEL_H
#define FG_FIELD_MODEL_H

#include <stddef.h>
#include <stdint.h>

#include "field/hashgrid.h"
#include "field/mlp.h"
#include "field/occupancy.h"

#define FG_FIELD_MAX_FEATURE_DIM 4096
#define FG_FIELD_FEATURE_HIDDEN 64
#define FG_FIELD_GEO_DIM 16
#define FG_FIELD_MAX_SAMPLES_PER_RAY 1024

typedef struct fg_field_config {
  double box_min[3]; /* metres, world frame */
  double box_size;   /* side of the cube, metres */
  fg_hashgrid_config grid;      /* density grid */
  fg_hashgrid_config feat_grid; /* feature grid */
  int feature_dim;              /* D; 0: no feature branch */
  int learn_background;         /* 1: a learned background colour per direction */
  int occ_resolution;           /* occupancy grid cells per axis (128) */
  float dt;                     /* marching step in cube units (sqrt(3)/1024) */
} fg_field_config;

/* Defaults (above) with a cube of side field_scale * max extent centred on the workspace
 * [ws_min, ws_max]. field_scale in [1, 64]; FG_EINVAL with a detail otherwise. */
int fg_field_config_for_workspace(fg_field_config *cfg, const double ws_min[3],
                                  const double ws_max[3], double field_scale, int feature_dim);

/* Checks every field of cfg. 0 or FG_EINVAL with a detail naming it. */
int fg_field_config_check(const fg_field_config *cfg);

/* 1 when a and b describe the same box (within a micrometre) and the same networks, so that
 * parameters trained for one can go on training as the other; else 0, with what differs
 * (the first difference, in words) in why[0..why_len) when why is not NULL. */
int fg_field_config_same(const fg_field_config *a, const fg_field_config *b, char *why,
                         size_t why_len);

enum fg_field_param_group {
  FG_FIELD_GRID = 0,   /* density hash tables */
  FG_FIELD_DENSITY,    /* density MLP */
  FG_FIELD_COLOUR,     /* colour MLP */
  FG_FIELD_BACKGROUND, /* W_bg (3 x 16), zero-length unless learn_background */
  FG_FIELD_FEAT_GRID,  /* feature hash tables, zero-length when D = 0 */
  FG_FIELD_FEAT_MLP,   /* feature MLP, zero-length when D = 0 */
  FG_FIELD_FEAT_OUT,   /* W_out (D x 64), zero-length when D = 0 */
  FG_FIELD_N_GROUPS
};

typedef struct fg_field {
  fg_field_config cfg;
  fg_mlp_config density_net, colour_net, feat_net;
  size_t group_offset[FG_FIELD_N_GROUPS + 1]; /* first float of each group (64-byte aligned) */
  size_t group_len[FG_FIELD_N_GROUPS];        /* floats in each group */
  size_t n_params;
  float *params;        /* n_params floats, 2 MB-aligned, owned */
  fg_occgrid *occ;      /* owned */
  int64_t trained_steps; /* steps the parameters have seen (0 for a new field) */
} fg_field;

/* Allocates a field for cfg and initialises its parameters from seed (hash tables uniform in
 * +-1e-4, MLPs Glorot uniform, W_bg zero: a grey background) and a fully occupied grid.
 * The caller owns *out (fg_field_free). FG_EINVAL, FG_ENOMEM. */
int fg_field_new(fg_field **out, const fg_field_config *cfg, uint64_t seed);

/* Allocates a field for cfg with every parameter (padding included) zero, a fully occupied
 * grid and trained_steps 0, for loaders that fill it. The caller owns *out (fg_field_free).
 * FG_EINVAL (with a detail), FG_ENOMEM. */
int fg_field_alloc(fg_field **out, const fg_field_config *cfg);

/* A field to go on training from src after its scene changed (an update): src's
 * configuration and parameters, a fully occupied occupancy grid (rebuilt from the new views
 * as a new field's is) and trained_steps 0, so that a trainer's schedule, occupancy warm-up
 * and optimiser start again. The caller owns *out (fg_field_free). FG_ENOMEM. */
int fg_field_copy_for_update(const fg_field *src, fg_field **out);

void fg_field_free(fg_field *f);

/* Group g's parameters, and their count in *n when n is not NULL. */
float *fg_field_group(fg_field *f, int g, size_t *n);
const float *fg_field_group_const(const fg_field *f, int g, size_t *n);

/* Maps world points (B,3) to the unit cube (B,3) (cube may alias world). */
void fg_field_to_cube(const fg_field *f, const float *world, int64_t B, float *cube);

/* The learned background (sRGB) of R rays whose directions' SH4 encodings are sh (R,16):
 * bg (R,3). The field must have learn_background set. */
void fg_field_background(const fg_field *f, const float *sh, int64_t R, float *bg);

/* ---- inference ------------------------------------------------------------------------ */
/* Inference runs in chunks over caller-given rays or points and allocates its own scratch
 * per call (a few tens of MB); every function returns 0, FG_EINVAL or FG_ENOMEM. Results are
 * bit-identical for any thread count. n_threads <= 0 takes the OpenMP default. */

/* Density sigma (1/m) at B world points. */
int fg_field_density(const fg_field *f, const float *x_world, int64_t B, float *sigma,
                     int n_threads);

/* Density and the 64-d feature hidden vector h at B world points, for voxel features; feat
 * (B, D) receives W_out h when not NULL, hidden (B, 64) receives h when not NULL. FG_EINVAL
 * when the field has no feature branch. */
int fg_field_features(const fg_field *f, const float *x_world, int64_t B, float *sigma,
                      float *hidden, float *feat, int n_threads);

/* Central differences of the density at B world points x (B,3): grad (B,3) receives
 * (sigma(x + h e_k) - sigma(x - h e_k)) / (2 h) per world axis k, in 1/m^2, with h = step_m
 * metres (> 0 and finite, else FG_EINVAL). A step of half a voxel of the scene's grid reads
 * the surface the voxels show rather than the hash grid's finest cells (about a millimetre),
 * where a trained density is rough. Costs six density evaluations a point. */
int fg_field_density_gradient(const fg_field *f, const float *x_world, int64_t B,
                              float step_m, float *grad, int n_threads);

/* The colour (sRGB in [0,1]) the colour network gives a sample at each of B world points
 * x (B,3) seen by a ray travelling along the unit direction dirs (B,3), world frame: rgb (B,3).
 * What a render composites, one sample at a time, for colouring meshes and points. */
int fg_field_colour(const fg_field *f, const float *x_world, const float *dirs, int64_t B,
                    float *rgb, int n_threads);

/* Renders R rays given in world coordinates (origins (R,3), unit directions (R,3)), with
 * samples placed at the centres of the marching lattice (no jitter) and early termination
 * at transmittance 1e-4. Rays see bg (3) where the field is empty, or the learned
 * background when bg is NULL (FG_EINVAL for a field without one). Outputs, each NULL when not
 * wanted: rgb (R,3) sRGB in [0,1], depth (R) expected distance along the ray in metres
 * (sum_i w_i t_i, not normalised by opacity), opacity (R), feat (R,D) (FG_EINVAL when
 * requested from a field without features). Without rgb the colour network is not run: a
 * depth or normal render costs about three quarters of a colour render. */
int fg_field_render_rays(const fg_field *f, const float *rays_o, const float *rays_d, int64_t R,
                         const float bg[3], float *rgb, float *depth, float *opacity,
                         float *feat, int n_threads);

/* Surface normals of R rays (origins (R,3), unit directions (R,3), world frame): each ray is
 * rendered as by fg_field_render_rays, its expected termination point taken as
 * p = o + d * depth / opacity, and its normal is n = -grad sigma / |grad sigma| at p
 * (fg_field_density_gradient with step_m): unit length, world frame, pointing from dense to
 * empty space. normals (R,3) receives n, or (0, 0, 0) where the ray's opacity is 0 or the
 * gradient vanishes or is not finite; opacity (R) receives each ray's opacity when not NULL,
 * so that callers can leave out rays that hit nothing solid. Errors as fg_field_render_rays
 * and FG_EINVAL for a bad step_m. */
int fg_field_render_normals(const fg_field *f, const float *rays_o, const float *rays_d,
                            int64_t R, float step_m, float *normals, float *opacity,
                            int n_threads);

#endif
