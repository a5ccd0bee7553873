/* Robot-driven scans (scan.h). */
#include "scan.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/pose.h"
#include "drive.h"
#include "frames.h"
#include "io/npy.h"
#include "state/ingest.h"
#include "state/job_train.h"
#include "state/json.h"

/* ---------------------------------------------------------------- viewpoints */

/* Half the narrower field of view, and the radius of the box's bounding sphere. */
static void view_and_box(const double lo[3], const double hi[3], const fg_intrinsics *in,
                         double *half_fov, double *r_box) {
  double r2 = 0;
  for (int k = 0; k < 3; k++) r2 += (hi[k] - lo[k]) * (hi[k] - lo[k]) / 4;
  *r_box = sqrt(r2);
  *half_fov = fmin(atan(in->w / (2 * in->fx)), atan(in->h / (2 * in->fy)));
}

void fg_scan_viewpoints(const double lo[3], const double hi[3], const fg_intrinsics *in,
                        const double T_tcp_cam[16], int n, double radius_m, double el_min_deg,
                        double el_max_deg, double *T_base_tcp) {
  double c[3];
  for (int k = 0; k < 3; k++) c[k] = (lo[k] + hi[k]) / 2;
  if (!(radius_m > 0)) {
    double half_fov, r_box;
    view_and_box(lo, hi, in, &half_fov, &r_box);
    radius_m = r_box / sin(0.8 * half_fov);
  }
  double T_cam_tcp[16];
  fg_pose_inverse(T_tcp_cam, T_cam_tcp);
  const double golden = M_PI * (3 - sqrt(5));
  for (int i = 0; i < n; i++) {
    const double el = (el_min_deg + (el_max_deg - el_min_deg) * (i + 0.5) / n) * M_PI / 180;
    const double az = i * golden;
    const double eye[3] = {c[0] + radius_m * cos(el) * cos(az),
                           c[1] + radius_m * cos(el) * sin(az), c[2] + radius_m * sin(el)};
    double T_base_cam[16];
    fg_pose_look_at(eye, c, 0, T_base_cam);
    fg_pose_compose(T_base_cam, T_cam_tcp, T_base_tcp + 16 * i);
  }
}

double fg_scan_default_radius(const double lo[3], const double hi[3], const fg_intrinsics *in,
                              const double T_tcp_cam[16], int n, double el_min_deg,
                              double el_max_deg, const fg_motion_limits *lim) {
  double half_fov, r_box;
  view_and_box(lo, hi, in, &half_fov, &r_box);
  const double r_far = r_box / sin(0.8 * half_fov), r_near = r_box / sin(half_fov);
  double *T = malloc(sizeof *T * 16 * (size_t)n), best_r = r_far;
  int best = 0;
  for (int s = 0; T && s <= 16; s++) {
    const double r = r_far + (r_near - r_far) * s / 16;
    fg_scan_viewpoints(lo, hi, in, T_tcp_cam, n, r, el_min_deg, el_max_deg, T);
    int ok = 0;
    for (int i = 0; i < n; i++) {
      double p[3], q[4];
      fg_pose_to_quat(T + 16 * i, p, q);
      ok += fg_motion_check_pose(lim, p, q, 0, 0, FG_RETREAT_NONE, NULL) == 0;
    }
    if (ok > best) {
      best = ok;
      best_r = r;
    }
  }
  free(T);
  return best_r;
}

/* ---------------------------------------------------------------- the job */

static void params_free(void *p) {
  fg_scan_request *r = p;
  free(r->T_base_tcp);
  free(r);
}

/* Captures at the viewpoint and stores the frame, with the TCP pose read back, into the
 * scan's capture. 0, or the failure. */
static int capture_store(fg_app *app, const fg_conf *conf, fg_scene *s,
                         const fg_conf_camera *cam, const char *job_id, int64_t capture, int i,
                         int *stored) {
  fg_capture cap;
  FG_TRY(fg_camera_capture(app->cameras, app->robot, cam, 0, &cap));
  char source[96];
  snprintf(source, sizeof source, "scan-%s-%03d", job_id, i);
  fg_npy features;
  fg_ingest_input fi = {.image = cap.image, .image_len = cap.image_len, .depth = cap.depth,
                        .depth_len = cap.depth_len, .depth_scale = cam->depth_scale,
                        .source = source, .capture = capture,
                        .has_robot_pose = cap.has_robot_pose};
  if (cap.has_robot_pose) memcpy(fi.T_world_tcp, cap.T_base_tcp, sizeof fi.T_world_tcp);
  if (cap.features && fg_npy_parse(cap.features, cap.features_len, &features) == 0)
    fi.features = &features;
  fg_cell_frame_camera(&cap.calib, cap.T_base_cam, &fi);
  int index;
  fg_frame frame;
  const int rc = fg_ingest_upload(app, conf, s, &fi, &index, &frame);
  if (rc == 0) {
    fg_frame_clear(&frame);
    (*stored)++;
  }
  fg_capture_release(&cap);
  return rc;
}

/* A viewpoint of the scan (drive.h's visit): capture_store. */
typedef struct scan_ctx {
  fg_app *app;
  const fg_conf *conf;
  fg_scene *scene;
  const fg_conf_camera *cam;
  const char *job_id;
  int64_t capture; /* the scan's own, taken as it starts */
} scan_ctx;

static int scan_visit(void *ctx, int i, int *stored) {
  const scan_ctx *c = ctx;
  return capture_store(c->app, c->conf, c->scene, c->cam, c->job_id, c->capture, i, stored);
}

static void scan_run(fg_job *job, fg_app *app, void *params) {
  fg_scan_request *p = params;
  const fg_conf *conf = fg_app_conf_acquire(app);
  const fg_conf_camera *cam = fg_conf_find_camera(conf, p->camera);
  int stored = 0, skipped = 0, at = 0, rc = 0;
  char route[128];
  snprintf(route, sizeof route, "/v1/scenes/%s/scan", fg_scene_name(fg_job_scene(job)));
  fg_job_set_phase(job, "scanning");
  if (!cam) {
    rc = fg_fail(FG_ENOENT, "camera %s is no longer configured", p->camera);
  } else {
    scan_ctx c = {app, conf, fg_job_scene(job), cam, fg_job_id(job),
                  fg_scene_new_capture(fg_job_scene(job))};
    rc = fg_cell_visit(app, job, route, p->T_base_tcp, p->n, p->settle_ms, scan_visit, &c,
                       &stored, &skipped, &at);
  }
  if (!fg_job_should_stop(job)) {
    if (rc < 0)
      fg_job_fail(job, "viewpoint %d of %d: %s", at, p->n, fg_error_detail());
    else if (stored == 0)
      fg_job_fail(job, "no viewpoint was reachable: the robot refused or failed all %d", p->n);
    else if (!p->train && fg_job_commit_begin(job) == 0)
      fg_job_finish(job, FG_JOB_DONE);
  }
  fg_app_conf_release(app, conf);
  if (p->train && rc == 0 && stored > 0 && !fg_job_should_stop(job))
    fg_job_kind_train.run(job, app, NULL); /* it finishes the job */
}

const fg_job_kind fg_job_kind_scan = {"scan", scan_run, params_free};

int fg_scan_submit(fg_app *app, const fg_conf *conf, fg_scene *s, fg_scan_request *req,
                   fg_job_info *out) {
  const fg_conf_camera *cam = fg_conf_find_camera(conf, req->camera);
  if (!cam)
    return fg_fail_as(FG_ENOENT, "camera_not_found", "no camera \"%s\"", req->camera);
  if (cam->mount != FG_MOUNT_HAND)
    return fg_fail_as(FG_EINVAL, "invalid_request", "%s is a fixed camera: a scan moves a "
                      "camera on the tool", cam->name);
  if (!fg_robot_svc_has_robot(app->robot))
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "a scan moves the robot: set [robot]");
  fg_camera_calib cal;
  fg_cameras_calib_get(app->cameras, cam->name, &cal);
  if (!cal.has_intrinsics || !cal.has_mount)
    return fg_fail_as(FG_EINVAL, "not_calibrated", "%s is not calibrated (intrinsics and "
                      "mount): POST /v1/cameras/%s/calibrate first", cam->name, cam->name);
  if (!req->T_base_tcp) {
    fg_scene_info si;
    fg_scene_get_info(s, &si);
    req->T_base_tcp = malloc(sizeof *req->T_base_tcp * 16 * (size_t)req->n);
    if (!req->T_base_tcp) return fg_fail(FG_ENOMEM, "viewpoints");
    if (!(req->radius_m > 0)) {
      fg_motion_limits lim;
      fg_robot_limits_get(app->robot, &lim);
      req->radius_m = fg_scan_default_radius(si.params.workspace_min, si.params.workspace_max,
                                             &cal.in, cal.T_mount, req->n, req->el_min_deg,
                                             req->el_max_deg, &lim);
    }
    fg_scan_viewpoints(si.params.workspace_min, si.params.workspace_max, &cal.in, cal.T_mount,
                       req->n, req->radius_m, req->el_min_deg, req->el_max_deg,
                       req->T_base_tcp);
  }
  if (req->train) FG_TRY(fg_train_check_init(app, s, &req->train_params));
  const fg_job_params jp = req->train ? req->train_params : (fg_job_params){.steps = req->n};
  fg_scan_request *own = malloc(sizeof *own);
  if (!own) return fg_fail(FG_ENOMEM, "a scan");
  *own = *req;
  const int rc = fg_jobs_submit(app->jobs, "scan", s, &jp, own, out);
  if (rc < 0) {
    free(own);
    return rc;
  }
  req->T_base_tcp = NULL; /* the job's now */
  return 0;
}
