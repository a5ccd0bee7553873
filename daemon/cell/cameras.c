/* The cameras' calibrations and captures (cameras.h). */
#include "cameras_priv.h"

#include "config.h"

#include <curl/curl.h>
#include <dirent.h>
#include <jansson.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/pose.h"
#include "io/image.h"
#include "io/npy.h"

#define SNAPSHOT_MAX_BYTES ((size_t)64 << 20)
/* The robot moved during a capture when its TCP did by more than this. */
#define STILL_M 0.0005
#define STILL_RAD (0.1 * M_PI / 180)

/* ---------------------------------------------------------------- files */

static json_t *matrix_json(const double T[16]) {
  json_t *rows = json_array();
  for (int r = 0; r < 4; r++) {
    json_t *row = json_array();
    for (int c = 0; c < 4; c++) json_array_append_new(row, json_real(T[4 * r + c]));
    json_array_append_new(rows, row);
  }
  return rows;
}

static int matrix_read(json_t *v, double T[16]) {
  if (!json_is_array(v) || json_array_size(v) != 4) return -1;
  for (int r = 0; r < 4; r++) {
    json_t *row = json_array_get(v, (size_t)r);
    if (!json_is_array(row) || json_array_size(row) != 4) return -1;
    for (int c = 0; c < 4; c++) {
      json_t *x = json_array_get(row, (size_t)c);
      if (!json_is_number(x)) return -1;
      T[4 * r + c] = json_number_value(x);
    }
  }
  return fg_pose_validate(T) == 0 ? 0 : -1;
}

static json_t *calib_json(const fg_camera_calib *c) {
  json_t *o = json_object();
  if (c->has_intrinsics) {
    const fg_intrinsics *in = &c->in;
    json_object_set_new(o, "intrinsics",
                        json_pack("{s:i, s:i, s:f, s:f, s:f, s:f, s:[f, f, f, f], s:f, s:i, s:I}",
                                  "w", in->w, "h", in->h, "fx", in->fx, "fy", in->fy, "cx",
                                  in->cx, "cy", in->cy, "k", in->k[0], in->k[1], in->k[2],
                                  in->k[3], "rms_px", c->intrinsics_rms_px, "views",
                                  c->intrinsics_views, "at_ms", (json_int_t)c->intrinsics_ms));
  }
  if (c->has_mount) {
    json_object_set_new(o, "mount",
                        json_pack("{s:o, s:s, s:f, s:f, s:f, s:i, s:I}", "matrix",
                                  matrix_json(c->T_mount), "method", c->method, "spread_mm",
                                  c->spread_mm, "spread_deg", c->spread_deg, "rms_px",
                                  c->mount_rms_px, "views", c->mount_views, "at_ms",
                                  (json_int_t)c->mount_ms));
  }
  return o;
}

static int calib_read(json_t *o, fg_camera_calib *c) {
  memset(c, 0, sizeof *c);
  json_t *in = json_object_get(o, "intrinsics"), *m = json_object_get(o, "mount");
  json_int_t at = 0;
  if (in) {
    json_t *k = NULL;
    if (json_unpack(in, "{s:i, s:i, s:F, s:F, s:F, s:F, s:o, s:F, s:i, s:I}", "w", &c->in.w,
                    "h", &c->in.h, "fx", &c->in.fx, "fy", &c->in.fy, "cx", &c->in.cx, "cy",
                    &c->in.cy, "k", &k, "rms_px", &c->intrinsics_rms_px, "views",
                    &c->intrinsics_views, "at_ms", &at) != 0 ||
        !json_is_array(k) || json_array_size(k) != 4)
      return -1;
    for (int i = 0; i < 4; i++) c->in.k[i] = json_number_value(json_array_get(k, (size_t)i));
    c->intrinsics_ms = at;
    c->has_intrinsics = 1;
  }
  if (m) {
    const char *method;
    if (json_unpack(m, "{s:s, s:F, s:F, s:F, s:i, s:I}", "method", &method, "spread_mm",
                    &c->spread_mm, "spread_deg", &c->spread_deg, "rms_px", &c->mount_rms_px,
                    "views", &c->mount_views, "at_ms", &at) != 0 ||
        matrix_read(json_object_get(m, "matrix"), c->T_mount) != 0)
      return -1;
    snprintf(c->method, sizeof c->method, "%s", method);
    c->mount_ms = at;
    c->has_mount = 1;
  }
  return 0;
}

static void load_all(fg_cameras *c) {
  DIR *d = opendir(c->dir);
  if (!d) return;
  struct dirent *de;
  while ((de = readdir(d)) && c->n < MAX_CAMERAS) {
    const size_t len = strlen(de->d_name);
    if (len < 6 || len - 5 > FG_CAMERA_NAME_MAX || strcmp(de->d_name + len - 5, ".json") != 0)
      continue;
    char *path = fg_path_join(c->dir, de->d_name);
    json_error_t jerr;
    json_t *o = path ? json_load_file(path, 0, &jerr) : NULL;
    entry *e = &c->e[c->n];
    if (o && calib_read(o, &e->calib) == 0) {
      snprintf(e->name, sizeof e->name, "%.*s", (int)(len - 5), de->d_name);
      c->n++;
    } else {
      fg_warn("%s: not a camera calibration; left out", path ? path : de->d_name);
    }
    json_decref(o);
    free(path);
  }
  closedir(d);
}

/* fieldgrip-grab beside the running program (the build tree, or an install that keeps them
 * together), else where it is installed. */
static void find_grabber(fg_cameras *c) {
  char exe[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n > 0) {
    exe[n] = 0;
    char *slash = strrchr(exe, '/');
    static const char name[] = "fieldgrip-grab";
    if (slash && (size_t)(slash + 1 - exe) + sizeof name <= sizeof c->grabber) {
      memcpy(c->grabber, exe, (size_t)(slash + 1 - exe));
      memcpy(c->grabber + (slash + 1 - exe), name, sizeof name);
      if (access(c->grabber, X_OK) == 0) return;
    }
  }
  snprintf(c->grabber, sizeof c->grabber, "%s", FG_LIBEXECDIR "/fieldgrip/fieldgrip-grab");
}

int fg_cameras_new(fg_cameras **out, const char *state_dir) {
  *out = NULL;
  curl_global_init(CURL_GLOBAL_DEFAULT);
  fg_cameras *c = calloc(1, sizeof *c);
  if (!c) return FG_ENOMEM;
  c->dir = fg_path_join(state_dir, "cameras");
  if (!c->dir) {
    free(c);
    return FG_ENOMEM;
  }
  int rc = fg_mkdir_p(c->dir);
  if (rc < 0) {
    free(c->dir);
    free(c);
    return rc;
  }
  pthread_mutex_init(&c->lock, NULL);
  find_grabber(c);
  load_all(c);
  *out = c;
  return 0;
}

void cameras_views_free(entry *e) {
  for (int i = 0; i < e->n_views; i++) {
    free(e->views[i].ids);
    free(e->views[i].px);
  }
  free(e->views);
  e->views = NULL;
  e->n_views = 0;
}

void fg_cameras_free(fg_cameras *c) {
  if (!c) return;
  for (int i = 0; i < c->n; i++) cameras_views_free(&c->e[i]);
  pthread_mutex_destroy(&c->lock);
  free(c->dir);
  free(c);
}

entry *cameras_find_locked(fg_cameras *c, const char *name, int add) {
  for (int i = 0; i < c->n; i++)
    if (strcmp(c->e[i].name, name) == 0) return &c->e[i];
  if (!add || c->n == MAX_CAMERAS) return NULL;
  entry *e = &c->e[c->n++];
  memset(e, 0, sizeof *e);
  snprintf(e->name, sizeof e->name, "%s", name);
  return e;
}

void fg_cameras_calib_get(fg_cameras *c, const char *name, fg_camera_calib *out) {
  pthread_mutex_lock(&c->lock);
  const entry *e = cameras_find_locked(c, name, 0);
  if (e)
    *out = e->calib;
  else
    memset(out, 0, sizeof *out);
  pthread_mutex_unlock(&c->lock);
}

int fg_cameras_calib_set(fg_cameras *c, const char *name, const fg_camera_calib *calib) {
  json_t *o = calib_json(calib);
  char *text = o ? json_dumps(o, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) : NULL;
  json_decref(o);
  char file[FG_CAMERA_NAME_MAX + 8];
  snprintf(file, sizeof file, "%s.json", name);
  char *path = fg_path_join(c->dir, file);
  int rc = text && path ? fg_write_file_atomic(path, text, strlen(text)) : FG_ENOMEM;
  free(text);
  free(path);
  if (rc < 0) return rc;
  pthread_mutex_lock(&c->lock);
  entry *e = cameras_find_locked(c, name, 1);
  if (e) e->calib = *calib;
  pthread_mutex_unlock(&c->lock);
  return 0;
}

/* ---------------------------------------------------------------- captures */

static int robot_pose(fg_robot_svc *robot, double T[16]) {
  fg_robot_tcp t;
  FG_TRY(fg_robot_tcp_read(robot, &t));
  return fg_pose_from_quat(t.p_m, t.q_wxyz, T);
}

int fg_camera_capture(fg_cameras *c, fg_robot_svc *robot, const fg_conf_camera *cam,
                      int image_only, fg_capture *out) {
  memset(out, 0, sizeof *out);
  fg_cameras_calib_get(c, cam->name, &out->calib);
  /* a hand camera's pose needs the robot's; a fixed camera's capture carries it when it can
   * be read (the tool holding a calibration board), and does without */
  const int on_hand = cam->mount == FG_MOUNT_HAND && fg_robot_svc_has_robot(robot);
  int posed = on_hand;
  double T_after[16];
  if (on_hand)
    FG_TRY(robot_pose(robot, out->T_base_tcp));
  else if (fg_robot_svc_has_robot(robot))
    posed = robot_pose(robot, out->T_base_tcp) == 0;
  int rc = fg_snapshot_fetch(c->grabber, cam->source, cam->timeout_ms, SNAPSHOT_MAX_BYTES, &out->image,
                             &out->image_len);
  if (rc == 0 && !fg_image_sniff(out->image, out->image_len))
    rc = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s sent %zu bytes that are no image "
                    "(PNG, JPEG, EXR or TIFF)", cam->source, out->image_len);
  if (rc == 0 && cam->depth_source && !image_only) {
    rc = fg_snapshot_fetch(c->grabber, cam->depth_source, cam->timeout_ms, SNAPSHOT_MAX_BYTES,
                           &out->depth, &out->depth_len);
    if (rc == 0 && !fg_image_sniff(out->depth, out->depth_len))
      rc = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s sent no image",
                      cam->depth_source);
  }
  if (rc == 0 && cam->features_source && !image_only) {
    fg_npy npy;
    rc = fg_snapshot_fetch(c->grabber, cam->features_source, cam->timeout_ms,
                           SNAPSHOT_MAX_BYTES, &out->features, &out->features_len);
    if (rc == 0 && fg_npy_parse(out->features, out->features_len, &npy) != 0)
      rc = fg_fail_as(FG_EUNAVAIL, "camera_unavailable", "%s sent no .npy: %s",
                      cam->features_source, fg_error_detail());
  }
  if (rc == 0 && posed) {
    rc = robot_pose(robot, T_after);
    if (rc == 0 && (sqrt(pow(T_after[3] - out->T_base_tcp[3], 2) +
                         pow(T_after[7] - out->T_base_tcp[7], 2) +
                         pow(T_after[11] - out->T_base_tcp[11], 2)) > STILL_M ||
                    fg_pose_angle_rad(T_after, out->T_base_tcp) > STILL_RAD))
      rc = fg_fail_as(FG_EBUSY, "robot_moved", "the robot moved while %s captured; hold it "
                      "still and capture again", cam->name);
  }
  if (rc < 0) {
    fg_capture_release(out);
    return rc;
  }
  out->has_robot_pose = posed;
  if (out->calib.has_mount && (on_hand || cam->mount == FG_MOUNT_FIXED)) {
    out->has_camera_pose = 1;
    if (on_hand)
      fg_pose_compose(out->T_base_tcp, out->calib.T_mount, out->T_base_cam);
    else
      memcpy(out->T_base_cam, out->calib.T_mount, sizeof out->T_base_cam);
  }
  return 0;
}

void fg_capture_release(fg_capture *cap) {
  free(cap->image);
  free(cap->depth);
  free(cap->features);
  cap->image = cap->depth = cap->features = NULL;
}
