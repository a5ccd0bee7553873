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

#endif
