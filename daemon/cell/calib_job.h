/* Calibrations the robot drives (POST /v1/cameras/{c}/calibrate with "drive"): a job of kind
 * "calibrate". It forgets the views kept before it and moves the robot through views of the
 * board: a hand camera around the board lying at a point the request gives, or, for a fixed
 * camera, the board the tool holds in front of the camera, shown along the line from the
 * camera to a point the request gives (each motion through the one gate to the robot and into
 * the audit log, drive.h). It keeps each view that shows the board
 * (calibration.c, as a capture with "calibration_view" does), and calibrates on them as the
 * synchronous calibration does (fg_camera_calibrate): a refusal fails the job with its
 * numbers and leaves the previous calibration. Jobs run one at a time (state/jobs.h), so a
 * calibration and a scan never interleave their motions. */
#ifndef FG_DAEMON_CELL_CALIB_JOB_H
#define FG_DAEMON_CELL_CALIB_JOB_H

#include "cameras.h"
#include "state/app.h"
#include "state/jobs.h"

#define FG_CALIB_DRIVE_MAX_VIEWS 60

/* A driven calibration's parameters. */
typedef struct fg_calib_drive {
  char camera[FG_CAMERA_NAME_MAX + 1];
  fg_calibrate_kind kind;
  int n;                   /* viewpoints, default 30 */
  double target[3];        /* hand: the board's centre (or near it); fixed: a point the camera
                              looks at, where the board is shown; base frame, metres */
  double dist_m[2];        /* camera to target (hand) or to the board (fixed), 0.30 .. 0.40 */
  double el_deg[2];        /* hand: elevation above the target, default 50 .. 80 */
  double tilt_deg[2];      /* fixed: the board's face turned from the camera, default 15 .. 45 */
  int has_el, has_tilt;    /* given by the request (each is for one mount only) */
  double roll_deg;         /* roll about the optical axis (hand) or the board's normal (fixed)
                              up to +- this, default 60 */
  int settle_ms;           /* after each motion, default 300 */
  int has_mount_guess;     /* hand: aim with this T_tcp_cam; else the calibrated mount, else the
                              camera on the TCP looking along its z. fixed: the board's centre
                              on the tool, its printed face along this pose's +z; else the
                              centre at the TCP, the face along the tool's +z */
  double T_mount_guess[16];
  int has_camera_guess;    /* fixed: where the camera stands (a ruler's guess); else the */
  double camera_guess[3];  /* calibrated T_base_cam's position */
  double *T_base_tcp;      /* n TCP poses, owned; filled by fg_calib_drive_submit */
} fg_calib_drive;

extern const fg_job_kind fg_job_kind_calibrate;

/* Queues the driven calibration req (its poses filled in and taken by the job) after checking
 * what can be checked now: the camera exists (camera_not_found), a robot is configured
 * (not_configured), a mount-only calibration has intrinsics (not_calibrated), a fixed camera's
 * position is known (invalid_request: neither camera_position nor a calibrated T_base_cam, or
 * the target on it), camera_position and tilts are given for a fixed camera only and
 * elevations for a hand camera only (invalid_request).
 * Failures as fg_jobs_submit_camera's. */
int fg_calib_drive_submit(fg_app *app, const fg_conf *conf, fg_calib_drive *req,
                          fg_job_info *out);

#endif
