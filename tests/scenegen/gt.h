/* gt.json of a fieldgrip-scenegen data set: writing an object's shape parameters, and
 * reading the whole file back for tests (object poses, analytic shapes for inside tests,
 * grasps, class embeddings).
 *
 * gt.json layout (world frame of SPEC.md, metres, quaternions [w, x, y, z]):
 *   seed, background_rgb [3] (sRGB-encoded, [0, 1]; what rays that miss the table show),
 *   width, height, views, feature_dim, patch, feature_grid [h, w], noise,
 *   look_at, camera_radius, light {direction, ambient}, table {min, max},
 *   classes [{name, embedding [D]}]          (index = mask value),
 *   objects [{name, class (index into classes), pose {position, quaternion, matrix},
 *             size [3] (edge lengths of the object-frame bounding box),
 *             aabb {min, max} (world), shape {type, parameters of shapes.h},
 *             albedo [3] (linear RGB),
 *             grasp {position, quaternion, matrix, width}}],
 *   masks "masks/NNNN.png", mask_values (a sentence: pixel = class index, an object's "class"),
 *   and only with depth maps: depth ("png" or "npy", scenegen's --depth), depth_maps
 *   ("depth/NNNN.png" or ".npy"), depth_values (a sentence: the unit and what 0 means).
 * The object's pose is its object frame (shapes.h): origin on its vertical axis at half its
 * height. The grasp is the gripper frame of SPEC.md (TCP between the fingertips, +z the
 * approach direction, +y the closing axis); width is the distance between the contacts. */
#ifndef SG_GT_H
#define SG_GT_H

#include <jansson.h>
#include <stdint.h>

#include "shapes.h"

#define SG_GT_NAME_MAX 32

typedef struct sg_gt_object {
  char name[SG_GT_NAME_MAX];
  int class_id;
  sg_shape shape;          /* T_world_obj from the pose, parameters from "shape" */
  double position[3];      /* world, metres */
  double quaternion[4];    /* w, x, y, z */
  double size[3];
  double aabb_min[3], aabb_max[3];
  double T_world_grasp[16];
  double grasp_width_m;
} sg_gt_object;

typedef struct sg_gt {
  uint64_t seed;
  float background_rgb[3];
  int width, height, views, feature_dim, patch;
  int n_classes;
  char (*class_names)[SG_GT_NAME_MAX]; /* n_classes; owned */
  float *embeddings;                   /* (n_classes, feature_dim); owned */
  int n_objects;
  sg_gt_object *objects;               /* owned */
  double table_min[3], table_max[3];
} sg_gt;

/* The "shape" object of gt.json for a shape (a new reference the caller owns). */
json_t *sg_shape_to_json(const sg_shape *s);

/* Reads a "shape" object back into s, with the pose T_world_obj. 0, or FG_EFORMAT with a
 * detail (fg_error_detail). */
int sg_shape_from_json(const json_t *j, const double T_world_obj[16], sg_shape *s);

/* Loads gt.json. 0 on success (the caller frees *out with sg_gt_free), or a negative FG_E*
 * code with a detail; on failure *out holds nothing to free. */
int sg_gt_load(const char *path, sg_gt *out);

void sg_gt_free(sg_gt *gt);

/* Index of a class by name, or -1. */
int sg_gt_class(const sg_gt *gt, const char *name);

/* 1 when p_world lies inside object k's solid. */
int sg_gt_inside(const sg_gt *gt, int k, const double p_world[3]);

#endif
