/* Training a feature field from a scene's frames (Instant-NGP's loop, F3RM's feature loss).
 *
 * One step:
 *   1. draws R rays: ray r takes frame, pixel and sub-pixel jitter from a hash of
 *      (seed, step, r) over the training frames (held-out frames are never drawn);
 *   2. marches them through the occupancy grid with a jittered start (occupancy.h);
 *   3. evaluates the density and colour networks on every sample, and the feature branch on
 *      the samples of the first R_f = ceil(feature_ray_fraction R) rays when the frames have
 *      features (each such ray's target is its frame's feature cell per SPEC.md "Files");
 *   4. composites (render.h) against the learned background, or the scene background when
 *      learn_background is 0, and takes
 *        L = L2(rgb) + feature_weight L2(feature)
 *            + depth_weight mean_{rays with depth} L_depth + distortion_weight mean L_dist
 *      (render.h, fg_loss_ray_weights: the depth term on rays whose pixel has a measured
 *      depth, its window depth_margin metres either side of the measured surface, turned
 *      into a distance along the jittered ray; the distortion term on every ray);
 *   5. back-propagates through everything (the feature loss does not reach the density: F3RM's
 *      features follow the geometry that colour found) and takes one Adam step per group
 *      (tables: lr 1e-2, no L2, entries without gradient skipped; MLPs: lr 1e-2, L2 1e-6);
 *   6. every 16 steps updates the occupancy grid (Instant-NGP's schedule);
 *   7. sets R for the next step so that the samples approach target_samples.
 * Every buffer is allocated by fg_trainer_new for the largest step; a step allocates nothing.
 * The same frames, options (seed included) and thread count give bit-identical parameters.
 *
 * Threads: every OpenMP region of a trainer runs n_threads threads from the calling thread's
 * own team, so a trainer driven from a dedicated thread may lower that team's priority. */
#ifndef FG_FIELD_TRAIN_H
#define FG_FIELD_TRAIN_H

#include <stddef.h>
#include <stdint.h>

#include "field/model.h"
#include "io/frame.h"

typedef struct fg_trainer fg_trainer;

typedef struct fg_train_opts {
  uint64_t seed;
  int n_threads;              /* >= 1 */
  int holdout_every;          /* 0: none; k: frames i with i % k == 0 are held out */
  int32_t target_samples;     /* samples per step (2^17) */
  float feature_ray_fraction; /* share of rays that carry a feature target (0.25) */
  float feature_weight;       /* lambda (1) */
  float lr;                   /* Adam learning rate (1e-2) */
  float background[3];        /* the scene's background, sRGB in [0,1] */
  float depth_weight;         /* weight of the depth loss on rays with depth (FG_TRAIN_DEPTH_WEIGHT) */
  float depth_margin;         /* half-width of the depth loss's surface window, metres
                                 (FG_TRAIN_DEPTH_MARGIN) */
  float distortion_weight;    /* weight of the distortion loss (0: off) */
} fg_train_opts;

/* The depth loss is on for every ray whose frame has a depth map (frames without one are
 * untouched). Measured on scenegen tabletops (36 RGB-D views at 240x180, 500 steps of 2^16
 * samples): weight 0.3 with a 3 cm window gives held-out object depth median 1.07 mm (p90
 * 3.4 mm), the mug's and bowl's cavities 99.7 % and 100 % free, their IoU 0.885 and 0.782,
 * every object's voxels >= 98 % solid, PSNR 33.1 dB (without depth: 13 mm, 0 % and 20 %,
 * IoU 0.52 and 0.40, 31.7 dB at 1000 steps). A 1 cm window lost the ball: a young field's
 * surface lies more than a window in front of the measurement, the front term then empties
 * the blob and nothing is left to pull (object depth p90 45 mm, PSNR 29.2 dB, the ball's
 * voxels all free); 5 cm kept it too. Depth surfaces are shells thinner than a voxel; voxel
 * opacities average each voxel's density (query/voxfeat.h), so they still count. */
#define FG_TRAIN_DEPTH_WEIGHT 0.3
#define FG_TRAIN_DEPTH_MARGIN 0.03 /* metres */
/* The distortion loss is opt-in: at 0.01 it measured better on a small tabletop without depth
 * (30 views at 160x120: held-out PSNR 26.9 -> 31.2 dB; lego equal at the same speed) but
 * about equal on the larger one above (1000 steps: 31.7 -> 31.9 dB, object depth median 13.1
 * -> 13.4 mm, the bowl's cavity 20 -> 24 % free, IoU 0.52 / 0.40 -> 0.51 / 0.43): not
 * enough to change every training. */
#define FG_TRAIN_DISTORTION_WEIGHT 0.0
#define FG_TRAIN_MAX_LOSS_WEIGHT 1000.0 /* the largest weight the daemon accepts */

void fg_train_opts_default(fg_train_opts *o);

typedef struct fg_train_stats {
  int64_t step;      /* steps done */
  int32_t rays;      /* rays of the last step */
  int32_t samples;   /* samples of the last step */
  float loss;        /* last step's total loss */
  float loss_rgb;    /* its colour part (mean squared error over the rays' channels) */
  float loss_feat;   /* its feature part before weighting (NaN when no features) */
  float loss_depth;  /* its depth part before weighting (NaN when no ray had depth) */
  float loss_dist;   /* its distortion part before weighting (NaN when off) */
  int32_t depth_rays; /* rays of the last step with a measured depth */
  float occupancy;   /* share of occupied grid cells */
} fg_train_stats;

/* Prepares training of field on frames[0..n) (all of one scene, same feature dimension as
 * field->cfg.feature_dim; frames whose feat_d is 0 then train colour only). The trainer
 * keeps pointers to field and frames, which must outlive it; it owns its buffers and the
 * optimiser state. FG_EINVAL (no training frame, mismatched features, bad options),
 * FG_ENOMEM. */
int fg_trainer_new(fg_trainer **out, fg_field *field, const fg_frame *frames, size_t n,
                   const fg_train_opts *opts);
void fg_trainer_free(fg_trainer *t);

/* One training step; updates field->params, field->occ and field->trained_steps. stats may
 * be NULL. 0, or FG_ERANGE when the loss stopped being finite (the field is then left as it
 * was before this step). */
int fg_trainer_step(fg_trainer *t, fg_train_stats *stats);

/* The loss of the rays the next step would draw, with the current parameters, and its
 * gradient with respect to every parameter into the trainer's gradient buffer
 * (fg_trainer_grad: n_params floats in the field's layout), without changing the field or
 * the step count: the first half of fg_trainer_step, for gradient checks. stats may be NULL.
 * 0, or FG_ERANGE when the loss is not finite (the gradient is then not computed). */
int fg_trainer_loss_grad(fg_trainer *t, fg_train_stats *stats);
const float *fg_trainer_grad(const fg_trainer *t);

/* Where the views changed: an update's rays drawn more where the scene changed (issue 39,
 * "only what changed"). before is the scene's field as it was (its own occupancy grid; the
 * trainer's field, fg_field_copy_for_update's copy of it, has a new one), with the trainer's
 * configuration. Every training frame is cut into square cells of FG_TRAIN_FOCUS_CELL pixels
 * (larger for frames of more than 4096 such cells, so that at most about 4096 are looked at
 * per frame); before is rendered at each cell's centre pixel, and a cell changed where
 *   - the mean absolute colour difference over the three channels exceeds FG_TRAIN_FOCUS_RGB, or
 *   - the frame measured a depth there (as the depth loss reads it) on a surface inside the
 *     field's cube, and before's render there is less than half opaque or its z-depth is more
 *     than FG_TRAIN_FOCUS_DEPTH metres from the measurement;
 * the changed cells and their 8 neighbours are kept. From then on a share `fraction` of every
 * step's rays (feature rays from the kept cells of frames with features) picks a kept cell
 * uniformly and a pixel in it uniformly; the others are drawn as without focus. fraction 0 or
 * no changed cell: the trainer draws as before the call. The draws stay a function of the
 * seed, step and ray. stats (may be NULL): the cells looked at and kept. 0, FG_EINVAL (fraction
 * outside [0, 1], before NULL or of another configuration), FG_ENOMEM. */
#define FG_TRAIN_FOCUS_FRACTION 0.5f /* the daemon's default for an update */
#define FG_TRAIN_FOCUS_CELL 4    /* pixels */
#define FG_TRAIN_FOCUS_RGB 0.1f  /* mean absolute difference, colour in [0, 1] */
#define FG_TRAIN_FOCUS_DEPTH 0.02f /* metres */

typedef struct fg_train_focus_stats {
  int64_t cells;   /* cells looked at, over the training frames */
  int64_t changed; /* of them, changed */
  int64_t kept;    /* changed or beside a changed one: where the focus draws */
} fg_train_focus_stats;

int fg_trainer_focus(fg_trainer *t, const fg_field *before, float fraction,
                     fg_train_focus_stats *stats);

/* Number of held-out frames. */
size_t fg_trainer_n_heldout(const fg_trainer *t);

/* PSNR (dB) of the field's renders of the held-out frames against their images, over every
 * pixel of every held-out frame (full = 1) or over a fixed sample of at most 16384 held-out
 * pixels (full = 0, cheap enough to report during training). NaN when no frame is held out.
 * 0, or FG_ENOMEM. */
int fg_trainer_eval(fg_trainer *t, int full, double *psnr);

#endif
