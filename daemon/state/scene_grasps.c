/* Demos and grasps on a scene (scene_grasps.h). */
#include "scene_grasps.h"

#include "scene_voxels.h"

#include "core/digest.h"
#include "core/error.h"
#include "core/log.h"
#include "core/rng.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- demos */

static int outside_workspace(const fg_scene_info *info, const double T[16]) {
  const double *lo = info->params.workspace_min, *hi = info->params.workspace_max;
  for (int a = 0; a < 3; a++)
    if (!(T[4 * a + 3] >= lo[a] && T[4 * a + 3] <= hi[a]))
      return fg_fail_as(FG_EINVAL, "pose_outside_workspace", "the pose's position [%g, %g, %g] "
                        "is outside scene '%s''s workspace [%g, %g, %g] .. [%g, %g, %g]; a "
                        "demo shows the gripper where the scene's field is", T[3], T[7], T[11],
                        info->name, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
  return 0;
}

/* The failure of a demo that does not fit its task (fg_task_check_demo's detail). */
static int misfit(int rc, fg_task_fit fit) {
  return fg_fail_as(rc, fit == FG_TASK_QUERY_POINTS_DIFFER ? "query_points_mismatch"
                        : fit == FG_TASK_KIND_DIFFERS      ? "kind_mismatch"
                        : fit == FG_TASK_DIM_DIFFERS       ? "feature_dim_mismatch"
                                                           : "too_many_demos",
                    "%s", fg_error_detail());
}

/* d's z: its query points placed at its pose, sampled on vox's grasp field into the malloc'd
 * *z. */
static int sample_demo(const char *scene, fg_voxels *vox, const fg_task_demo_new *d,
                       int n_threads, float **z) {
  const fg_grasp_field *gf = NULL;
  int rc = fg_voxels_grasp_field(vox, n_threads, &gf, NULL);
  if (rc != 0)
    return fg_fail_as(rc, "internal_error", "cannot build the grasp field of scene '%s': %s",
                      scene, fg_error_detail());
  const size_t n = (size_t)d->n_points * (size_t)d->dim;
  float *p = malloc((size_t)d->n_points * 3 * sizeof *p);
  *z = malloc(n * sizeof **z);
  if (!p || !*z)
    rc = fg_fail_as(FG_ENOMEM, "internal_error", "out of memory");
  else if (fg_grasp_query_points_layout(d->qp_layout, d->n_points, d->qp_mean_m, d->qp_std_m,
                                        d->qp_size_m, p) != 0 ||
           fg_grasp_sample(gf, d->T_world_gripper, p, d->n_points, *z) != 0)
    rc = fg_fail_as(FG_EINVAL, "invalid_query_points", "%s", fg_error_detail());
  free(p);
  double zz = 0;
  for (size_t k = 0; rc == 0 && k < n; k++) zz += (double)(*z)[k] * (*z)[k];
  if (rc == 0 && !(zz > 0))
    rc = fg_fail_as(FG_EINVAL, "demo_in_free_space", "at this pose every query point of the "
                    "gripper lies in free space of scene '%s''s field, so the demo would show "
                    "nothing; give the pose of the gripper at the object (the TCP between the "
                    "fingertips, +z the approach direction)", scene);
  if (rc != 0) {
    free(*z);
    *z = NULL;
  }
  return rc;
}

int fg_scene_demo_add(fg_scene *s, fg_tasks *ts, const char *name, const fg_task *t,
                      fg_task_demo_new *d, int n_threads, const fg_task **task, int *id) {
  *task = NULL;
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  FG_TRY(outside_workspace(&info, d->T_world_gripper));
  fg_scene_voxels sv;
  FG_TRY(fg_scene_voxels_acquire(s, 0, "a demo has nothing to sample", n_threads, &sv));
  d->dim = fg_voxel_features_dim(sv.vf);
  fg_task_fit fit = fg_task_check_demo(t, d);
  float *z = NULL;
  int rc = fit != FG_TASK_FITS ? misfit(FG_EEXIST, fit)
                               : sample_demo(info.name, sv.vox, d, n_threads, &z);
  fg_scene_voxels_release(&sv);
  if (rc != 0) return rc;
  d->z = z;
  rc = fg_tasks_add_demo(ts, name, d, &fit, task, id);
  d->z = NULL;
  free(z);
  if (rc == FG_EEXIST) return misfit(rc, fit);
  if (rc == FG_EBUSY) return fg_fail_as(rc, "task_unreadable", "%s", fg_error_detail());
  if (rc != 0) return fg_state_write_failed(rc, "the demo");
  fg_info("task %s: demo %d on scene %s (%d query points, D = %d)", name, *id, info.name,
          d->n_points, d->dim);
  return 0;
}

/* ---------------------------------------------------------------- grasps */

int fg_tasks_get_demonstrated(fg_tasks *ts, const char *name, const fg_task **out) {
  *out = fg_tasks_get(ts, name);
  if (!*out)
    return fg_fail_as(FG_ENOENT, "task_not_found", "no task named '%s'; GET /v1/tasks lists "
                      "them, POST /v1/tasks/%s/demos with a demo creates it", name, name);
  if ((*out)->n_demos == 0) {
    fg_task_unref(*out);
    *out = NULL;
    return fg_fail_as(FG_EINVAL, "task_empty", "task '%s' has no demo, so there is nothing to "
                      "look for; POST /v1/tasks/%s/demos to add one", name, name);
  }
  return 0;
}

static fg_grasp_task plan_task(const fg_task *t) {
  return (fg_grasp_task){.name = t->name, .place = t->kind == FG_TASK_PLACE,
                         .n_points = t->n_points, .dim = t->dim, .p_gripper = t->p_gripper,
                         .Z = t->Z, .width_m = t->width_m, .approach_m = t->approach_m};
}

/* The tasks the plan chooses from: r's, else every task with demos, into out->tasks (each
 * with a reference) and *list (malloc'd, the plan's view of them). */
static int gather_tasks(fg_tasks *ts, const fg_scene_grasps_req *r, fg_scene_grasps *out,
                        fg_grasp_task **list) {
  const fg_task **all = NULL;
  size_t n = 0;
  if (r->task) {
    all = malloc(sizeof *all);
    if (!all) return fg_fail(FG_ENOMEM, "out of memory");
    all[n++] = fg_task_ref(r->task);
  } else {
    FG_TRY(fg_tasks_list(ts, &all, &n));
  }
  *list = malloc((n ? n : 1) * sizeof **list);
  if (!*list) {
    fg_tasks_list_free(all, n);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  size_t k = 0;
  for (size_t i = 0; i < n; i++) {
    if (all[i]->n_demos == 0) {
      fg_task_unref(all[i]);
      continue;
    }
    (*list)[k] = plan_task(all[i]);
    all[k++] = all[i];
  }
  out->tasks = all;
  out->n_tasks = (int)k;
  return 0;
}

/* "g" + 16 hex digits: the field's identity, the request and the rank, mixed. */
static void grasp_id(uint64_t version, uint64_t request, int rank, char out[24]) {
  uint64_t h = fg_splitmix64(version ^ fg_splitmix64(request ^ fg_splitmix64((uint64_t)rank)));
  snprintf(out, 24, "g%016" PRIx64, h);
}

/* The plan's grasps as log entries, with their ids. */
static int entries_of(const char *scene, const char *request, uint64_t version,
                      fg_scene_grasps *g) {
  const fg_grasp_plan *p = &g->plan;
  const fg_task *t = g->tasks[p->task];
  const fg_span parts[] = {{scene, strlen(scene) + 1}, {request, strlen(request)}};
  uint8_t d[FG_SHA256_BYTES];
  fg_sha256(parts, 2, d);
  uint64_t rh;
  memcpy(&rh, d, sizeof rh);
  g->entries = calloc((size_t)(p->result.n ? p->result.n : 1), sizeof *g->entries);
  if (!g->entries) return fg_fail(FG_ENOMEM, "out of memory");
  for (int i = 0; i < p->result.n; i++) {
    fg_grasp_entry *e = &g->entries[i];
    grasp_id(version, rh, i, e->id);
    snprintf(e->scene, sizeof e->scene, "%s", scene);
    snprintf(e->task, sizeof e->task, "%s", t->name);
    e->field_version = version;
    memcpy(e->T_world_gripper, p->result.poses[i].T_world_gripper, sizeof e->T_world_gripper);
    e->width_m = p->width_m;
    e->approach_m = p->approach_m;
    e->place = t->kind == FG_TASK_PLACE;
  }
  return 0;
}

/* The plan on sv's voxels, its failures given their reasons. */
static int plan_on(const char *scene, const fg_scene_voxels *sv, fg_tasks *ts,
                   const fg_scene_grasps_req *r, int n_threads, fg_scene_grasps *out) {
  const int D = fg_voxel_features_dim(sv->vf);
  const fg_task *t = r->task;
  if (t && t->dim != D)
    return fg_fail_as(FG_EINVAL, "feature_dim_mismatch", "task '%s' holds features of D = %d "
                      "but scene '%s' has D = %d; show the task on a scene of this feature "
                      "space, or name another task", t->name, t->dim, scene, D);
  fg_grasp_task *list = NULL;
  FG_TRY(gather_tasks(ts, r, out, &list));
  const fg_grasp_field *gf = NULL;
  int rc = fg_voxels_grasp_field(sv->vox, n_threads, &gf, NULL);
  if (rc != 0) {
    free(list);
    return fg_fail_as(rc, "internal_error", "cannot build the grasp field of scene '%s': %s",
                      scene, fg_error_detail());
  }
  const fg_grasp_plan_request pr = {.tasks = list, .n_tasks = out->n_tasks, .retrieve = !t,
                                    .query = r->query, .language_weight = r->language_weight,
                                    .opt = r->opt};
  rc = fg_grasp_plan_run(gf, &pr, &out->plan);
  free(list);
  if (rc == FG_ENOENT)
    return fg_fail_as(rc, "no_matching_task", "no task has demos with features of D = %d "
                      "(scene '%s''s), so none can be retrieved for the query; add a demo on "
                      "a scene of this feature space (POST /v1/tasks/{name}/demos)", D, scene);
  if (rc != 0)
    return fg_fail_as(rc, rc == FG_EINVAL || rc == FG_ERANGE ? "invalid_request"
                      : "internal_error", "the grasp search failed: %s", fg_error_detail());
  return 0;
}

int fg_scene_grasps_plan(fg_scene *s, fg_tasks *ts, fg_grasp_log *log,
                         const fg_scene_grasps_req *r, fg_scene_grasps *out) {
  memset(out, 0, sizeof *out);
  const char *scene = fg_scene_name(s);
  const int threads = r->opt.n_threads;
  fg_scene_voxels sv;
  FG_TRY(fg_scene_voxels_acquire(s, r->query ? r->query->dim : 0, r->query
                                 ? "a query has nothing to score" : "grasps have nothing to "
                                 "match", threads, &sv));
  int rc = plan_on(scene, &sv, ts, r, threads, out);
  if (rc == 0) rc = entries_of(scene, r->request, fg_grasp_log_field_version(sv.vf), out);
  fg_scene_voxels_release(&sv);
  if (rc != 0) {
    fg_scene_grasps_release(out);
    return rc;
  }
  fg_grasp_log_put(log, out->entries, out->plan.result.n);
  const fg_grasp_stats *st = &out->plan.result.stats;
  fg_info("scene %s: %d grasps of task %s in %.2f s (%zu candidates x %d rotations)", scene,
          out->plan.result.n, out->tasks[out->plan.task]->name, st->seconds, st->candidates,
          st->rotations);
  return 0;
}

void fg_scene_grasps_release(fg_scene_grasps *g) {
  fg_grasp_plan_release(&g->plan);
  fg_tasks_list_free(g->tasks, (size_t)g->n_tasks);
  free(g->entries);
  memset(g, 0, sizeof *g);
}

/* The identity of scene s's field now (fg_grasp_log_field_version); *trained 0 when it has
 * none. */
static int field_version_now(fg_scene *s, int n_threads, int *trained, uint64_t *version) {
  *trained = 0;
  fg_field_ref *ref;
  int rc = fg_scene_field_acquire(s, &ref);
  if (rc == FG_EBUSY || rc == FG_ENOMEM)
    return fg_fail_as(rc, "memory_limit", "%s", fg_error_detail());
  if (rc != 0) return fg_fail_as(rc, "internal_error", "%s", fg_error_detail());
  if (!ref) return 0;
  *trained = 1;
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  fg_voxel_grid grid;
  fg_voxels *vox = NULL;
  rc = fg_voxel_grid_init(&grid, info.params.workspace_min, info.params.workspace_max,
                          info.params.voxel_size);
  if (rc == 0) rc = fg_field_voxels(ref, &grid, info.name, n_threads, &vox);
  else rc = fg_fail_as(rc, "internal_error", "cannot build the voxel features of scene '%s': "
                       "%s", info.name, fg_error_detail());
  fg_field_ref_release(ref);
  if (rc != 0) return rc;
  *version = fg_grasp_log_field_version(fg_voxels_features(vox));
  fg_voxels_release(vox);
  return 0;
}

int fg_scene_grasp_current(fg_scene *s, fg_grasp_log *log, const char *id, int n_threads,
                           fg_grasp_entry *out) {
  const char *scene = fg_scene_name(s);
  if (fg_grasp_log_get(log, scene, id, out) != 0)
    return fg_fail_as(FG_ENOENT, "grasp_not_found", "scene '%s' has no grasp '%s' (the newest "
                      "%d grasps of each scene are kept in memory, until a restart); POST "
                      "/v1/scenes/%s/grasps to infer grasps", scene, id, FG_GRASP_LOG_PER_SCENE,
                      scene);
  int trained;
  uint64_t now;
  FG_TRY(field_version_now(s, n_threads, &trained, &now));
  if (!trained || now != out->field_version)
    return fg_fail_as(FG_EINVAL, "grasp_stale", "grasp '%s' was inferred on an earlier field "
                      "of scene '%s', which has changed since (trained again, or its workspace "
                      "changed); POST /v1/scenes/%s/grasps again and execute one of the new ids",
                      id, scene, scene);
  return 0;
}
