/* Volume rendering, activations and losses: the threaded kernels against the scalar
 * references, gradients against central differences of the loss sum(g . outputs) evaluated in
 * double, early termination, empty rays, extreme densities, and bit-identical results for any
 * thread count. */
#include "field/render.h"

#include <float.h>
#include <stdint.h>

#include "test.h"

/* ---- helpers -------------------------------------------------------------------------- */

static uint64_t rng_state;

static uint32_t rng_u32(void) {
  rng_state += 0x9e3779b97f4a7c15ull; /* splitmix64 */
  uint64_t z = rng_state;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return (uint32_t)((z ^ (z >> 31)) >> 32);
}

static float rng_uniform(float lo, float hi) {
  return lo + (hi - lo) * (float)(rng_u32() >> 8) * (1.0f / 16777216.0f);
}

static void *xcalloc(size_t n, size_t size) {
  void *p = calloc(n ? n : 1, size);
  if (!p) FG_TEST_FAIL("out of memory");
  return p;
}

/* A batch of rays with every input and output array. */
typedef struct {
  int32_t R, S, D, bg_per_ray;
  int32_t *offset, *count, *n_used;
  float *sigma, *rgb, *dt, *t, *feat, *bg;
  float *out_rgb, *out_depth, *out_opacity, *out_feat;
  float *g_rgb, *g_depth, *g_opacity, *g_feat;
  float *d_sigma, *d_rgb, *d_feat;
} batch;

enum { SIGMA_MODERATE, SIGMA_WIDE };

/* Random rays with 0..max_n samples each. SIGMA_MODERATE keeps sigma dt in about
 * [0, 1.5] (gradients of every sample matter); SIGMA_WIDE spans 1e-4..1e3 with zeros. */
static batch batch_new(int32_t R, int max_n, int D, int bg_per_ray, int sigma_kind) {
  batch b = {0};
  b.R = R;
  b.D = D;
  b.bg_per_ray = bg_per_ray;
  b.offset = xcalloc((size_t)R, sizeof(int32_t));
  b.count = xcalloc((size_t)R, sizeof(int32_t));
  b.n_used = xcalloc((size_t)R, sizeof(int32_t));
  for (int32_t r = 0; r < R; r++) {
    b.offset[r] = b.S;
    b.count[r] = (int32_t)(rng_u32() % (uint32_t)(max_n + 1));
    b.S += b.count[r];
  }
  size_t S = (size_t)b.S, Dz = (size_t)D;
  b.sigma = xcalloc(S, sizeof(float));
  b.rgb = xcalloc(3 * S, sizeof(float));
  b.dt = xcalloc(S, sizeof(float));
  b.t = xcalloc(S, sizeof(float));
  b.feat = D ? xcalloc(S * Dz, sizeof(float)) : NULL;
  b.bg = xcalloc(bg_per_ray ? 3 * (size_t)R : 3, sizeof(float));
  for (int32_t r = 0; r < R; r++) {
    float tt = rng_uniform(0.05f, 0.5f);
    for (int32_t i = 0; i < b.count[r]; i++) {
      size_t s = (size_t)(b.offset[r] + i);
      b.dt[s] = rng_uniform(0.005f, 0.05f);
      b.t[s] = tt + 0.5f * b.dt[s];
      tt += b.dt[s];
      if (sigma_kind == SIGMA_MODERATE) {
        b.sigma[s] = rng_uniform(0.0f, 30.0f);
      } else {
        uint32_t k = rng_u32() % 8;
        b.sigma[s] = k == 0 ? 0.0f : expf(rng_uniform(-9.0f, 11.0f));
      }
      for (int k = 0; k < 3; k++) b.rgb[3 * s + k] = rng_uniform(0.0f, 1.0f);
      for (int d = 0; d < D; d++) b.feat[s * Dz + d] = rng_uniform(-1.0f, 1.0f);
    }
  }
  for (int k = 0; k < (bg_per_ray ? 3 * R : 3); k++) b.bg[k] = rng_uniform(0.0f, 1.0f);
  b.out_rgb = xcalloc(3 * (size_t)R, sizeof(float));
  b.out_depth = xcalloc((size_t)R, sizeof(float));
  b.out_opacity = xcalloc((size_t)R, sizeof(float));
  b.out_feat = D ? xcalloc((size_t)R * Dz, sizeof(float)) : NULL;
  b.g_rgb = xcalloc(3 * (size_t)R, sizeof(float));
  b.g_depth = xcalloc((size_t)R, sizeof(float));
  b.g_opacity = xcalloc((size_t)R, sizeof(float));
  b.g_feat = D ? xcalloc((size_t)R * Dz, sizeof(float)) : NULL;
  for (int32_t k = 0; k < 3 * R; k++) b.g_rgb[k] = rng_uniform(-1.0f, 1.0f);
  for (int32_t r = 0; r < R; r++) b.g_depth[r] = rng_uniform(-1.0f, 1.0f);
  for (int32_t r = 0; r < R; r++) b.g_opacity[r] = rng_uniform(-1.0f, 1.0f);
  for (size_t k = 0; k < (size_t)R * Dz; k++) b.g_feat[k] = rng_uniform(-1.0f, 1.0f);
  b.d_sigma = xcalloc(S, sizeof(float));
  b.d_rgb = xcalloc(3 * S, sizeof(float));
  b.d_feat = D ? xcalloc(S * Dz, sizeof(float)) : NULL;
  return b;
}

static void batch_free(batch *b) {
  void *ps[] = {b->offset, b->count, b->n_used, b->sigma, b->rgb, b->dt, b->t, b->feat,
                b->bg, b->out_rgb, b->out_depth, b->out_opacity, b->out_feat, b->g_rgb,
                b->g_depth, b->g_opacity, b->g_feat, b->d_sigma, b->d_rgb, b->d_feat};
  for (size_t i = 0; i < sizeof ps / sizeof ps[0]; i++) free(ps[i]);
}

static void run_forward(batch *b, float t_min, int n_threads) {
  fg_render_forward(b->R, b->offset, b->count, b->sigma, b->rgb, b->dt, b->t, b->feat, b->D,
                    b->bg, b->bg_per_ray, t_min, b->out_rgb, b->out_depth, b->out_opacity,
                    b->out_feat, b->n_used, n_threads);
}

static void run_backward(batch *b, int n_threads) {
  fg_render_backward(b->R, b->offset, b->count, b->n_used, b->sigma, b->rgb, b->dt, b->t,
                     b->feat, b->D, b->bg, b->bg_per_ray, b->g_rgb, b->g_depth, b->g_opacity,
                     b->g_feat, b->d_sigma, b->d_rgb, b->d_feat, n_threads);
}

static int all_finite(const float *x, size_t n) {
  for (size_t i = 0; i < n; i++)
    if (!isfinite(x[i])) return 0;
  return 1;
}

/* |a - b| <= atol + rtol |b|, elementwise, with the worst offender in the message. */
static void assert_close(const char *what, const float *a, const float *b, size_t n,
                         double atol, double rtol) {
  for (size_t i = 0; i < n; i++) {
    double d = fabs((double)a[i] - (double)b[i]);
    if (!(d <= atol + rtol * fabs((double)b[i])))
      FG_TEST_FAIL("%s[%zu]: %.9g vs %.9g (atol %g, rtol %g)", what, i, (double)a[i],
                   (double)b[i], atol, rtol);
  }
}

/* ---- the loss in double --------------------------------------------------------------- */

/* y_r = g . outputs of ray r with its first n samples, all in double. Each parameter array
 * may be replaced by a double copy (the one being perturbed); the others come from b. */
static double ray_loss(const batch *b, int32_t r, int32_t n, const double *sigma,
                       const double *rgb, const double *feat) {
  const size_t o = (size_t)b->offset[r], Dz = (size_t)b->D;
  const float *bg = b->bg_per_ray ? b->bg + 3 * (size_t)r : b->bg;
  double T = 1.0, y = 0.0;
  for (int32_t i = 0; i < n; i++) {
    size_t s = o + (size_t)i;
    double x = sigma[s] * (double)b->dt[s];
    double w = T * -expm1(-x);
    double v = (double)b->g_depth[r] * b->t[s] + b->g_opacity[r];
    for (int k = 0; k < 3; k++) v += (double)b->g_rgb[3 * r + k] * rgb[3 * s + k];
    for (size_t d = 0; d < Dz; d++) v += (double)b->g_feat[(size_t)r * Dz + d] * feat[s * Dz + d];
    y += w * v;
    T *= exp(-x);
  }
  for (int k = 0; k < 3; k++) y += T * (double)b->g_rgb[3 * r + k] * bg[k];
  return y;
}

static double *to_double(const float *x, size_t n) {
  double *y = xcalloc(n, sizeof(double));
  for (size_t i = 0; i < n; i++) y[i] = x[i];
  return y;
}

/* Central differences of ray_loss for every sigma, rgb and feat value of every used sample,
 * against the gradients in b (from the threaded backward); n_used is the cut held fixed.
 * Returns the largest |fd| seen, so that callers can tell that the check had teeth. */
static double check_fd(batch *b) {
  size_t S = (size_t)b->S, Dz = (size_t)b->D;
  double *sigma = to_double(b->sigma, S), *rgb = to_double(b->rgb, 3 * S);
  double *feat = b->D ? to_double(b->feat, S * Dz) : NULL;
  double max_fd = 0.0;
  struct {
    const char *name;
    double *p;
    const float *grad;
    size_t per_sample;
  } params[] = {{"d_sigma", sigma, b->d_sigma, 1},
                {"d_rgb", rgb, b->d_rgb, 3},
                {"d_feat", feat, b->d_feat, Dz}};
  for (size_t k = 0; k < 3; k++) {
    if (!params[k].p) continue;
    for (int32_t r = 0; r < b->R; r++) {
      int32_t n = b->n_used[r];
      for (size_t j = (size_t)b->offset[r] * params[k].per_sample;
           j < (size_t)(b->offset[r] + n) * params[k].per_sample; j++) {
        double *p = params[k].p, p0 = p[j];
        double eps = 1e-4 * (fabs(p0) > 1.0 ? fabs(p0) : 1.0);
        p[j] = p0 + eps;
        double lp = ray_loss(b, r, n, sigma, rgb, feat);
        p[j] = p0 - eps;
        double lm = ray_loss(b, r, n, sigma, rgb, feat);
        p[j] = p0;
        double fd = (lp - lm) / (2.0 * eps), an = params[k].grad[j];
        if (fabs(fd) > max_fd) max_fd = fabs(fd);
        if (!(fabs(an - fd) <= 2e-6 + 2e-4 * fabs(fd)))
          FG_TEST_FAIL("%s[%zu] (ray %d, n_used %d): analytic %.9g, finite difference %.9g",
                       params[k].name, j, (int)r, (int)n, an, fd);
      }
    }
  }
  free(sigma);
  free(rgb);
  free(feat);
  return max_fd;
}

/* ---- tests ---------------------------------------------------------------------------- */

/* Threaded kernels against the references, on wide densities with early termination. */
static void test_fast_vs_ref(void) {
  static const int Ds[] = {0, 5, 37, 64};
  for (size_t di = 0; di < sizeof Ds / sizeof Ds[0]; di++) {
    for (int bg_per_ray = 0; bg_per_ray < 2; bg_per_ray++) {
      int D = Ds[di];
      batch b = batch_new(300, 48, D, bg_per_ray, SIGMA_WIDE);
      size_t S = (size_t)b.S, R = (size_t)b.R, Dz = (size_t)D;
      float *rgb = xcalloc(3 * R, sizeof(float)), *depth = xcalloc(R, sizeof(float));
      float *opac = xcalloc(R, sizeof(float));
      float *feat = D ? xcalloc(R * Dz, sizeof(float)) : NULL;
      int32_t *n_used = xcalloc(R, sizeof(int32_t));
      fg_render_forward_ref(b.R, b.offset, b.count, b.sigma, b.rgb, b.dt, b.t, b.feat, D, b.bg,
                            bg_per_ray, 1e-4f, rgb, depth, opac, feat, n_used);
      run_forward(&b, 1e-4f, 2);
      int cut = 0;
      for (size_t r = 0; r < R; r++) {
        ASSERT_EQ(b.n_used[r], n_used[r]);
        cut += n_used[r] < b.count[r];
      }
      ASSERT(cut > 10); /* the wide densities do end rays early */
      /* the forward reference does the same float operations in the same order, except
       * for the feature sums; only those may differ */
      ASSERT(memcmp(b.out_rgb, rgb, 3 * R * sizeof(float)) == 0);
      ASSERT(memcmp(b.out_depth, depth, R * sizeof(float)) == 0);
      ASSERT(memcmp(b.out_opacity, opac, R * sizeof(float)) == 0);
      if (D) assert_close("out_feat", b.out_feat, feat, R * Dz, 1e-6, 1e-6);

      float *d_sigma = xcalloc(S, sizeof(float)), *d_rgb = xcalloc(3 * S, sizeof(float));
      float *d_feat = D ? xcalloc(S * Dz, sizeof(float)) : NULL;
      fg_render_backward_ref(b.R, b.offset, b.count, n_used, b.sigma, b.rgb, b.dt, b.t, b.feat,
                             D, b.bg, bg_per_ray, b.g_rgb, b.g_depth, b.g_opacity, b.g_feat,
                             d_sigma, d_rgb, d_feat);
      /* poison the outputs: every value must be written */
      memset(b.d_sigma, 0xff, S * sizeof(float));
      memset(b.d_rgb, 0xff, 3 * S * sizeof(float));
      if (D) memset(b.d_feat, 0xff, S * Dz * sizeof(float));
      run_backward(&b, 2);
      ASSERT(all_finite(b.d_sigma, S) && all_finite(b.d_rgb, 3 * S));
      assert_close("d_sigma", b.d_sigma, d_sigma, S, 1e-6, 1e-4);
      ASSERT(memcmp(b.d_rgb, d_rgb, 3 * S * sizeof(float)) == 0);
      if (D) {
        ASSERT(all_finite(b.d_feat, S * Dz));
        ASSERT(memcmp(b.d_feat, d_feat, S * Dz * sizeof(float)) == 0);
      }
      free(rgb), free(depth), free(opac), free(feat), free(n_used);
      free(d_sigma), free(d_rgb), free(d_feat);
      batch_free(&b);
    }
  }
}

/* Gradients against finite differences, every sample used (threshold 0), with and without a
 * background, with and without features, shared and per-ray backgrounds. */
static void test_fd_full(void) {
  static const int Ds[] = {0, 7, 20};
  for (size_t di = 0; di < sizeof Ds / sizeof Ds[0]; di++) {
    for (int bg_kind = 0; bg_kind < 3; bg_kind++) { /* black, shared colour, per ray */
      batch b = batch_new(40, 24, Ds[di], bg_kind == 2, SIGMA_MODERATE);
      if (bg_kind == 0) memset(b.bg, 0, 3 * sizeof(float));
      run_forward(&b, 0.0f, 2);
      for (int32_t r = 0; r < b.R; r++) ASSERT_EQ(b.n_used[r], b.count[r]);
      run_backward(&b, 2);
      double max_fd = check_fd(&b);
      ASSERT(max_fd > 0.1);
      batch_free(&b);
    }
  }
}

/* The background's pull on density: a single sample in front of a background has
 * d out_rgb / d sigma = dt T_1 (c - bg) exactly. */
static void test_background_gradient(void) {
  int32_t off = 0, cnt = 1, used = 0;
  float sigma = 20.0f, rgb[3] = {0.2f, 0.5f, 0.9f}, dt = 0.03f, t = 1.0f, bg[3] = {1, 1, 1};
  float out[3], depth, opac, g[3] = {1.0f, 0.0f, 0.0f}, d_sigma, d_rgb[3];
  fg_render_forward(1, &off, &cnt, &sigma, rgb, &dt, &t, NULL, 0, bg, 0, 0.0f, out, &depth,
                    &opac, NULL, &used, 1);
  double T1 = exp(-20.0 * 0.03);
  ASSERT_NEAR(out[0], (1 - T1) * 0.2 + T1 * 1.0, 1e-6);
  ASSERT_NEAR(opac, 1 - T1, 1e-6);
  ASSERT_NEAR(depth, (1 - T1) * 1.0, 1e-6);
  fg_render_backward(1, &off, &cnt, &used, &sigma, rgb, &dt, &t, NULL, 0, bg, 0, g, NULL, NULL,
                     NULL, &d_sigma, d_rgb, NULL, 1);
  ASSERT_NEAR(d_sigma, 0.03 * T1 * (0.2 - 1.0), 1e-7);
  ASSERT_NEAR(d_rgb[0], 1 - T1, 1e-6);
  ASSERT_EQ(d_rgb[1], 0);
}

/* Early termination: the cut is where T first falls below the threshold; the used samples'
 * gradients are those of the loss with the cut held fixed (checked by finite differences),
 * and the unused samples get exactly zero. */
static void test_early_termination(void) {
  const float t_min = 0.02f;
  batch b = batch_new(60, 40, 6, 0, SIGMA_MODERATE);
  run_forward(&b, t_min, 2);
  int cut = 0;
  for (int32_t r = 0; r < b.R; r++) {
    const int32_t o = b.offset[r], n = b.n_used[r];
    ASSERT(n <= b.count[r]);
    /* recompute the transmittance in double: >= t_min before every used sample, < t_min
     * after the last one if the ray was cut (the margin covers float rounding) */
    double T = 1.0;
    for (int32_t i = 0; i < n; i++) {
      ASSERT(T >= t_min * (1 - 1e-5));
      T *= exp(-(double)b.sigma[o + i] * b.dt[o + i]);
    }
    if (n < b.count[r]) {
      cut++;
      ASSERT(T < t_min * (1 + 1e-5));
    }
  }
  ASSERT(cut > 20);
  size_t S = (size_t)b.S, Dz = (size_t)b.D;
  memset(b.d_sigma, 0xff, S * sizeof(float));
  memset(b.d_rgb, 0xff, 3 * S * sizeof(float));
  memset(b.d_feat, 0xff, S * Dz * sizeof(float));
  run_backward(&b, 2);
  for (int32_t r = 0; r < b.R; r++) {
    for (int32_t i = b.n_used[r]; i < b.count[r]; i++) {
      size_t s = (size_t)(b.offset[r] + i);
      ASSERT(b.d_sigma[s] == 0.0f);
      for (int k = 0; k < 3; k++) ASSERT(b.d_rgb[3 * s + k] == 0.0f);
      for (size_t d = 0; d < Dz; d++) ASSERT(b.d_feat[s * Dz + d] == 0.0f);
    }
  }
  ASSERT(check_fd(&b) > 0.1);

  /* a ray cut at n renders exactly as the same ray with only its first n samples */
  float *rgb2 = xcalloc(3 * (size_t)b.R, sizeof(float)), *feat2 = xcalloc((size_t)b.R * Dz, 4);
  int32_t *used2 = xcalloc((size_t)b.R, sizeof(int32_t));
  fg_render_forward(b.R, b.offset, b.n_used, b.sigma, b.rgb, b.dt, b.t, b.feat, b.D, b.bg, 0,
                    0.0f, rgb2, NULL, NULL, feat2, used2, 1);
  ASSERT(memcmp(rgb2, b.out_rgb, 3 * (size_t)b.R * sizeof(float)) == 0);
  ASSERT(memcmp(feat2, b.out_feat, (size_t)b.R * Dz * sizeof(float)) == 0);
  ASSERT(memcmp(used2, b.n_used, (size_t)b.R * sizeof(int32_t)) == 0);
  free(rgb2), free(feat2), free(used2);
  batch_free(&b);
}

/* Rays with no samples render the background with opacity 0, depth 0 and a zero feature;
 * a ray of zero densities does too, and its density gradients are dt (v_i - g . bg). */
static void test_empty_and_transparent(void) {
  batch b = batch_new(8, 5, 4, 1, SIGMA_MODERATE);
  for (int32_t r = 0; r < b.R; r += 2) b.count[r] = 0; /* offsets keep their sample ranges */
  for (int32_t s = 0; s < b.S; s++) b.sigma[s] = 0.0f;
  memset(b.out_feat, 0xff, (size_t)b.R * 4 * sizeof(float));
  run_forward(&b, 1e-4f, 2);
  for (int32_t r = 0; r < b.R; r++) {
    for (int k = 0; k < 3; k++) ASSERT(b.out_rgb[3 * r + k] == b.bg[3 * r + k]);
    ASSERT(b.out_depth[r] == 0.0f);
    ASSERT(b.out_opacity[r] == 0.0f);
    for (int d = 0; d < 4; d++) ASSERT(b.out_feat[4 * r + d] == 0.0f);
    ASSERT_EQ(b.n_used[r], b.count[r]);
  }
  run_backward(&b, 2);
  for (int32_t r = 1; r < b.R; r += 2) {
    const float *g = b.g_rgb + 3 * r, *bg = b.bg + 3 * r;
    for (int32_t i = 0; i < b.count[r]; i++) {
      size_t s = (size_t)(b.offset[r] + i);
      double v = (double)g[0] * b.rgb[3 * s] + (double)g[1] * b.rgb[3 * s + 1] +
                 (double)g[2] * b.rgb[3 * s + 2] + (double)b.g_depth[r] * b.t[s] +
                 b.g_opacity[r];
      for (int d = 0; d < 4; d++) v += (double)b.g_feat[4 * r + d] * b.feat[4 * s + d];
      double bgv = (double)g[0] * bg[0] + (double)g[1] * bg[1] + (double)g[2] * bg[2];
      ASSERT_NEAR(b.d_sigma[s], b.dt[s] * (v - bgv), 1e-6);
      for (int k = 0; k < 3; k++) ASSERT(b.d_rgb[3 * s + k] == 0.0f);
    }
  }
  batch_free(&b);
}

/* Huge densities (alpha == 1 in float, transmittance 0 after the sample) and infinities:
 * no NaN anywhere, the first opaque sample takes the whole weight. */
static void test_extreme_sigma(void) {
  static const float big[] = {3.3e6f, 1e30f, FLT_MAX, INFINITY};
  for (size_t k = 0; k < sizeof big / sizeof big[0]; k++) {
    batch b = batch_new(50, 20, 3, 0, SIGMA_WIDE);
    for (int32_t s = 0; s < b.S; s += 3) b.sigma[s] = big[k];
    for (int pass = 0; pass < 2; pass++) {
      run_forward(&b, pass ? 1e-4f : 0.0f, 2);
      run_backward(&b, 2);
      size_t S = (size_t)b.S;
      ASSERT(all_finite(b.out_rgb, 3 * (size_t)b.R) && all_finite(b.out_depth, (size_t)b.R));
      ASSERT(all_finite(b.out_opacity, (size_t)b.R) && all_finite(b.out_feat, 3 * (size_t)b.R));
      ASSERT(all_finite(b.d_sigma, S) && all_finite(b.d_rgb, 3 * S));
      ASSERT(all_finite(b.d_feat, 3 * S));
      for (int32_t r = 0; r < b.R; r++) {
        ASSERT(b.out_opacity[r] >= 0.0f && b.out_opacity[r] <= 1.0f + 1e-6f);
        if (b.count[r] > 0 && b.offset[r] % 3 == 0) { /* first sample opaque */
          ASSERT(b.out_opacity[r] == 1.0f);
          ASSERT_EQ(b.n_used[r], pass ? 1 : b.count[r]);
          for (int c = 0; c < 3; c++) ASSERT(b.out_rgb[3 * r + c] == b.rgb[3 * b.offset[r] + c]);
        }
      }
    }
    batch_free(&b);
  }
}

/* The same inputs give bit-identical outputs and gradients for 1, 2, 3 and the default
 * number of threads. */
static void test_threads_deterministic(void) {
  batch b = batch_new(2000, 40, 33, 1, SIGMA_WIDE);
  size_t R = (size_t)b.R, S = (size_t)b.S, D = (size_t)b.D;
  run_forward(&b, 1e-4f, 1);
  run_backward(&b, 1);
  float *o_rgb = xcalloc(3 * R, 4), *o_feat = xcalloc(R * D, 4), *o_ds = xcalloc(S, 4);
  float *o_drgb = xcalloc(3 * S, 4), *o_df = xcalloc(S * D, 4);
  memcpy(o_rgb, b.out_rgb, 3 * R * 4), memcpy(o_feat, b.out_feat, R * D * 4);
  memcpy(o_ds, b.d_sigma, S * 4), memcpy(o_drgb, b.d_rgb, 3 * S * 4);
  memcpy(o_df, b.d_feat, S * D * 4);
  static const int threads[] = {2, 3, 0};
  for (size_t k = 0; k < 3; k++) {
    run_forward(&b, 1e-4f, threads[k]);
    run_backward(&b, threads[k]);
    ASSERT(memcmp(o_rgb, b.out_rgb, 3 * R * 4) == 0);
    ASSERT(memcmp(o_feat, b.out_feat, R * D * 4) == 0);
    ASSERT(memcmp(o_ds, b.d_sigma, S * 4) == 0);
    ASSERT(memcmp(o_drgb, b.d_rgb, 3 * S * 4) == 0);
    ASSERT(memcmp(o_df, b.d_feat, S * D * 4) == 0);
  }
  free(o_rgb), free(o_feat), free(o_ds), free(o_drgb), free(o_df);
  batch_free(&b);
}

/* Optional outputs and gradients may be NULL. */
static void test_optional_null(void) {
  batch b = batch_new(30, 10, 4, 0, SIGMA_MODERATE);
  size_t S = (size_t)b.S;
  run_forward(&b, 0.0f, 1);
  float *rgb = xcalloc(3 * (size_t)b.R, 4);
  fg_render_forward(b.R, b.offset, b.count, b.sigma, b.rgb, b.dt, b.t, NULL, 0, b.bg, 0, 0.0f,
                    rgb, NULL, NULL, NULL, NULL, 2);
  ASSERT(memcmp(rgb, b.out_rgb, 3 * (size_t)b.R * 4) == 0);
  float *ds = xcalloc(S, 4), *drgb = xcalloc(3 * S, 4), *df = xcalloc(4 * S, 4);
  /* without d_feat, the feature loss still shapes the density */
  run_backward(&b, 1);
  fg_render_backward(b.R, b.offset, b.count, b.n_used, b.sigma, b.rgb, b.dt, b.t, b.feat, 4,
                     b.bg, 0, b.g_rgb, b.g_depth, b.g_opacity, b.g_feat, ds, drgb, NULL, 2);
  ASSERT(memcmp(ds, b.d_sigma, S * 4) == 0);
  ASSERT(memcmp(drgb, b.d_rgb, 3 * S * 4) == 0);
  fg_render_backward_ref(b.R, b.offset, b.count, b.n_used, b.sigma, b.rgb, b.dt, b.t, b.feat, 4,
                         b.bg, 0, b.g_rgb, b.g_depth, b.g_opacity, b.g_feat, ds, drgb, NULL);
  assert_close("d_sigma", ds, b.d_sigma, S, 1e-6, 1e-4);
  /* without depth, opacity and feature gradients, the result equals the full backward with
   * those upstream gradients zeroed, and d_feat is zero */
  memset(b.g_depth, 0, (size_t)b.R * 4), memset(b.g_opacity, 0, (size_t)b.R * 4);
  memset(b.g_feat, 0, (size_t)b.R * 4 * 4);
  run_backward(&b, 1);
  memset(df, 0xff, 4 * S * 4);
  fg_render_backward(b.R, b.offset, b.count, b.n_used, b.sigma, b.rgb, b.dt, b.t, b.feat, 4,
                     b.bg, 0, b.g_rgb, NULL, NULL, NULL, ds, drgb, df, 2);
  ASSERT(memcmp(ds, b.d_sigma, S * 4) == 0);
  ASSERT(memcmp(drgb, b.d_rgb, 3 * S * 4) == 0);
  for (size_t i = 0; i < 4 * S; i++) ASSERT(df[i] == 0.0f);
  free(rgb), free(ds), free(drgb), free(df);
  batch_free(&b);
}

static void test_activations(void) {
  enum { N = 64 };
  float x[N], y[N], g[N], dx[N];
  for (int i = 0; i < N; i++) x[i] = rng_uniform(-14.0f, 14.0f), g[i] = rng_uniform(-1, 1);
  /* trunc_exp: derivative exp(x) inside the clamp */
  fg_act_trunc_exp_forward(y, x, N);
  fg_act_trunc_exp_backward(dx, y, g, N);
  for (int i = 0; i < N; i++) {
    double e = 1e-3, fd = (exp((double)x[i] + e) - exp((double)x[i] - e)) / (2 * e);
    ASSERT_NEAR(y[i], exp((double)x[i]), 1e-6 * exp((double)x[i]));
    ASSERT_NEAR(dx[i], g[i] * fd, 1e-5 * fabs(g[i] * fd) + 1e-30);
  }
  /* ...and truncated outside: the forward value and the gradient stay at exp(+-15) */
  float xc[4] = {-40.0f, -15.5f, 16.0f, 1e30f}, yc[4], gc[4] = {1, 1, 1, 1}, dc[4];
  fg_act_trunc_exp_forward(yc, xc, 4);
  fg_act_trunc_exp_backward(dc, yc, gc, 4);
  ASSERT(yc[0] == expf(-15.0f) && yc[1] == expf(-15.0f) && dc[0] == expf(-15.0f));
  ASSERT(yc[2] == expf(15.0f) && yc[3] == expf(15.0f) && dc[3] == expf(15.0f));
  /* sigmoid */
  for (int i = 0; i < N; i++) x[i] = rng_uniform(-10.0f, 10.0f);
  fg_act_sigmoid_forward(y, x, N);
  fg_act_sigmoid_backward(dx, y, g, N);
  for (int i = 0; i < N; i++) {
    double xd = x[i], e = 1e-4;
    double fd = (1 / (1 + exp(-(xd + e))) - 1 / (1 + exp(-(xd - e)))) / (2 * e);
    ASSERT_NEAR(y[i], 1 / (1 + exp(-xd)), 1e-7);
    ASSERT_NEAR(dx[i], g[i] * fd, 1e-5 * fabs(fd) + 1e-7); /* out (1 - out): 1 - out loses digits */
  }
  float xs[3] = {-200.0f, 200.0f, NAN}, ys[3];
  fg_act_sigmoid_forward(ys, xs, 3);
  ASSERT(ys[0] == 0.0f && ys[1] == 1.0f && isnan(ys[2]));
  fg_act_trunc_exp_forward(ys, xs + 2, 1);
  ASSERT(isnan(ys[0])); /* a diverging training must show */
  /* in place */
  memcpy(y, x, sizeof x);
  fg_act_sigmoid_forward(y, y, N);
  fg_act_sigmoid_forward(dx, x, N);
  ASSERT(memcmp(y, dx, sizeof y) == 0);
}

static void test_losses(void) {
  enum { N = 50 };
  float p[N], q[N], d[N];
  for (int i = 0; i < N; i++) p[i] = rng_uniform(-2, 2), q[i] = rng_uniform(-2, 2);
  double ref = 0;
  for (int i = 0; i < N; i++) ref += ((double)p[i] - q[i]) * ((double)p[i] - q[i]);
  float l = fg_loss_l2(p, q, N, d, 0.5f);
  ASSERT_NEAR(l, ref / N, 1e-6);
  for (int i = 0; i < N; i++) ASSERT_NEAR(d[i], 0.5 * 2 * ((double)p[i] - q[i]) / N, 1e-7);
  ASSERT_NEAR(fg_loss_l2(p, q, N, NULL, 1.0f), l, 0);
  ASSERT(fg_loss_l2(p, q, 0, d, 1.0f) == 0.0f);

  /* Huber against central differences of its own value */
  const float delta = 0.7f;
  float lh = fg_loss_huber(p, q, N, delta, d, 2.0f);
  double refh = 0;
  for (int i = 0; i < N; i++) {
    double e = (double)p[i] - q[i], a = fabs(e);
    refh += a <= delta ? 0.5 * e * e : delta * (a - 0.5 * delta);
  }
  ASSERT_NEAR(lh, refh / N, 1e-6);
  for (int i = 0; i < N; i++) {
    float save = p[i], h = 1e-3f;
    p[i] = save + h;
    double lp = fg_loss_huber(p, q, N, delta, NULL, 1.0f);
    p[i] = save - h;
    double lm = fg_loss_huber(p, q, N, delta, NULL, 1.0f);
    p[i] = save;
    double fd = 2.0 * (lp - lm) / ((double)(save + h) - (double)(save - h));
    ASSERT_NEAR(d[i], fd, 2e-4);
  }
}

/* The geometry losses of fg_loss_ray_weights, straight from their definitions (render.h) in
 * double: weights, then the depth and distortion sums, O(n^2) per ray. */
static double ray_weights_ref(const batch *b, const double *sigma, const float *z, double margin,
                              double w_depth, double w_dist, double *ld_out, double *lw_out) {
  double ld = 0.0, lw = 0.0;
  for (int32_t r = 0; r < b->R; r++) {
    const int32_t o = b->offset[r], m = b->count[r];
    double w[64], T = 1.0;
    for (int32_t i = 0; i < m; i++) {
      const double a = 1.0 - exp(-sigma[o + i] * b->dt[o + i]);
      w[i] = T * a;
      T *= 1.0 - a;
    }
    for (int32_t i = 0; i < m; i++) {
      for (int32_t j = 0; j < m; j++) lw += w[i] * w[j] * fabs((double)b->t[o + i] - b->t[o + j]);
      lw += w[i] * w[i] * b->dt[o + i] / 3.0;
    }
    if (z[r] > 0.0f) {
      double E = 0.0, l = 1.0;
      for (int32_t i = 0; i < m; i++) {
        const double rel = (double)b->t[o + i] - z[r];
        if (rel < -margin) l += w[i];
        if (fabs(rel) <= margin) l -= w[i], E += w[i] * rel;
      }
      ld += l + (E / margin) * (E / margin);
    }
  }
  if (ld_out) *ld_out = ld;
  if (lw_out) *lw_out = lw;
  return w_depth * ld + w_dist * lw;
}

/* fg_loss_ray_weights' sums against the reference, and its gradient, taken to sigma through
 * fg_render_backward as render.h says, against central differences of the reference. */
static void test_ray_weight_losses(void) {
  batch b = batch_new(40, 12, 1, 0, SIGMA_MODERATE);
  float *z = xcalloc((size_t)b.R, sizeof(float)), *g = xcalloc((size_t)b.S, sizeof(float));
  float *ones = xcalloc((size_t)b.R, sizeof(float));
  int with_depth = 0;
  for (int32_t r = 0; r < b.R; r++) {
    ones[r] = 1.0f;
    memset(b.g_rgb + 3 * r, 0, 3 * sizeof(float));
    if (r % 5 != 4 && b.count[r] > 0) { /* a measurement inside the ray's samples */
      const int32_t o = b.offset[r], m = b.count[r];
      z[r] = rng_uniform(b.t[o], b.t[o + m - 1]);
      with_depth++;
    }
  }
  const float margin = 0.03f, w_depth = 0.7f, w_dist = 2.5f;
  run_forward(&b, 0.0f, 2); /* every sample used */
  double ld, lw;
  int32_t nd;
  fg_loss_ray_weights(b.R, b.offset, b.count, b.n_used, b.sigma, b.dt, b.t, z, margin, w_depth,
                      w_dist, g, &ld, &nd, &lw, 2);
  double *sig = to_double(b.sigma, (size_t)b.S);
  double ld_ref, lw_ref;
  ray_weights_ref(&b, sig, z, margin, w_depth, w_dist, &ld_ref, &lw_ref);
  ASSERT_EQ(nd, with_depth);
  ASSERT_NEAR(ld, ld_ref, 1e-4 * fabs(ld_ref) + 1e-5);
  ASSERT_NEAR(lw, lw_ref, 1e-4 * fabs(lw_ref) + 1e-6);
  ASSERT(ld_ref > 1.0 && lw_ref > 0.01); /* both terms have something to say */

  /* identical g on one and on three threads */
  float *g1 = xcalloc((size_t)b.S, sizeof(float));
  double ld1, lw1;
  int32_t nd1;
  fg_loss_ray_weights(b.R, b.offset, b.count, b.n_used, b.sigma, b.dt, b.t, z, margin, w_depth,
                      w_dist, g1, &ld1, &nd1, &lw1, 1);
  ASSERT(memcmp(g, g1, (size_t)b.S * sizeof(float)) == 0);
  free(g1);

  fg_render_backward(b.R, b.offset, b.count, b.n_used, b.sigma, b.rgb, b.dt, b.t, g, 1, b.bg, 0,
                     b.g_rgb, NULL, NULL, ones, b.d_sigma, b.d_rgb, NULL, 2);
  int checked = 0;
  for (int32_t s = 0; s < b.S; s++) {
    const double keep = sig[s], h = 1e-4 * fmax(1.0, keep);
    sig[s] = keep + h;
    const double lp = ray_weights_ref(&b, sig, z, margin, w_depth, w_dist, NULL, NULL);
    sig[s] = keep - h;
    const double lm = ray_weights_ref(&b, sig, z, margin, w_depth, w_dist, NULL, NULL);
    sig[s] = keep;
    const double fd = (lp - lm) / (2.0 * h);
    if (!(fabs(fd - b.d_sigma[s]) <= 2e-3 * fabs(fd) + 2e-4))
      FG_TEST_FAIL("d sigma[%d]: analytic %.9g, finite difference %.9g", s,
                   (double)b.d_sigma[s], fd);
    checked += fabs(fd) > 1e-3;
  }
  printf("ray weight losses: %d of %d sample gradients above 1e-3 checked\n", checked, b.S);
  ASSERT(checked > b.S / 4); /* behind a window only the distortion term acts */

  /* without depth and distortion weight: g is zero, the sums still come back */
  fg_loss_ray_weights(b.R, b.offset, b.count, b.n_used, b.sigma, b.dt, b.t, NULL, margin, 0.0f,
                      0.0f, g, &ld, &nd, &lw, 2);
  ASSERT_EQ(nd, 0);
  ASSERT(ld == 0.0);
  for (int32_t s = 0; s < b.S; s++) ASSERT(g[s] == 0.0f);
  free(sig);
  free(z);
  free(g);
  free(ones);
  batch_free(&b);
}

int main(void) {
  rng_state = 12345;
  test_fast_vs_ref();
  test_fd_full();
  test_background_gradient();
  test_early_termination();
  test_empty_and_transparent();
  test_extreme_sigma();
  test_threads_deterministic();
  test_optional_null();
  test_activations();
  test_losses();
  test_ray_weight_losses();
  printf("render: all tests passed\n");
  return 0;
}
