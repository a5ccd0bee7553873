/* The motions of the cell's jobs (drive.h). */
#include "drive.h"

#include <stdio.h>
#include <time.h>

#include "core/error.h"
#include "core/log.h"
#include "core/pose.h"
#include "robot/audit.h"
#include "robot/robot.h"
#include "state/json.h"

/* The audit log's line for one motion (robot/audit.h): as a request's, the job as its
 * client. */
static void audit_motion(fg_app *app, fg_job *job, const char *route,
                         const fg_robot_request *req, int rc, const fg_robot_cmd_view *v) {
  const char *outcome = rc < 0 ? "refused" : fg_cmd_state_name(v->state);
  char client[32];
  snprintf(client, sizeof client, "%s job", fg_job_scene(job) ? "scan" : "calibration");
  json_t *e = json_pack("{s:s, s:s, s:s, s:o, s:o, s:s, s:s, s:s}", "kind", "request", "route",
                        route, "command", "move", "command_id",
                        rc < 0 ? json_null() : json_integer((json_int_t)v->id), "pose",
                        fg_json_pose_quat(req->p_world_m, req->q_wxyz), "outcome", outcome,
                        "client", client, "request_id", fg_job_id(job));
  if (e && rc < 0)
    json_object_set_new(e, "error", json_pack("{s:s, s:s}", "code",
                                              fg_error_reason() ? fg_error_reason() : "refused",
                                              "message", fg_error_detail()));
  if (e && rc == 0 && v->seq) json_object_set_new(e, "robot_seq", json_integer(v->seq));
  if (e) fg_audit_append(app->audit, e);
  json_decref(e);
}

int fg_cell_move(fg_app *app, fg_job *job, const char *route, const double T[16]) {
  fg_robot_request req = {.command = FG_ROBOT_MOVE, .has_pose = 1, .has_approach = 1,
                          .approach_m = 0, .wait = 1};
  fg_pose_to_quat(T, req.p_world_m, req.q_wxyz);
  if (fg_audit_ready(app->audit) < 0) /* nothing moves unrecorded */
    return fg_fail(FG_EIO, "the robot's audit log cannot be written: %s", fg_error_detail()),
           -1;
  fg_robot_cmd_view v;
  const int rc = fg_robot_execute(app->robot, &req, &v);
  audit_motion(app, job, route, &req, rc, &v);
  if (rc == FG_ELIMIT || rc == FG_ERANGE) return 0;
  if (rc < 0) return -1;
  if (v.state == FG_CMD_DONE) return 1;
  if (v.state == FG_CMD_FAILED) return 0;
  fg_fail(FG_EPEER, "the robot's motion to a viewpoint ended %s: %s",
          fg_cmd_state_name(v.state), v.message);
  return -1;
}

int fg_cell_visit(fg_app *app, fg_job *job, const char *route, const double *T, int n,
                  int settle_ms, fg_cell_visit_fn visit, void *ctx, int *count, int *skipped,
                  int *at) {
  *count = *skipped = 0;
  for (*at = 0; *at < n && !fg_job_should_stop(job); (*at)++) {
    const int moved = fg_cell_move(app, job, route, T + 16 * *at);
    if (moved < 0) return -1;
    if (moved == 0) {
      (*skipped)++;
      fg_info("job %s: viewpoint %d skipped: %s", fg_job_id(job), *at, fg_error_detail());
    } else {
      fg_cell_settle(settle_ms);
      if (visit(ctx, *at, count) < 0) return -1;
    }
    fg_job_info *info = fg_job_update_begin(job);
    info->step = *at + 1;
    info->n_frames = *count;
    info->skipped = *skipped;
    fg_job_update_end(job);
  }
  return 0;
}

void fg_cell_settle(int ms) {
  const struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
  nanosleep(&ts, NULL);
}
