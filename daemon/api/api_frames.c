/* Frames: upload one (multipart), import a data set folder, list, and a frame's image. */
#include "api.h"
#include "api_decode.h"
#include "decoder/decoder.h"
#include "api_views.h"
#include "cell/frames.h"
#include "state/ingest.h"
#include "state/jobs.h"
#include "state/json.h"

#include "core/error.h"
#include "core/pose.h"
#include "io/depth.h"
#include "io/npy.h"
#include "io/transforms.h"

#include <errno.h>
#include <math.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>

static void reply_added(fg_resp *resp, int status, const fg_frame *f, int index) {
  json_t *features = f->feat_d ? json_pack("{s:i,s:i,s:i}", "h", f->feat_h, "w", f->feat_w, "d",
                                           f->feat_d)
                               : json_null();
  json_t *depth = f->depth_w ? json_pack("{s:i,s:i,s:f}", "w", f->depth_w, "h", f->depth_h,
                                         "valid_fraction", f->depth_valid)
                             : json_null();
  fg_resp_json(resp, status, json_pack("{s:i,s:I,s:{s:i,s:i},s:o,s:o}", "frame", index,
                                       "capture", (json_int_t)f->capture, "image", "w",
                                       f->cam.w, "h", f->cam.h, "features", features, "depth",
                                       depth));
}

/* "capture" of an upload's meta or an import's body: absent, null or "latest" (0: the
 * newest), "new" (a new one of scene s), or a number from 1 to FG_CAPTURE_MAX. 0, or -1
 * after answering 400. */
static int parse_capture(json_t *obj, fg_scene *s, int64_t *out, fg_resp *resp) {
  json_t *v = json_object_get(obj, "capture");
  const char *str = json_string_value(v);
  *out = 0;
  if (!v || json_is_null(v) || (str && strcmp(str, "latest") == 0)) return 0;
  if (str && strcmp(str, "new") == 0) {
    *out = fg_scene_new_capture(s);
    return 0;
  }
  if (json_is_integer(v) && json_integer_value(v) >= 1 &&
      json_integer_value(v) <= FG_CAPTURE_MAX) {
    *out = json_integer_value(v);
    return 0;
  }
  return fg_resp_error(resp, 400, "invalid_request", "\"capture\" must be \"latest\" (the "
                       "default: the scene's newest capture), \"new\" or a capture number from "
                       "1 to %lld", (long long)FG_CAPTURE_MAX), -1;
}

/* ---------------------------------------------------------------- upload */

/* Reads the pose and camera of an upload's meta part. */
int fg_api_parse_meta(json_t *meta, double T[16], fg_transforms_frame *camera, fg_resp *resp) {
  json_t *pose = json_object_get(meta, "transform_matrix");
  const char *what = "transform_matrix";
  if (!pose) {
    pose = json_object_get(meta, "pose");
    what = "pose";
  }
  if (!pose)
    return fg_resp_error(resp, 400, "invalid_pose", "meta needs \"transform_matrix\" (4x4 "
                         "camera-to-world, row-major) or \"pose\" {\"position\", \"quaternion\"}"),
           -1;
  if (fg_json_pose_parse(pose, what, T, NULL) != 0)
    return fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail()), -1;
  const char *conv_name = "opengl";
  fg_convention conv;
  if (fg_json_string(meta, "convention", &conv_name) < 0 ||
      fg_convention_parse(conv_name, &conv) != 0)
    return fg_resp_error(resp, 400, "invalid_request", "%s", fg_error_detail()), -1;
  if (conv == FG_CONV_OPENCV) fg_pose_flip_yz(T);
  json_t *camobj = json_object_get(meta, "camera");
  memset(camera, 0, sizeof *camera);
  camera->file_path = "upload";
  if (fg_json_camera(camobj ? camobj : meta, camobj != NULL, camera) != 0)
    return fg_resp_error(resp, 400, "invalid_camera", "%s", fg_error_detail()), -1;
  return 0;
}

/* meta's optional depth_scale (metres per unit of an integer depth image). */
int fg_api_parse_depth_scale(json_t *meta, int has_depth, const char *source, double *scale,
                             fg_resp *resp) {
  json_t *v = json_object_get(meta, "depth_scale");
  if (!v) return 0;
  if (!has_depth)
    return fg_resp_error(resp, 400, "invalid_depth", "frame '%s': meta has depth_scale but the "
                         "upload has no 'depth' part", source), -1;
  if (!json_is_number(v) || !(json_number_value(v) > 0.0) || !isfinite(json_number_value(v)))
    return fg_resp_error(resp, 400, "invalid_depth", "frame '%s': depth_scale must be a number "
                         "> 0 (metres per unit of the depth image: 0.001 for millimetres)",
                         source), -1;
  *scale = json_number_value(v);
  return 0;
}

/* Reads an upload's parts into *in (its features parsed into *feats, its meta kept in *meta,
 * which the caller releases). Answers 400 itself and returns -1 when they are wrong. */
static int parse_upload(const fg_req *req, json_t **meta, fg_npy *feats, fg_ingest_input *in,
                        fg_resp *resp) {
  const fg_part *image = fg_req_part(req, "image");
  const fg_part *meta_part = fg_req_part(req, "meta");
  const fg_part *feat_part = fg_req_part(req, "features");
  const fg_part *depth_part = fg_req_part(req, "depth");
  for (int i = 0; i < req->n_parts; i++) {
    const char *n = req->parts[i].name;
    if (strcmp(n, "image") && strcmp(n, "meta") && strcmp(n, "features") && strcmp(n, "depth"))
      return fg_resp_error(resp, 400, "invalid_request", "unexpected part '%s'; the parts are "
                           "image, meta and, optionally, features and depth", n), -1;
  }
  if (!image || image->len == 0 || !meta_part)
    return fg_resp_error(resp, 400, "missing_part", "the upload needs a non-empty 'image' part "
                         "(the photo) and a 'meta' part (JSON with transform_matrix and "
                         "camera)%s", !image || image->len == 0 ? "; 'image' is missing"
                                                                : "; 'meta' is missing"), -1;
  char err[256];
  *meta = fg_json_parse(meta_part->data, meta_part->len, err, sizeof err);
  if (!*meta)
    return fg_resp_error(resp, 400, "malformed_json", "the 'meta' part is not valid JSON: %s",
                         err), -1;
  if (!json_is_object(*meta))
    return fg_resp_error(resp, 400, "invalid_request", "the 'meta' part must be a JSON object"),
           -1;
  *in = (fg_ingest_input){.image = image->data, .image_len = image->len,
                          .depth_scale = FG_DEPTH_DEFAULT_SCALE,
                          .source = image->filename ? image->filename : "upload"};
  if (!json_is_string(json_object_get(*meta, "camera")) &&
      fg_api_parse_meta(*meta, in->T_world_cam, &in->camera, resp) != 0)
    return -1;
  if (feat_part) {
    if (fg_npy_parse(feat_part->data, feat_part->len, feats) != 0)
      return fg_resp_error(resp, 400, "invalid_features", "the 'features' part is not a usable "
                           ".npy: %s", fg_error_detail()), -1;
    in->features = feats;
  }
  if (fg_api_parse_depth_scale(*meta, depth_part != NULL, in->source, &in->depth_scale, resp))
    return -1;
  if (depth_part && depth_part->len == 0)
    return fg_resp_error(resp, 400, "invalid_depth", "frame '%s': the 'depth' part is empty",
                         in->source), -1;
  if (depth_part) {
    in->depth = depth_part->data;
    in->depth_len = depth_part->len;
  }
  return 0;
}

/* A frame from the robot: meta's "camera" names a calibrated camera, "robot_pose" is the TCP
 * pose (a pose, or "current": read now; none for a fixed camera) and no pose or intrinsics
 * are given. *cam and *has_pose, T: what it says; 0, or -1 after a 4xx. */
static int parse_robot_frame(const fg_req *req, json_t *meta, const fg_conf_camera **cam,
                             int *has_pose, double T[16], fg_resp *resp) {
  const char *name = json_string_value(json_object_get(meta, "camera"));
  *cam = fg_conf_find_camera(req->conf, name);
  if (!*cam)
    return fg_resp_error(resp, 404, "camera_not_found", "meta names camera \"%s\", which no "
                         "[camera NAME] declares", name), -1;
  static const char *const stray[] = {"transform_matrix", "pose", "convention", "fl_x", "fl_y",
                                      "camera_angle_x", NULL};
  for (int i = 0; stray[i]; i++)
    if (json_object_get(meta, stray[i]))
      return fg_resp_error(resp, 400, "invalid_request", "meta names a camera, whose "
                           "calibration and the robot's pose give the frame's pose and "
                           "intrinsics: drop \"%s\"", stray[i]), -1;
  json_t *rp = json_object_get(meta, "robot_pose");
  *has_pose = rp && !(json_is_string(rp) && strcmp(json_string_value(rp), "current") == 0);
  if (*has_pose && fg_json_pose_parse(rp, "robot_pose", T, NULL) != 0)
    return fg_resp_error(resp, 400, "invalid_pose", "%s (or \"current\": the pose read now)",
                         fg_error_detail()), -1;
  return 0;
}

int fg_api_frames_upload(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *meta = NULL;
  fg_npy feats;
  fg_ingest_input in;
  const fg_conf_camera *cam = NULL;
  int has_pose = 0;
  double T_base_tcp[16];
  if (parse_upload(req, &meta, &feats, &in, resp) == 0 &&
      (!json_is_string(json_object_get(meta, "camera")) ||
       parse_robot_frame(req, meta, &cam, &has_pose, T_base_tcp, resp) == 0) &&
      parse_capture(meta, s, &in.capture, resp) == 0) {
    fg_frame frame;
    int index;
    const int rc = cam ? fg_cell_frame_upload(req->app, req->conf, s, &in, cam,
                                              has_pose ? T_base_tcp : NULL, &index, &frame)
                       : fg_ingest_upload(req->app, req->conf, s, &in, &index, &frame);
    if (rc != 0) {
      fg_api_fail(resp, rc);
    } else {
      reply_added(resp, 201, &frame, index);
      fg_frame_clear(&frame);
    }
  }
  json_decref(meta);
  fg_scene_unref(s);
  return 0;
}

/* ---------------------------------------------------------------- list */

int fg_api_frames_list(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  fg_frame *frames;
  int *indices;
  size_t n;
  int rc = fg_scene_list_frames(s, &frames, &indices, &n);
  fg_scene_unref(s);
  if (rc != 0) return fg_resp_error(resp, 500, "internal_error", "%s", fg_error_detail());
  json_t *arr = json_array();
  for (size_t i = 0; arr && i < n; i++) json_array_append_new(arr, fg_json_frame(&frames[i], indices[i]));
  free(frames);
  free(indices);
  fg_resp_json(resp, 200, json_pack("{s:o}", "frames", arr));
  return 0;
}

/* ---------------------------------------------------------------- image */

/* A number in a path: decimal digits only, from lo to hi. 0 with *out, or -1. */
static int path_number(const char *s, long long lo, long long hi, long long *out) {
  char *end;
  errno = 0;
  const long long v = strtoll(s, &end, 10);
  if (s[0] < '0' || s[0] > '9' || *end || errno == ERANGE || v < lo || v > hi) return -1;
  *out = v;
  return 0;
}

/* GET /v1/scenes/{s}/frames/{i}/image: the frame's stored image (undistorted and downscaled
 * as training sees it, sRGB) as an 8-bit RGB PNG, encoded in a decoder child like renders,
 * so that a viewer can show a photo beside the field's render from the same camera. */
int fg_api_frame_image(fg_req *req, fg_resp *resp) {
  const char *num = req->params[1];
  long long number;
  if (path_number(num, 0, INT_MAX, &number) != 0)
    return fg_resp_error(resp, 400, "invalid_request", "the frame number must be a "
                         "non-negative integer as GET /v1/scenes/%s/frames lists them, got "
                         "\"%.40s\"", req->params[0], num);
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  fg_frame f;
  int rc = fg_scene_load_frame(s, (int)number, &f);
  if (rc == FG_ENOENT) {
    fg_resp_error(resp, 404, "frame_not_found", "scene '%s' has no frame %lld; GET "
                  "/v1/scenes/%s/frames lists them", fg_scene_name(s), number, fg_scene_name(s));
    fg_scene_unref(s);
    return 0;
  }
  fg_scene_unref(s);
  if (rc != 0)
    return fg_resp_error(resp, 500, "internal_error", "cannot read the frame: %s",
                         fg_error_detail());
  const size_t n = (size_t)f.cam.w * (size_t)f.cam.h * 3;
  uint8_t *px = malloc(n ? n : 1);
  uint8_t *png = NULL;
  size_t png_len = 0;
  if (!px) {
    rc = fg_fail(FG_ENOMEM, "out of memory for a %dx%d image", f.cam.w, f.cam.h);
  } else {
    for (size_t i = 0; i < n; i++)
      px[i] = (uint8_t)(((uint32_t)f.rgb[i] * 255u + 32767u) / 65535u); /* 16 to 8 bits */
    rc = fg_decoder_encode_png(req->app->decoder, px, f.cam.w, f.cam.h, 3, 8, &png, &png_len);
  }
  free(px);
  fg_frame_clear(&f);
  if (rc != 0)
    return fg_resp_error(resp, 500, "internal_error", "cannot encode the PNG: %s",
                         fg_error_detail());
  fg_resp_take(resp, 200, "image/png", (char *)png, png_len);
  return 0;
}

/* ---------------------------------------------------------------- import */

static json_t *imported_json(const fg_import_result *r) {
  json_t *files = json_array(), *skipped = json_array(), *ids = json_array();
  for (size_t i = 0; i < r->n_skipped; i++) {
    const fg_import_skip *k = &r->skipped[i];
    json_array_append_new(files, json_string(k->file_path));
    json_array_append_new(skipped, json_pack("{s:I,s:s,s:s}", "frame", (json_int_t)k->frame,
                                             "file_path", k->file_path, "reason", k->reason));
  }
  for (size_t i = 0; i < r->imported; i++) json_array_append_new(ids, json_integer(r->first + (int)i));
  return json_pack("{s:I,s:I,s:o,s:o,s:I,s:I,s:o,s:o}", "imported", (json_int_t)r->imported,
                   "skipped", (json_int_t)r->n_skipped, "skipped_files", files, "skipped_frames",
                   skipped, "with_depth", (json_int_t)r->with_depth, "depth_missing",
                   (json_int_t)r->depth_missing, "frames", ids, "capture",
                   r->imported ? json_integer((json_int_t)r->capture) : json_null());
}

int fg_api_scene_import(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = fg_api_body_object(req, resp);
  const char *path = NULL, *tname = "transforms.json";
  int64_t capture = 0;
  if (body && (fg_json_string(body, "path", &path) <= 0 ||
               fg_json_string(body, "transforms", &tname) < 0)) {
    fg_resp_error(resp, 400, "invalid_request", "the body needs \"path\": the data set's "
                  "folder, and optionally \"transforms\": the file name inside it, and "
                  "\"capture\"");
  } else if (body && parse_capture(body, s, &capture, resp) == 0) {
    fg_import_result r;
    const int rc = fg_ingest_import(req->app, req->conf, s, path, tname, capture, &r);
    if (rc != 0)
      fg_api_fail(resp, rc);
    else
      fg_resp_json(resp, 200, imported_json(&r));
    fg_import_result_release(&r);
  }
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}

/* ---------------------------------------------------------------- captures */

static json_t *capture_json(const fg_scene_capture_info *c, int64_t latest) {
  char first[32], last[32];
  fg_iso8601(c->first_ms, first);
  fg_iso8601(c->last_ms, last);
  return json_pack("{s:I,s:I,s:I,s:I,s:[i,i],s:s,s:s,s:b}", "capture", (json_int_t)c->capture,
                   "frames", (json_int_t)c->n_frames, "with_depth", (json_int_t)c->n_depth,
                   "with_robot_pose", (json_int_t)c->n_robot_pose, "frame_range",
                   c->first_frame, c->last_frame, "first_created", first, "last_created", last,
                   "latest", c->capture == latest);
}

int fg_api_captures_list(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  fg_scene_capture_info *v;
  size_t n;
  const int rc = fg_scene_list_captures(s, &v, &n);
  fg_scene_unref(s);
  if (rc != 0) return fg_api_fail(resp, rc);
  json_t *arr = json_array();
  /* the newest that holds frames: what a training takes by default */
  const int64_t latest = n ? v[n - 1].capture : 0;
  for (size_t i = 0; arr && i < n; i++) json_array_append_new(arr, capture_json(&v[i], latest));
  free(v);
  fg_resp_json(resp, 200, json_pack("{s:o}", "captures", arr));
  return 0;
}

int fg_api_capture_delete(fg_req *req, fg_resp *resp) {
  const char *num = req->params[1];
  long long capture;
  if (path_number(num, 1, FG_CAPTURE_MAX, &capture) != 0)
    return fg_resp_error(resp, 400, "invalid_request", "the capture must be a number from 1 as "
                         "GET /v1/scenes/%s/captures lists them, got \"%.40s\"", req->params[0],
                         num);
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  size_t removed = 0;
  /* a training reads the frames as it starts: none is taken from under one */
  int rc = fg_jobs_scene_idle(req->app->jobs, fg_scene_name(s));
  if (rc == 0) rc = fg_scene_delete_capture(s, capture, &removed);
  if (rc == FG_ENOENT)
    fg_resp_error(resp, 404, "capture_not_found", "scene '%s' has no capture %lld; GET "
                  "/v1/scenes/%s/captures lists them", fg_scene_name(s), capture,
                  fg_scene_name(s));
  else if (rc != 0)
    fg_api_fail(resp, rc);
  else
    fg_resp_json(resp, 200, json_pack("{s:I,s:I,s:I}", "deleted", (json_int_t)capture,
                                      "frames", (json_int_t)removed, "latest_capture",
                                      (json_int_t)fg_scene_latest_capture(s)));
  fg_scene_unref(s);
  return 0;
}
