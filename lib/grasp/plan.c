/* Grasp planning (plan.h): retrieval, the language mask, the opening and the pre-grasps
 * around one fg_grasp_search. */
#include "grasp/plan.h"

#include "core/error.h"
#include "core/pose.h"
#include "grasp/internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct ranked {
  fg_grasp_retrieval r;
  const char *name;
} ranked;

static int cmp_ranked(const void *a, const void *b) {
  const ranked *x = a, *y = b;
  if (x->r.score != y->r.score) return x->r.score > y->r.score ? -1 : 1;
  return strcmp(x->name, y->name);
}

/* F3RM's retrieval: the tasks of q's D with a defined likeness, best first. */
static int retrieve(const fg_grasp_task *tasks, int n, const fg_query *q, fg_grasp_plan *p) {
  ranked *rk = malloc((size_t)(n > 0 ? n : 1) * sizeof *rk);
  if (!rk) return fg_fail(FG_ENOMEM, "out of memory");
  int k = 0;
  for (int i = 0; i < n; i++) {
    const fg_grasp_task *t = &tasks[i];
    if (t->dim != q->dim) continue;
    const double s = fg_grasp_task_similarity(t->Z, t->n_points, t->dim, q->q);
    if (isnan(s)) continue;
    rk[k++] = (ranked){{i, s}, t->name};
  }
  if (k == 0) {
    free(rk);
    return fg_fail(FG_ENOENT, "no task has demos with features of D = %d", q->dim);
  }
  qsort(rk, (size_t)k, sizeof *rk, cmp_ranked);
  p->retrieval = malloc((size_t)k * sizeof *p->retrieval);
  if (!p->retrieval) {
    free(rk);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  for (int i = 0; i < k; i++) p->retrieval[i] = rk[i].r;
  p->n_retrieval = k;
  p->task = rk[0].r.task;
  free(rk);
  return 0;
}

/* The candidates where q's heatmap score, at the search's candidate threshold, reaches
 * FG_GRASP_PLAN_MASK_SCORE, into a malloc'd mask. */
static int language_mask(const fg_grasp_field *gf, const fg_query *q, const fg_grasp_options *o,
                         uint8_t **out) {
  const size_t n = gf->n_vox;
  float *scores = malloc(n * sizeof *scores);
  uint8_t *mask = malloc(n);
  int rc = scores && mask ? fg_voxel_features_score(gf->vf, q, o->candidate_alpha, scores,
                                                    o->n_threads)
                          : fg_fail(FG_ENOMEM, "out of memory");
  if (rc == 0)
    for (size_t i = 0; i < n; i++) mask[i] = scores[i] >= FG_GRASP_PLAN_MASK_SCORE;
  free(scores);
  if (rc != 0) {
    free(mask);
    return fg_fail(rc, "cannot score the query: %s", fg_error_detail());
  }
  *out = mask;
  return 0;
}

int fg_grasp_plan_run(const fg_grasp_field *gf, const fg_grasp_plan_request *r,
                      fg_grasp_plan *out) {
  memset(out, 0, sizeof *out);
  if (!gf || !r || !r->tasks || r->n_tasks < 1 ||
      ((r->retrieve || r->language_weight) && !r->query))
    return fg_fail(FG_EINVAL, "a plan needs a task, and a query to retrieve or weight by");
  fg_grasp_plan p = {0};
  uint8_t *mask = NULL;
  int rc = r->retrieve ? retrieve(r->tasks, r->n_tasks, r->query, &p) : 0;
  if (rc == 0 && r->query && r->query->dim != gf->dim)
    rc = fg_fail(FG_EINVAL, "the query has D = %d, the field %d", r->query->dim, gf->dim);
  if (rc == 0 && r->query) rc = language_mask(gf, r->query, &r->opt, &mask);
  if (rc != 0) {
    fg_grasp_plan_release(&p);
    return rc;
  }
  const fg_grasp_task *t = &r->tasks[p.task];
  fg_grasp_options o = r->opt;
  const double stroke = fg_gripper_spec_get(o.gripper)->stroke_m;
  o.width_m = t->width_m < stroke ? t->width_m : stroke;
  o.approach_m = t->approach_m;
  if (t->place) o.retreat_m = 0;
  o.candidate_mask = mask;
  const fg_grasp_target target = {.n_points = t->n_points, .dim = t->dim,
                                  .p_gripper = t->p_gripper, .Z = t->Z,
                                  .q = r->language_weight ? r->query->q : NULL};
  rc = fg_grasp_search(gf, &target, &o, &p.result);
  free(mask);
  if (rc == 0 && p.result.n > 0 &&
      !(p.T_world_pre = malloc((size_t)p.result.n * sizeof *p.T_world_pre)))
    rc = fg_fail(FG_ENOMEM, "out of memory");
  if (rc != 0) {
    fg_grasp_plan_release(&p);
    return rc;
  }
  double T_gripper_pre[16];
  fg_pose_identity(T_gripper_pre);
  T_gripper_pre[11] = -t->approach_m; /* the gripper approaches along its own +z */
  for (int i = 0; i < p.result.n; i++)
    fg_pose_compose(p.result.poses[i].T_world_gripper, T_gripper_pre, p.T_world_pre[i]);
  p.width_m = o.width_m;
  p.approach_m = t->approach_m;
  *out = p;
  return 0;
}

void fg_grasp_plan_release(fg_grasp_plan *p) {
  free(p->retrieval);
  free(p->T_world_pre);
  fg_grasp_result_release(&p->result);
  memset(p, 0, sizeof *p);
}
