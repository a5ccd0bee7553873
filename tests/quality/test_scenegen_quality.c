/* Quality on trained scenegen tabletops: four layouts (layout.h), each trained once and
 * checked for everything it serves, in this order:
 *   layout 1 captured with depth maps: issue 13's geometry and issue 5's heatmaps
 *     (heatmap_quality.c);
 *   layouts 1 and 3 in colour: the grasp demos;
 *   layout 0 in colour: issue 5's heatmaps, then the grasps asked for there.
 * Training is nearly all of this test's time (about 100 s a layout alone on 2 cores), so a
 * layout serves every check it can. The demos do not use the RGB-D layout: features sampled
 * on a field trained with depth differ from those of the colour-only layout the question is
 * asked on (measured with OpenBLAS's AVX2 kernels: the mug's top grasp 36.9 degrees off, its
 * true pose scoring 0.80 instead of 0.93). All three grasp layouts take layout 0's class embeddings
 * (--embedding-seed 0), so that layout 0 is also issue 5's layout as it was; with other
 * embeddings there the bowl's best voxel once fell outside it.
 *
 * Grasp quality, issue 12's criterion: demos recorded on two layouts, the question asked on a
 * third where every object moved at least 10 cm and turned at least 45 degrees about z
 * (asserted from gt.json). Three tasks:
 *   mug   by its handle: the TCP on the far end of the handle's ring, from above, the fingers
 *         closing across the ring's tube;
 *   box   from above across its short side (gt.json's grasp);
 *   ball  from above at its equator (gt.json's grasp).
 * For each task, the top grasp in the third layout lies within 1.5 cm and 20 degrees of the
 * ground-truth pose carried over from the demo (the object's own grasp in its new pose), with
 * the object's symmetries allowed (the box turned by 180 degrees about its vertical axis; the
 * ball in any orientation, so only its position counts) and the parallel gripper's 180-degree
 * turn about its approach axis; and it is collision-free for the Robotiq 2F-140 open to the
 * task's width. The layouts share their class embeddings (scenegen's --embedding-seed), as
 * frames of one feature extractor do. By language: the class embedding of each object, with
 * the other classes as negatives, retrieves that object's task (F3RM's mean query-point
 * feature) and, searching only where the heatmap passes its mask, finds the same pose.
 *
 * Query points. Each task's demos use 100 points spread over the box the 2F-140's fingers
 * close on at the task's width (fg_grasp_query_box_default): across the opening, the pads'
 * width and their height. Inside the box's solid the features are the same everywhere, so
 * its yaw shows only in the points that reach its faces, 3 cm from the TCP. With F3RM's
 * Gaussians (12 mm) about one point in a hundred reached them: the best pose then depended on
 * the rounding of the trainer's SGEMMs (25 degrees off with OpenBLAS's AVX-512 kernels, 15.5
 * with its AVX2 ones), and this test widened the box's spread to 20 mm by hand (the box then
 * 3.4 mm and 4.4 degrees off with AVX-512, 3.3 mm with AVX2; the mug 8.8 mm and 15.5 degrees
 * (7.2 mm, 11.5 degrees); the ball 8.3 mm (4.2 mm)). Those Gaussians find no collision-free
 * grasp of the mug with the gripper's pads, holders and links (gripper.h): every optimised
 * pose collides. With the box between the pads (AVX2): the mug 4.2 mm and 9.5 degrees off,
 * the box 5.6 mm and 10.0 degrees, the ball 6.3 mm; with the poses also centred along the
 * pads (grasp.h), the mug 4.1 mm and 9.5 degrees, the box 2.7 mm and 10.0, the ball 6.3 mm.
 *
 * Physics, issue 36's criterion: every top grasp, by task and by language, executed as a pick
 * in fieldgrip-sim's physics cell of the question layout (its cell.xml, the Robotiq 2F-140 of
 * the search open to the task's width, through the int16 words fieldgripd writes) lifts its
 * object. A pose can pass the tolerances above and still close on air or knock the object
 * over; only contact physics tells.
 *
 * Updates, issue 39's criterion (update_checks): layout 0 changed as a pick changes it, its
 * field updated rather than trained again.
 * argv[1]: the fieldgrip-scenegen program, argv[2]: fieldgrip-sim. */
#include "cellproc.h"
#include "testutil.h"

#include "core/pose.h"
#include "grasp/grasp.h"
#include "grasps.h"
#include "gtvox.h"
#include "heatmap_quality.h"
#include "layout.h"
#include "query/heatmap.h"

#define N_QUERY 100
#define POS_TOL_M 0.015
#define ANGLE_TOL_DEG 20.0

enum { TASK_MUG, TASK_BOX, TASK_BALL, N_TASKS };
static const char *const task_object[N_TASKS] = {"mug", "box", "ball"};
static const double task_width_m[N_TASKS] = {0.05, 0.11, 0.12};
#define GRIPPER FG_GRIPPER_ROBOTIQ_2F140

/* The task's gripper pose on its object in layout gt (world frame). */
static void task_pose(const sg_gt *gt, int task, double T_world_gripper[16]) {
  const sg_gt_object *ob = &gt->objects[sg_object_index(gt, task_object[task])];
  if (task != TASK_MUG) {
    memcpy(T_world_gripper, ob->T_world_grasp, 16 * sizeof(double));
    return;
  }
  /* the far end of the handle's ring (the ring lies in the object's x-z plane), from above:
   * approach along -z_obj, close along y_obj across the ring's tube, gripper x = y cross z =
   * -x_obj; the fingers come down on both sides of the handle's outer, upright part */
  const sg_shape *s = &ob->shape;
  const double T_obj_grasp[16] = {-1, 0, 0, s->handle_center[0] + s->handle_major,
                                  0, 1, 0, s->handle_center[1],
                                  0, 0, -1, s->handle_center[2],
                                  0, 0, 0, 1};
  fg_pose_compose(s->T_world_obj, T_obj_grasp, T_world_gripper);
}

/* Position and symmetry-aware angle errors of T against the truth of task in layout gt. */
static void task_errors(const sg_gt *gt, int task, const double T[16], double *dist_m,
                        double *angle_deg) {
  double truth[16];
  task_pose(gt, task, truth);
  sg_grasp_errors(gt, sg_object_index(gt, task_object[task]), truth, T, dist_m, angle_deg);
}

/* Every object of b moved >= 10 cm and turned >= 45 degrees about z from where it is in a. */
static void assert_moved(const sg_gt *a, const sg_gt *b) {
  for (int k = 0; k < a->n_objects; k++) {
    const sg_gt_object *oa = &a->objects[k], *ob = &b->objects[sg_object_index(b, oa->name)];
    const double d = hypot(oa->position[0] - ob->position[0], oa->position[1] - ob->position[1]);
    const double ya = atan2(oa->shape.T_world_obj[4], oa->shape.T_world_obj[0]);
    const double yb = atan2(ob->shape.T_world_obj[4], ob->shape.T_world_obj[0]);
    const double dyaw = fabs(remainder(ya - yb, 2 * M_PI)) * 180.0 / M_PI;
    printf("  %s: moved %.1f cm, turned %.0f degrees\n", oa->name, 100 * d, dyaw);
    ASSERT(d >= 0.10);
    ASSERT(dyaw >= 45.0);
  }
}

static char *g_tmp; /* the simulator's files */

/* Pose T executed as a pick in the physics cell of layout dir; it must lift the task's
 * object. A fresh simulator, so that each pick meets the layout as it was rendered. */
static void physics_check(const char *dir, int task, const double T[16], const char *how) {
  char cell[PATH_MAX + 16];
  snprintf(cell, sizeof cell, "%s/cell.xml", dir);
  const char *const extra[] = {"--gripper", "robotiq-2f140", NULL};
  cellproc c;
  cellproc_start(&c, cell, "int16", g_tmp, extra);
  double R[9], rv[3], p[3] = {T[3], T[7], T[11]};
  fg_pose_get_rotmat(T, R);
  fg_rotvec_from_rotmat(R, rv);
  ASSERT_EQ(cellproc_command(&c, 1, 1, p, rv, task_width_m[task], 0.10, 0), 2);
  json_t *r = cellproc_report(&c, 1);
  cellproc_stop(&c);
  json_t *ob = cellproc_object(r, task_object[task]);
  const int lifted = cellproc_flag(ob, "lifted");
  printf("%-8s %-4s: in physics %s, dz %.3f m, gOBJ %d%s%s\n", how, task_object[task],
         lifted ? "lifted" : "NOT lifted", cellproc_num(ob, "dz_m"), cellproc_gobj(r),
         cellproc_flag(ob, "collided") ? ", touched on the approach" : "",
         cellproc_flag(ob, "knocked_over") ? ", knocked over" : "");
  json_decref(r);
  ASSERT(lifted);
}

/* The top grasp of task by the field gf into *r (caller releases), printed with its distance
 * and angle from the truth in *dist, *ang and the next ones; the truth itself must be free. */
static fg_grasp_options grasp_options(int task, const uint8_t *mask) {
  fg_grasp_options o;
  fg_grasp_options_default(&o);
  o.gripper = GRIPPER;
  o.width_m = task_width_m[task];
  o.n_threads = 2;
  o.top_k = 5;
  o.candidate_mask = mask;
  return o;
}

static void search_top(const sg_gt *gt, const fg_grasp_field *gf, int task,
                       const fg_grasp_target *t, const uint8_t *mask, const char *how,
                       fg_grasp_result *r, double *dist, double *ang) {
  const fg_grasp_options o = grasp_options(task, mask);
  { /* the truth itself is free and like the task, or the criterion could not be met */
    double T[16], cosv;
    task_pose(gt, task, T);
    fg_grasp_cost(gf, t, T, NULL, NULL, &cosv, NULL);
    printf("%-8s %-4s: the true pose scores %.4f\n", how, task_object[task], cosv);
    ASSERT_EQ(fg_grasp_collides(gf, o.gripper, o.width_m, T, o.collision_alpha), 0);
  }
  ASSERT_OK(fg_grasp_search(gf, t, &o, r));
  if (r->n == 0) FG_TEST_FAIL("%s %s: no grasp (%s)", how, task_object[task], r->reason);
  task_errors(gt, task, r->poses[0].T_world_gripper, dist, ang);
  printf("%-8s %-4s: score %.4f, %.1f mm and %.1f degrees from the truth; %zu candidates x %d "
         "rotations, %zu optimised, %zu collisions rejected, %.2f s\n",
         how, task_object[task], r->poses[0].score, 1e3 * *dist, *ang, r->stats.candidates,
         r->stats.rotations, r->stats.poses_optimised, r->stats.rejected_collisions,
         r->stats.seconds);
  for (int k = 1; k < r->n; k++) {
    double d2, a2;
    task_errors(gt, task, r->poses[k].T_world_gripper, &d2, &a2);
    printf("            #%d: score %.4f, %.1f mm, %.1f degrees\n", k, r->poses[k].score,
           1e3 * d2, a2);
  }
  ASSERT_EQ(r->poses[0].collision_free, 1);
  ASSERT_EQ(fg_grasp_collides(gf, o.gripper, o.width_m, r->poses[0].T_world_gripper,
                              o.collision_alpha), 0);
}

static void search_and_check(const char *dir, const sg_gt *gt, const fg_grasp_field *gf, int task,
                             const fg_grasp_target *t,
                             const uint8_t *mask, const char *how) {
  fg_grasp_result r;
  double dist, ang;
  search_top(gt, gf, task, t, mask, how, &r, &dist, &ang);
  ASSERT(dist <= POS_TOL_M);
  ASSERT(ang <= ANGLE_TOL_DEG);
  physics_check(dir, task, r.poses[0].T_world_gripper, how);
  fg_grasp_result_release(&r);
}

/* Demo layout L: each task's query-point features z at its pose there, added into Z with
 * weight 1/2 (two demos). */
static void record_demos(const sg_layout *L, float p[N_TASKS][N_QUERY * 3], float *Z[N_TASKS]) {
  const int D = L->gt.feature_dim;
  fg_grasp_field *gf;
  ASSERT_OK(fg_grasp_field_new(&gf, L->vf, 2));
  float *z = malloc((size_t)N_QUERY * D * sizeof *z);
  ASSERT(z);
  for (int task = 0; task < N_TASKS; task++) {
    if (!Z[task]) Z[task] = calloc((size_t)N_QUERY * D, sizeof *Z[task]);
    ASSERT(Z[task]);
    double T[16];
    task_pose(&L->gt, task, T);
    ASSERT_OK(fg_grasp_sample(gf, T, p[task], N_QUERY, z));
    for (size_t i = 0; i < (size_t)N_QUERY * D; i++) Z[task][i] += 0.5f * z[i];
  }
  free(z);
  fg_grasp_field_free(gf);
}

/* The question on layout Q, whose objects all moved from where they lie in the demo layouts
 * demo_gt: by task, then by language. */
static void grasp_checks(const sg_layout *Q, const sg_gt demo_gt[2], const char *const seeds[2],
                         float p[N_TASKS][N_QUERY * 3], float *Z[N_TASKS]) {
  const int D = Q->gt.feature_dim;
  for (int l = 0; l < 2; l++) {
    printf("layout %s against demo layout %s:\n", Q->spec.seed, seeds[l]);
    assert_moved(&demo_gt[l], &Q->gt);
    ASSERT_EQ(demo_gt[l].n_classes, Q->gt.n_classes);
    ASSERT(memcmp(demo_gt[l].embeddings, Q->gt.embeddings,
                  (size_t)Q->gt.n_classes * D * sizeof(float)) == 0);
  }
  fg_grasp_field *gf;
  ASSERT_OK(fg_grasp_field_new(&gf, Q->vf, 2));

  /* by task */
  for (int task = 0; task < N_TASKS; task++) {
    const fg_grasp_target t = {N_QUERY, D, p[task], Z[task], NULL};
    search_and_check(Q->dir, &Q->gt, gf, task, &t, NULL, "task");
  }

  /* by language: retrieval, then the masked search */
  const size_t N = fg_voxel_grid_count(fg_voxel_features_grid(Q->vf));
  uint8_t *mask = malloc(N);
  ASSERT(mask);
  for (int task = 0; task < N_TASKS; task++) {
    fg_query q;
    sg_class_query(&Q->gt, task_object[task], &q);
    double sims[N_TASKS];
    const int best = sg_task_retrieve(Z, N_TASKS, N_QUERY, D, q.q, sims);
    for (int k = 0; k < N_TASKS; k++)
      printf("retrieval of '%s': task %s scores %.3f\n", task_object[task], task_object[k],
             sims[k]);
    ASSERT_EQ(best, task);
    sg_language_mask(Q, &q, mask);
    const fg_grasp_target t = {N_QUERY, D, p[best], Z[best], NULL};
    search_and_check(Q->dir, &Q->gt, gf, task, &t, mask, "language");
    fg_query_release(&q);
  }
  free(mask);
  fg_grasp_field_free(gf);
}

/* The scene changed (issue 39): layout 0 again with the mug taken away and the box moved
 * 10 cm, as a second capture would show it. Its field updated from layout 0's for
 * UPDATE_STEPS steps on the new views, against one trained from scratch on them
 * (SG_LAYOUT_STEPS): where the mug stood is free, the box's heatmap is as good, and its grasp
 * by task passes the grasp tests' tolerances, is free and lifts it in the changed cell's
 * physics (below). The update draws half
 * its rays where the views changed, as fieldgripd's updates do (fg_trainer_focus). */
#define UPDATE_STEPS 500
#define REMOVED_FREE 0.95 /* of the mug's voxels, alpha < 0.1 after the update */
#define ABOVE_TABLE_M 0.015 /* ... those whose centre lies this far above the table's top: the
                               layer the table's surface shares is solid in any field */
#define IOU_SLACK 0.05    /* the box's heatmap IoU at most this below the scratch field's */

static void update_checks(const char *scenegen, const sg_layout *before,
                          float p[N_TASKS][N_QUERY * 3], float *Z[N_TASKS]) {
  static const char *const edit[] = {"--remove", "mug", "--move", "box,0.10,0", NULL};
  const sg_layout_spec changed = {"0", "0", 0, 10, UPDATE_STEPS, 0, edit, before->field,
                                  FG_TRAIN_FOCUS_FRACTION};
  sg_layout U, S;
  sg_layout_train(scenegen, &changed, &U);
  sg_layout_spec scratch = changed;
  scratch.steps = 0;
  scratch.init = NULL;
  sg_layout_train(scenegen, &scratch, &S);

  const fg_voxel_grid g = *fg_voxel_features_grid(before->vf);
  const size_t N = fg_voxel_grid_count(&g);
  signed char *owner = malloc(N), *cavity = malloc(N);
  ASSERT(owner && cavity);
  sg_gt_voxelise(&before->gt, &g, owner, cavity);
  const int mug = sg_object_index(&before->gt, "mug");
  const float *a0 = fg_voxel_features_alpha(before->vf), *au = fg_voxel_features_alpha(U.vf),
              *as = fg_voxel_features_alpha(S.vf);
  size_t n = 0, solid0 = 0, free_u = 0, free_s = 0;
  const size_t nx = (size_t)g.nx, ny = (size_t)g.ny;
  for (size_t i = 0; i < N; i++) {
    double c[3];
    fg_voxel_grid_centre(&g, (int)(i % nx), (int)(i / nx % ny), (int)(i / (nx * ny)), c);
    if (owner[i] != mug || c[2] < before->gt.table_max[2] + ABOVE_TABLE_M) continue;
    n++;
    solid0 += a0[i] >= FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
    free_u += au[i] < FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
    free_s += as[i] < FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
  }
  printf("update: the mug's %zu voxels above the table: %.1f %% solid before, %.1f %% free "
         "after %d steps of update, %.1f %% free from scratch\n", n, 100.0 * solid0 / n, 100.0 * free_u / n,
         UPDATE_STEPS, 100.0 * free_s / n);
  ASSERT(n > 100);
  ASSERT(free_u >= REMOVED_FREE * n);

  const double iou_u = heatmap_iou(&U, sg_object_index(&U.gt, "box"));
  const double iou_s = heatmap_iou(&S, sg_object_index(&S.gt, "box"));
  printf("update: the moved box's heatmap IoU %.3f, from scratch %.3f\n", iou_u, iou_s);
  ASSERT(iou_u >= iou_s - IOU_SLACK);

  /* The box's grasp by task: the update's is held to the grasp tests' tolerances, and must
   * be free and lift the box in the changed cell's physics. Before the search centred its
   * poses along the pads (grasp.h) the update's was 18.8 mm off after 500 steps and 34.5 mm
   * after 1000: along the box's long side the pads meet the same two faces over some 7 cm,
   * and the optimum landed anywhere there. Centred, 9.0 mm and 14.3 degrees after 500. The
   * scratch field's is printed beside it, not held: there the true pose itself is not free.
   * Where the box's old place was, 99.7 % of the voxels are free after the 500-step update,
   * so nothing left behind pulls the grasp. */
  const fg_grasp_target t = {N_QUERY, U.gt.feature_dim, p[TASK_BOX], Z[TASK_BOX], NULL};
  fg_grasp_field *gf;
  ASSERT_OK(fg_grasp_field_new(&gf, S.vf, 2));
  fg_grasp_options o = grasp_options(TASK_BOX, NULL);
  fg_grasp_result r;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r));
  double dist, ang;
  if (r.n) {
    task_errors(&S.gt, TASK_BOX, r.poses[0].T_world_gripper, &dist, &ang);
    printf("scratch  box : %.1f mm and %.1f degrees from the truth\n", 1e3 * dist, ang);
  }
  fg_grasp_result_release(&r);
  fg_grasp_field_free(gf);
  ASSERT_OK(fg_grasp_field_new(&gf, U.vf, 2));
  search_top(&U.gt, gf, TASK_BOX, &t, NULL, "update", &r, &dist, &ang);
  ASSERT(dist <= POS_TOL_M);
  ASSERT(ang <= ANGLE_TOL_DEG);
  physics_check(U.dir, TASK_BOX, r.poses[0].T_world_gripper, "update");
  fg_grasp_result_release(&r);
  fg_grasp_field_free(gf);
  free(owner);
  free(cavity);
  sg_layout_free(&S);
  sg_layout_free(&U);
}

int main(int argc, char **argv) {
  ASSERT(argc == 3);
  setvbuf(stdout, NULL, _IOLBF, 0);
  g_tmp = sg_test_tmpdir("quality-physics");
  simproc_init(argv[2], g_tmp);
  float p[N_TASKS][N_QUERY * 3];
  for (int task = 0; task < N_TASKS; task++) {
    double mean[3], size[3];
    ASSERT_OK(fg_grasp_query_box_default(GRIPPER, task_width_m[task], mean, size));
    ASSERT_OK(fg_grasp_query_points_box(N_QUERY, mean, size, p[task]));
    printf("%s: query points over %.1f x %.1f x %.1f mm centred %.1f mm along z\n",
           task_object[task], 1e3 * size[0], 1e3 * size[1], 1e3 * size[2], 1e3 * mean[2]);
  }
  float *Z[N_TASKS] = {0};
  sg_layout L;

  /* An RGB-D capture: issue 13's geometry and issue 5's heatmaps. */
  const sg_layout_spec rgbd = {"1", "1", 1, 10};
  sg_layout_train(argv[1], &rgbd, &L);
  heatmap_quality_check(&L);
  sg_layout_free(&L);

  /* The grasp demos, on two layouts with every view trained. Layout 0's vocabulary
   * (--embedding-seed 0) for all three, so that layout 0 is the one heatmap layout without
   * depth as well. */
  static const char *const demo_seeds[2] = {"1", "3"};
  sg_gt demo_gt[2];
  for (int l = 0; l < 2; l++) {
    const sg_layout_spec demo = {demo_seeds[l], "0", 0, 0};
    sg_layout_train(argv[1], &demo, &L);
    record_demos(&L, p, Z);
    demo_gt[l] = L.gt;
    memset(&L.gt, 0, sizeof L.gt); /* kept for assert_moved */
    sg_layout_free(&L);
  }

  /* Layout 0, colour only, views 0, 10 and 20 held out: issue 5's heatmaps, then the grasps
   * asked for there. */
  const sg_layout_spec question = {"0", "0", 0, 10};
  sg_layout_train(argv[1], &question, &L);
  heatmap_quality_check(&L);
  grasp_checks(&L, demo_gt, demo_seeds, p, Z);
  update_checks(argv[1], &L, p, Z);
  sg_layout_free(&L);

  for (int l = 0; l < 2; l++) sg_gt_free(&demo_gt[l]);
  for (int task = 0; task < N_TASKS; task++) free(Z[task]);
  fg_rmtree(g_tmp);
  free(g_tmp);
  printf("ok\n");
  return 0;
}
