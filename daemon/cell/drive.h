/* The motions of the cell's jobs (a scan, a calibration the robot drives): each one through
 * the one gate to the robot (fg_robot_execute: limits, latch) and into the audit log, with
 * the job as its client, as a request's would be. */
#ifndef FG_DAEMON_CELL_DRIVE_H
#define FG_DAEMON_CELL_DRIVE_H

#include "state/app.h"
#include "state/jobs.h"

/* Moves the TCP to T_base_tcp (no approach) and waits for the motion to end, recorded in the
 * audit log under route (the request that queued the job). 1: reached; 0: refused by the
 * limits or failed (out of reach: the caller skips it); -1: the job must stop (the audit log
 * cannot be written, the robot is latched or gone, the motion was stopped; detail recorded). */
int fg_cell_move(fg_app *app, fg_job *job, const char *route, const double T_base_tcp[16]);

/* Waits ms milliseconds: the robot and the camera settle after a motion. */
void fg_cell_settle(int ms);

/* What a job does at a viewpoint it reached: 0, or the failure (the job stops). *count: what
 * the job has gathered so far (frames stored, views kept), shown as its "frames". */
typedef int (*fg_cell_visit_fn)(void *ctx, int i, int *count);

/* Visits the n viewpoints T_base_tcp (16 doubles each) in order for job: moves to each
 * (fg_cell_move, audited under route), skips and counts the ones refused or out of reach,
 * lets the robot settle settle_ms and calls visit at each one reached, showing the job's
 * step, frames (*count) and skipped as it goes; stops early when the job should stop. 0, or
 * -1 when a motion or a visit failed (detail recorded) at viewpoint *at (0-based). */
int fg_cell_visit(fg_app *app, fg_job *job, const char *route, const double *T_base_tcp, int n,
                  int settle_ms, fg_cell_visit_fn visit, void *ctx, int *count, int *skipped,
                  int *at);

#endif
