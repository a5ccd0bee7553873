/* Grasp search (grasp.h): candidates on occupied voxels times a cover of SO(3), collision
 * checks against the voxel grid, Adam on every kept pose, non-maximum suppression. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <omp.h>

#include "core/clock.h"
#include "core/error.h"
#include "core/pose.h"
#include "core/rng.h"
#include "core/threads.h"
#include "grasp/grasp.h"
#include "grasp/internal.h"

#define PRUNE_FRACTION 0.025 /* F3RM drops the worst 2.5 % of the poses every step */
#define ADAM_BETA1 0.9
#define ADAM_BETA2 0.999
#define ADAM_EPS 1e-8
#define SCORE_CHUNK 256      /* poses collision-checked at a time while filling n_keep */
#define COARSE_POINTS 32     /* query points that score the candidate poses */
#define CENTRE_STEP_M 0.002  /* the steps of centring (grasp.h) */
#define CENTRE_ALPHA 0.5     /* ... the alpha that counts as the object's ... */
#define CENTRE_SCAN 3.0      /* ... and how far each way the stretch is looked for, in centre_m */

/* ---------------------------------------------------------------- rotations */

void fg_so3_super_fibonacci(int n, double *q_wxyz) {
  /* Alexa 2022, Algorithm 1: phi = sqrt(2), psi the root of psi^4 = psi + 4. */
  const double phi = sqrt(2.0), psi = 1.533751168755204288118041;
  for (int i = 0; i < n; i++) {
    const double s = i + 0.5, r = sqrt(s / n), R = sqrt(1.0 - s / n);
    const double alpha = 2.0 * M_PI * s / phi, beta = 2.0 * M_PI * s / psi;
    double q[4] = {r * sin(alpha), r * cos(alpha), R * sin(beta), R * cos(beta)};
    /* (x, y, z, w) in the paper's order: store w first, with w >= 0 */
    double w = q[3], x = q[0], y = q[1], z = q[2];
    if (w < 0) w = -w, x = -x, y = -y, z = -z;
    q_wxyz[4 * i] = w;
    q_wxyz[4 * i + 1] = x;
    q_wxyz[4 * i + 2] = y;
    q_wxyz[4 * i + 3] = z;
  }
}

/* C = A B for 3x3 matrices. */
static void mul3(const double A[9], const double B[9], double C[9]) {
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++)
      C[3 * r + c] = A[3 * r] * B[c] + A[3 * r + 1] * B[3 + c] + A[3 * r + 2] * B[6 + c];
}

/* Angle between two parallel-gripper orientations: a turn of 180 degrees about the approach
 * axis (z) gives the same grasp, so the smaller of the two angles. */
static double grip_angle(const double A[9], const double B[9]) {
  const double Bf[9] = {-B[0], -B[1], B[2], -B[3], -B[4], B[5], -B[6], -B[7], B[8]};
  const double a = fg_rotmat_angle_rad(A, B), b = fg_rotmat_angle_rad(A, Bf);
  return a < b ? a : b;
}

/* ---------------------------------------------------------------- collisions */

/* Sample lattice of a box: per axis count and spacing so that the spacing is at most step
 * (voxel_size / sqrt(3): every voxel whose inscribed ball lies in the box holds a sample). */
static int box_collides(const fg_grasp_field *gf, const uint8_t *occ, const fg_gripper_box *b,
                        const double T[16], double step, int floor_solid) {
  const fg_voxel_grid *g = &gf->grid;
  int n[3];
  double d[3];
  for (int a = 0; a < 3; a++) {
    n[a] = (int)ceil(2.0 * b->half_m[a] / step) + 1;
    d[a] = n[a] > 1 ? 2.0 * b->half_m[a] / (n[a] - 1) : 0.0;
  }
  for (int k = 0; k < n[2]; k++)
    for (int j = 0; j < n[1]; j++)
      for (int i = 0; i < n[0]; i++) {
        const double p[3] = {b->centre_m[0] - b->half_m[0] + i * d[0],
                             b->centre_m[1] - b->half_m[1] + j * d[1],
                             b->centre_m[2] - b->half_m[2] + k * d[2]};
        int idx[3], inside = 1;
        const int na[3] = {g->nx, g->ny, g->nz};
        for (int a = 0; a < 3 && inside; a++) {
          const double x = T[4 * a] * p[0] + T[4 * a + 1] * p[1] + T[4 * a + 2] * p[2] +
                           T[4 * a + 3];
          const double u = floor((x - g->min[a]) / g->voxel_size);
          if (a == 2 && floor_solid && u < 0) return 1; /* under the table */
          if (!(u >= 0 && u < na[a])) inside = 0;
          else idx[a] = (int)u;
        }
        if (!inside) continue;
        if (occ[((size_t)idx[2] * g->ny + idx[1]) * g->nx + idx[0]]) return 1;
      }
  return 0;
}

/* Fingers first, from the pads back (FG_GRIPPER_BOX_* order, the palm last): they are small
 * and meet the object first, so colliding poses exit early. */
static int gripper_collides(const fg_grasp_field *gf, const uint8_t *occ,
                            const fg_gripper_box boxes[FG_GRIPPER_N_BOXES], const double T[16],
                            int floor_solid) {
  const double step = gf->grid.voxel_size / sqrt(3.0);
  for (int i = 1; i <= FG_GRIPPER_N_BOXES; i++)
    if (box_collides(gf, occ, &boxes[i % FG_GRIPPER_N_BOXES], T, step, floor_solid)) return 1;
  return 0;
}

/* The check before optimising: only the palm, on a lattice of one voxel. A candidate sits on
 * a voxel centre with a rotation up to half the cover's spacing off, so its fingers often
 * graze the object that the optimisation then moves them clear of; a palm in the scene means
 * the approach itself is blocked. */
static int palm_collides(const fg_grasp_field *gf, const uint8_t *occ,
                         const fg_gripper_box boxes[FG_GRIPPER_N_BOXES], const double T[16],
                         int floor_solid) {
  return box_collides(gf, occ, &boxes[FG_GRIPPER_BOX_PALM], T, gf->grid.voxel_size,
                      floor_solid);
}

/* Whether the robot may be sent to T: cone, box, approach and lift (motion/limits.h). */
static int within_limits(const fg_grasp_options *o, const double T[16]) {
  if (!o->limits) return 1;
  double p[3], q[4];
  fg_pose_to_quat(T, p, q);
  return fg_motion_check_pose(o->limits, p, q, o->approach_m, o->retreat_m, FG_RETREAT_UP,
                              NULL) == 0;
}

static uint8_t *occupancy(const fg_grasp_field *gf, float alpha_min) {
  uint8_t *occ = malloc(gf->n_vox ? gf->n_vox : 1);
  if (!occ) return NULL;
  for (size_t i = 0; i < gf->n_vox; i++) occ[i] = gf->alpha[i] >= alpha_min;
  return occ;
}

int fg_grasp_collides(const fg_grasp_field *gf, fg_gripper_model m, double width_m,
                      const double T_world_gripper[16], float alpha_min) {
  fg_gripper_box boxes[FG_GRIPPER_N_BOXES];
  FG_TRY(fg_gripper_boxes(m, width_m, boxes));
  uint8_t *occ = occupancy(gf, alpha_min);
  if (!occ) return fg_fail(FG_ENOMEM, "grasp: out of memory");
  const int hit = gripper_collides(gf, occ, boxes, T_world_gripper, 0);
  free(occ);
  return hit;
}

/* ---------------------------------------------------------------- options */

void fg_grasp_options_default(fg_grasp_options *o) {
  memset(o, 0, sizeof *o);
  o->candidate_alpha = 0.1f;
  o->mask_dilation = 2;
  o->n_rotations = 24;
  o->n_keep = 1024;
  o->n_final = 64;
  o->iterations = 100;
  o->lr_translation_m = 0.002;
  o->lr_rotation_rad = 0.03;
  o->top_k = 10;
  o->nms_distance_m = 0.01;
  o->nms_angle_rad = 15.0 * M_PI / 180.0;
  o->gripper = FG_GRIPPER_PANDA;
  o->width_m = fg_gripper_spec_get(FG_GRIPPER_PANDA)->stroke_m;
  o->check_collisions = 1;
  o->collision_alpha = 0.1f;
  o->centre_m = 0.04;
}

static int check_options(const fg_grasp_options *o) {
  if (!(o->candidate_alpha >= FG_QUERY_ALPHA_FLOOR && o->candidate_alpha <= 1.0f))
    return fg_fail(FG_EINVAL, "the candidates' alpha threshold must be in [%g, 1]",
                   (double)FG_QUERY_ALPHA_FLOOR);
  if (o->n_rotations < FG_GRASP_MIN_ROTATIONS || o->n_rotations > FG_GRASP_MAX_ROTATIONS)
    return fg_fail(FG_EINVAL, "rotations must be in %d..%d, got %d", FG_GRASP_MIN_ROTATIONS,
                   FG_GRASP_MAX_ROTATIONS,
                   o->n_rotations);
  if (o->mask_dilation < 0 || o->mask_dilation > 16)
    return fg_fail(FG_EINVAL, "mask_dilation must be in 0..16 voxels, got %d", o->mask_dilation);
  if (o->n_keep < 1 || o->n_final < 1 || o->n_final > o->n_keep || o->n_keep > 1 << 20)
    return fg_fail(FG_EINVAL, "need 1 <= n_final <= n_keep <= 2^20");
  if (o->iterations < 0 || o->iterations > 10000)
    return fg_fail(FG_EINVAL, "iterations must be in 0..10000, got %d", o->iterations);
  if (!(o->lr_translation_m >= 0 && o->lr_translation_m < 1) ||
      !(o->lr_rotation_rad >= 0 && o->lr_rotation_rad < 1))
    return fg_fail(FG_EINVAL, "learning rates must be in [0, 1)");
  if (o->top_k < 1 || o->top_k > FG_GRASP_MAX_TOP_K)
    return fg_fail(FG_EINVAL, "top_k must be in 1..%d, got %d", FG_GRASP_MAX_TOP_K, o->top_k);
  if (!(o->nms_distance_m >= 0) || !(o->nms_angle_rad >= 0) || !isfinite(o->nms_distance_m) ||
      !isfinite(o->nms_angle_rad))
    return fg_fail(FG_EINVAL, "NMS distance and angle must be finite and >= 0");
  if (!(o->centre_m >= 0 && o->centre_m <= 0.5))
    return fg_fail(FG_EINVAL, "centre_m must be in [0, 0.5] metres, got %g", o->centre_m);
  if (!(o->collision_alpha >= FG_QUERY_ALPHA_FLOOR && o->collision_alpha <= 1.0f))
    return fg_fail(FG_EINVAL, "the collision alpha must be in [%g, 1]",
                   (double)FG_QUERY_ALPHA_FLOOR);
  fg_gripper_box boxes[FG_GRIPPER_N_BOXES];
  return fg_gripper_boxes(o->gripper, o->width_m, boxes);
}

/* ---------------------------------------------------------------- search */

/* One pose under optimisation. */
typedef struct pose_state {
  double R[9], t[3];
  double m[6], v[6]; /* Adam moments: translation, then rotation */
  double cost, cosv, weight;
  uint32_t id;       /* candidate * rotations + rotation: the tie-breaker */
} pose_state;

static int cmp_pose(const void *a, const void *b) {
  const pose_state *x = a, *y = b;
  if (x->cost < y->cost) return -1;
  if (x->cost > y->cost) return 1;
  return (x->id > y->id) - (x->id < y->id);
}

typedef struct scored {
  double cost;
  uint32_t id;
} scored;

static int cmp_scored(const void *a, const void *b) {
  const scored *x = a, *y = b;
  if (x->cost < y->cost) return -1;
  if (x->cost > y->cost) return 1;
  return (x->id > y->id) - (x->id < y->id);
}

void fg_grasp_result_release(fg_grasp_result *r) {
  if (!r) return;
  free(r->poses);
  memset(r, 0, sizeof *r);
}

/* Everything one search allocates, freed in one place. */
typedef struct search_bufs {
  fg_grasp_prepared prep;    /* the target */
  fg_grasp_prepared coarse;  /* its first COARSE_POINTS query points */
  fg_grasp_scratch *scratch; /* (nt) */
  int nt;
  uint8_t *occ;
  uint32_t *cand;            /* (n_cand) flat voxel indices */
  double *rot;               /* (n_rot, 9) */
  scored *sc;                /* (n_cand * n_rot) */
  pose_state *ps;            /* (n_keep) */
  uint8_t *hit;              /* (SCORE_CHUNK) */
  uint8_t *dilated;          /* (nz, ny, nx) the candidate mask grown, or NULL */
} search_bufs;

static void bufs_release(search_bufs *b) {
  fg_grasp_prepared_release(&b->prep);
  fg_grasp_prepared_release(&b->coarse);
  if (b->scratch)
    for (int i = 0; i < b->nt; i++) fg_grasp_scratch_release(&b->scratch[i]);
  free(b->scratch);
  free(b->occ);
  free(b->cand);
  free(b->rot);
  free(b->sc);
  free(b->ps);
  free(b->hit);
  free(b->dilated);
}

/* mask (nz, ny, nx) grown by r voxels along every axis (a cube of side 2r + 1: a separable
 * maximum), into a new array the caller frees; NULL when out of memory. */
static uint8_t *dilate(const fg_voxel_grid *g, const uint8_t *mask, int r) {
  const size_t N = fg_voxel_grid_count(g);
  uint8_t *a = malloc(N), *t = malloc(N);
  if (!a || !t) {
    free(a);
    free(t);
    return NULL;
  }
  memcpy(a, mask, N);
  const int n[3] = {g->nx, g->ny, g->nz};
  const size_t stride[3] = {1, (size_t)g->nx, (size_t)g->nx * g->ny};
  for (int ax = 0; ax < 3; ax++) {
    for (size_t i = 0; i < N; i++) {
      const int c = (int)((i / stride[ax]) % (size_t)n[ax]);
      uint8_t v = 0;
      for (int d = -r; d <= r && !v; d++) {
        const int cc = c + d;
        if (cc >= 0 && cc < n[ax]) v = a[i + (ptrdiff_t)d * (ptrdiff_t)stride[ax]] != 0;
      }
      t[i] = v;
    }
    memcpy(a, t, N);
  }
  free(t);
  return a;
}

/* The pose of candidate id: voxel centre, rotation id % n_rot. */
static void candidate_pose(const fg_grasp_field *gf, const search_bufs *b, int n_rot, uint32_t id,
                           double R[9], double t[3]) {
  const uint32_t flat = b->cand[id / (uint32_t)n_rot];
  const fg_voxel_grid *g = &gf->grid;
  const int ix = (int)(flat % (uint32_t)g->nx), iy = (int)((flat / (uint32_t)g->nx) % (uint32_t)g->ny),
            iz = (int)(flat / ((uint32_t)g->nx * (uint32_t)g->ny));
  fg_voxel_grid_centre(g, ix, iy, iz, t);
  memcpy(R, b->rot + (size_t)(id % (uint32_t)n_rot) * 9, 9 * sizeof *R);
}

/* Adam on every pose of ps[0..n), pruning to n_final; returns the number left (sorted). */
static int optimise(const fg_grasp_field *gf, search_bufs *b, const fg_grasp_options *o,
                    pose_state *ps, int n, fg_grasp_stats *st) {
  for (int it = 0; it <= o->iterations; it++) {
    const int last = it == o->iterations;
#pragma omp parallel for num_threads(b->nt) schedule(dynamic, 8)
    for (int k = 0; k < n; k++) {
      pose_state *p = &ps[k];
      double T[16], gt[3], gw[3];
      fg_pose_from_rotmat(p->R, p->t, T);
      fg_grasp_scratch *s = &b->scratch[omp_get_thread_num()];
      p->cost = fg_grasp_cost_fast(gf, &b->prep, T, last ? NULL : gt, last ? NULL : gw,
                                   &p->cosv, &p->weight, s);
      if (last) continue;
      const double g[6] = {gt[0], gt[1], gt[2], gw[0], gw[1], gw[2]};
      const double c1 = 1.0 - pow(ADAM_BETA1, it + 1), c2 = 1.0 - pow(ADAM_BETA2, it + 1);
      double step[6];
      for (int j = 0; j < 6; j++) {
        p->m[j] = ADAM_BETA1 * p->m[j] + (1 - ADAM_BETA1) * g[j];
        p->v[j] = ADAM_BETA2 * p->v[j] + (1 - ADAM_BETA2) * g[j] * g[j];
        const double lr = j < 3 ? o->lr_translation_m : o->lr_rotation_rad;
        step[j] = -lr * (p->m[j] / c1) / (sqrt(p->v[j] / c2) + ADAM_EPS);
      }
      for (int j = 0; j < 3; j++) p->t[j] += step[j];
      double dR[9], Rn[9];
      fg_rotmat_from_rotvec(step + 3, dR);
      mul3(dR, p->R, Rn);
      memcpy(p->R, Rn, sizeof Rn);
    }
    st->evaluations += (size_t)n;
    /* prune on the costs just computed (the poses then step from them) */
    if (!last && n > o->n_final) {
      qsort(ps, (size_t)n, sizeof *ps, cmp_pose);
      int drop = (int)(PRUNE_FRACTION * n);
      if (drop < 1) drop = 1;
      if (n - drop < o->n_final) drop = n - o->n_final;
      n -= drop;
    }
  }
  qsort(ps, (size_t)n, sizeof *ps, cmp_pose);
  return n;
}

/* The field's alpha at x (world, metres): trilinear between voxel centres, 0 outside the
 * grid. */
static double alpha_at(const fg_grasp_field *gf, const double x[3]) {
  const fg_voxel_grid *g = &gf->grid;
  const int n[3] = {g->nx, g->ny, g->nz};
  int i0[3];
  double f[3];
  for (int a = 0; a < 3; a++) {
    const double u = (x[a] - g->min[a]) / g->voxel_size - 0.5;
    if (!(u > -1.0 && u < n[a])) return 0.0;
    i0[a] = (int)floor(u);
    f[a] = u - i0[a];
  }
  double v = 0.0;
  for (int c = 0; c < 8; c++) {
    const int ix = i0[0] + (c & 1), iy = i0[1] + (c >> 1 & 1), iz = i0[2] + (c >> 2 & 1);
    if (ix < 0 || iy < 0 || iz < 0 || ix >= n[0] || iy >= n[1] || iz >= n[2]) continue;
    const double w = (c & 1 ? f[0] : 1 - f[0]) * (c >> 1 & 1 ? f[1] : 1 - f[1]) *
                     (c >> 2 & 1 ? f[2] : 1 - f[2]);
    v += w * gf->alpha[((size_t)iz * g->ny + iy) * g->nx + ix];
  }
  return v;
}

/* 1 when something solid (alpha >= CENTRE_ALPHA) lies between the pads of the pose (R, t)
 * slid by s along its x: on the segment across the opening (the gripper's y, width_m) at the
 * TCP and CENTRE_STEP_M * 4 above and below it. */
static int object_between_pads(const fg_grasp_field *gf, const double R[9], const double t[3],
                               double s, double width_m) {
  const int ny = (int)ceil(width_m / CENTRE_STEP_M);
  for (int kz = -1; kz <= 1; kz++)
    for (int j = 0; j <= ny; j++) {
      const double y = -0.5 * width_m + j * width_m / ny, z = kz * 4 * CENTRE_STEP_M;
      double x[3];
      for (int a = 0; a < 3; a++) x[a] = t[a] + R[3 * a] * s + R[3 * a + 1] * y + R[3 * a + 2] * z;
      if (alpha_at(gf, x) >= CENTRE_ALPHA) return 1;
    }
  return 0;
}

/* Centring (grasp.h): p slid along its x to the middle of the stretch over which the object
 * lies between its pads (looked for up to CENTRE_SCAN centre_m each way; the move at most
 * centre_m), when its cost there stays within FG_GRASP_CENTRE_TOL of its own and
 * it is free and within the limits (else half way, else not at all); its cost, likeness and
 * weight scored again. On the calling thread (scratch[0]). */
static void centre(const fg_grasp_field *gf, search_bufs *b, const fg_grasp_options *o,
                   const fg_gripper_box *boxes, pose_state *p, fg_grasp_stats *st) {
  const int n = (int)floor(CENTRE_SCAN * o->centre_m / CENTRE_STEP_M + 1e-9);
  if (n < 1 || !isfinite(p->cost) || !object_between_pads(gf, p->R, p->t, 0.0, o->width_m))
    return;
  int reach[2] = {0, 0}; /* steps towards -x and +x with the object still between the pads */
  for (int side = 0; side < 2; side++)
    while (reach[side] < n && object_between_pads(gf, p->R, p->t, (side ? 1 : -1) *
                                                  (reach[side] + 1) * CENTRE_STEP_M, o->width_m))
      reach[side]++;
  const double to_middle =
    fmax(-o->centre_m, fmin(o->centre_m, 0.5 * (reach[1] - reach[0]) * CENTRE_STEP_M));
  const double limit = p->cost + FG_GRASP_CENTRE_TOL * fabs(p->cost);
  for (int half = 0; half < 2; half++) {
    const double shift = to_middle / (1 << half);
    if (shift == 0) return;
    double t[3], T[16], cosv, weight;
    for (int a = 0; a < 3; a++) t[a] = p->t[a] + shift * p->R[3 * a];
    fg_pose_from_rotmat(p->R, t, T);
    const double c = fg_grasp_cost_fast(gf, &b->prep, T, NULL, NULL, &cosv, &weight,
                                        &b->scratch[0]);
    st->evaluations++;
    if (!(c <= limit) || !within_limits(o, T)) continue;
    if (o->check_collisions) {
      st->collision_checks++;
      if (gripper_collides(gf, b->occ, boxes, T, o->floor_solid)) continue;
    }
    memcpy(p->t, t, sizeof t);
    p->cost = c;
    p->cosv = cosv;
    p->weight = weight;
    return;
  }
}

int fg_grasp_search(const fg_grasp_field *gf, const fg_grasp_target *t,
                    const fg_grasp_options *opt, fg_grasp_result *out) {
  if (!gf || !t || !out) return fg_fail(FG_EINVAL, "grasp search: NULL argument");
  memset(out, 0, sizeof *out);
  fg_grasp_options o;
  if (opt)
    o = *opt;
  else
    fg_grasp_options_default(&o);
  FG_TRY(check_options(&o));
  const double t0 = fg_mono_s();
  search_bufs b = {0};
  int rc = fg_grasp_prepare(gf, t, &b.prep);
  if (rc < 0) return rc;
  {
    fg_grasp_target tc = *t;
    if (tc.n_points > COARSE_POINTS) tc.n_points = COARSE_POINTS;
    /* a task whose first points all lie in free space is scored on all of them */
    rc = fg_grasp_prepare(gf, &tc, &b.coarse);
    if (rc == FG_EINVAL) rc = fg_grasp_prepare(gf, t, &b.coarse);
    if (rc < 0) {
      bufs_release(&b);
      return rc;
    }
  }
  fg_grasp_stats *st = &out->stats;
  const int n_rot = o.n_rotations;
  st->rotations = n_rot;
  st->iterations = o.iterations;
  b.nt = fg_threads(o.n_threads);
  fg_gripper_box boxes[FG_GRIPPER_N_BOXES];
  fg_gripper_boxes(o.gripper, o.width_m, boxes);

  b.scratch = calloc((size_t)b.nt, sizeof *b.scratch);
  b.occ = occupancy(gf, o.collision_alpha);
  b.cand = malloc((gf->n_vox ? gf->n_vox : 1) * sizeof *b.cand);
  b.rot = malloc((size_t)n_rot * 9 * sizeof *b.rot);
  b.hit = malloc(SCORE_CHUNK);
  if (!b.scratch || !b.occ || !b.cand || !b.rot || !b.hit) goto nomem;
  for (int i = 0; i < b.nt; i++)
    if (fg_grasp_scratch_init(&b.scratch[i], t->n_points) < 0) goto nomem;

  /* candidates */
  const uint8_t *mask = o.candidate_mask;
  if (mask && o.mask_dilation > 0) {
    b.dilated = dilate(&gf->grid, mask, o.mask_dilation);
    if (!b.dilated) goto nomem;
    mask = b.dilated;
  }
  size_t n_cand = 0;
  for (size_t i = 0; i < gf->n_vox; i++)
    if (gf->alpha[i] >= o.candidate_alpha && (!mask || mask[i]))
      b.cand[n_cand++] = (uint32_t)i;
  st->candidates = n_cand;
  if (n_cand == 0) {
    out->reason = o.candidate_mask ? "no occupied voxel passes the language mask"
                                   : "no occupied voxel in the workspace";
    goto done;
  }
  if (n_cand * (size_t)n_rot > UINT32_MAX) {
    rc = fg_fail(FG_ERANGE, "%zu candidates x %d rotations is too many poses", n_cand, n_rot);
    goto error;
  }

  /* the cover of SO(3), turned as a whole by a rotation from the seed */
  {
    double *q = malloc((size_t)n_rot * 4 * sizeof *q);
    if (!q) goto nomem;
    fg_so3_super_fibonacci(n_rot, q);
    double Rs[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    if (o.seed) { /* Shoemake's uniform quaternion */
      const double u1 = fg_rng_uniform(o.seed, 0), u2 = fg_rng_uniform(o.seed, 1),
                   u3 = fg_rng_uniform(o.seed, 2);
      const double qs[4] = {sqrt(u1) * cos(2 * M_PI * u3), sqrt(1 - u1) * sin(2 * M_PI * u2),
                            sqrt(1 - u1) * cos(2 * M_PI * u2), sqrt(u1) * sin(2 * M_PI * u3)};
      fg_rotmat_from_quat(qs, Rs);
    }
    for (int r = 0; r < n_rot; r++) {
      double R0[9];
      fg_rotmat_from_quat(q + 4 * r, R0);
      mul3(Rs, R0, b.rot + (size_t)r * 9);
    }
    free(q);
  }

  /* score every candidate pose */
  const size_t n_poses = n_cand * (size_t)n_rot;
  st->poses_scored = n_poses;
  b.sc = malloc(n_poses * sizeof *b.sc);
  if (!b.sc) goto nomem;
#pragma omp parallel for num_threads(b.nt) schedule(dynamic, 64)
  for (int64_t id = 0; id < (int64_t)n_poses; id++) {
    double R[9], tr[3], T[16];
    candidate_pose(gf, &b, n_rot, (uint32_t)id, R, tr);
    fg_pose_from_rotmat(R, tr, T);
    /* a rotation the cone refuses is never kept: the tool's +z (R's third column) */
    b.sc[id].cost = o.limits && o.limits->cone_rad < M_PI &&
                            acos(fmax(-1.0, fmin(1.0, -R[8]))) > o.limits->cone_rad
                        ? INFINITY
                        : fg_grasp_cost_fast(gf, &b.coarse, T, NULL, NULL, NULL, NULL,
                                             &b.scratch[omp_get_thread_num()]);
    b.sc[id].id = (uint32_t)id;
  }
  st->evaluations += n_poses;
  qsort(b.sc, n_poses, sizeof *b.sc, cmp_scored);

  /* the best collision-free ones, checked a chunk at a time in parallel */
  b.ps = malloc((size_t)o.n_keep * sizeof *b.ps);
  if (!b.ps) goto nomem;
  int n_keep = 0, cone_end = 0;
  for (size_t s0 = 0; s0 < n_poses && n_keep < o.n_keep && !cone_end; s0 += SCORE_CHUNK) {
    const int m = (int)(n_poses - s0 < SCORE_CHUNK ? n_poses - s0 : SCORE_CHUNK);
    if (o.check_collisions) {
#pragma omp parallel for num_threads(b.nt) schedule(dynamic, 4)
      for (int k = 0; k < m; k++) {
        double R[9], tr[3], T[16];
        candidate_pose(gf, &b, n_rot, b.sc[s0 + k].id, R, tr);
        fg_pose_from_rotmat(R, tr, T);
        b.hit[k] = (uint8_t)palm_collides(gf, b.occ, boxes, T, o.floor_solid);
      }
      st->collision_checks += (size_t)m;
    }
    for (int k = 0; k < m && n_keep < o.n_keep; k++) {
      if (isinf(b.sc[s0 + k].cost)) { /* sorted last: only cone-refused poses remain */
        st->rejected_limits += n_poses - s0 - (size_t)k;
        cone_end = 1;
        break;
      }
      if (o.check_collisions && b.hit[k]) {
        st->rejected_collisions++;
        continue;
      }
      pose_state *p = &b.ps[n_keep++];
      memset(p, 0, sizeof *p);
      p->id = b.sc[s0 + k].id;
      candidate_pose(gf, &b, n_rot, p->id, p->R, p->t);
      p->cost = b.sc[s0 + k].cost;
    }
  }
  if (n_keep == 0) {
    out->reason = st->rejected_limits ? "every candidate pose collides with the scene or "
                                        "approaches from outside the robot's approach cone"
                                      : "every candidate pose collides with the scene";
    goto done;
  }
  st->poses_optimised = (size_t)n_keep;
  const int n_left = optimise(gf, &b, &o, b.ps, n_keep, st);

  /* collisions after optimising, then non-maximum suppression: the survivors best first,
   * then, while fewer than top_k are free, the pruned poses from the last pruned (ps keeps
   * them behind the survivors, the latest first), each scored again where it stands */
  out->poses = calloc((size_t)o.top_k, sizeof *out->poses);
  if (!out->poses) goto nomem;
  for (int k = 0; k < n_keep && out->n < o.top_k; k++) {
    pose_state *p = &b.ps[k];
    double T[16];
    fg_pose_from_rotmat(p->R, p->t, T);
    if (k >= n_left) {
      p->cost = fg_grasp_cost_fast(gf, &b.prep, T, NULL, NULL, &p->cosv, &p->weight,
                                   &b.scratch[0]);
      st->evaluations++;
    }
    if (!(p->cosv > 0.0)) continue; /* no likeness to the task */
    centre(gf, &b, &o, boxes, p, st);
    fg_pose_from_rotmat(p->R, p->t, T);
    if (!within_limits(&o, T)) {
      st->rejected_limits++;
      continue;
    }
    if (o.check_collisions) {
      st->collision_checks++;
      if (gripper_collides(gf, b.occ, boxes, T, o.floor_solid)) {
        st->rejected_collisions++;
        continue;
      }
    }
    int dup = 0;
    for (int j = 0; j < out->n && !dup; j++) {
      const fg_grasp_result_pose *q = &out->poses[j];
      double Rq[9];
      for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) Rq[3 * r + c] = q->T_world_gripper[4 * r + c];
      const double dx = T[3] - q->T_world_gripper[3], dy = T[7] - q->T_world_gripper[7],
                   dz = T[11] - q->T_world_gripper[11];
      if (sqrt(dx * dx + dy * dy + dz * dz) <= o.nms_distance_m &&
          grip_angle(p->R, Rq) <= o.nms_angle_rad)
        dup = 1;
    }
    if (dup) continue;
    fg_grasp_result_pose *r = &out->poses[out->n++];
    memcpy(r->T_world_gripper, T, sizeof T);
    r->cost = p->cost;
    r->score = p->cosv;
    r->weight = p->weight;
    r->collision_free = o.check_collisions;
  }
  if (out->n == 0) {
    free(out->poses);
    out->poses = NULL;
    out->reason = o.check_collisions ? "every optimised pose collides with the scene, lies "
                                       "outside the robot's motion limits, or is unlike the "
                                       "task"
                                     : "no pose is like the task or within the motion limits";
  }
done:
  st->seconds = fg_mono_s() - t0;
  bufs_release(&b);
  return 0;
nomem:
  rc = fg_fail(FG_ENOMEM, "grasp search: out of memory");
error:
  bufs_release(&b);
  fg_grasp_result_release(out);
  return rc;
}
