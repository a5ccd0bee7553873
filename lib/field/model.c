#include "field/model.h"

#include <cblas.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "core/arena.h"
#include "core/error.h"
#include "core/threads.h"
#include "field/render.h"
#include "field/sh.h"

#define HUGE_ALIGN ((size_t)2 << 20)

static void default_grids(fg_field_config *cfg) {
  fg_hashgrid_config_default(&cfg->grid);
  cfg->grid.log2_table_size = 18;
  cfg->feat_grid = (fg_hashgrid_config){
      .n_levels = 12, .n_features = 4, .log2_table_size = 18,
      .base_resolution = 16, .finest_resolution = 128};
}

int fg_field_config_for_workspace(fg_field_config *cfg, const double ws_min[3],
                                  const double ws_max[3], double field_scale, int feature_dim) {
  memset(cfg, 0, sizeof *cfg);
  if (!(field_scale >= 1.0 && field_scale <= 64.0))
    return fg_fail(FG_EINVAL, "field_scale must be in [1, 64], got %g", field_scale);
  double extent = 0.0;
  for (int k = 0; k < 3; k++) {
    if (!(ws_max[k] > ws_min[k]) || !isfinite(ws_min[k]) || !isfinite(ws_max[k]))
      return fg_fail(FG_EINVAL, "workspace max must exceed min on every axis");
    if (ws_max[k] - ws_min[k] > extent) extent = ws_max[k] - ws_min[k];
  }
  cfg->box_size = extent * field_scale;
  for (int k = 0; k < 3; k++) cfg->box_min[k] = 0.5 * (ws_min[k] + ws_max[k]) - 0.5 * cfg->box_size;
  default_grids(cfg);
  cfg->feature_dim = feature_dim;
  cfg->learn_background = 0;
  cfg->occ_resolution = FG_OCCGRID_DEFAULT_RES;
  cfg->dt = FG_OCCGRID_DEFAULT_DT;
  return fg_field_config_check(cfg);
}

int fg_field_config_check(const fg_field_config *cfg) {
  for (int k = 0; k < 3; k++)
    if (!isfinite(cfg->box_min[k]) || fabs(cfg->box_min[k]) > 1e6)
      return fg_fail(FG_EINVAL, "field box_min must be finite and within 1e6 m");
  if (!(cfg->box_size > 1e-6 && cfg->box_size < 1e6))
    return fg_fail(FG_EINVAL, "field box_size must be in (1e-6, 1e6) m, got %g", cfg->box_size);
  if (fg_hashgrid_config_check(&cfg->grid) < 0) return FG_EINVAL;
  if (cfg->grid.n_levels * cfg->grid.n_features > 64)
    return fg_fail(FG_EINVAL, "density grid gives more than 64 features per point");
  if (cfg->feature_dim < 0 || cfg->feature_dim > FG_FIELD_MAX_FEATURE_DIM)
    return fg_fail(FG_EINVAL, "feature_dim must be in [0, %d], got %d", FG_FIELD_MAX_FEATURE_DIM,
                   cfg->feature_dim);
  if (cfg->feature_dim > 0) {
    if (fg_hashgrid_config_check(&cfg->feat_grid) < 0) return FG_EINVAL;
    if (cfg->feat_grid.n_levels * cfg->feat_grid.n_features > 256)
      return fg_fail(FG_EINVAL, "feature grid gives more than 256 features per point");
  }
  if (cfg->learn_background != 0 && cfg->learn_background != 1)
    return fg_fail(FG_EINVAL, "learn_background must be 0 or 1");
  if (!fg_occgrid_size(cfg->occ_resolution))
    return fg_fail(FG_EINVAL, "occ_resolution must be a multiple of 4 in [4, 1024], got %d",
                   cfg->occ_resolution);
  if (!(cfg->dt > 1e-6f && cfg->dt < 0.5f))
    return fg_fail(FG_EINVAL, "dt must be in (1e-6, 0.5) cube units, got %g", (double)cfg->dt);
  return 0;
}

static int grid_same(const fg_hashgrid_config *a, const fg_hashgrid_config *b) {
  return a->n_levels == b->n_levels && a->n_features == b->n_features &&
         a->log2_table_size == b->log2_table_size && a->base_resolution == b->base_resolution &&
         a->finest_resolution == b->finest_resolution;
}

int fg_field_config_same(const fg_field_config *a, const fg_field_config *b, char *why,
                         size_t why_len) {
  char buf[256];
  buf[0] = '\0';
  double d = fabs(a->box_size - b->box_size);
  for (int k = 0; k < 3; k++) d = fmax(d, fabs(a->box_min[k] - b->box_min[k]));
  if (d > 1e-6)
    snprintf(buf, sizeof buf, "its box is a cube of %.4f m from (%.4f, %.4f, %.4f), not of "
             "%.4f m from (%.4f, %.4f, %.4f)", a->box_size, a->box_min[0], a->box_min[1],
             a->box_min[2], b->box_size, b->box_min[0], b->box_min[1], b->box_min[2]);
  else if (a->feature_dim != b->feature_dim)
    snprintf(buf, sizeof buf, "its features have %d dimensions, not %d", a->feature_dim,
             b->feature_dim);
  else if (!grid_same(&a->grid, &b->grid) ||
           (a->feature_dim > 0 && !grid_same(&a->feat_grid, &b->feat_grid)))
    snprintf(buf, sizeof buf, "its hash grids differ");
  else if (a->learn_background != b->learn_background)
    snprintf(buf, sizeof buf, "it %s a background",
             a->learn_background ? "learns" : "does not learn");
  else if (a->occ_resolution != b->occ_resolution || a->dt != b->dt)
    snprintf(buf, sizeof buf, "its occupancy grid or marching step differs");
  if (why && why_len) snprintf(why, why_len, "%s", buf);
  return buf[0] == '\0';
}

static void *alloc_huge(size_t bytes) {
  const size_t size = (bytes + HUGE_ALIGN - 1) / HUGE_ALIGN * HUGE_ALIGN;
  void *p = aligned_alloc(HUGE_ALIGN, size ? size : HUGE_ALIGN);
  if (p && size >= HUGE_ALIGN) (void)madvise(p, size, MADV_HUGEPAGE);
  return p;
}

int fg_field_alloc(fg_field **out, const fg_field_config *cfg) {
  if (!out || !cfg) return fg_fail(FG_EINVAL, "field: NULL out or config");
  *out = NULL;
  FG_TRY(fg_field_config_check(cfg));
  fg_field *f = calloc(1, sizeof *f);
  if (!f) return fg_fail(FG_ENOMEM, "cannot allocate a field");
  f->cfg = *cfg;
  const int D = cfg->feature_dim;
  f->density_net = (fg_mlp_config){cfg->grid.n_levels * cfg->grid.n_features, 64, 1,
                                   FG_FIELD_GEO_DIM};
  f->colour_net = (fg_mlp_config){FG_SH4_DIM + FG_FIELD_GEO_DIM, 64, 2, 3};
  /* The feature grid's config is only checked, and only used, with a feature branch. */
  f->feat_net = (fg_mlp_config){D > 0 ? cfg->feat_grid.n_levels * cfg->feat_grid.n_features : 1,
                                64, 1, FG_FIELD_FEATURE_HIDDEN};
  size_t n[FG_FIELD_N_GROUPS] = {0};
  if (fg_hashgrid_layout(&cfg->grid, NULL, &n[FG_FIELD_GRID]) < 0) goto bad;
  n[FG_FIELD_DENSITY] = fg_mlp_n_params(&f->density_net);
  n[FG_FIELD_COLOUR] = fg_mlp_n_params(&f->colour_net);
  n[FG_FIELD_BACKGROUND] = cfg->learn_background ? 3 * FG_SH4_DIM : 0;
  if (D > 0) {
    if (fg_hashgrid_layout(&cfg->feat_grid, NULL, &n[FG_FIELD_FEAT_GRID]) < 0) goto bad;
    n[FG_FIELD_FEAT_MLP] = fg_mlp_n_params(&f->feat_net);
    n[FG_FIELD_FEAT_OUT] = (size_t)D * FG_FIELD_FEATURE_HIDDEN;
  }
  /* Each group starts on a 64-byte boundary so that kernels see aligned arrays. */
  size_t off = 0;
  for (int g = 0; g < FG_FIELD_N_GROUPS; g++) {
    f->group_offset[g] = off;
    f->group_len[g] = n[g];
    off += (n[g] + 15) / 16 * 16;
  }
  f->group_offset[FG_FIELD_N_GROUPS] = off;
  f->n_params = f->group_offset[FG_FIELD_N_GROUPS];
  f->params = alloc_huge(f->n_params * sizeof(float));
  if (!f->params) {
    const size_t n_params = f->n_params;
    free(f);
    return fg_fail(FG_ENOMEM, "cannot allocate %zu field parameters", n_params);
  }
  memset(f->params, 0, f->n_params * sizeof(float));
  if (fg_occgrid_new(&f->occ, cfg->occ_resolution) < 0) {
    free(f->params);
    free(f);
    return FG_ENOMEM;
  }
  *out = f;
  return 0;
bad:
  free(f);
  return FG_EINVAL;
}

int fg_field_new(fg_field **out, const fg_field_config *cfg, uint64_t seed) {
  FG_TRY(fg_field_alloc(out, cfg));
  fg_field *f = *out;
  /* One stream per group, so that adding a group later leaves the others' values alone. */
  fg_hashgrid_init(&cfg->grid, fg_field_group(f, FG_FIELD_GRID, NULL), seed * 8 + 0);
  fg_mlp_init(&f->density_net, fg_field_group(f, FG_FIELD_DENSITY, NULL), seed * 8 + 1);
  fg_mlp_init(&f->colour_net, fg_field_group(f, FG_FIELD_COLOUR, NULL), seed * 8 + 2);
  if (cfg->feature_dim > 0) {
    fg_hashgrid_init(&cfg->feat_grid, fg_field_group(f, FG_FIELD_FEAT_GRID, NULL), seed * 8 + 4);
    fg_mlp_init(&f->feat_net, fg_field_group(f, FG_FIELD_FEAT_MLP, NULL), seed * 8 + 5);
    /* W_out: Glorot uniform for a 64 -> D layer, through a one-layer MLP config. */
    const fg_mlp_config out_layer = {FG_FIELD_FEATURE_HIDDEN, 1, 0, cfg->feature_dim};
    fg_mlp_init(&out_layer, fg_field_group(f, FG_FIELD_FEAT_OUT, NULL), seed * 8 + 6);
  }
  return 0;
}

int fg_field_copy_for_update(const fg_field *src, fg_field **out) {
  FG_TRY(fg_field_alloc(out, &src->cfg));
  memcpy((*out)->params, src->params, src->n_params * sizeof *src->params);
  return 0;
}

void fg_field_free(fg_field *f) {
  if (!f) return;
  fg_occgrid_free(f->occ);
  free(f->params);
  free(f);
}

float *fg_field_group(fg_field *f, int g, size_t *n) {
  if (n) *n = f->group_len[g];
  return f->params + f->group_offset[g];
}

const float *fg_field_group_const(const fg_field *f, int g, size_t *n) {
  if (n) *n = f->group_len[g];
  return f->params + f->group_offset[g];
}

void fg_field_to_cube(const fg_field *f, const float *world, int64_t B, float *cube) {
  const float inv = (float)(1.0 / f->cfg.box_size);
  const float m0 = (float)f->cfg.box_min[0], m1 = (float)f->cfg.box_min[1],
              m2 = (float)f->cfg.box_min[2];
  for (int64_t i = 0; i < B; i++) {
    cube[3 * i + 0] = (world[3 * i + 0] - m0) * inv;
    cube[3 * i + 1] = (world[3 * i + 1] - m1) * inv;
    cube[3 * i + 2] = (world[3 * i + 2] - m2) * inv;
  }
}

/* ---- inference ------------------------------------------------------------------------ */

/* Points per chunk of fg_field_density / fg_field_features, and the sample capacity of one
 * fg_field_render_rays chunk: about 300 floats a sample, so some 80 MB of scratch. */
#define POINT_CHUNK 65536
#define SAMPLE_CHUNK 65536
#define RAY_CHUNK 4096

/* Scratch of the inference passes, one allocation carved into named arrays. */
typedef struct infer_buf {
  float *x, *dt, *t;              /* (S,3), (S), (S) cube units */
  float *enc, *dacts, *dout;      /* (S,32), (S,64), (S,16) */
  float *cin, *cacts, *rgb;       /* (S,32), (2,S,64), (S,3) */
  float *sigma;                   /* (S) 1/cube unit */
  float *fenc, *facts, *h;        /* (S,48), (S,64), (S,64) */
  float *o, *d, *sh;              /* (R,3), (R,3), (R,16) */
  float *hc;                      /* (R,64) composited hidden features */
  int32_t *off, *cnt;             /* (R) */
  void *mem;
} infer_buf;

static int infer_buf_new(infer_buf *b, const fg_field *f, int64_t S, int64_t R) {
  const size_t ld = (size_t)f->density_net.n_in, lf = (size_t)f->feat_net.n_in;
  const size_t fs = f->cfg.feature_dim > 0 ? (size_t)S : 0, fr = fs ? (size_t)R : 0;
  const size_t F = sizeof(float);
  fg_arena a = {0};
  for (int pass = 0; pass < 2; pass++) {
    if (pass && fg_arena_alloc(&a) < 0)
      return fg_fail(FG_ENOMEM, "cannot allocate %zu MB of render scratch", a.used >> 20);
    b->x = fg_arena_take(&a, 3 * (size_t)S * F);
    b->dt = fg_arena_take(&a, (size_t)S * F);
    b->t = fg_arena_take(&a, (size_t)S * F);
    b->enc = fg_arena_take(&a, ld * (size_t)S * F);
    b->dacts = fg_arena_take(&a, 64 * (size_t)S * F);
    b->dout = fg_arena_take(&a, FG_FIELD_GEO_DIM * (size_t)S * F);
    b->cin = fg_arena_take(&a, 32 * (size_t)S * F);
    b->cacts = fg_arena_take(&a, 128 * (size_t)S * F);
    b->rgb = fg_arena_take(&a, 3 * (size_t)S * F);
    b->sigma = fg_arena_take(&a, (size_t)S * F);
    b->fenc = fg_arena_take(&a, lf * fs * F);
    b->facts = fg_arena_take(&a, 64 * fs * F);
    b->h = fg_arena_take(&a, 64 * fs * F);
    b->o = fg_arena_take(&a, 3 * (size_t)R * F);
    b->d = fg_arena_take(&a, 3 * (size_t)R * F);
    b->sh = fg_arena_take(&a, 16 * (size_t)R * F);
    b->hc = fg_arena_take(&a, 64 * fr * F);
    b->off = fg_arena_take(&a, (size_t)R * sizeof(int32_t));
    b->cnt = fg_arena_take(&a, (size_t)R * sizeof(int32_t));
  }
  b->mem = a.base;
  return 0;
}

/* Density network on S cube points b->x: sigma (1/cube unit) and the geo features. */
static void eval_density(const fg_field *f, infer_buf *b, int S, int nt) {
  fg_hashgrid_forward(&f->cfg.grid, fg_field_group_const(f, FG_FIELD_GRID, NULL), b->x, S,
                      b->enc, nt);
  fg_mlp_forward(&f->density_net, fg_field_group_const(f, FG_FIELD_DENSITY, NULL), b->enc, S,
                 b->dacts, b->dout, nt);
  for (int i = 0; i < S; i++) b->sigma[i] = b->dout[(size_t)i * FG_FIELD_GEO_DIM];
  fg_act_trunc_exp_forward(b->sigma, b->sigma, (size_t)S);
}

/* Feature network's hidden output h (S,64) on the S cube points b->x. */
static void eval_hidden(const fg_field *f, infer_buf *b, int S, int nt) {
  fg_hashgrid_forward(&f->cfg.feat_grid, fg_field_group_const(f, FG_FIELD_FEAT_GRID, NULL),
                      b->x, S, b->fenc, nt);
  fg_mlp_forward(&f->feat_net, fg_field_group_const(f, FG_FIELD_FEAT_MLP, NULL), b->fenc, S,
                 b->facts, b->h, nt);
  for (size_t i = 0; i < (size_t)S * FG_FIELD_FEATURE_HIDDEN; i++)
    if (!(b->h[i] > 0.0f)) b->h[i] = 0.0f;
}

/* out (n, D) = hidden (n, 64) @ W_out^T. */
static void apply_feat_out(const fg_field *f, const float *hidden, int64_t n, float *out) {
  const int D = f->cfg.feature_dim;
  const float *W = fg_field_group_const(f, FG_FIELD_FEAT_OUT, NULL);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)n, D, FG_FIELD_FEATURE_HIDDEN, 1.0f,
              hidden, FG_FIELD_FEATURE_HIDDEN, W, FG_FIELD_FEATURE_HIDDEN, 0.0f, out, D);
}

static int check_points(const fg_field *f, const float *x, int64_t B, const float *sigma) {
  if (!f || B < 0 || (B > 0 && (!x || !sigma)))
    return fg_fail(FG_EINVAL, "field: NULL field or point arrays, or negative count");
  return 0;
}

/* Density sigma (n) in 1/m at n world points x (n,3), through scratch b of at least n
 * samples. */
static void density_world(const fg_field *f, infer_buf *b, const float *x_world, int n,
                          float *sigma, int nt) {
  const float to_m = (float)(1.0 / f->cfg.box_size);
  fg_field_to_cube(f, x_world, n, b->x);
  eval_density(f, b, n, nt);
  for (int i = 0; i < n; i++) sigma[i] = b->sigma[i] * to_m;
}

int fg_field_density(const fg_field *f, const float *x_world, int64_t B, float *sigma,
                     int n_threads) {
  FG_TRY(check_points(f, x_world, B, sigma));
  infer_buf b;
  FG_TRY(infer_buf_new(&b, f, B < POINT_CHUNK ? B : POINT_CHUNK, 1));
  for (int64_t i0 = 0; i0 < B; i0 += POINT_CHUNK) {
    const int n = (int)(B - i0 < POINT_CHUNK ? B - i0 : POINT_CHUNK);
    density_world(f, &b, x_world + 3 * i0, n, sigma + i0, n_threads);
  }
  free(b.mem);
  return 0;
}

int fg_field_features(const fg_field *f, const float *x_world, int64_t B, float *sigma,
                      float *hidden, float *feat, int n_threads) {
  FG_TRY(check_points(f, x_world, B, sigma));
  if (f->cfg.feature_dim <= 0)
    return fg_fail(FG_EINVAL, "the field has no feature branch (its frames had no features)");
  infer_buf b;
  FG_TRY(infer_buf_new(&b, f, B < POINT_CHUNK ? B : POINT_CHUNK, 1));
  const float to_m = (float)(1.0 / f->cfg.box_size);
  const int D = f->cfg.feature_dim;
  for (int64_t i0 = 0; i0 < B; i0 += POINT_CHUNK) {
    const int n = (int)(B - i0 < POINT_CHUNK ? B - i0 : POINT_CHUNK);
    fg_field_to_cube(f, x_world + 3 * i0, n, b.x);
    eval_density(f, &b, n, n_threads);
    eval_hidden(f, &b, n, n_threads);
    for (int i = 0; i < n; i++) sigma[i0 + i] = b.sigma[i] * to_m;
    if (hidden) memcpy(hidden + i0 * 64, b.h, (size_t)n * 64 * sizeof(float));
    if (feat) apply_feat_out(f, b.h, n, feat + i0 * D);
  }
  free(b.mem);
  return 0;
}

/* The learned background of R rays with SH-encoded directions sh (R,16): bg (R,3). */
void fg_field_background(const fg_field *f, const float *sh, int64_t R, float *bg) {
  const float *W = fg_field_group_const(f, FG_FIELD_BACKGROUND, NULL);
  for (int64_t r = 0; r < R; r++)
    for (int c = 0; c < 3; c++) {
      float acc = 0.0f;
      for (int k = 0; k < FG_SH4_DIM; k++) acc += W[c * FG_SH4_DIM + k] * sh[r * FG_SH4_DIM + k];
      bg[3 * r + c] = acc;
    }
  fg_act_sigmoid_forward(bg, bg, (size_t)(3 * R));
}

/* Colour network on S samples whose rays' SH encodings are in b->sh: b->rgb (S,3). */
static void eval_colour(const fg_field *f, infer_buf *b, int R, int S, int nt) {
  for (int r = 0; r < R; r++)
    for (int32_t i = b->off[r]; i < b->off[r] + b->cnt[r]; i++) {
      memcpy(b->cin + (size_t)i * 32, b->sh + (size_t)r * 16, 16 * sizeof(float));
      memcpy(b->cin + (size_t)i * 32 + 16, b->dout + (size_t)i * 16, 16 * sizeof(float));
    }
  fg_mlp_forward(&f->colour_net, fg_field_group_const(f, FG_FIELD_COLOUR, NULL), b->cin, S,
                 b->cacts, b->rgb, nt);
  fg_act_sigmoid_forward(b->rgb, b->rgb, (size_t)S * 3);
}

/* Rendering marches in waves, as Instant-NGP's inference does: every live ray takes up to
 * WAVE_SAMPLES more samples from where it stopped, those are evaluated and composited, and
 * rays that left the cube, used their samples or became opaque (T < 1e-4) drop out. The
 * networks then see only the samples that count, not the occupied space behind a surface.
 * A ray resumes from its last sample shifted by half a step, so its samples stay on one
 * lattice with spacing dt. */
#define WAVE_SAMPLES 16
#define WAVE_RAYS (SAMPLE_CHUNK / WAVE_SAMPLES)

typedef struct ray_state {
  float T, rgb[3], depth; /* transmittance, accumulated colour, accumulated w t (cube) */
  float t0;               /* distance of the ray's current origin from its start (cube) */
  int32_t n;              /* samples used so far */
} ray_state;

int fg_field_render_rays(const fg_field *f, const float *rays_o, const float *rays_d, int64_t R,
                         const float bg[3], float *rgb, float *depth, float *opacity,
                         float *feat, int n_threads) {
  if (!f || R < 0 || (R > 0 && (!rays_o || !rays_d)))
    return fg_fail(FG_EINVAL, "render: NULL field or ray arrays, or negative count");
  if (feat && f->cfg.feature_dim <= 0)
    return fg_fail(FG_EINVAL, "the field has no feature branch (its frames had no features)");
  if (!bg && !f->cfg.learn_background)
    return fg_fail(FG_EINVAL, "render: no background given and the field learned none");
  const int D = f->cfg.feature_dim, H = FG_FIELD_FEATURE_HIDDEN;
  infer_buf b;
  FG_TRY(infer_buf_new(&b, f, SAMPLE_CHUNK, RAY_CHUNK));
  ray_state *st = malloc((size_t)RAY_CHUNK * sizeof *st);
  int32_t *live = malloc((size_t)RAY_CHUNK * sizeof(int32_t));
  float *o0 = malloc((size_t)RAY_CHUNK * 3 * sizeof(float));
  float *shr = malloc((size_t)RAY_CHUNK * 16 * sizeof(float));
  float *hacc = feat ? calloc((size_t)RAY_CHUNK * H, sizeof(float)) : NULL;
  int rc = 0;
  if (!st || !live || !o0 || !shr || (feat && !hacc)) {
    rc = fg_fail(FG_ENOMEM, "cannot allocate render scratch");
    goto out;
  }
  const float L = (float)f->cfg.box_size, dt = f->cfg.dt;
  for (int64_t r0 = 0; r0 < R; r0 += RAY_CHUNK) {
    const int n = (int)(R - r0 < RAY_CHUNK ? R - r0 : RAY_CHUNK);
    fg_field_to_cube(f, rays_o + 3 * r0, n, o0);
    fg_sh4_encode(rays_d + 3 * r0, n, shr);
    int n_live = 0;
    for (int r = 0; r < n; r++) {
      st[r] = (ray_state){.T = 1.0f};
      live[n_live++] = r;
    }
    if (feat) memset(hacc, 0, (size_t)n * H * sizeof(float));
    while (n_live > 0) {
      /* One wave over up to WAVE_RAYS live rays, the first n_wave of the list. */
      const int n_wave = n_live < WAVE_RAYS ? n_live : WAVE_RAYS;
      for (int i = 0; i < n_wave; i++) {
        const int r = live[i];
        const float *d = rays_d + 3 * (r0 + r);
        for (int k = 0; k < 3; k++) {
          b.o[3 * i + k] = o0[3 * r + k] + st[r].t0 * d[k];
          b.d[3 * i + k] = d[k];
        }
        memcpy(b.sh + 16 * i, shr + 16 * r, 16 * sizeof(float));
      }
      int32_t S = 0;
      rc = fg_occgrid_march(f->occ, n_wave, b.o, b.d, dt, WAVE_SAMPLES, 0, -1, SAMPLE_CHUNK,
                            b.off, b.cnt, b.x, b.dt, b.t, &S, n_threads);
      if (rc < 0) goto out;
      eval_density(f, &b, S, n_threads);
      if (rgb) eval_colour(f, &b, n_wave, S, n_threads); /* depth, opacity, normals: no colour */
      if (feat) eval_hidden(f, &b, S, n_threads);
#pragma omp parallel for schedule(static) num_threads(fg_threads(n_threads))
      for (int i = 0; i < n_wave; i++) {
        ray_state *s = &st[live[i]];
        float *ha = feat ? hacc + (size_t)live[i] * H : NULL;
        int done = b.cnt[i] < WAVE_SAMPLES; /* it left the cube */
        for (int32_t j = b.off[i]; j < b.off[i] + b.cnt[i]; j++) {
          if (s->T < 1e-4f || s->n >= FG_FIELD_MAX_SAMPLES_PER_RAY) {
            done = 1;
            break;
          }
          const float alpha = 1.0f - expf(-b.sigma[j] * b.dt[j]), w = s->T * alpha;
          if (rgb)
            for (int c = 0; c < 3; c++) s->rgb[c] += w * b.rgb[3 * (size_t)j + c];
          s->depth += w * (s->t0 + b.t[j]);
          if (ha)
            for (int k = 0; k < H; k++) ha[k] += w * b.h[(size_t)j * H + k];
          s->T *= 1.0f - alpha;
          s->n++;
        }
        if (s->T < 1e-4f || s->n >= FG_FIELD_MAX_SAMPLES_PER_RAY) done = 1;
        if (!done) s->t0 += b.t[b.off[i] + b.cnt[i] - 1] + 0.5f * dt;
        else s->n = -1 - s->n; /* marks the ray finished for the compaction below */
      }
      /* Keep the rays that go on, in order; rays beyond this wave wait for the next. */
      int m = 0;
      for (int i = 0; i < n_live; i++)
        if (st[live[i]].n >= 0) live[m++] = live[i];
      n_live = m;
    }
    for (int r = 0; r < n; r++) {
      const ray_state *s = &st[r];
      float bgc[3];
      if (bg) {
        memcpy(bgc, bg, sizeof bgc);
      } else {
        fg_field_background(f, shr + 16 * r, 1, bgc);
      }
      if (rgb)
        for (int c = 0; c < 3; c++) rgb[3 * (r0 + r) + c] = s->rgb[c] + s->T * bgc[c];
      if (depth) depth[r0 + r] = s->depth * L;
      if (opacity) opacity[r0 + r] = 1.0f - s->T;
    }
    if (feat) apply_feat_out(f, hacc, n, feat + r0 * D);
  }
out:
  free(hacc);
  free(shr);
  free(o0);
  free(live);
  free(st);
  free(b.mem);
  return rc;
}

/* ---- surfaces: gradients, normals, colours -------------------------------------------- */

/* Points per fg_field_density_gradient chunk (six samples each, ~20 MB of scratch), rays per
 * fg_field_render_normals chunk, points per fg_field_colour chunk (~15 MB). */
#define GRAD_CHUNK 2048
#define NORMAL_CHUNK 65536
#define COLOUR_CHUNK 8192

int fg_field_density_gradient(const fg_field *f, const float *x_world, int64_t B,
                              float step_m, float *grad, int n_threads) {
  FG_TRY(check_points(f, x_world, B, grad));
  if (!(step_m > 0.0f) || !isfinite(step_m))
    return fg_fail(FG_EINVAL, "density gradient: the step must be a positive length in "
                   "metres, got %g", (double)step_m);
  if (B == 0) return 0;
  const int chunk = (int)(B < GRAD_CHUNK ? B : GRAD_CHUNK);
  infer_buf b;
  FG_TRY(infer_buf_new(&b, f, 6 * (int64_t)chunk, 1));
  float *pts = malloc((size_t)chunk * 6 * 3 * sizeof *pts); /* (6 chunk, 3): +x -x +y -y +z -z */
  float *sig = malloc((size_t)chunk * 6 * sizeof *sig);     /* (6 chunk) */
  if (!pts || !sig) {
    free(pts), free(sig), free(b.mem);
    return fg_fail(FG_ENOMEM, "density gradient: out of memory");
  }
  const double inv_2h = 0.5 / (double)step_m;
  for (int64_t i0 = 0; i0 < B; i0 += chunk) {
    const int n = (int)(B - i0 < chunk ? B - i0 : chunk);
    for (int i = 0; i < n; i++)
      for (int s = 0; s < 6; s++) {
        float *q = pts + 3 * (6 * (size_t)i + (size_t)s);
        memcpy(q, x_world + 3 * (i0 + i), 3 * sizeof *q);
        q[s / 2] += s % 2 ? -step_m : step_m;
      }
    density_world(f, &b, pts, 6 * n, sig, n_threads);
    for (int i = 0; i < n; i++)
      for (int k = 0; k < 3; k++)
        grad[3 * (i0 + i) + k] =
            (float)(((double)sig[6 * i + 2 * k] - (double)sig[6 * i + 2 * k + 1]) * inv_2h);
  }
  free(pts);
  free(sig);
  free(b.mem);
  return 0;
}

int fg_field_colour(const fg_field *f, const float *x_world, const float *dirs, int64_t B,
                    float *rgb, int n_threads) {
  FG_TRY(check_points(f, x_world, B, rgb));
  if (B > 0 && !dirs) return fg_fail(FG_EINVAL, "field colour: NULL directions");
  if (B == 0) return 0;
  const int chunk = (int)(B < COLOUR_CHUNK ? B : COLOUR_CHUNK);
  infer_buf b;
  FG_TRY(infer_buf_new(&b, f, chunk, chunk));
  for (int64_t i0 = 0; i0 < B; i0 += chunk) {
    const int n = (int)(B - i0 < chunk ? B - i0 : chunk);
    /* n rays of one sample each: the colour network sees each point with its own direction. */
    for (int i = 0; i < n; i++) b.off[i] = i, b.cnt[i] = 1;
    fg_field_to_cube(f, x_world + 3 * i0, n, b.x);
    fg_sh4_encode(dirs + 3 * i0, n, b.sh);
    eval_density(f, &b, n, n_threads);
    eval_colour(f, &b, n, n, n_threads);
    memcpy(rgb + 3 * i0, b.rgb, (size_t)n * 3 * sizeof *rgb);
  }
  free(b.mem);
  return 0;
}

int fg_field_render_normals(const fg_field *f, const float *rays_o, const float *rays_d,
                            int64_t R, float step_m, float *normals, float *opacity,
                            int n_threads) {
  if (!f || R < 0 || (R > 0 && (!rays_o || !rays_d || !normals)))
    return fg_fail(FG_EINVAL, "render normals: NULL field or ray arrays, or negative count");
  if (!(step_m > 0.0f) || !isfinite(step_m))
    return fg_fail(FG_EINVAL, "render normals: the step must be a positive length in metres, "
                   "got %g", (double)step_m);
  if (R == 0) return 0;
  static const float black[3] = {0.0f, 0.0f, 0.0f}; /* no colour is rendered */
  const int chunk = (int)(R < NORMAL_CHUNK ? R : NORMAL_CHUNK);
  float *depth = malloc((size_t)chunk * sizeof *depth), *op = malloc((size_t)chunk * sizeof *op);
  float *p = malloc((size_t)chunk * 3 * sizeof *p), *g = malloc((size_t)chunk * 3 * sizeof *g);
  int *hit = malloc((size_t)chunk * sizeof *hit); /* rays of the chunk with some opacity */
  int rc = depth && op && p && g && hit ? 0 : fg_fail(FG_ENOMEM, "render normals: out of memory");
  for (int64_t r0 = 0; rc == 0 && r0 < R; r0 += chunk) {
    const int m = (int)(R - r0 < chunk ? R - r0 : chunk);
    rc = fg_field_render_rays(f, rays_o + 3 * r0, rays_d + 3 * r0, m, black, NULL, depth, op,
                              NULL, n_threads);
    if (rc != 0) break;
    int n_hit = 0;
    for (int i = 0; i < m; i++) {
      float *n = normals + 3 * (r0 + i);
      n[0] = n[1] = n[2] = 0.0f;
      if (!(op[i] > 0.0f) || !isfinite(depth[i])) continue;
      const float t = depth[i] / op[i]; /* expected termination distance, metres */
      for (int k = 0; k < 3; k++)
        p[3 * n_hit + k] = rays_o[3 * (r0 + i) + k] + t * rays_d[3 * (r0 + i) + k];
      hit[n_hit++] = i;
    }
    rc = fg_field_density_gradient(f, p, n_hit, step_m, g, n_threads);
    for (int q = 0; rc == 0 && q < n_hit; q++) {
      const double gx = g[3 * q], gy = g[3 * q + 1], gz = g[3 * q + 2];
      const double len = sqrt(gx * gx + gy * gy + gz * gz);
      if (!(len > 0.0) || !isfinite(len)) continue;
      float *n = normals + 3 * (r0 + hit[q]);
      n[0] = (float)(-gx / len), n[1] = (float)(-gy / len), n[2] = (float)(-gz / len);
    }
    if (rc == 0 && opacity) memcpy(opacity + r0, op, (size_t)m * sizeof *op);
  }
  free(depth), free(op), free(p), free(g), free(hit);
  return rc;
}
