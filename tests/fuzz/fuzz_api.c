/* Fuzz target for the request decoders of every endpoint (daemon/api/api_decode.h). The input is
 * a request body: it goes through the body parser with its limits (fg_json_parse), and when
 * that yields an object (what the handlers pass on, via fg_api_body_object) it is fed to
 * every decoder in turn, as scene creation, training, heatmap, geometry and points (its
 * string members as the query string), render, grasp, robot command, gripper action, demo (for a new task
 * and for one with demos), upload meta and text embedding body. Each decoder either
 * succeeds, and then what it decoded is finite and within the ranges the handlers rely on,
 * or fails with FG_EINVAL or a 4xx answer with a message. */
#include "api/api_decode.h"
#include "state/json.h"

#include "core/error.h"
#include "grasp/gripper.h"
#include "query/voxfeat.h"

#include <jansson.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static const fg_conf *conf(void) {
  static fg_conf *c;
  if (!c) c = fg_conf_defaults();
  if (!c) abort();
  return c;
}

static void finite_or_die(const double *v, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(v[i])) abort();
}

/* A decoder that answered: a 4xx with a body (the error JSON) when it failed, nothing when
 * it succeeded. Frees the answer. */
static void check_resp(fg_resp *resp, int rc) {
  if (rc != 0 && (rc != -1 || resp->status < 400 || resp->status > 499 || !resp->body ||
                  resp->len == 0))
    abort();
  if (rc == 0 && resp->body) abort();
  free(resp->body);
  memset(resp, 0, sizeof *resp);
}

static void scene_and_train(json_t *body, fg_scene_params *params) {
  fg_resp resp = {0};
  fg_scene_params p;
  int rc = fg_api_parse_scene_params(body, &p, &resp);
  check_resp(&resp, rc);
  if (rc == 0) {
    finite_or_die(p.workspace_min, 3);
    finite_or_die(p.workspace_max, 3);
    finite_or_die(p.background, 3);
    for (int k = 0; k < 3; k++)
      if (!(p.workspace_min[k] < p.workspace_max[k])) abort();
    if (!(p.voxel_size > 0) || !isfinite(p.voxel_size)) abort();
    *params = p; /* the scene the later decoders check against */
  }
  fg_job_params jp;
  rc = fg_api_parse_train(body, conf(), &jp, &resp);
  check_resp(&resp, rc);
  if (rc == 0 && (jp.steps < 1 || jp.steps > FG_TRAIN_MAX_STEPS || jp.holdout_every < 0 ||
                  !(jp.max_seconds >= 0) || !isfinite(jp.depth_weight) ||
                  !isfinite(jp.distortion_weight) || jp.depth_weight < 0 ||
                  jp.distortion_weight < 0))
    abort();
}

static void heatmap_geometry(json_t *body, const fg_scene_params *params) {
  fg_resp resp = {0};
  fg_api_heatmap_req h;
  int rc = fg_api_parse_heatmap(body, params, &h, &resp);
  if (rc == 0 && (!(h.alpha_threshold >= FG_QUERY_ALPHA_FLOOR && h.alpha_threshold <= 1) ||
                  isnan(h.min_score) || h.min_score == INFINITY))
    abort();
  check_resp(&resp, rc);

  /* the body's string members as the query string */
  fg_api_geometry_query q = {0};
  const char *key;
  json_t *v;
  json_object_foreach(body, key, v) {
    const char *s = json_is_string(v) ? json_string_value(v) : "";
    if (strcmp(key, "kind") == 0) q.kind = s;
    else if (strcmp(key, "threshold") == 0) q.threshold = s;
    else if (strcmp(key, "alpha") == 0) q.alpha = s;
    else if (strcmp(key, "voxel_size") == 0) q.voxel_size = s;
    else if (!q.unknown && json_is_string(v)) q.unknown = key;
  }
  fg_api_geometry_req g;
  rc = fg_api_parse_geometry(&q, params, &g, &resp);
  if (rc == 0 && (!(g.threshold > 0 && g.threshold < 1) || !(g.voxel_size > 0) ||
                  !isfinite(g.voxel_size)))
    abort();
  check_resp(&resp, rc);

  fg_api_points_query pq = {0};
  json_object_foreach(body, key, v) {
    const char *s = json_is_string(v) ? json_string_value(v) : "";
    if (strcmp(key, "alpha") == 0) pq.alpha = s;
    else if (strcmp(key, "voxel_size") == 0) pq.voxel_size = s;
    else if (strcmp(key, "max_points") == 0) pq.max_points = s;
    else if (!pq.unknown && json_is_string(v)) pq.unknown = key;
  }
  fg_api_points_req p;
  rc = fg_api_parse_points(&pq, params, &p, &resp);
  if (rc == 0 && (!(p.alpha > 0 && p.alpha < 1) || !(p.voxel_size > 0) ||
                  !isfinite(p.voxel_size) || p.max_points < 1 || p.max_points > FG_API_POINTS_MAX))
    abort();
  check_resp(&resp, rc);
}

static void render_grasp(json_t *body) {
  fg_resp resp = {0};
  fg_api_render_req r;
  int rc = fg_api_parse_render(body, &r, &resp);
  if (rc == 0) {
    finite_or_die(r.T_world_cam, 16);
    const double cam[4] = {r.cam.fl_x, r.cam.fl_y, r.cam.cx, r.cam.cy};
    finite_or_die(cam, 4);
    if (r.cam.w < 1 || r.cam.h < 1 || r.cam.w > FG_API_RENDER_MAX_SIDE ||
        r.cam.h > FG_API_RENDER_MAX_SIDE || !(r.cam.fl_x > 0) || !(r.cam.fl_y > 0) ||
        r.depth + r.normal + r.heatmap > 1)
      abort();
  }
  check_resp(&resp, rc);

  fg_api_grasp_req g;
  rc = fg_api_parse_grasp(body, &g, &resp);
  if (rc == 0 && (g.opt.top_k < 1 || g.opt.top_k > FG_GRASP_MAX_TOP_K ||
                  g.opt.n_rotations < FG_GRASP_MIN_ROTATIONS ||
                  g.opt.n_rotations > FG_GRASP_MAX_ROTATIONS || (!g.task && !g.has_query) ||
                  (g.language_weight && !g.has_query)))
    abort();
  check_resp(&resp, rc);
}

static void robot(json_t *body) {
  /* the key lists of POST /v1/robot/commands and POST /v1/gripper/{action} */
  static const char *const command_keys[] = {"command", "pose",    "width", "force",
                                             "speed",   "dry_run", "wait",  NULL};
  static const char *const gripper_keys[] = {"width", "speed", "force", "dry_run", NULL};
  const char *const *lists[] = {command_keys, gripper_keys};
  for (int l = 0; l < 2; l++) {
    fg_resp resp = {0};
    fg_robot_request r;
    int rc = fg_api_parse_robot_request(body, lists[l], &r, &resp);
    if (rc == 0) {
      finite_or_die(r.p_world_m, 3);
      finite_or_die(r.q_wxyz, 4);
      const double n[3] = {r.width_m, r.force_n, r.speed_mps};
      finite_or_die(n, 3);
      if (r.command < 0 || r.command > FG_ROBOT_MOVE || (l == 1 && (r.command || r.has_pose)))
        abort();
    }
    check_resp(&resp, rc);
  }
}

static void demo(json_t *body) {
  /* a new task (defaults: the box) and one with demos of a Gaussian (its query points are
   * the defaults) */
  fg_task with_demos;
  memset(&with_demos, 0, sizeof with_demos);
  with_demos.n_demos = 1;
  with_demos.n_points = 16;
  with_demos.qp_std_m = 0.02;
  with_demos.qp_mean_m[2] = 0.05;
  const fg_task *tasks[] = {NULL, &with_demos};
  const double stroke = fg_gripper_spec_get(conf()->gripper_model)->stroke_m;
  for (int i = 0; i < 2; i++) {
    fg_resp resp = {0};
    fg_task_demo_new d;
    memset(&d, 0, sizeof d);
    int rc = fg_api_parse_demo(body, conf(), tasks[i], &d, &resp);
    if (rc == 0) {
      finite_or_die(d.T_world_gripper, 16);
      finite_or_die(d.qp_mean_m, 3);
      finite_or_die(d.qp_size_m, 3);
      if (!d.scene || !(d.width_m > 0 && d.width_m <= stroke + 1e-12) ||
          !(d.approach_m >= 0 && d.approach_m <= 1) || d.n_points < 1 ||
          d.n_points > FG_GRASP_MAX_QUERY_POINTS)
        abort();
      if (d.qp_layout == FG_GRASP_QP_BOX) {
        for (int a = 0; a < 3; a++)
          if (!(d.qp_size_m[a] > 0 && d.qp_size_m[a] <= 1)) abort();
      } else if (d.qp_layout != FG_GRASP_QP_GAUSSIAN || !(d.qp_std_m > 0 && d.qp_std_m <= 1)) {
        abort();
      }
    }
    check_resp(&resp, rc);
  }
}

static void frame_meta(json_t *body) {
  fg_resp resp = {0};
  double T[16];
  fg_transforms_frame cam;
  int rc = fg_api_parse_meta(body, T, &cam, &resp);
  if (rc == 0) finite_or_die(T, 16);
  check_resp(&resp, rc);
  for (int has_depth = 0; has_depth <= 1; has_depth++) {
    double scale = 0.001;
    rc = fg_api_parse_depth_scale(body, has_depth, "upload", &scale, &resp);
    if (rc == 0 && !(scale > 0 && isfinite(scale))) abort();
    check_resp(&resp, rc);
  }
}

static void embed(json_t *body) {
  fg_resp resp = {0};
  fg_api_embed_text_req r;
  int rc = fg_api_parse_embed_text(body, &r, &resp);
  if (rc == 0) {
    if (r.n < 1 || r.n > FG_CLIP_MAX_TEXTS) abort();
    for (int i = 0; i < r.n; i++)
      if (!r.texts[i]) abort();
  }
  check_resp(&resp, rc);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  char err[256];
  json_t *body = fg_json_parse(data, size, err, sizeof err);
  if (!body) return 0;
  if (json_is_object(body)) {
    fg_scene_params params = {.workspace_min = {0.10, -0.45, 0.005},
                              .workspace_max = {0.80, 0.45, 0.35},
                              .voxel_size = 0.01,
                              .background = {1, 1, 1}};
    scene_and_train(body, &params);
    heatmap_geometry(body, &params);
    render_grasp(body);
    robot(body);
    demo(body);
    frame_meta(body);
    embed(body);
  }
  json_decref(body);
  return 0;
}
