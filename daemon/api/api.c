#include "api.h"

#include "state/clip_svc.h"
#include "state/jobs.h"
#include "state/json.h"
#include "metrics/metrics.h"
#include "api_query.h"
#include "robot/audit.h"
#include "robot/robot.h"
#include "state/scene_voxels.h"
#include "state/voxcache.h"

#include "config.h"
#include "core/error.h"
#include "core/log.h"
#include "query/geometry.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const fg_route fg_api_routes[] = {
  {"GET", "/v1/health", "/v1/health", fg_api_health, FG_ROUTE_PUBLIC},
  {"GET", "/metrics", "/metrics", fg_api_metrics, 0},
  /* The web viewer's page and files: public, so that the page can load and ask for the token
   * (api_viewer.c). */
  {"GET", "/", "/", fg_api_viewer_index, FG_ROUTE_PUBLIC | FG_ROUTE_OFFLOAD},
  {"GET", "/viewer/{}", "/viewer/{file}", fg_api_viewer_file, FG_ROUTE_PUBLIC | FG_ROUTE_OFFLOAD},
  {"GET", "/v1/scenes", "/v1/scenes", fg_api_scenes_list, 0},
  {"POST", "/v1/scenes", "/v1/scenes", fg_api_scenes_create, 0},
  {"GET", "/v1/scenes/{}", "/v1/scenes/{s}", fg_api_scene_get, 0},
  {"PATCH", "/v1/scenes/{}", "/v1/scenes/{s}", fg_api_scene_patch, 0},
  {"DELETE", "/v1/scenes/{}", "/v1/scenes/{s}", fg_api_scene_delete, 0},
  {"GET", "/v1/scenes/{}/frames", "/v1/scenes/{s}/frames", fg_api_frames_list, 0},
  {"GET", "/v1/scenes/{}/frames/{}/image", "/v1/scenes/{s}/frames/{i}/image",
   fg_api_frame_image, FG_ROUTE_OFFLOAD},
  {"POST", "/v1/scenes/{}/frames", "/v1/scenes/{s}/frames", fg_api_frames_upload,
   FG_ROUTE_MULTIPART | FG_ROUTE_OFFLOAD | FG_ROUTE_LARGE_BODY},
  {"POST", "/v1/scenes/{}/import", "/v1/scenes/{s}/import", fg_api_scene_import,
   FG_ROUTE_OFFLOAD},
  {"GET", "/v1/scenes/{}/captures", "/v1/scenes/{s}/captures", fg_api_captures_list, 0},
  {"DELETE", "/v1/scenes/{}/captures/{}", "/v1/scenes/{s}/captures/{c}",
   fg_api_capture_delete, FG_ROUTE_OFFLOAD},
  {"POST", "/v1/scenes/{}/train", "/v1/scenes/{s}/train", fg_api_train_start, 0},
  {"POST", "/v1/scenes/{}/scan", "/v1/scenes/{s}/scan", fg_api_audit_scene_scan, 0},
  {"POST", "/v1/scenes/{}/render", "/v1/scenes/{s}/render", fg_api_scene_render,
   FG_ROUTE_OFFLOAD},
  {"POST", "/v1/scenes/{}/heatmap", "/v1/scenes/{s}/heatmap", fg_api_scene_heatmap,
   FG_ROUTE_OFFLOAD},
  {"GET", "/v1/scenes/{}/geometry", "/v1/scenes/{s}/geometry", fg_api_scene_geometry,
   FG_ROUTE_OFFLOAD},
  {"GET", "/v1/scenes/{}/points", "/v1/scenes/{s}/points", fg_api_scene_points,
   FG_ROUTE_OFFLOAD},
  {"POST", "/v1/embed/text", "/v1/embed/text", fg_api_embed_text, FG_ROUTE_OFFLOAD},
  {"POST", "/v1/embed/image", "/v1/embed/image", fg_api_embed_image,
   FG_ROUTE_OFFLOAD | FG_ROUTE_LARGE_BODY | FG_ROUTE_IMAGE_BODY},
  {"GET", "/v1/jobs", "/v1/jobs", fg_api_jobs_list, 0},
  {"GET", "/v1/jobs/{}", "/v1/jobs/{id}", fg_api_job_get, 0},
  {"DELETE", "/v1/jobs/{}", "/v1/jobs/{id}", fg_api_job_cancel, 0},
  {"GET", "/v1/jobs/{}/events", "/v1/jobs/{id}/events", fg_api_job_events, 0},
  {"GET", "/v1/robot", "/v1/robot", fg_api_robot_get, 0},
  {"POST", "/v1/robot/commands", "/v1/robot/commands", fg_api_audit_robot_command,
   FG_ROUTE_OFFLOAD},
  {"GET", "/v1/robot/log", "/v1/robot/log", fg_api_robot_log, FG_ROUTE_OFFLOAD},
  {"GET", "/v1/robot/commands/{}", "/v1/robot/commands/{id}", fg_api_robot_command_get, 0},
  {"POST", "/v1/robot/stop", "/v1/robot/stop", fg_api_audit_robot_stop, FG_ROUTE_OFFLOAD},
  {"POST", "/v1/robot/reset", "/v1/robot/reset", fg_api_audit_robot_reset, FG_ROUTE_OFFLOAD},
  {"GET", "/v1/gripper", "/v1/gripper", fg_api_gripper_get, 0},
  {"GET", "/v1/calibration/board.png", "/v1/calibration/board.png", fg_api_calibration_board,
   FG_ROUTE_OFFLOAD},
  {"GET", "/v1/cameras", "/v1/cameras", fg_api_cameras_list, 0},
  {"GET", "/v1/cameras/{}", "/v1/cameras/{c}", fg_api_camera_get, 0},
  {"POST", "/v1/cameras/{}/capture", "/v1/cameras/{c}/capture", fg_api_camera_capture,
   FG_ROUTE_OFFLOAD},
  {"POST", "/v1/cameras/{}/views", "/v1/cameras/{c}/views", fg_api_camera_view_upload,
   FG_ROUTE_MULTIPART | FG_ROUTE_OFFLOAD | FG_ROUTE_LARGE_BODY},
  {"DELETE", "/v1/cameras/{}/views", "/v1/cameras/{c}/views", fg_api_camera_views_clear, 0},
  {"POST", "/v1/cameras/{}/calibrate", "/v1/cameras/{c}/calibrate",
   fg_api_audit_camera_calibrate, FG_ROUTE_OFFLOAD},
  {"POST", "/v1/gripper/{}", "/v1/gripper/{action}", fg_api_audit_gripper_action,
   FG_ROUTE_OFFLOAD},
  {"GET", "/v1/tasks", "/v1/tasks", fg_api_tasks_list, 0},
  {"GET", "/v1/tasks/{}", "/v1/tasks/{t}", fg_api_task_get, 0},
  {"DELETE", "/v1/tasks/{}", "/v1/tasks/{t}", fg_api_task_delete, 0},
  {"POST", "/v1/tasks/{}/demos", "/v1/tasks/{t}/demos", fg_api_task_demo_add, FG_ROUTE_OFFLOAD},
  {"DELETE", "/v1/tasks/{}/demos/{}", "/v1/tasks/{t}/demos/{i}", fg_api_task_demo_delete, 0},
  {"POST", "/v1/scenes/{}/grasps", "/v1/scenes/{s}/grasps", fg_api_scene_grasps,
   FG_ROUTE_OFFLOAD},
  {"POST", "/v1/scenes/{}/grasps/{}/execute", "/v1/scenes/{s}/grasps/{id}/execute",
   fg_api_audit_grasp_execute, FG_ROUTE_OFFLOAD},
};
const size_t fg_api_n_routes = sizeof fg_api_routes / sizeof fg_api_routes[0];

/* ---------------------------------------------------------------- shared helpers */

json_t *fg_api_body_object(fg_req *req, fg_resp *resp) {
  char err[256];
  json_t *body = fg_json_parse(req->body, req->body_len, err, sizeof err);
  if (!body) {
    fg_resp_error(resp, 400, "malformed_json", "the body is not valid JSON: %s", err);
    return NULL;
  }
  if (!json_is_object(body)) {
    json_decref(body);
    fg_resp_error(resp, 400, "invalid_request", "the body must be a JSON object");
    return NULL;
  }
  return body;
}

void fg_api_scene_info_refresh(fg_app *app, fg_scene_info *info) {
  if (!app->jobs || !info->last_job_id[0]) return;
  fg_job *j = fg_jobs_get(app->jobs, info->last_job_id);
  if (!j) return;
  uint64_t version;
  fg_job_state state;
  fg_job_peek(j, &version, &state);
  fg_job_unref(j);
  snprintf(info->last_job_state, sizeof info->last_job_state, "%s", fg_job_state_name(state));
}

int fg_api_storage_error(fg_resp *resp, int rc, const char *what) {
  return fg_api_fail(resp, fg_state_write_failed(rc, what));
}

fg_scene *fg_api_scene_param(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_store_get(req->app->store, req->params[0]);
  if (!s)
    fg_resp_error(resp, 404, "scene_not_found",
                  "no scene named '%s'; GET /v1/scenes lists them, POST /v1/scenes creates one",
                  req->params[0]);
  return s;
}

fg_field_ref *fg_api_scene_field(fg_scene *s, fg_resp *resp) {
  fg_field_ref *ref;
  const int rc = fg_scene_field_get(s, &ref);
  return rc == 0 ? ref : (fg_api_fail(resp, rc), NULL);
}

int fg_api_solid_get(fg_scene *s, const fg_scene_info *info, double voxel_size, int n_threads,
                     fg_api_solid *out, fg_resp *resp) {
  memset(out, 0, sizeof *out);
  int rc = fg_voxel_grid_init(&out->grid, info->params.workspace_min,
                              info->params.workspace_max, voxel_size);
  if (rc == FG_ERANGE)
    return fg_resp_error(resp, 400, "grid_too_large", "scene '%s': its workspace at voxel_size "
                         "%g m has more than %zu voxels (%s); ask with a larger "
                         "\"voxel_size\"", info->name, voxel_size, FG_QUERY_MAX_VOXELS,
                         fg_error_detail()), -1;
  if (rc != 0)
    return fg_resp_error(resp, 500, "internal_error", "scene '%s': %s", info->name,
                         fg_error_detail()), -1;
  out->ref = fg_api_scene_field(s, resp);
  if (!out->ref) return -1;
  const fg_voxel_grid *g = &out->grid;
  const fg_field *field = fg_field_ref_field(out->ref);
  if (field->cfg.feature_dim > 0 && g->voxel_size == info->params.voxel_size) {
    if ((rc = fg_field_voxels(out->ref, g, info->name, n_threads, &out->vox)) != 0) {
      fg_api_solid_release(out);
      return fg_api_fail(resp, rc), -1;
    }
    out->alpha = fg_voxel_features_alpha(fg_voxels_features(out->vox));
    return 0;
  }
  out->own = malloc(fg_voxel_grid_count(g) * sizeof *out->own);
  rc = out->own ? fg_voxel_alpha(field, g, out->own, n_threads)
                : fg_fail(FG_ENOMEM, "out of memory for %zu voxels", fg_voxel_grid_count(g));
  if (rc != 0) {
    fg_api_solid_release(out);
    return fg_resp_error(resp, 500, "internal_error", "cannot sample the field of scene '%s': "
                         "%s", info->name, fg_error_detail()), -1;
  }
  out->alpha = out->own;
  return 0;
}

void fg_api_solid_release(fg_api_solid *sv) {
  free(sv->own);
  fg_voxels_release(sv->vox);
  fg_field_ref_release(sv->ref);
  sv->own = NULL;
  sv->vox = NULL;
  sv->ref = NULL;
  sv->alpha = NULL;
}

/* ---------------------------------------------------------------- health and metrics */

int fg_api_health(fg_req *req, fg_resp *resp) {
  static const char body[] = "{\"status\":\"ok\",\"version\":\"" FG_VERSION "\"}";
  fg_resp_take(resp, 200, "application/json", strdup(body), sizeof body - 1);
  return 0;
}

int fg_api_metrics(fg_req *req, fg_resp *resp) {
  fg_metrics_gauges g = {0};
  fg_store_totals(req->app->store, &g.scenes, &g.frames);
  g.trained_scenes = fg_store_trained(req->app->store);
  fg_store_field_stats fs;
  fg_store_field_stats_get(req->app->store, &fs);
  g.fields_loaded = fs.loaded;
  g.max_loaded_fields = fs.max_loaded;
  g.field_loads = fs.loads;
  g.field_evictions = fs.evictions;
  g.voxel_cache_bytes = fg_store_voxel_cache_bytes(req->app->store);
  if (req->app->jobs) fg_jobs_count(req->app->jobs, g.jobs);
  fg_clip_model *m = req->app->clip ? fg_clip_svc_acquire(req->app->clip) : NULL;
  g.clip_loaded = m != NULL;
  fg_clip_model_release(m);
  fg_decoder_get_stats(req->app->decoder, &g.decoder);
  size_t len;
  char *text = fg_metrics_render(&g, &len);
  if (!text) return fg_resp_error(resp, 500, "internal_error", "out of memory rendering metrics");
  if (req->app->robot) {
    char modbus[8192];
    size_t n = fg_robot_metrics(req->app->robot, modbus, sizeof modbus);
    n += fg_audit_metrics(req->app->audit, modbus + n, sizeof modbus - n);
    char *more = realloc(text, len + n + 1);
    if (!more) {
      free(text);
      return fg_resp_error(resp, 500, "internal_error", "out of memory rendering metrics");
    }
    memcpy(more + len, modbus, n + 1);
    text = more;
    len += n;
  }
  fg_resp_take(resp, 200, "text/plain; version=0.0.4; charset=utf-8", text, len);
  return 0;
}
