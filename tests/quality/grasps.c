/* Grasp questions on trained layouts: see grasps.h. */
#include "grasps.h"

#include "testutil.h"

#include "core/pose.h"
#include "grasp/grasp.h"

int sg_object_index(const sg_gt *gt, const char *name) {
  for (int k = 0; k < gt->n_objects; k++)
    if (strcmp(gt->objects[k].name, name) == 0) return k;
  FG_TEST_FAIL("gt.json has no %s", name);
}

void sg_class_query(const sg_gt *gt, const char *name, fg_query *q) {
  const int D = gt->feature_dim, cls = sg_gt_class(gt, name);
  if (cls < 0) FG_TEST_FAIL("gt.json has no class %s", name);
  float *neg = malloc((size_t)gt->n_classes * D * sizeof *neg);
  ASSERT(neg);
  int nn = 0;
  for (int c = 0; c < gt->n_classes; c++)
    if (c != cls)
      memcpy(neg + (size_t)nn++ * D, gt->embeddings + (size_t)c * D, D * sizeof *neg);
  ASSERT_OK(fg_query_init(q, D, gt->embeddings + (size_t)cls * D, 1, neg, nn, SG_QUERY_TEMP));
  free(neg);
}

int sg_task_retrieve(float *const Z[], int n_tasks, int n_q, int D, const float *q,
                     double *sims) {
  int best = -1;
  double best_sim = -INFINITY;
  for (int k = 0; k < n_tasks; k++) {
    const double sim = fg_grasp_task_similarity(Z[k], n_q, D, q);
    if (sims) sims[k] = sim;
    if (sim > best_sim) best_sim = sim, best = k;
  }
  ASSERT(best >= 0);
  return best;
}

void sg_language_mask(const sg_layout *L, const fg_query *q, uint8_t *mask) {
  const size_t N = fg_voxel_grid_count(fg_voxel_features_grid(L->vf));
  float *scores = malloc(N * sizeof *scores);
  ASSERT(scores);
  ASSERT_OK(fg_voxel_features_score(L->vf, q, 0.1f, scores, L->spec.threads > 0
                                                               ? L->spec.threads
                                                               : SG_LAYOUT_THREADS));
  for (size_t i = 0; i < N; i++) mask[i] = scores[i] >= SG_MASK_SCORE;
  free(scores);
}

/* T with its rotation post-multiplied by a turn of angle_rad about its own axis a. */
static void turn_about(const double T[16], int a, double angle_rad, double out[16]) {
  double axis[3] = {0, 0, 0}, R[9], Ry[16];
  axis[a] = angle_rad;
  fg_rotmat_from_rotvec(axis, R);
  const double zero[3] = {0, 0, 0};
  fg_pose_from_rotmat(R, zero, Ry);
  fg_pose_compose(T, Ry, out);
}

/* The truth of object ob carried by a turn of angle_rad about the object's vertical axis. */
static void turn_object(const sg_gt_object *ob, const double truth[16], double angle_rad,
                        double out[16]) {
  double Tz[16], M[16];
  turn_about(ob->shape.T_world_obj, 2, angle_rad, Tz);
  fg_pose_compose(Tz, ob->shape.T_obj_world, M);
  fg_pose_compose(M, truth, out);
}

/* The angle about the object's vertical axis of a world point, in the object frame. */
static double azimuth(const sg_gt_object *ob, const double p_world[3]) {
  double p_obj[3];
  fg_pose_apply(ob->shape.T_obj_world, p_world, p_obj);
  return atan2(p_obj[1], p_obj[0]);
}

void sg_grasp_errors(const sg_gt *gt, int k, const double truth[16], const double T[16],
                     double *dist_m, double *angle_deg) {
  const sg_gt_object *ob = &gt->objects[k];
  double t0[16];
  memcpy(t0, truth, sizeof t0);
  if (ob->shape.type == SG_SHAPE_BOWL) { /* the truth's pinch moved round the rim to T's */
    const double pt[3] = {truth[3], truth[7], truth[11]}, pT[3] = {T[3], T[7], T[11]};
    turn_object(ob, truth, azimuth(ob, pT) - azimuth(ob, pt), t0);
  }
  const double d[3] = {T[3] - t0[3], T[7] - t0[7], T[11] - t0[11]};
  *dist_m = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (ob->shape.type == SG_SHAPE_BALL) { /* a ball looks the same from every side */
    *angle_deg = 0.0;
    return;
  }
  double best = INFINITY;
  for (int obj_turn = 0; obj_turn < (ob->shape.type == SG_SHAPE_BOX ? 2 : 1); obj_turn++) {
    double t1[16];
    if (obj_turn)
      turn_object(ob, t0, M_PI, t1);
    else
      memcpy(t1, t0, sizeof t1);
    for (int flip = 0; flip < 2; flip++) { /* the gripper turned about its approach axis */
      double t2[16];
      if (flip)
        turn_about(t1, 2, M_PI, t2);
      else
        memcpy(t2, t1, sizeof t2);
      const double a = fg_pose_angle_rad(T, t2) * 180.0 / M_PI;
      if (a < best) best = a;
    }
  }
  *angle_deg = best;
}
