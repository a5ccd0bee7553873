/* Calibrations the robot drives (POST /v1/cameras/{c}/calibrate with "drive"): a job of kind
 * "calibrate" on a hand camera. It forgets the views kept before it, moves the camera through
 * views of the board lying around a point the request gives (each motion through the one gate
 * to the robot and into the audit log, drive.h), keeps each view that shows the board
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
  double target[3];        /* the board's centre (or near it), base frame, metres */
  double dist_m[2];        /* camera to target, default 0.30 .. 0.40 */
  double el_deg[2];        /* elevation above the target, default 50 .. 80 */
  double roll_deg;         /* roll about the optical axis up to +- this, default 60 */
  int settle_ms;           /* after each motion, default 300 */
  int has_mount_guess;     /* aim with this T_tcp_cam; else the calibrated mount, else the */
  double T_mount_guess[16]; /* camera on the TCP looking along its z */
  double *T_base_tcp;      /* n TCP poses, owned; filled by fg_calib_drive_submit */
} fg_calib_drive;

extern const fg_job_kind fg_job_kind_calibrate;

/* Queues the driven calibration req (its poses filled in and taken by the job) after checking
 * what can be checked now: the camera exists (camera_not_found) and is on the tool
 * (invalid_request), a robot is configured (not_configured), a mount-only calibration has
 * intrinsics (not_calibrated). Failures as fg_jobs_submit_camera's. */
int fg_calib_drive_submit(fg_app *app, const fg_conf *conf, fg_calib_drive *req,
                          fg_job_info *out);

#endif
