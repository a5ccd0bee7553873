/* POST /v1/scenes/{s}/render: an image of the scene's trained field from a camera, as PNG:
 * colour, depth, surface normals or a query's heatmap. Runs on the offload pool; the PNG is
 * encoded by a fieldgrip-decode child (decoder.h). */
#include "api.h"
#include "api_decode.h"
#include "decoder/decoder.h"
#include "state/json.h"
#include "state/scene_voxels.h"
#include "metrics/metrics.h"
#include "api_query.h"

#include "core/error.h"
#include "core/pose.h"
#include "field/image.h"
#include "query/heatmap_view.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static const char *const camera_keys[] = {"fl_x", "fl_y", "cx", "cy", "w", "h", "camera_model",
                                          "k1", "k2", "k3", "p1", "p2", "camera_angle_x",
                                          "camera_angle_y"};
#define N_CAMERA_KEYS (sizeof camera_keys / sizeof camera_keys[0])

static int is_camera_key(const char *k) {
  for (size_t i = 0; i < N_CAMERA_KEYS; i++)
    if (strcmp(k, camera_keys[i]) == 0) return 1;
  return 0;
}

/* Takes the pose keys (transform_matrix, pose, convention) of src into *matrix, *pose and
 * *convention (borrowed) and its intrinsics into merged, refusing any other key and any key
 * given twice. top_level skips "camera", "output" and the query keys (api_query.h); where names
 * src in messages. */
static int collect(json_t *src, const char *where, int top_level, json_t *merged,
                   json_t **matrix, json_t **pose, json_t **convention) {
  const char *key;
  json_t *v;
  json_object_foreach(src, key, v) {
    if (top_level && (strcmp(key, "camera") == 0 || strcmp(key, "output") == 0 ||
                      fg_query_is_key(key)))
      continue;
    json_t **slot = strcmp(key, "transform_matrix") == 0 ? matrix
                    : strcmp(key, "pose") == 0           ? pose
                    : strcmp(key, "convention") == 0     ? convention
                                                         : NULL;
    if (slot) {
      if (*slot) return fg_fail(FG_EINVAL, "\"%s\" is given twice (in \"camera\" and at the top "
                                "level); give it once", key);
      *slot = v;
      continue;
    }
    if (!is_camera_key(key))
      return fg_fail(FG_EINVAL, "unknown key \"%s\" in %s; a render takes \"camera\" "
                     "{transform_matrix or pose, fl_x, fl_y, cx, cy, w, h}, \"convention\", "
                     "\"output\" and, for \"heatmap\", a query (\"text\" or \"embedding\", ...)",
                     key, where);
    if (json_object_get(merged, key))
      return fg_fail(FG_EINVAL, "\"%s\" is given twice (in \"camera\" and at the top level); "
                     "give it once", key);
    json_object_set(merged, key, v);
  }
  return 0;
}

/* Parses the body but its query; answers 400 itself and returns -1 when it cannot be
 * rendered. */
int fg_api_parse_render(json_t *body, fg_api_render_req *r, fg_resp *resp) {
  json_t *camobj = json_object_get(body, "camera");
  if (camobj && !json_is_object(camobj))
    return fg_resp_error(resp, 400, "invalid_camera", "\"camera\" must be an object: "
                         "{\"transform_matrix\": 4x4, \"fl_x\", \"fl_y\", \"cx\", \"cy\", \"w\", "
                         "\"h\"}"), -1;
  json_t *merged = json_object();
  json_t *matrix = NULL, *pose = NULL, *convention = NULL;
  int rc = camobj ? collect(camobj, "\"camera\"", 0, merged, &matrix, &pose, &convention) : 0;
  if (rc == 0) rc = collect(body, "the body", 1, merged, &matrix, &pose, &convention);
  if (rc != 0) {
    json_decref(merged);
    return fg_resp_error(resp, 400, "invalid_request", "%s", fg_error_detail()), -1;
  }
  const char *output = "rgb";
  if (fg_json_string(body, "output", &output) < 0) {
    json_decref(merged);
    return fg_resp_error(resp, 400, "invalid_request", "%s", fg_error_detail()), -1;
  }
  if (strcmp(output, "rgb") != 0 && strcmp(output, "depth") != 0 &&
      strcmp(output, "normal") != 0 && strcmp(output, "heatmap") != 0) {
    json_decref(merged);
    return fg_resp_error(resp, 400, "invalid_request", "\"output\" must be \"rgb\" (8-bit sRGB "
                         "PNG), \"depth\" (16-bit PNG of z-depth in millimetres), \"normal\" "
                         "(8-bit PNG of world-frame surface normals, RGB = 127.5 (n + 1)) or "
                         "\"heatmap\" (with a query), got \"%.40s\"", output), -1;
  }
  r->depth = strcmp(output, "depth") == 0;
  r->normal = strcmp(output, "normal") == 0;
  r->heatmap = strcmp(output, "heatmap") == 0;
  if (!r->heatmap && fg_query_present(body)) {
    json_decref(merged);
    return fg_resp_error(resp, 400, "invalid_request", "the query keys (\"text\", "
                         "\"embedding\", \"negatives\", \"negative_embeddings\", "
                         "\"temperature\") go with \"output\": \"heatmap\" only"), -1;
  }

  if (matrix && pose) rc = fg_fail(FG_EINVAL, "give either \"transform_matrix\" or \"pose\"");
  else if (!matrix && !pose)
    rc = fg_fail(FG_EINVAL, "the camera needs \"transform_matrix\" (4x4 camera-to-world, "
                 "row-major) or \"pose\" {\"position\", \"quaternion\"}");
  else rc = fg_json_pose_parse(matrix ? matrix : pose, matrix ? "transform_matrix" : "pose",
                              r->T_world_cam, NULL);
  if (rc != 0) {
    json_decref(merged);
    return fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail()), -1;
  }
  fg_convention conv = FG_CONV_OPENGL;
  if (convention && (!json_is_string(convention) ||
                     fg_convention_parse(json_string_value(convention), &conv) != 0)) {
    json_decref(merged);
    return fg_resp_error(resp, 400, "invalid_request", "\"convention\" must be \"opengl\" or "
                         "\"opencv\""), -1;
  }
  if (conv == FG_CONV_OPENCV) fg_pose_flip_yz(r->T_world_cam);

  fg_transforms_frame tf;
  memset(&tf, 0, sizeof tf);
  tf.file_path = "camera";
  rc = fg_json_camera(merged, 1, &tf);
  json_decref(merged);
  if (rc == 0 && !tf.has_size)
    rc = fg_fail(FG_EINVAL, "the camera needs \"w\" and \"h\": the size of the image to render, "
                 "in pixels");
  if (rc == 0 && (tf.cam.w > FG_API_RENDER_MAX_SIDE || tf.cam.h > FG_API_RENDER_MAX_SIDE))
    rc = fg_fail(FG_EINVAL, "a render is at most %dx%d pixels; %dx%d asked", FG_API_RENDER_MAX_SIDE,
                 FG_API_RENDER_MAX_SIDE, tf.cam.w, tf.cam.h);
  if (rc == 0) rc = fg_transforms_complete_camera(&tf, tf.cam.w, tf.cam.h);
  if (rc == 0 && fg_camera_is_distorted(&tf.cam))
    rc = fg_fail(FG_EINVAL, "renders use a pinhole camera; leave out the distortion "
                 "coefficients k1 k2 k3 p1 p2");
  if (rc != 0) return fg_resp_error(resp, 400, "invalid_camera", "%s", fg_error_detail()), -1;
  r->cam = tf.cam;
  return 0;
}

/* Answers the render's pixels as a PNG, encoded in a decoder child. */
static void send_png(fg_req *req, fg_resp *resp, const fg_api_render_req *r, const void *pixels) {
  uint8_t *png = NULL;
  size_t png_len = 0;
  if (fg_decoder_encode_png(req->app->decoder, pixels, r->cam.w, r->cam.h, r->depth ? 1 : 3,
                            r->depth ? 16 : 8, &png, &png_len) != 0)
    fg_resp_error(resp, 500, "internal_error", "cannot encode the PNG: %s", fg_error_detail());
  else
    fg_resp_take(resp, 200, "image/png", (char *)png, png_len);
}

int fg_api_scene_render(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = fg_api_body_object(req, resp);
  fg_field_ref *ref = NULL;
  void *pixels = NULL;
  fg_query q = {0};
  if (!body) goto out;
  fg_api_render_req r;
  if (fg_api_parse_render(body, &r, resp) != 0) goto out;
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  /* The query is checked first, against the trained field's D, else the frames'. */
  if (r.heatmap && fg_query_parse(req, resp, body, info.field_feature_dim ? info.field_feature_dim
                                  : info.feature_dim, &q) != 0)
    goto out;
  ref = fg_api_scene_field(s, resp);
  if (!ref) goto out;
  const fg_field *field = fg_field_ref_field(ref);
  int rc = r.heatmap ? fg_field_features_fit(field, info.name, q.dim,
                                                "a query has nothing to score") : 0;
  if (rc != 0) {
    fg_api_fail(resp, rc);
    goto out;
  }
  size_t n = (size_t)r.cam.w * (size_t)r.cam.h;
  pixels = malloc(n * (r.depth ? sizeof(uint16_t) : 3));
  if (!pixels) {
    fg_resp_error(resp, 500, "internal_error", "out of memory for a %dx%d render", r.cam.w,
                  r.cam.h);
    goto out;
  }
  float bg[3] = {(float)info.params.background[0], (float)info.params.background[1],
                 (float)info.params.background[2]};
  int threads = fg_conf_threads(req->conf);
  /* Normals read the density half a voxel of the scene's grid to either side: the surface the
   * voxels show, not the hash grid's millimetre-scale roughness. */
  const float step_m = (float)(0.5 * info.params.voxel_size);
  const fg_field_image_kind kind = r.depth    ? FG_FIELD_IMAGE_DEPTH
                                   : r.normal ? FG_FIELD_IMAGE_NORMAL
                                              : FG_FIELD_IMAGE_RGB;
  rc = r.heatmap ? fg_heatmap_render_view(field, r.T_world_cam, &r.cam, &q, bg, threads, pixels)
                 : fg_field_render_image(field, r.T_world_cam, &r.cam, kind, bg, step_m, threads,
                                         pixels);
  if (rc != 0) {
    fg_resp_error(resp, 500, "internal_error", "render failed: %s", fg_error_detail());
    goto out;
  }
  if (r.heatmap) fg_metrics_count_heatmap(FG_METRICS_HEATMAP_RENDER);
  fg_field_ref_release(ref);
  ref = NULL;
  send_png(req, resp, &r, pixels);
out:
  fg_query_release(&q);
  fg_field_ref_release(ref);
  free(pixels);
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}
