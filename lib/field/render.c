/* Volume rendering forward and backward, output activations and losses (see render.h).
 *
 * Gradient of the compositing, per ray
 * -------------------------------------
 * Write x_i = sigma_i dt_i and e_i = exp(-x_i), so alpha_i = 1 - e_i and
 *   T_0 = 1,  T_{i+1} = T_i e_i = exp(-sum_{j<=i} x_j),  w_i = T_i alpha_i = T_i - T_{i+1}.
 * Every output the backward pass sees enters the loss through one scalar per ray,
 *   y = g_rgb . rgb + g_depth depth + g_opacity opacity + g_feat . feat
 *     = sum_i w_i v_i + T_n b,
 * with the per-sample value  v_i = g_rgb . rgb_i + g_depth t_i + g_opacity + g_feat . feat_i
 * and the background value   b   = g_rgb . bg      (the only output with a T_n term is rgb;
 * n is the number of samples the ray used, held fixed).
 *
 * Colour and feature paths: y is linear in rgb_i and feat_i with coefficient w_i, so
 *   dL/drgb_i = w_i g_rgb,   dL/dfeat_i = w_i g_feat.
 *
 * Density path: x_i appears in every T_k with k > i, and dT_k/dsigma_i = -dt_i T_k there (0 for
 * k <= i). Hence, for the weights,
 *   k < i:  dw_k/dsigma_i = 0
 *   k = i:  dw_i/dsigma_i = d(T_i - T_{i+1})/dsigma_i = dt_i T_{i+1}
 *   k > i:  dw_k/dsigma_i = d(T_k - T_{k+1})/dsigma_i = -dt_i (T_k - T_{k+1}) = -dt_i w_k
 * and for the background term d(T_n b)/dsigma_i = -dt_i T_n b: every sample's density dims
 * the background. Together
 *   dL/dsigma_i = dt_i (T_{i+1} v_i - S_i),   S_i = sum_{k>i} w_k v_k + T_n b,
 * where S_i is what the ray collects behind sample i, background included. S satisfies
 *   S_{n-1} = T_n b,   S_{i-1} = S_i + w_i v_i,
 * so one sweep from the last used sample to the first gives every gradient in O(n), the
 * suffix-sum trick of Instant-NGP. Instant-NGP forms S_i as (output - prefix sum), which loses
 * the digits of S_i once the prefix nearly equals the output (deep in a ray, exactly where S_i
 * is small); summing the suffix from the back keeps them and needs no forward outputs. The
 * sweep needs T_{i+1}, w_i and v_i for i in reverse order: a first, forward sweep recomputes
 * T and w exactly as the forward pass did, forms v_i and the feature gradients, and parks
 * T_{i+1} in d_sigma[i] and w_i, v_i in d_rgb[3 i], d_rgb[3 i + 1], which the second sweep
 * then overwrites with the gradients. (The wide feature rows are thus read and written in
 * address order; walking them backwards cost several times more.) Samples behind the cut get
 * zero gradients: they did not contribute to any output. (When a ray ends because
 * T < t_min_transmittance, the loss is not differentiable at the cut itself; away from it the
 * cut is locally constant.)
 *
 * alpha for small x: 1 - expf(-x) in float loses the relative precision of alpha when x is
 * tiny (x = 1e-6 leaves one significant digit). alpha_of() uses a short Taylor series below
 * x = 1/32 instead; T still advances by e_i = expf(-x_i). Both passes and both references
 * use the same helper, so the forward, backward and reference transmittances agree to the
 * bit and the early-termination cut is the same everywhere. */
#include "field/render.h"

#include "core/threads.h"

#include <math.h>
#include <string.h>

#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- shared helpers ------------------------------------------------------------------- */

/* alpha = 1 - exp(-x) for x = sigma dt >= 0, given e = expf(-x). Below 1/32 the series
 * x - x^2/2 + x^3/6 - x^4/24 has a relative error under 1e-8. */
static inline float alpha_of(float x, float e) {
  if (x < 0.03125f) return x * (1.0f - x * (0.5f - x * (1.0f / 6.0f - x * (1.0f / 24.0f))));
  return 1.0f - e;
}

static inline const float *bg_of(const float *bg_rgb, int bg_per_ray, int32_t r) {
  return bg_per_ray ? bg_rgb + (size_t)3 * (size_t)r : bg_rgb;
}

/* Rays per scheduling chunk. Each ray is computed start to finish by one thread, so the
 * results do not depend on which thread takes which chunk: the dynamic schedule only
 * balances rays of unequal length and costs no determinism. */
enum { RAYS_PER_CHUNK = 64 };

/* Lane count of the fixed-order dot product below: 16 partial sums combined in a fixed tree,
 * the same order of operations for any vector width (FMA contraction aside). */
enum { DOT_LANES = 16 };

/* sum_d a[d] b[d] over D values, in DOT_LANES partial sums. GCC vector extensions: the
 * autovectoriser does not reorder a float reduction by itself, and a scalar loop costs ~4x. */
typedef float v4f __attribute__((vector_size(16)));

static inline v4f load4(const float *p) {
  v4f v;
  memcpy(&v, p, sizeof v);
  return v;
}

static float dot_fixed_order(const float *restrict a, const float *restrict b, int D) {
  v4f acc0 = {0}, acc1 = {0}, acc2 = {0}, acc3 = {0};
  int d = 0;
  for (; d + DOT_LANES <= D; d += DOT_LANES) {
    acc0 += load4(a + d) * load4(b + d);
    acc1 += load4(a + d + 4) * load4(b + d + 4);
    acc2 += load4(a + d + 8) * load4(b + d + 8);
    acc3 += load4(a + d + 12) * load4(b + d + 12);
  }
  v4f acc = (acc0 + acc1) + (acc2 + acc3);
  float sum = (acc[0] + acc[1]) + (acc[2] + acc[3]);
  for (; d < D; d++) sum += a[d] * b[d];
  return sum;
}

/* ---- forward -------------------------------------------------------------------------- */

static void forward_ray(int32_t r, const int32_t *ray_offset, const int32_t *ray_count,
                        const float *restrict sigma, const float *restrict rgb,
                        const float *restrict dt, const float *restrict t,
                        const float *restrict feat, int D, const float *bg, float t_min,
                        float *restrict out_rgb, float *restrict out_depth,
                        float *restrict out_opacity, float *restrict out_feat,
                        int32_t *restrict n_used) {
  const int32_t o = ray_offset[r], m = ray_count[r];
  float T = 1.0f, c0 = 0.0f, c1 = 0.0f, c2 = 0.0f, depth = 0.0f, opacity = 0.0f;
  float *restrict F = feat ? out_feat + (size_t)r * (size_t)D : NULL;
  if (F) memset(F, 0, (size_t)D * sizeof(float));
  int32_t i = 0;
  for (; i < m; i++) {
    if (T < t_min) break;
    const size_t s = (size_t)o + (size_t)i;
    const float x = sigma[s] * dt[s];
    const float e = expf(-x);
    const float w = T * alpha_of(x, e);
    c0 += w * rgb[3 * s + 0];
    c1 += w * rgb[3 * s + 1];
    c2 += w * rgb[3 * s + 2];
    depth += w * t[s];
    opacity += w;
    if (F) {
      const float *restrict f = feat + s * (size_t)D;
      for (int d = 0; d < D; d++) F[d] += w * f[d];
    }
    T *= e;
  }
  out_rgb[3 * (size_t)r + 0] = c0 + T * bg[0];
  out_rgb[3 * (size_t)r + 1] = c1 + T * bg[1];
  out_rgb[3 * (size_t)r + 2] = c2 + T * bg[2];
  if (out_depth) out_depth[r] = depth;
  if (out_opacity) out_opacity[r] = opacity;
  if (n_used) n_used[r] = i;
}

void fg_render_forward(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                       const float *sigma, const float *rgb, const float *dt, const float *t,
                       const float *feat, int D, const float *bg_rgb, int bg_per_ray,
                       float t_min_transmittance, float *out_rgb, float *out_depth,
                       float *out_opacity, float *out_feat, int32_t *n_used, int n_threads) {
  if (!feat || !out_feat || D <= 0) feat = NULL, out_feat = NULL, D = 0;
  const int nt = fg_threads(n_threads);
#pragma omp parallel for schedule(dynamic, RAYS_PER_CHUNK) num_threads(nt) \
    if (nt > 1 && n_rays > RAYS_PER_CHUNK)
  for (int32_t r = 0; r < n_rays; r++)
    forward_ray(r, ray_offset, ray_count, sigma, rgb, dt, t, feat, D,
                bg_of(bg_rgb, bg_per_ray, r), t_min_transmittance, out_rgb, out_depth,
                out_opacity, out_feat, n_used);
}

/* ---- backward ------------------------------------------------------------------------- */

static void backward_ray(int32_t r, const int32_t *ray_offset, const int32_t *ray_count,
                         const int32_t *n_used, const float *restrict sigma,
                         const float *restrict rgb, const float *restrict dt,
                         const float *restrict t, const float *restrict feat, int D,
                         const float *bg, const float *restrict d_out_rgb,
                         const float *restrict d_out_depth, const float *restrict d_out_opacity,
                         const float *restrict d_out_feat, float *restrict d_sigma,
                         float *restrict d_rgb, float *restrict d_feat) {
  const size_t o = (size_t)ray_offset[r];
  const int32_t m = ray_count[r], n = n_used[r] < m ? n_used[r] : m;
  const float g0 = d_out_rgb[3 * (size_t)r + 0], g1 = d_out_rgb[3 * (size_t)r + 1],
              g2 = d_out_rgb[3 * (size_t)r + 2];
  const float g_depth = d_out_depth ? d_out_depth[r] : 0.0f;
  const float g_opacity = d_out_opacity ? d_out_opacity[r] : 0.0f;
  const float *restrict g_feat = (feat && d_out_feat) ? d_out_feat + (size_t)r * (size_t)D : NULL;

  /* sweep 1, near to far: the weights, the per-sample values v_i (the feature dot products
   * included, so the wide rows stream in address order) and the feature gradients; park
   * T_{i+1} in d_sigma[i], w_i and v_i in d_rgb[3 i] and d_rgb[3 i + 1] */
  float T = 1.0f;
  for (int32_t i = 0; i < n; i++) {
    const size_t s = o + (size_t)i;
    const float x = sigma[s] * dt[s];
    const float e = expf(-x);
    const float w = T * alpha_of(x, e);
    float v = g0 * rgb[3 * s + 0] + g1 * rgb[3 * s + 1] + g2 * rgb[3 * s + 2] +
              g_depth * t[s] + g_opacity;
    if (g_feat) v += dot_fixed_order(g_feat, feat + s * (size_t)D, D);
    if (d_feat) {
      float *restrict df = d_feat + s * (size_t)D;
      if (g_feat)
        for (int d = 0; d < D; d++) df[d] = w * g_feat[d];
      else
        memset(df, 0, (size_t)D * sizeof(float));
    }
    T *= e;
    d_sigma[s] = T;
    d_rgb[3 * s + 0] = w;
    d_rgb[3 * s + 1] = v;
  }

  /* sweep 2, far to near: S is what the ray collects behind sample i, background included */
  float S = T * (g0 * bg[0] + g1 * bg[1] + g2 * bg[2]);
  for (int32_t i = n - 1; i >= 0; i--) {
    const size_t s = o + (size_t)i;
    const float w = d_rgb[3 * s + 0], v = d_rgb[3 * s + 1], T_next = d_sigma[s];
    d_sigma[s] = dt[s] * (T_next * v - S);
    S += w * v;
    d_rgb[3 * s + 0] = w * g0;
    d_rgb[3 * s + 1] = w * g1;
    d_rgb[3 * s + 2] = w * g2;
  }

  /* samples behind the cut contributed nothing */
  if (m > n) {
    const size_t s = o + (size_t)n, k = (size_t)(m - n);
    memset(d_sigma + s, 0, k * sizeof(float));
    memset(d_rgb + 3 * s, 0, 3 * k * sizeof(float));
    if (d_feat) memset(d_feat + s * (size_t)D, 0, k * (size_t)D * sizeof(float));
  }
}

void fg_render_backward(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                        const int32_t *n_used, const float *sigma, const float *rgb,
                        const float *dt, const float *t, const float *feat, int D,
                        const float *bg_rgb, int bg_per_ray, const float *d_out_rgb,
                        const float *d_out_depth, const float *d_out_opacity,
                        const float *d_out_feat, float *d_sigma, float *d_rgb, float *d_feat,
                        int n_threads) {
  if (!feat || D <= 0) feat = NULL, d_out_feat = NULL, d_feat = NULL, D = 0;
  const int nt = fg_threads(n_threads);
#pragma omp parallel for schedule(dynamic, RAYS_PER_CHUNK) num_threads(nt) \
    if (nt > 1 && n_rays > RAYS_PER_CHUNK)
  for (int32_t r = 0; r < n_rays; r++)
    backward_ray(r, ray_offset, ray_count, n_used, sigma, rgb, dt, t, feat, D,
                 bg_of(bg_rgb, bg_per_ray, r), d_out_rgb, d_out_depth, d_out_opacity,
                 d_out_feat, d_sigma, d_rgb, d_feat);
}

/* ---- references ----------------------------------------------------------------------- */

void fg_render_forward_ref(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                           const float *sigma, const float *rgb, const float *dt,
                           const float *t, const float *feat, int D, const float *bg_rgb,
                           int bg_per_ray, float t_min_transmittance, float *out_rgb,
                           float *out_depth, float *out_opacity, float *out_feat,
                           int32_t *n_used) {
  if (!feat || !out_feat || D <= 0) feat = NULL, out_feat = NULL, D = 0;
  for (int32_t r = 0; r < n_rays; r++) {
    const int32_t o = ray_offset[r], m = ray_count[r];
    const float *bg = bg_of(bg_rgb, bg_per_ray, r);
    float T = 1.0f, c[3] = {0, 0, 0}, depth = 0.0f, opacity = 0.0f;
    for (int d = 0; d < D; d++) out_feat[(size_t)r * D + d] = 0.0f;
    int32_t i = 0;
    for (; i < m; i++) {
      if (T < t_min_transmittance) break;
      const size_t s = (size_t)(o + i);
      const float x = sigma[s] * dt[s], e = expf(-x);
      const float alpha = alpha_of(x, e);
      const float w = T * alpha;
      for (int k = 0; k < 3; k++) c[k] += w * rgb[3 * s + k];
      for (int d = 0; d < D; d++) out_feat[(size_t)r * D + d] += w * feat[s * D + d];
      depth += w * t[s];
      opacity += w;
      T *= e; /* = 1 - alpha */
    }
    for (int k = 0; k < 3; k++) out_rgb[3 * (size_t)r + k] = c[k] + T * bg[k];
    if (out_depth) out_depth[r] = depth;
    if (out_opacity) out_opacity[r] = opacity;
    if (n_used) n_used[r] = i;
  }
}

/* v_i of the derivation at the top of the file. */
static float sample_value_ref(size_t s, const float *rgb, const float *t, const float *feat,
                              int D, const float *g_rgb, float g_depth, float g_opacity,
                              const float *g_feat) {
  float v = g_rgb[0] * rgb[3 * s] + g_rgb[1] * rgb[3 * s + 1] + g_rgb[2] * rgb[3 * s + 2] +
            g_depth * t[s] + g_opacity;
  if (g_feat)
    for (int d = 0; d < D; d++) v += g_feat[d] * feat[s * D + d];
  return v;
}

void fg_render_backward_ref(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                            const int32_t *n_used, const float *sigma, const float *rgb,
                            const float *dt, const float *t, const float *feat, int D,
                            const float *bg_rgb, int bg_per_ray, const float *d_out_rgb,
                            const float *d_out_depth, const float *d_out_opacity,
                            const float *d_out_feat, float *d_sigma, float *d_rgb,
                            float *d_feat) {
  if (!feat || D <= 0) feat = NULL, d_out_feat = NULL, d_feat = NULL, D = 0;
  for (int32_t r = 0; r < n_rays; r++) {
    const int32_t o = ray_offset[r], m = ray_count[r], n = n_used[r] < m ? n_used[r] : m;
    const float *bg = bg_of(bg_rgb, bg_per_ray, r);
    const float *g_rgb = d_out_rgb + 3 * (size_t)r;
    const float g_depth = d_out_depth ? d_out_depth[r] : 0.0f;
    const float g_opacity = d_out_opacity ? d_out_opacity[r] : 0.0f;
    const float *g_feat = (feat && d_out_feat) ? d_out_feat + (size_t)r * D : NULL;
    const float b = g_rgb[0] * bg[0] + g_rgb[1] * bg[1] + g_rgb[2] * bg[2];
    float T_i = 1.0f;
    for (int32_t i = 0; i < m; i++) {
      const size_t s = (size_t)(o + i);
      if (i >= n) { /* behind the cut */
        d_sigma[s] = 0.0f;
        for (int k = 0; k < 3; k++) d_rgb[3 * s + k] = 0.0f;
        for (int d = 0; d < D && d_feat; d++) d_feat[s * D + d] = 0.0f;
        continue;
      }
      const float x = sigma[s] * dt[s], e = expf(-x);
      const float w_i = T_i * alpha_of(x, e), T_next = T_i * e;
      /* S_i = sum_{k>i} w_k v_k + T_n b, summed directly */
      float S = 0.0f, T_k = T_next;
      for (int32_t k = i + 1; k < n; k++) {
        const size_t q = (size_t)(o + k);
        const float xk = sigma[q] * dt[q], ek = expf(-xk);
        S += T_k * alpha_of(xk, ek) *
             sample_value_ref(q, rgb, t, feat, D, g_rgb, g_depth, g_opacity, g_feat);
        T_k *= ek;
      }
      S += T_k * b;
      const float v_i = sample_value_ref(s, rgb, t, feat, D, g_rgb, g_depth, g_opacity, g_feat);
      d_sigma[s] = dt[s] * (T_next * v_i - S);
      for (int k = 0; k < 3; k++) d_rgb[3 * s + k] = w_i * g_rgb[k];
      for (int d = 0; d < D && d_feat; d++) d_feat[s * D + d] = g_feat ? w_i * g_feat[d] : 0.0f;
      T_i = T_next;
    }
  }
}

/* ---- activations ---------------------------------------------------------------------- */

/* Comparisons rather than fminf/fmaxf: a NaN stays NaN, so a diverging training shows. */
static inline float clamp15(float x) { return x < -15.0f ? -15.0f : x > 15.0f ? 15.0f : x; }

void fg_act_trunc_exp_forward(float *out, const float *x, size_t n) {
  for (size_t i = 0; i < n; i++) out[i] = expf(clamp15(x[i]));
}

void fg_act_trunc_exp_backward(float *dx, const float *out, const float *dout, size_t n) {
  for (size_t i = 0; i < n; i++) dx[i] = dout[i] * out[i];
}

void fg_act_sigmoid_forward(float *out, const float *x, size_t n) {
  for (size_t i = 0; i < n; i++) out[i] = 1.0f / (1.0f + expf(-x[i]));
}

void fg_act_sigmoid_backward(float *dx, const float *out, const float *dout, size_t n) {
  for (size_t i = 0; i < n; i++) dx[i] = dout[i] * out[i] * (1.0f - out[i]);
}

/* ---- losses --------------------------------------------------------------------------- */

/* One ray of fg_loss_ray_weights: weights first (as forward_ray computes them), then the
 * losses and g in a second pass over the same samples. */
static void ray_weights_loss(int32_t r, const int32_t *ray_offset, const int32_t *n_used,
                             const float *restrict sigma, const float *restrict dt,
                             const float *restrict t, float z, float margin, float w_depth,
                             float w_dist, float *restrict g, double *ld, double *lw) {
  const int32_t o = ray_offset[r], m = n_used[r];
  float *restrict w = g + o; /* the weights are parked in g, then overwritten in place */
  float T = 1.0f;
  double W = 0.0, WT = 0.0, E = 0.0, front = 0.0, window = 0.0, self = 0.0;
  for (int32_t i = 0; i < m; i++) {
    const float x = sigma[o + i] * dt[o + i], e = expf(-x);
    w[i] = T * alpha_of(x, e);
    T *= e;
    W += w[i];
    WT += (double)w[i] * t[o + i];
    const double rel = (double)t[o + i] - z;
    front += rel < -margin ? w[i] : 0.0;
    if (fabs(rel) <= margin) {
      window += w[i];
      E += w[i] * rel;
    }
    self += (double)w[i] * w[i] * dt[o + i];
  }
  *ld = z > 0.0f ? 1.0 + front - window + (E / margin) * (E / margin) : 0.0;
  /* sum_j w_j |t_i - t_j| from prefix sums (t rises along the ray) */
  double A = 0.0, B = 0.0, pair = 0.0;
  for (int32_t i = 0; i < m; i++) {
    const double ti = t[o + i], wi = w[i];
    const double spread = ti * A - B + (WT - B - wi * ti) - ti * (W - A - wi);
    pair += wi * spread;
    A += wi;
    B += wi * ti;
    double gi = w_dist * (2.0 * spread + (2.0 / 3.0) * wi * dt[o + i]);
    if (z > 0.0f) {
      const double rel = ti - z;
      if (rel < -margin)
        gi += w_depth;
      else if (fabs(rel) <= margin)
        gi += w_depth * (2.0 * E * rel / ((double)margin * margin) - 1.0);
    }
    w[i] = (float)gi;
  }
  *lw = pair + self / 3.0;
}

void fg_loss_ray_weights(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                         const int32_t *n_used, const float *sigma, const float *dt,
                         const float *t, const float *depth_z, float margin, float w_depth,
                         float w_dist, float *g, double *loss_depth, int32_t *n_depth,
                         double *loss_dist, int n_threads) {
  double ld = 0.0, lw = 0.0;
  int32_t nd = 0;
#pragma omp parallel for schedule(static) num_threads(fg_threads(n_threads)) reduction(+ : ld, lw, nd)
  for (int32_t r = 0; r < n_rays; r++) {
    const float z = depth_z && depth_z[r] > 0.0f ? depth_z[r] : 0.0f;
    double a, b;
    ray_weights_loss(r, ray_offset, n_used, sigma, dt, t, z, margin, w_depth, w_dist, g, &a, &b);
    for (int32_t i = ray_offset[r] + n_used[r]; i < ray_offset[r] + ray_count[r]; i++) g[i] = 0.0f;
    ld += a;
    lw += b;
    nd += z > 0.0f;
  }
  *loss_depth = ld;
  *n_depth = nd;
  *loss_dist = lw;
}

float fg_loss_l2(const float *pred, const float *target, size_t n, float *d_pred, float scale) {
  if (n == 0) return 0.0f;
  const float k = 2.0f * scale / (float)n;
  double sum = 0.0;
  for (size_t i = 0; i < n; i++) {
    const float e = pred[i] - target[i];
    sum += (double)e * (double)e;
    if (d_pred) d_pred[i] = k * e;
  }
  return (float)(sum / (double)n);
}

float fg_loss_huber(const float *pred, const float *target, size_t n, float delta,
                    float *d_pred, float scale) {
  if (n == 0) return 0.0f;
  const float k = scale / (float)n;
  double sum = 0.0;
  for (size_t i = 0; i < n; i++) {
    const float e = pred[i] - target[i], a = fabsf(e);
    float g;
    if (a <= delta) {
      sum += 0.5 * (double)e * (double)e;
      g = e;
    } else {
      sum += (double)delta * ((double)a - 0.5 * (double)delta);
      g = e > 0.0f ? delta : -delta;
    }
    if (d_pred) d_pred[i] = k * g;
  }
  return (float)(sum / (double)n);
}
