/* Calibrations the robot drives (calib_job.h). */
#include "calib_job.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/pose.h"
#include "drive.h"

/* The n TCP poses that put a camera at T_tcp_cam on the tool at eyes around target, each
 * looking at it: azimuths spread over the circle, elevations, distances and rolls over their
 * ranges in interleaved patterns, so that any 8 consecutive views turn about several axes
 * (hand-eye needs that). */
static void drive_viewpoints(const double target[3], const double T_tcp_cam[16], int n,
                             const double dist_m[2], const double el_deg[2], double roll_deg,
                             double *T_base_tcp) {
  double T_cam_tcp[16];
  fg_pose_inverse(T_tcp_cam, T_cam_tcp);
  for (int i = 0; i < n; i++) {
    /* steps of 3/5, 2/3 and 5/7 of a range walk it in a different order each */
    const double az = 2 * M_PI * i / n + 0.3 * (i % 3);
    const double el = (el_deg[0] + (el_deg[1] - el_deg[0]) * ((i * 3) % 5) / 4.0) * M_PI / 180;
    const double d = dist_m[0] + (dist_m[1] - dist_m[0]) * ((i * 2) % 3) / 2.0;
    const double roll = roll_deg * (-1 + 2 * ((i * 5) % 7) / 6.0) * M_PI / 180;
    const double eye[3] = {target[0] + d * cos(el) * cos(az), target[1] + d * cos(el) * sin(az),
                           target[2] + d * sin(el)};
    double T_base_cam[16];
    fg_pose_look_at(eye, target, roll, T_base_cam);
    fg_pose_compose(T_base_cam, T_cam_tcp, T_base_tcp + 16 * i);
  }
}

static void params_free(void *p) {
  fg_calib_drive *r = p;
  free(r->T_base_tcp);
  free(r);
}

typedef struct view_ctx {
  fg_app *app;
  const fg_conf *conf;
  const fg_conf_camera *cam;
} view_ctx;

/* Captures at the viewpoint and keeps the view when it shows the board (drive.h's visit): 0
 * (*kept: the views kept now, unchanged when the board was not seen), or the failure. */
static int capture_view(void *ctx, int i, int *kept) {
  const view_ctx *c = ctx;
  (void)i;
  fg_capture cap;
  FG_TRY(fg_camera_capture(c->app->cameras, c->app->robot, c->cam, 1, &cap));
  int corners, now;
  const int rc = fg_cameras_view_add(c->app->cameras, c->app->decoder, &c->conf->board, c->cam,
                                     &cap, &corners, &now);
  fg_capture_release(&cap);
  if (rc == 0 && now > 0) *kept = now;
  return rc;
}

static void calibrate_run(fg_job *job, fg_app *app, void *params) {
  fg_calib_drive *p = params;
  const fg_conf *conf = fg_app_conf_acquire(app);
  const fg_conf_camera *cam = fg_conf_find_camera(conf, p->camera);
  char route[128];
  snprintf(route, sizeof route, "/v1/cameras/%s/calibrate", p->camera);
  int kept = 0, skipped = 0, rc = 0, at = 0; /* at: the viewpoint being worked on */
  fg_job_set_phase(job, "capturing");
  if (!cam) {
    rc = fg_fail(FG_ENOENT, "camera %s is no longer configured", p->camera);
  } else {
    fg_cameras_views_clear(app->cameras, cam->name);
    view_ctx c = {app, conf, cam};
    rc = fg_cell_visit(app, job, route, p->T_base_tcp, p->n, p->settle_ms, capture_view, &c,
                       &kept, &skipped, &at);
  }
  if (!fg_job_should_stop(job)) {
    if (rc < 0) {
      fg_job_fail(job, "viewpoint %d of %d: %s", at + 1, p->n, fg_error_detail());
    } else {
      fg_job_set_phase(job, "calibrating");
      fg_calibration_report r;
      if (fg_job_commit_begin(job) == 0) {
        if (fg_camera_calibrate(app->cameras, &conf->board, cam, p->kind, &r) < 0)
          fg_job_fail(job, "%s (%d of %d viewpoints showed the board, %d were out of reach)",
                      fg_error_detail(), kept, p->n, skipped);
        else
          fg_job_finish(job, FG_JOB_DONE);
      }
    }
  }
  fg_app_conf_release(app, conf);
}

const fg_job_kind fg_job_kind_calibrate = {"calibrate", calibrate_run, params_free};

int fg_calib_drive_submit(fg_app *app, const fg_conf *conf, fg_calib_drive *req,
                          fg_job_info *out) {
  const fg_conf_camera *cam = fg_conf_find_camera(conf, req->camera);
  if (!cam)
    return fg_fail_as(FG_ENOENT, "camera_not_found", "no camera \"%s\"", req->camera);
  if (cam->mount != FG_MOUNT_HAND)
    return fg_fail_as(FG_EINVAL, "invalid_request", "%s is a fixed camera: \"drive\" moves a "
                      "camera on the tool around the board; for a fixed camera, move the board "
                      "with the robot and upload its views (POST /v1/cameras/%s/views)",
                      cam->name, cam->name);
  if (!fg_robot_svc_has_robot(app->robot))
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "\"drive\" moves the robot: set [robot]");
  fg_camera_calib cal;
  fg_cameras_calib_get(app->cameras, cam->name, &cal);
  if (req->kind == FG_CALIBRATE_HAND_EYE && !cal.has_intrinsics)
    return fg_fail_as(FG_EINVAL, "not_calibrated", "%s has no intrinsics yet: calibrate them "
                      "first, or both at once (\"kind\": \"both\")", cam->name);
  double T_guess[16];
  if (req->has_mount_guess)
    memcpy(T_guess, req->T_mount_guess, sizeof T_guess);
  else if (cal.has_mount)
    memcpy(T_guess, cal.T_mount, sizeof T_guess);
  else
    fg_pose_identity(T_guess);
  free(req->T_base_tcp);
  req->T_base_tcp = malloc(sizeof *req->T_base_tcp * 16 * (size_t)req->n);
  fg_calib_drive *own = malloc(sizeof *own);
  if (!req->T_base_tcp || !own) {
    free(own);
    return fg_fail(FG_ENOMEM, "a calibration's viewpoints");
  }
  drive_viewpoints(req->target, T_guess, req->n, req->dist_m, req->el_deg, req->roll_deg,
                   req->T_base_tcp);
  *own = *req;
  const fg_job_params jp = {.steps = req->n};
  const int rc = fg_jobs_submit_camera(app->jobs, "calibrate", cam->name, &jp, own, out);
  if (rc < 0) {
    free(own);
    return rc;
  }
  req->T_base_tcp = NULL; /* the job's now */
  return 0;
}
