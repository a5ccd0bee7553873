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
 * The plan is state/scene_grasps.h's (lib/grasp's plan on the scene's voxels, the ids, the
 * grasp log); these handlers decode, call it once and write its view. */
#include "api.h"
#include "api_decode.h"
#include "api_query.h"
#include "robot/robot.h"
#include "state/json.h"
#include "state/scene_grasps.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/pose.h"
#include "grasp/gripper.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

/* ---------------------------------------------------------------- the reply */

/* A grasp's JSON: its entry e (id, width) and the plan's pose i. */
static json_t *grasp_json(const fg_grasp_entry *e, const fg_grasp_plan *p, int i,
                          const fg_task *t) {
  const fg_grasp_result_pose *pose = &p->result.poses[i];
  return json_pack("{s:s, s:o, s:o, s:f, s:s, s:s, s:f, s:b}", "id", e->id, "pose",
                   fg_json_pose(pose->T_world_gripper), "pre_grasp",
                   fg_json_pose(p->T_world_pre[i]), "score", pose->score, "task", t->name,
                   "kind", fg_task_kind_name(t->kind), "width", e->width_m, "collision_free",
                   pose->collision_free);
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

/* The reply to planned grasps g. */
static json_t *grasps_json(const fg_scene_grasps *g, fg_gripper_model gripper) {
  const fg_grasp_plan *p = &g->plan;
  const fg_task *t = g->tasks[p->task];
  json_t *grasps = json_array();
  for (int i = 0; i < p->result.n; i++)
    json_array_append_new(grasps, grasp_json(&g->entries[i], p, i, t));
  const fg_grasp_stats *st = &p->result.stats;
  json_t *reply = json_pack(
    "{s:o, s:s, s:{s:I, s:i, s:I, s:I, s:i, s:I, s:I, s:I, s:I}}", "grasps", grasps, "task",
    t->name, "search", "candidates", (json_int_t)st->candidates, "rotations", st->rotations,
    "poses_scored", (json_int_t)st->poses_scored, "poses_optimised",
    (json_int_t)st->poses_optimised, "iterations", st->iterations, "evaluations",
    (json_int_t)st->evaluations, "collision_checks", (json_int_t)st->collision_checks,
    "rejected_collisions", (json_int_t)st->rejected_collisions, "rejected_limits",
    (json_int_t)st->rejected_limits);
  if (!reply) return NULL;
  if (p->retrieval) {
    json_t *a = json_array();
    for (int i = 0; i < p->n_retrieval; i++)
      json_array_append_new(a, json_pack("{s:s, s:f}", "task",
                                         g->tasks[p->retrieval[i].task]->name, "score",
                                         p->retrieval[i].score));
    json_object_set_new(reply, "retrieval", a);
  }
  json_object_set_new(reply, "gripper", gripper_json(gripper, p->width_m));
  if (p->result.n == 0) json_object_set_new(reply, "reason", json_string(p->result.reason));
  return reply;
}

/* The search's options that are not the request's: the gripper, and only poses the robot may
 * be sent to (the robot's limits, its lift after a pick), never through the table. */
static void robot_options(fg_req *req, fg_motion_limits *lim, fg_grasp_options *o) {
  double approach_m, retreat_m, speed_mps; /* the robot's defaults: only the retreat counts */
  fg_robot_limits_get(req->app->robot, lim);
  fg_robot_path_defaults(req->app->robot, &approach_m, &retreat_m, &speed_mps);
  o->gripper = req->conf->gripper_model;
  o->n_threads = fg_conf_threads(req->conf);
  o->limits = lim;
  o->retreat_m = retreat_m;
  o->floor_solid = 1;
}

int fg_api_scene_grasps(fg_req *req, fg_resp *resp) {
  const double t0 = fg_mono_s();
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = fg_api_body_object(req, resp);
  fg_query q = {0};
  fg_scene_grasps g = {0};
  fg_api_grasp_req r;
  fg_scene_grasps_req sr = {0};
  fg_motion_limits lim;
  if (!body || fg_api_parse_grasp(body, &r, resp) != 0) goto out;
  int rc = r.task ? fg_tasks_get_demonstrated(req->app->tasks, r.task, &sr.task) : 0;
  if (rc != 0) {
    fg_api_fail(resp, rc);
    goto out;
  }
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  if (r.has_query && fg_query_parse(req, resp, body, info.field_feature_dim
                                    ? info.field_feature_dim : info.feature_dim, &q) != 0)
    goto out;
  sr.query = r.has_query ? &q : NULL;
  sr.language_weight = r.language_weight;
  sr.opt = r.opt;
  robot_options(req, &lim, &sr.opt);
  char *canon = json_dumps(body, JSON_COMPACT | JSON_SORT_KEYS);
  sr.request = canon;
  rc = canon ? fg_scene_grasps_plan(s, req->app->tasks, req->app->grasps, &sr, &g)
             : fg_fail(FG_ENOMEM, "out of memory");
  free(canon);
  json_t *reply = rc == 0 ? grasps_json(&g, sr.opt.gripper) : NULL;
  if (rc != 0 || !reply) {
    fg_api_fail(resp, rc ? rc : fg_fail(FG_ENOMEM, "out of memory"));
    goto out;
  }
  snprintf(resp->header, sizeof resp->header, "X-Took-Ms: %.1f", (fg_mono_s() - t0) * 1e3);
  fg_resp_json(resp, 200, reply);
out:
  fg_scene_grasps_release(&g);
  fg_task_unref(sr.task);
  fg_query_release(&q);
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}

/* ---------------------------------------------------------------- POST .../execute */

/* Reads execute's body (dry_run, wait) into *r; answers 400 itself and returns -1. */
static int parse_execute(json_t *body, fg_robot_request *r, fg_resp *resp) {
  memset(r, 0, sizeof *r);
  r->wait = 1;
  const char *key;
  json_t *v;
  json_object_foreach(body, key, v) {
    int *flag = strcmp(key, "dry_run") == 0 ? &r->dry_run : strcmp(key, "wait") == 0 ? &r->wait
                                                                                     : NULL;
    if (!flag)
      return fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; execute takes "
                           "\"dry_run\" and \"wait\"", key), -1;
    if (!json_is_boolean(v))
      return fg_resp_error(resp, 400, "invalid_request", "\"%s\" must be true or false", key),
             -1;
    *flag = json_is_true(v);
  }
  return 0;
}

int fg_api_grasp_execute(fg_req *req, fg_resp *resp) {
  if (fg_api_idem_replay(req, resp)) return 0;
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = req->body_len ? fg_api_body_object(req, resp) : json_object();
  fg_robot_request r;
  int parsed = body && parse_execute(body, &r, resp) == 0;
  json_decref(body);
  fg_grasp_entry e;
  const int rc = parsed ? fg_scene_grasp_current(s, req->app->grasps, req->params[1],
                                                 fg_conf_threads(req->conf), &e)
                        : 0;
  fg_scene_unref(s);
  if (!parsed) return 0;
  if (rc != 0) return fg_api_fail(resp, rc);
  r.command = e.place ? FG_ROBOT_PLACE : FG_ROBOT_PICK;
  r.has_pose = 1;
  fg_pose_to_quat(e.T_world_gripper, r.p_world_m, r.q_wxyz);
  r.has_width = 1;
  r.width_m = e.width_m;
  r.has_approach = 1; /* the robot comes in from the pre_grasp the search returned */
  r.approach_m = e.approach_m;
  return fg_api_robot_run(req, resp, &r);
}
