/* Frames: upload one (multipart), import a data set folder, list, and a frame's image. */
#include "api.h"
#include "api_decode.h"
#include "decoder/decoder.h"
#include "api_views.h"
#include "state/json.h"
#include "metrics/metrics.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/pose.h"
#include "io/depth.h"
#include "io/image.h"
#include "io/npy.h"
#include "io/transforms.h"

#include <errno.h>
#include <math.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>

/* The largest image or feature file an import reads. */
#define IMPORT_MAX_FILE (512u << 20)

/* What went wrong with one frame, as the HTTP reply will say it. depth: the fault is the
 * frame's depth map (an import skips such a frame and says why instead of failing). */
typedef struct ingest_error {
  int status;
  const char *code;
  int depth;
  char message[768];
} ingest_error;

/* An encoded depth map to ingest with a frame (io/depth.h), or none when bytes is NULL. */
typedef struct depth_input {
  const void *bytes;
  size_t len;
  double scale; /* metres per unit of an integer depth image */
} depth_input;

static int ingest_fail(ingest_error *e, int status, const char *code, const char *prefix) {
  e->status = status;
  e->code = code;
  snprintf(e->message, sizeof e->message, "%s%s", prefix, fg_error_detail());
  return -1;
}

/* Decodes a frame's depth map: a .npy here, an image in a decoder child. */
static int decode_depth(fg_app *app, const depth_input *in, fg_depth_map *out,
                        ingest_error *err) {
  fg_npy npy;
  int rc;
  if (in->len >= 6 && memcmp(in->bytes, "\x93NUMPY", 6) == 0) {
    rc = fg_npy_parse(in->bytes, in->len, &npy);
    if (rc == 0) rc = fg_depth_from_npy(&npy, out);
  } else {
    rc = fg_decoder_decode_depth(app->decoder, in->bytes, in->len, in->scale, out);
    if (rc == FG_ENOENT || rc == FG_EIO || rc == FG_ENOMEM)
      return ingest_fail(err, 500, "internal_error", "cannot decode the depth map: ");
  }
  if (rc != 0) {
    err->depth = 1;
    return ingest_fail(err, 400, "invalid_depth", "depth: ");
  }
  return 0;
}

/* Turns one encoded image plus its camera, pose and optional features and depth into a frame
 * ready to store. The camera may still lack what only the image's size gives. The image is
 * decoded by app's decoder, in a child process. */
static int ingest_one(fg_app *app, const void *image, size_t image_len,
                      fg_transforms_frame camera, const double T_world_cam[16],
                      const fg_npy *features, const depth_input *depth,
                      const fg_scene_params *params, int max_side, const char *source,
                      fg_frame *out, ingest_error *err) {
  if (!fg_image_sniff(image, image_len))
    return ingest_fail(err, 415, "unsupported_media_type",
                       "the image is not PNG, JPEG, OpenEXR or TIFF data");
  if (features && fg_frame_check_features(features) != 0)
    return ingest_fail(err, 400, "invalid_features", "");
  float bg[3] = {(float)params->background[0], (float)params->background[1],
                 (float)params->background[2]};
  fg_image img = {0};
  int rc = fg_decoder_decode(app->decoder, image, image_len, bg, &img);
  /* The image's fault (corrupt, too large, or it crashed the decoder) or the server's (the
   * decoder program is missing or cannot be started). */
  if (rc == FG_ENOENT || rc == FG_EIO || rc == FG_ENOMEM)
    return ingest_fail(err, 500, "internal_error", "cannot decode the image: ");
  if (rc != 0) return ingest_fail(err, 400, "invalid_image", "");
  rc = fg_transforms_complete_camera(&camera, img.w, img.h);
  if (rc != 0) {
    fg_image_release(&img);
    return ingest_fail(err, 400, "invalid_camera", "");
  }
  fg_depth_map dm = {0};
  if (depth && depth->bytes) {
    rc = decode_depth(app, depth, &dm, err);
    if (rc == 0 && fg_depth_check_grid(dm.w, dm.h, img.w, img.h) != 0) {
      err->depth = 1;
      rc = ingest_fail(err, 400, "invalid_depth", "depth: ");
    }
    if (rc != 0) {
      fg_depth_release(&dm);
      fg_image_release(&img);
      return -1;
    }
  }
  fg_ingest_opts opts = {.background_rgb = {bg[0], bg[1], bg[2]}, .max_image_side = max_side};
  rc = fg_frame_prepare_image_depth(out, &img, &camera.cam, T_world_cam, features,
                                    dm.m ? &dm : NULL, &opts);
  fg_depth_release(&dm);
  fg_image_release(&img);
  if (rc != 0) return ingest_fail(err, rc == FG_ENOMEM ? 500 : 400,
                                  rc == FG_ENOMEM ? "internal_error" : "invalid_request", "");
  snprintf(out->source, sizeof out->source, "%s", source);
  return 0;
}

static void reply_added(fg_resp *resp, int status, const fg_frame *f, int index) {
  json_t *features = f->feat_d ? json_pack("{s:i,s:i,s:i}", "h", f->feat_h, "w", f->feat_w, "d",
                                           f->feat_d)
                               : json_null();
  json_t *depth = f->depth_w ? json_pack("{s:i,s:i,s:f}", "w", f->depth_w, "h", f->depth_h,
                                         "valid_fraction", f->depth_valid)
                             : json_null();
  fg_resp_json(resp, status, json_pack("{s:i,s:{s:i,s:i},s:o,s:o}", "frame", index, "image", "w",
                                       f->cam.w, "h", f->cam.h, "features", features, "depth",
                                       depth));
}

static int add_failed(fg_resp *resp, int rc) {
  if (rc == FG_EINVAL) return fg_resp_error(resp, 400, "invalid_features", "%s", fg_error_detail());
  if (rc == FG_ENOENT) return fg_resp_error(resp, 404, "scene_not_found", "%s", fg_error_detail());
  return fg_api_storage_error(resp, rc, "the frame");
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

int fg_api_frames_upload(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  const fg_part *image = fg_req_part(req, "image");
  const fg_part *meta_part = fg_req_part(req, "meta");
  const fg_part *feat_part = fg_req_part(req, "features");
  const fg_part *depth_part = fg_req_part(req, "depth");
  json_t *meta = NULL;
  for (int i = 0; i < req->n_parts; i++) {
    const char *n = req->parts[i].name;
    if (strcmp(n, "image") && strcmp(n, "meta") && strcmp(n, "features") && strcmp(n, "depth")) {
      fg_resp_error(resp, 400, "invalid_request", "unexpected part '%s'; the parts are image, "
                    "meta and, optionally, features and depth", n);
      goto out;
    }
  }
  if (!image || image->len == 0 || !meta_part) {
    fg_resp_error(resp, 400, "missing_part", "the upload needs a non-empty 'image' part (the "
                  "photo) and a 'meta' part (JSON with transform_matrix and camera)%s",
                  !image || image->len == 0 ? "; 'image' is missing" : "; 'meta' is missing");
    goto out;
  }
  char err[256];
  meta = fg_json_parse(meta_part->data, meta_part->len, err, sizeof err);
  if (!meta) {
    fg_resp_error(resp, 400, "malformed_json", "the 'meta' part is not valid JSON: %s", err);
    goto out;
  }
  if (!json_is_object(meta)) {
    fg_resp_error(resp, 400, "invalid_request", "the 'meta' part must be a JSON object");
    goto out;
  }
  double T[16];
  fg_transforms_frame camera;
  if (fg_api_parse_meta(meta, T, &camera, resp) != 0) goto out;
  fg_npy feats, *featp = NULL;
  if (feat_part) {
    if (fg_npy_parse(feat_part->data, feat_part->len, &feats) != 0) {
      fg_resp_error(resp, 400, "invalid_features", "the 'features' part is not a usable .npy: %s",
                    fg_error_detail());
      goto out;
    }
    featp = &feats;
  }
  const char *source = image->filename ? image->filename : "upload";
  depth_input depth = {.scale = FG_DEPTH_DEFAULT_SCALE};
  if (fg_api_parse_depth_scale(meta, depth_part != NULL, source, &depth.scale, resp) != 0)
    goto out;
  if (depth_part) {
    if (depth_part->len == 0) {
      fg_resp_error(resp, 400, "invalid_depth", "frame '%s': the 'depth' part is empty", source);
      goto out;
    }
    depth.bytes = depth_part->data;
    depth.len = depth_part->len;
  }
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  fg_frame frame;
  ingest_error ie = {0};
  if (ingest_one(req->app, image->data, image->len, camera, T, featp, &depth, &info.params,
                 req->conf->max_image_side, source, &frame, &ie) != 0) {
    if (ie.depth)
      fg_resp_error(resp, ie.status, ie.code, "frame '%s': %s", source, ie.message);
    else
      fg_resp_error(resp, ie.status, ie.code, "%s", ie.message);
    goto out;
  }
  int index;
  int rc = fg_scene_add_frames(s, &frame, 1, &index);
  if (rc != 0) {
    add_failed(resp, rc);
  } else {
    fg_metrics_add_frames_ingested(1);
    reply_added(resp, 201, &frame, index);
  }
  fg_frame_clear(&frame);
out:
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

/* GET /v1/scenes/{s}/frames/{i}/image: the frame's stored image (undistorted and downscaled
 * as training sees it, sRGB) as an 8-bit RGB PNG, encoded in a decoder child like renders,
 * so that a viewer can show a photo beside the field's render from the same camera. */
int fg_api_frame_image(fg_req *req, fg_resp *resp) {
  const char *num = req->params[1];
  char *end;
  errno = 0;
  const long number = strtol(num, &end, 10);
  if (num[0] < '0' || num[0] > '9' || *end || errno == ERANGE || number > INT_MAX)
    return fg_resp_error(resp, 400, "invalid_request", "the frame number must be a "
                         "non-negative integer as GET /v1/scenes/%s/frames lists them, got "
                         "\"%.40s\"", req->params[0], num);
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  fg_frame f;
  int rc = fg_scene_load_frame(s, (int)number, &f);
  if (rc == FG_ENOENT) {
    fg_resp_error(resp, 404, "frame_not_found", "scene '%s' has no frame %ld; GET "
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

static int has_dotdot(const char *p) {
  for (const char *s = p; (s = strstr(s, "..")) != NULL; s += 2)
    if ((s == p || s[-1] == '/') && (s[2] == '\0' || s[2] == '/')) return 1;
  return 0;
}

/* True when real (a resolved path) is one of the import folders or inside one. */
static int inside_import_dirs(const fg_conf *conf, const char *real) {
  for (size_t i = 0; i < conf->n_import_dirs; i++) {
    char dir[PATH_MAX];
    if (!realpath(conf->import_dirs[i], dir)) continue;
    size_t n = strlen(dir);
    if (strncmp(real, dir, n) == 0 && (real[n] == '\0' || real[n] == '/' || n == 1)) return 1;
  }
  return 0;
}

/* Resolves the requested folder: absolute, or relative to the first import folder that has
 * it. Answers 403/404 itself and returns -1 when it cannot be used. */
static int resolve_import_dir(const fg_conf *conf, const char *path, char real[PATH_MAX],
                              fg_resp *resp) {
  if (conf->n_import_dirs == 0)
    return fg_resp_error(resp, 403, "forbidden_path", "imports are off: no folder may be read; "
                         "list the folders in [state] import_dirs of the configuration file"), -1;
  if (has_dotdot(path))
    return fg_resp_error(resp, 403, "forbidden_path", "the path may not contain '..'"), -1;
  int found = 0;
  if (path[0] == '/') {
    found = realpath(path, real) != NULL;
  } else {
    for (size_t i = 0; !found && i < conf->n_import_dirs; i++) {
      char *p = fg_path_join(conf->import_dirs[i], path);
      found = p && realpath(p, real) != NULL;
      free(p);
    }
  }
  if (!found)
    return fg_resp_error(resp, 404, "path_not_found", "no folder '%s' under the import folders",
                         path), -1;
  if (!inside_import_dirs(conf, real))
    return fg_resp_error(resp, 403, "forbidden_path", "'%s' is outside the folders this server "
                         "may read ([state] import_dirs)", path), -1;
  return 0;
}

/* Reads and prepares frame i of a data set; the result goes to frames[i] or err. */
static int import_one(fg_app *app, const fg_conf *conf, const fg_transforms_frame *tf,
                      const fg_scene_params *params, fg_frame *out, ingest_error *err) {
  char real[PATH_MAX];
  if (!realpath(tf->image_path, real) || !inside_import_dirs(conf, real)) {
    err->status = 403;
    err->code = "forbidden_path";
    snprintf(err->message, sizeof err->message, "'%s' leads outside the import folders",
             tf->file_path);
    return -1;
  }
  char *image = NULL, *feat_buf = NULL, *depth_buf = NULL;
  size_t image_len = 0, feat_len = 0, depth_len = 0;
  depth_input depth = {.scale = tf->depth_scale};
  fg_npy feats, *featp = NULL;
  int rc = -1;
  if (fg_read_file(real, IMPORT_MAX_FILE, &image, &image_len) != 0) {
    ingest_fail(err, 400, "invalid_image", "");
    goto out;
  }
  if (tf->features_path) {
    if (!realpath(tf->features_path, real) || !inside_import_dirs(conf, real)) {
      err->status = 403;
      err->code = "forbidden_path";
      snprintf(err->message, sizeof err->message, "features_path leads outside the import folders");
      goto out;
    }
    if (fg_read_file(real, IMPORT_MAX_FILE, &feat_buf, &feat_len) != 0 ||
        fg_npy_parse(feat_buf, feat_len, &feats) != 0) {
      ingest_fail(err, 400, "invalid_features", "");
      goto out;
    }
    featp = &feats;
  }
  if (tf->depth_path) {
    if (!realpath(tf->depth_path, real) || !inside_import_dirs(conf, real)) {
      err->status = 403;
      err->code = "forbidden_path";
      snprintf(err->message, sizeof err->message, "depth_file_path leads outside the import folders");
      goto out;
    }
    if (fg_read_file(real, IMPORT_MAX_FILE, &depth_buf, &depth_len) != 0) {
      err->depth = 1;
      ingest_fail(err, 400, "invalid_depth", "depth: ");
      goto out;
    }
    depth.bytes = depth_buf;
    depth.len = depth_len;
  }
  if (fg_pose_validate(tf->T_world_cam) != 0) {
    ingest_fail(err, 400, "invalid_pose", "transform_matrix: ");
    goto out;
  }
  const char *base = strrchr(tf->image_path, '/');
  rc = ingest_one(app, image, image_len, *tf, tf->T_world_cam, featp, &depth, params,
                  conf->max_image_side, base ? base + 1 : tf->image_path, out, err);
out:
  free(image);
  free(feat_buf);
  free(depth_buf);
  return rc;
}

int fg_api_scene_import(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  const fg_conf *conf = req->conf;
  json_t *body = fg_api_body_object(req, resp);
  fg_transforms t = {0};
  fg_frame *frames = NULL;
  ingest_error *errs = NULL;
  char *tf_path = NULL;
  if (!body) goto out;
  const char *path = NULL, *tname = "transforms.json";
  if (fg_json_string(body, "path", &path) <= 0 || fg_json_string(body, "transforms", &tname) < 0) {
    fg_resp_error(resp, 400, "invalid_request", "the body needs \"path\": the data set's folder, "
                  "and optionally \"transforms\": the file name inside it");
    goto out;
  }
  if (tname[0] == '/' || has_dotdot(tname) || !*tname) {
    fg_resp_error(resp, 403, "forbidden_path", "\"transforms\" must be a file name inside the "
                  "folder, without '..'");
    goto out;
  }
  char real[PATH_MAX], treal[PATH_MAX];
  if (resolve_import_dir(conf, path, real, resp) != 0) goto out;
  tf_path = fg_path_join(real, tname);
  if (!tf_path || !realpath(tf_path, treal)) {
    fg_resp_error(resp, 404, "path_not_found", "no file '%s' in '%s'", tname, path);
    goto out;
  }
  if (!inside_import_dirs(conf, treal)) {
    fg_resp_error(resp, 403, "forbidden_path", "'%s' leads outside the import folders", tname);
    goto out;
  }
  if (fg_transforms_load(treal, &t) != 0) {
    fg_resp_error(resp, 400, "invalid_transforms", "%s: %s", tname, fg_error_detail());
    goto out;
  }
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  frames = calloc(t.n_frames ? t.n_frames : 1, sizeof *frames);
  errs = calloc(t.n_frames ? t.n_frames : 1, sizeof *errs);
  if (!frames || !errs) {
    fg_resp_error(resp, 500, "internal_error", "out of memory");
    goto out;
  }
  int failed = 0;
  /* Decoding dominates: one frame per thread. Errors are kept per frame so the reply names
   * the first failing frame in file order, whatever the threads' timing. */
#pragma omp parallel for schedule(dynamic, 1) num_threads(fg_conf_threads(conf)) reduction(| : failed)
  for (size_t i = 0; i < t.n_frames; i++) {
    if (!t.frames[i].image_path) continue;
    if (import_one(req->app, conf, &t.frames[i], &info.params, &frames[i], &errs[i]) != 0)
      failed = 1;
  }
  /* A frame whose depth map is unusable is skipped with the reason; any other failure fails
   * the whole import. */
  for (size_t i = 0; failed && i < t.n_frames; i++)
    if (errs[i].status && !errs[i].depth) {
      fg_resp_error(resp, errs[i].status, errs[i].code, "frame %zu (%s): %s; nothing was "
                    "imported", i, t.frames[i].file_path, errs[i].message);
      goto out;
    }
  /* The store checks D again under its lock; checking here first lets the reply name the
   * frame. */
  int d = info.feature_dim;
  for (size_t i = 0; i < t.n_frames; i++) {
    if (!frames[i].feat_d) continue;
    if (d && frames[i].feat_d != d) {
      fg_resp_error(resp, 400, "invalid_features", "frame %zu (%s): features have D = %d but %s "
                    "%d; every frame of a scene must have the same D; nothing was imported", i,
                    t.frames[i].file_path, frames[i].feat_d,
                    info.feature_dim ? "the scene's frames have D =" : "earlier frames have D =",
                    d);
      goto out;
    }
    d = frames[i].feat_d;
  }
  /* Pack the frames to store to the front, in file order. */
  size_t n = 0, n_skipped = 0, n_depth = 0;
  json_t *skipped = json_array(), *skipped_frames = json_array();
  for (size_t i = 0; i < t.n_frames; i++) {
    if (t.frames[i].image_path && !errs[i].status) {
      n_depth += frames[i].depth != NULL;
      if (n != i) {
        frames[n] = frames[i];
        memset(&frames[i], 0, sizeof frames[i]); /* moved: not freed twice */
      }
      n++;
    } else {
      n_skipped++;
      json_array_append_new(skipped, json_string(t.frames[i].file_path));
      json_array_append_new(skipped_frames,
                            json_pack("{s:I,s:s,s:s}", "frame", (json_int_t)i, "file_path",
                                      t.frames[i].file_path, "reason",
                                      errs[i].status ? errs[i].message : "image missing"));
    }
  }
  int first = 0;
  int rc = n ? fg_scene_add_frames(s, frames, n, &first) : 0;
  if (rc != 0) {
    json_decref(skipped);
    json_decref(skipped_frames);
    add_failed(resp, rc);
    goto out;
  }
  fg_metrics_add_frames_ingested((unsigned)n);
  fg_info("scene %s: imported %zu frames (%zu with depth) from %s; %zu skipped (%zu: image "
          "missing), %zu without their missing depth file", info.name, n, n_depth, treal,
          n_skipped, t.n_missing, t.n_depth_missing);
  json_t *ids = json_array();
  for (size_t i = 0; i < n; i++) json_array_append_new(ids, json_integer(first + (int)i));
  fg_resp_json(resp, 200, json_pack("{s:I,s:I,s:o,s:o,s:I,s:I,s:o}", "imported", (json_int_t)n,
                                    "skipped", (json_int_t)n_skipped, "skipped_files", skipped,
                                    "skipped_frames", skipped_frames, "with_depth",
                                    (json_int_t)n_depth, "depth_missing",
                                    (json_int_t)t.n_depth_missing, "frames", ids));
out:
  if (frames)
    for (size_t i = 0; i < t.n_frames; i++) fg_frame_clear(&frames[i]);
  free(frames);
  free(errs);
  free(tf_path);
  fg_transforms_free(&t);
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}
