/* gt.json shape parameters and the reader for tests (gt.h). */
#include "gt.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/pose.h"

/* ---------------------------------------------------------------- writing */

static json_t *vec_json(const double *v, int n) {
  json_t *a = json_array();
  for (int i = 0; i < n; i++) json_array_append_new(a, json_real(v[i]));
  return a;
}

json_t *sg_shape_to_json(const sg_shape *s) {
  json_t *j = json_object();
  json_object_set_new(j, "type", json_string(sg_shape_type_name(s->type)));
  switch (s->type) {
  case SG_SHAPE_MUG:
    json_object_set_new(j, "outer_radius", json_real(s->outer_radius));
    json_object_set_new(j, "inner_radius", json_real(s->inner_radius));
    json_object_set_new(j, "height", json_real(s->height));
    json_object_set_new(j, "bottom", json_real(s->bottom));
    json_object_set_new(j, "handle_center", vec_json(s->handle_center, 3));
    json_object_set_new(j, "handle_major", json_real(s->handle_major));
    json_object_set_new(j, "handle_minor", json_real(s->handle_minor));
    json_object_set_new(j, "handle_clip_radius", json_real(s->handle_clip_radius));
    break;
  case SG_SHAPE_BOWL:
    json_object_set_new(j, "outer_radius", json_real(s->outer_radius));
    json_object_set_new(j, "inner_radius", json_real(s->inner_radius));
    json_object_set_new(j, "height", json_real(s->height));
    json_object_set_new(j, "sphere_center_z", json_real(s->sphere_center_z));
    break;
  case SG_SHAPE_BOX: json_object_set_new(j, "size", vec_json(s->size, 3)); break;
  case SG_SHAPE_BALL: json_object_set_new(j, "radius", json_real(s->radius)); break;
  }
  return j;
}

/* ---------------------------------------------------------------- reading */

static int get_num(const json_t *o, const char *key, double *out) {
  const json_t *v = json_object_get(o, key);
  if (!json_is_number(v)) return fg_fail(FG_EFORMAT, "gt.json: \"%s\" is not a number", key);
  *out = json_number_value(v);
  return 0;
}

static int get_vec(const json_t *o, const char *key, double *out, size_t n) {
  const json_t *a = json_object_get(o, key);
  if (!json_is_array(a) || json_array_size(a) != n)
    return fg_fail(FG_EFORMAT, "gt.json: \"%s\" is not an array of %zu numbers", key, n);
  for (size_t i = 0; i < n; i++) {
    const json_t *v = json_array_get(a, i);
    if (!json_is_number(v))
      return fg_fail(FG_EFORMAT, "gt.json: \"%s\"[%zu] is not a number", key, i);
    out[i] = json_number_value(v);
  }
  return 0;
}

static int get_int(const json_t *o, const char *key, int *out) {
  const json_t *v = json_object_get(o, key);
  if (!json_is_integer(v)) return fg_fail(FG_EFORMAT, "gt.json: \"%s\" is not an integer", key);
  *out = (int)json_integer_value(v);
  return 0;
}

int sg_shape_from_json(const json_t *j, const double T_world_obj[16], sg_shape *s) {
  memset(s, 0, sizeof *s);
  const char *type = json_string_value(json_object_get(j, "type"));
  if (!type) return fg_fail(FG_EFORMAT, "gt.json: shape without a \"type\"");
  memcpy(s->T_world_obj, T_world_obj, sizeof s->T_world_obj);
  if (strcmp(type, "mug") == 0) {
    s->type = SG_SHAPE_MUG;
    FG_TRY(get_num(j, "outer_radius", &s->outer_radius));
    FG_TRY(get_num(j, "inner_radius", &s->inner_radius));
    FG_TRY(get_num(j, "height", &s->height));
    FG_TRY(get_num(j, "bottom", &s->bottom));
    FG_TRY(get_vec(j, "handle_center", s->handle_center, 3));
    FG_TRY(get_num(j, "handle_major", &s->handle_major));
    FG_TRY(get_num(j, "handle_minor", &s->handle_minor));
    FG_TRY(get_num(j, "handle_clip_radius", &s->handle_clip_radius));
  } else if (strcmp(type, "bowl") == 0) {
    s->type = SG_SHAPE_BOWL;
    FG_TRY(get_num(j, "outer_radius", &s->outer_radius));
    FG_TRY(get_num(j, "inner_radius", &s->inner_radius));
    FG_TRY(get_num(j, "height", &s->height));
    FG_TRY(get_num(j, "sphere_center_z", &s->sphere_center_z));
  } else if (strcmp(type, "box") == 0) {
    s->type = SG_SHAPE_BOX;
    FG_TRY(get_vec(j, "size", s->size, 3));
  } else if (strcmp(type, "ball") == 0) {
    s->type = SG_SHAPE_BALL;
    FG_TRY(get_num(j, "radius", &s->radius));
  } else {
    return fg_fail(FG_EFORMAT, "gt.json: unknown shape type \"%s\"", type);
  }
  sg_shape_finish(s); /* the inverse pose and the bounding sphere need the sizes above */
  return 0;
}

static int load_pose(const json_t *o, const char *key, double p[3], double q[4], double T[16]) {
  const json_t *pose = json_object_get(o, key);
  if (!json_is_object(pose)) return fg_fail(FG_EFORMAT, "gt.json: \"%s\" is not an object", key);
  FG_TRY(get_vec(pose, "position", p, 3));
  FG_TRY(get_vec(pose, "quaternion", q, 4));
  return fg_pose_from_quat(p, q, T);
}

static int load_object(const json_t *jo, int n_classes, sg_gt_object *ob) {
  const char *name = json_string_value(json_object_get(jo, "name"));
  if (!name || strlen(name) >= SG_GT_NAME_MAX)
    return fg_fail(FG_EFORMAT, "gt.json: bad object name");
  snprintf(ob->name, sizeof ob->name, "%s", name);
  FG_TRY(get_int(jo, "class", &ob->class_id));
  if (ob->class_id < 0 || ob->class_id >= n_classes)
    return fg_fail(FG_EFORMAT, "gt.json: object %s has class %d of %d", name, ob->class_id,
                   n_classes);
  double T[16];
  FG_TRY(load_pose(jo, "pose", ob->position, ob->quaternion, T));
  FG_TRY(get_vec(jo, "size", ob->size, 3));
  const json_t *aabb = json_object_get(jo, "aabb");
  FG_TRY(get_vec(aabb, "min", ob->aabb_min, 3));
  FG_TRY(get_vec(aabb, "max", ob->aabb_max, 3));
  FG_TRY(sg_shape_from_json(json_object_get(jo, "shape"), T, &ob->shape));
  double gp[3], gq[4];
  FG_TRY(load_pose(jo, "grasp", gp, gq, ob->T_world_grasp));
  FG_TRY(get_num(json_object_get(jo, "grasp"), "width", &ob->grasp_width_m));
  return 0;
}

static int load_root(const json_t *root, sg_gt *gt) {
  json_int_t seed = json_integer_value(json_object_get(root, "seed"));
  gt->seed = (uint64_t)seed;
  double bg[3];
  FG_TRY(get_vec(root, "background_rgb", bg, 3));
  for (int i = 0; i < 3; i++) gt->background_rgb[i] = (float)bg[i];
  FG_TRY(get_int(root, "width", &gt->width));
  FG_TRY(get_int(root, "height", &gt->height));
  FG_TRY(get_int(root, "views", &gt->views));
  FG_TRY(get_int(root, "feature_dim", &gt->feature_dim));
  FG_TRY(get_int(root, "patch", &gt->patch));
  const json_t *table = json_object_get(root, "table");
  FG_TRY(get_vec(table, "min", gt->table_min, 3));
  FG_TRY(get_vec(table, "max", gt->table_max, 3));

  const json_t *classes = json_object_get(root, "classes");
  if (!json_is_array(classes) || json_array_size(classes) == 0 || gt->feature_dim < 1)
    return fg_fail(FG_EFORMAT, "gt.json: no classes or no feature_dim");
  gt->n_classes = (int)json_array_size(classes);
  gt->class_names = calloc((size_t)gt->n_classes, sizeof *gt->class_names);
  gt->embeddings = calloc((size_t)gt->n_classes * (size_t)gt->feature_dim, sizeof(float));
  if (!gt->class_names || !gt->embeddings) return fg_fail(FG_ENOMEM, "gt.json: out of memory");
  for (int k = 0; k < gt->n_classes; k++) {
    const json_t *c = json_array_get(classes, (size_t)k);
    const char *name = json_string_value(json_object_get(c, "name"));
    const json_t *e = json_object_get(c, "embedding");
    if (!name || strlen(name) >= SG_GT_NAME_MAX || !json_is_array(e) ||
        json_array_size(e) != (size_t)gt->feature_dim)
      return fg_fail(FG_EFORMAT, "gt.json: class %d lacks a name or a %d-long embedding", k,
                     gt->feature_dim);
    snprintf(gt->class_names[k], SG_GT_NAME_MAX, "%s", name);
    for (int i = 0; i < gt->feature_dim; i++)
      gt->embeddings[(size_t)k * gt->feature_dim + i] =
          (float)json_number_value(json_array_get(e, (size_t)i));
  }

  const json_t *objects = json_object_get(root, "objects");
  if (!json_is_array(objects)) return fg_fail(FG_EFORMAT, "gt.json: no \"objects\" array");
  gt->n_objects = (int)json_array_size(objects);
  gt->objects = calloc((size_t)gt->n_objects + 1, sizeof *gt->objects);
  if (!gt->objects) return fg_fail(FG_ENOMEM, "gt.json: out of memory");
  for (int k = 0; k < gt->n_objects; k++)
    FG_TRY(load_object(json_array_get(objects, (size_t)k), gt->n_classes, &gt->objects[k]));
  return 0;
}

int sg_gt_load(const char *path, sg_gt *out) {
  memset(out, 0, sizeof *out);
  json_error_t err;
  json_t *root = json_load_file(path, 0, &err);
  if (!root)
    return fg_fail(FG_EFORMAT, "%s:%d:%d: %s", path, err.line, err.column, err.text);
  int rc = load_root(root, out);
  json_decref(root);
  if (rc != 0) sg_gt_free(out);
  return rc;
}

void sg_gt_free(sg_gt *gt) {
  free(gt->class_names);
  free(gt->embeddings);
  free(gt->objects);
  memset(gt, 0, sizeof *gt);
}

int sg_gt_class(const sg_gt *gt, const char *name) {
  for (int k = 0; k < gt->n_classes; k++)
    if (strcmp(gt->class_names[k], name) == 0) return k;
  return -1;
}

int sg_gt_inside(const sg_gt *gt, int k, const double p_world[3]) {
  if (k < 0 || k >= gt->n_objects) return 0;
  return sg_shape_inside(&gt->objects[k].shape, p_world);
}
