/* Views kept from captures, and calibrating on them (cameras.h, "calibration.c"). */
#include "cameras_priv.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/clock.h"
#include "core/error.h"
#include "decoder/decoder.h"

/* The capture's image as 8-bit grey, decoded in the decoder's children. */
static int grey(struct fg_decoder *dec, const fg_capture *cap, uint8_t **out, int *w, int *h) {
  const float white[3] = {1, 1, 1};
  fg_image img;
  FG_TRY(fg_decoder_decode_sent(dec, cap->image, cap->image_len, white, &img));
  *out = malloc((size_t)img.w * img.h);
  if (!*out) {
    fg_image_release(&img);
    return fg_fail(FG_ENOMEM, "an image of %d x %d", img.w, img.h);
  }
  for (size_t i = 0; i < (size_t)img.w * img.h; i++) {
    const float *p = img.rgb + 3 * i, y = 0.299f * p[0] + 0.587f * p[1] + 0.114f * p[2];
    (*out)[i] = (uint8_t)lrintf(y * 255);
  }
  *w = img.w;
  *h = img.h;
  fg_image_release(&img);
  return 0;
}

int fg_cameras_view_add(fg_cameras *c, struct fg_decoder *dec, const fg_charuco_board *b,
                        const fg_conf_camera *cam, const fg_capture *cap, int *corners,
                        int *kept) {
  *corners = *kept = 0;
  uint8_t *g;
  kept_view v = {.has_robot_pose = cap->has_robot_pose};
  FG_TRY(grey(dec, cap, &g, &v.w, &v.h));
  const int max = fg_charuco_corner_count(b);
  v.ids = malloc(sizeof *v.ids * (size_t)max);
  v.px = malloc(sizeof *v.px * 2 * (size_t)max);
  int rc = v.ids && v.px ? fg_charuco_detect(b, g, v.w, v.h, v.ids, v.px, &v.n) : FG_ENOMEM;
  free(g);
  *corners = v.n;
  if (rc == 0 && v.n >= FG_CALIB_MIN_CORNERS) {
    memcpy(v.T_base_tcp, cap->T_base_tcp, sizeof v.T_base_tcp);
    pthread_mutex_lock(&c->lock);
    entry *e = cameras_find_locked(c, cam->name, 1);
    kept_view *grown = NULL;
    if (!e || e->n_views == FG_CAMERA_MAX_VIEWS)
      rc = fg_fail_as(FG_ERANGE, "too_many_views", "%s keeps at most %d views; calibrate on "
                      "them or forget them (DELETE /v1/cameras/%s/views)", cam->name,
                      FG_CAMERA_MAX_VIEWS, cam->name);
    else if (e->n_views && (e->views[0].w != v.w || e->views[0].h != v.h))
      rc = fg_fail_as(FG_EINVAL, "invalid_image", "this image is %d x %d, the views kept are "
                      "%d x %d; forget them first (DELETE /v1/cameras/%s/views)", v.w, v.h,
                      e->views[0].w, e->views[0].h, cam->name);
    else if (!(grown = realloc(e->views, sizeof *grown * (size_t)(e->n_views + 1))))
      rc = fg_fail(FG_ENOMEM, "a view");
    if (rc == 0) {
      e->views = grown;
      e->views[e->n_views++] = v;
      *kept = e->n_views;
      v.ids = NULL;
      v.px = NULL;
    }
    pthread_mutex_unlock(&c->lock);
  }
  free(v.ids);
  free(v.px);
  return rc;
}

int fg_cameras_views_count(fg_cameras *c, const char *name) {
  pthread_mutex_lock(&c->lock);
  const entry *e = cameras_find_locked(c, name, 0);
  const int n = e ? e->n_views : 0;
  pthread_mutex_unlock(&c->lock);
  return n;
}

void fg_cameras_views_clear(fg_cameras *c, const char *name) {
  pthread_mutex_lock(&c->lock);
  entry *e = cameras_find_locked(c, name, 0);
  if (e) cameras_views_free(e);
  pthread_mutex_unlock(&c->lock);
}

/* The kept views, taken out of the entry (NULL, 0 when none). */
static kept_view *views_take(fg_cameras *c, const char *name, int *n) {
  pthread_mutex_lock(&c->lock);
  entry *e = cameras_find_locked(c, name, 0);
  kept_view *v = e ? e->views : NULL;
  *n = e ? e->n_views : 0;
  if (e) {
    e->views = NULL;
    e->n_views = 0;
  }
  pthread_mutex_unlock(&c->lock);
  return v;
}

/* Puts views back in front of any kept meanwhile (a refused calibration keeps its views). */
static void views_put_back(fg_cameras *c, const char *name, kept_view *v, int n) {
  if (n == 0) return;
  pthread_mutex_lock(&c->lock);
  entry *e = cameras_find_locked(c, name, 1);
  kept_view *all = e ? realloc(v, sizeof *v * (size_t)(n + e->n_views)) : NULL;
  if (all) {
    if (e->n_views) memcpy(all + n, e->views, sizeof *all * (size_t)e->n_views);
    free(e->views);
    e->views = all;
    e->n_views += n;
  } else {
    entry lost = {.views = v, .n_views = n};
    cameras_views_free(&lost);
  }
  pthread_mutex_unlock(&c->lock);
}

static int calibrate_intrinsics(const fg_charuco_board *b, const kept_view *kv, int n,
                                fg_calibration_report *r) {
  fg_calib_view *views = malloc(sizeof *views * (size_t)n);
  double *per_view = malloc(sizeof *per_view * (size_t)n);
  if (!views || !per_view) {
    free(views);
    free(per_view);
    return fg_fail(FG_ENOMEM, "calibration views");
  }
  for (int i = 0; i < n; i++) views[i] = (fg_calib_view){kv[i].n, kv[i].ids, kv[i].px};
  double rms;
  int rc = fg_calibrate_intrinsics(b, views, n, kv[0].w, kv[0].h, &r->calib.in, &rms, per_view);
  if (rc < 0) rc = fg_fail_as(rc, "not_enough_views", "%s", fg_error_detail());
  for (int i = 0; i < n; i++) r->views_used += rc == 0 && !isnan(per_view[i]);
  free(views);
  free(per_view);
  FG_TRY(rc);
  r->calib.has_intrinsics = 1;
  r->calib.intrinsics_rms_px = rms;
  r->calib.intrinsics_views = r->views_used;
  r->calib.intrinsics_ms = fg_real_ms();
  if (rms > FG_CALIB_MAX_RMS_PX)
    return fg_fail_as(FG_ERANGE, "calibration_rejected", "the intrinsics explain the %d views "
                      "to %.2f px rms, more than %.1f px: views blurred, or the board bent or "
                      "measured wrong; the previous calibration stays", r->views_used, rms,
                      FG_CALIB_MAX_RMS_PX);
  return 0;
}

static int calibrate_mount(const fg_charuco_board *b, const fg_conf_camera *cam,
                           const kept_view *kv, int n, fg_calibration_report *r) {
  if (!r->calib.has_intrinsics)
    return fg_fail_as(FG_EINVAL, "not_calibrated", "%s has no intrinsics yet: calibrate them "
                      "first (\"kind\": \"intrinsics\")", cam->name);
  double *T_tcp = malloc(sizeof *T_tcp * 16 * (size_t)n), *T_cb = malloc(sizeof *T_cb * 16 * (size_t)n);
  fg_calib_view *views = malloc(sizeof *views * (size_t)n);
  int rc = T_tcp && T_cb && views ? 0 : fg_fail(FG_ENOMEM, "calibration views"), m = 0;
  for (int i = 0; rc == 0 && i < n; i++) {
    double e;
    const fg_calib_view v = {kv[i].n, kv[i].ids, kv[i].px};
    if (!kv[i].has_robot_pose)
      rc = fg_fail_as(FG_EINVAL, "not_enough_views", "view %d has no robot pose: hand-eye "
                      "calibration needs the robot's TCP with every view", i);
    else if (fg_calib_board_pose(b, &v, &r->calib.in, T_cb + 16 * m, &e) == 0) {
      memcpy(T_tcp + 16 * m, kv[i].T_base_tcp, sizeof kv[i].T_base_tcp);
      views[m++] = v;
    }
  }
  const int fixed = cam->mount == FG_MOUNT_FIXED;
  if (rc == 0) {
    rc = fg_calibrate_hand_eye(T_tcp, T_cb, m, fixed, r->methods, &r->best);
    if (rc < 0) {
      const int few = m < FG_CALIB_MIN_VIEWS_HAND_EYE;
      rc = fg_fail_as(rc, few ? "not_enough_views" : "degenerate_motion", "%s",
                      fg_error_detail());
    }
  }
  double rms = 0;
  fg_camera_calib *k = &r->calib;
  if (rc == 0) {
    memcpy(k->T_mount, r->methods[r->best].T, sizeof k->T_mount);
    double T_fixed[16];
    memcpy(T_fixed, r->methods[r->best].T_fixed, sizeof T_fixed);
    rc = fg_calibrate_hand_eye_refine(b, views, T_tcp, m, fixed, 0, &k->in, k->T_mount, T_fixed,
                                      &rms);
  }
  if (rc == 0) {
    /* the spread of the refined mount, on board poses of the refined intrinsics */
    for (int i = 0; i < m; i++) {
      double e;
      fg_calib_board_pose(b, &views[i], &k->in, T_cb + 16 * i, &e);
    }
    double T_fixed[16];
    fg_hand_eye_spread(T_tcp, T_cb, m, fixed, k->T_mount, T_fixed, &k->spread_mm,
                       &k->spread_deg);
    r->views_used = k->mount_views = m;
    k->has_mount = 1;
    k->mount_rms_px = rms;
    snprintf(k->method, sizeof k->method, "%s", fg_hand_eye_method_name(r->best));
    k->mount_ms = fg_real_ms();
    if (rms > FG_CALIB_MAX_RMS_PX || k->spread_mm > FG_CALIB_MAX_SPREAD_MM ||
        k->spread_deg > FG_CALIB_MAX_SPREAD_DEG)
      rc = fg_fail_as(FG_ERANGE, "calibration_rejected", "the mount explains the %d views to "
                      "%.2f px rms and the board's pose spreads by %.2f mm and %.2f degrees "
                      "over them (bounds: %.1f px, %.1f mm, %.1f degrees): the robot's poses or "
                      "the board moved between views, or the board is measured wrong; the "
                      "previous calibration stays", m, rms, k->spread_mm, k->spread_deg,
                      FG_CALIB_MAX_RMS_PX, FG_CALIB_MAX_SPREAD_MM, FG_CALIB_MAX_SPREAD_DEG);
  }
  free(T_tcp);
  free(T_cb);
  free(views);
  return rc;
}

int fg_camera_calibrate(fg_cameras *c, const fg_charuco_board *b, const fg_conf_camera *cam,
                        fg_calibrate_kind kind, fg_calibration_report *r) {
  memset(r, 0, sizeof *r);
  r->best = -1;
  fg_cameras_calib_get(c, cam->name, &r->calib);
  int n;
  kept_view *kv = views_take(c, cam->name, &n);
  r->views = n;
  int rc = 0;
  if (n == 0)
    rc = fg_fail_as(FG_EINVAL, "not_enough_views", "%s has no views kept: capture with "
                    "{\"calibration_view\": true} first", cam->name);
  else if (kind != FG_CALIBRATE_HAND_EYE)
    rc = calibrate_intrinsics(b, kv, n, r);
  if (rc == 0 && kind != FG_CALIBRATE_INTRINSICS) rc = calibrate_mount(b, cam, kv, n, r);
  if (rc == 0) rc = fg_cameras_calib_set(c, cam->name, &r->calib);
  if (rc < 0) {
    views_put_back(c, cam->name, kv, n);
    return rc;
  }
  entry done = {.views = kv, .n_views = n};
  cameras_views_free(&done);
  return 0;
}
