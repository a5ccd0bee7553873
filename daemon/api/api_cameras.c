/* GET /v1/cameras, GET /v1/cameras/{c}, POST /v1/cameras/{c}/capture, POST and DELETE
 * /v1/cameras/{c}/views, POST /v1/cameras/{c}/calibrate: the cameras of [camera NAME], what
 * their calibration says, a capture, the views kept for the next calibration, and
 * calibrating on them (or queueing a calibration the robot drives). */
#include "api.h"

#include "core/error.h"

#include "cell/calib_job.h"
#include "cell/cameras.h"
#include "state/json.h"

#include <nettle/base64.h>
#include <stdlib.h>
#include <string.h>

/* The intrinsics as frames take them (SPEC.md "Frames and units"), with the calibration's
 * residual; null when not calibrated. */
static json_t *intrinsics_json(const fg_camera_calib *c) {
  if (!c->has_intrinsics) return json_null();
  const fg_intrinsics *in = &c->in;
  return json_pack("{s:f, s:f, s:f, s:f, s:i, s:i, s:s, s:f, s:f, s:f, s:f}", "fl_x", in->fx,
                   "fl_y", in->fy, "cx", in->cx, "cy", in->cy, "w", in->w, "h", in->h,
                   "camera_model", "OPENCV", "k1", in->k[0], "k2", in->k[1], "p1", in->k[2],
                   "p2", in->k[3]);
}

static json_t *calibration_json(const fg_camera_calib *c) {
  json_t *o = json_object();
  json_object_set_new(o, "intrinsics",
                      c->has_intrinsics
                          ? json_pack("{s:f, s:i, s:o}", "rms_px", c->intrinsics_rms_px, "views",
                                      c->intrinsics_views, "at",
                                      fg_json_time_ms(c->intrinsics_ms))
                          : json_null());
  json_object_set_new(o, "mount",
                      c->has_mount
                          ? json_pack("{s:s, s:f, s:f, s:f, s:i, s:o}", "method", c->method,
                                      "spread_mm", c->spread_mm, "spread_deg", c->spread_deg,
                                      "rms_px", c->mount_rms_px, "views", c->mount_views, "at",
                                      fg_json_time_ms(c->mount_ms))
                          : json_null());
  return o;
}

static json_t *camera_json(const fg_conf_camera *cam, const fg_camera_calib *c, int views) {
  json_t *o = json_pack("{s:s, s:s, s:o, s:f, s:o, s:s, s:b}", "name", cam->name, "source",
                        cam->source, "depth_source",
                        cam->depth_source ? json_string(cam->depth_source) : json_null(),
                        "depth_scale", cam->depth_scale, "features_source",
                        cam->features_source ? json_string(cam->features_source) : json_null(),
                        "mount",
                        cam->mount == FG_MOUNT_HAND ? "hand" : "fixed", "calibrated",
                        c->has_intrinsics && c->has_mount);
  json_object_set_new(o, "intrinsics", intrinsics_json(c));
  json_object_set_new(o, cam->mount == FG_MOUNT_HAND ? "T_tcp_cam" : "T_base_cam",
                      c->has_mount ? fg_json_pose(c->T_mount) : json_null());
  json_object_set_new(o, "calibration", calibration_json(c));
  json_object_set_new(o, "views_kept", json_integer(views));
  return o;
}

/* The camera of the path, or NULL after a 404. */
static const fg_conf_camera *camera_param(fg_req *req, fg_resp *resp) {
  const fg_conf_camera *cam = fg_conf_find_camera(req->conf, req->params[0]);
  if (!cam)
    fg_resp_error(resp, 404, "camera_not_found", "no camera \"%s\"; [camera NAME] sections "
                  "declare them (GET /v1/cameras lists them)", req->params[0]);
  return cam;
}

int fg_api_cameras_list(fg_req *req, fg_resp *resp) {
  json_t *list = json_array();
  for (size_t i = 0; i < req->conf->n_cameras; i++) {
    fg_camera_calib c;
    fg_cameras_calib_get(req->app->cameras, req->conf->cameras[i].name, &c);
    json_array_append_new(list, camera_json(&req->conf->cameras[i], &c,
                                            fg_cameras_views_count(req->app->cameras,
                                                                   req->conf->cameras[i].name)));
  }
  fg_resp_json(resp, 200, json_pack("{s:o}", "cameras", list));
  return 0;
}

int fg_api_camera_get(fg_req *req, fg_resp *resp) {
  const fg_conf_camera *cam = camera_param(req, resp);
  if (!cam) return 0;
  fg_camera_calib c;
  fg_cameras_calib_get(req->app->cameras, cam->name, &c);
  fg_resp_json(resp, 200,
               camera_json(cam, &c, fg_cameras_views_count(req->app->cameras, cam->name)));
  return 0;
}

static json_t *base64_json(const uint8_t *data, size_t len) {
  if (!data) return json_null();
  char *text = malloc(BASE64_ENCODE_RAW_LENGTH(len) + 1);
  if (!text) return NULL;
  base64_encode_raw(text, len, data);
  text[BASE64_ENCODE_RAW_LENGTH(len)] = '\0';
  json_t *s = json_string(text);
  free(text);
  return s;
}

/* The capture's view: the images and the features (base64), the robot's pose, the camera's pose (OpenCV
 * convention) and intrinsics when calibrated. */
static json_t *capture_json(const fg_conf_camera *cam, const fg_capture *cap) {
  json_t *o = json_pack("{s:s, s:s}", "camera", cam->name, "image_type",
                        fg_image_sniff(cap->image, cap->image_len));
  json_object_set_new(o, "image", base64_json(cap->image, cap->image_len));
  json_object_set_new(o, "depth", base64_json(cap->depth, cap->depth_len));
  json_object_set_new(o, "depth_scale", cap->depth ? json_real(cam->depth_scale) : json_null());
  json_object_set_new(o, "features", base64_json(cap->features, cap->features_len));
  json_object_set_new(o, "robot_pose",
                      cap->has_robot_pose ? fg_json_pose(cap->T_base_tcp) : json_null());
  json_object_set_new(o, "camera_pose",
                      cap->has_camera_pose ? fg_json_pose(cap->T_base_cam) : json_null());
  json_object_set_new(o, "convention", json_string("opencv"));
  json_object_set_new(o, "intrinsics", intrinsics_json(&cap->calib));
  return o;
}

/* The body of a capture: empty, or {"calibration_view": bool}. 0, or -1 after a 400. */
static int parse_capture(fg_req *req, fg_resp *resp, int *keep) {
  *keep = 0;
  if (!req->body_len) return 0;
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return -1;
  static const char *const keys[] = {"calibration_view", NULL};
  json_t *k = json_object_get(body, "calibration_view");
  const char *unknown = fg_json_unknown_key(body, keys);
  int ok = !unknown && (!k || json_is_boolean(k));
  if (ok) *keep = json_is_true(k);
  json_decref(body);
  if (ok) return 0;
  fg_resp_error(resp, 400, "invalid_request", "a capture takes only \"calibration_view\": "
                "true or false");
  return -1;
}

int fg_api_camera_capture(fg_req *req, fg_resp *resp) {
  const fg_conf_camera *cam = camera_param(req, resp);
  int keep;
  if (!cam || parse_capture(req, resp, &keep) != 0) return 0;
  fg_capture cap;
  int rc = fg_camera_capture(req->app->cameras, req->app->robot, cam, 0, &cap);
  int corners = 0, kept = 0;
  if (rc == 0 && keep)
    rc = fg_cameras_view_add(req->app->cameras, req->app->decoder, &req->conf->board, cam, &cap,
                             &corners, &kept);
  if (rc < 0) {
    fg_capture_release(&cap);
    return fg_api_fail(resp, rc);
  }
  json_t *o = capture_json(cam, &cap);
  if (keep) {
    json_object_set_new(o, "board_corners", json_integer(corners));
    json_object_set_new(o, "views_kept", json_integer(fg_cameras_views_count(req->app->cameras,
                                                                             cam->name)));
    json_object_set_new(o, "view_kept", json_boolean(kept > 0));
  }
  fg_resp_json(resp, 200, o);
  fg_capture_release(&cap);
  return 0;
}

/* The parts of a view upload: a non-empty image and a meta object with robot_pose. 0, or
 * -1 after a 400. */
static int parse_view_upload(fg_req *req, fg_resp *resp, fg_capture *cap) {
  memset(cap, 0, sizeof *cap);
  const fg_part *image = fg_req_part(req, "image"), *meta_part = fg_req_part(req, "meta");
  for (int i = 0; i < req->n_parts; i++)
    if (strcmp(req->parts[i].name, "image") != 0 && strcmp(req->parts[i].name, "meta") != 0)
      return fg_resp_error(resp, 400, "invalid_request", "unexpected part '%s'; a view is an "
                           "'image' and a 'meta' part", req->parts[i].name), -1;
  if (!image || image->len == 0 || !meta_part)
    return fg_resp_error(resp, 400, "missing_part", "a view needs a non-empty 'image' part (the "
                         "photo of the board) and a 'meta' part ({\"robot_pose\": the TCP pose "
                         "when it was taken})"), -1;
  char err[256];
  json_t *meta = fg_json_parse(meta_part->data, meta_part->len, err, sizeof err);
  if (!meta)
    return fg_resp_error(resp, 400, "malformed_json", "the 'meta' part is not valid JSON: %s",
                         err), -1;
  static const char *const keys[] = {"robot_pose", NULL};
  const char *unknown = fg_json_unknown_key(meta, keys);
  int rc = 0;
  if (!json_is_object(meta) || unknown)
    rc = (fg_resp_error(resp, 400, "invalid_request", "the 'meta' part is an object with only "
                        "\"robot_pose\""), -1);
  else if (fg_json_pose_parse(json_object_get(meta, "robot_pose"), "robot_pose", cap->T_base_tcp,
                              NULL) != 0)
    rc = (fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail()), -1);
  json_decref(meta);
  cap->image = (uint8_t *)image->data; /* borrowed: the request's */
  cap->image_len = image->len;
  cap->has_robot_pose = 1;
  return rc;
}

/* POST /v1/cameras/{c}/views: a calibration view from a robot stack that moves the robot
 * itself: the photo and the TCP pose it was taken at. */
int fg_api_camera_view_upload(fg_req *req, fg_resp *resp) {
  const fg_conf_camera *cam = camera_param(req, resp);
  fg_capture cap;
  if (!cam || parse_view_upload(req, resp, &cap) != 0) return 0;
  int corners = 0, kept = 0;
  int rc = fg_cameras_view_add(req->app->cameras, req->app->decoder, &req->conf->board, cam, &cap,
                               &corners, &kept);
  if (rc < 0) return fg_api_fail(resp, rc);
  if (!kept)
    return fg_resp_error(resp, 422, "board_not_found", "the view shows %d of the board's corners; "
                         "a view needs %d or more (the whole board in focus, no glare)", corners,
                         FG_CALIB_MIN_CORNERS);
  fg_resp_json(resp, 201, json_pack("{s:s, s:i, s:i}", "camera", cam->name, "board_corners",
                                    corners, "views_kept", kept));
  return 0;
}

/* DELETE /v1/cameras/{c}/views: forgets the views kept for calibration. */
int fg_api_camera_views_clear(fg_req *req, fg_resp *resp) {
  const fg_conf_camera *cam = camera_param(req, resp);
  if (!cam) return 0;
  fg_cameras_views_clear(req->app->cameras, cam->name);
  fg_resp_json(resp, 200, json_pack("{s:i}", "views_kept", 0));
  return 0;
}

static json_t *report_json(const fg_conf_camera *cam, const fg_calibration_report *r,
                           const fg_camera_calib *now, int views) {
  json_t *o = json_pack("{s:i, s:i}", "views", r->views, "views_used", r->views_used);
  if (r->best >= 0) {
    json_t *methods = json_array();
    for (int m = 0; m < FG_HAND_EYE_METHODS; m++) {
      const fg_hand_eye_result *h = &r->methods[m];
      json_array_append_new(methods, h->ok ? json_pack("{s:s, s:o, s:f, s:f}", "method",
                                                       fg_hand_eye_method_name(m), "pose",
                                                       fg_json_pose(h->T), "spread_mm",
                                                       h->spread_mm, "spread_deg",
                                                       h->spread_deg)
                                           : json_pack("{s:s, s:n}", "method",
                                                       fg_hand_eye_method_name(m), "pose"));
    }
    json_object_set_new(o, "methods", methods);
    json_object_set_new(o, "refined_from", json_string(fg_hand_eye_method_name(r->best)));
  }
  json_object_set_new(o, "camera", camera_json(cam, now, views));
  return o;
}

/* "drive": {"target", "viewpoints", "distance_m", "elevations_deg", "tilt_deg", "roll_deg",
 * "settle_ms", "mount", "camera_position"} into *d (cell/calib_job.h). 0, or -1 after a 400. */
static int parse_drive(json_t *v, fg_calib_drive *d, fg_resp *resp) {
  static const char *const keys[] = {"target", "viewpoints", "distance_m", "elevations_deg",
                                     "tilt_deg", "roll_deg", "settle_ms", "mount",
                                     "camera_position", NULL};
  const char *unknown = json_is_object(v) ? fg_json_unknown_key(v, keys) : "(not an object)";
  if (unknown)
    return fg_resp_error(resp, 400, "invalid_request", "\"drive\" takes target, viewpoints, "
                         "distance_m, elevations_deg, tilt_deg, roll_deg, settle_ms, mount, "
                         "camera_position; not %s", unknown), -1;
  d->n = 30;
  d->dist_m[0] = 0.30;
  d->dist_m[1] = 0.40;
  d->el_deg[0] = 50;
  d->el_deg[1] = 80;
  d->tilt_deg[0] = 15;
  d->tilt_deg[1] = 45;
  d->roll_deg = 60;
  long long n = d->n, settle = 300;
  json_t *dist = json_object_get(v, "distance_m"), *el = json_object_get(v, "elevations_deg"),
         *tilt = json_object_get(v, "tilt_deg"), *mount = json_object_get(v, "mount"),
         *camera = json_object_get(v, "camera_position");
  d->has_el = el != NULL;
  d->has_tilt = tilt != NULL;
  d->has_camera_guess = camera != NULL;
  if (fg_json_vec(json_object_get(v, "target"), d->target, 3, "target") != 0)
    return fg_resp_error(resp, 400, "invalid_request", "\"drive\" needs \"target\": [x, y, "
                         "z], where the board lies (its centre, or near it) in the base frame, "
                         "metres"), -1;
  if ((json_object_get(v, "viewpoints") &&
       fg_json_int_range(v, "viewpoints", FG_CALIB_MIN_VIEWS_INTRINSICS,
                         FG_CALIB_DRIVE_MAX_VIEWS, &n) != 1) ||
      (dist && (fg_json_vec(dist, d->dist_m, 2, "distance_m") != 0 ||
                !(d->dist_m[0] > 0 && d->dist_m[0] <= d->dist_m[1] && d->dist_m[1] <= 2))) ||
      (el && (fg_json_vec(el, d->el_deg, 2, "elevations_deg") != 0 ||
              !(d->el_deg[0] >= 0 && d->el_deg[0] <= d->el_deg[1] && d->el_deg[1] <= 90))) ||
      (tilt && (fg_json_vec(tilt, d->tilt_deg, 2, "tilt_deg") != 0 ||
                !(d->tilt_deg[0] >= 0 && d->tilt_deg[0] <= d->tilt_deg[1] &&
                  d->tilt_deg[1] <= 60))) ||
      (camera && fg_json_vec(camera, d->camera_guess, 3, "camera_position") != 0) ||
      (json_object_get(v, "roll_deg") &&
       (fg_json_number(v, "roll_deg", &d->roll_deg) != 1 ||
        !(d->roll_deg >= 0 && d->roll_deg <= 90))) ||
      (json_object_get(v, "settle_ms") &&
       fg_json_int_range(v, "settle_ms", 0, 10000, &settle) != 1))
    return fg_resp_error(resp, 400, "invalid_request", "drive: viewpoints %d to %d; "
                         "distance_m [near, far] above 0, at most 2; elevations_deg [low, "
                         "high] from 0 to 90, low <= high; tilt_deg [low, high] from 0 to 60, "
                         "low <= high; camera_position [x, y, z]; roll_deg 0 to 90; settle_ms "
                         "0 to 10000", FG_CALIB_MIN_VIEWS_INTRINSICS, FG_CALIB_DRIVE_MAX_VIEWS),
           -1;
  d->n = (int)n;
  d->settle_ms = (int)settle;
  double q[4];
  d->has_mount_guess = mount != NULL;
  if (mount && fg_json_pose_parse(mount, "drive.mount", d->T_mount_guess, q) != 0)
    return fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail()), -1;
  return 0;
}

/* Queues the driven calibration d: 202 and the job, or the refusal. */
static int calibrate_driven(fg_req *req, fg_resp *resp, fg_calib_drive *d) {
  fg_job_info job;
  const int rc = fg_calib_drive_submit(req->app, req->conf, d, &job);
  free(d->T_base_tcp); /* NULL once the job took them */
  if (rc < 0) return fg_api_fail(resp, rc);
  snprintf(resp->location, sizeof resp->location, "/v1/jobs/%s", job.id);
  fg_resp_json(resp, 202, json_pack("{s:s, s:s, s:i}", "job", job.id, "state",
                                    fg_job_state_name(job.state), "viewpoints", d->n));
  return 0;
}

int fg_api_camera_calibrate(fg_req *req, fg_resp *resp) {
  const fg_conf_camera *cam = camera_param(req, resp);
  if (!cam) return 0;
  json_t *body = fg_api_body_object(req, resp);
  if (!body) return 0;
  static const char *const keys[] = {"kind", "drive", NULL};
  static const char *const kinds[] = {"intrinsics", "hand_eye", "both"};
  const char *kind = json_string_value(json_object_get(body, "kind"));
  int k = -1;
  for (int i = 0; kind && i < 3; i++)
    if (strcmp(kind, kinds[i]) == 0) k = i;
  fg_calib_drive d = {.kind = (fg_calibrate_kind)k};
  json_t *drive = json_object_get(body, "drive");
  int rc = 0;
  if (fg_json_unknown_key(body, keys) || k < 0) {
    fg_resp_error(resp, 400, "invalid_request", "calibrate takes {\"kind\": \"intrinsics\" | "
                  "\"hand_eye\" | \"both\"}: on the views kept by captures with "
                  "\"calibration_view\": true and uploads; with \"drive\": {\"target\": [x, y, "
                  "z], ...} the robot takes the views itself");
    rc = -1;
  } else if (drive) {
    rc = parse_drive(drive, &d, resp);
  }
  if (rc == 0 && drive) snprintf(d.camera, sizeof d.camera, "%s", cam->name);
  json_decref(body);
  if (rc < 0) return 0;
  if (drive) return calibrate_driven(req, resp, &d);
  fg_calibration_report r;
  rc = fg_camera_calibrate(req->app->cameras, &req->conf->board, cam, d.kind, &r);
  if (rc < 0) return fg_api_fail(resp, rc);
  fg_camera_calib now;
  fg_cameras_calib_get(req->app->cameras, cam->name, &now);
  fg_resp_json(resp, 200,
               report_json(cam, &r, &now, fg_cameras_views_count(req->app->cameras, cam->name)));
  return 0;
}
