#include "field/train.h"

#include <cblas.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core/arena.h"
#include "core/blas.h"
#include "core/error.h"
#include "core/half.h"
#include "core/rng.h"
#include "field/adam.h"
#include "field/render.h"
#include "field/sh.h"

#define OCC_UPDATE_INTERVAL 16 /* Instant-NGP refreshes its grid every 16 steps */
#define MIN_RAYS 64
#define MAX_RAYS 65536
#define EVAL_PIXELS 16384
#define T_MIN 1e-4f /* transmittance at which a ray stops */

/* ---- random streams: a hash of (seed, step, index, stream), as in occupancy.c ------------ */

enum { STREAM_FRAME = 1, STREAM_PIXEL, STREAM_JITTER, STREAM_EVAL };


static inline uint64_t hash4(uint64_t seed, int64_t step, uint64_t index, uint64_t stream) {
  uint64_t h = fg_mix64(seed + 0x9e3779b97f4a7c15ull);
  h = fg_mix64(h ^ ((uint64_t)step + 0x632be59bd9b4e019ull));
  h = fg_mix64(h ^ (index * 4 + stream));
  return h;
}

static inline float unit24(uint64_t h, int shift) { /* uniform in [0, 1) */
  return (float)((h >> shift) & 0xffffffu) * (1.0f / 16777216.0f);
}

static inline uint32_t below(uint64_t h, uint32_t n) { /* uniform in [0, n) */
  return (uint32_t)(((h >> 32) * (uint64_t)n) >> 32);
}

/* ---- the trainer ---------------------------------------------------------------------- */

struct fg_trainer {
  fg_field *f;
  const fg_frame *frames;
  fg_train_opts opts;
  size_t *train_idx, n_train;  /* frames drawn for colour */
  size_t *feat_idx, n_feat;    /* training frames with features */
  size_t *held_idx, n_held;    /* held-out frames */
  int D;                       /* feature dim (0: no feature branch) */
  int geometry;                /* the depth or distortion loss is on */
  int64_t step;
  int32_t n_rays;              /* rays of the next step */
  int32_t cap_s, cap_r;        /* sample and ray capacity */

  /* Optimiser state: grads, m, v in the parameter layout. */
  float *grad, *m, *v;
  fg_adam_config adam_table, adam_mlp;

  /* Per ray. */
  float *o, *d, *sh, *bg, *target, *out_rgb, *out_opacity, *d_out_rgb, *zero_rgb, *frgb;
  float *depth_z, *ones;       /* measured distance along the ray (cube units, 0: none); 1s */
  float *ftarget, *hc, *fpred, *d_fpred, *d_hc; /* feature rays (R_f, .) */
  int32_t *off, *cnt, *used, *used_f;
  /* Per sample. */
  float *x, *dts, *ts, *enc, *dacts, *dout, *cin, *cacts, *rgb, *sigma;
  float *d_sigma, *d_rgb, *d_cin, *d_dout, *d_enc;
  float *fenc, *facts, *h, *d_h, *d_fenc, *d_sigma_f, *d_rgb_f;
  float *wg, *d_sigma_g, *d_rgb_g; /* geometry losses: dL/dw, and their backward's output */
  float *mlp_scratch;
  /* Occupancy updates. */
  int32_t *occ_cells;
  float *occ_x, *occ_sigma;
  int32_t occ_cap;
  void *mem;
  /* Focus (fg_trainer_focus): the kept cells, over the training frames and those with
   * features, and the share of rays drawn from them. */
  struct focus_cell *focus, *focus_f;
  size_t n_focus, n_focus_f;
  float focus_fraction;
};

void fg_train_opts_default(fg_train_opts *o) {
  memset(o, 0, sizeof *o);
  o->n_threads = 1;
  o->target_samples = 1 << 17;
  o->feature_ray_fraction = 0.25f;
  o->feature_weight = 1.0f;
  o->lr = 1e-2f;
  o->background[0] = o->background[1] = o->background[2] = 1.0f;
  o->depth_weight = (float)FG_TRAIN_DEPTH_WEIGHT;
  o->distortion_weight = (float)FG_TRAIN_DISTORTION_WEIGHT;
  o->depth_margin = (float)FG_TRAIN_DEPTH_MARGIN;
}

static int check_opts(const fg_train_opts *o) {
  if (o->n_threads < 1 || o->n_threads > 1024)
    return fg_fail(FG_EINVAL, "training threads must be in [1, 1024], got %d", o->n_threads);
  if (o->holdout_every < 0) return fg_fail(FG_EINVAL, "holdout_every must be >= 0");
  if (o->target_samples < 4096 || o->target_samples > (1 << 22))
    return fg_fail(FG_EINVAL, "target_samples must be in [4096, 2^22], got %d",
                   o->target_samples);
  if (!(o->feature_ray_fraction > 0.0f && o->feature_ray_fraction <= 1.0f))
    return fg_fail(FG_EINVAL, "feature_ray_fraction must be in (0, 1]");
  if (!(o->feature_weight >= 0.0f && isfinite(o->feature_weight)))
    return fg_fail(FG_EINVAL, "feature_weight must be finite and >= 0");
  if (!(o->lr > 0.0f && o->lr < 1.0f)) return fg_fail(FG_EINVAL, "lr must be in (0, 1)");
  if (!(o->depth_weight >= 0.0f && isfinite(o->depth_weight)))
    return fg_fail(FG_EINVAL, "depth_weight must be finite and >= 0");
  if (!(o->depth_margin > 0.0f && o->depth_margin < 1.0f))
    return fg_fail(FG_EINVAL, "depth_margin must be in (0, 1) metres");
  if (!(o->distortion_weight >= 0.0f && isfinite(o->distortion_weight)))
    return fg_fail(FG_EINVAL, "distortion_weight must be finite and >= 0");
  for (int c = 0; c < 3; c++)
    if (!(o->background[c] >= 0.0f && o->background[c] <= 1.0f))
      return fg_fail(FG_EINVAL, "background must be in [0, 1]");
  return 0;
}

static int32_t feature_rays(const fg_trainer *t, int32_t R) {
  if (!t->D || !t->n_feat) return 0;
  int32_t rf = (int32_t)ceilf(t->opts.feature_ray_fraction * (float)R);
  return rf < 1 ? 1 : (rf > R ? R : rf);
}

static void trainer_carve(fg_trainer *t, fg_arena *a) {
  const size_t F = sizeof(float), S = (size_t)t->cap_s, R = (size_t)t->cap_r;
  const size_t P = t->f->n_params, ld = (size_t)t->f->density_net.n_in;
  const size_t fs = t->D ? S : 0, fr = t->D ? R : 0, lf = (size_t)t->f->feat_net.n_in;
  const size_t gs = t->geometry ? S : 0, gr = t->geometry ? R : 0;
  const size_t D = (size_t)t->D;
  t->grad = fg_arena_take(a, P * F);
  t->m = fg_arena_take(a, P * F);
  t->v = fg_arena_take(a, P * F);
  t->o = fg_arena_take(a, 3 * R * F);
  t->d = fg_arena_take(a, 3 * R * F);
  t->sh = fg_arena_take(a, 16 * R * F);
  t->bg = fg_arena_take(a, 3 * R * F);
  t->target = fg_arena_take(a, 3 * R * F);
  t->out_rgb = fg_arena_take(a, 3 * R * F);
  t->out_opacity = fg_arena_take(a, R * F);
  t->d_out_rgb = fg_arena_take(a, 3 * R * F);
  t->zero_rgb = fg_arena_take(a, 3 * (fr > gr ? fr : gr) * F);
  t->depth_z = fg_arena_take(a, gr * F);
  t->ones = fg_arena_take(a, gr * F);
  t->wg = fg_arena_take(a, gs * F);
  t->d_sigma_g = fg_arena_take(a, gs * F);
  t->d_rgb_g = fg_arena_take(a, 3 * gs * F);
  t->frgb = fg_arena_take(a, 3 * fr * F);
  t->ftarget = fg_arena_take(a, D * fr * F);
  t->hc = fg_arena_take(a, 64 * fr * F);
  t->fpred = fg_arena_take(a, D * fr * F);
  t->d_fpred = fg_arena_take(a, D * fr * F);
  t->d_hc = fg_arena_take(a, 64 * fr * F);
  t->off = fg_arena_take(a, R * sizeof(int32_t));
  t->cnt = fg_arena_take(a, R * sizeof(int32_t));
  t->used = fg_arena_take(a, R * sizeof(int32_t));
  t->used_f = fg_arena_take(a, fr * sizeof(int32_t));
  t->x = fg_arena_take(a, 3 * S * F);
  t->dts = fg_arena_take(a, S * F);
  t->ts = fg_arena_take(a, S * F);
  t->enc = fg_arena_take(a, ld * S * F);
  t->dacts = fg_arena_take(a, 64 * S * F);
  t->dout = fg_arena_take(a, 16 * S * F);
  t->cin = fg_arena_take(a, 32 * S * F);
  t->cacts = fg_arena_take(a, 128 * S * F);
  t->rgb = fg_arena_take(a, 3 * S * F);
  t->sigma = fg_arena_take(a, S * F);
  t->d_sigma = fg_arena_take(a, S * F);
  t->d_rgb = fg_arena_take(a, 3 * S * F);
  t->d_cin = fg_arena_take(a, 32 * S * F);
  t->d_dout = fg_arena_take(a, 16 * S * F);
  t->d_enc = fg_arena_take(a, ld * S * F);
  t->fenc = fg_arena_take(a, lf * fs * F);
  t->facts = fg_arena_take(a, 64 * fs * F);
  t->h = fg_arena_take(a, 64 * fs * F);
  t->d_h = fg_arena_take(a, 64 * fs * F);
  t->d_fenc = fg_arena_take(a, lf * fs * F);
  t->d_sigma_f = fg_arena_take(a, fs * F);
  t->d_rgb_f = fg_arena_take(a, 3 * fs * F);
  size_t scratch = fg_mlp_scratch_floats(&t->f->density_net, t->cap_s);
  const size_t sc = fg_mlp_scratch_floats(&t->f->colour_net, t->cap_s);
  if (sc > scratch) scratch = sc;
  if (t->D) {
    const size_t sf = fg_mlp_scratch_floats(&t->f->feat_net, t->cap_s);
    if (sf > scratch) scratch = sf;
  }
  t->mlp_scratch = fg_arena_take(a, scratch * F);
  t->occ_cells = fg_arena_take(a, (size_t)t->occ_cap * sizeof(int32_t));
  t->occ_x = fg_arena_take(a, 3 * (size_t)t->occ_cap * F);
  t->occ_sigma = fg_arena_take(a, (size_t)t->occ_cap * F);
}

int fg_trainer_new(fg_trainer **out, fg_field *field, const fg_frame *frames, size_t n,
                   const fg_train_opts *opts) {
  *out = NULL;
  if (!field || (n && !frames) || !opts)
    return fg_fail(FG_EINVAL, "trainer: NULL field, frames or options");
  FG_TRY(check_opts(opts));
  const int D = field->cfg.feature_dim;
  for (size_t i = 0; i < n; i++) {
    const fg_frame *fr = &frames[i];
    if (!fr->rgb || fr->cam.w < 1 || fr->cam.h < 1)
      return fg_fail(FG_EINVAL, "frame %zu has no pixels loaded", i);
    if (fr->feat_d && fr->feat_d != D)
      return fg_fail(FG_EINVAL, "frame %zu has %d-d features but the field has %d", i,
                     fr->feat_d, D);
    if (fr->feat_d && (!fr->feat || (fr->feat_dtype != FG_DTYPE_F32 &&
                                     fr->feat_dtype != FG_DTYPE_F16)))
      return fg_fail(FG_EINVAL, "frame %zu has features of an unsupported type", i);
  }
  fg_trainer *t = calloc(1, sizeof *t);
  if (!t) return fg_fail(FG_ENOMEM, "cannot allocate a trainer");
  t->f = field;
  t->frames = frames;
  t->opts = *opts;
  t->D = D;
  t->train_idx = calloc(n ? n : 1, sizeof(size_t));
  t->feat_idx = calloc(n ? n : 1, sizeof(size_t));
  t->held_idx = calloc(n ? n : 1, sizeof(size_t));
  if (!t->train_idx || !t->feat_idx || !t->held_idx) goto nomem;
  for (size_t i = 0; i < n; i++) {
    if (opts->holdout_every > 0 && i % (size_t)opts->holdout_every == 0) {
      t->held_idx[t->n_held++] = i;
      continue;
    }
    t->train_idx[t->n_train++] = i;
    if (frames[i].feat_d) t->feat_idx[t->n_feat++] = i;
  }
  int has_depth = 0;
  for (size_t k = 0; k < t->n_train; k++) has_depth |= frames[t->train_idx[k]].depth != NULL;
  t->geometry = (has_depth && opts->depth_weight > 0.0f) || opts->distortion_weight > 0.0f;
  if (!t->n_train) {
    const size_t n_held = t->n_held;
    fg_trainer_free(t);
    return fg_fail(FG_EINVAL, "no frame left to train on (%zu frames, %zu held out)", n, n_held);
  }
  t->cap_s = opts->target_samples + opts->target_samples / 2;
  t->cap_r = MAX_RAYS;
  /* The first steps march a fully occupied grid: few rays, many samples each. */
  t->n_rays = opts->target_samples / 256 < MIN_RAYS ? MIN_RAYS : opts->target_samples / 256;
  t->occ_cap = fg_occgrid_update_count(field->occ, 0, FG_OCCGRID_DEFAULT_WARMUP_STEPS, 0);
  fg_adam_config_default(&t->adam_mlp);
  t->adam_mlp.lr = opts->lr;
  t->adam_table = t->adam_mlp;
  t->adam_table.l2 = 0.0f;
  t->adam_table.skip_zero_grad = 1;
  fg_arena a = {0};
  for (int pass = 0; pass < 2; pass++) {
    if (pass && fg_arena_alloc(&a) < 0) goto nomem;
    trainer_carve(t, &a);
  }
  t->mem = a.base;
  memset(t->m, 0, field->n_params * sizeof(float));
  memset(t->v, 0, field->n_params * sizeof(float));
  if (t->D || t->geometry) memset(t->zero_rgb, 0, (size_t)t->cap_r * 3 * sizeof(float));
  if (t->geometry) {
    memset(t->depth_z, 0, (size_t)t->cap_r * sizeof(float));
    for (int32_t r = 0; r < t->cap_r; r++) t->ones[r] = 1.0f;
  }
  t->step = field->trained_steps;
  *out = t;
  return 0;
nomem:
  fg_trainer_free(t);
  return fg_fail(FG_ENOMEM, "cannot allocate the trainer's buffers");
}

void fg_trainer_free(fg_trainer *t) {
  if (!t) return;
  free(t->mem);
  free(t->train_idx);
  free(t->feat_idx);
  free(t->held_idx);
  free(t->focus);
  free(t->focus_f);
  free(t);
}

size_t fg_trainer_n_heldout(const fg_trainer *t) { return t->n_held; }

/* ---- rays ----------------------------------------------------------------------------- */

/* World ray through pixel position (px, py) (pixel units, corner origin) of frame fr, in the
 * field's cube: o (3), d (3, unit). Returns the ray's length per metre of z-depth. */
static double frame_ray(const fg_field *f, const fg_frame *fr, float px, float py, float *o,
                        float *d) {
  const double *T = fr->T_world_cam;
  const double dc[3] = {(px - fr->cam.cx) / fr->cam.fl_x, -(py - fr->cam.cy) / fr->cam.fl_y,
                        -1.0};
  double dw[3], norm = 0.0;
  for (int k = 0; k < 3; k++) {
    dw[k] = T[4 * k + 0] * dc[0] + T[4 * k + 1] * dc[1] + T[4 * k + 2] * dc[2];
    norm += dw[k] * dw[k];
  }
  norm = sqrt(norm);
  for (int k = 0; k < 3; k++) {
    o[k] = (float)((T[4 * k + 3] - f->cfg.box_min[k]) / f->cfg.box_size);
    d[k] = (float)(dw[k] / norm);
  }
  return norm; /* |dc| with a unit z component; rotation keeps it */
}

static inline void pixel_rgb(const fg_frame *fr, int u, int v, float *rgb) {
  const uint16_t *p = fr->rgb + ((size_t)v * (size_t)fr->cam.w + (size_t)u) * 3;
  for (int c = 0; c < 3; c++) rgb[c] = (float)p[c] * (1.0f / 65535.0f);
}

/* The feature cell of pixel (u, v) per SPEC.md "Files", as floats into out (D). */
static void pixel_feature(const fg_frame *fr, int u, int v, float *out) {
  const int cy = (int)((int64_t)v * fr->feat_h / fr->cam.h);
  const int cx = (int)((int64_t)u * fr->feat_w / fr->cam.w);
  const size_t at = ((size_t)cy * (size_t)fr->feat_w + (size_t)cx) * (size_t)fr->feat_d;
  if (fr->feat_dtype == FG_DTYPE_F32) {
    memcpy(out, (const float *)fr->feat + at, (size_t)fr->feat_d * sizeof(float));
  } else {
    const uint16_t *h = (const uint16_t *)fr->feat + at;
    for (int k = 0; k < fr->feat_d; k++) out[k] = fg_half_to_float(h[k]);
  }
}

/* The measured z-depth (m) at pixel position (px, py) (pixel units, corner origin) for the
 * depth loss, or 0 for none: bilinear between the four pixel centres around it, so that a
 * jittered ray on a slanted surface gets the depth its own position has (nearest would be
 * off by up to half the step to a neighbour, more than the margin at grazing angles). None
 * where the frame has no depth, one of the four has none, or they differ by more than
 * margin: at a depth edge one value stands for two surfaces (a ray may meet either, and real
 * sensors put "flying pixels" there). */
static float pixel_depth(const fg_frame *fr, float px, float py, float margin) {
  if (!fr->depth) return 0.0f;
  const int w = fr->cam.w, h = fr->cam.h;
  float x = px - 0.5f, y = py - 0.5f;
  x = x < 0.0f ? 0.0f : x > (float)(w - 1) ? (float)(w - 1) : x;
  y = y < 0.0f ? 0.0f : y > (float)(h - 1) ? (float)(h - 1) : y;
  const int x0 = (int)x, y0 = (int)y, x1 = x0 + 1 < w ? x0 + 1 : x0, y1 = y0 + 1 < h ? y0 + 1 : y0;
  const float fx = x - (float)x0, fy = y - (float)y0;
  const float *d = fr->depth;
  const float z00 = d[(size_t)y0 * (size_t)w + (size_t)x0], z01 = d[(size_t)y0 * (size_t)w + (size_t)x1];
  const float z10 = d[(size_t)y1 * (size_t)w + (size_t)x0], z11 = d[(size_t)y1 * (size_t)w + (size_t)x1];
  float lo = z00, hi = z00;
  const float c[3] = {z01, z10, z11};
  for (int k = 0; k < 3; k++) {
    lo = c[k] < lo ? c[k] : lo;
    hi = c[k] > hi ? c[k] : hi;
  }
  if (!(lo > 0.0f) || !(hi - lo <= margin)) return 0.0f;
  return (z00 * (1.0f - fx) + z01 * fx) * (1.0f - fy) + (z10 * (1.0f - fx) + z11 * fx) * fy;
}

/* ---- focus: where the views changed (fg_trainer_focus) ---------------------------------- */

typedef struct focus_cell {
  uint32_t frame;        /* index into frames */
  uint16_t cu, cv, side; /* the cell's column and row, and its side (focus_side) */
} focus_cell;

/* The cell side (pixels) for a w x h frame: FG_TRAIN_FOCUS_CELL, or more so that about 4096
 * cells cover it. */
static int focus_side(int w, int h) {
  const int s = (int)ceil(sqrt((double)w * (double)h / 4096.0));
  return s > FG_TRAIN_FOCUS_CELL ? s : FG_TRAIN_FOCUS_CELL;
}

/* Draws the step's R rays (the first R_f from frames with features), each jittered within its
 * pixel, with the depth measured at its position (pixel_depth); with a focus, a share of them
 * from its kept cells. */
static void draw_rays(fg_trainer *t, int32_t R, int32_t R_f) {
  const uint64_t seed = t->opts.seed;
  const int64_t step = t->step;
#pragma omp parallel for schedule(static) num_threads(t->opts.n_threads)
  for (int32_t r = 0; r < R; r++) {
    const uint64_t hp = hash4(seed, step, (uint64_t)r, STREAM_PIXEL);
    const uint64_t hj = hash4(seed, step, (uint64_t)r, STREAM_JITTER);
    const focus_cell *fc = NULL;
    const size_t n_fc = r < R_f ? t->n_focus_f : t->n_focus;
    if (n_fc && t->focus_fraction > 0.0f) {
      const uint64_t hf = fg_mix64(hj ^ 0x243f6a8885a308d3ull);
      if (unit24(hf, 0) < t->focus_fraction)
        fc = (r < R_f ? t->focus_f : t->focus) + below(hf, (uint32_t)n_fc);
    }
    size_t fi;
    if (fc)
      fi = fc->frame;
    else if (r < R_f)
      fi = t->feat_idx[below(hash4(seed, step, (uint64_t)r, STREAM_FRAME), (uint32_t)t->n_feat)];
    else
      fi = t->train_idx[below(hash4(seed, step, (uint64_t)r, STREAM_FRAME), (uint32_t)t->n_train)];
    const fg_frame *fr = &t->frames[fi];
    int u, v;
    if (fc) {
      const int side = fc->side;
      const int u0 = fc->cu * side, v0 = fc->cv * side;
      u = u0 + (int)below(hp, (uint32_t)(fr->cam.w - u0 < side ? fr->cam.w - u0 : side));
      v = v0 + (int)below(hp << 32, (uint32_t)(fr->cam.h - v0 < side ? fr->cam.h - v0 : side));
    } else {
      u = (int)below(hp, (uint32_t)fr->cam.w);
      v = (int)below(hp << 32, (uint32_t)fr->cam.h);
    }
    const float px = (float)u + unit24(hj, 0), py = (float)v + unit24(hj, 24);
    const float z = t->geometry && t->opts.depth_weight > 0.0f
                        ? pixel_depth(fr, px, py, t->opts.depth_margin)
                        : 0.0f;
    const double per_z = frame_ray(t->f, fr, px, py, t->o + 3 * r, t->d + 3 * r);
    pixel_rgb(fr, u, v, t->target + 3 * r);
    if (t->geometry) t->depth_z[r] = (float)(z * per_z / t->f->cfg.box_size); /* 0: none */
    if (r < R_f) pixel_feature(fr, u, v, t->ftarget + (size_t)r * (size_t)t->D);
  }
}

/* Which cells of frame fr changed (changed[nx * ny]), before rendered at their centres
 * through the rays' buffers o, d, ow (3 * nx * ny each) and out (5 * nx * ny). */
static int focus_frame(const fg_trainer *t, const fg_field *before, const fg_frame *fr, int side,
                       int nx, int ny, float *o, float *d, float *ow, float *out,
                       unsigned char *changed) {
  const int n = nx * ny;
  const fg_field *f = t->f;
  float *rgb = out, *dist = out + 3 * (size_t)n, *opacity = out + 4 * (size_t)n;
  double *per_z = malloc((size_t)n * sizeof *per_z);
  if (!per_z) return fg_fail(FG_ENOMEM, "cannot allocate the focus's rays");
  for (int c = 0; c < n; c++) {
    const int u = (c % nx) * side + side / 2, v = (c / nx) * side + side / 2;
    const float px = (float)(u < fr->cam.w ? u : fr->cam.w - 1) + 0.5f;
    const float py = (float)(v < fr->cam.h ? v : fr->cam.h - 1) + 0.5f;
    per_z[c] = frame_ray(f, fr, px, py, o + 3 * c, d + 3 * c);
    for (int k = 0; k < 3; k++)
      ow[3 * c + k] = (float)(o[3 * c + k] * f->cfg.box_size + f->cfg.box_min[k]);
  }
  int rc = fg_field_render_rays(before, ow, d, n,
                                before->cfg.learn_background ? NULL : t->opts.background, rgb,
                                dist, opacity, NULL, t->opts.n_threads);
  for (int c = 0; c < n && rc == 0; c++) {
    const int u = (c % nx) * side + side / 2, v = (c / nx) * side + side / 2;
    const int uu = u < fr->cam.w ? u : fr->cam.w - 1, vv = v < fr->cam.h ? v : fr->cam.h - 1;
    float ref[3];
    pixel_rgb(fr, uu, vv, ref);
    const float drgb = (fabsf(rgb[3 * c] - ref[0]) + fabsf(rgb[3 * c + 1] - ref[1]) +
                        fabsf(rgb[3 * c + 2] - ref[2])) / 3.0f;
    changed[c] = drgb > FG_TRAIN_FOCUS_RGB;
    const float zm = pixel_depth(fr, (float)uu + 0.5f, (float)vv + 0.5f, t->opts.depth_margin);
    if (changed[c] || !(zm > 0.0f)) continue;
    const double along = zm * per_z[c] / f->cfg.box_size; /* cube units */
    int inside = 1;
    for (int k = 0; k < 3; k++) {
      const double x = o[3 * c + k] + d[3 * c + k] * along;
      inside &= x >= 0.0 && x <= 1.0;
    }
    if (!inside) continue;
    changed[c] = opacity[c] < 0.5f ||
                 fabs(dist[c] / opacity[c] / per_z[c] - zm) > FG_TRAIN_FOCUS_DEPTH;
  }
  free(per_z);
  return rc;
}

int fg_trainer_focus(fg_trainer *t, const fg_field *before, float fraction,
                     fg_train_focus_stats *stats) {
  if (!before || !(fraction >= 0.0f && fraction <= 1.0f))
    return fg_fail(FG_EINVAL, "focus: no field before, or a fraction outside [0, 1]");
  char why[160];
  if (!fg_field_config_same(&before->cfg, &t->f->cfg, why, sizeof why))
    return fg_fail(FG_EINVAL, "focus: the field before differs from the trainer's: %s", why);
  free(t->focus);
  free(t->focus_f);
  t->focus = t->focus_f = NULL;
  t->n_focus = t->n_focus_f = 0;
  t->focus_fraction = 0.0f;
  fg_train_focus_stats st = {0};
  size_t cap = 0, max_cells = 0;
  for (size_t k = 0; k < t->n_train; k++) {
    const fg_frame *fr = &t->frames[t->train_idx[k]];
    const int side = focus_side(fr->cam.w, fr->cam.h);
    const size_t n = (size_t)((fr->cam.w + side - 1) / side) * (size_t)((fr->cam.h + side - 1) / side);
    cap += n;
    max_cells = n > max_cells ? n : max_cells;
  }
  float *buf = malloc(max_cells * 14 * sizeof(float));
  unsigned char *changed = malloc(max_cells);
  t->focus = malloc(cap * sizeof *t->focus);
  t->focus_f = malloc(cap * sizeof *t->focus_f);
  int rc = buf && changed && t->focus && t->focus_f
             ? 0 : fg_fail(FG_ENOMEM, "cannot allocate the focus's cells");
  for (size_t k = 0; k < t->n_train && rc == 0; k++) {
    const size_t fi = t->train_idx[k];
    const fg_frame *fr = &t->frames[fi];
    const int side = focus_side(fr->cam.w, fr->cam.h);
    const int nx = (fr->cam.w + side - 1) / side, ny = (fr->cam.h + side - 1) / side;
    const size_t n = (size_t)nx * (size_t)ny;
    rc = focus_frame(t, before, fr, side, nx, ny, buf, buf + 3 * n, buf + 6 * n, buf + 9 * n,
                     changed);
    for (int c = 0; c < (int)n && rc == 0; c++) {
      const int cu = c % nx, cv = c / nx;
      int near = 0;
      for (int y = cv - 1; y <= cv + 1 && !near; y++)
        for (int x = cu - 1; x <= cu + 1 && !near; x++)
          near = x >= 0 && x < nx && y >= 0 && y < ny && changed[y * nx + x];
      st.cells++;
      st.changed += changed[c];
      if (!near) continue;
      const focus_cell fc = {(uint32_t)fi, (uint16_t)cu, (uint16_t)cv, (uint16_t)side};
      t->focus[t->n_focus++] = fc;
      if (fr->feat_d) t->focus_f[t->n_focus_f++] = fc;
    }
  }
  free(changed);
  free(buf);
  if (rc != 0) {
    t->n_focus = t->n_focus_f = 0;
    return rc;
  }
  st.kept = (int64_t)t->n_focus;
  t->focus_fraction = fraction;
  if (stats) *stats = st;
  return 0;
}

/* Marches R rays; when their samples exceed the capacity, keeps the longest prefix of rays
 * that fits and marches that again (same seed and step: the same samples). Returns the
 * number of rays kept and their sample count in *S. */
static int32_t march(fg_trainer *t, int32_t R, int32_t *S) {
  fg_field *f = t->f;
  int rc = fg_occgrid_march(f->occ, R, t->o, t->d, f->cfg.dt, FG_FIELD_MAX_SAMPLES_PER_RAY,
                            t->opts.seed, (int32_t)t->step, t->cap_s, t->off, t->cnt, t->x,
                            t->dts, t->ts, S, t->opts.n_threads);
  if (rc == FG_ERANGE) {
    int32_t keep = 0;
    for (int64_t acc = 0; keep < R && acc + t->cnt[keep] <= t->cap_s; keep++) acc += t->cnt[keep];
    R = keep;
    rc = fg_occgrid_march(f->occ, R, t->o, t->d, f->cfg.dt, FG_FIELD_MAX_SAMPLES_PER_RAY,
                          t->opts.seed, (int32_t)t->step, t->cap_s, t->off, t->cnt, t->x,
                          t->dts, t->ts, S, t->opts.n_threads);
  }
  return rc < 0 ? 0 : R; /* rc < 0 only for arguments checked above */
}

/* ---- forward and backward ------------------------------------------------------------- */

/* sigma (S) and geo (S,16) of the density network, colour rgb (S,3) of the colour network,
 * for the S samples of R rays. */
static void forward_colour(fg_trainer *t, int32_t R, int32_t S) {
  fg_field *f = t->f;
  const int nt = t->opts.n_threads;
  fg_hashgrid_forward(&f->cfg.grid, fg_field_group(f, FG_FIELD_GRID, NULL), t->x, S, t->enc, nt);
  fg_mlp_forward(&f->density_net, fg_field_group(f, FG_FIELD_DENSITY, NULL), t->enc, S, t->dacts,
                 t->dout, nt);
#pragma omp parallel for schedule(static) num_threads(nt)
  for (int32_t r = 0; r < R; r++)
    for (int32_t i = t->off[r]; i < t->off[r] + t->cnt[r]; i++) {
      memcpy(t->cin + (size_t)i * 32, t->sh + (size_t)r * 16, 16 * sizeof(float));
      memcpy(t->cin + (size_t)i * 32 + 16, t->dout + (size_t)i * 16, 16 * sizeof(float));
      t->sigma[i] = t->dout[(size_t)i * 16];
    }
  fg_act_trunc_exp_forward(t->sigma, t->sigma, (size_t)S);
  fg_mlp_forward(&f->colour_net, fg_field_group(f, FG_FIELD_COLOUR, NULL), t->cin, S, t->cacts,
                 t->rgb, nt);
  fg_act_sigmoid_forward(t->rgb, t->rgb, (size_t)S * 3);
}

/* The feature branch on the S_f samples of the first R_f rays: h (S_f,64), composited per
 * ray into hc (R_f,64), then fpred (R_f,D) = hc W_out^T. */
static void forward_features(fg_trainer *t, int32_t R_f, int32_t S_f) {
  fg_field *f = t->f;
  const int nt = t->opts.n_threads;
  fg_hashgrid_forward(&f->cfg.feat_grid, fg_field_group(f, FG_FIELD_FEAT_GRID, NULL), t->x, S_f,
                      t->fenc, nt);
  fg_mlp_forward(&f->feat_net, fg_field_group(f, FG_FIELD_FEAT_MLP, NULL), t->fenc, S_f,
                 t->facts, t->h, nt);
  for (size_t i = 0; i < (size_t)S_f * 64; i++)
    if (!(t->h[i] > 0.0f)) t->h[i] = 0.0f;
  fg_render_forward(R_f, t->off, t->cnt, t->sigma, t->rgb, t->dts, t->ts, t->h, 64, t->bg, 1,
                    T_MIN, t->frgb, NULL, NULL, t->hc,
                    t->used_f, nt);
  const int blas = fg_blas_single_begin();
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, R_f, t->D, 64, 1.0f, t->hc, 64,
              fg_field_group(f, FG_FIELD_FEAT_OUT, NULL), 64, 0.0f, t->fpred, t->D);
  fg_blas_single_end(blas);
}

/* Back-propagates the feature loss d_fpred (R_f,D) into the feature branch's gradients (not
 * into the density: the feature loss follows the geometry colour found). */
static void backward_features(fg_trainer *t, int32_t R_f, int32_t S_f) {
  fg_field *f = t->f;
  const int nt = t->opts.n_threads, D = t->D;
  float *g_out = t->grad + f->group_offset[FG_FIELD_FEAT_OUT];
  /* dW_out (D,64) += d_fpred^T hc;  d_hc (R_f,64) = d_fpred W_out. */
  const int blas = fg_blas_single_begin();
  cblas_sgemm(CblasRowMajor, CblasTrans, CblasNoTrans, D, 64, R_f, 1.0f, t->d_fpred, D, t->hc, 64,
              1.0f, g_out, 64);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, R_f, 64, D, 1.0f, t->d_fpred, D,
              fg_field_group(f, FG_FIELD_FEAT_OUT, NULL), 64, 0.0f, t->d_hc, 64);
  fg_blas_single_end(blas);
  fg_render_backward(R_f, t->off, t->cnt, t->used_f, t->sigma, t->rgb, t->dts, t->ts, t->h, 64,
                     t->bg, 1, t->zero_rgb, NULL, NULL, t->d_hc, t->d_sigma_f, t->d_rgb_f, t->d_h,
                     nt);
  for (size_t i = 0; i < (size_t)S_f * 64; i++)
    if (!(t->h[i] > 0.0f)) t->d_h[i] = 0.0f;
  fg_mlp_backward(&f->feat_net, fg_field_group(f, FG_FIELD_FEAT_MLP, NULL), t->fenc, t->facts,
                  t->d_h, S_f, t->grad + f->group_offset[FG_FIELD_FEAT_MLP], t->d_fenc,
                  t->mlp_scratch, nt);
  fg_hashgrid_backward(&f->cfg.feat_grid, t->x, S_f, t->d_fenc,
                       t->grad + f->group_offset[FG_FIELD_FEAT_GRID], nt);
}

/* Back-propagates d_out_rgb (R,3) through compositing, colour and density networks. */
static void backward_colour(fg_trainer *t, int32_t R, int32_t S) {
  fg_field *f = t->f;
  const int nt = t->opts.n_threads;
  fg_render_backward(R, t->off, t->cnt, t->used, t->sigma, t->rgb, t->dts, t->ts, NULL, 0, t->bg,
                     1, t->d_out_rgb, NULL, NULL, NULL, t->d_sigma, t->d_rgb, NULL, nt);
  if (t->geometry) {
    /* the geometry losses' dL/dw (t->wg) composited as a one-channel feature: render.h */
    fg_render_backward(R, t->off, t->cnt, t->used, t->sigma, t->rgb, t->dts, t->ts, t->wg, 1,
                       t->bg, 1, t->zero_rgb, NULL, NULL, t->ones, t->d_sigma_g, t->d_rgb_g,
                       NULL, nt);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int32_t i = 0; i < S; i++) t->d_sigma[i] += t->d_sigma_g[i];
  }
  if (f->cfg.learn_background) {
    /* d bg_r = T_n d_out_rgb_r; bg = sigmoid(W_bg sh): summed over rays in order. */
    float *gW = t->grad + f->group_offset[FG_FIELD_BACKGROUND];
    for (int32_t r = 0; r < R; r++)
      for (int c = 0; c < 3; c++) {
        const float b = t->bg[3 * r + c];
        const float g = (1.0f - t->out_opacity[r]) * t->d_out_rgb[3 * r + c] * b * (1.0f - b);
        for (int k = 0; k < FG_SH4_DIM; k++) gW[c * FG_SH4_DIM + k] += g * t->sh[16 * r + k];
      }
  }
  fg_act_sigmoid_backward(t->d_rgb, t->rgb, t->d_rgb, (size_t)S * 3);
  fg_mlp_backward(&f->colour_net, fg_field_group(f, FG_FIELD_COLOUR, NULL), t->cin, t->cacts,
                  t->d_rgb, S, t->grad + f->group_offset[FG_FIELD_COLOUR], t->d_cin,
                  t->mlp_scratch, nt);
  fg_act_trunc_exp_backward(t->d_sigma, t->sigma, t->d_sigma, (size_t)S);
#pragma omp parallel for schedule(static) num_threads(nt)
  for (int32_t i = 0; i < S; i++) {
    memcpy(t->d_dout + (size_t)i * 16, t->d_cin + (size_t)i * 32 + 16, 16 * sizeof(float));
    t->d_dout[(size_t)i * 16] += t->d_sigma[i];
  }
  fg_mlp_backward(&f->density_net, fg_field_group(f, FG_FIELD_DENSITY, NULL), t->enc, t->dacts,
                  t->d_dout, S, t->grad + f->group_offset[FG_FIELD_DENSITY], t->d_enc,
                  t->mlp_scratch, nt);
  fg_hashgrid_backward(&f->cfg.grid, t->x, S, t->d_enc, t->grad + f->group_offset[FG_FIELD_GRID],
                       nt);
}

/* Folds fresh density samples into the occupancy grid (every OCC_UPDATE_INTERVAL steps). */
static void update_occupancy(fg_trainer *t) {
  fg_field *f = t->f;
  const int nt = t->opts.n_threads;
  int32_t M = 0;
  if (fg_occgrid_update_points(f->occ, (int32_t)t->step, t->opts.seed,
                               FG_OCCGRID_DEFAULT_WARMUP_STEPS, 0, t->occ_cells, t->occ_x,
                               t->occ_cap, &M, nt) < 0)
    return;
  /* Densities in batches through the training buffers (cube units, as the grid keeps). */
  for (int32_t i0 = 0; i0 < M; i0 += t->cap_s) {
    const int32_t n = M - i0 < t->cap_s ? M - i0 : t->cap_s;
    fg_hashgrid_forward(&f->cfg.grid, fg_field_group(f, FG_FIELD_GRID, NULL), t->occ_x + 3 * i0,
                        n, t->enc, nt);
    fg_mlp_forward(&f->density_net, fg_field_group(f, FG_FIELD_DENSITY, NULL), t->enc, n,
                   t->dacts, t->dout, nt);
    for (int32_t i = 0; i < n; i++) t->occ_sigma[i0 + i] = t->dout[(size_t)i * 16];
  }
  fg_act_trunc_exp_forward(t->occ_sigma, t->occ_sigma, (size_t)M);
  fg_occgrid_update_density(f->occ, t->occ_cells, t->occ_sigma, M, FG_OCCGRID_DEFAULT_DECAY,
                            fg_occgrid_density_threshold(f->cfg.dt), nt);
}

static void adam_group(fg_trainer *t, int g, const fg_adam_config *cfg, int step) {
  size_t n;
  float *p = fg_field_group(t->f, g, &n);
  const size_t o = t->f->group_offset[g];
  if (n) fg_adam_step(cfg, p, t->grad + o, t->m + o, t->v + o, n, step, t->opts.n_threads);
}

int fg_trainer_loss_grad(fg_trainer *t, fg_train_stats *stats) {
  fg_field *f = t->f;
  int32_t R = t->n_rays, S = 0;
  int32_t R_f = feature_rays(t, R);
  draw_rays(t, R, R_f);
  const int32_t R_kept = march(t, R, &S);
  if (R_kept < R) {
    R = R_kept;
    if (R_f > R) R_f = R;
  }
  const int32_t S_f = R_f ? t->off[R_f - 1] + t->cnt[R_f - 1] : 0;
  float *grad = t->grad;
  const size_t n_params = f->n_params;
#pragma omp parallel for schedule(static) num_threads(t->opts.n_threads)
  for (size_t i0 = 0; i0 < n_params; i0 += 65536)
    memset(grad + i0, 0, (n_params - i0 < 65536 ? n_params - i0 : 65536) * sizeof(float));

  fg_sh4_encode(t->d, R, t->sh);
  if (f->cfg.learn_background) {
    fg_field_background(f, t->sh, R, t->bg);
  } else {
    for (int32_t r = 0; r < R; r++) memcpy(t->bg + 3 * r, t->opts.background, 3 * sizeof(float));
  }
  forward_colour(t, R, S);
  fg_render_forward(R, t->off, t->cnt, t->sigma, t->rgb, t->dts, t->ts, NULL, 0, t->bg, 1, T_MIN,
                    t->out_rgb, NULL, t->out_opacity, NULL, t->used, t->opts.n_threads);
  const float loss_rgb = fg_loss_l2(t->out_rgb, t->target, (size_t)R * 3, t->d_out_rgb, 1.0f);
  float loss_depth = NAN, loss_dist = NAN;
  int32_t n_depth = 0;
  if (t->geometry) {
    const fg_train_opts *op = &t->opts;
    const int use_depth = op->depth_weight > 0.0f;
    for (int32_t r = 0; use_depth && r < R; r++) n_depth += t->depth_z[r] > 0.0f;
    double ld, lw;
    int32_t nd;
    fg_loss_ray_weights(R, t->off, t->cnt, t->used, t->sigma, t->dts, t->ts,
                        use_depth ? t->depth_z : NULL,
                        (float)(op->depth_margin / f->cfg.box_size),
                        n_depth ? op->depth_weight / (float)n_depth : 0.0f,
                        op->distortion_weight / (float)R, t->wg, &ld, &nd, &lw, op->n_threads);
    if (nd) loss_depth = (float)(ld / nd);
    if (op->distortion_weight > 0.0f) loss_dist = (float)(lw / R);
  }
  float loss_feat = NAN;
  if (R_f) {
    forward_features(t, R_f, S_f);
    loss_feat = fg_loss_l2(t->fpred, t->ftarget, (size_t)R_f * (size_t)t->D, t->d_fpred,
                           t->opts.feature_weight);
  }
  const float loss = loss_rgb + (R_f ? t->opts.feature_weight * loss_feat : 0.0f) +
                     (n_depth ? t->opts.depth_weight * loss_depth : 0.0f) +
                     (isnan(loss_dist) ? 0.0f : t->opts.distortion_weight * loss_dist);
  if (stats) {
    stats->step = t->step;
    stats->rays = R;
    stats->samples = S;
    stats->loss = loss;
    stats->loss_rgb = loss_rgb;
    stats->loss_feat = loss_feat;
    stats->loss_depth = loss_depth;
    stats->loss_dist = loss_dist;
    stats->depth_rays = n_depth;
    stats->occupancy = (float)((double)fg_occgrid_n_occupied(f->occ) /
                               pow((double)fg_occgrid_resolution(f->occ), 3.0));
  }
  if (!isfinite(loss))
    return fg_fail(FG_ERANGE, "the training loss is not finite at step %lld",
                   (long long)t->step + 1);
  backward_colour(t, R, S);
  if (R_f) backward_features(t, R_f, S_f);
  return 0;
}

const float *fg_trainer_grad(const fg_trainer *t) { return t->grad; }

int fg_trainer_step(fg_trainer *t, fg_train_stats *stats) {
  fg_field *f = t->f;
  fg_train_stats st;
  FG_TRY(fg_trainer_loss_grad(t, &st));
  const int adam_step = (int)(t->step + 1);
  const float lr = fg_lr_exponential(t->opts.lr, adam_step, 20000, 10000, 0.33f);
  t->adam_mlp.lr = lr;
  t->adam_table.lr = lr;
  adam_group(t, FG_FIELD_GRID, &t->adam_table, adam_step);
  adam_group(t, FG_FIELD_DENSITY, &t->adam_mlp, adam_step);
  adam_group(t, FG_FIELD_COLOUR, &t->adam_mlp, adam_step);
  adam_group(t, FG_FIELD_BACKGROUND, &t->adam_mlp, adam_step);
  adam_group(t, FG_FIELD_FEAT_GRID, &t->adam_table, adam_step);
  adam_group(t, FG_FIELD_FEAT_MLP, &t->adam_mlp, adam_step);
  adam_group(t, FG_FIELD_FEAT_OUT, &t->adam_mlp, adam_step);

  if (t->step % OCC_UPDATE_INTERVAL == 0) update_occupancy(t);
  t->step++;
  f->trained_steps = t->step;

  /* Rays for the next step, so that the samples approach the target. */
  const double per_ray = st.rays ? (double)st.samples / (double)st.rays : 1.0;
  double next = (double)t->opts.target_samples / (per_ray > 1.0 ? per_ray : 1.0);
  if (next < MIN_RAYS) next = MIN_RAYS;
  if (next > MAX_RAYS) next = MAX_RAYS;
  t->n_rays = (int32_t)next;
  st.step = t->step;
  if (stats) *stats = st;
  return 0;
}

/* ---- evaluation ----------------------------------------------------------------------- */

/* Pixels of the held-out frames to evaluate: every one (full) or a fixed sample. */
typedef struct eval_px {
  size_t frame; /* index into frames */
  int u, v;
} eval_px;

static int eval_pixels(const fg_trainer *t, int full, eval_px **out, size_t *n_out) {
  size_t total = 0;
  for (size_t k = 0; k < t->n_held; k++) {
    const fg_frame *fr = &t->frames[t->held_idx[k]];
    total += (size_t)fr->cam.w * (size_t)fr->cam.h;
  }
  const size_t n = full || total <= EVAL_PIXELS ? total : EVAL_PIXELS;
  eval_px *px = malloc((n ? n : 1) * sizeof *px);
  if (!px) return fg_fail(FG_ENOMEM, "cannot allocate evaluation pixels");
  if (n == total) {
    size_t i = 0;
    for (size_t k = 0; k < t->n_held; k++) {
      const fg_frame *fr = &t->frames[t->held_idx[k]];
      for (int v = 0; v < fr->cam.h; v++)
        for (int u = 0; u < fr->cam.w; u++) px[i++] = (eval_px){t->held_idx[k], u, v};
    }
  } else {
    for (size_t i = 0; i < n; i++) {
      const uint64_t h = hash4(t->opts.seed, -1, i, STREAM_EVAL);
      const size_t k = below(h, (uint32_t)t->n_held);
      const fg_frame *fr = &t->frames[t->held_idx[k]];
      const uint64_t hp = fg_mix64(h);
      px[i] = (eval_px){t->held_idx[k], (int)below(hp, (uint32_t)fr->cam.w),
                        (int)below(hp << 32, (uint32_t)fr->cam.h)};
    }
  }
  *out = px;
  *n_out = n;
  return 0;
}

/* Renders the pixels px (n) in batches; rgb (n,3) and, when feat is not NULL, feat (n,D). */
static int eval_render(fg_trainer *t, const eval_px *px, size_t n, float *rgb, float *feat) {
  const size_t B = 16384;
  float *o = malloc(B * 3 * sizeof(float)), *d = malloc(B * 3 * sizeof(float));
  float *ow = malloc(B * 3 * sizeof(float));
  int rc = 0;
  if (!o || !d || !ow) {
    rc = fg_fail(FG_ENOMEM, "cannot allocate evaluation rays");
    goto out;
  }
  for (size_t i0 = 0; i0 < n && rc == 0; i0 += B) {
    const size_t m = n - i0 < B ? n - i0 : B;
    for (size_t i = 0; i < m; i++) {
      const eval_px *p = &px[i0 + i];
      frame_ray(t->f, &t->frames[p->frame], (float)p->u + 0.5f, (float)p->v + 0.5f, o + 3 * i,
                d + 3 * i);
      for (int k = 0; k < 3; k++)
        ow[3 * i + k] = (float)(o[3 * i + k] * t->f->cfg.box_size + t->f->cfg.box_min[k]);
    }
    rc = fg_field_render_rays(t->f, ow, d, (int64_t)m,
                              t->f->cfg.learn_background ? NULL : t->opts.background,
                              rgb + 3 * i0, NULL, NULL, feat ? feat + i0 * (size_t)t->D : NULL,
                              t->opts.n_threads);
  }
out:
  free(ow);
  free(d);
  free(o);
  return rc;
}

int fg_trainer_eval(fg_trainer *t, int full, double *psnr) {
  *psnr = NAN;
  if (!t->n_held) return 0;
  eval_px *px = NULL;
  size_t n = 0;
  FG_TRY(eval_pixels(t, full, &px, &n));
  float *rgb = malloc((n ? n : 1) * 3 * sizeof(float));
  if (!rgb) {
    free(px);
    return fg_fail(FG_ENOMEM, "cannot allocate evaluation output");
  }
  int rc = eval_render(t, px, n, rgb, NULL);
  if (rc == 0) {
    double se = 0.0;
    for (size_t i = 0; i < n; i++) {
      float ref[3];
      pixel_rgb(&t->frames[px[i].frame], px[i].u, px[i].v, ref);
      for (int c = 0; c < 3; c++) se += (double)(rgb[3 * i + c] - ref[c]) * (rgb[3 * i + c] - ref[c]);
    }
    const double mse = se / (double)(3 * (n ? n : 1));
    *psnr = mse > 0.0 ? -10.0 * log10(mse) : INFINITY;
  }
  free(rgb);
  free(px);
  return rc;
}
