/* 6-DOF grasps (and placements) from demonstrations, F3RM's method on the voxel features of a
 * trained field (query/voxfeat.h).
 *
 * Query points. A task samples the field at N_q points p_i in the gripper frame (gripper.h),
 * in one of two layouts, each a fixed sequence so that the same parameters give the same
 * points on every machine, and the first n points of a longer draw are those of n:
 *   box       spread evenly over a box (a Halton sequence in bases 2, 3, 5), by default the
 *             region the fingers close on: between the pads' faces across y, the pads' width
 *             along x and their height along z (fg_grasp_query_box_default). A box's faces
 *             and a handle's opening lie 2 to 7 cm from the TCP, where few points of a
 *             Gaussian of a centimetre reach: a box's yaw and a handle's hole are seen only
 *             by points that reach what the fingers will touch.
 *   gaussian  F3RM's: mean mu, isotropic std sigma, drawn from a fixed seed.
 * At a gripper pose T = T_world_gripper the points sit at x_i = T p_i in the world.
 *
 * Field samples. F3RM describes a pose by z_T = [alpha(x_i) f(x_i)]_i, the alpha-weighted
 * features at the query points (N_q x D). Here alpha f is interpolated trilinearly between the
 * voxel centres of the cache (zero in voxels that keep no features and outside the grid), so
 * z_T is a continuous, piecewise-smooth function of T with an analytic gradient. The feature
 * head is linear (f = W h, W of D x 64), so alpha f = W (alpha h) and
 *   z_T . Z = sum_i (R u_i) . (Q^T Z_i),   |z_T|^2 = sum_i |R u_i|^2
 * where W = Q R (Q: D x 64 orthonormal columns, R: 64 x 64 upper triangular) and u_i is the
 * interpolated alpha h at x_i. The grasp field keeps y_v = alpha_v R h_v (64 floats) for every
 * voxel with features, so a pose costs 8 x 64 multiply-adds per query point whatever D is.
 *
 * Cost (F3RM). A task embedding Z (N_q x D) is the mean of its demos' z. The cost of a pose is
 *   J(T) = -cos(z_T, Z)                    (0 when z_T = 0: every point in free space)
 * and with a language query q (unit, D) the cost is weighted by the query's similarity at the
 * query points, J_lang(T) = w(T) J(T) with w(T) = sum_i q . z_T,i / sum_i |z_T,i|: the
 * cosine of q with each point's feature, averaged with the points' alpha-weighted lengths
 * as weights (0 when every point is in free space). The mean_i q . z_T,i grows with
 * density as much as with likeness to q, and pulled poses into the middle of solid objects,
 * away from the demonstrated geometry; this w is scale-free and in [-1, 1].
 *
 * Search (fg_grasp_search). Candidates are the centres of every voxel with alpha >= the
 * candidate threshold (optionally only those a mask allows, e.g. a language heatmap, grown by
 * mask_dilation voxels), each with the same deterministic near-uniform cover of SO(3) (a
 * super-Fibonacci spiral, Alexa 2022), optionally turned as a whole by a rotation drawn from
 * the seed. Every candidate pose is scored on the first 32 query points; the best ones whose
 * palm is free (up to n_keep) are optimised with Adam over translation and a world-frame
 * rotation vector on all the query points, dropping the worst 2.5 % every iteration down to
 * n_final; the survivors, then the pruned poses (latest pruned first), are centred (below),
 * checked for collisions with the whole gripper and thinned by non-maximum suppression in
 * position and angle (a parallel gripper turned by 180 degrees about its approach axis is the
 * same grasp).
 *
 * Centring (opt.centre_m > 0). Along the pads' width (the gripper's x) the pads often meet the
 * same two faces over a stretch (a box's long side, a cylinder's height), where the cost is
 * nearly flat and the optimum lands anywhere on it, often near an end. The stretch is read
 * from the geometry, surer than the features: from the pose, in steps of 2 mm up to three
 * times centre_m each way along its x, as long as something solid (alpha >= 0.5) lies
 * between the pads (across the opening, at the TCP's height and 8 mm above and below). The
 * pose moves towards its middle (at most centre_m), where a lift holds the object with the
 * least torque, if its cost there stays
 * within FG_GRASP_CENTRE_TOL (relative) of its own and it is free and within the limits;
 * else half way; else it stays.
 * Every pose is optimised on its own, so the result is bit-identical for any thread count,
 * and the same inputs and seed give the same poses.
 *
 * Collisions. A pose collides when a sample point of one of the gripper's boxes (a lattice of
 * spacing at most voxel_size / sqrt(3) over each box, so every voxel whose inscribed ball lies
 * in a box holds a point) falls in a voxel whose alpha is at least the collision threshold. Space outside the workspace grid counts as free, except below its floor when the search is
 * told that the floor is solid (a table: the workspace's lowest voxel layer stands on it).
 *
 * Motion limits. With opt.limits (motion/limits.h) the search returns only poses the robot
 * may be sent to: rotations outside the approach cone are never scored, and every result's
 * pose, the start of its approach (opt.approach_m back along the tool's -z) and the end of
 * its lift (opt.retreat_m up) lie in the position box. */
#ifndef FG_GRASP_GRASP_H
#define FG_GRASP_GRASP_H

#include <stddef.h>
#include <stdint.h>

#include "grasp/gripper.h"
#include "motion/limits.h"
#include "query/voxfeat.h"

#define FG_GRASP_MAX_QUERY_POINTS 1000
#define FG_GRASP_DEFAULT_QUERY_POINTS 100
#define FG_GRASP_DEFAULT_STD_M 0.0075 /* the Gaussian layout's std when none is given */
#define FG_GRASP_QUERY_SEED 0x6772617370ULL /* "grasp": the Gaussian points' fixed stream */
#define FG_GRASP_MAX_TOP_K 100
#define FG_GRASP_MIN_ROTATIONS 8
#define FG_GRASP_MAX_ROTATIONS 4096

/* ---- query points --------------------------------------------------------------------- */

typedef enum {
  FG_GRASP_QP_GAUSSIAN = 0, /* N(mean, std^2 I): F3RM's, and every task's before the box */
  FG_GRASP_QP_BOX = 1,      /* evenly over mean +- size / 2: the default */
} fg_grasp_qp_layout;

/* n points of the Gaussian N(mean_m, std_m^2 I) in the gripper frame (metres) into p_gripper
 * (n, 3), the caller's buffer, from stream FG_GRASP_QUERY_SEED (Box-Muller over a
 * counter-based generator): the same arguments give the same floats everywhere. FG_EINVAL
 * with a detail for n outside 1..FG_GRASP_MAX_QUERY_POINTS, std_m not finite or <= 0 (or
 * above 1 m), a mean not finite or farther than 1 m. */
int fg_grasp_query_points(int n, const double mean_m[3], double std_m, float *p_gripper);

/* n points spread evenly over the box centred on mean_m with edge lengths size_m (x, y, z;
 * gripper frame, metres) into p_gripper (n, 3), the caller's buffer: point i is the (i+1)-th
 * of the Halton sequence in bases 2, 3 and 5 scaled to the box, in double, then rounded to
 * float, so the same arguments give the same floats everywhere. FG_EINVAL with a detail for
 * n outside 1..FG_GRASP_MAX_QUERY_POINTS, a size not finite or outside (0, 1] m, a mean not
 * finite or farther than 1 m along an axis. */
int fg_grasp_query_points_box(int n, const double mean_m[3], const double size_m[3],
                              float *p_gripper);

/* The points of either layout: fg_grasp_query_points_box(n, mean_m, size_m, ...) for
 * FG_GRASP_QP_BOX, else fg_grasp_query_points(n, mean_m, std_m, ...); the other parameter is
 * not read. */
int fg_grasp_query_points_layout(fg_grasp_qp_layout layout, int n, const double mean_m[3],
                                 double std_m, const double size_m[3], float *p_gripper);

/* The default box of the query points for gripper m open to width_m (metres, in (0, stroke]):
 * what its fingers close on, into mean_m and size_m (gripper frame, metres): across y the
 * opening between the pads' faces, along x the pads' width, along z the pads' height, where
 * the pads stand at that width (gripper.h: a Robotiq's pads stand further along +z the more
 * they are closed). FG_EINVAL for an unknown model or a width outside (0, stroke]. */
int fg_grasp_query_box_default(fg_gripper_model m, double width_m, double mean_m[3],
                               double size_m[3]);

/* ---- the grasp field ------------------------------------------------------------------ */

typedef struct fg_grasp_field fg_grasp_field; /* opaque, immutable once built */

/* Builds the per-voxel vectors y_v described above from a voxel cache. vf stays the caller's
 * and must outlive *out (its grid and alpha are read, not copied); the caller owns *out
 * (fg_grasp_field_free). FG_EINVAL (NULL), FG_ENOMEM. */
int fg_grasp_field_new(fg_grasp_field **out, const fg_voxel_features *vf, int n_threads);

/* Accepts NULL. */
void fg_grasp_field_free(fg_grasp_field *gf);

/* Heap bytes the grasp field holds (not counting the voxel cache). */
size_t fg_grasp_field_bytes(const fg_grasp_field *gf);

/* The F3RM sample z (n, D) = alpha f at the n query points p_gripper (n, 3) placed by
 * T_world_gripper (row-major 4x4, metres), trilinear as described above, into the caller's z.
 * This is what a demo stores. FG_EINVAL for NULL or n out of range. */
int fg_grasp_sample(const fg_grasp_field *gf, const double T_world_gripper[16],
                    const float *p_gripper, int n, float *z);

/* ---- targets and costs ------------------------------------------------------------------ */

/* What a search looks for: a task embedding and, optionally, a language query. The arrays
 * stay the caller's for the call. */
typedef struct fg_grasp_target {
  int n_points;           /* N_q */
  int dim;                /* D, must equal the field's */
  const float *p_gripper; /* (N_q, 3) query points, gripper frame, metres */
  const float *Z;         /* (N_q, D) task embedding */
  const float *q;         /* (D) unit language query, or NULL for J without weighting */
} fg_grasp_target;

/* The cost of pose T_world_gripper and its gradient: d_t (3) = dJ/dt (the translation, world
 * frame, per metre) and d_w (3) = dJ/dw for a rotation exp([w]) applied on the left (world
 * frame, per radian); both may be NULL. *cos_out (may be NULL) receives cos(z_T, Z) and
 * *weight_out (may be NULL) w(T) (1 without a query). Returns the cost J or J_lang; NaN for
 * invalid arguments (dims that differ from the field's). */
double fg_grasp_cost(const fg_grasp_field *gf, const fg_grasp_target *t,
                     const double T_world_gripper[16], double d_t[3], double d_w[3],
                     double *cos_out, double *weight_out);

/* Scalar reference of the same cost straight from the voxel cache in double: full D-dim
 * features W h per voxel (from the float16 h), trilinear interpolation of alpha f, the cosine
 * with Z. For tests; slow. No gradient. */
double fg_grasp_cost_ref(const fg_voxel_features *vf, const fg_grasp_target *t,
                         const double T_world_gripper[16]);

/* F3RM's task retrieval by language: the cosine between a task's mean query-point feature
 * (the mean of the rows of Z (n_points, D)) and a query q (D). NaN when either is zero or
 * holds a value that is not finite. */
double fg_grasp_task_similarity(const float *Z, int n_points, int dim, const float *q);

/* ---- rotations and collisions ----------------------------------------------------------- */

/* n rotations of the super-Fibonacci spiral (Alexa, "Super-Fibonacci Spirals: Fast,
 * Low-Discrepancy Sampling of SO(3)", CVPR 2022) as unit quaternions [w, x, y, z] (n, 4),
 * each with w >= 0, into the caller's buffer. n >= 1. */
void fg_so3_super_fibonacci(int n, double *q_wxyz);

/* 1 when the gripper's boxes (fg_gripper_boxes of model m at width_m) placed by
 * T_world_gripper meet a voxel of gf's grid with alpha >= alpha_min; 0 when free; a negative
 * FG_E* code for a bad model or width. */
int fg_grasp_collides(const fg_grasp_field *gf, fg_gripper_model m, double width_m,
                      const double T_world_gripper[16], float alpha_min);

/* ---- search ----------------------------------------------------------------------------- */

typedef struct fg_grasp_options {
  float candidate_alpha;      /* candidates: voxel centres with alpha >= this (0.1) */
  const uint8_t *candidate_mask; /* (nz, ny, nx): 0 rules a voxel out; NULL: none ruled out */
  int mask_dilation;          /* the mask grows by this many voxels first (0..16): the TCP
                               * sits between the fingers, often in air beside the object */
  int n_rotations;            /* per candidate, >= FG_GRASP_MIN_ROTATIONS */
  int n_keep;                 /* best collision-free candidate poses optimised */
  int n_final;                /* pruned down to this many while optimising */
  int iterations;             /* Adam steps */
  double lr_translation_m;    /* Adam step size of the translation, metres */
  double lr_rotation_rad;     /* Adam step size of the rotation, radians */
  int top_k;                  /* 1..FG_GRASP_MAX_TOP_K poses returned */
  double nms_distance_m;      /* two results differ by more than this in position ... */
  double nms_angle_rad;       /* ... or by more than this in rotation */
  fg_gripper_model gripper;
  double width_m;             /* opening used for the collision check */
  int check_collisions;       /* 1: reject colliding poses (before and after optimising) */
  float collision_alpha;      /* voxels with alpha >= this are obstacles */
  uint64_t seed;              /* 0: the spiral as it is; else turned by a rotation from seed */
  int n_threads;              /* <= 0: OpenMP's default */
  int floor_solid;            /* 1: below the grid's lowest face is solid (checked collisions) */
  const fg_motion_limits *limits; /* NULL: none; else results satisfy them (kept by the caller) */
  double centre_m;            /* centring along the pads' width: how far each way (0: none) */
  double approach_m;          /* the path checked against limits: approach back along -z ... */
  double retreat_m;           /* ... and the lift along world +z after the grasp */
} fg_grasp_options;

/* How far above a pose's own cost (relative to its magnitude) centring may go. */
#define FG_GRASP_CENTRE_TOL 0.05

/* The defaults: candidate_alpha 0.1, no mask, mask_dilation 2, 24 rotations, n_keep 1024, n_final 64,
 * 100 iterations, lr 2 mm and 0.03 rad, top_k 10, NMS 1 cm and 15 degrees, panda at its
 * stroke, collisions checked at alpha 0.1, seed 0, n_threads 0, the floor not solid, no
 * limits, centring up to 4 cm each way. */
void fg_grasp_options_default(fg_grasp_options *o);

typedef struct fg_grasp_result_pose {
  double T_world_gripper[16]; /* row-major, metres */
  double cost;                /* J or J_lang, lower is better */
  double score;               /* cos(z_T, Z) */
  double weight;              /* w(T); 1 without a language query */
  int collision_free;         /* 1 when checked and free; 0 when not checked */
} fg_grasp_result_pose;

typedef struct fg_grasp_stats {
  size_t candidates;          /* voxels used as candidates */
  int rotations;              /* rotations per candidate */
  size_t poses_scored;        /* candidates x rotations */
  size_t poses_optimised;     /* poses that entered Adam */
  int iterations;
  size_t evaluations;         /* cost evaluations in all (with or without gradient) */
  size_t collision_checks;
  size_t rejected_collisions; /* poses dropped because they collide */
  size_t rejected_limits;     /* poses dropped by the motion limits (rotations outside the
                               * cone count once per candidate) */
  double seconds;
} fg_grasp_stats;

typedef struct fg_grasp_result {
  fg_grasp_result_pose *poses; /* (n) best first; owned; NULL when n = 0 */
  int n;
  fg_grasp_stats stats;
  const char *reason;          /* static text when n = 0 ("no occupied voxel", "every pose
                                * collides", ...), else NULL */
} fg_grasp_result;

/* Runs the search described at the top. On success the caller owns what *out holds
 * (fg_grasp_result_release); on failure *out holds nothing to release. An empty result
 * (no candidate, or nothing collision-free) is a success with n = 0 and a reason. FG_EINVAL
 * with a detail for a target whose D differs from the field's, n_points out of range, bad
 * options; FG_ENOMEM. */
int fg_grasp_search(const fg_grasp_field *gf, const fg_grasp_target *t,
                    const fg_grasp_options *opt, fg_grasp_result *out);

/* Frees what *r owns and zeroes it; accepts a zeroed struct. */
void fg_grasp_result_release(fg_grasp_result *r);

#endif
