#include "json.h"
#include "store.h"

#include "core/error.h"
#include "core/pose.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

json_t *fg_json_parse(const void *body, size_t len, char *err, size_t errlen) {
  if (!body || len == 0) {
    snprintf(err, errlen, "the request body is empty; send a JSON object");
    return NULL;
  }
  json_error_t e;
  /* Any value parses, so that valid JSON of the wrong shape is told apart from bad JSON. */
  json_t *v = json_loadb(body, len, JSON_REJECT_DUPLICATES | JSON_DECODE_ANY, &e);
  if (!v) snprintf(err, errlen, "line %d, column %d: %s", e.line, e.column, e.text);
  return v;
}

int fg_json_number(json_t *obj, const char *key, double *out) {
  json_t *v = json_object_get(obj, key);
  if (!v || json_is_null(v)) return 0;
  if (!json_is_number(v)) return fg_fail(FG_EINVAL, "\"%s\" must be a number", key);
  double d = json_number_value(v);
  if (!isfinite(d)) return fg_fail(FG_EINVAL, "\"%s\" must be a finite number", key);
  *out = d;
  return 1;
}

static int is_auto(json_t *v) {
  return json_is_string(v) && strcmp(json_string_value(v), "auto") == 0;
}

int fg_json_read_field_settings(json_t *obj, double *field_scale, int *learn_background) {
  json_t *v = json_object_get(obj, "field_scale");
  if (is_auto(v)) *field_scale = FG_FIELD_SCALE_AUTO;
  else if (v && !json_is_null(v) &&
           (!json_is_number(v) || !(json_number_value(v) >= 1 && json_number_value(v) <= 64)))
    return fg_fail(FG_EINVAL, "\"field_scale\" must be \"auto\" or a number from 1 to 64 "
                   "(the field's cube over the workspace's largest extent)");
  else if (v && !json_is_null(v)) *field_scale = json_number_value(v);
  v = json_object_get(obj, "learn_background");
  if (is_auto(v)) *learn_background = FG_LEARN_BACKGROUND_AUTO;
  else if (v && !json_is_null(v) && !json_is_boolean(v))
    return fg_fail(FG_EINVAL, "\"learn_background\" must be \"auto\", true or false");
  else if (v && !json_is_null(v)) *learn_background = json_is_true(v);
  return 0;
}

json_t *fg_json_field_scale(double field_scale) {
  return field_scale == FG_FIELD_SCALE_AUTO ? json_string("auto") : json_real(field_scale);
}

json_t *fg_json_learn_background(int learn_background) {
  return learn_background == FG_LEARN_BACKGROUND_AUTO ? json_string("auto")
                                                      : json_boolean(learn_background);
}

int fg_json_string(json_t *obj, const char *key, const char **out) {
  json_t *v = json_object_get(obj, key);
  if (!v || json_is_null(v)) return 0;
  if (!json_is_string(v)) return fg_fail(FG_EINVAL, "\"%s\" must be a string", key);
  *out = json_string_value(v);
  return 1;
}

int fg_json_vec(json_t *v, double *out, size_t n, const char *what) {
  if (!json_is_array(v) || json_array_size(v) != n)
    return fg_fail(FG_EINVAL, "%s must be an array of %zu numbers", what, n);
  for (size_t i = 0; i < n; i++) {
    json_t *x = json_array_get(v, i);
    if (!json_is_number(x) || !isfinite(json_number_value(x)))
      return fg_fail(FG_EINVAL, "%s[%zu] must be a finite number", what, i);
    out[i] = json_number_value(x);
  }
  return 0;
}

int fg_json_matrix4(json_t *v, double T[16], const char *what) {
  if (!json_is_array(v) || json_array_size(v) != 4)
    return fg_fail(FG_EINVAL, "%s must be a 4x4 matrix: an array of 4 rows of 4 numbers", what);
  for (size_t r = 0; r < 4; r++) {
    json_t *row = json_array_get(v, r);
    if (!json_is_array(row) || json_array_size(row) != 4)
      return fg_fail(FG_EINVAL, "%s must be a 4x4 matrix; row %zu does not have 4 numbers", what,
                     r);
    for (size_t c = 0; c < 4; c++) {
      json_t *x = json_array_get(row, c);
      if (!json_is_number(x))
        return fg_fail(FG_EINVAL, "%s[%zu][%zu] is not a number", what, r, c);
      T[r * 4 + c] = json_number_value(x);
    }
  }
  return 0;
}

int fg_json_pose_parse(json_t *v, const char *what, double T[16], double q_wxyz[4]) {
  double q[4];
  int quaternion_form = 0;
  if (json_is_array(v)) {
    FG_TRY(fg_json_matrix4(v, T, what));
  } else if (json_is_object(v) && json_object_get(v, "matrix")) {
    FG_TRY(fg_json_matrix4(json_object_get(v, "matrix"), T, what));
  } else if (json_is_object(v)) {
    double p[3];
    char name[96];
    snprintf(name, sizeof name, "%s.position", what);
    FG_TRY(fg_json_vec(json_object_get(v, "position"), p, 3, name));
    snprintf(name, sizeof name, "%s.quaternion", what);
    FG_TRY(fg_json_vec(json_object_get(v, "quaternion"), q, 4, name));
    FG_TRY(fg_pose_from_quat(p, q, T));
    quaternion_form = 1;
  } else {
    return fg_fail(FG_EINVAL, "%s must be a 4x4 matrix or {\"position\": [x, y, z], "
                   "\"quaternion\": [w, x, y, z]}", what);
  }
  if (fg_pose_validate(T) != 0) {
    char detail[512];
    snprintf(detail, sizeof detail, "%s", fg_error_detail());
    return fg_fail(FG_EINVAL, "%s: %s", what, detail);
  }
  if (!q_wxyz) return 0;
  if (quaternion_form) {
    /* fg_pose_from_quat checked that the norm is within FG_POSE_ORTHO_TOL of 1 */
    const double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int i = 0; i < 4; i++) q_wxyz[i] = q[i] / n;
  } else {
    double p[3];
    fg_pose_to_quat(T, p, q_wxyz);
  }
  return 0;
}

json_t *fg_json_pose_quat(const double p[3], const double q_wxyz[4]) {
  double T[16];
  double R[9];
  fg_rotmat_from_quat(q_wxyz, R);
  fg_pose_from_rotmat(R, p, T);
  return json_pack("{s:o, s:o, s:o}", "position", fg_json_from_vec(p, 3), "quaternion",
                   fg_json_from_vec(q_wxyz, 4), "matrix", fg_json_from_matrix4(T));
}

json_t *fg_json_pose(const double T[16]) {
  double p[3], q[4];
  fg_pose_to_quat(T, p, q);
  return json_pack("{s:o, s:o, s:o}", "position", fg_json_from_vec(p, 3), "quaternion",
                   fg_json_from_vec(q, 4), "matrix", fg_json_from_matrix4(T));
}

static const char *const camera_keys[] = {"fl_x", "fl_y", "cx", "cy", "w", "h", "camera_model",
                                          "k1", "k2", "k3", "p1", "p2", "camera_angle_x",
                                          "camera_angle_y"};

int fg_json_camera(json_t *obj, int strict, fg_transforms_frame *f) {
  if (!json_is_object(obj)) return fg_fail(FG_EINVAL, "\"camera\" must be an object");
  if (strict) {
    const char *key;
    json_t *val;
    json_object_foreach(obj, key, val) {
      int known = 0;
      for (size_t i = 0; i < sizeof camera_keys / sizeof camera_keys[0]; i++)
        known |= strcmp(key, camera_keys[i]) == 0;
      if (!known)
        return fg_fail(FG_EINVAL, "unknown camera key \"%s\" (known: fl_x fl_y cx cy w h "
                       "camera_model k1 k2 k3 p1 p2 camera_angle_x camera_angle_y)", key);
    }
  }
  fg_camera *cam = &f->cam;
  struct { const char *key; double *dst; int *has; } nums[] = {
    {"fl_x", &cam->fl_x, &f->has_fl_x}, {"fl_y", &cam->fl_y, &f->has_fl_y},
    {"cx", &cam->cx, &f->has_cx},       {"cy", &cam->cy, &f->has_cy},
    {"k1", &cam->k1, NULL},             {"k2", &cam->k2, NULL},
    {"k3", &cam->k3, NULL},             {"p1", &cam->p1, NULL},
    {"p2", &cam->p2, NULL},             {"camera_angle_x", &f->camera_angle_x, NULL},
    {"camera_angle_y", &f->camera_angle_y, NULL},
  };
  for (size_t i = 0; i < sizeof nums / sizeof nums[0]; i++) {
    int rc = fg_json_number(obj, nums[i].key, nums[i].dst);
    FG_TRY(rc);
    if (nums[i].has) *nums[i].has = rc;
  }
  double w = 0, h = 0;
  int hw = fg_json_number(obj, "w", &w), hh = fg_json_number(obj, "h", &h);
  FG_TRY(hw);
  FG_TRY(hh);
  if (hw != hh) return fg_fail(FG_EINVAL, "give both camera w and h, or neither");
  if (hw && (w != floor(w) || w < 1 || w > 32768 || h != floor(h) || h < 1 || h > 32768))
    return fg_fail(FG_EINVAL, "camera w and h must be whole numbers of pixels from 1 to 32768");
  f->has_size = hw;
  cam->w = (int)w;
  cam->h = (int)h;
  for (int i = 0; i < 2; i++) {
    double a = i ? f->camera_angle_y : f->camera_angle_x;
    if (a != 0 && !(a > 0 && a < M_PI))
      return fg_fail(FG_EINVAL, "camera_angle_%c must be in (0, pi) radians", i ? 'y' : 'x');
  }
  if (!f->has_fl_x && !f->has_fl_y && !f->camera_angle_x && !f->camera_angle_y)
    return fg_fail(FG_EINVAL, "the camera has no focal length: give fl_x (and fl_y) in pixels, "
                   "or camera_angle_x in radians");
  const char *model = NULL;
  int hm = fg_json_string(obj, "camera_model", &model);
  FG_TRY(hm);
  int distorted = cam->k1 || cam->k2 || cam->k3 || cam->p1 || cam->p2;
  if (hm) FG_TRY(fg_camera_model_parse(model, &cam->model));
  else cam->model = distorted ? FG_CAMERA_OPENCV : FG_CAMERA_PINHOLE;
  if (cam->model == FG_CAMERA_PINHOLE && distorted)
    return fg_fail(FG_EINVAL, "a PINHOLE camera has no distortion; use camera_model \"OPENCV\" "
                   "with k1 k2 p1 p2 [k3]");
  return 0;
}

json_t *fg_json_from_vec(const double *v, size_t n) {
  json_t *a = json_array();
  for (size_t i = 0; a && i < n; i++) json_array_append_new(a, json_real(v[i]));
  return a;
}

json_t *fg_json_from_matrix4(const double T[16]) {
  json_t *m = json_array();
  for (int r = 0; m && r < 4; r++) json_array_append_new(m, fg_json_from_vec(T + 4 * r, 4));
  return m;
}

int fg_json_int_range(json_t *obj, const char *key, long long lo, long long hi, long long *out) {
  json_t *v = json_object_get(obj, key);
  if (!v || json_is_null(v)) return 0;
  if (!json_is_integer(v) || json_integer_value(v) < lo || json_integer_value(v) > hi) return -1;
  *out = json_integer_value(v);
  return 1;
}

const char *fg_json_unknown_key(json_t *obj, const char *const *keys) {
  const char *key;
  json_t *v;
  json_object_foreach(obj, key, v) {
    int known = 0;
    for (size_t i = 0; !known && keys[i]; i++) known = strcmp(key, keys[i]) == 0;
    if (!known) return key;
  }
  return NULL;
}

void fg_iso8601(int64_t ms, char out[32]) {
  time_t t = (time_t)(ms / 1000);
  struct tm tm;
  gmtime_r(&t, &tm);
  char date[24];
  strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &tm);
  snprintf(out, 32, "%.19s.%03dZ", date, (int)(ms % 1000));
}

json_t *fg_json_time_ms(int64_t ms) {
  if (ms <= 0) return json_null();
  char out[32];
  fg_iso8601(ms, out);
  return json_string(out);
}
