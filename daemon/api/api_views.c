/* The API's views of scenes and frames (api_views.h). */
#include "api_views.h"

#include "state/json.h"

/* The trained field's cube and background: what the settings gave it. */
static json_t *json_field(const fg_scene_info *info) {
  double extent = 0;
  for (int i = 0; i < 3; i++)
    if (info->params.workspace_max[i] - info->params.workspace_min[i] > extent)
      extent = info->params.workspace_max[i] - info->params.workspace_min[i];
  return json_pack("{s:o,s:f,s:f,s:b}", "box_min", fg_json_from_vec(info->field_box_min, 3),
                   "box_size", info->field_box_size, "scale", info->field_box_size / extent,
                   "learn_background", info->field_learn_background);
}

json_t *fg_json_scene(const fg_scene_info *info) {
  char created[32];
  fg_iso8601(info->created_ms, created);
  json_t *last_job = info->last_job_id[0]
    ? json_pack("{s:s,s:s}", "id", info->last_job_id, "state", info->last_job_state)
    : json_null();
  json_t *o = json_pack("{s:s,s:{s:o,s:o},s:f,s:o,s:I,s:o,s:b,s:o,s:s,s:b}", "name", info->name,
                        "workspace", "min", fg_json_from_vec(info->params.workspace_min, 3),
                        "max", fg_json_from_vec(info->params.workspace_max, 3), "voxel_size",
                        info->params.voxel_size, "background",
                        fg_json_from_vec(info->params.background, 3), "frames",
                        (json_int_t)info->n_frames, "feature_dim",
                        info->feature_dim         ? json_integer(info->feature_dim)
                        : info->field_feature_dim ? json_integer(info->field_feature_dim)
                                                  : json_null(),
                        "trained", info->trained, "last_job", last_job, "created", created,
                        "declared_in_config", info->declared_in_config);
  if (!o) return NULL;
  json_object_set_new(o, "captures", json_integer((json_int_t)info->n_captures));
  json_object_set_new(o, "latest_capture", info->latest_capture
                                             ? json_integer((json_int_t)info->latest_capture)
                                             : json_null());
  json_object_set_new(o, "field_scale", fg_json_field_scale(info->params.field_scale));
  json_object_set_new(o, "learn_background",
                      fg_json_learn_background(info->params.learn_background));
  json_object_set_new(o, "field", info->trained ? json_field(info) : json_null());
  json_object_set_new(o, "trained_steps", json_integer(info->trained_steps));
  json_object_set_new(o, "checkpoint_bytes", json_integer(info->checkpoint_bytes));
  json_object_set_new(o, "partial", json_boolean(info->partial));
  json_object_set_new(o, "loaded", json_boolean(info->loaded));
  json_t *err = NULL;
  if (info->checkpoint_error[0]) {
    err = json_string(info->checkpoint_error);
    if (!err) err = json_string("the checkpoint does not load (see the daemon's log)");
  }
  json_object_set_new(o, "checkpoint_error", err ? err : json_null());
  const fg_voxcache_info *v = &info->voxel_cache;
  json_object_set_new(o, "voxel_cache",
                      json_pack("{s:b,s:b,s:I,s:I,s:I,s:o,s:o}", "built", v->built, "building",
                                v->building, "bytes", (json_int_t)v->bytes, "voxels",
                                (json_int_t)v->voxels, "kept", (json_int_t)v->kept,
                                "voxel_size", v->built ? json_real(v->voxel_size) : json_null(),
                                "build_seconds",
                                v->built ? json_real(v->build_seconds) : json_null()));
  return o;
}

json_t *fg_json_frame(const fg_frame *f, int index) {
  char created[32];
  fg_iso8601(f->created_ms, created);
  json_t *features = f->feat_d
    ? json_pack("{s:i,s:i,s:i,s:s}", "h", f->feat_h, "w", f->feat_w, "d", f->feat_d, "dtype",
                f->feat_dtype == FG_DTYPE_F16 ? "float16" : "float32")
    : json_null();
  json_t *depth = f->depth_w ? json_pack("{s:i,s:i,s:f}", "w", f->depth_w, "h", f->depth_h,
                                         "valid_fraction", f->depth_valid)
                             : json_null();
  json_t *o = json_pack("{s:i,s:s,s:o,s:s,s:{s:f,s:f,s:f,s:f,s:i,s:i,s:s},s:[i,i],s:b,s:o,s:o,"
                        "s:s}",
                        "frame", index, "source", f->source, "transform_matrix",
                        fg_json_from_matrix4(f->T_world_cam), "convention", "opengl", "camera",
                        "fl_x", f->cam.fl_x, "fl_y", f->cam.fl_y, "cx", f->cam.cx, "cy",
                        f->cam.cy, "w", f->cam.w, "h", f->cam.h, "camera_model",
                        fg_camera_model_name(f->cam.model), "source_size", f->src_w, f->src_h,
                        "undistorted", f->undistorted, "features", features, "depth", depth,
                        "created", created);
  if (o) {
    json_object_set_new(o, "capture", json_integer((json_int_t)f->capture));
    json_object_set_new(o, "robot_pose",
                        f->has_robot_pose ? fg_json_pose(f->T_world_tcp) : json_null());
  }
  return o;
}
