/* instant-ngp / nerfstudio transforms.json reader: see transforms.h.
 *
 * The two tools write the same keys with different habits: instant-ngp's Blender scenes give
 * only camera_angle_x at the top level and extension-less file paths ("./train/r_0");
 * nerfstudio gives fl_x fl_y cx cy w h and distortion at the top level, sometimes overridden
 * per frame. Both are read here into one fg_camera per frame. Where the image size is not in
 * the file, the intrinsics that depend on it wait for fg_transforms_complete_camera. */
#include "io/transforms.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "io/camera.h"
#include "io/depth.h"

#include <jansson.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* fg_camera_validate's limit; checked early here so that the message names the frame. */
#define SIDE_MAX 32768

static const char *const image_exts[] = {".png", ".jpg", ".jpeg", ".exr", ".tif", ".tiff",
                                         ".PNG", ".JPG", ".JPEG", ".EXR", ".TIF", ".TIFF", NULL};
static const char *const features_exts[] = {".npy", ".NPY", NULL};

/* ---------------------------------------------------------------- camera keys */

/* The camera keys of one JSON object (the top level or a frame); has_* = present, not null. */
typedef struct cam_keys {
  int has_fl_x, has_fl_y, has_angle_x, has_angle_y, has_cx, has_cy, has_w, has_h, has_model;
  double fl_x, fl_y, angle_x, angle_y, cx, cy;
  int w, h;
  fg_camera_model model;
  int has_k[5];
  double k[5]; /* k1 k2 k3 p1 p2, fg_camera's order */
} cam_keys;

static const char *const k_names[5] = {"k1", "k2", "k3", "p1", "p2"};

static const char *type_name(const json_t *v) {
  switch (json_typeof(v)) {
  case JSON_OBJECT: return "an object";
  case JSON_ARRAY: return "an array";
  case JSON_STRING: return "a string";
  case JSON_INTEGER:
  case JSON_REAL: return "a number";
  case JSON_TRUE: return "true";
  case JSON_FALSE: return "false";
  case JSON_NULL: return "null";
  }
  return "something else";
}

/* Reads an optional number. JSON null counts as absent: some exporters write "k3": null. */
static int get_number(const char *path, const char *where, const json_t *obj, const char *key,
                      int *has, double *out) {
  const json_t *v = json_object_get(obj, key);
  *has = 0;
  if (!v || json_is_null(v)) return 0;
  if (!json_is_number(v))
    return fg_fail(FG_EFORMAT, "%s: %s: %s must be a number, got %s", path, where, key,
                   type_name(v));
  double x = json_number_value(v);
  if (!isfinite(x))
    return fg_fail(FG_EFORMAT, "%s: %s: %s is not a finite number", path, where, key);
  *out = x;
  *has = 1;
  return 0;
}

/* A positive number (a focal length). */
static int get_positive(const char *path, const char *where, const json_t *obj, const char *key,
                        int *has, double *out) {
  FG_TRY(get_number(path, where, obj, key, has, out));
  if (*has && !(*out > 0))
    return fg_fail(FG_EFORMAT, "%s: %s: %s must be positive (pixels), got %g", path, where, key,
                   *out);
  return 0;
}

/* A field of view in radians: (0, pi). Degrees (e.g. 50) are the likely mistake. */
static int get_angle(const char *path, const char *where, const json_t *obj, const char *key,
                     int *has, double *out) {
  FG_TRY(get_number(path, where, obj, key, has, out));
  if (*has && !(*out > 0 && *out < M_PI))
    return fg_fail(FG_EFORMAT, "%s: %s: %s must be a field of view in radians between 0 and pi, "
                   "got %g", path, where, key, *out);
  return 0;
}

/* An image side: a whole number of pixels, written as 800 or 800.0. */
static int get_side(const char *path, const char *where, const json_t *obj, const char *key,
                    int *has, int *out) {
  double x = 0;
  FG_TRY(get_number(path, where, obj, key, has, &x));
  if (!*has) return 0;
  if (x != floor(x) || x < 1 || x > SIDE_MAX)
    return fg_fail(FG_EFORMAT, "%s: %s: %s must be a whole number of pixels from 1 to %d, got %g",
                   path, where, key, SIDE_MAX, x);
  *out = (int)x;
  return 0;
}

/* Reads the camera keys of obj; where ("top level", "frame 3") goes into messages. */
static int read_cam_keys(const char *path, const char *where, const json_t *obj, cam_keys *ck) {
  memset(ck, 0, sizeof *ck);
  FG_TRY(get_positive(path, where, obj, "fl_x", &ck->has_fl_x, &ck->fl_x));
  FG_TRY(get_positive(path, where, obj, "fl_y", &ck->has_fl_y, &ck->fl_y));
  FG_TRY(get_angle(path, where, obj, "camera_angle_x", &ck->has_angle_x, &ck->angle_x));
  FG_TRY(get_angle(path, where, obj, "camera_angle_y", &ck->has_angle_y, &ck->angle_y));
  FG_TRY(get_number(path, where, obj, "cx", &ck->has_cx, &ck->cx));
  FG_TRY(get_number(path, where, obj, "cy", &ck->has_cy, &ck->cy));
  FG_TRY(get_side(path, where, obj, "w", &ck->has_w, &ck->w));
  FG_TRY(get_side(path, where, obj, "h", &ck->has_h, &ck->h));
  for (int i = 0; i < 5; i++)
    FG_TRY(get_number(path, where, obj, k_names[i], &ck->has_k[i], &ck->k[i]));

  /* instant-ngp marks fisheye data sets with a flag instead of a model name */
  const json_t *fisheye = json_object_get(obj, "is_fisheye");
  if (fisheye && json_is_true(fisheye))
    return fg_fail(FG_EFORMAT, "%s: %s: is_fisheye is true, but fisheye cameras are not "
                   "supported; supported camera models are PINHOLE and OPENCV", path, where);

  const json_t *model = json_object_get(obj, "camera_model");
  if (model && !json_is_null(model)) {
    if (!json_is_string(model))
      return fg_fail(FG_EFORMAT, "%s: %s: camera_model must be a string (PINHOLE or OPENCV), "
                     "got %s", path, where, type_name(model));
    if (fg_camera_model_parse(json_string_value(model), &ck->model) < 0) {
      char detail[512];
      snprintf(detail, sizeof detail, "%s", fg_error_detail());
      return fg_fail(FG_EFORMAT, "%s: %s: %s", path, where, detail);
    }
    ck->has_model = 1;
  }
  return 0;
}

/* The frame's keys over the top level's. Focal length goes per axis as a unit: a frame that
 * gives camera_angle_x replaces a top-level fl_x, since the more specific scope wins. */
static cam_keys merge_keys(const cam_keys *top, const cam_keys *fr) {
  cam_keys m = *top;
  if (fr->has_fl_x || fr->has_angle_x) {
    m.has_fl_x = fr->has_fl_x, m.fl_x = fr->fl_x;
    m.has_angle_x = fr->has_angle_x, m.angle_x = fr->angle_x;
  }
  if (fr->has_fl_y || fr->has_angle_y) {
    m.has_fl_y = fr->has_fl_y, m.fl_y = fr->fl_y;
    m.has_angle_y = fr->has_angle_y, m.angle_y = fr->angle_y;
  }
  if (fr->has_cx) m.has_cx = 1, m.cx = fr->cx;
  if (fr->has_cy) m.has_cy = 1, m.cy = fr->cy;
  if (fr->has_w) m.has_w = 1, m.w = fr->w;
  if (fr->has_h) m.has_h = 1, m.h = fr->h;
  if (fr->has_model) m.has_model = 1, m.model = fr->model;
  for (int i = 0; i < 5; i++)
    if (fr->has_k[i]) m.has_k[i] = 1, m.k[i] = fr->k[i];
  return m;
}

/* Fills the intrinsics that depend on the image size, which cam.w/h now hold. */
static void finish_camera(fg_transforms_frame *f) {
  fg_camera *c = &f->cam;
  if (!f->has_fl_x && f->camera_angle_x > 0) c->fl_x = 0.5 * c->w / tan(0.5 * f->camera_angle_x);
  if (!f->has_fl_y && f->camera_angle_y > 0) c->fl_y = 0.5 * c->h / tan(0.5 * f->camera_angle_y);
  int x_known = f->has_fl_x || f->camera_angle_x > 0;
  int y_known = f->has_fl_y || f->camera_angle_y > 0;
  if (!x_known) c->fl_x = c->fl_y;
  if (!y_known) c->fl_y = c->fl_x;
  if (!f->has_cx) c->cx = 0.5 * c->w;
  if (!f->has_cy) c->cy = 0.5 * c->h;
}

/* Builds frame i's camera from the merged keys. */
static int build_camera(const char *path, size_t i, const cam_keys *m, fg_transforms_frame *f) {
  fg_camera *c = &f->cam;
  memset(c, 0, sizeof *c);
  int distorted = 0;
  c->k1 = m->k[0], c->k2 = m->k[1], c->k3 = m->k[2], c->p1 = m->k[3], c->p2 = m->k[4];
  for (int j = 0; j < 5; j++) distorted |= m->k[j] != 0;
  c->model = m->has_model ? m->model : (distorted ? FG_CAMERA_OPENCV : FG_CAMERA_PINHOLE);
  if (c->model == FG_CAMERA_PINHOLE && distorted)
    return fg_fail(FG_EFORMAT, "%s: frame %zu: camera_model is PINHOLE but distortion "
                   "coefficients are non-zero; set camera_model to \"OPENCV\" or drop them",
                   path, i);

  if (!m->has_fl_x && !m->has_angle_x && !m->has_fl_y && !m->has_angle_y)
    return fg_fail(FG_EFORMAT, "%s: frame %zu: no focal length; give fl_x (pixels) or "
                   "camera_angle_x (radians), at the top level or in the frame", path, i);
  f->has_fl_x = m->has_fl_x;
  f->has_fl_y = m->has_fl_y;
  if (m->has_fl_x) c->fl_x = m->fl_x;
  if (m->has_fl_y) c->fl_y = m->fl_y;
  f->camera_angle_x = m->has_fl_x || !m->has_angle_x ? 0 : m->angle_x;
  f->camera_angle_y = m->has_fl_y || !m->has_angle_y ? 0 : m->angle_y;
  f->has_cx = m->has_cx;
  f->has_cy = m->has_cy;
  if (m->has_cx) c->cx = m->cx;
  if (m->has_cy) c->cy = m->cy;

  if (m->has_w != m->has_h)
    return fg_fail(FG_EFORMAT, "%s: frame %zu: %s is given without %s; give both or neither",
                   path, i, m->has_w ? "w" : "h", m->has_w ? "h" : "w");
  f->has_size = m->has_w;
  if (!f->has_size) {
    /* without a size the frame cannot be complete yet; fill what does not depend on it */
    if (!m->has_fl_x && !m->has_angle_x && m->has_fl_y) c->fl_x = c->fl_y;
    if (!m->has_fl_y && !m->has_angle_y && m->has_fl_x) c->fl_y = c->fl_x;
    return 0;
  }
  c->w = m->w;
  c->h = m->h;
  finish_camera(f);
  if (fg_camera_validate(c) < 0) {
    char detail[512];
    snprintf(detail, sizeof detail, "%s", fg_error_detail());
    return fg_fail(FG_EFORMAT, "%s: frame %zu: %s", path, i, detail);
  }
  return 0;
}

/* ---------------------------------------------------------------- matrix and paths */

static int read_matrix(const char *path, size_t i, const json_t *fo, double T[16]) {
  const json_t *m = json_object_get(fo, "transform_matrix");
  if (!m)
    return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix is missing; give the 4x4 "
                   "camera-to-world matrix as 4 rows of 4 numbers", path, i);
  if (!json_is_array(m))
    return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix must be 4 rows of 4 numbers, "
                   "got %s", path, i, type_name(m));
  if (json_array_size(m) > 0 && json_is_number(json_array_get(m, 0)))
    return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix is a flat list of %zu numbers; "
                   "write it as 4 rows of 4 numbers", path, i, json_array_size(m));
  if (json_array_size(m) != 4)
    return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix has %zu rows; expected 4 rows "
                   "of 4 numbers", path, i, json_array_size(m));
  for (size_t r = 0; r < 4; r++) {
    const json_t *row = json_array_get(m, r);
    if (!json_is_array(row))
      return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix row %zu is %s; expected an "
                     "array of 4 numbers", path, i, r, type_name(row));
    if (json_array_size(row) != 4)
      return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix row %zu has %zu entries; "
                     "expected 4 rows of 4 numbers", path, i, r, json_array_size(row));
    for (size_t c = 0; c < 4; c++) {
      const json_t *v = json_array_get(row, c);
      if (!json_is_number(v))
        return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix[%zu][%zu] is %s; expected "
                       "a number", path, i, r, c, type_name(v));
      T[r * 4 + c] = json_number_value(v);
      if (!isfinite(T[r * 4 + c]))
        return fg_fail(FG_EFORMAT, "%s: frame %zu: transform_matrix[%zu][%zu] is not finite",
                       path, i, r, c);
    }
  }
  return 0;
}

static int is_file(const char *p) {
  struct stat sb;
  return stat(p, &sb) == 0 && S_ISREG(sb.st_mode);
}

/* Finds the file that rel names relative to dir: rel itself, else rel plus one of exts.
 * *out is the malloc'd path, or NULL when there is none. 0 or FG_ENOMEM. */
static int resolve_file(const char *dir, const char *rel, const char *const *exts, char **out) {
  *out = NULL;
  while (rel[0] == '.' && rel[1] == '/') {
    rel += 2;
    while (*rel == '/') rel++;
  }
  char *base = rel[0] == '/' || strcmp(dir, ".") == 0 ? strdup(rel) : fg_path_join(dir, rel);
  if (!base) return fg_fail(FG_ENOMEM, "out of memory");
  if (is_file(base)) {
    *out = base;
    return 0;
  }
  size_t n = strlen(base);
  char *cand = malloc(n + 8);
  if (!cand) {
    free(base);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  for (size_t e = 0; exts[e]; e++) {
    snprintf(cand, n + 8, "%s%s", base, exts[e]);
    if (is_file(cand)) {
      free(base);
      *out = cand;
      return 0;
    }
  }
  free(base);
  free(cand);
  return 0;
}

/* A frame's path key: a non-empty string, or absent (NULL) when optional. */
static int get_path_key(const char *path, size_t i, const json_t *fo, const char *key,
                        int required, const char **out) {
  const json_t *v = json_object_get(fo, key);
  *out = NULL;
  if (!v || json_is_null(v)) {
    if (required)
      return fg_fail(FG_EFORMAT, "%s: frame %zu: %s is missing; give the image's path relative "
                     "to the transforms file", path, i, key);
    return 0;
  }
  if (!json_is_string(v) || json_string_length(v) == 0)
    return fg_fail(FG_EFORMAT, "%s: frame %zu: %s must be a non-empty path string, got %s", path,
                   i, key, json_is_string(v) ? "an empty string" : type_name(v));
  if (strlen(json_string_value(v)) != json_string_length(v))
    return fg_fail(FG_EFORMAT, "%s: frame %zu: %s holds a NUL character", path, i, key);
  *out = json_string_value(v);
  return 0;
}

/* ---------------------------------------------------------------- frames */

static void frame_free(fg_transforms_frame *f) {
  free(f->image_path);
  free(f->file_path);
  free(f->features_path);
  free(f->depth_path);
}

/* depth_unit_scale_factor of obj into *scale when present: a number > 0. */
static int get_depth_scale(const char *path, const char *where, const json_t *obj,
                           double *scale) {
  int has;
  double v;
  FG_TRY(get_number(path, where, obj, "depth_unit_scale_factor", &has, &v));
  if (has && !(v > 0))
    return fg_fail(FG_EFORMAT, "%s: %s: depth_unit_scale_factor must be > 0 (metres per unit of "
                   "the depth images, 0.001 for millimetres), got %g", path, where, v);
  if (has) *scale = v;
  return 0;
}

static int read_frame(const char *path, const char *dir, size_t i, const json_t *fo,
                      const cam_keys *top, double depth_scale, fg_transforms_frame *f) {
  char where[48];
  snprintf(where, sizeof where, "frame %zu", i);
  if (!json_is_object(fo))
    return fg_fail(FG_EFORMAT, "%s: frame %zu must be an object with file_path and "
                   "transform_matrix, got %s", path, i, type_name(fo));
  cam_keys own, merged;
  FG_TRY(read_cam_keys(path, where, fo, &own));
  merged = merge_keys(top, &own);
  FG_TRY(build_camera(path, i, &merged, f));
  FG_TRY(read_matrix(path, i, fo, f->T_world_cam));

  const char *file_path, *features_path, *depth_path;
  FG_TRY(get_path_key(path, i, fo, "file_path", 1, &file_path));
  FG_TRY(get_path_key(path, i, fo, "features_path", 0, &features_path));
  FG_TRY(get_path_key(path, i, fo, "depth_file_path", 0, &depth_path));
  f->depth_scale = depth_scale;
  FG_TRY(get_depth_scale(path, where, fo, &f->depth_scale));
  if (depth_path) {
    FG_TRY(resolve_file(dir, depth_path, image_exts, &f->depth_path));
    if (!f->depth_path) FG_TRY(resolve_file(dir, depth_path, features_exts, &f->depth_path));
    f->depth_missing = !f->depth_path;
  }
  f->file_path = strdup(file_path);
  if (!f->file_path) return fg_fail(FG_ENOMEM, "out of memory");
  FG_TRY(resolve_file(dir, file_path, image_exts, &f->image_path));
  if (features_path) {
    FG_TRY(resolve_file(dir, features_path, features_exts, &f->features_path));
    /* a frame without its image is skipped on import, so its features do not matter */
    if (!f->features_path && f->image_path)
      return fg_fail(FG_ENOENT, "%s: frame %zu: features_path \"%s\" names no file (looked in "
                     "%s, also with .npy appended); add the file or drop the key", path, i,
                     features_path, dir);
  }
  return 0;
}

static char *folder_of(const char *path) {
  const char *slash = strrchr(path, '/');
  if (!slash) return strdup(".");
  if (slash == path) return strdup("/");
  return strndup(path, (size_t)(slash - path));
}

int fg_transforms_load(const char *path, fg_transforms *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_transforms_load: no output given");
  memset(out, 0, sizeof *out);
  if (!path || !path[0]) return fg_fail(FG_EINVAL, "no transforms file given");

  /* jansson reports a missing file as a parse error; tell the two apart first */
  struct stat sb;
  if (stat(path, &sb) != 0)
    return fg_fail(errno == ENOENT ? FG_ENOENT : FG_EIO, "%s: cannot open: %s", path,
                   strerror(errno));
  if (!S_ISREG(sb.st_mode))
    return fg_fail(FG_EINVAL, "%s is not a file; name the transforms .json file itself", path);

  json_error_t jerr;
  json_t *root = json_load_file(path, 0, &jerr);
  if (!root) {
    if (json_error_code(&jerr) == json_error_cannot_open_file)
      return fg_fail(FG_EIO, "%s: cannot open: %s", path, jerr.text);
    return fg_fail(FG_EFORMAT, "%s: line %d, column %d: %s (the file is not valid JSON)", path,
                   jerr.line, jerr.column, jerr.text);
  }

  int rc = 0;
  char *dir = NULL;
  fg_transforms_frame *frames = NULL;
  size_t n = 0, n_missing = 0, n_depth_missing = 0;
  if (!json_is_object(root)) {
    rc = fg_fail(FG_EFORMAT, "%s: the top level must be an object with a \"frames\" array, got %s",
                 path, type_name(root));
    goto error;
  }
  const json_t *jframes = json_object_get(root, "frames");
  if (!json_is_array(jframes) || json_array_size(jframes) == 0) {
    rc = fg_fail(FG_EFORMAT, "%s: \"frames\" must be a non-empty array of frames, got %s", path,
                 !jframes ? "nothing" : json_is_array(jframes) ? "an empty array"
                                                               : type_name(jframes));
    goto error;
  }
  cam_keys top;
  rc = read_cam_keys(path, "top level", root, &top);
  if (rc < 0) goto error;
  double depth_scale = FG_DEPTH_DEFAULT_SCALE;
  rc = get_depth_scale(path, "top level", root, &depth_scale);
  if (rc < 0) goto error;

  dir = folder_of(path);
  n = json_array_size(jframes);
  frames = calloc(n, sizeof *frames);
  if (!dir || !frames) {
    rc = fg_fail(FG_ENOMEM, "out of memory");
    goto error;
  }
  for (size_t i = 0; i < n; i++) {
    rc = read_frame(path, dir, i, json_array_get(jframes, i), &top, depth_scale, &frames[i]);
    if (rc < 0) goto error;
    if (!frames[i].image_path) n_missing++;
    else if (frames[i].depth_missing) n_depth_missing++;
  }
  free(dir);
  json_decref(root);
  out->frames = frames;
  out->n_frames = n;
  out->n_missing = n_missing;
  out->n_depth_missing = n_depth_missing;
  return 0;

error:
  if (frames)
    for (size_t i = 0; i < n; i++) frame_free(&frames[i]);
  free(frames);
  free(dir);
  json_decref(root);
  return rc;
}

void fg_transforms_frame_set_camera(fg_transforms_frame *f, const fg_camera *cam) {
  f->cam = *cam;
  f->has_size = 1;
  f->has_fl_x = f->has_fl_y = f->has_cx = f->has_cy = 1;
  f->camera_angle_x = f->camera_angle_y = 0;
}

int fg_transforms_complete_camera(fg_transforms_frame *f, int image_w, int image_h) {
  if (!f) return fg_fail(FG_EINVAL, "no frame given");
  const char *name = f->file_path ? f->file_path : "?";
  if (image_w <= 0 || image_h <= 0)
    return fg_fail(FG_EINVAL, "frame \"%s\": image size %dx%d is not positive", name, image_w,
                   image_h);
  if (f->has_size && (f->cam.w != image_w || f->cam.h != image_h))
    return fg_fail(FG_EINVAL, "frame \"%s\": the image is %dx%d pixels but the transforms file "
                   "says w %d, h %d; fix w/h or use the image they describe", name, image_w,
                   image_h, f->cam.w, f->cam.h);
  f->cam.w = image_w;
  f->cam.h = image_h;
  finish_camera(f);
  if (fg_camera_validate(&f->cam) < 0) {
    char detail[512];
    snprintf(detail, sizeof detail, "%s", fg_error_detail());
    return fg_fail(FG_EINVAL, "frame \"%s\": %s", name, detail);
  }
  return 0;
}

void fg_transforms_free(fg_transforms *t) {
  if (!t) return;
  for (size_t i = 0; i < t->n_frames; i++) frame_free(&t->frames[i]);
  free(t->frames);
  memset(t, 0, sizeof *t);
}
