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

/* The n TCP poses that show a fixed camera at cam the board the tool holds (its centre at
 * T_tcp_board on the tool, its printed face along that pose's +z): the board's centre along
 * the line from cam through target at distances over dist_m, off that line by up to a tenth
 * of the distance (so that the board crosses the image), its face towards the camera turned
 * by tilts over tilt_deg about axes all around, and rolled about its normal; the same
 * interleaved patterns as drive_viewpoints. cam must differ from target. */
static void show_viewpoints(const double cam[3], const double target[3],
                            const double T_tcp_board[16], int n, const double dist_m[2],
                            const double tilt_deg[2], double roll_deg, double *T_base_tcp) {
  double T_board_tcp[16], u[3], e1[3], e2[3], T_line[16];
  fg_pose_inverse(T_tcp_board, T_board_tcp);
  fg_pose_look_at(cam, target, 0, T_line); /* its z along the line, x and y across it */
  for (int k = 0; k < 3; k++) {
    e1[k] = T_line[4 * k];
    e2[k] = T_line[4 * k + 1];
    u[k] = T_line[4 * k + 2];
  }
  for (int i = 0; i < n; i++) {
    const double d = dist_m[0] + (dist_m[1] - dist_m[0]) * ((i * 2) % 3) / 2.0;
    const double off = 0.1 * d * ((i * 3) % 5) / 4.0, psi = 2 * M_PI * i / n + 0.3 * (i % 3);
    const double tilt = (tilt_deg[0] + (tilt_deg[1] - tilt_deg[0]) * ((i * 4) % 5) / 4.0) *
                        M_PI / 180;
    const double phi = 2.4 * i; /* the tilt's axis: turns by about 137 degrees a view */
    const double roll = roll_deg * (-1 + 2 * ((i * 5) % 7) / 6.0) * M_PI / 180;
    double c[3];
    for (int k = 0; k < 3; k++)
      c[k] = cam[k] + d * u[k] + off * (cos(psi) * e1[k] + sin(psi) * e2[k]);
    double T_face[16], T_tilt[16], T_base_board[16];
    fg_pose_look_at(c, cam, roll, T_face); /* +z from the board's centre towards the camera */
    const double zero[3] = {0, 0, 0},
                 q[4] = {cos(tilt / 2), sin(tilt / 2) * cos(phi), sin(tilt / 2) * sin(phi), 0};
    fg_pose_from_quat(zero, q, T_tilt);
    fg_pose_compose(T_face, T_tilt, T_base_board);
    fg_pose_compose(T_base_board, T_board_tcp, T_base_tcp + 16 * i);
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
  const int fixed = cam->mount == FG_MOUNT_FIXED;
  if (fixed ? req->has_el : req->has_camera_guess || req->has_tilt)
    return fg_fail_as(FG_EINVAL, "invalid_request", "%s is %s: \"drive\" takes %s for a %s "
                      "camera only", cam->name, fixed ? "a fixed camera" : "on the tool",
                      fixed ? "elevations_deg" : "camera_position and tilt_deg",
                      fixed ? "hand" : "fixed");
  if (!fg_robot_svc_has_robot(app->robot))
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "\"drive\" moves the robot: set [robot]");
  fg_camera_calib cal;
  fg_cameras_calib_get(app->cameras, cam->name, &cal);
  if (req->kind == FG_CALIBRATE_HAND_EYE && !cal.has_intrinsics)
    return fg_fail_as(FG_EINVAL, "not_calibrated", "%s has no intrinsics yet: calibrate them "
                      "first, or both at once (\"kind\": \"both\")", cam->name);
  double T_guess[16], cam_at[3];
  if (req->has_mount_guess)
    memcpy(T_guess, req->T_mount_guess, sizeof T_guess);
  else if (cal.has_mount && !fixed)
    memcpy(T_guess, cal.T_mount, sizeof T_guess);
  else
    fg_pose_identity(T_guess);
  if (fixed) {
    if (!req->has_camera_guess && !cal.has_mount)
      return fg_fail_as(FG_EINVAL, "invalid_request", "%s is a fixed camera with no T_base_cam "
                        "yet: \"drive\" needs \"camera_position\": [x, y, z], where it "
                        "stands in the base frame (a ruler's guess is enough)", cam->name);
    for (int k = 0; k < 3; k++)
      cam_at[k] = req->has_camera_guess ? req->camera_guess[k] : cal.T_mount[4 * k + 3];
    const double dx = req->target[0] - cam_at[0], dy = req->target[1] - cam_at[1],
                 dz = req->target[2] - cam_at[2];
    if (sqrt(dx * dx + dy * dy + dz * dz) < 1e-3)
      return fg_fail_as(FG_EINVAL, "invalid_request", "drive: the target is where %s stands: "
                        "give a point it looks at", cam->name);
  }
  free(req->T_base_tcp);
  req->T_base_tcp = malloc(sizeof *req->T_base_tcp * 16 * (size_t)req->n);
  fg_calib_drive *own = malloc(sizeof *own);
  if (!req->T_base_tcp || !own) {
    free(own);
    return fg_fail(FG_ENOMEM, "a calibration's viewpoints");
  }
  if (fixed)
    show_viewpoints(cam_at, req->target, T_guess, req->n, req->dist_m, req->tilt_deg,
                    req->roll_deg, req->T_base_tcp);
  else
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
