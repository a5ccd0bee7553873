/* Scenes: create, list, describe, delete. */
#include "api.h"
#include "api_decode.h"
#include "state/jobs.h"
#include "api_views.h"
#include "state/json.h"

#include "core/error.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

int fg_api_scenes_list(fg_req *req, fg_resp *resp) {
  fg_scene_info *infos;
  size_t n;
  if (fg_store_list(req->app->store, &infos, &n) != 0)
    return fg_resp_error(resp, 500, "internal_error", "%s", fg_error_detail());
  json_t *arr = json_array();
  for (size_t i = 0; arr && i < n; i++) {
    fg_api_scene_info_refresh(req->app, &infos[i]);
    json_array_append_new(arr, fg_json_scene(&infos[i]));
  }
  free(infos);
  fg_resp_json(resp, 200, json_pack("{s:o}", "scenes", arr));
  return 0;
}

/* Reads the optional fields of a scene creation over the SPEC.md tabletop defaults. 0, or
 * FG_EINVAL with a detail (and, from fg_scene_params_validate, a reason). */
static int scene_params(json_t *body, fg_scene_params *p) {
  static const fg_scene_params defaults = {
    .workspace_min = {0.10, -0.45, 0.005}, .workspace_max = {0.80, 0.45, 0.35},
    .voxel_size = 0.01, .background = {1, 1, 1}, .field_scale = FG_FIELD_SCALE_AUTO,
    .learn_background = FG_LEARN_BACKGROUND_AUTO};
  *p = defaults;
  json_t *ws = json_object_get(body, "workspace");
  if (ws && !json_is_null(ws)) {
    if (!json_is_object(ws))
      return fg_fail(FG_EINVAL, "\"workspace\" must be {\"min\": [x, y, z], \"max\": [x, y, z]} "
                     "in metres");
    FG_TRY(fg_json_vec(json_object_get(ws, "min"), p->workspace_min, 3, "workspace.min"));
    FG_TRY(fg_json_vec(json_object_get(ws, "max"), p->workspace_max, 3, "workspace.max"));
  }
  FG_TRY(fg_json_number(body, "voxel_size", &p->voxel_size));
  json_t *bg = json_object_get(body, "background");
  if (bg && !json_is_null(bg)) FG_TRY(fg_json_vec(bg, p->background, 3, "background"));
  FG_TRY(fg_json_read_field_settings(body, &p->field_scale, &p->learn_background));
  return fg_scene_params_validate(p);
}

int fg_api_parse_scene_params(json_t *body, fg_scene_params *p, fg_resp *resp) {
  const int rc = scene_params(body, p);
  return rc == 0 ? 0 : (fg_api_fail(resp, rc), -1);
}

int fg_api_scenes_create(fg_req *req, fg_resp *resp) {
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return 0;
  const char *name = NULL;
  fg_scene_params p;
  int rc = fg_json_string(body, "name", &name);
  if (rc == 0) rc = fg_fail(FG_EINVAL, "\"name\" is required: the scene's name, 1 to 64 of "
                            "A-Z a-z 0-9 _ . -");
  if (rc > 0 && fg_api_parse_scene_params(body, &p, resp) != 0) {
    json_decref(body);
    return 0;
  }
  if (rc > 0) rc = fg_store_create(req->app->store, name, &p, 0);
  if (rc != 0) {
    fg_api_fail(resp, rc);
  } else {
    fg_scene *s = fg_store_get(req->app->store, name);
    fg_scene_info info;
    if (s) {
      fg_scene_get_info(s, &info);
      fg_scene_unref(s);
      fg_resp_json(resp, 201, fg_json_scene(&info));
    } else { /* deleted again in the meantime */
      fg_resp_error(resp, 404, "scene_not_found", "scene '%s' was deleted right after creation",
                    name);
    }
  }
  json_decref(body);
  return 0;
}

/* 200 with scene s's view as it is now; drops the caller's reference. */
static int answer_scene(fg_req *req, fg_resp *resp, fg_scene *s) {
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  fg_scene_unref(s);
  fg_api_scene_info_refresh(req->app, &info);
  fg_resp_json(resp, 200, fg_json_scene(&info));
  return 0;
}

int fg_api_scene_get(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  return answer_scene(req, resp, s);
}

/* PATCH /v1/scenes/{s}: the field settings, the only ones a scene's data does not depend on
 * (its frames were composited on the background and its voxels are the workspace's). */
int fg_api_scene_patch(fg_req *req, fg_resp *resp) {
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return 0;
  const char *key;
  json_t *v;
  json_object_foreach(body, key, v) {
    if (strcmp(key, "field_scale") != 0 && strcmp(key, "learn_background") != 0) {
      fg_resp_error(resp, 400, "invalid_request", "\"%.40s\" cannot change: a scene's "
                    "field_scale and learn_background can; the workspace, voxel_size and "
                    "background are fixed when it is created", key);
      json_decref(body);
      return 0;
    }
  }
  double scale = NAN;
  int learn_bg = INT_MIN;
  int rc = fg_json_read_field_settings(body, &scale, &learn_bg);
  json_decref(body);
  fg_scene *s = rc == 0 ? fg_api_scene_param(req, resp) : NULL;
  if (rc != 0) return fg_api_fail(resp, rc);
  if (!s) return 0;
  rc = fg_scene_set_field_settings(s, isnan(scale) ? NULL : &scale,
                                   learn_bg == INT_MIN ? NULL : &learn_bg);
  if (rc != 0) {
    fg_scene_unref(s);
    return fg_api_fail(resp, rc);
  }
  return answer_scene(req, resp, s);
}

int fg_api_scene_delete(fg_req *req, fg_resp *resp) {
  int rc = fg_store_delete(req->app->store, req->params[0]);
  if (rc != 0) return fg_api_fail(resp, rc);
  /* After the store's delete, so that a training submitted meanwhile is caught too. */
  if (req->app->jobs) fg_jobs_cancel_scene(req->app->jobs, req->params[0]);
  fg_resp_json(resp, 200, json_pack("{s:s}", "deleted", req->params[0]));
  return 0;
}
