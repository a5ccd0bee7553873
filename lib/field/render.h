/* Volume rendering (compositing samples along rays), forward and backward, and the field's
 * output activations and training losses.
 *
 * Samples are grouped by ray in marching order (near to far): ray r owns the samples
 * [ray_offset[r], ray_offset[r] + ray_count[r]) of every per-sample array. Per sample:
 *   sigma (S)   density, already activated (>= 0), in 1/m
 *   rgb   (S,3) colour, already activated (in [0,1])
 *   dt    (S)   length of the segment the sample stands for, in m
 *   t     (S)   distance of the sample along the ray, in m (for depth only)
 *   feat  (S,D) optional feature
 *
 * Compositing (NeRF / F3RM, background as Instant-NGP does for RGBA data sets):
 *   alpha_i = 1 - exp(-sigma_i dt_i),  T_i = prod_{j<i} (1 - alpha_j),  w_i = T_i alpha_i
 *   rgb     = sum_i w_i rgb_i + T_n bg      (T_n: transmittance left after the last used sample)
 *   feat    = sum_i w_i feat_i              (no background term)
 *   depth   = sum_i w_i t_i                 (no background term)
 *   opacity = sum_i w_i                     (= 1 - T_n)
 * Early termination: a ray stops before a sample when T has fallen below
 * t_min_transmittance (1e-4 is usual; 0 uses every sample). The number of samples a ray used
 * is written to n_used and the backward pass treats that cut as fixed.
 *
 * Threads: rays are split across threads; each ray is computed by one thread in a fixed order,
 * so the results are bit-identical for any thread count and timing. n_threads <= 0 takes the
 * OpenMP default. No function here allocates or keeps a pointer: every array stays the
 * caller's. */
#ifndef FG_FIELD_RENDER_H
#define FG_FIELD_RENDER_H

#include <stddef.h>
#include <stdint.h>

/* ---- compositing ---------------------------------------------------------------------- */

/* Composites every ray. bg_rgb is (3), one colour for all rays, or (R,3) when bg_per_ray is
 * nonzero (Instant-NGP trains RGBA data sets against a random background per ray).
 * feat and out_feat are both given (D > 0) or both NULL (D ignored).
 * out_rgb is (R,3); out_depth (R), out_opacity (R), out_feat (R,D) and n_used (R) may each be
 * NULL when not wanted; n_used is needed by fg_render_backward. A ray with no samples renders
 * as the background with depth 0, opacity 0 and a zero feature. */
void fg_render_forward(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                       const float *sigma, const float *rgb, const float *dt, const float *t,
                       const float *feat, int D, const float *bg_rgb, int bg_per_ray,
                       float t_min_transmittance, float *out_rgb, float *out_depth,
                       float *out_opacity, float *out_feat, int32_t *n_used, int n_threads);

/* Gradients of a loss L with respect to sigma, rgb and feat, given dL/d(outputs):
 * d_out_rgb (R,3) is required; d_out_depth (R), d_out_opacity (R) and d_out_feat (R,D) may be
 * NULL (zero gradient). n_used (R) is the forward pass's output. Writes (overwrites)
 * d_sigma (S) and d_rgb (S,3), and d_feat (S,D) when feat and d_feat are both given (d_feat
 * may be NULL while d_out_feat still acts on d_sigma); samples
 * a ray did not use get zero gradients. O(samples x (3 + D)) work and no scratch: the
 * backward parks per-sample values in d_sigma and d_rgb before overwriting them, so those
 * must not alias any input.
 * The background is a constant here; its gradient, if it is learned, is T_n * d_out_rgb with
 * T_n = 1 - opacity. */
void fg_render_backward(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                        const int32_t *n_used, const float *sigma, const float *rgb,
                        const float *dt, const float *t, const float *feat, int D,
                        const float *bg_rgb, int bg_per_ray, const float *d_out_rgb,
                        const float *d_out_depth, const float *d_out_opacity,
                        const float *d_out_feat, float *d_sigma, float *d_rgb, float *d_feat,
                        int n_threads);

/* Readable single-threaded references of the two functions above (same arguments, no
 * n_threads). The backward reference evaluates each sum of the gradient directly, O(n^2) per
 * ray; it is for tests only. */
void fg_render_forward_ref(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                           const float *sigma, const float *rgb, const float *dt,
                           const float *t, const float *feat, int D, const float *bg_rgb,
                           int bg_per_ray, float t_min_transmittance, float *out_rgb,
                           float *out_depth, float *out_opacity, float *out_feat,
                           int32_t *n_used);
void fg_render_backward_ref(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                            const int32_t *n_used, const float *sigma, const float *rgb,
                            const float *dt, const float *t, const float *feat, int D,
                            const float *bg_rgb, int bg_per_ray, const float *d_out_rgb,
                            const float *d_out_depth, const float *d_out_opacity,
                            const float *d_out_feat, float *d_sigma, float *d_rgb,
                            float *d_feat);

/* ---- activations ---------------------------------------------------------------------- */
/* Elementwise over n values; out may alias x and dx may alias dout. Backward functions take
 * the forward output (which the caller keeps anyway) and overwrite dx. */

/* Density: out = exp(clamp(x, -15, 15)). The backward is Instant-NGP's truncated exponential:
 * dx = dout * exp(clamp(x, -15, 15)) = dout * out, so it stays nonzero below -15 (training can
 * recover from a dead density) and bounded above 15. */
void fg_act_trunc_exp_forward(float *out, const float *x, size_t n);
void fg_act_trunc_exp_backward(float *dx, const float *out, const float *dout, size_t n);

/* Colour: out = 1 / (1 + exp(-x)); dx = dout * out * (1 - out). */
void fg_act_sigmoid_forward(float *out, const float *x, size_t n);
void fg_act_sigmoid_backward(float *dx, const float *out, const float *dout, size_t n);

/* ---- losses --------------------------------------------------------------------------- */
/* Both return the loss (a mean over the n values, summed in double in index order) and, when
 * d_pred is not NULL, overwrite d_pred (n) with scale * dLoss/dpred. The training loss
 * L = L_rgb + lambda L_feat is
 *   fg_loss_l2(rgb, rgb_gt, 3R, d_rgb, 1) + lambda * fg_loss_l2(feat, feat_gt, D R', d_feat,
 *   lambda), the feature loss taken over the R' rays that carry a feature target. */

/* Losses on the compositing weights w_i = T_i alpha_i of each ray (geometry, not colour).
 * Per ray r, over the samples it used (n_used from fg_render_forward), t_i its samples'
 * distances and dt_i their lengths:
 *
 * Depth (rays with a measured distance z_r > 0 along the ray, in t's units; margin e > 0):
 *   L_depth,r = 1 + sum_{t_i < z_r - e} w_i - sum_{|t_i - z_r| <= e} w_i + (E_r / e)^2,
 *   E_r = sum_{|t_i - z_r| <= e} w_i (t_i - z_r).
 * The two sums are Urban Radiance Fields' line-of-sight idea in its simplest form: a
 * measured surface at z_r says space in front of it is empty (weight there costs 1) and the
 * ray ends within e of it (weight there earns 1). They carve what colour cannot: the lid a
 * photometric loss leaves over a uniformly coloured cavity is weight in front of the
 * measured floor. Inside the window they are flat, so the last term, the first moment of the
 * window's weight about the measurement, pulls the surface onto it to well below e. It is
 * taken over the window only, so L_depth,r stays in [0, 3] and its gradient per weight in
 * [-3, 3] however far the field is from the measurement: far weight is the sums' business.
 * Unlike DS-NeRF's KL term it needs no per-ray variance, and unlike a plain expected-depth
 * L2 it cannot be met by weight split in front of and behind the surface.
 *
 * Distortion (every ray; Mip-NeRF 360's L_dist on the samples' intervals):
 *   L_dist,r = sum_{i,j} w_i w_j |t_i - t_j| + 1/3 sum_i w_i^2 dt_i,
 * small when a ray's weight is one compact peak; it removes floaters and thin fog.
 *
 * fg_loss_ray_weights writes g (S): g_i = w_depth dL_depth,r/dw_i + w_dist dL_dist,r/dw_i
 * for the samples a ray used, 0 for the others, and returns the sums over rays of L_depth,r
 * (*loss_depth, over rays with z_r > 0, counted in *n_depth) and of L_dist,r (*loss_dist).
 * depth_z may be NULL (no depth term); w_dist 0 skips the distortion term. The gradient with
 * respect to sigma follows from fg_render_backward with feat = g, D = 1, d_out_feat = 1 per
 * ray and d_out_rgb = 0, since sum_i g_i w_i is then the composited "feature".
 * Rays are split across threads; each is computed by one thread, so g is identical for any
 * thread count (the three sums may differ in their last bits). */
void fg_loss_ray_weights(int32_t n_rays, const int32_t *ray_offset, const int32_t *ray_count,
                         const int32_t *n_used, const float *sigma, const float *dt,
                         const float *t, const float *depth_z, float margin, float w_depth,
                         float w_dist, float *g, double *loss_depth, int32_t *n_depth,
                         double *loss_dist, int n_threads);

/* Mean squared error: mean_i (pred_i - target_i)^2. */
float fg_loss_l2(const float *pred, const float *target, size_t n, float *d_pred, float scale);

/* Huber loss with threshold delta > 0: mean_i h(pred_i - target_i), h(e) = e^2 / 2 for
 * |e| <= delta, delta (|e| - delta / 2) beyond. */
float fg_loss_huber(const float *pred, const float *target, size_t n, float delta,
                    float *d_pred, float scale);

#endif
