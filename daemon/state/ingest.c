/* Frames into a scene: one upload, or a data set folder (ingest.h). */
#include "ingest.h"

#include "decoder/decoder.h"
#include "metrics/metrics.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/pose.h"
#include "io/depth.h"
#include "io/image.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------------- one frame */

/* Decodes a frame's depth map: a .npy here, an image in a decoder child. *depth_fault: the
 * map's fault, not the server's. */
static int decode_depth(fg_app *app, const fg_ingest_input *in, fg_depth_map *out,
                        int *depth_fault) {
  fg_npy npy;
  int rc;
  if (in->depth_len >= 6 && memcmp(in->depth, "\x93NUMPY", 6) == 0) {
    rc = fg_npy_parse(in->depth, in->depth_len, &npy);
    if (rc == 0) rc = fg_depth_from_npy(&npy, out);
  } else {
    rc = fg_decoder_decode_depth(app->decoder, in->depth, in->depth_len, in->depth_scale, out);
    if (rc == FG_ENOENT || rc == FG_EIO || rc == FG_ENOMEM)
      return fg_fail_as(rc, "internal_error", "cannot decode the depth map: %s",
                        fg_error_detail());
  }
  if (rc != 0) {
    *depth_fault = 1;
    return fg_fail_as(rc, "invalid_depth", "depth: %s", fg_error_detail());
  }
  return 0;
}

/* Turns one frame as it arrived into a frame ready to store. */
static int ingest_one(fg_app *app, const fg_ingest_input *in, const fg_scene_params *params,
                      int max_side, fg_frame *out, int *depth_fault) {
  *depth_fault = 0;
  if (!fg_image_sniff(in->image, in->image_len))
    return fg_fail_as(FG_EINVAL, "unsupported_media_type", "the image is not PNG, JPEG, "
                      "OpenEXR or TIFF data");
  if (in->features && fg_frame_check_features(in->features) != 0)
    return fg_fail_as(FG_EINVAL, "invalid_features", "%s", fg_error_detail());
  float bg[3] = {(float)params->background[0], (float)params->background[1],
                 (float)params->background[2]};
  fg_image img = {0};
  int rc = fg_decoder_decode_sent(app->decoder, in->image, in->image_len, bg, &img);
  if (rc != 0) return rc;
  fg_transforms_frame camera = in->camera;
  rc = fg_transforms_complete_camera(&camera, img.w, img.h);
  if (rc != 0) {
    fg_image_release(&img);
    return fg_fail_as(rc, "invalid_camera", "%s", fg_error_detail());
  }
  fg_depth_map dm = {0};
  if (in->depth) {
    rc = decode_depth(app, in, &dm, depth_fault);
    if (rc == 0 && (rc = fg_depth_check_grid(dm.w, dm.h, img.w, img.h)) != 0) {
      *depth_fault = 1;
      rc = fg_fail_as(rc, "invalid_depth", "depth: %s", fg_error_detail());
    }
    if (rc != 0) {
      fg_depth_release(&dm);
      fg_image_release(&img);
      return rc;
    }
  }
  fg_ingest_opts opts = {.background_rgb = {bg[0], bg[1], bg[2]}, .max_image_side = max_side};
  rc = fg_frame_prepare_image_depth(out, &img, &camera.cam, in->T_world_cam, in->features,
                                    dm.m ? &dm : NULL, &opts);
  fg_depth_release(&dm);
  fg_image_release(&img);
  if (rc != 0)
    return fg_fail_as(rc, rc == FG_ENOMEM ? "internal_error" : "invalid_request", "%s",
                      fg_error_detail());
  snprintf(out->source, sizeof out->source, "%s", in->source);
  out->capture = in->capture;
  out->has_robot_pose = in->has_robot_pose;
  if (in->has_robot_pose) memcpy(out->T_world_tcp, in->T_world_tcp, sizeof out->T_world_tcp);
  return 0;
}

/* Stores frames (n) in scene s. */
static int add_frames(fg_scene *s, fg_frame *frames, size_t n, int *first) {
  const int rc = fg_scene_add_frames(s, frames, n, first);
  if (rc == FG_EINVAL) return fg_fail_as(rc, "invalid_features", "%s", fg_error_detail());
  if (rc == FG_ENOENT) return fg_fail_as(rc, "scene_not_found", "%s", fg_error_detail());
  if (rc != 0) return fg_state_write_failed(rc, "the frame");
  fg_metrics_add_frames_ingested((unsigned)n);
  return 0;
}

int fg_ingest_upload(fg_app *app, const fg_conf *conf, fg_scene *s, const fg_ingest_input *in,
                     int *index, fg_frame *out) {
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  int depth_fault;
  int rc = ingest_one(app, in, &info.params, conf->max_image_side, out, &depth_fault);
  if (rc != 0 && depth_fault)
    return fg_fail_as(rc, fg_error_reason(), "frame '%s': %s", in->source, fg_error_detail());
  if (rc == 0 && (rc = add_frames(s, out, 1, index)) != 0) fg_frame_clear(out);
  return rc;
}

/* ---------------------------------------------------------------- a data set */

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
 * it. */
static int resolve_import_dir(const fg_conf *conf, const char *path, char real[PATH_MAX]) {
  if (conf->n_import_dirs == 0)
    return fg_fail_as(FG_EPERM, "forbidden_path", "imports are off: no folder may be read; "
                      "list the folders in [state] import_dirs of the configuration file");
  if (has_dotdot(path))
    return fg_fail_as(FG_EPERM, "forbidden_path", "the path may not contain '..'");
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
    return fg_fail_as(FG_ENOENT, "path_not_found", "no folder '%s' under the import folders",
                      path);
  if (!inside_import_dirs(conf, real))
    return fg_fail_as(FG_EPERM, "forbidden_path", "'%s' is outside the folders this server "
                      "may read ([state] import_dirs)", path);
  return 0;
}

/* The transforms file `name` of folder `path` loaded into *t; *where gets its real path. */
static int load_transforms(const fg_conf *conf, const char *path, const char *name,
                           fg_transforms *t, char where[PATH_MAX]) {
  if (name[0] == '/' || has_dotdot(name) || !*name)
    return fg_fail_as(FG_EPERM, "forbidden_path", "\"transforms\" must be a file name inside "
                      "the folder, without '..'");
  char real[PATH_MAX];
  FG_TRY(resolve_import_dir(conf, path, real));
  char *file = fg_path_join(real, name);
  const int found = file && realpath(file, where);
  free(file);
  if (!found)
    return fg_fail_as(FG_ENOENT, "path_not_found", "no file '%s' in '%s'", name, path);
  if (!inside_import_dirs(conf, where))
    return fg_fail_as(FG_EPERM, "forbidden_path", "'%s' leads outside the import folders",
                      name);
  if (fg_transforms_load(where, t) != 0)
    return fg_fail_as(FG_EINVAL, "invalid_transforms", "%s: %s", name, fg_error_detail());
  return 0;
}

/* Reads file `path` (a data set's, named `what` in errors) when it lies inside the import
 * folders. */
static int read_inside(const fg_conf *conf, const char *path, const char *what, char **buf,
                       size_t *len) {
  char real[PATH_MAX];
  if (!realpath(path, real) || !inside_import_dirs(conf, real))
    return fg_fail_as(FG_EPERM, "forbidden_path", "%s leads outside the import folders", what);
  return fg_read_file(real, FG_INGEST_MAX_FILE, buf, len);
}

/* What went wrong with one frame of an import, kept per frame: the threads' failures are
 * reported in file order. */
typedef struct frame_error {
  int rc;
  const char *code;
  int depth;
  char message[768];
} frame_error;

static int frame_failed(frame_error *e, int rc, int depth) {
  e->rc = rc;
  e->code = fg_error_reason();
  e->depth = depth;
  snprintf(e->message, sizeof e->message, "%s", fg_error_detail());
  return rc;
}

/* Reads and prepares frame tf of a data set into *out, or says why not in *err. */
static int import_one(fg_app *app, const fg_conf *conf, const fg_transforms_frame *tf,
                      const fg_scene_params *params, fg_frame *out, frame_error *err) {
  fg_error_clear(); /* a reason below is this frame's */
  char quoted[PATH_MAX + 2];
  snprintf(quoted, sizeof quoted, "'%s'", tf->file_path);
  char *image = NULL, *feat_buf = NULL, *depth_buf = NULL;
  size_t image_len = 0, feat_len = 0, depth_len = 0;
  fg_npy feats;
  fg_ingest_input in = {.camera = *tf, .depth_scale = tf->depth_scale, .source = tf->image_path};
  int rc = read_inside(conf, tf->image_path, quoted, &image, &image_len);
  if (rc != 0 && !fg_error_reason()) rc = fg_fail_as(rc, "invalid_image", "%s", fg_error_detail());
  if (rc == 0 && tf->features_path) {
    rc = read_inside(conf, tf->features_path, "features_path", &feat_buf, &feat_len);
    if (rc == 0) rc = fg_npy_parse(feat_buf, feat_len, &feats);
    if (rc != 0 && !fg_error_reason())
      rc = fg_fail_as(rc, "invalid_features", "%s", fg_error_detail());
    in.features = &feats;
  }
  int depth = 0;
  if (rc == 0 && tf->depth_path) {
    rc = read_inside(conf, tf->depth_path, "depth_file_path", &depth_buf, &depth_len);
    if (rc != 0 && !fg_error_reason()) {
      depth = 1;
      rc = fg_fail_as(rc, "invalid_depth", "depth: %s", fg_error_detail());
    }
    in.depth = depth_buf;
    in.depth_len = depth_len;
  }
  if (rc == 0 && (rc = fg_pose_validate(tf->T_world_cam)) != 0)
    rc = fg_fail_as(rc, "invalid_pose", "transform_matrix: %s", fg_error_detail());
  if (rc == 0) {
    const char *base = strrchr(tf->image_path, '/');
    memcpy(in.T_world_cam, tf->T_world_cam, sizeof in.T_world_cam);
    in.image = image;
    in.image_len = image_len;
    in.source = base ? base + 1 : tf->image_path;
    rc = ingest_one(app, &in, params, conf->max_image_side, out, &depth);
  }
  free(image);
  free(feat_buf);
  free(depth_buf);
  return rc ? frame_failed(err, rc, depth) : 0;
}

/* The store checks D again under its lock; checking here first lets the answer name the
 * frame. */
static int same_dim(const fg_transforms *t, const fg_frame *frames, int scene_dim) {
  int d = scene_dim;
  for (size_t i = 0; i < t->n_frames; i++) {
    if (!frames[i].feat_d) continue;
    if (d && frames[i].feat_d != d)
      return fg_fail_as(FG_EINVAL, "invalid_features", "frame %zu (%s): features have D = %d "
                        "but %s %d; every frame of a scene must have the same D; nothing was "
                        "imported", i, t->frames[i].file_path, frames[i].feat_d, scene_dim
                        ? "the scene's frames have D =" : "earlier frames have D =", d);
    d = frames[i].feat_d;
  }
  return 0;
}

/* Packs the frames to store to the front, in file order, and lists the others. */
static int pack(const fg_transforms *t, fg_frame *frames, const frame_error *errs,
                fg_import_result *out) {
  out->skipped = calloc(t->n_frames ? t->n_frames : 1, sizeof *out->skipped);
  if (!out->skipped) return fg_fail(FG_ENOMEM, "out of memory");
  size_t n = 0;
  for (size_t i = 0; i < t->n_frames; i++) {
    if (t->frames[i].image_path && !errs[i].rc) {
      out->with_depth += frames[i].depth != NULL;
      if (n != i) {
        frames[n] = frames[i];
        memset(&frames[i], 0, sizeof frames[i]); /* moved: not freed twice */
      }
      n++;
    } else {
      fg_import_skip *k = &out->skipped[out->n_skipped++];
      k->frame = i;
      k->file_path = t->frames[i].file_path;
      snprintf(k->reason, sizeof k->reason, "%s", errs[i].rc ? errs[i].message
                                                             : "image missing");
    }
  }
  out->imported = n;
  return 0;
}

/* Reads every frame of out->t in parallel into frames; fails on the first frame in file
 * order whose failure is not its depth map's. */
static int read_frames(fg_app *app, const fg_conf *conf, const fg_scene_params *params,
                       fg_import_result *out, fg_frame *frames, frame_error *errs) {
  const fg_transforms *t = &out->t;
  int failed = 0;
  /* Decoding dominates: one frame per thread. */
#pragma omp parallel for schedule(dynamic, 1) num_threads(fg_conf_threads(conf)) reduction(| : failed)
  for (size_t i = 0; i < t->n_frames; i++) {
    if (!t->frames[i].image_path) continue;
    if (import_one(app, conf, &t->frames[i], params, &frames[i], &errs[i]) != 0) failed = 1;
  }
  for (size_t i = 0; failed && i < t->n_frames; i++)
    if (errs[i].rc && !errs[i].depth)
      return fg_fail_as(errs[i].rc, errs[i].code, "frame %zu (%s): %s; nothing was imported", i,
                        t->frames[i].file_path, errs[i].message);
  return 0;
}

int fg_ingest_import(fg_app *app, const fg_conf *conf, fg_scene *s, const char *path,
                     const char *transforms, int64_t capture, fg_import_result *out) {
  memset(out, 0, sizeof *out);
  char where[PATH_MAX];
  int rc = load_transforms(conf, path, transforms, &out->t, where);
  const size_t n = out->t.n_frames ? out->t.n_frames : 1;
  fg_frame *frames = rc == 0 ? calloc(n, sizeof *frames) : NULL;
  frame_error *errs = rc == 0 ? calloc(n, sizeof *errs) : NULL;
  if (rc == 0 && (!frames || !errs)) rc = fg_fail(FG_ENOMEM, "out of memory");
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  if (rc == 0) rc = read_frames(app, conf, &info.params, out, frames, errs);
  if (rc == 0) rc = same_dim(&out->t, frames, info.feature_dim);
  if (rc == 0) rc = pack(&out->t, frames, errs, out);
  for (size_t i = 0; rc == 0 && i < out->imported; i++) frames[i].capture = capture;
  if (rc == 0 && out->imported) rc = add_frames(s, frames, out->imported, &out->first);
  if (rc == 0 && out->imported) out->capture = frames[0].capture;
  for (size_t i = 0; frames && i < out->t.n_frames; i++) fg_frame_clear(&frames[i]);
  free(frames);
  free(errs);
  if (rc != 0) {
    fg_import_result_release(out);
    return rc;
  }
  out->depth_missing = out->t.n_depth_missing;
  fg_info("scene %s: imported %zu frames (%zu with depth) from %s; %zu skipped (%zu: image "
          "missing), %zu without their missing depth file", info.name, out->imported,
          out->with_depth, where, out->n_skipped, out->t.n_missing, out->t.n_depth_missing);
  return 0;
}

void fg_import_result_release(fg_import_result *r) {
  free(r->skipped);
  fg_transforms_free(&r->t);
  memset(r, 0, sizeof *r);
}
