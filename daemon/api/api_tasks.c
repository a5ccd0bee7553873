/* The demonstration library over HTTP (tasks.h): GET /v1/tasks, GET and DELETE
 * /v1/tasks/{t}, POST /v1/tasks/{t}/demos (the first demo creates the task) and DELETE
 * /v1/tasks/{t}/demos/{i}. A demo samples the scene's current field at the task's query
 * points placed by the demo's gripper pose (F3RM's z) and keeps the sample, not the scene. */
#include "api.h"
#include "api_decode.h"
#include "state/json.h"
#include "state/tasks.h"
#include "state/scene_grasps.h"

#include "core/error.h"
#include "core/log.h"
#include "grasp/grasp.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- views */

static json_t *demo_json(const fg_task_demo *d) {
  return json_pack("{s:i, s:s, s:o, s:s, s:f, s:f, s:o}", "id", d->id, "scene", d->scene,
                   "pose", fg_json_pose(d->T_world_gripper), "kind",
                   fg_task_kind_name(d->kind), "width", d->width_m, "approach", d->approach_m,
                   "created", fg_json_time_ms(d->created_ms));
}

/* The task object of the API; with_demos adds the demos. */
static json_t *task_json(const fg_task *t, int with_demos) {
  const int has = t->n_demos > 0;
  json_t *o = json_pack(
      "{s:s, s:o, s:o, s:o, s:o, s:o, s:i, s:o}", "name", t->name, "kind",
      has ? json_string(fg_task_kind_name(t->kind)) : json_null(), "dim",
      has ? json_integer(t->dim) : json_null(), "query_points", fg_task_query_points_json(t),
      "width", has ? json_real(t->width_m) : json_null(), "approach",
      has ? json_real(t->approach_m) : json_null(), "n_demos", t->n_demos, "created",
      fg_json_time_ms(t->created_ms));
  if (o && with_demos) {
    json_t *a = json_array();
    for (int i = 0; a && i < t->n_demos; i++) json_array_append_new(a, demo_json(&t->demos[i]));
    json_object_set_new(o, "demos", a);
  }
  return o;
}

/* The task named by the first path parameter with a reference, or NULL after answering 404. */
static const fg_task *task_param(fg_req *req, fg_resp *resp) {
  const fg_task *t = fg_tasks_get(req->app->tasks, req->params[0]);
  if (!t)
    fg_resp_error(resp, 404, "task_not_found", "no task named '%s'; GET /v1/tasks lists them, "
                  "POST /v1/tasks/{name}/demos with a first demo creates one", req->params[0]);
  return t;
}

/* ---------------------------------------------------------------- reading and deleting */

int fg_api_tasks_list(fg_req *req, fg_resp *resp) {
  const fg_task **list = NULL;
  size_t n = 0;
  if (fg_tasks_list(req->app->tasks, &list, &n) != 0)
    return fg_resp_error(resp, 500, "internal_error", "%s", fg_error_detail());
  json_t *a = json_array();
  for (size_t i = 0; a && i < n; i++) json_array_append_new(a, task_json(list[i], 0));
  fg_tasks_list_free(list, n);
  fg_resp_json(resp, 200, json_pack("{s:o}", "tasks", a));
  return 0;
}

int fg_api_task_get(fg_req *req, fg_resp *resp) {
  const fg_task *t = task_param(req, resp);
  if (!t) return 0;
  fg_resp_json(resp, 200, task_json(t, 1));
  fg_task_unref(t);
  return 0;
}

int fg_api_task_delete(fg_req *req, fg_resp *resp) {
  int rc = fg_tasks_delete(req->app->tasks, req->params[0]);
  if (rc == FG_ENOENT)
    return fg_resp_error(resp, 404, "task_not_found", "no task named '%s'; GET /v1/tasks "
                         "lists them", req->params[0]);
  if (rc != 0) return fg_resp_error(resp, 500, "internal_error", "%s", fg_error_detail());
  fg_resp_json(resp, 200, json_pack("{s:s}", "deleted", req->params[0]));
  return 0;
}

int fg_api_task_demo_delete(fg_req *req, fg_resp *resp) {
  char *end;
  long id = strtol(req->params[1], &end, 10);
  if (*end || end == req->params[1] || id < 1 || id > (1L << 30))
    id = 0; /* answered as an unknown demo below, once the task is known to exist */
  const fg_task *t = NULL;
  int rc;
  if (id) {
    rc = fg_tasks_delete_demo(req->app->tasks, req->params[0], (int)id, &t);
  } else {
    const fg_task *had = fg_tasks_get(req->app->tasks, req->params[0]);
    rc = had ? FG_ERANGE : FG_ENOENT;
    fg_task_unref(had);
  }
  if (rc == FG_ENOENT)
    return fg_resp_error(resp, 404, "task_not_found", "no task named '%s'; GET /v1/tasks "
                         "lists them", req->params[0]);
  if (rc == FG_ERANGE)
    return fg_resp_error(resp, 404, "demo_not_found", "task '%s' has no demo '%s'; GET "
                         "/v1/tasks/%s lists its demos and their ids", req->params[0],
                         req->params[1], req->params[0]);
  if (rc != 0) return fg_api_storage_error(resp, rc, "the deletion");
  fg_resp_json(resp, 200, json_pack("{s:{s:s, s:i}, s:o}", "deleted", "task", req->params[0],
                                    "demo", (int)id, "task", task_json(t, 1)));
  fg_task_unref(t);
  return 0;
}

/* ---------------------------------------------------------------- adding a demo */

static const char *const demo_keys[] = {"scene", "pose", "kind", "width", "approach",
                                        "query_points", NULL};

/* Reads "query_points" ({"n", "layout", "std", "size", "mean"}, each optional) into d, over
 * the task's when it has demos, else over the defaults: 100 points in the box between the
 * pads of `model` open to d->width_m (set before). "std" alone means the Gaussian layout,
 * "size" alone the box; "layout": "gaussian" without a std takes FG_GRASP_DEFAULT_STD_M, the
 * Gaussian's default before the box. Answers 400 itself and returns -1 when they are wrong. */
int fg_api_parse_query_points(json_t *body, const fg_task *t, fg_gripper_model model,
                              fg_task_demo_new *d, fg_resp *resp) {
  const int from_task = t && t->n_demos > 0;
  json_t *qp = json_object_get(body, "query_points");
  const char *key;
  json_t *v;
  if (qp && json_is_null(qp)) qp = NULL;
  if (qp && !json_is_object(qp)) goto bad;
  json_object_foreach(qp, key, v) {
    if (strcmp(key, "n") && strcmp(key, "layout") && strcmp(key, "std") &&
        strcmp(key, "size") && strcmp(key, "mean"))
      goto bad;
  }
  d->n_points = from_task ? t->n_points : FG_GRASP_DEFAULT_QUERY_POINTS;
  v = json_object_get(qp, "n");
  if (v) {
    if (!json_is_integer(v) || json_integer_value(v) < 1 ||
        json_integer_value(v) > FG_GRASP_MAX_QUERY_POINTS)
      goto bad;
    d->n_points = (int)json_integer_value(v);
  }
  json_t *jl = json_object_get(qp, "layout"), *js = json_object_get(qp, "std"),
         *jz = json_object_get(qp, "size"), *jm = json_object_get(qp, "mean");
  const char *ls = json_string_value(jl); /* NULL unless a string */
  if (jl && !(ls && (!strcmp(ls, "gaussian") || !strcmp(ls, "box")))) goto bad;
  const int layout = ls   ? (!strcmp(ls, "box") ? FG_GRASP_QP_BOX : FG_GRASP_QP_GAUSSIAN)
                     : js ? FG_GRASP_QP_GAUSSIAN
                     : jz ? FG_GRASP_QP_BOX
                     : from_task ? t->qp_layout
                                 : FG_GRASP_QP_BOX;
  if ((js && layout != FG_GRASP_QP_GAUSSIAN) || (jz && layout != FG_GRASP_QP_BOX)) goto bad;
  /* the task's parameters of this layout, else the layout's defaults ... */
  d->qp_layout = layout;
  d->qp_std_m = 0.0;
  for (int k = 0; k < 3; k++) d->qp_mean_m[k] = d->qp_size_m[k] = 0.0;
  if (from_task && t->qp_layout == layout) {
    d->qp_std_m = t->qp_std_m;
    memcpy(d->qp_mean_m, t->qp_mean_m, sizeof d->qp_mean_m);
    memcpy(d->qp_size_m, t->qp_size_m, sizeof d->qp_size_m);
  } else if (layout == FG_GRASP_QP_GAUSSIAN) {
    d->qp_std_m = FG_GRASP_DEFAULT_STD_M;
  } else if (fg_grasp_query_box_default(model, d->width_m, d->qp_mean_m, d->qp_size_m) != 0) {
    return fg_resp_error(resp, 400, "invalid_query_points", "%s", fg_error_detail()), -1;
  }
  /* ... with the request's on top */
  if (js) {
    if (!json_is_number(js) || !(json_number_value(js) > 0) || !(json_number_value(js) <= 1))
      goto bad;
    d->qp_std_m = json_number_value(js);
  }
  if (jz) {
    double z[3];
    if (fg_json_vec(jz, z, 3, "query_points.size") != 0) goto bad;
    for (int k = 0; k < 3; k++)
      if (!(z[k] > 0 && z[k] <= 1)) goto bad;
    memcpy(d->qp_size_m, z, sizeof z);
  }
  if (jm) {
    double m[3];
    if (fg_json_vec(jm, m, 3, "query_points.mean") != 0 ||
        sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) > 1)
      goto bad;
    memcpy(d->qp_mean_m, m, sizeof m);
  }
  return 0;
bad:
  return fg_resp_error(resp, 400, "invalid_query_points", "\"query_points\" must be {\"n\": "
                       "1..%d points, \"layout\": \"box\" or \"gaussian\", \"size\": the box's "
                       "[x, y, z] edges, metres > 0 and <= 1, or \"std\": the Gaussian's, metres > "
                       "0 and <= 1, \"mean\": [x, y, z] metres in the gripper frame, within 1 m}, "
                       "each optional (default %d points in the box between the pads of the "
                       "[gripper] model at the demo's width, or the task's)",
                       FG_GRASP_MAX_QUERY_POINTS, FG_GRASP_DEFAULT_QUERY_POINTS), -1;
}

/* Reads the demo's keys but its z into d (scene name, pose, kind, width, approach, query
 * points). Answers 400 itself and returns -1 on a bad request. */
int fg_api_parse_demo(json_t *body, const fg_conf *conf, const fg_task *t,
                      fg_task_demo_new *d, fg_resp *resp) {
  const char *key = fg_json_unknown_key(body, demo_keys);
  if (key)
    return fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; a demo takes "
                         "\"scene\", \"pose\", \"kind\", \"width\", \"approach\" and "
                         "\"query_points\"", key), -1;
  if (fg_json_string(body, "scene", &d->scene) != 1)
    return fg_resp_error(resp, 400, "invalid_request", "\"scene\" is required: the name of a "
                         "trained scene the demo's pose is shown on"), -1;
  json_t *pose = json_object_get(body, "pose");
  if (!pose)
    return fg_resp_error(resp, 400, "invalid_pose", "\"pose\" is required: the gripper's pose "
                         "in the world frame, {\"position\": [x, y, z], \"quaternion\": [w, x, "
                         "y, z]} or {\"matrix\": 4x4}"), -1;
  if (fg_json_pose_parse(pose, "pose", d->T_world_gripper, NULL) != 0)
    return fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail()), -1;
  const char *kind = "grasp";
  if (fg_json_string(body, "kind", &kind) < 0 || (strcmp(kind, "grasp") && strcmp(kind, "place")))
    return fg_resp_error(resp, 400, "invalid_request", "\"kind\" must be \"grasp\" (the "
                         "robot picks at the pose) or \"place\" (it places there)"), -1;
  d->kind = strcmp(kind, "place") == 0 ? FG_TASK_PLACE : FG_TASK_GRASP;
  const fg_gripper_spec *gripper = fg_gripper_spec_get(conf->gripper_model);
  const double stroke = gripper->stroke_m;
  d->width_m = stroke;
  int rc = fg_json_number(body, "width", &d->width_m);
  if (rc < 0 || (json_object_get(body, "width") && rc == 0) ||
      !(d->width_m > 0 && d->width_m <= stroke + 1e-12))
    return fg_resp_error(resp, 400, "invalid_request", "\"width\" must be the gripper's "
                         "opening in metres, more than 0 and at most the %s's stroke %g m "
                         "([gripper] model; default the stroke)", gripper->name, stroke), -1;
  d->approach_m = FG_TASK_DEFAULT_APPROACH_M;
  rc = fg_json_number(body, "approach", &d->approach_m);
  if (rc < 0 || (json_object_get(body, "approach") && rc == 0) ||
      !(d->approach_m >= 0 && d->approach_m <= 1))
    return fg_resp_error(resp, 400, "invalid_request", "\"approach\" must be the pre-grasp "
                         "distance in metres along the gripper's -z, 0 to 1 (default %g)",
                         FG_TASK_DEFAULT_APPROACH_M), -1;
  return fg_api_parse_query_points(body, t, conf->gripper_model, d, resp);
}

int fg_api_task_demo_add(fg_req *req, fg_resp *resp) {
  const char *name = req->params[0];
  if (fg_scene_name_validate(name) != 0)
    return fg_resp_error(resp, 400, "invalid_name", "task name '%s': %s", name,
                         fg_error_detail());
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return 0;
  const fg_task *t = fg_tasks_get(req->app->tasks, name), *nt = NULL;
  fg_scene *s = NULL;
  fg_task_demo_new d = {0};
  if (fg_api_parse_demo(body, req->conf, t, &d, resp) != 0) goto out;
  s = fg_store_get(req->app->store, d.scene);
  if (!s) {
    fg_resp_error(resp, 404, "scene_not_found", "no scene named '%s'; GET /v1/scenes lists "
                  "them", d.scene);
    goto out;
  }
  int id = 0;
  const int rc = fg_scene_demo_add(s, req->app->tasks, name, t, &d, fg_conf_threads(req->conf),
                                   &nt, &id);
  if (rc != 0) {
    fg_api_fail(resp, rc);
    goto out;
  }
  snprintf(resp->location, sizeof resp->location, "/v1/tasks/%s", name);
  fg_resp_json(resp, 201, json_pack("{s:o, s:o}", "demo", demo_json(&nt->demos[nt->n_demos - 1]),
                                    "task", task_json(nt, 0)));
out:
  fg_task_unref(nt);
  if (s) fg_scene_unref(s);
  fg_task_unref(t);
  json_decref(body);
  return 0;
}
