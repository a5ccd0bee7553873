/* Scans the robot drives (POST /v1/scenes/{s}/scan): a job of kind "scan" on a scene that
 * moves a calibrated camera on the tool through viewpoints around the scene's workspace,
 * through the one gate to the robot (fg_robot_execute: limits, latch, audit), lets it settle,
 * captures with the TCP pose read around it, and stores each frame with its pose in the base
 * frame and that TCP pose, all in a new capture of the scene (store.h). A viewpoint the
 * robot refuses (outside the limits, or it answers failed: out of reach) is skipped and
 * counted; a scan that reaches none fails. A scan may go on to train the scene in the same
 * job (the "train" kind's run, job_train.h): the job then shows the training's params,
 * phases and steps, and ends when the training does. That training's default captures,
 * "latest", are the scan's own. */
#ifndef FG_DAEMON_CELL_SCAN_H
#define FG_DAEMON_CELL_SCAN_H

#include "cameras.h"
#include "motion/limits.h"
#include "state/app.h"
#include "state/jobs.h"

#define FG_SCAN_MAX_VIEWPOINTS 200

/* A scan's own parameters. */
typedef struct fg_scan_request {
  char camera[FG_CAMERA_NAME_MAX + 1];
  int n;                 /* viewpoints */
  double *T_base_tcp;    /* n TCP poses (16 each), owned; NULL: placed on a sphere cap */
  double radius_m;       /* the cap's: camera to the workspace's centre; 0: from the view
                            and the limits (fg_scan_default_radius) */
  double el_min_deg, el_max_deg; /* the cap's elevations, default 35 .. 75 */
  int settle_ms;         /* after each motion, default 300 */
  int train;             /* then train the scene in the same job, with train_params */
  fg_job_params train_params;
} fg_scan_request;

extern const fg_job_kind fg_job_kind_scan;

/* The TCP poses that put a camera of intrinsics in on the tool at T_tcp_cam on a sphere cap
 * around the centre of the box [lo, hi] (world frame), each looking at that centre: n points
 * spread over azimuth (golden angle) and elevations el_min..el_max degrees; radius_m 0 puts
 * the camera where the box's bounding sphere fills 80 % of the narrower field of view. */
void fg_scan_viewpoints(const double lo[3], const double hi[3], const fg_intrinsics *in,
                        const double T_tcp_cam[16], int n, double radius_m, double el_min_deg,
                        double el_max_deg, double *T_base_tcp);

/* The radius of a scan's cap when the request gives none: from where the box's bounding
 * sphere fills 80 % of the narrower field of view in to where it fills all of it, the
 * farthest at which the motion limits lim (the position box and the reach) accept the most
 * of the n viewpoints; the 80 % radius when they accept none anywhere. */
double fg_scan_default_radius(const double lo[3], const double hi[3], const fg_intrinsics *in,
                              const double T_tcp_cam[16], int n, double el_min_deg,
                              double el_max_deg, const fg_motion_limits *lim);

/* Queues the scan of req (taken: its poses are the job's) on scene s with camera cam, after
 * checking what can be checked now: a hand camera, calibrated, a robot. Failures as
 * fg_jobs_submit's, and not_calibrated, invalid_request (a fixed camera). */
int fg_scan_submit(fg_app *app, const fg_conf *conf, fg_scene *s, fg_scan_request *req,
                   fg_job_info *out);

#endif
