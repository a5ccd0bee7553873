/* Grasps over HTTP: POST /v1/scenes/{s}/grasps infers 6-DOF grasps (or placements) of a task
 * (tasks.h) on the scene's current field, named or retrieved by a language query (F3RM);
 * POST /v1/scenes/{s}/grasps/{id}/execute sends one of them to the robot through the
 * /v1/robot/commands path (api_robot.c).
 *
 * Determinism: the same request on the same field with the same seed gives the same body,
 * byte for byte, also after a restart: the search is deterministic (grasp.h), the numbers
 * are printed the same way, the grasp ids are hashes of the field's identity
 * (fg_grasp_log_field_version), the request and the rank, and the elapsed time goes in the
 * X-Took-Ms header, not the body. Both routes run on the offload pool.
 *
 * The search is lib/grasp's on the grasp field the scene's voxels keep (voxcache.h), built
 * by the first demo or search of a field and shared by every later one. */
#include "api.h"
#include "api_decode.h"
#include "state/grasp_log.h"
#include "state/json.h"
#include "metrics/metrics.h"
#include "api_query.h"
#include "robot/robot.h"
#include "state/tasks.h"
#include "state/voxcache.h"

#include "core/clock.h"
#include "core/digest.h"
#include "core/error.h"
#include "core/log.h"
#include "core/pose.h"
#include "core/rng.h"
#include "grasp/grasp.h"
#include "grasp/gripper.h"

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LANG_MASK_SCORE 0.5f /* candidates where the query's heatmap score reaches this */

/* ---------------------------------------------------------------- the request */

static const char *const grasp_keys[] = {"task", "top_k", "seed", "rotations",
                                         "language_weight"};
#define N_GRASP_KEYS (sizeof grasp_keys / sizeof grasp_keys[0])

/* An integer key of body in [lo, hi] into *out (unchanged when absent); answers 400 itself
 * and returns -1 otherwise. */
static int int_key(json_t *body, const char *key, json_int_t lo, json_int_t hi, json_int_t *out,
                   const char *meaning, fg_resp *resp) {
  long long x;
  const int rc = fg_json_int_range(body, key, lo, hi, &x);
  if (rc < 0)
    return fg_resp_error(resp, 400, "invalid_request", "\"%s\" must be an integer from %"
                         JSON_INTEGER_FORMAT " to %" JSON_INTEGER_FORMAT ": %s", key, lo, hi,
                         meaning), -1;
  if (rc == 1) *out = x;
  return 0;
}

int fg_api_parse_grasp(json_t *body, fg_api_grasp_req *r, fg_resp *resp) {
  const char *key = fg_query_unknown_key(body, grasp_keys, N_GRASP_KEYS);
  if (key)
    return fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; a grasp request "
                         "takes \"task\" and/or a query (\"text\" or \"embedding\", "
                         "\"negatives\" or \"negative_embeddings\", \"temperature\"), and "
                         "\"top_k\", \"seed\", \"rotations\", \"language_weight\"", key),
           -1;
  memset(r, 0, sizeof *r);
  fg_grasp_options_default(&r->opt);
  if (fg_json_string(body, "task", &r->task) < 0)
    return fg_resp_error(resp, 400, "invalid_request", "\"task\" must be a task's name"), -1;
  r->has_query = fg_query_present(body);
  json_t *lw = json_object_get(body, "language_weight");
  if (lw && !json_is_boolean(lw))
    return fg_resp_error(resp, 400, "invalid_request", "\"language_weight\" must be true or "
                         "false (default false: the query masks the candidates and picks the "
                         "task; true also weights the cost by its likeness to the query)"), -1;
  r->language_weight = lw && json_is_true(lw);
  if (r->language_weight && !r->has_query)
    return fg_resp_error(resp, 400, "invalid_request", "\"language_weight\" needs a query "
                         "(\"text\" or \"embedding\")"), -1;
  if (!r->task && !r->has_query)
    return fg_resp_error(resp, 400, "invalid_request", "name a task (\"task\": \"mug_handle\") "
                         "or give a query (\"text\": \"a mug\" or \"embedding\": [D numbers]) "
                         "that retrieves one"), -1;
  json_int_t top_k = r->opt.top_k, rotations = r->opt.n_rotations, seed = 0;
  char top_k_means[64], rotations_means[80];
  snprintf(top_k_means, sizeof top_k_means, "the number of grasps returned (default %d)",
           r->opt.top_k);
  snprintf(rotations_means, sizeof rotations_means, "orientations tried at every candidate "
           "voxel (default %d)", r->opt.n_rotations);
  if (int_key(body, "top_k", 1, FG_GRASP_MAX_TOP_K, &top_k, top_k_means, resp) != 0 ||
      int_key(body, "rotations", FG_GRASP_MIN_ROTATIONS, FG_GRASP_MAX_ROTATIONS, &rotations,
              rotations_means, resp) != 0 ||
      int_key(body, "seed", 0, INT64_MAX, &seed, "turns the orientations as a whole (default "
              "0)", resp) != 0)
    return -1;
  r->opt.top_k = (int)top_k;
  r->opt.n_rotations = (int)rotations;
  r->opt.seed = (uint64_t)seed;
  return 0;
}

/* ---------------------------------------------------------------- retrieval */

typedef struct retrieved {
  const fg_task *task; /* a reference */
  double score;
} retrieved;

static int cmp_retrieved(const void *a, const void *b) {
  const retrieved *x = a, *y = b;
  if (x->score != y->score) return x->score > y->score ? -1 : 1;
  return strcmp(x->task->name, y->task->name);
}

/* F3RM's retrieval: every task with demos of the scene's D, scored by the cosine of its
 * demos' mean query-point feature with the query, best first, into a malloc'd array of n
 * (each with a reference; free with retrieved_free). 0, or FG_ENOMEM. */
static int retrieve(fg_tasks *ts, const fg_query *q, retrieved **out, size_t *n) {
  *out = NULL;
  *n = 0;
  const fg_task **list = NULL;
  size_t nl = 0;
  FG_TRY(fg_tasks_list(ts, &list, &nl));
  retrieved *r = malloc((nl ? nl : 1) * sizeof *r);
  if (!r) {
    fg_tasks_list_free(list, nl);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  size_t k = 0;
  for (size_t i = 0; i < nl; i++) {
    const fg_task *t = list[i];
    if (t->n_demos == 0 || t->dim != q->dim || !t->feature) {
      fg_task_unref(t);
      continue;
    }
    double s = 0;
    for (int d = 0; d < q->dim; d++) s += (double)t->feature[d] * q->q[d];
    r[k].task = t;
    r[k++].score = s;
  }
  free(list); /* the references moved to r or were dropped */
  qsort(r, k, sizeof *r, cmp_retrieved);
  *out = r;
  *n = k;
  return 0;
}

static void retrieved_free(retrieved *r, size_t n) {
  for (size_t i = 0; r && i < n; i++) fg_task_unref(r[i].task);
  free(r);
}

/* ---------------------------------------------------------------- ids and replies */

/* "g" + 16 hex digits: the field's identity, the request and the rank, mixed. */
static void grasp_id(uint64_t version, uint64_t request, int rank, char out[24]) {
  uint64_t h = fg_splitmix64(version ^ fg_splitmix64(request ^ fg_splitmix64((uint64_t)rank)));
  snprintf(out, 24, "g%016" PRIx64, h);
}

/* The grasp's JSON; its pre_grasp is the pose backed off by approach_m along the gripper's
 * own -z (the approach direction is +z). */
static json_t *grasp_json(const fg_grasp_entry *e, const fg_grasp_result_pose *p,
                          double approach_m, const fg_task *t) {
  double T_gripper_pre[16], T_world_pre[16];
  fg_pose_identity(T_gripper_pre);
  T_gripper_pre[11] = -approach_m;
  fg_pose_compose(p->T_world_gripper, T_gripper_pre, T_world_pre);
  return json_pack("{s:s, s:o, s:o, s:f, s:s, s:s, s:f, s:b}", "id", e->id, "pose",
                   fg_json_pose(p->T_world_gripper), "pre_grasp", fg_json_pose(T_world_pre),
                   "score", p->score, "task", t->name, "kind", fg_task_kind_name(t->kind),
                   "width", e->width_m, "collision_free", p->collision_free);
}

/* The gripper the grasps were checked with: the [gripper] model's boxes (lib/grasp/gripper.h:
 * the palm, then per finger its pad, holder and link) at the grasps' width, in the gripper
 * frame, each with the part it belongs to, so that a client draws exactly what the collision
 * check saw. */
static json_t *gripper_json(fg_gripper_model model, double width_m) {
  fg_gripper_box b[FG_GRIPPER_N_BOXES];
  if (fg_gripper_boxes(model, width_m, b) != 0) return json_null();
  json_t *boxes = json_array();
  for (int i = 0; i < FG_GRIPPER_N_BOXES; i++)
    json_array_append_new(boxes, json_pack("{s:s, s:s, s:b, s:o, s:o}", "name",
                                           fg_gripper_box_name(i), "part",
                                           fg_gripper_part_name(b[i].part), "pad", b[i].pad,
                                           "centre", fg_json_from_vec(b[i].centre_m, 3),
                                           "half_size", fg_json_from_vec(b[i].half_m, 3)));
  return json_pack("{s:s, s:f, s:o}", "model", fg_gripper_spec_get(model)->name, "width",
                   width_m, "boxes", boxes);
}

/* ---------------------------------------------------------------- POST .../grasps */

int fg_api_scene_grasps(fg_req *req, fg_resp *resp) {
  const double t0 = fg_mono_s();
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = fg_api_body_object(req, resp);
  fg_field_ref *ref = NULL;
  fg_voxels *vox = NULL;
  fg_query q = {0};
  const fg_task *task = NULL;
  retrieved *ret = NULL;
  size_t n_ret = 0;
  float *scores = NULL;
  uint8_t *mask = NULL;
  fg_grasp_result res = {0};
  fg_grasp_entry *entries = NULL;
  char *canon = NULL;
  if (!body) goto out;
  fg_api_grasp_req r;
  if (fg_api_parse_grasp(body, &r, resp) != 0) goto out;
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  if (r.task) {
    task = fg_tasks_get(req->app->tasks, r.task);
    if (!task) {
      fg_resp_error(resp, 404, "task_not_found", "no task named '%s'; GET /v1/tasks lists "
                    "them, POST /v1/tasks/%s/demos with a demo creates it", r.task, r.task);
      goto out;
    }
    if (task->n_demos == 0) {
      fg_resp_error(resp, 409, "task_empty", "task '%s' has no demo, so there is nothing to "
                    "look for; POST /v1/tasks/%s/demos to add one", r.task, r.task);
      goto out;
    }
  }
  if (r.has_query && fg_query_parse(req, resp, body, info.field_feature_dim
                                    ? info.field_feature_dim : info.feature_dim, &q) != 0)
    goto out;
  fg_voxel_grid grid;
  int rc = fg_voxel_grid_init(&grid, info.params.workspace_min, info.params.workspace_max,
                              info.params.voxel_size);
  if (rc != 0) {
    fg_resp_error(resp, rc == FG_ERANGE ? 400 : 500, rc == FG_ERANGE ? "grid_too_large"
                  : "internal_error", "scene '%s': %s", info.name, fg_error_detail());
    goto out;
  }
  ref = fg_api_scene_field(s, &info, resp);
  if (!ref) goto out;
  const fg_field *field = fg_field_ref_field(ref);
  const int D = field->cfg.feature_dim;
  if (r.has_query && fg_api_query_fits(field, &q, info.name, resp) != 0) goto out;
  if (D == 0) {
    fg_resp_error(resp, 409, "no_features", "scene '%s' was trained on colour only, without "
                  "features, so grasps have nothing to match; upload frames with "
                  "\"features\" (.npy) or configure [clip], then train it again", info.name);
    goto out;
  }
  if (task && task->dim != D) {
    fg_resp_error(resp, 409, "feature_dim_mismatch", "task '%s' holds features of D = %d but "
                  "scene '%s' has D = %d; show the task on a scene of this feature space, or "
                  "name another task", task->name, task->dim, info.name, D);
    goto out;
  }
  if (!task) { /* F3RM: the task whose demos look most like the query */
    if (retrieve(req->app->tasks, &q, &ret, &n_ret) != 0) {
      fg_resp_error(resp, 500, "internal_error", "%s", fg_error_detail());
      goto out;
    }
    if (n_ret == 0) {
      fg_resp_error(resp, 409, "no_matching_task", "no task has demos with features of D = "
                    "%d (scene '%s''s), so none can be retrieved for the query; add a demo "
                    "on a scene of this feature space (POST /v1/tasks/{name}/demos)", D,
                    info.name);
      goto out;
    }
    task = ret[0].task;
    ret[0].task = NULL; /* the reference moves to task */
  }
  const int threads = fg_conf_threads(req->conf);
  if (fg_api_scene_voxels(ref, &grid, info.name, threads, &vox, resp) != 0) goto out;
  /* The voxels do not refer to the field: let a new training's field replace it meanwhile. */
  fg_field_ref_release(ref);
  ref = NULL;
  const fg_voxel_features *vf = fg_voxels_features(vox);
  const fg_grasp_field *gf = NULL;
  rc = fg_voxels_grasp_field(vox, threads, &gf, NULL);
  if (rc != 0) {
    fg_resp_error(resp, 500, "internal_error", "cannot build the grasp field of scene '%s': %s",
                  info.name, fg_error_detail());
    goto out;
  }
  fg_grasp_options *o = &r.opt;

  /* The language mask: candidates only where the query's heatmap score reaches 0.5, scored
   * at the search's own candidate threshold. */
  if (r.has_query) {
    const size_t n_vox = fg_voxel_grid_count(&grid);
    scores = malloc(n_vox * sizeof *scores);
    mask = malloc(n_vox);
    if (!scores || !mask ||
        fg_voxel_features_score(vf, &q, o->candidate_alpha, scores, threads) != 0) {
      fg_resp_error(resp, 500, "internal_error", "cannot score the query: %s",
                    scores && mask ? fg_error_detail() : "out of memory");
      goto out;
    }
    for (size_t i = 0; i < n_vox; i++) mask[i] = scores[i] >= LANG_MASK_SCORE;
  }
  o->gripper = req->conf->gripper_model;
  const double stroke = fg_gripper_spec_get(o->gripper)->stroke_m;
  o->width_m = task->width_m < stroke ? task->width_m : stroke;
  o->candidate_mask = mask;
  o->n_threads = threads;
  /* only poses the robot may be sent to, and never through the table */
  fg_motion_limits lim;
  double approach_m, retreat_m, speed_mps; /* the robot's defaults: only the retreat counts */
  fg_robot_limits_get(req->app->robot, &lim);
  fg_robot_path_defaults(req->app->robot, &approach_m, &retreat_m, &speed_mps);
  o->approach_m = task->approach_m; /* the pre_grasp this task returns */
  o->retreat_m = task->kind == FG_TASK_PLACE ? 0 : retreat_m;
  o->limits = &lim;
  o->floor_solid = 1;
  const fg_grasp_target target = {.n_points = task->n_points, .dim = D,
                                   .p_gripper = task->p_gripper, .Z = task->Z,
                                   .q = r.language_weight ? q.q : NULL};
  rc = fg_grasp_search(gf, &target, o, &res);
  if (rc != 0) {
    fg_resp_error(resp, rc == FG_EINVAL || rc == FG_ERANGE ? 400 : 500,
                  rc == FG_EINVAL || rc == FG_ERANGE ? "invalid_request" : "internal_error",
                  "the grasp search failed: %s", fg_error_detail());
    goto out;
  }

  /* Ids: the field's identity, the request (its keys sorted) and the rank. */
  const uint64_t version = fg_grasp_log_field_version(vf);
  canon = json_dumps(body, JSON_COMPACT | JSON_SORT_KEYS);
  uint64_t rh = 0;
  if (canon) {
    const fg_span parts[] = {{info.name, strlen(info.name) + 1}, {canon, strlen(canon)}};
    uint8_t d[FG_SHA256_BYTES];
    fg_sha256(parts, 2, d);
    memcpy(&rh, d, sizeof rh);
  }
  entries = calloc((size_t)(res.n ? res.n : 1), sizeof *entries);
  json_t *grasps = json_array();
  if (!entries || !grasps || !canon) {
    json_decref(grasps);
    fg_resp_error(resp, 500, "internal_error", "out of memory");
    goto out;
  }
  for (int i = 0; i < res.n; i++) {
    fg_grasp_entry *e = &entries[i];
    grasp_id(version, rh, i, e->id);
    snprintf(e->scene, sizeof e->scene, "%s", info.name);
    snprintf(e->task, sizeof e->task, "%s", task->name);
    e->field_version = version;
    memcpy(e->T_world_gripper, res.poses[i].T_world_gripper, sizeof e->T_world_gripper);
    e->width_m = o->width_m;
    e->approach_m = task->approach_m;
    e->place = task->kind == FG_TASK_PLACE;
    json_array_append_new(grasps, grasp_json(e, &res.poses[i], task->approach_m, task));
  }
  fg_grasp_log_put(req->app->grasps, entries, res.n);
  const fg_grasp_stats *st = &res.stats;
  json_t *reply = json_pack("{s:o, s:s, s:{s:I, s:i, s:I, s:I, s:i, s:I, s:I}}", "grasps", grasps,
                            "task", task->name, "search", "candidates",
                            (json_int_t)st->candidates, "rotations", st->rotations,
                            "poses_scored", (json_int_t)st->poses_scored, "poses_optimised",
                            (json_int_t)st->poses_optimised, "iterations", st->iterations,
                            "evaluations", (json_int_t)st->evaluations, "rejected_limits",
                            (json_int_t)st->rejected_limits);
  if (reply && ret) {
    json_t *a = json_array();
    /* ret[0]'s reference moved to task: it is the first entry */
    json_array_append_new(a, json_pack("{s:s, s:f}", "task", task->name, "score", ret[0].score));
    for (size_t i = 1; i < n_ret; i++)
      json_array_append_new(a, json_pack("{s:s, s:f}", "task", ret[i].task->name, "score",
                                         ret[i].score));
    json_object_set_new(reply, "retrieval", a);
  }
  if (reply) json_object_set_new(reply, "gripper", gripper_json(o->gripper, o->width_m));
  if (reply && res.n == 0) json_object_set_new(reply, "reason", json_string(res.reason));
  snprintf(resp->header, sizeof resp->header, "X-Took-Ms: %.1f", (fg_mono_s() - t0) * 1e3);
  fg_resp_json(resp, 200, reply);
  fg_info("scene %s: %d grasps of task %s in %.2f s (%zu candidates x %d rotations)",
          info.name, res.n, task->name, st->seconds, st->candidates, st->rotations);
out:
  free(canon);
  free(entries);
  fg_grasp_result_release(&res);
  free(mask);
  free(scores);
  retrieved_free(ret, n_ret);
  fg_task_unref(task);
  fg_query_release(&q);
  fg_voxels_release(vox);
  fg_field_ref_release(ref);
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}

/* ---------------------------------------------------------------- POST .../execute */

int fg_api_grasp_execute(fg_req *req, fg_resp *resp) {
  if (fg_api_idem_replay(req, resp)) return 0;
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  const char *id = req->params[1];
  json_t *body = req->body_len ? fg_api_body_object(req, resp) : json_object();
  fg_field_ref *ref = NULL;
  fg_voxels *vox = NULL;
  if (!body) goto out;
  fg_robot_request r;
  memset(&r, 0, sizeof r);
  r.wait = 1;
  const char *key;
  json_t *v;
  json_object_foreach(body, key, v) {
    int *flag = strcmp(key, "dry_run") == 0 ? &r.dry_run : strcmp(key, "wait") == 0 ? &r.wait
                                                                                   : NULL;
    if (!flag) {
      fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; execute takes "
                    "\"dry_run\" and \"wait\"", key);
      goto out;
    }
    if (!json_is_boolean(v)) {
      fg_resp_error(resp, 400, "invalid_request", "\"%s\" must be true or false", key);
      goto out;
    }
    *flag = json_is_true(v);
  }
  fg_grasp_entry e;
  if (fg_grasp_log_get(req->app->grasps, fg_scene_name(s), id, &e) != 0) {
    fg_resp_error(resp, 404, "grasp_not_found", "scene '%s' has no grasp '%s' (the newest %d "
                  "grasps of each scene are kept in memory, until a restart); POST "
                  "/v1/scenes/%s/grasps to infer grasps", fg_scene_name(s), id,
                  FG_GRASP_LOG_PER_SCENE, fg_scene_name(s));
    goto out;
  }
  /* Stale when the scene's field is not the one the grasp came from any more. */
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  int acq = fg_scene_field_acquire(s, &ref);
  if (acq != 0) {
    fg_api_field_error(resp, acq);
    goto out;
  }
  uint64_t now = 0;
  if (ref) {
    fg_voxel_grid grid;
    int rc = fg_voxel_grid_init(&grid, info.params.workspace_min, info.params.workspace_max,
                                info.params.voxel_size);
    if (rc == 0)
      rc = fg_voxcache_get(fg_field_ref_voxcache(ref), fg_field_ref_field(ref), &grid,
                           fg_conf_threads(req->conf), &vox, NULL);
    if (rc != 0) {
      fg_resp_error(resp, 500, "internal_error", "cannot build the voxel features of scene "
                    "'%s': %s", info.name, fg_error_detail());
      goto out;
    }
    fg_field_ref_release(ref);
    ref = NULL;
    now = fg_grasp_log_field_version(fg_voxels_features(vox));
  }
  if (!ref && !vox) now = e.field_version + 1; /* untrained now: differs */
  if (now != e.field_version) {
    fg_resp_error(resp, 409, "grasp_stale", "grasp '%s' was inferred on an earlier field of "
                  "scene '%s', which has changed since (trained again, or its workspace "
                  "changed); POST /v1/scenes/%s/grasps again and execute one of the new ids",
                  id, info.name, info.name);
    goto out;
  }
  r.command = e.place ? FG_ROBOT_PLACE : FG_ROBOT_PICK;
  r.has_pose = 1;
  fg_pose_to_quat(e.T_world_gripper, r.p_world_m, r.q_wxyz);
  r.has_width = 1;
  r.width_m = e.width_m;
  r.has_approach = 1; /* the robot comes in from the pre_grasp the search returned */
  r.approach_m = e.approach_m;
  json_decref(body);
  body = NULL;
  fg_voxels_release(vox);
  vox = NULL;
  fg_scene_unref(s);
  return fg_api_robot_run(req, resp, &r);
out:
  fg_voxels_release(vox);
  fg_field_ref_release(ref);
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}
