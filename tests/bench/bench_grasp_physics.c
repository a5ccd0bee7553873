/* Grasps executed in physics: the success rate of inferred grasps when a simulated gripper
 * carries them out, against the ground truth's own.
 *
 * Layouts. Question layouts from scenegen seeds 101, 102, ... (--layouts N of them, default
 * 10: 101-110), four objects each (mug, bowl, box, ball); the tests and scripts/demo.sh use
 * seeds 0, 1, 2, 3, 5, 7, 9, 11, 12 and 23 only. Demos on the quality test's two demo
 * layouts, seeds 1 and 3. All share layout 0's class embeddings
 * (--embedding-seed 0), as frames of one feature extractor do. Each layout is trained
 * in-process as tests/quality/layout.h does (30 views of 160 x 120, 32-d features in
 * 4-pixel patches, 2^15 samples a step, every view trained) for --steps steps on --threads
 * threads: twice, with and without depth maps (an RGB-D capture and a colour one). The demos
 * of each mode are recorded on demo layouts trained the same way, since features sampled on
 * a field trained with depth differ from those of a colour-only field (test_scenegen_quality.c).
 *
 * Demos. Per object, the F3RM sample at its ground-truth grasp (gt.json: the mug's and the
 * bowl's rims pinched from above, the box from above across its short side, the ball from
 * above at its equator) on each demo layout, averaged: Z = (z_1 + z_2) / 2. fieldgripd's
 * default query points for every object: 100 over the box between the pads of the 2F-85 open
 * to its stroke (proto/query-points.md).
 *
 * Questions. On each question layout, for each object, two grasp requests as fieldgripd
 * answers them (the grasp field built, then fg_grasp_search with the default options):
 *   task   the object's task embedding, no mask;
 *   query  the object's class embedding as the language query with the other classes as
 *          negatives: F3RM's retrieval picks the task, whose search runs only where the
 *          query's heatmap scores >= 0.5 (tests/quality/grasps.h, as the quality test).
 * The search checks collisions for the Robotiq 2F-85 open to its stroke (how the pick opens
 * it), with the table below the workspace solid, and returns only poses fieldgripd's shipped
 * motion limits allow (config/fieldgripd.conf: approach within 60 degrees of straight down;
 * the approach's start, the pose and the lift's end inside the workspace grown by 10 cm).
 * The time of a request is its wall time: grasp field, (query: heatmap mask and retrieval),
 * search.
 *
 * Execution. The top grasp of each request is executed in a fresh physics cell
 * (sim/cell.h) on the layout's cell.xml: the 2F-85, a pick (command 1) at the pose, width
 * the stroke, approach 0.10 m, force 40 N, speed 0.1 m/s, the default lift of 0.10 m, run to
 * rest at once (time scale 0). Success: the queried object held and 5 cm above where it
 * rested, and no other object knocked over. The ball is never counted as knocked over: the
 * cell calls an object knocked over when its z axis tilts by 45 degrees, which a ball that
 * merely rolls does too. A failure gets the first cause that fits, in this order:
 *   no_grasp      the search returned nothing;
 *   refused       the cell refused the block (out of its reach);
 *   knocked_over  the target (or another object) ended knocked over;
 *   collided      the hand touched an object on the way in, before the fingers closed (a
 *                 touch alone is no failure: the mug's own ground-truth pinch brushes it);
 *   missed        the fingers closed fully and never touched the target;
 *   wrong_object  the fingers stopped on, or lifted, another object, never the target;
 *   slipped       the target was touched or held but not lifted 5 cm.
 * Control: every object's ground-truth grasp on every question layout executed the same way
 * (once: the cell does not depend on depth maps). If it is not near 100 %, the cell is wrong
 * and no rate measured in it means anything.
 *
 * Usage: bench_grasp_physics --scenegen PROGRAM [--layouts N] [--steps N] [--threads N]
 *                            [--depth both|with|without]
 * Defaults: 10 layouts, 1200 steps, 2 threads, both. 900 steps of a layout took 31-34 s on 2
 * idle cores (AMD EPYC), so 1200 keep the 24 trainings, the 160 requests and the 200 picks
 * of the defaults under half an hour. Output: per layout trained
 *   bench=grasp_physics_layout seed=.. depth=.. steps=.. train_s=.. voxel_s=..
 * per grasp executed
 *   bench=grasp_physics_grasp layout=.. object=.. kind=task|query|control depth=yes|no|-
 *     outcome=success|failure cause=.. dist_m=.. angle_deg=.. ...
 * per depth mode bench=grasp_physics_depth depth=yes|no ..., and the summary
 *   bench=grasp_physics layouts=.. grasps=.. success=.. rate=.. ... pass=yes|no
 * with pass=yes when the rate with depth is >= 0.90 and the control's >= 0.95. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

#include "benchstat.h"
#include "cellproc.h"
#include "cellreport.h"
#include "core/clock.h"
#include "core/pose.h"
#include "grasp/grasp.h"
#include "grasps.h"
#include "layout.h"
#include "sim/cell.h"
#include "testutil.h"

#define N_QUERY 100
#define N_OBJECTS 4
#define N_DEMOS 2
#define FIRST_SEED 101
#define EMBEDDING_SEED "0"
#define GRIPPER FG_GRIPPER_ROBOTIQ_2F85
#define PICK_APPROACH_M 0.10
#define PICK_FORCE_N 40.0
#define PICK_SPEED_MPS 0.1
#define LIFTED_M 0.05      /* held and this far above its rest: lifted */
#define LIMIT_MARGIN_M 0.10 /* fieldgripd's limit_margin around the workspace */
#define LIMIT_CONE_DEG 60.0 /* ... and its approach_cone_deg */
#define TARGET_RATE 0.90
#define TARGET_CONTROL 0.95

static const char *const object_name[N_OBJECTS] = {"mug", "bowl", "box", "ball"};
static const char *const demo_seed[N_DEMOS] = {"1", "3"};

enum { KIND_TASK, KIND_QUERY, KIND_CONTROL, N_KINDS };
static const char *const kind_name[N_KINDS] = {"task", "query", "control"};

typedef enum {
  CAUSE_NONE,
  CAUSE_NO_GRASP,
  CAUSE_REFUSED,
  CAUSE_KNOCKED_OVER,
  CAUSE_COLLIDED,
  CAUSE_MISSED,
  CAUSE_WRONG_OBJECT,
  CAUSE_SLIPPED,
  N_CAUSES
} cause;
static const char *const cause_name[N_CAUSES] = {"none",     "no_grasp", "refused",
                                                 "knocked_over", "collided", "missed",
                                                 "wrong_object", "slipped"};

/* Counts of one depth mode (or of the control). */
typedef struct tally {
  int grasps, success;
  int obj_grasps[N_OBJECTS], obj_success[N_OBJECTS];
  int kind_grasps[N_KINDS], kind_success[N_KINDS];
  int causes[N_CAUSES];
} tally;

static void tally_add(tally *t, int object, int kind, cause c) {
  t->grasps++;
  t->obj_grasps[object]++;
  t->kind_grasps[kind]++;
  t->causes[c]++;
  if (c == CAUSE_NONE) {
    t->success++;
    t->obj_success[object]++;
    t->kind_success[kind]++;
  }
}

static double ratio(int a, int b) { return b > 0 ? (double)a / b : NAN; }

/* ---------------------------------------------------------------- the pick */

/* What one pick did, from the cell's report. */
typedef struct pick {
  int refused, gobj, touched, held, knocked, collided, other_knocked, other_lifted;
  int other_touched;
  double dz_m;
  char knocked_names[64]; /* the objects knocked over, comma-separated; "none" */
} pick;

/* Picks with the gripper at T_world_gripper in a fresh cell on cell_xml; target is the
 * queried object's index in gt. */
static void pick_run(const char *cell_xml, const sg_gt *gt, int target,
                     const double T_world_gripper[16], pick *out) {
  memset(out, 0, sizeof *out);
  char *text = NULL;
  size_t len = 0;
  FILE *report = open_memstream(&text, &len);
  ASSERT(report);
  sim_cell_config cfg;
  sim_cell_config_default(&cfg);
  cfg.scene_path = cell_xml;
  cfg.gripper = GRIPPER;
  cfg.time_scale = 0;
  cfg.report = report;
  char err[512];
  sim_cell *c = sim_cell_open(&cfg, err, sizeof err);
  if (!c) FG_TEST_FAIL("the cell does not open: %s", err);
  sim_cell_block b = {.seq = 1, .command = 1, .width = fg_gripper_spec_get(GRIPPER)->stroke_m,
                      .force = PICK_FORCE_N, .approach = PICK_APPROACH_M, .retreat = 0,
                      .speed = PICK_SPEED_MPS};
  double R[9];
  fg_pose_get_rotmat(T_world_gripper, R);
  fg_rotvec_from_rotmat(R, b.rv);
  for (int k = 0; k < 3; k++) b.p[k] = T_world_gripper[4 * k + 3];
  char why[256];
  if (sim_cell_program_start(c, &b, 0, why, sizeof why) == 0) {
    sim_cell_advance(c, 0); /* time scale 0: to rest at once */
    ASSERT(!sim_cell_busy(c));
    ASSERT_EQ(sim_cell_program_result(c), 2);
  } else {
    out->refused = 1;
  }
  sim_cell_close(c);
  ASSERT_EQ(fclose(report), 0);
  json_t *r = cellreport_line(text, -1, "the cell's report");
  free(text);
  out->gobj = cellproc_gobj(r);
  strcpy(out->knocked_names, "none");
  size_t kn = 0;
  for (int k = 0; k < gt->n_objects; k++) {
    json_t *ob = cellproc_object(r, gt->objects[k].name);
    const int knocked = cellproc_flag(ob, "knocked_over") &&
                        gt->objects[k].shape.type != SG_SHAPE_BALL;
    if (knocked && kn + strlen(gt->objects[k].name) + 2 < sizeof out->knocked_names)
      kn += (size_t)snprintf(out->knocked_names + kn, sizeof out->knocked_names - kn, "%s%s",
                             kn ? "," : "", gt->objects[k].name);
    out->collided |= cellproc_flag(ob, "collided");
    if (k == target) {
      out->touched = cellproc_flag(ob, "touched");
      out->held = cellproc_flag(ob, "held");
      out->knocked = knocked;
      out->dz_m = cellproc_num(ob, "dz_m");
    } else {
      out->other_knocked |= knocked;
      out->other_lifted |= cellproc_flag(ob, "lifted");
      out->other_touched |= cellproc_flag(ob, "touched");
    }
  }
  json_decref(r);
}

/* The outcome of a pick as described at the top. */
static cause pick_cause(const pick *p) {
  if (p->refused) return CAUSE_REFUSED;
  const int lifted = p->held && p->dz_m > LIFTED_M;
  if (lifted && !p->other_knocked) return CAUSE_NONE;
  if (p->knocked || p->other_knocked) return CAUSE_KNOCKED_OVER;
  if (p->collided) return CAUSE_COLLIDED;
  if (!p->touched && !p->held) {
    if (p->other_lifted || (p->gobj == 2 && p->other_touched)) return CAUSE_WRONG_OBJECT;
    return CAUSE_MISSED;
  }
  return CAUSE_SLIPPED;
}

/* ---------------------------------------------------------------- requests */

typedef struct question {
  float p[N_OBJECTS][N_QUERY * 3]; /* each task's query points, gripper frame */
  float *Z[N_OBJECTS];             /* (N_QUERY, D) task embeddings */
  double *secs;                    /* the requests' wall times */
  int n_secs, cap_secs;
  int threads;
} question;

static void time_add(question *qn, double s) {
  if (qn->n_secs == qn->cap_secs) {
    qn->cap_secs = qn->cap_secs ? 2 * qn->cap_secs : 64;
    qn->secs = realloc(qn->secs, (size_t)qn->cap_secs * sizeof *qn->secs);
    ASSERT(qn->secs);
  }
  qn->secs[qn->n_secs++] = s;
}

static void search_options(fg_grasp_options *o, const fg_motion_limits *lim, int threads) {
  fg_grasp_options_default(o);
  o->gripper = GRIPPER;
  o->width_m = fg_gripper_spec_get(GRIPPER)->stroke_m;
  o->n_threads = threads;
  o->top_k = 1;
  o->floor_solid = 1;
  o->limits = lim;
  o->approach_m = PICK_APPROACH_M;
  o->retreat_m = 0.10; /* the cell's lift */
}

/* One request on layout L for object k: by task, or by language (query) when kind is
 * KIND_QUERY, with *retrieved the task the query picked. 1 with the top pose in T, 0 when
 * the search found none. */
static int request(question *qn, const sg_layout *L, int k, int kind, int *retrieved,
                   double T[16], double *score) {
  const int D = L->gt.feature_dim;
  const fg_voxel_grid *g = fg_voxel_features_grid(L->vf);
  fg_motion_limits lim = {.has_box = 1, .cone_rad = LIMIT_CONE_DEG * M_PI / 180,
                          .max_width_m = fg_gripper_spec_get(GRIPPER)->stroke_m};
  for (int a = 0; a < 3; a++) {
    lim.box_min_m[a] = g->min[a] - LIMIT_MARGIN_M;
    lim.box_max_m[a] = g->max[a] + LIMIT_MARGIN_M;
  }
  fg_grasp_options o;
  search_options(&o, &lim, qn->threads);
  uint8_t *mask = NULL;
  int task = k;
  const double t0 = fg_mono_s();
  fg_grasp_field *gf;
  ASSERT_OK(fg_grasp_field_new(&gf, L->vf, qn->threads));
  if (kind == KIND_QUERY) {
    fg_query q;
    sg_class_query(&L->gt, object_name[k], &q);
    task = sg_task_retrieve(qn->Z, N_OBJECTS, N_QUERY, D, q.q, NULL);
    mask = malloc(fg_voxel_grid_count(g));
    ASSERT(mask);
    sg_language_mask(L, &q, mask);
    o.candidate_mask = mask;
    fg_query_release(&q);
  }
  *retrieved = task;
  const fg_grasp_target t = {N_QUERY, D, qn->p[task], qn->Z[task], NULL};
  fg_grasp_result r;
  ASSERT_OK(fg_grasp_search(gf, &t, &o, &r));
  fg_grasp_field_free(gf);
  time_add(qn, fg_mono_s() - t0);
  free(mask);
  const int found = r.n > 0;
  if (found) {
    memcpy(T, r.poses[0].T_world_gripper, 16 * sizeof *T);
    *score = r.poses[0].score;
  }
  fg_grasp_result_release(&r);
  return found;
}

/* ---------------------------------------------------------------- layouts */

static void layout_train(const char *scenegen, const char *seed, int depth, int steps,
                         int threads, sg_layout *L) {
  const sg_layout_spec spec = {seed, EMBEDDING_SEED, depth, 0, steps, threads};
  sg_layout_train(scenegen, &spec, L);
  printf("bench=grasp_physics_layout seed=%s depth=%s steps=%d threads=%d train_s=%.1f "
         "voxel_s=%.2f\n", seed, depth ? "yes" : "no", steps, threads, L->train_s,
         fg_voxel_features_build_seconds(L->vf));
}

/* Z of every object: the mean of its samples at its ground-truth grasp on the demo layouts,
 * trained with depth maps or without. */
static void record_demos(question *qn, const char *scenegen, int depth, int steps,
                         double *train_s) {
  for (int l = 0; l < N_DEMOS; l++) {
    sg_layout L;
    layout_train(scenegen, demo_seed[l], depth, steps, qn->threads, &L);
    *train_s += L.train_s;
    const int D = L.gt.feature_dim;
    fg_grasp_field *gf;
    ASSERT_OK(fg_grasp_field_new(&gf, L.vf, qn->threads));
    float *z = malloc((size_t)N_QUERY * D * sizeof *z);
    ASSERT(z);
    for (int k = 0; k < N_OBJECTS; k++) {
      if (!qn->Z[k]) qn->Z[k] = malloc((size_t)N_QUERY * D * sizeof *qn->Z[k]);
      ASSERT(qn->Z[k]);
      if (l == 0) memset(qn->Z[k], 0, (size_t)N_QUERY * D * sizeof *qn->Z[k]);
      const int i = sg_object_index(&L.gt, object_name[k]);
      ASSERT_OK(fg_grasp_sample(gf, L.gt.objects[i].T_world_grasp, qn->p[k], N_QUERY, z));
      for (size_t j = 0; j < (size_t)N_QUERY * D; j++) qn->Z[k][j] += z[j] / N_DEMOS;
    }
    free(z);
    fg_grasp_field_free(gf);
    sg_layout_free(&L);
  }
}

static void print_grasp(const char *seed, const char *object, int kind, const char *depth,
                        cause c, const pick *p, double dist_m, double angle_deg, double score,
                        const char *retrieved, double approach_deg) {
  printf("bench=grasp_physics_grasp layout=%s object=%s kind=%s depth=%s outcome=%s cause=%s "
         "dist_m=%.4f angle_deg=%.1f score=%.4f retrieved=%s approach_deg=%.1f gobj=%d "
         "touched=%d held=%d dz_m=%.4f collided=%d knocked=%s\n",
         seed, object, kind_name[kind], depth, c == CAUSE_NONE ? "success" : "failure",
         cause_name[c], dist_m, angle_deg, score, retrieved, approach_deg, p->gobj, p->touched,
         p->held, p->dz_m, p->collided, p->knocked_names);
}

/* The angle of the tool's +z from straight down, degrees. */
static double approach_deg(const double T[16]) {
  return acos(fmax(-1.0, fmin(1.0, -T[10]))) * 180.0 / M_PI;
}

/* Question layout seed: both requests of every object executed (into t), and the control
 * once (into control, when it is not NULL). */
static void layout_questions(question *qn, const char *scenegen, const char *seed, int depth,
                             int steps, double *train_s, tally *t, tally *control) {
  sg_layout L;
  layout_train(scenegen, seed, depth, steps, qn->threads, &L);
  *train_s += L.train_s;
  char *cell = fg_path_join(L.dir, "cell.xml");
  ASSERT(cell);
  for (int k = 0; k < N_OBJECTS; k++) {
    const int i = sg_object_index(&L.gt, object_name[k]);
    const double *truth = L.gt.objects[i].T_world_grasp;
    for (int kind = KIND_TASK; kind <= KIND_QUERY; kind++) {
      double T[16], score = NAN, dist = NAN, ang = NAN;
      int retrieved;
      pick p = {.knocked_names = "none"};
      cause c = CAUSE_NO_GRASP;
      const int found = request(qn, &L, k, kind, &retrieved, T, &score);
      if (found) {
        sg_grasp_errors(&L.gt, i, truth, T, &dist, &ang);
        pick_run(cell, &L.gt, i, T, &p);
        c = pick_cause(&p);
      }
      tally_add(t, k, kind, c);
      print_grasp(seed, object_name[k], kind, depth ? "yes" : "no", c, &p, dist, ang, score,
                  kind == KIND_QUERY ? object_name[retrieved] : "-",
                  found ? approach_deg(T) : NAN);
    }
    if (control) {
      pick p;
      pick_run(cell, &L.gt, i, truth, &p);
      const cause c = pick_cause(&p);
      tally_add(control, k, KIND_CONTROL, c);
      print_grasp(seed, object_name[k], KIND_CONTROL, "-", c, &p, 0, 0, NAN, "-",
                  approach_deg(truth));
    }
    fflush(stdout);
  }
  free(cell);
  sg_layout_free(&L);
}

/* ---------------------------------------------------------------- main */

static void print_depth(int depth, const tally *t) {
  printf("bench=grasp_physics_depth depth=%s grasps=%d success=%d rate=%.3f", depth ? "yes" : "no",
         t->grasps, t->success, ratio(t->success, t->grasps));
  for (int k = 0; k < N_OBJECTS; k++)
    printf(" %s_success=%d %s_rate=%.3f", object_name[k], t->obj_success[k], object_name[k],
           ratio(t->obj_success[k], t->obj_grasps[k]));
  for (int kind = KIND_TASK; kind <= KIND_QUERY; kind++)
    printf(" %s_success=%d %s_rate=%.3f", kind_name[kind], t->kind_success[kind],
           kind_name[kind], ratio(t->kind_success[kind], t->kind_grasps[kind]));
  for (int c = 1; c < N_CAUSES; c++) printf(" fail_%s=%d", cause_name[c], t->causes[c]);
  printf("\n");
}

static void usage(const char *bad) {
  fprintf(stderr,
          "bench_grasp_physics: bad argument '%s'\n"
          "usage: bench_grasp_physics --scenegen PROGRAM [--layouts N] [--steps N]\n"
          "                           [--threads N] [--depth both|with|without]\n"
          "  (see the comment at the top of tests/bench/bench_grasp_physics.c)\n",
          bad);
  exit(2);
}

int main(int argc, char **argv) {
  const char *scenegen = NULL, *depth_arg = "both";
  int n_layouts = 10, steps = 1200, threads = 2;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    const int more = i + 1 < argc;
    if (!strcmp(a, "--scenegen") && more) scenegen = argv[++i];
    else if (!strcmp(a, "--layouts") && more) n_layouts = atoi(argv[++i]);
    else if (!strcmp(a, "--steps") && more) steps = atoi(argv[++i]);
    else if (!strcmp(a, "--threads") && more) threads = atoi(argv[++i]);
    else if (!strcmp(a, "--depth") && more) depth_arg = argv[++i];
    else usage(a);
  }
  const int with = !strcmp(depth_arg, "both") || !strcmp(depth_arg, "with");
  const int without = !strcmp(depth_arg, "both") || !strcmp(depth_arg, "without");
  if (!scenegen || n_layouts < 1 || n_layouts > 1000 || steps < 1 || threads < 1 ||
      !(with || without))
    usage(scenegen ? "(a value out of range)" : "(--scenegen is required)");
  setvbuf(stdout, NULL, _IOLBF, 0);
  const double t_start = fg_mono_s();

  question qn = {.threads = threads};
  double mean[3], size[3];
  ASSERT_OK(fg_grasp_query_box_default(GRIPPER, fg_gripper_spec_get(GRIPPER)->stroke_m, mean,
                                       size));
  for (int k = 0; k < N_OBJECTS; k++)
    ASSERT_OK(fg_grasp_query_points_box(N_QUERY, mean, size, qn.p[k]));

  tally by_depth[2] = {{0}}, control = {0};
  double train_s = 0;
  int trainings = 0;
  /* with depth first: the target's mode, and the control with it */
  for (int depth = 1; depth >= 0; depth--) {
    if (depth ? !with : !without) continue;
    record_demos(&qn, scenegen, depth, steps, &train_s);
    trainings += N_DEMOS;
    for (int l = 0; l < n_layouts; l++) {
      char seed[16];
      snprintf(seed, sizeof seed, "%d", FIRST_SEED + l);
      const int first_mode = depth == 1 || !with;
      layout_questions(&qn, scenegen, seed, depth, steps, &train_s, &by_depth[depth],
                       first_mode ? &control : NULL);
      trainings++;
    }
  }
  for (int depth = 1; depth >= 0; depth--)
    if (by_depth[depth].grasps) print_depth(depth, &by_depth[depth]);

  tally all = {0};
  for (int d = 0; d < 2; d++) {
    const tally *t = &by_depth[d];
    all.grasps += t->grasps;
    all.success += t->success;
    for (int k = 0; k < N_OBJECTS; k++) {
      all.obj_grasps[k] += t->obj_grasps[k];
      all.obj_success[k] += t->obj_success[k];
    }
    for (int kind = 0; kind < N_KINDS; kind++) {
      all.kind_grasps[kind] += t->kind_grasps[kind];
      all.kind_success[kind] += t->kind_success[kind];
    }
    for (int c = 0; c < N_CAUSES; c++) all.causes[c] += t->causes[c];
  }
  const double rate_with = ratio(by_depth[1].success, by_depth[1].grasps);
  const double rate_without = ratio(by_depth[0].success, by_depth[0].grasps);
  const double rate_control = ratio(control.success, control.grasps);
  double mean_s = 0;
  for (int i = 0; i < qn.n_secs; i++) mean_s += qn.secs[i] / qn.n_secs;
  const double p50_s = qn.n_secs ? bench_median(qn.secs, qn.n_secs) : NAN;
  const int pass = rate_with >= TARGET_RATE && rate_control >= TARGET_CONTROL;

  printf("bench=grasp_physics layouts=%d question_seeds=%d-%d demo_seeds=%s,%s "
         "embedding_seed=%s objects=%d gripper=%s grasps=%d success=%d rate=%.3f",
         n_layouts, FIRST_SEED, FIRST_SEED + n_layouts - 1, demo_seed[0], demo_seed[1],
         EMBEDDING_SEED, N_OBJECTS, fg_gripper_spec_get(GRIPPER)->name, all.grasps,
         all.success, ratio(all.success, all.grasps));
  for (int k = 0; k < N_OBJECTS; k++)
    printf(" %s_success=%d %s_rate=%.3f", object_name[k], all.obj_success[k], object_name[k],
           ratio(all.obj_success[k], all.obj_grasps[k]));
  for (int kind = KIND_TASK; kind <= KIND_QUERY; kind++)
    printf(" %s_success=%d %s_rate=%.3f", kind_name[kind], all.kind_success[kind],
           kind_name[kind], ratio(all.kind_success[kind], all.kind_grasps[kind]));
  printf(" grasps_with_depth=%d success_with_depth=%d rate_with_depth=%.3f"
         " grasps_without_depth=%d success_without_depth=%d rate_without_depth=%.3f"
         " control_grasps=%d control_success=%d control_rate=%.3f",
         by_depth[1].grasps, by_depth[1].success, rate_with, by_depth[0].grasps,
         by_depth[0].success, rate_without, control.grasps, control.success, rate_control);
  for (int c = 1; c < N_CAUSES; c++) printf(" fail_%s=%d", cause_name[c], all.causes[c]);
  printf(" requests=%d p50_request_s=%.3f mean_request_s=%.3f steps=%d threads=%d"
         " trainings=%d train_s_mean=%.1f wall_s=%.0f target_min_rate_with_depth=%.2f"
         " target_min_control_rate=%.2f pass=%s\n",
         qn.n_secs, p50_s, mean_s, steps, threads, trainings,
         trainings ? train_s / trainings : NAN, fg_mono_s() - t_start, TARGET_RATE,
         TARGET_CONTROL, pass ? "yes" : "no");
  for (int k = 0; k < N_OBJECTS; k++) free(qn.Z[k]);
  free(qn.secs);
  return 0;
}
