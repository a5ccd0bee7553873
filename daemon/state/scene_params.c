/* A scene's parameters and their file, scene.json; see scene_params.h. */
#include "scene_params.h"

#include "json.h"

#include "core/error.h"
#include "core/fsutil.h"

#include <jansson.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- parameters */

int fg_scene_params_validate(const fg_scene_params *p) {
  static const char axis[] = "xyz";
  for (int i = 0; i < 3; i++) {
    if (!isfinite(p->workspace_min[i]) || !isfinite(p->workspace_max[i]))
      return fg_fail(FG_EINVAL, "workspace %c bounds must be finite numbers (metres)", axis[i]);
    if (!(p->workspace_min[i] < p->workspace_max[i]))
      return fg_fail(FG_EINVAL, "workspace min %c (%g) must be less than max %c (%g)", axis[i],
                     p->workspace_min[i], axis[i], p->workspace_max[i]);
    if (!(p->background[i] >= 0 && p->background[i] <= 1))
      return fg_fail(FG_EINVAL, "background must hold three numbers in [0, 1]");
  }
  double smallest = INFINITY;
  for (int i = 0; i < 3; i++)
    smallest = fmin(smallest, p->workspace_max[i] - p->workspace_min[i]);
  if (!(p->voxel_size > 0) || !isfinite(p->voxel_size) || p->voxel_size > smallest)
    return fg_fail(FG_EINVAL, "voxel_size must be a positive length in metres no larger than the "
                   "workspace's smallest side (%g), got %g", smallest, p->voxel_size);
  if (p->field_scale != FG_FIELD_SCALE_AUTO && !(p->field_scale >= 1 && p->field_scale <= 64))
    return fg_fail(FG_EINVAL, "field_scale must be \"auto\" or a number from 1 to 64 (the "
                   "field's cube over the workspace's largest extent), got %g", p->field_scale);
  if (p->learn_background != FG_LEARN_BACKGROUND_AUTO && p->learn_background != 0 &&
      p->learn_background != 1)
    return fg_fail(FG_EINVAL, "learn_background must be \"auto\", true or false");
  return 0;
}

int fg_scene_params_equal(const fg_scene_params *a, const fg_scene_params *b) {
  for (int i = 0; i < 3; i++)
    if (a->workspace_min[i] != b->workspace_min[i] || a->workspace_max[i] != b->workspace_max[i] ||
        a->background[i] != b->background[i])
      return 0;
  return a->voxel_size == b->voxel_size && a->field_scale == b->field_scale &&
         a->learn_background == b->learn_background;
}

/* ---------------------------------------------------------------- scene.json */

int fg_scene_json_write(const char *dir, const char *name, const fg_scene_params *p,
                        int64_t created_ms) {
  json_t *o = json_pack(
    "{s:s,s:{s:[f,f,f],s:[f,f,f]},s:f,s:[f,f,f],s:I}", "name", name, "workspace", "min",
    p->workspace_min[0], p->workspace_min[1], p->workspace_min[2], "max", p->workspace_max[0],
    p->workspace_max[1], p->workspace_max[2], "voxel_size", p->voxel_size, "background",
    p->background[0], p->background[1], p->background[2], "created_ms", (json_int_t)created_ms);
  if (o) {
    json_object_set_new(o, "field_scale", fg_json_field_scale(p->field_scale));
    json_object_set_new(o, "learn_background", fg_json_learn_background(p->learn_background));
  }
  char *text = o ? json_dumps(o, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) : NULL;
  json_decref(o);
  if (!text) return fg_fail(FG_ENOMEM, "out of memory");
  char *path = fg_path_join(dir, "scene.json");
  int rc = path ? fg_write_file_atomic(path, text, strlen(text)) : fg_fail(FG_ENOMEM, "oom");
  free(path);
  free(text);
  return rc;
}

static int read_vec3(json_t *a, double out[3]) {
  if (!json_is_array(a) || json_array_size(a) != 3) return -1;
  for (int i = 0; i < 3; i++) {
    json_t *v = json_array_get(a, (size_t)i);
    if (!json_is_number(v)) return -1;
    out[i] = json_number_value(v);
  }
  return 0;
}

int fg_scene_json_read(const char *dir, fg_scene_params *params, int64_t *created_ms) {
  char *path = fg_path_join(dir, "scene.json");
  if (!path) return fg_fail(FG_ENOMEM, "out of memory");
  json_error_t jerr;
  json_t *o = json_load_file(path, 0, &jerr);
  int rc = 0;
  json_t *ws = o ? json_object_get(o, "workspace") : NULL;
  if (!o) {
    rc = fg_fail(FG_EFORMAT, "%s: %s (line %d)", path, jerr.text, jerr.line);
  } else if (read_vec3(json_object_get(ws, "min"), params->workspace_min) ||
             read_vec3(json_object_get(ws, "max"), params->workspace_max) ||
             read_vec3(json_object_get(o, "background"), params->background) ||
             !json_is_number(json_object_get(o, "voxel_size"))) {
    rc = fg_fail(FG_EFORMAT, "%s: missing or malformed workspace, voxel_size or background", path);
  } else {
    params->field_scale = FG_FIELD_SCALE_AUTO;
    params->learn_background = FG_LEARN_BACKGROUND_AUTO;
    params->voxel_size = json_number_value(json_object_get(o, "voxel_size"));
    *created_ms = json_integer_value(json_object_get(o, "created_ms"));
    /* absent in scenes made before the settings existed: auto */
    if (fg_json_read_field_settings(o, &params->field_scale, &params->learn_background))
      rc = fg_fail(FG_EFORMAT, "%s: %s", path, fg_error_detail());
    else if (fg_scene_params_validate(params) != 0)
      rc = fg_fail(FG_EFORMAT, "%s: %s", path, fg_error_detail());
  }
  json_decref(o);
  free(path);
  return rc;
}
