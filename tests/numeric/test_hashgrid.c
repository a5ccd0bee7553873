/* Hash-grid encoding and SH direction encoding: level geometry, fast kernels against the
 * references (bit for bit), an independent double-precision transcription of tiny-cuda-nn's
 * lookup, finite-difference gradients, grid vertices and the cube boundary, determinism across
 * thread counts; SH against the associated-Legendre definition and orthonormality. */
#include "test.h"

#include "core/error.h"
#include "field/hashgrid.h"
#include "field/sh.h"

#include <stdint.h>

/* ---- helpers -------------------------------------------------------------------------- */

static uint64_t rng_state = 42;

static uint64_t rng_u64(void) {
  uint64_t z = (rng_state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

/* Uniform in [0, 1). */
static double urand(void) { return (double)(rng_u64() >> 11) * 0x1p-53; }

static void *xmalloc(size_t n) {
  void *p = malloc(n ? n : 1);
  if (!p) FG_TEST_FAIL("out of memory (%zu bytes)", n);
  return p;
}

static float *alloc_params(const fg_hashgrid_config *cfg, size_t *n) {
  ASSERT_OK(fg_hashgrid_layout(cfg, NULL, n));
  return xmalloc(*n * sizeof(float));
}

static void fill_uniform(float *v, size_t n, float lo, float hi) {
  for (size_t i = 0; i < n; i++) v[i] = lo + (hi - lo) * (float)urand();
}

static fg_hashgrid_config make_cfg(int L, int F, int log2_T, int n_min, int n_max) {
  fg_hashgrid_config c = {L, F, log2_T, n_min, n_max};
  return c;
}

/* Small config with both kinds of level: scales 3, 7, 15, 31, resolutions 4, 8 (dense,
 * 64 and 512 <= 1024 entries), 16, 32 (hashed). */
static fg_hashgrid_config small_cfg(void) { return make_cfg(4, 2, 10, 4, 32); }

/* ---- an independent transcription of tiny-cuda-nn's lookup, in double --------------------- */

/* tcnn's grid_index (strides while they fit, hash otherwise, modulo the table size). */
static uint32_t tcnn_grid_index(int dense, uint32_t hashmap_size, uint32_t res,
                                const uint32_t pos_grid[3]) {
  static const uint32_t primes[3] = {1u, 2654435761u, 805459861u};
  uint32_t stride = 1, index = 0;
  for (int dim = 0; dim < 3 && stride <= hashmap_size; dim++) {
    index += pos_grid[dim] * stride;
    stride *= res;
  }
  if (!dense && hashmap_size < stride) {
    index = 0;
    for (int dim = 0; dim < 3; dim++) index ^= pos_grid[dim] * primes[dim];
  }
  return index % hashmap_size;
}

/* Level l of sample xi, feature f, interpolated in double from the same float positions. */
static double tcnn_encode(const fg_hashgrid_config *cfg, const float *params, const float *xi,
                          int l, int f) {
  fg_hashgrid_level lv;
  ASSERT_OK(fg_hashgrid_level_info(cfg, l, &lv));
  float pos[3];
  uint32_t g[3];
  for (int d = 0; d < 3; d++) {
    float v = xi[d];
    v = v != v ? 0.0f : v < 0.0f ? 0.0f : v > 1.0f ? 1.0f : v;
    float p = v * lv.scale + 0.5f;
    float fl = floorf(p);
    g[d] = (uint32_t)(int)fl;
    pos[d] = p - fl;
  }
  double sum = 0.0;
  for (uint32_t idx = 0; idx < 8; idx++) {
    double w = 1.0;
    uint32_t local[3];
    for (int d = 0; d < 3; d++) {
      if ((idx & (1u << d)) == 0) {
        w *= 1.0 - pos[d];
        local[d] = g[d];
      } else {
        w *= pos[d];
        local[d] = g[d] + 1;
      }
    }
    uint32_t e = tcnn_grid_index(lv.dense, lv.n_entries, lv.resolution, local);
    sum += w * params[lv.offset + (size_t)e * cfg->n_features + f];
  }
  return sum;
}

/* ---- configuration -------------------------------------------------------------------- */

static void test_config(void) {
  fg_hashgrid_config c;
  size_t n;
  fg_hashgrid_config_default(&c);
  ASSERT_OK(fg_hashgrid_config_check(&c));
  c.n_levels = 0;
  ASSERT_ERR(fg_hashgrid_layout(&c, NULL, &n), FG_EINVAL, "n_levels");
  fg_hashgrid_config_default(&c);
  c.n_features = 17;
  ASSERT_ERR(fg_hashgrid_layout(&c, NULL, &n), FG_EINVAL, "n_features");
  fg_hashgrid_config_default(&c);
  c.log2_table_size = 29;
  ASSERT_ERR(fg_hashgrid_layout(&c, NULL, &n), FG_EINVAL, "log2_table_size");
  fg_hashgrid_config_default(&c);
  c.finest_resolution = 8;
  ASSERT_ERR(fg_hashgrid_layout(&c, NULL, &n), FG_EINVAL, "finest_resolution");
  fg_hashgrid_config_default(&c);
  c.base_resolution = 1;
  ASSERT_ERR(fg_hashgrid_layout(&c, NULL, &n), FG_EINVAL, "base_resolution");
  fg_hashgrid_level lv;
  fg_hashgrid_config_default(&c);
  ASSERT_ERR(fg_hashgrid_level_info(&c, 16, &lv), FG_EINVAL, "level");
}

/* Default config: levels as Instant-NGP's NeRF has them (b = 128^(1/15) ~ 1.3819). */
static void test_default_levels(void) {
  static const uint32_t res[16] = {16,  23,  31,  43,  59,  81,   112,  154,
                                   213, 295, 407, 562, 777, 1073, 1483, 2048};
  static const uint32_t entries[5] = {4096, 12168, 29792, 79512, 205384};
  fg_hashgrid_config c;
  fg_hashgrid_config_default(&c);
  size_t offsets[16], n = 0, expect_off = 0;
  ASSERT_OK(fg_hashgrid_layout(&c, offsets, &n));
  printf("default hash grid (L=16 F=2 T=2^19 N_min=16 N_max=2048):\n");
  for (int l = 0; l < 16; l++) {
    fg_hashgrid_level lv;
    ASSERT_OK(fg_hashgrid_level_info(&c, l, &lv));
    printf("  level %2d scale %9.4f res %5u %-6s entries %7u offset %9zu\n", l, lv.scale,
           lv.resolution, lv.dense ? "dense" : "hashed", lv.n_entries, lv.offset);
    ASSERT_EQ(lv.resolution, res[l]);
    ASSERT_EQ(lv.dense, l < 5);
    ASSERT_EQ(lv.dense, (uint64_t)res[l] * res[l] * res[l] <= (1u << 19));
    ASSERT_EQ(lv.n_entries, l < 5 ? entries[l] : 1u << 19);
    ASSERT_EQ(lv.offset, expect_off);
    ASSERT_EQ(offsets[l], expect_off);
    expect_off += (size_t)lv.n_entries * 2;
  }
  ASSERT_EQ(n, 12196240);
  ASSERT_EQ(n, expect_off);
  fg_hashgrid_level first, last;
  ASSERT_OK(fg_hashgrid_level_info(&c, 0, &first));
  ASSERT_OK(fg_hashgrid_level_info(&c, 15, &last));
  ASSERT(first.scale == 15.0f);
  ASSERT(last.scale == 2047.0f);

  /* the feature-field config of the benchmark: 9 dense levels up to res 73, 3 hashed */
  c = make_cfg(12, 4, 19, 16, 128);
  for (int l = 0; l < 12; l++) {
    fg_hashgrid_level lv;
    ASSERT_OK(fg_hashgrid_level_info(&c, l, &lv));
    ASSERT_EQ(lv.dense, l < 9);
  }
  /* small config: dense, dense, hashed, hashed */
  c = small_cfg();
  static const uint32_t small_res[4] = {4, 8, 16, 32};
  for (int l = 0; l < 4; l++) {
    fg_hashgrid_level lv;
    ASSERT_OK(fg_hashgrid_level_info(&c, l, &lv));
    ASSERT_EQ(lv.resolution, small_res[l]);
    ASSERT_EQ(lv.dense, l < 2);
    ASSERT_EQ(lv.n_entries, l < 2 ? small_res[l] * small_res[l] * small_res[l] : 1024u);
  }
  /* res^3 == T exactly is still dense: level 0 has res 16 and T = 4096 */
  c = make_cfg(2, 2, 12, 16, 32);
  {
    fg_hashgrid_level lv;
    ASSERT_OK(fg_hashgrid_level_info(&c, 0, &lv));
    ASSERT_EQ(lv.resolution, 16);
    ASSERT_EQ(lv.dense, 1);
    ASSERT_EQ(lv.n_entries, 4096);
    ASSERT_OK(fg_hashgrid_level_info(&c, 1, &lv));
    ASSERT_EQ(lv.dense, 0);
  }
  /* a single level */
  c = make_cfg(1, 2, 12, 8, 8);
  ASSERT_OK(fg_hashgrid_layout(&c, offsets, &n));
  ASSERT_EQ(n, 2 * 512);
}

static void test_init(void) {
  fg_hashgrid_config c = small_cfg();
  size_t n;
  float *a = alloc_params(&c, &n), *b = xmalloc(n * sizeof(float));
  ASSERT_OK(fg_hashgrid_init(&c, a, 7));
  ASSERT_OK(fg_hashgrid_init(&c, b, 7));
  ASSERT(memcmp(a, b, n * sizeof(float)) == 0);
  double sum = 0.0, amax = 0.0;
  for (size_t i = 0; i < n; i++) {
    ASSERT(a[i] >= -1e-4f && a[i] <= 1e-4f);
    sum += a[i];
    if (fabs(a[i]) > amax) amax = fabs(a[i]);
  }
  ASSERT(amax > 0.99e-4);
  ASSERT(fabs(sum / n) < 1e-5); /* n ~ 10^4: the mean's sd is ~6e-7 */
  ASSERT_OK(fg_hashgrid_init(&c, b, 8));
  ASSERT(memcmp(a, b, n * sizeof(float)) != 0);
  free(a);
  free(b);
}

/* ---- points ----------------------------------------------------------------------------- */

/* Points into x: n_random uniform ones, then the 27 points of {0, 0.5, 1}^3 (cube corners,
 * edge and face centres), points outside the cube and non-finite ones (N_EXTRA_POINTS in all).
 * Returns the number written. */
static int make_points(float *x, int n_random) {
  int B = 0;
  for (int i = 0; i < n_random; i++, B++)
    for (int d = 0; d < 3; d++) x[B * 3 + d] = (float)urand();
  for (int i = 0; i < 27; i++, B++) {
    x[B * 3 + 0] = 0.5f * (float)(i % 3);
    x[B * 3 + 1] = 0.5f * (float)(i / 3 % 3);
    x[B * 3 + 2] = 0.5f * (float)(i / 9);
  }
  static const float odd[][3] = {
      {-0.5f, 0.3f, 1.5f}, {2.0f, -1.0f, 0.7f}, {INFINITY, -INFINITY, 0.2f},
      {NAN, 0.4f, NAN},    {1.0f, 1.0f, 1.0f},  {0.99999994f, 0.0f, 1e-30f},
  };
  for (size_t i = 0; i < sizeof odd / sizeof odd[0]; i++, B++)
    for (int d = 0; d < 3; d++) x[B * 3 + d] = odd[i][d];
  return B;
}
#define N_EXTRA_POINTS (27 + 6)

/* ---- fast against reference ------------------------------------------------------------- */

static void check_fast_vs_ref(const fg_hashgrid_config *c, int n_random) {
  size_t n;
  float *params = alloc_params(c, &n);
  fill_uniform(params, n, -1.0f, 1.0f);
  const int LF = c->n_levels * c->n_features;
  float *x = xmalloc((size_t)(n_random + N_EXTRA_POINTS) * 3 * sizeof(float));
  const int B = make_points(x, n_random);
  float *out_ref = xmalloc((size_t)B * LF * sizeof(float));
  float *out = xmalloc((size_t)B * LF * sizeof(float));
  float *dout = xmalloc((size_t)B * LF * sizeof(float));
  float *g_ref = xmalloc(n * sizeof(float)), *g = xmalloc(n * sizeof(float));
  fill_uniform(dout, (size_t)B * LF, -1.0f, 1.0f);

  fg_hashgrid_forward_ref(c, params, x, B, out_ref);
  for (size_t i = 0; i < (size_t)B * LF; i++) ASSERT(isfinite(out_ref[i]));
  /* the grads start from nonzero values: the kernels accumulate */
  fill_uniform(g_ref, n, -1.0f, 1.0f);
  float *g0 = xmalloc(n * sizeof(float));
  memcpy(g0, g_ref, n * sizeof(float));
  fg_hashgrid_backward_ref(c, x, B, dout, g_ref);

  static const int threads[] = {1, 2, 3, 0};
  for (size_t t = 0; t < sizeof threads / sizeof threads[0]; t++) {
    memset(out, 0xff, (size_t)B * LF * sizeof(float));
    fg_hashgrid_forward(c, params, x, B, out, threads[t]);
    for (size_t i = 0; i < (size_t)B * LF; i++)
      if (memcmp(&out[i], &out_ref[i], sizeof(float)) != 0)
        FG_TEST_FAIL("forward L=%d F=%d threads %d: out[%zu] = %.9g, reference %.9g",
                     c->n_levels, c->n_features, threads[t], i, out[i], out_ref[i]);
    memcpy(g, g0, n * sizeof(float));
    fg_hashgrid_backward(c, x, B, dout, g, threads[t]);
    for (size_t i = 0; i < n; i++)
      if (memcmp(&g[i], &g_ref[i], sizeof(float)) != 0)
        FG_TEST_FAIL("backward L=%d F=%d threads %d: grad[%zu] = %.9g, reference %.9g",
                     c->n_levels, c->n_features, threads[t], i, g[i], g_ref[i]);
  }

  /* the reference agrees with the independent tcnn transcription (in double) */
  for (int i = 0; i < B; i++)
    for (int l = 0; l < c->n_levels; l++)
      for (int f = 0; f < c->n_features; f++) {
        double e = tcnn_encode(c, params, x + (size_t)i * 3, l, f);
        ASSERT_NEAR(out_ref[(size_t)i * LF + l * c->n_features + f], e, 4e-6);
      }

  /* out-of-range points encode as their clamped versions */
  for (int i = 0; i < B; i++) {
    float xc[3];
    for (int d = 0; d < 3; d++) {
      float v = x[i * 3 + d];
      xc[d] = v != v ? 0.0f : v < 0.0f ? 0.0f : v > 1.0f ? 1.0f : v;
    }
    float oc[FG_HASHGRID_MAX_LEVELS * FG_HASHGRID_MAX_FEATURES];
    fg_hashgrid_forward(c, params, xc, 1, oc, 1);
    ASSERT(memcmp(oc, out_ref + (size_t)i * LF, (size_t)LF * sizeof(float)) == 0);
  }
  free(params);
  free(x);
  free(out_ref);
  free(out);
  free(dout);
  free(g_ref);
  free(g);
  free(g0);
}

static void test_fast_vs_ref(void) {
  fg_hashgrid_config c;
  fg_hashgrid_config_default(&c);
  check_fast_vs_ref(&c, 3000);
  c = small_cfg();
  check_fast_vs_ref(&c, 3000);
  c = make_cfg(12, 4, 19, 16, 128); /* feature grid */
  check_fast_vs_ref(&c, 2000);
  c = make_cfg(8, 8, 14, 8, 256);
  check_fast_vs_ref(&c, 1000);
  c = make_cfg(5, 3, 12, 2, 64); /* generic F path, a res-3 level */
  check_fast_vs_ref(&c, 1000);
  c = make_cfg(3, 1, 8, 4, 16);
  check_fast_vs_ref(&c, 500);
  c = make_cfg(1, 2, 16, 20, 20);
  check_fast_vs_ref(&c, 500);
  c = make_cfg(2, 2, 12, 16, 32); /* a dense level with res^3 == T: no padding to wrap into */
  check_fast_vs_ref(&c, 500);
}

/* ---- gradient by finite differences ----------------------------------------------------- */

static double weighted_sum(const fg_hashgrid_config *c, const float *params, const float *x,
                           int B, const float *w, float *out) {
  const size_t m = (size_t)B * c->n_levels * c->n_features;
  fg_hashgrid_forward(c, params, x, B, out, 2);
  double s = 0.0;
  for (size_t i = 0; i < m; i++) s += (double)w[i] * out[i];
  return s;
}

static void test_finite_differences(void) {
  fg_hashgrid_config c = small_cfg();
  size_t n;
  float *params = alloc_params(&c, &n);
  fill_uniform(params, n, -1.0f, 1.0f);
  const int B = 48, LF = c.n_levels * c.n_features;
  float x[48 * 3];
  for (int i = 0; i < B * 3; i++) x[i] = (float)urand();
  x[0] = x[1] = x[2] = 1.0f; /* a boundary point whose dense corners wrap */
  float *w = xmalloc((size_t)B * LF * sizeof(float));
  float *out = xmalloc((size_t)B * LF * sizeof(float));
  float *grad = xmalloc(n * sizeof(float));
  fill_uniform(w, (size_t)B * LF, -1.0f, 1.0f);
  memset(grad, 0, n * sizeof(float));
  fg_hashgrid_backward(&c, x, B, w, grad, 2);

  /* half the checks at random entries (mostly untouched in the hashed levels: gradient 0),
   * half at entries the samples use */
  size_t used[4096];
  size_t n_used = 0;
  for (size_t i = 0; i < n && n_used < 4096; i++)
    if (grad[i] != 0.0f) used[n_used++] = i;
  ASSERT(n_used > 100);
  const float eps = 1e-2f;
  double worst = 0.0;
  for (int k = 0; k < 400; k++) {
    const size_t j = k % 2 ? used[rng_u64() % n_used] : (size_t)(rng_u64() % n);
    const float p = params[j];
    params[j] = p + eps;
    const double lp = weighted_sum(&c, params, x, B, w, out);
    params[j] = p - eps;
    const double lm = weighted_sum(&c, params, x, B, w, out);
    params[j] = p;
    const double fd = (lp - lm) / ((double)(p + eps) - (double)(p - eps));
    const double err = fabs(fd - grad[j]) / fmax(1.0, fabs(grad[j]));
    if (err > worst) worst = err;
    if (err > 1e-3)
      FG_TEST_FAIL("d loss / d param[%zu]: backward %.9g, finite difference %.9g", j,
                   grad[j], fd);
  }
  printf("finite differences: 400 entries, worst relative error %.3g\n", worst);
  free(params);
  free(w);
  free(out);
  free(grad);
}

/* ---- grid vertices and the cube boundary ---------------------------------------------- */

static void test_vertices(void) {
  fg_hashgrid_config c = small_cfg();
  size_t n;
  float *params = alloc_params(&c, &n);
  fill_uniform(params, n, -1.0f, 1.0f);
  float out[4 * 2];

  /* x = 0.5 is a vertex of every level here (scale odd: pos = (scale+1)/2, frac 0): the
   * encoding is that vertex's entry, exactly, and the gradient goes to it alone. */
  const float centre[3] = {0.5f, 0.5f, 0.5f};
  fg_hashgrid_forward(&c, params, centre, 1, out, 1);
  float *grad = xmalloc(n * sizeof(float));
  memset(grad, 0, n * sizeof(float));
  float dout[8] = {1, 1, 1, 1, 1, 1, 1, 1};
  fg_hashgrid_backward(&c, centre, 1, dout, grad, 1);
  for (int l = 0; l < 4; l++) {
    fg_hashgrid_level lv;
    ASSERT_OK(fg_hashgrid_level_info(&c, l, &lv));
    const uint32_t v = (uint32_t)(lv.scale + 1.0f) / 2;
    const uint32_t g[3] = {v, v, v};
    const uint32_t e = tcnn_grid_index(lv.dense, lv.n_entries, lv.resolution, g);
    for (int f = 0; f < 2; f++) ASSERT(out[l * 2 + f] == params[lv.offset + e * 2 + f]);
    int nonzero = 0;
    for (size_t i = lv.offset; i < lv.offset + (size_t)lv.n_entries * 2; i++)
      nonzero += grad[i] != 0.0f;
    ASSERT_EQ(nonzero, 2);
    ASSERT(grad[lv.offset + e * 2] == 1.0f);
    ASSERT(grad[lv.offset + e * 2 + 1] == 1.0f);
  }

  /* Vertices k of each level, at x = (k - 0.5) / scale: the encoding is the vertex entry up to
   * the rounding of x (the float pos lands within an ulp of k), and matches the reference. */
  for (int l = 0; l < 4; l++) {
    fg_hashgrid_level lv;
    ASSERT_OK(fg_hashgrid_level_info(&c, l, &lv));
    for (int trial = 0; trial < 200; trial++) {
      uint32_t k[3];
      float xv[3];
      for (int d = 0; d < 3; d++) {
        k[d] = 1 + (uint32_t)(rng_u64() % (uint32_t)lv.scale); /* 1..scale: x in (0, 1) */
        xv[d] = (float)((k[d] - 0.5) / lv.scale);
      }
      float o_ref[8];
      fg_hashgrid_forward(&c, params, xv, 1, out, 1);
      fg_hashgrid_forward_ref(&c, params, xv, 1, o_ref);
      ASSERT(memcmp(out, o_ref, sizeof out) == 0);
      const uint32_t e = tcnn_grid_index(lv.dense, lv.n_entries, lv.resolution, k);
      for (int f = 0; f < 2; f++)
        ASSERT_NEAR(out[l * 2 + f], params[lv.offset + e * 2 + f], 1e-4);
    }
  }

  /* Faces of the cube: x = 0 gives pos = 0.5 on every level (the average of vertices 0 and 1
   * along that axis), x = 1 gives pos = scale + 0.5 (vertices scale and scale + 1: on the
   * dense levels the latter is the wrapped index, as in tcnn). Checked in double. */
  for (int trial = 0; trial < 200; trial++) {
    float xb[3];
    for (int d = 0; d < 3; d++) xb[d] = (float)urand();
    xb[trial % 3] = (trial / 3) % 2 ? 1.0f : 0.0f;
    if (trial % 7 == 0) xb[(trial + 1) % 3] = 1.0f;
    fg_hashgrid_forward(&c, params, xb, 1, out, 2);
    for (int l = 0; l < 4; l++)
      for (int f = 0; f < 2; f++)
        ASSERT_NEAR(out[l * 2 + f], tcnn_encode(&c, params, xb, l, f), 4e-6);
  }
  free(params);
  free(grad);
}

/* ---- determinism -------------------------------------------------------------------------- */

static void test_determinism(void) {
  fg_hashgrid_config c;
  fg_hashgrid_config_default(&c);
  size_t n;
  float *params = alloc_params(&c, &n);
  ASSERT_OK(fg_hashgrid_init(&c, params, 1));
  const int B = 20000, LF = 32;
  float *x = xmalloc((size_t)B * 3 * sizeof(float));
  /* clustered points, so that entries collect many contributions each */
  for (int i = 0; i < B * 3; i++) x[i] = 0.4f + 0.05f * (float)urand();
  float *dout = xmalloc((size_t)B * LF * sizeof(float));
  fill_uniform(dout, (size_t)B * LF, -1.0f, 1.0f);
  const size_t out_bytes = (size_t)B * LF * sizeof(float);
  float *o1 = xmalloc(out_bytes), *o2 = xmalloc(out_bytes);
  float *g1 = calloc(n, sizeof(float)), *g2 = calloc(n, sizeof(float));
  float *g3 = calloc(n, sizeof(float));
  ASSERT(g1 && g2 && g3);
  fg_hashgrid_forward(&c, params, x, B, o1, 1);
  fg_hashgrid_forward(&c, params, x, B, o2, 2);
  ASSERT(memcmp(o1, o2, out_bytes) == 0);
  fg_hashgrid_forward(&c, params, x, B, o2, 2);
  ASSERT(memcmp(o1, o2, out_bytes) == 0);
  fg_hashgrid_backward(&c, x, B, dout, g1, 1);
  fg_hashgrid_backward(&c, x, B, dout, g2, 2);
  fg_hashgrid_backward(&c, x, B, dout, g3, 2);
  ASSERT(memcmp(g1, g2, n * sizeof(float)) == 0);
  ASSERT(memcmp(g2, g3, n * sizeof(float)) == 0);
  /* B = 0 is a no-op */
  fg_hashgrid_forward(&c, params, x, 0, o1, 2);
  fg_hashgrid_backward(&c, x, 0, dout, g1, 2);
  ASSERT(memcmp(g1, g2, n * sizeof(float)) == 0);
  free(params);
  free(x);
  free(dout);
  free(o1);
  free(o2);
  free(g1);
  free(g2);
  free(g3);
}

/* ---- spherical harmonics ------------------------------------------------------------------ */

/* Associated Legendre P_l^m(z), m >= 0, with the Condon-Shortley phase (standard recurrence). */
static double legendre(int l, int m, double z) {
  double pmm = 1.0, s = sqrt(fmax(0.0, 1.0 - z * z));
  for (int i = 1; i <= m; i++) pmm *= -(2.0 * i - 1.0) * s;
  if (l == m) return pmm;
  double pm1 = z * (2.0 * m + 1.0) * pmm;
  if (l == m + 1) return pm1;
  double pl = 0.0;
  for (int ll = m + 2; ll <= l; ll++) {
    pl = ((2.0 * ll - 1.0) * z * pm1 - (ll + m - 1.0) * pmm) / (ll - m);
    pmm = pm1;
    pm1 = pl;
  }
  return pl;
}

static double factorial(int k) { return k <= 1 ? 1.0 : k * factorial(k - 1); }

/* The orthonormal real SH Y_l^m at a unit direction, from its definition (see sh.h). */
static double sh_direct(int l, int m, const double d[3]) {
  const double phi = atan2(d[1], d[0]);
  const int am = m < 0 ? -m : m;
  const double K = sqrt((2.0 * l + 1.0) / (4.0 * M_PI) * factorial(l - am) / factorial(l + am));
  const double P = legendre(l, am, d[2]);
  if (m == 0) return K * P;
  return sqrt(2.0) * K * P * (m > 0 ? cos(m * phi) : sin(am * phi));
}

static void random_direction(double d[3]) {
  const double z = 2.0 * urand() - 1.0, phi = 2.0 * M_PI * urand(), r = sqrt(1.0 - z * z);
  d[0] = r * cos(phi);
  d[1] = r * sin(phi);
  d[2] = z;
}

static void test_sh_values(void) {
  enum { N = 20000 };
  float *d = xmalloc(N * 3 * sizeof(float)), *out = xmalloc(N * 16 * sizeof(float));
  double *dd = xmalloc(N * 3 * sizeof(double));
  for (int i = 0; i < N; i++) {
    random_direction(dd + i * 3);
    if (i < 6) { /* the axes */
      dd[i * 3 + 0] = dd[i * 3 + 1] = dd[i * 3 + 2] = 0.0;
      dd[i * 3 + i / 2] = i % 2 ? -1.0 : 1.0;
    }
    for (int k = 0; k < 3; k++) d[i * 3 + k] = (float)dd[i * 3 + k];
    /* evaluate the definition at the float direction actually encoded, made unit in double
     * (the definition reads only z and the azimuth; the float vector is unit to ~1e-7) */
    const double nrm = sqrt((double)d[i * 3] * d[i * 3] + (double)d[i * 3 + 1] * d[i * 3 + 1] +
                            (double)d[i * 3 + 2] * d[i * 3 + 2]);
    for (int k = 0; k < 3; k++) dd[i * 3 + k] = d[i * 3 + k] / nrm;
  }
  fg_sh4_encode(d, N, out);
  double worst = 0.0;
  for (int i = 0; i < N; i++)
    for (int l = 0; l < 4; l++)
      for (int m = -l; m <= l; m++) {
        const double e = sh_direct(l, m, dd + i * 3);
        const double got = out[i * 16 + l * l + l + m];
        if (fabs(got - e) > worst) worst = fabs(got - e);
        if (fabs(got - e) > 1e-6)
          FG_TEST_FAIL("SH l=%d m=%d at (%g, %g, %g): %.9g, definition %.9g", l, m,
                       dd[i * 3], dd[i * 3 + 1], dd[i * 3 + 2], got, e);
      }
  printf("SH-4 against the definition: %d directions, worst error %.3g\n", N, worst);
  free(d);
  free(out);
  free(dd);
}

/* Gram matrix of the 16 functions under a weighted set of directions; checks it against
 * I / (4 pi) with a diagonal relative and an off-diagonal absolute tolerance. */
static void check_gram(const float *d, const double *wgt, int N, double tol, const char *what) {
  float *y = xmalloc((size_t)N * 16 * sizeof(float));
  fg_sh4_encode(d, N, y);
  double gram[16][16] = {{0}}, wsum = 0.0;
  for (int i = 0; i < N; i++) {
    const double wi = wgt ? wgt[i] : 1.0;
    wsum += wi;
    for (int a = 0; a < 16; a++)
      for (int b = a; b < 16; b++) gram[a][b] += wi * y[i * 16 + a] * y[i * 16 + b];
  }
  double worst = 0.0;
  const double target = 1.0 / (4.0 * M_PI);
  for (int a = 0; a < 16; a++)
    for (int b = a; b < 16; b++) {
      const double v = gram[a][b] / wsum, err = fabs(v - (a == b ? target : 0.0)) / target;
      if (err > worst) worst = err;
      if (err > tol)
        FG_TEST_FAIL("%s: mean Y_%d Y_%d = %.6g, expected %.6g", what, a, b, v,
                     a == b ? target : 0.0);
    }
  printf("SH-4 orthonormality (%s, %d directions): worst error %.3g of 1/(4 pi)\n", what, N,
         worst);
  free(y);
}

static void test_sh_orthonormal(void) {
  /* Monte Carlo: 10^6 uniform directions, within 2% (the errors are ~0.3% standard deviation) */
  enum { N = 1000000 };
  float *d = xmalloc((size_t)N * 3 * sizeof(float));
  for (int i = 0; i < N; i++) {
    double v[3];
    random_direction(v);
    for (int k = 0; k < 3; k++) d[i * 3 + k] = (float)v[k];
  }
  check_gram(d, NULL, N, 0.02, "Monte Carlo");
  free(d);

  /* Exact quadrature: Gauss-Legendre in z (5 nodes, exact to degree 9) times 12 equally spaced
   * azimuths (exact for trigonometric degree < 12); Y_a Y_b has degree <= 6 in both. */
  static const double gl_x[5] = {-0.9061798459386640, -0.5384693101056831, 0.0,
                                 0.5384693101056831, 0.9061798459386640};
  static const double gl_w[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                                 0.4786286704993665, 0.2369268850561891};
  float q[5 * 12 * 3];
  double qw[5 * 12];
  for (int a = 0; a < 5; a++)
    for (int b = 0; b < 12; b++) {
      const double z = gl_x[a], r = sqrt(1.0 - z * z), phi = 2.0 * M_PI * (b + 0.25) / 12.0;
      q[(a * 12 + b) * 3 + 0] = (float)(r * cos(phi));
      q[(a * 12 + b) * 3 + 1] = (float)(r * sin(phi));
      q[(a * 12 + b) * 3 + 2] = (float)z;
      qw[a * 12 + b] = gl_w[a];
    }
  check_gram(q, qw, 5 * 12, 1e-5, "Gauss-Legendre x uniform azimuth");
}

int main(void) {
  test_config();
  test_default_levels();
  test_init();
  test_fast_vs_ref();
  test_finite_differences();
  test_vertices();
  test_determinism();
  test_sh_values();
  test_sh_orthonormal();
  printf("hashgrid and SH: all passed\n");
  return 0;
}
