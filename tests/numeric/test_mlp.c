/* MLP and Adam: fast kernels against the scalar references, finite-difference gradients,
 * determinism across thread counts, edge cases, Adam against a hand-computed sequence and a
 * small least-squares fit. */
#include "core/error.h"
#include "field/adam.h"
#include "field/mlp.h"
#include "test.h"

#include <stdint.h>

/* ---- helpers ---------------------------------------------------------------------------- */

static uint64_t rng_state = 12345;

static float frand(void) { /* uniform [-1, 1) */
  rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
  return (float)(rng_state >> 40) * 0x1p-23f - 1.0f;
}

static float *falloc(size_t n) {
  float *p = malloc(sizeof(float) * (n ? n : 1));
  ASSERT(p);
  return p;
}

static float *frandom(size_t n, float scale) {
  float *p = falloc(n);
  for (size_t i = 0; i < n; i++) p[i] = scale * frand();
  return p;
}

static float max_abs(const float *a, size_t n) {
  float m = 0.0f;
  for (size_t i = 0; i < n; i++) m = fabsf(a[i]) > m ? fabsf(a[i]) : m;
  return m;
}

/* max |a - b| <= rel * max |b| (and exact agreement when b is all zero). */
static void assert_close(const char *what, const float *a, const float *b, size_t n, float rel) {
  const float scale = max_abs(b, n);
  float err = 0.0f;
  size_t at = 0;
  for (size_t i = 0; i < n; i++)
    if (fabsf(a[i] - b[i]) > err) err = fabsf(a[i] - b[i]), at = i;
  if (!(err <= rel * scale))
    FG_TEST_FAIL("%s: max error %g at %zu (%g vs %g), scale %g, rel tol %g", what, (double)err,
                 at, (double)a[at], (double)b[at], (double)scale, (double)rel);
}

static void assert_same_bits(const char *what, const float *a, const float *b, size_t n) {
  if (n && memcmp(a, b, n * sizeof(float)) != 0) FG_TEST_FAIL("%s: not bit-identical", what);
}

/* ---- config and init -------------------------------------------------------------------- */

static void test_config(void) {
  const fg_mlp_config density = {32, 64, 1, 16}, colour = {32, 64, 2, 3},
                      feature = {32, 64, 2, 512}, linear = {5, 9, 0, 3};
  ASSERT_OK(fg_mlp_config_check(&density));
  ASSERT_EQ(fg_mlp_n_params(&density), 32 * 64 + 64 * 16);
  ASSERT_EQ(fg_mlp_n_params(&colour), 32 * 64 + 64 * 64 + 64 * 3);
  ASSERT_EQ(fg_mlp_n_params(&feature), 32 * 64 + 64 * 64 + 64 * 512);
  ASSERT_EQ(fg_mlp_n_params(&linear), 5 * 3);
  ASSERT_EQ(fg_mlp_layer_offset(&colour, 2), 32 * 64 + 64 * 64);
  ASSERT_EQ(fg_mlp_layer_fan_in(&colour, 2), 64);
  ASSERT_EQ(fg_mlp_layer_fan_out(&colour, 2), 3);
  ASSERT_EQ(fg_mlp_layer_fan_out(&linear, 0), 3);
  ASSERT_EQ(fg_mlp_acts_floats(&colour, 10), 2 * 10 * 64);
  fg_mlp_config bad = density;
  bad.n_hidden = 0;
  ASSERT_ERR(fg_mlp_config_check(&bad), FG_EINVAL, "n_hidden");
  bad = density, bad.n_hidden_layers = -1;
  ASSERT_ERR(fg_mlp_config_check(&bad), FG_EINVAL, "n_hidden_layers");
  bad = density, bad.n_out = FG_MLP_MAX_WIDTH + 1;
  ASSERT_ERR(fg_mlp_config_check(&bad), FG_EINVAL, "n_out");
  ASSERT_ERR(fg_mlp_config_check(NULL), FG_EINVAL, "NULL");

  /* Init: deterministic, within the Glorot bound of each layer, seed-dependent, centred. */
  const size_t n = fg_mlp_n_params(&colour);
  float *a = falloc(n), *b = falloc(n);
  fg_mlp_init(&colour, a, 7);
  fg_mlp_init(&colour, b, 7);
  assert_same_bits("init", a, b, n);
  fg_mlp_init(&colour, b, 8);
  ASSERT(memcmp(a, b, n * sizeof(float)) != 0);
  for (int l = 0; l <= colour.n_hidden_layers; l++) {
    const int K = fg_mlp_layer_fan_in(&colour, l), N = fg_mlp_layer_fan_out(&colour, l);
    const float bound = sqrtf(6.0f / (float)(K + N));
    const float *Wl = a + fg_mlp_layer_offset(&colour, l);
    double mean = 0.0;
    for (int i = 0; i < K * N; i++) {
      ASSERT(fabsf(Wl[i]) <= bound);
      mean += Wl[i];
    }
    mean /= K * N;
    ASSERT(fabs(mean) < 0.1 * bound);
    ASSERT(max_abs(Wl, (size_t)K * N) > 0.9f * bound);
  }
  free(a), free(b);
}

/* ---- fast versus reference, determinism ------------------------------------------------- */

typedef struct run {
  float *acts, *out, *dW, *din;
} run;

static void run_alloc(run *r, const fg_mlp_config *cfg, int B) {
  r->acts = falloc(fg_mlp_acts_floats(cfg, B));
  r->out = falloc((size_t)B * cfg->n_out);
  r->dW = falloc(fg_mlp_n_params(cfg));
  r->din = falloc((size_t)B * cfg->n_in);
}

static void run_free(run *r) { free(r->acts), free(r->out), free(r->dW), free(r->din); }

/* Forward and backward from dW = 0 (test_edges checks the +=). */
static void run_fast(run *r, const fg_mlp_config *cfg, const float *W, const float *in,
                     const float *dout, int B, float *scratch, int n_threads) {
  const size_t np = fg_mlp_n_params(cfg);
  memset(r->dW, 0, np * sizeof(float));
  fg_mlp_forward(cfg, W, in, B, r->acts, r->out, n_threads);
  fg_mlp_backward(cfg, W, in, r->acts, dout, B, r->dW, r->din, scratch, n_threads);
}

static void check_config(const fg_mlp_config *cfg, int B, int check_threads) {
  const size_t np = fg_mlp_n_params(cfg);
  float *W = falloc(np);
  fg_mlp_init(cfg, W, 99);
  float *in = frandom((size_t)B * cfg->n_in, 1.0f);
  float *dout = frandom((size_t)B * cfg->n_out, 1.0f);
  float *scratch = falloc(fg_mlp_scratch_floats(cfg, B));
  run ref, fast;
  run_alloc(&ref, cfg, B);
  run_alloc(&fast, cfg, B);

  fg_mlp_forward_ref(cfg, W, in, B, ref.acts, ref.out);
  memset(ref.dW, 0, np * sizeof(float));
  ASSERT_OK(fg_mlp_backward_ref(cfg, W, in, ref.acts, dout, B, ref.dW, ref.din));

  char what[160];
  for (int kernel = 1; kernel <= 2; kernel++) {
    fg_mlp_set_kernel(kernel);
    snprintf(what, sizeof what, "{%d,%d,%d,%d} B=%d %s", cfg->n_in, cfg->n_hidden,
             cfg->n_hidden_layers, cfg->n_out, B, fg_mlp_kernel_name());
    run_fast(&fast, cfg, W, in, dout, B, scratch, 2);
    assert_close(what, fast.acts, ref.acts, fg_mlp_acts_floats(cfg, B), 1e-5f);
    assert_close(what, fast.out, ref.out, (size_t)B * cfg->n_out, 1e-5f);
    assert_close(what, fast.dW, ref.dW, np, 1e-5f);
    assert_close(what, fast.din, ref.din, (size_t)B * cfg->n_in, 1e-5f);
    if (!check_threads) continue;
    /* Bit-identical for any thread count, and run to run. */
    run other;
    run_alloc(&other, cfg, B);
    const int threads[] = {1, 3, 2};
    for (int t = 0; t < 3; t++) {
      run_fast(&other, cfg, W, in, dout, B, scratch, threads[t]);
      assert_same_bits("acts", other.acts, fast.acts, fg_mlp_acts_floats(cfg, B));
      assert_same_bits("out", other.out, fast.out, (size_t)B * cfg->n_out);
      assert_same_bits("dW", other.dW, fast.dW, np);
      assert_same_bits("din", other.din, fast.din, (size_t)B * cfg->n_in);
    }
    run_free(&other);
  }
  fg_mlp_set_kernel(0);
  run_free(&ref), run_free(&fast);
  free(W), free(in), free(dout), free(scratch);
}

static void test_fast_vs_ref(void) {
  const fg_mlp_config density = {32, 64, 1, 16}, colour = {32, 64, 2, 3},
                      feature = {32, 64, 2, 512}, small = {5, 7, 2, 3}, linear = {5, 9, 0, 3},
                      odd = {19, 40, 3, 33}, wide = {600, 24, 1, 530};
  /* B: one row, less than a tile, not a multiple of 16 or of any chunk, several chunks per
   * group (B = 20011 is cut into 20 chunks of 1024 rows, the most a chunk has, in 16 groups). */
  const int Bs[] = {1, 5, 17, 1000, 3001};
  for (int i = 0; i < 5; i++) {
    check_config(&density, Bs[i], i >= 3);
    check_config(&colour, Bs[i], i >= 3);
    check_config(&small, Bs[i], i >= 3);
    check_config(&linear, Bs[i], 0);
    check_config(&odd, Bs[i], 0);
  }
  check_config(&colour, 20011, 1);
  check_config(&feature, 1000, 1);
  check_config(&wide, 333, 1); /* fan_in 600: the AVX-512 forward falls back to SGEMM */
}

/* ---- finite differences ----------------------------------------------------------------- */

/* L = sum g * out, forward in double with double weights. */
static double loss_double(const fg_mlp_config *cfg, const double *W, const double *in, int B,
                          const double *g, double *min_pre) {
  double L = 0.0, a[64], o[64];
  for (int r = 0; r < B; r++) {
    for (int k = 0; k < cfg->n_in; k++) a[k] = in[(size_t)r * cfg->n_in + k];
    for (int l = 0; l <= cfg->n_hidden_layers; l++) {
      const int K = fg_mlp_layer_fan_in(cfg, l), N = fg_mlp_layer_fan_out(cfg, l);
      const double *Wl = W + fg_mlp_layer_offset(cfg, l);
      for (int j = 0; j < N; j++) {
        double s = 0.0;
        for (int k = 0; k < K; k++) s += a[k] * Wl[j * K + k];
        if (l < cfg->n_hidden_layers) {
          if (min_pre && fabs(s) < *min_pre) *min_pre = fabs(s);
          s = s > 0.0 ? s : 0.0;
        }
        o[j] = s;
      }
      memcpy(a, o, sizeof(double) * (size_t)N);
    }
    for (int j = 0; j < cfg->n_out; j++) L += g[(size_t)r * cfg->n_out + j] * a[j];
  }
  return L;
}

static void test_finite_differences(void) {
  const fg_mlp_config cfg = {5, 7, 2, 3};
  const int B = 9;
  const size_t np = fg_mlp_n_params(&cfg);
  float *W = falloc(np), *in = frandom((size_t)B * 5, 1.0f), *g = frandom((size_t)B * 3, 1.0f);
  fg_mlp_init(&cfg, W, 3);
  double *Wd = malloc(np * sizeof(double)), *ind = malloc(B * 5 * sizeof(double));
  double *gd = malloc(B * 3 * sizeof(double));
  ASSERT(Wd && ind && gd);
  for (size_t i = 0; i < np; i++) Wd[i] = W[i];
  for (int i = 0; i < B * 5; i++) ind[i] = in[i];
  for (int i = 0; i < B * 3; i++) gd[i] = g[i];
  double min_pre = 1e30;
  loss_double(&cfg, Wd, ind, B, gd, &min_pre);
  ASSERT(min_pre > 1e-4); /* no pre-activation near the ReLU kink: differences are valid */

  float *scratch = falloc(fg_mlp_scratch_floats(&cfg, B));
  run fast, ref;
  run_alloc(&fast, &cfg, B);
  run_alloc(&ref, &cfg, B);
  for (int kernel = 1; kernel <= 2; kernel++) {
    fg_mlp_set_kernel(kernel);
    memset(fast.dW, 0, np * sizeof(float));
    fg_mlp_forward(&cfg, W, in, B, fast.acts, fast.out, 2);
    fg_mlp_backward(&cfg, W, in, fast.acts, g, B, fast.dW, fast.din, scratch, 2);
    memset(ref.dW, 0, np * sizeof(float));
    fg_mlp_forward_ref(&cfg, W, in, B, ref.acts, ref.out);
    ASSERT_OK(fg_mlp_backward_ref(&cfg, W, in, ref.acts, g, B, ref.dW, ref.din));
    const double h = 1e-6;
    for (size_t i = 0; i < np; i++) {
      const double w0 = Wd[i];
      Wd[i] = w0 + h;
      const double lp = loss_double(&cfg, Wd, ind, B, gd, NULL);
      Wd[i] = w0 - h;
      const double lm = loss_double(&cfg, Wd, ind, B, gd, NULL);
      Wd[i] = w0;
      const double fd = (lp - lm) / (2 * h);
      ASSERT_NEAR(fast.dW[i], fd, 1e-5 * (1.0 + fabs(fd)));
      ASSERT_NEAR(ref.dW[i], fd, 1e-5 * (1.0 + fabs(fd)));
    }
    for (int i = 0; i < B * 5; i++) {
      const double x0 = ind[i];
      ind[i] = x0 + h;
      const double lp = loss_double(&cfg, Wd, ind, B, gd, NULL);
      ind[i] = x0 - h;
      const double lm = loss_double(&cfg, Wd, ind, B, gd, NULL);
      ind[i] = x0;
      const double fd = (lp - lm) / (2 * h);
      ASSERT_NEAR(fast.din[i], fd, 1e-5 * (1.0 + fabs(fd)));
      ASSERT_NEAR(ref.din[i], fd, 1e-5 * (1.0 + fabs(fd)));
    }
  }
  fg_mlp_set_kernel(0);
  run_free(&fast), run_free(&ref);
  free(W), free(in), free(g), free(Wd), free(ind), free(gd), free(scratch);
}

/* ---- edge cases --------------------------------------------------------------------------- */

static void test_edges(void) {
  const fg_mlp_config cfg = {32, 64, 2, 3};
  const size_t np = fg_mlp_n_params(&cfg);
  float *W = falloc(np);
  fg_mlp_init(&cfg, W, 1);
  ASSERT_EQ(fg_mlp_acts_floats(&cfg, 0), 0);
  ASSERT_EQ(fg_mlp_scratch_floats(&cfg, 0), 0);

  /* B = 0: nothing read, nothing written, dW unchanged (NULL buffers are never touched). */
  float *dW = falloc(np);
  for (size_t i = 0; i < np; i++) dW[i] = (float)i;
  fg_mlp_forward(&cfg, W, NULL, 0, NULL, NULL, 2);
  fg_mlp_backward(&cfg, W, NULL, NULL, NULL, 0, dW, NULL, NULL, 2);
  for (size_t i = 0; i < np; i++) ASSERT_EQ(dW[i], (float)i);

  /* din = NULL gives the same dW; two backward calls accumulate twice. */
  const int B = 777;
  float *in = frandom((size_t)B * 32, 1.0f), *dout = frandom((size_t)B * 3, 1.0f);
  float *acts = falloc(fg_mlp_acts_floats(&cfg, B)), *out = falloc((size_t)B * 3);
  float *scratch = falloc(fg_mlp_scratch_floats(&cfg, B)), *din = falloc((size_t)B * 32);
  float *dW2 = falloc(np);
  memset(dW, 0, np * sizeof(float));
  memset(dW2, 0, np * sizeof(float));
  fg_mlp_forward(&cfg, W, in, B, acts, out, 0);
  fg_mlp_backward(&cfg, W, in, acts, dout, B, dW, din, scratch, 0);
  fg_mlp_backward(&cfg, W, in, acts, dout, B, dW2, NULL, scratch, 0);
  assert_same_bits("dW without din", dW2, dW, np);
  fg_mlp_backward(&cfg, W, in, acts, dout, B, dW2, NULL, scratch, 0);
  const float dw_scale = max_abs(dW, np);
  for (size_t i = 0; i < np; i++) ASSERT_NEAR(dW2[i], 2.0f * dW[i], 1e-6 * dw_scale);

  /* Dead ReLUs: a negative input to an all-positive first layer gives zero acts and zero
   * gradients below them. */
  for (size_t i = 0; i < np; i++) W[i] = fabsf(W[i]);
  for (int i = 0; i < B * 32; i++) in[i] = -fabsf(in[i]) - 0.01f;
  fg_mlp_forward(&cfg, W, in, B, acts, out, 2);
  ASSERT_EQ(max_abs(acts, fg_mlp_acts_floats(&cfg, B)), 0);
  ASSERT_EQ(max_abs(out, (size_t)B * 3), 0);
  memset(dW, 0, np * sizeof(float));
  fg_mlp_backward(&cfg, W, in, acts, dout, B, dW, din, scratch, 2);
  ASSERT_EQ(max_abs(dW, np), 0);
  ASSERT_EQ(max_abs(din, (size_t)B * 32), 0);

  free(W), free(dW), free(dW2), free(in), free(dout), free(acts), free(out), free(scratch);
  free(din);
}

/* ---- Adam --------------------------------------------------------------------------------- */

/* f(x, y) = 0.5 * (3 x^2 + 0.5 y^2), gradient (3x, 0.5y), from (1, -2); the sequence is computed
 * here in double from the formulas of adam.h. */
static void test_adam_quadratic(void) {
  fg_adam_config cfg;
  fg_adam_config_default(&cfg);
  cfg.lr = 0.1f;
  cfg.l2 = 0.01f;
  cfg.eps = 1e-8f;
  ASSERT_OK(fg_adam_config_check(&cfg));
  float p[2] = {1.0f, -2.0f}, m[2] = {0, 0}, v[2] = {0, 0}, g[2];
  double pd[2] = {1.0, -2.0}, md[2] = {0, 0}, vd[2] = {0, 0};
  const double curv[2] = {3.0, 0.5};
  for (int t = 1; t <= 8; t++) {
    for (int i = 0; i < 2; i++) g[i] = (float)(curv[i] * p[i]);
    fg_adam_step(&cfg, p, g, m, v, 2, t, 1);
    const double lr_t = 0.1 * sqrt(1 - pow(0.99, t)) / (1 - pow(0.9, t));
    for (int i = 0; i < 2; i++) {
      const double gi = curv[i] * pd[i] + 0.01 * pd[i];
      md[i] = 0.9 * md[i] + 0.1 * gi;
      vd[i] = 0.99 * vd[i] + 0.01 * gi * gi;
      pd[i] -= lr_t * md[i] / (sqrt(vd[i]) + 1e-8);
      ASSERT_NEAR(p[i], pd[i], 1e-5);
      ASSERT_NEAR(m[i], md[i], 1e-5 * (1 + fabs(md[i])));
      ASSERT_NEAR(v[i], vd[i], 1e-5 * (1 + fabs(vd[i])));
    }
  }
  /* The first step moves every parameter by lr against the sign of its gradient. */
  float q[3] = {0.5f, 0.5f, 0.5f}, qg[3] = {1e-3f, -40.0f, 0.0f}, qm[3] = {0}, qv[3] = {0};
  cfg.l2 = 0.0f;
  cfg.eps = 1e-15f;
  fg_adam_step(&cfg, q, qg, qm, qv, 3, 1, 1);
  ASSERT_NEAR(q[0], 0.4f, 1e-6);
  ASSERT_NEAR(q[1], 0.6f, 1e-6);
  ASSERT_NEAR(q[2], 0.5f, 0); /* g = 0, eps > 0: no move */

  /* skip_zero_grad leaves zero-gradient entries and their moments alone. */
  cfg.skip_zero_grad = 1;
  float s[2] = {1.0f, 1.0f}, sg[2] = {0.0f, 1.0f}, sm[2] = {0.5f, 0.5f}, sv[2] = {0.25f, 0.25f};
  fg_adam_step(&cfg, s, sg, sm, sv, 2, 5, 1);
  ASSERT_EQ(s[0], 1.0f);
  ASSERT_EQ(sm[0], 0.5f);
  ASSERT_EQ(sv[0], 0.25f);
  ASSERT(s[1] < 1.0f && sm[1] != 0.5f);

  fg_adam_config bad = cfg;
  bad.beta2 = 1.0f;
  ASSERT_ERR(fg_adam_config_check(&bad), FG_EINVAL, "beta2");
  bad = cfg, bad.lr = NAN;
  ASSERT_ERR(fg_adam_config_check(&bad), FG_EINVAL, "lr");
}

/* Each loop this CPU runs (and fg_adam_step's pick) equals the reference bit for bit, for any
 * thread count. */
static void test_adam_fast_vs_ref(void) {
  const size_t n = 300007;
  for (int skip = 0; skip <= 1; skip++) {
    fg_adam_config cfg;
    fg_adam_config_default(&cfg);
    cfg.skip_zero_grad = skip;
    float *p0 = frandom(n, 1.0f), *g = frandom(n, 1.0f);
    for (size_t i = 0; i < n; i += 3) g[i] = 0.0f;
    float *pr = falloc(n), *mr = falloc(n), *vr = falloc(n);
    float *pf = falloc(n), *mf = falloc(n), *vf = falloc(n);
    for (int k = FG_ADAM_AUTO; k <= FG_ADAM_AVX512; k++) {
      if (k != FG_ADAM_AUTO && !fg_adam_kernel_supported(k)) {
        printf("adam: this CPU has no %s loop\n", k == FG_ADAM_AVX2 ? "AVX2" : "AVX-512");
        continue;
      }
      for (int nt = 1; nt <= 3; nt++) {
        memcpy(pr, p0, n * sizeof(float)), memcpy(pf, p0, n * sizeof(float));
        for (size_t i = 0; i < n; i++)
          mr[i] = mf[i] = 0.1f * g[(i * 7) % n], vr[i] = vf[i] = 0.01f;
        for (int t = 1; t <= 3; t++) {
          fg_adam_step_ref(&cfg, pr, g, mr, vr, n, t);
          if (k == FG_ADAM_AUTO) fg_adam_step(&cfg, pf, g, mf, vf, n, t, nt);
          else fg_adam_step_kernel(k, &cfg, pf, g, mf, vf, n, t, nt);
        }
        assert_same_bits("adam params", pf, pr, n);
        assert_same_bits("adam m", mf, mr, n);
        assert_same_bits("adam v", vf, vr, n);
      }
    }
    free(p0), free(g), free(pr), free(mr), free(vr), free(pf), free(mf), free(vf);
  }
}

static void test_lr_schedule(void) {
  ASSERT_EQ(fg_lr_exponential(1e-2f, 1, 20000, 10000, 0.33f), 1e-2f);
  ASSERT_EQ(fg_lr_exponential(1e-2f, 20000, 20000, 10000, 0.33f), 1e-2f);
  ASSERT_NEAR(fg_lr_exponential(1e-2f, 20001, 20000, 10000, 0.33f), 0.33e-2, 1e-9);
  ASSERT_NEAR(fg_lr_exponential(1e-2f, 30000, 20000, 10000, 0.33f), 0.33e-2, 1e-9);
  ASSERT_NEAR(fg_lr_exponential(1e-2f, 30001, 20000, 10000, 0.33f), 0.33 * 0.33e-2, 1e-9);
  ASSERT_NEAR(fg_lr_exponential(1e-2f, 55001, 20000, 10000, 0.33f), 0.33 * 0.33 * 0.33 * 0.33e-2,
              1e-9);
  ASSERT_EQ(fg_lr_exponential(1e-2f, 99999, 20000, 0, 0.33f), 1e-2f);
}

/* Fits a colour-net-shaped MLP to a smooth target with Adam; the loss must fall 100x. */
static void test_adam_fit(void) {
  const fg_mlp_config cfg = {8, 32, 2, 3};
  const int B = 512;
  const size_t np = fg_mlp_n_params(&cfg);
  float *W = falloc(np), *dW = falloc(np), *m = falloc(np), *v = falloc(np);
  fg_mlp_init(&cfg, W, 11);
  memset(m, 0, np * sizeof(float)), memset(v, 0, np * sizeof(float));
  float *in = frandom((size_t)B * 8, 1.0f), *target = falloc((size_t)B * 3);
  for (int r = 0; r < B; r++) {
    const float *x = in + r * 8;
    target[r * 3 + 0] = 0.5f * sinf(2.0f * x[0]) + 0.3f * x[1] * x[2];
    target[r * 3 + 1] = 0.4f * cosf(x[3] + x[4]) - 0.2f;
    target[r * 3 + 2] = 0.3f * x[5] - 0.3f * x[6] * x[7] + 0.1f;
  }
  float *acts = falloc(fg_mlp_acts_floats(&cfg, B)), *out = falloc((size_t)B * 3);
  float *dout = falloc((size_t)B * 3), *scratch = falloc(fg_mlp_scratch_floats(&cfg, B));
  fg_adam_config acfg;
  fg_adam_config_default(&acfg);
  acfg.lr = 1e-2f;
  double first = 0.0, last = 0.0;
  for (int step = 1; step <= 600; step++) {
    fg_mlp_forward(&cfg, W, in, B, acts, out, 1);
    double loss = 0.0;
    for (int i = 0; i < B * 3; i++) {
      const float d = out[i] - target[i];
      loss += (double)d * d / B;
      dout[i] = 2.0f * d / (float)B;
    }
    if (step == 1) first = loss;
    last = loss;
    memset(dW, 0, np * sizeof(float));
    fg_mlp_backward(&cfg, W, in, acts, dout, B, dW, NULL, scratch, 1);
    fg_adam_step(&acfg, W, dW, m, v, np, step, 1);
  }
  printf("adam fit: loss %.3g -> %.3g (%.0fx)\n", first, last, first / last);
  ASSERT(last * 100.0 < first);
  free(W), free(dW), free(m), free(v), free(in), free(target), free(acts), free(out);
  free(dout), free(scratch);
}

int main(void) {
  printf("mlp kernel: %s\n", fg_mlp_kernel_name());
  test_config();
  test_fast_vs_ref();
  test_finite_differences();
  test_edges();
  test_adam_quadratic();
  test_adam_fast_vs_ref();
  test_lr_schedule();
  test_adam_fit();
  printf("ok\n");
  return 0;
}
