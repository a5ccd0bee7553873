/* Training step checks on a small synthetic field:
 *  - the gradient of one whole training step (rays, marching, density, colour and feature
 *    networks, compositing, losses) against central finite differences of the loss, for
 *    parameters of every group;
 *  - determinism: two trainings with the same frames, seed and threads give the same
 *    parameters and byte-identical checkpoints;
 *  - a checkpoint loads into a field that renders the same pixels and features;
 *  - an update's focus (fg_trainer_focus) finds the cells where the frames differ from the
 *    field before, in colour or in measured depth, and draws its rays there;
 *  - bad input to the trainer is refused with a detail. */
#include <unistd.h>

#include "core/error.h"
#include "field/checkpoint.h"
#include "field/image.h"
#include "field/model.h"
#include "field/train.h"
#include "io/frame.h"
#include "test.h"

#define W 24
#define H 18
#define FD 8 /* feature cells 3 x 4, D = FD */
#define N_FRAMES 4

static uint64_t rng_state = 7;
static float urand(void) {
  rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
  return (float)(rng_state >> 40) * (1.0f / 16777216.0f);
}

/* Camera i on a circle around the box centre (0.5, 0.5, 0.25) at 1 m, looking at it. */
static void make_frames(fg_frame *fr, int with_features) {
  for (int i = 0; i < N_FRAMES; i++) {
    memset(&fr[i], 0, sizeof fr[i]);
    const double a = 2.0 * M_PI * i / N_FRAMES, c[3] = {0.5, 0.5, 0.25};
    const double p[3] = {c[0] + cos(a), c[1] + sin(a), c[2] + 0.4};
    double z[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]}, n = 0; /* camera looks along -z */
    for (int k = 0; k < 3; k++) n += z[k] * z[k];
    for (int k = 0; k < 3; k++) z[k] /= sqrt(n);
    double x[3] = {-z[1], z[0], 0.0}; /* up x z */
    n = sqrt(x[0] * x[0] + x[1] * x[1]);
    for (int k = 0; k < 3; k++) x[k] /= n;
    const double y[3] = {z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2],
                         z[0] * x[1] - z[1] * x[0]};
    for (int r = 0; r < 3; r++) {
      fr[i].T_world_cam[4 * r + 0] = x[r];
      fr[i].T_world_cam[4 * r + 1] = y[r];
      fr[i].T_world_cam[4 * r + 2] = z[r];
      fr[i].T_world_cam[4 * r + 3] = p[r];
    }
    fr[i].T_world_cam[15] = 1.0;
    fr[i].cam = (fg_camera){.fl_x = 20, .fl_y = 20, .cx = W / 2.0, .cy = H / 2.0, .w = W, .h = H};
    fr[i].rgb = malloc(sizeof(uint16_t) * W * H * 3);
    for (int k = 0; k < W * H * 3; k++) fr[i].rgb[k] = (uint16_t)(urand() * 65535.0f);
    if (with_features) {
      fr[i].feat_h = 3;
      fr[i].feat_w = 4;
      fr[i].feat_d = FD;
      fr[i].feat_dtype = FG_DTYPE_F32;
      float *f = malloc(sizeof(float) * 3 * 4 * FD);
      for (int k = 0; k < 3 * 4 * FD; k++) f[k] = urand() - 0.5f;
      fr[i].feat = f;
    }
  }
}

static void small_config(fg_field_config *cfg, int D) {
  const double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {1.0, 1.0, 0.5};
  ASSERT_OK(fg_field_config_for_workspace(cfg, lo, hi, 1.0, D));
  cfg->grid.log2_table_size = 10;
  cfg->grid.n_levels = 4;
  cfg->grid.finest_resolution = 64;
  cfg->feat_grid.log2_table_size = 10;
  cfg->feat_grid.n_levels = 3;
  cfg->occ_resolution = 16;
  cfg->dt = 0.02f;
}

static fg_train_opts small_opts(void) {
  fg_train_opts o;
  fg_train_opts_default(&o);
  o.seed = 3;
  o.n_threads = 2;
  o.target_samples = 4096;
  o.feature_ray_fraction = 0.5f;
  return o;
}

enum { LOSS_RGB, LOSS_FEATURE, LOSS_GEOMETRY };

/* The part of a step's loss a check differentiates. The geometry part is summed in double
 * from its float parts: taken as loss - loss_rgb it would drown in the total's rounding. */
static double loss_part(const fg_train_stats *s, int which, double wd, double wdist) {
  if (which == LOSS_RGB) return s->loss_rgb;
  if (which == LOSS_FEATURE) return (double)s->loss - s->loss_rgb;
  return (isnan(s->loss_depth) ? 0.0 : wd * s->loss_depth) +
         (isnan(s->loss_dist) ? 0.0 : wdist * s->loss_dist);
}

/* Central differences of the loss for a few parameters of group g with the largest
 * gradients; which_loss: the part of the loss (loss_part) whose gradient is checked, with
 * the weights wd, wdist of the geometry losses. The trainer's gradient is of the whole loss:
 * base, when given, is the gradient of the other parts (n_params floats), subtracted. */
static void check_group_w(fg_trainer *t, fg_field *f, int g, int which_loss, double wd,
                          double wdist, const float *base, const char *name) {
  size_t n;
  float *p = fg_field_group(f, g, &n);
  if (!n) return;
  ASSERT_OK(fg_trainer_loss_grad(t, NULL));
  float *grad = malloc(n * sizeof *grad);
  ASSERT(grad);
  memcpy(grad, fg_trainer_grad(t) + f->group_offset[g], n * sizeof *grad);
  if (base)
    for (size_t i = 0; i < n; i++) grad[i] -= base[f->group_offset[g] + i];
  /* The 4 largest |gradient| entries (many table entries see no sample). */
  size_t pick[4] = {0, 0, 0, 0};
  for (int k = 0; k < 4; k++) {
    double best = -1.0;
    for (size_t i = 0; i < n; i++) {
      int taken = 0;
      for (int j = 0; j < k; j++) taken |= pick[j] == i;
      if (!taken && fabs(grad[i]) > best) best = fabs(grad[i]), pick[k] = i;
    }
  }
  float analytic[4];
  for (int k = 0; k < 4; k++) analytic[k] = grad[pick[k]];
  for (int k = 0; k < 4; k++) {
    const size_t i = pick[k];
    const float keep = p[i], h = fmaxf(1e-2f, 1e-2f * fabsf(keep));
    fg_train_stats sp, sm;
    p[i] = keep + h;
    ASSERT_OK(fg_trainer_loss_grad(t, &sp));
    p[i] = keep - h;
    ASSERT_OK(fg_trainer_loss_grad(t, &sm));
    p[i] = keep;
    const double lp = loss_part(&sp, which_loss, wd, wdist);
    const double lm = loss_part(&sm, which_loss, wd, wdist);
    const double fd = (lp - lm) / (2.0 * h);
    const double tol = 0.05 * fabs(analytic[k]) + 2e-6;
    printf("%-10s param %6zu: analytic %+.6e  finite difference %+.6e\n", name, i,
           (double)analytic[k], fd);
    if (!(fabs(fd - analytic[k]) <= tol))
      FG_TEST_FAIL("%s parameter %zu: gradient %.6e, finite difference %.6e", name, i,
                   (double)analytic[k], fd);
  }
  ASSERT(fabs(analytic[0]) > 5e-6); /* the check saw a gradient worth checking */
  free(grad);
}

static void check_group(fg_trainer *t, fg_field *f, int g, int which_loss, const char *name) {
  check_group_w(t, f, g, which_loss, 0.0, 0.0, NULL, name);
}

static void test_gradient(void) {
  fg_frame fr[N_FRAMES];
  make_frames(fr, 1);
  fg_field_config cfg;
  small_config(&cfg, FD);
  cfg.learn_background = 1;
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 11));
  /* Stronger initial values than the +-1e-4 tables, so the density path matters. */
  size_t n;
  float *tab = fg_field_group(f, FG_FIELD_GRID, &n);
  for (size_t i = 0; i < n; i++) tab[i] = (urand() - 0.5f) * 2.0f;
  tab = fg_field_group(f, FG_FIELD_FEAT_GRID, &n);
  for (size_t i = 0; i < n; i++) tab[i] = (urand() - 0.5f) * 2.0f;
  float *bgw = fg_field_group(f, FG_FIELD_BACKGROUND, &n);
  for (size_t i = 0; i < n; i++) bgw[i] = urand() - 0.5f;
  fg_train_opts o = small_opts();
  fg_trainer *t;
  ASSERT_OK(fg_trainer_new(&t, f, fr, N_FRAMES, &o));
  check_group(t, f, FG_FIELD_GRID, LOSS_RGB, "grid");
  check_group(t, f, FG_FIELD_DENSITY, LOSS_RGB, "density");
  check_group(t, f, FG_FIELD_COLOUR, LOSS_RGB, "colour");
  check_group(t, f, FG_FIELD_BACKGROUND, LOSS_RGB, "background");
  check_group(t, f, FG_FIELD_FEAT_GRID, LOSS_FEATURE, "feat_grid");
  check_group(t, f, FG_FIELD_FEAT_MLP, LOSS_FEATURE, "feat_mlp");
  check_group(t, f, FG_FIELD_FEAT_OUT, LOSS_FEATURE, "feat_out");
  fg_trainer_free(t);
  fg_field_free(f);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);
}

/* The same check with the geometry losses: depth maps on every frame (a few pixels without
 * a measurement) and the distortion term, through the density path they act on. */
/* The same check with the geometry losses: depth maps on every frame (a few pixels without
 * a measurement), then the distortion term, through the density path they act on. */
static void test_gradient_geometry(void) {
  fg_frame fr[N_FRAMES];
  make_frames(fr, 0);
  for (int i = 0; i < N_FRAMES; i++) {
    fr[i].depth_w = W;
    fr[i].depth_h = H;
    fr[i].depth = malloc(sizeof(float) * W * H);
    for (int k = 0; k < W * H; k++) /* smooth, so few pixels count as depth edges */
      fr[i].depth[k] = k % 29 == 3 ? 0.0f : 0.8f + 0.002f * (float)(k % W + k / W) + 0.002f * urand();
  }
  fg_field_config cfg;
  small_config(&cfg, 0);
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 13));
  size_t n;
  float *tab = fg_field_group(f, FG_FIELD_GRID, &n);
  /* milder densities than the colour check's: no ray reaches the early-termination cut,
   * whose jumps the depth term's +-1 per unit of weight would make visible in a finite
   * difference */
  for (size_t i = 0; i < n; i++) tab[i] = (urand() - 0.5f) * 1.0f;
  fg_train_opts o = small_opts();
  fg_trainer *t;
  fg_train_stats st;
  const float weights[2][2] = {{0.5f, 0.0f}, {0.0f, 0.05f}}; /* depth, then distortion */
  /* the colour loss's gradient alone, on the same rays */
  o.depth_weight = 0.0f;
  ASSERT_OK(fg_trainer_new(&t, f, fr, N_FRAMES, &o));
  ASSERT_OK(fg_trainer_loss_grad(t, &st));
  float *base = malloc(f->n_params * sizeof *base);
  ASSERT(base);
  memcpy(base, fg_trainer_grad(t), f->n_params * sizeof *base);
  fg_trainer_free(t);
  for (int c = 0; c < 2; c++) {
    o.depth_weight = weights[c][0];
    o.distortion_weight = weights[c][1];
    ASSERT_OK(fg_trainer_new(&t, f, fr, N_FRAMES, &o));
    ASSERT_OK(fg_trainer_loss_grad(t, &st));
    printf("geometry losses: depth %.4f over %d of %d rays, distortion %.5f\n",
           (double)st.loss_depth, st.depth_rays, st.rays, (double)st.loss_dist);
    if (c == 0)
      ASSERT(st.depth_rays > 0 && st.depth_rays < st.rays && isnan(st.loss_dist));
    else
      ASSERT(st.depth_rays == 0 && isnan(st.loss_depth) && st.loss_dist > 0.0f);
    check_group_w(t, f, FG_FIELD_GRID, LOSS_GEOMETRY, o.depth_weight, o.distortion_weight,
                  base, c ? "grid (distortion)" : "grid (depth)");
    check_group_w(t, f, FG_FIELD_DENSITY, LOSS_GEOMETRY, o.depth_weight, o.distortion_weight,
                  base, c ? "density (distortion)" : "density (depth)");
    fg_trainer_free(t);
  }
  /* without depth maps and distortion the geometry losses are off */
  for (int i = 0; i < N_FRAMES; i++) {
    free(fr[i].depth);
    fr[i].depth = NULL;
    fr[i].depth_w = fr[i].depth_h = 0;
  }
  o.depth_weight = 0.5f;
  o.distortion_weight = 0.0f;
  ASSERT_OK(fg_trainer_new(&t, f, fr, N_FRAMES, &o));
  ASSERT_OK(fg_trainer_loss_grad(t, &st));
  ASSERT(st.depth_rays == 0 && isnan(st.loss_depth) && isnan(st.loss_dist));
  ASSERT(st.loss == st.loss_rgb);
  fg_trainer_free(t);
  free(base);
  fg_field_free(f);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);
}

static fg_field *train_small(fg_frame *fr, int steps, uint64_t seed) {
  fg_field_config cfg;
  small_config(&cfg, FD);
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, seed));
  fg_train_opts o = small_opts();
  o.seed = seed;
  o.holdout_every = 4;
  fg_trainer *t;
  ASSERT_OK(fg_trainer_new(&t, f, fr, N_FRAMES, &o));
  ASSERT_EQ(fg_trainer_n_heldout(t), 1);
  fg_train_stats st;
  float first = NAN;
  for (int s = 0; s < steps; s++) {
    ASSERT_OK(fg_trainer_step(t, &st));
    if (s == 0) first = st.loss;
    ASSERT(isfinite(st.loss));
  }
  ASSERT_EQ(st.step, steps);
  ASSERT_EQ(f->trained_steps, steps);
  ASSERT(st.loss < first); /* it learns something of the random images */
  double psnr;
  ASSERT_OK(fg_trainer_eval(t, 0, &psnr));
  ASSERT(isfinite(psnr));
  fg_trainer_free(t);
  return f;
}

static size_t file_bytes(const char *path, unsigned char **out) {
  FILE *fp = fopen(path, "rb");
  ASSERT(fp);
  fseek(fp, 0, SEEK_END);
  const long len = ftell(fp);
  fseek(fp, 0, SEEK_SET);
  *out = malloc((size_t)len);
  ASSERT(fread(*out, 1, (size_t)len, fp) == (size_t)len);
  fclose(fp);
  return (size_t)len;
}

static void test_determinism_and_checkpoint(void) {
  fg_frame fr[N_FRAMES];
  make_frames(fr, 1);
  /* 40 steps cross the occupancy updates at steps 0, 16 and 32. */
  fg_field *a = train_small(fr, 40, 5), *b = train_small(fr, 40, 5), *c = train_small(fr, 40, 6);
  ASSERT_EQ(a->n_params, b->n_params);
  ASSERT(memcmp(a->params, b->params, a->n_params * sizeof(float)) == 0);
  ASSERT(memcmp(a->params, c->params, a->n_params * sizeof(float)) != 0); /* the seed matters */

  char dir[] = "/tmp/fg-test-train-XXXXXX", pa[64], pb[64];
  ASSERT(mkdtemp(dir));
  snprintf(pa, sizeof pa, "%s/a.fgc", dir);
  snprintf(pb, sizeof pb, "%s/b.fgc", dir);
  ASSERT_OK(fg_checkpoint_save(a, pa, 0));
  ASSERT_OK(fg_checkpoint_save(b, pb, 0));
  unsigned char *ba, *bb;
  const size_t la = file_bytes(pa, &ba), lb = file_bytes(pb, &bb);
  ASSERT_EQ(la, lb);
  ASSERT(memcmp(ba, bb, la) == 0);
  free(ba);
  free(bb);

  /* Save -> load -> the same renders, colour, depth, opacity and features. */
  fg_field *l;
  ASSERT_OK(fg_checkpoint_load(pa, &l));
  const size_t px = (size_t)W * H;
  float *r1 = calloc(px * (5 + FD), sizeof(float)), *r2 = calloc(px * (5 + FD), sizeof(float));
  const float bg[3] = {1, 1, 1};
  ASSERT_OK(fg_field_render_camera(a, fr[0].T_world_cam, &fr[0].cam, bg, r1, r1 + 3 * px,
                                   r1 + 4 * px, r1 + 5 * px, 2));
  ASSERT_OK(fg_field_render_camera(l, fr[0].T_world_cam, &fr[0].cam, bg, r2, r2 + 3 * px,
                                   r2 + 4 * px, r2 + 5 * px, 1));
  ASSERT(memcmp(r1, r2, px * (5 + FD) * sizeof(float)) == 0);
  double opacity = 0.0;
  for (size_t i = 0; i < px; i++) opacity += r1[4 * px + i];
  ASSERT(opacity > 0.0);
  free(r1);
  free(r2);
  unlink(pa);
  unlink(pb);
  rmdir(dir);
  fg_field_free(l);
  fg_field_free(a);
  fg_field_free(b);
  fg_field_free(c);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);
}

static void test_bad_input(void) {
  fg_frame fr[N_FRAMES];
  make_frames(fr, 1);
  fg_field_config cfg;
  small_config(&cfg, FD + 1);
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 1));
  fg_train_opts o = small_opts();
  fg_trainer *t;
  ASSERT_ERR(fg_trainer_new(&t, f, fr, N_FRAMES, &o), FG_EINVAL, "features");
  fg_field_free(f);
  small_config(&cfg, FD);
  ASSERT_OK(fg_field_new(&f, &cfg, 1));
  o.holdout_every = 1;
  ASSERT_ERR(fg_trainer_new(&t, f, fr, N_FRAMES, &o), FG_EINVAL, "no frame left");
  o = small_opts();
  o.n_threads = 0;
  ASSERT_ERR(fg_trainer_new(&t, f, fr, N_FRAMES, &o), FG_EINVAL, "threads");
  /* A NaN pose gives no rays' samples, never a crash; a NaN image value cannot occur (u16). */
  fg_field_free(f);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);
}

/* ---- focus (fg_trainer_focus) --------------------------------------------------------- */

/* An empty field (an empty occupancy grid: every ray sees the white background, opacity 0)
 * and frames that show exactly that: white, no depth, features on. */
static fg_field *empty_field(void) {
  fg_field_config cfg;
  small_config(&cfg, FD);
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, 11));
  const int N = fg_occgrid_resolution(f->occ);
  uint64_t *bits = calloc((size_t)N * N * N / 64, sizeof *bits);
  ASSERT(bits);
  ASSERT_OK(fg_occgrid_set_bits(f->occ, bits, 1));
  free(bits);
  return f;
}

static void white_frames(fg_frame *fr) {
  make_frames(fr, 1);
  for (int i = 0; i < N_FRAMES; i++)
    for (int k = 0; k < W * H * 3; k++) fr[i].rgb[k] = 65535;
}

/* Pixels [8, 16) x [4, 12): the centres of exactly the 4 cells (2, 1), (3, 1), (2, 2), (3, 2)
 * of 4 pixels; with their neighbours, 16 cells. */
static int in_patch(int u, int v) { return u >= 8 && u < 16 && v >= 4 && v < 12; }

static void paint_red(fg_frame *fr) {
  for (int v = 0; v < H; v++)
    for (int u = 0; u < W; u++)
      if (in_patch(u, v)) {
        fr->rgb[(v * W + u) * 3 + 1] = 0;
        fr->rgb[(v * W + u) * 3 + 2] = 0;
      }
}

/* A depth map: z metres in the patch (patch_only) or everywhere, none elsewhere. */
static void give_depth(fg_frame *fr, float z, int patch_only) {
  fr->depth = calloc(W * H, sizeof(float));
  ASSERT(fr->depth);
  for (int v = 0; v < H; v++)
    for (int u = 0; u < W; u++)
      if (!patch_only || in_patch(u, v)) fr->depth[v * W + u] = z;
}

static fg_trainer *focus_trainer(const fg_field *before, fg_frame *fr, fg_field **copy) {
  ASSERT_OK(fg_field_copy_for_update(before, copy));
  fg_train_opts o = small_opts();
  o.target_samples = 1 << 16; /* 256 rays a step through the full grid at first */
  fg_trainer *t;
  ASSERT_OK(fg_trainer_new(&t, *copy, fr, N_FRAMES, &o));
  return t;
}

/* Three steps of trainers t (of field a) and u (of b) leave a and b the same. */
static void same_after_steps(fg_trainer *t, const fg_field *a, fg_trainer *u, const fg_field *b) {
  for (int s = 0; s < 3; s++) {
    ASSERT_OK(fg_trainer_step(t, NULL));
    ASSERT_OK(fg_trainer_step(u, NULL));
  }
  ASSERT(memcmp(a->params, b->params, a->n_params * sizeof(float)) == 0);
}

static void test_focus(void) {
  fg_field *before = empty_field(), *copy, *plain;
  fg_frame fr[N_FRAMES];
  fg_train_focus_stats st;

  /* Nothing changed: nothing kept, and the draws are those of no focus, bit for bit. */
  white_frames(fr);
  fg_trainer *t = focus_trainer(before, fr, &copy), *u = focus_trainer(before, fr, &plain);
  ASSERT_OK(fg_trainer_focus(t, before, 0.5f, &st));
  ASSERT_EQ(st.cells, N_FRAMES * 6 * 5); /* 24 x 18 pixels: 6 x 5 cells a frame */
  ASSERT_EQ(st.changed, 0);
  ASSERT_EQ(st.kept, 0);
  same_after_steps(t, copy, u, plain);
  fg_trainer_free(t);
  fg_trainer_free(u);
  fg_field_free(copy);
  fg_field_free(plain);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);

  /* A red patch in frame 0; a surface 1 m away in frame 1's patch, where before has none;
   * frame 2 measures 100 m everywhere, outside the field's cube: not a change. */
  white_frames(fr);
  paint_red(&fr[0]);
  give_depth(&fr[1], 1.0f, 1);
  give_depth(&fr[2], 100.0f, 0);
  t = focus_trainer(before, fr, &copy);
  ASSERT_OK(fg_trainer_focus(t, before, 0.5f, &st));
  ASSERT_EQ(st.changed, 8);
  ASSERT_EQ(st.kept, 32);
  fg_trainer_free(t);
  fg_field_free(copy);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);

  /* The draws: only frame 1's patch has depth. Every ray from its 16 kept cells (fraction 1)
   * carries depth about a fifth of the time (the patch's quarter of them, less its border,
   * where the depth loss's four neighbours are not all measured), against about 3 % of the
   * rays drawn over all frames. */
  white_frames(fr);
  give_depth(&fr[1], 1.0f, 1);
  t = focus_trainer(before, fr, &copy);
  fg_train_stats s0, s1;
  ASSERT_OK(fg_trainer_loss_grad(t, &s0));
  ASSERT_OK(fg_trainer_focus(t, before, 1.0f, &st));
  ASSERT_EQ(st.kept, 16);
  ASSERT_OK(fg_trainer_loss_grad(t, &s1));
  ASSERT_EQ(s1.rays, s0.rays);
  printf("focus: %d of %d rays with depth drawn over all frames, %d with the focus\n",
         s0.depth_rays, s0.rays, s1.depth_rays);
  ASSERT(s1.depth_rays > 4 * s0.depth_rays);
  ASSERT(s1.depth_rays > s1.rays / 10);
  fg_trainer_free(t);
  fg_field_free(copy);

  /* The same frames, seed and focus give the same parameters. */
  t = focus_trainer(before, fr, &copy);
  u = focus_trainer(before, fr, &plain);
  ASSERT_OK(fg_trainer_focus(t, before, 0.5f, NULL));
  ASSERT_OK(fg_trainer_focus(u, before, 0.5f, NULL));
  same_after_steps(t, copy, u, plain);
  fg_trainer_free(u);
  fg_field_free(plain);

  /* Bad input. */
  ASSERT_ERR(fg_trainer_focus(t, before, -0.1f, NULL), FG_EINVAL, "fraction");
  ASSERT_ERR(fg_trainer_focus(t, before, 1.5f, NULL), FG_EINVAL, "fraction");
  ASSERT_ERR(fg_trainer_focus(t, before, NAN, NULL), FG_EINVAL, "fraction");
  ASSERT_ERR(fg_trainer_focus(t, NULL, 0.5f, NULL), FG_EINVAL, "no field");
  fg_field_config cfg;
  small_config(&cfg, FD);
  cfg.box_size *= 2.0;
  fg_field *other;
  ASSERT_OK(fg_field_new(&other, &cfg, 1));
  ASSERT_ERR(fg_trainer_focus(t, other, 0.5f, NULL), FG_EINVAL, "differs");
  fg_field_free(other);
  fg_trainer_free(t);
  fg_field_free(copy);
  for (int i = 0; i < N_FRAMES; i++) fg_frame_clear(&fr[i]);
  fg_field_free(before);
}

int main(void) {
  test_gradient();
  test_gradient_geometry();
  test_determinism_and_checkpoint();
  test_bad_input();
  test_focus();
  printf("ok\n");
  return 0;
}
