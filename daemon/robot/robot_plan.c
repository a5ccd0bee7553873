/* Planning a command of the robot service (robot.h): its steps and words, checked against
 * the motion limits (motion/limits.h). No I/O. */
#include "robot_priv.h"

#include <math.h>
#include <string.h>

#include "core/error.h"
#include "core/pose.h"

/* ---------------------------------------------------------------- planning */

/* The force of a request that gives none: 40 N, or the limit when that is lower. */
static double default_force(const fg_robot_svc *svc) {
  return fmin(DEFAULT_FORCE_N, floor(svc->lim.max_force_n));
}

/* A gripper step moving to position at the request's speed and force. */
int robot_plan_gripper(fg_robot_svc *svc, const fg_robot_request *req, const char *name,
                       int position, fg_robot_step *st) {
  memset(st, 0, sizeof *st);
  st->kind = FG_STEP_GRIPPER;
  st->name = name;
  st->position = position;
  const fg_robotiq_model *m = svc->model;
  FG_TRY(fg_robotiq_speed_to_byte(m, req->has_speed ? req->speed_mps : m->speed_max_mps,
                                  &st->speed));
  FG_TRY(fg_robotiq_force_to_byte(m, req->has_force ? req->force_n : default_force(svc),
                                  &st->force));
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_GTO, position, st->speed, st->force, st->words);
  st->n_words = FG_ROBOTIQ_WORDS;
  st->address = FG_ROBOTIQ_REQUEST_ADDR;
  return 0;
}

/* The position of the request's width, or fully open without one. */
int robot_open_position(fg_robot_svc *svc, const fg_robot_request *req, int *position) {
  if (!req->has_width) {
    *position = 0;
    return 0;
  }
  return fg_robotiq_width_to_position(svc->model, req->width_m, position);
}

/* The limits in force: [robot]'s, with the box of the scenes' workspaces (grown by the
 * margin) when [robot] sets none. Takes the lock itself; the workspace source runs
 * outside it. */
void robot_limits_now(fg_robot_svc *svc, fg_motion_limits *lim) {
  pthread_mutex_lock(&svc->lock);
  *lim = svc->lim;
  const int from_conf = svc->box_from_conf;
  const double margin = svc->margin_m;
  pthread_mutex_unlock(&svc->lock);
  if (from_conf) return;
  double mn[3], mx[3];
  lim->has_box = svc->ws_fn && svc->ws_fn(svc->ws_ctx, mn, mx);
  for (int i = 0; lim->has_box && i < 3; i++) {
    lim->box_min_m[i] = mn[i] - margin;
    lim->box_max_m[i] = mx[i] + margin;
  }
}

/* Fills a robot step with block b. */
static int plan_robot_step(fg_robot_svc *svc, const char *name, const fg_pose_block *b,
                           fg_robot_step *st) {
  memset(st, 0, sizeof *st);
  st->kind = FG_STEP_ROBOT;
  st->name = name;
  FG_TRY(fg_pose_block_encode(b, svc->rp.encoding, st->words));
  st->n_words = fg_pose_block_words(svc->rp.encoding);
  st->address = svc->rp.base;
  return 0;
}

/* A length of the path (approach or retreat) as asked, or its default. */
static int path_length(int has, double asked, double dflt, const char *name, double *out) {
  if (!has) {
    *out = dflt;
    return 0;
  }
  if (!(asked >= 0 && asked <= 1))
    return fg_fail(FG_ERANGE, "%s = %g m: expected 0 .. 1 m", name, asked);
  *out = asked;
  return 0;
}

/* Plans req under the lock with the limits lim (robot_limits_now). The steps, in order:
 *   pick:  gripper_open, robot (approach, descend), gripper_close, robot_retreat (lift)
 *   place: robot (approach, descend), gripper_open, robot_retreat (back out)
 *   move:  robot; open / close: the gripper (or the robot block without a gripper).
 * Without a gripper of its own the robot program actuates the tool and retreats itself: the
 * block carries the retreat and no robot_retreat step follows. */
int robot_plan_locked(fg_robot_svc *svc, const fg_motion_limits *lim,
                      const fg_robot_request *req, fg_robot_cmd_view *v) {
  memset(v, 0, sizeof *v);
  v->command = req->command;
  v->req = *req;
  v->robot_status = -1;
  v->object_detected = -1;
  v->gripper_width_m = NAN;
  v->ack_ms = -1;
  v->stage = "queued";
  v->robot_unit = svc->robot_unit;
  v->gripper_unit = svc->gripper_unit;
  v->robot_base = svc->rp.base;
  v->encoding = svc->rp.encoding;
  const int c = req->command, grip = svc->gripper != NULL;
  if (c < FG_ROBOT_PICK || c > FG_ROBOT_MOVE)
    return fg_fail(FG_EINVAL, "unknown command %d", c);
  const int robot_step = !(grip && (c == FG_ROBOT_OPEN || c == FG_ROBOT_CLOSE));
  const int needs_pose = c == FG_ROBOT_PICK || c == FG_ROBOT_PLACE || c == FG_ROBOT_MOVE;
  if (needs_pose && !req->has_pose)
    return fg_fail(FG_EINVAL, "this command needs a pose: {\"position\": [x, y, z], "
                   "\"quaternion\": [w, x, y, z]} or a 4x4 matrix, in the robot's base frame");
  if (!robot_step && req->has_pose)
    return fg_fail(FG_EINVAL, "open and close go to the gripper ([gripper.modbus]) and take no "
                   "pose; use pick or place to move");
  if (!needs_pose && (req->has_approach || req->has_retreat))
    return fg_fail(FG_EINVAL, "open and close take no approach or retreat");
  if (c == FG_ROBOT_MOVE && req->has_retreat)
    return fg_fail(FG_EINVAL, "move takes no retreat (it ends at its pose); send another move");
  if (req->has_force && (req->force_n != floor(req->force_n) || req->force_n < 0 ||
                         req->force_n > 65535))
    return fg_fail(FG_ERANGE, "force = %g N: expected whole newtons, 0 .. 65535", req->force_n);
  if (req->has_speed && !(req->speed_mps > 0))
    return fg_fail(FG_ERANGE, "speed = %g m/s: expected a speed above 0", req->speed_mps);
  if (svc->latch.latched)
    return fg_fail(FG_ESTOPPED, "the robot is stopped (%s); no motion is sent until an "
                   "operator makes the cell safe and calls POST /v1/robot/reset",
                   svc->latch.reason);
  double approach = 0, retreat = 0;
  FG_TRY(path_length(req->has_approach, req->approach_m,
                     c == FG_ROBOT_MOVE ? 0 : svc->approach_m, "approach", &approach));
  FG_TRY(path_length(req->has_retreat, req->retreat_m, c == FG_ROBOT_MOVE ? 0 : svc->retreat_m,
                     "retreat", &retreat));
  const double speed = req->has_speed ? req->speed_mps : svc->speed_mps;
  const double force = req->has_force ? req->force_n : default_force(svc);
  const fg_retreat_kind rk = c == FG_ROBOT_PICK    ? FG_RETREAT_UP
                             : c == FG_ROBOT_PLACE ? FG_RETREAT_BACK
                                                   : FG_RETREAT_NONE;
  FG_TRY(fg_motion_check_values(lim, req->has_force ? req->force_n : -1,
                                robot_step ? speed : -1, req->has_width ? req->width_m : -1,
                                &v->violation));
  /* the robot steps' speed only: the gripper's fingers keep their own full speed */
  fg_robot_request greq = *req;
  greq.has_speed = 0;
  int n = 0, pos;
  if (grip && c == FG_ROBOT_PICK) {
    FG_TRY(robot_open_position(svc, req, &pos));
    FG_TRY(robot_plan_gripper(svc, &greq, "gripper_open", pos, &v->steps[n++]));
  }
  const int split_retreat = grip && (c == FG_ROBOT_PICK || c == FG_ROBOT_PLACE) && retreat > 0;
  fg_pose_block b = {0};
  if (robot_step) {
    b = (fg_pose_block){
        .seq = fg_seq_next(svc->last_seq),
        .command = c,
        .width_m = req->has_width ? req->width_m : svc->model->stroke_m,
        .force_n = (int)force,
        .approach_m = needs_pose ? approach : 0,
        .retreat_m = needs_pose && !split_retreat ? retreat : 0,
        .speed_mps = speed,
    };
    if (req->has_pose) {
      memcpy(b.p_world_m, req->p_world_m, sizeof b.p_world_m);
      fg_rotvec_from_quat(req->q_wxyz, b.rotvec_rad);
    }
    FG_TRY(plan_robot_step(svc, "robot", &b, &v->steps[n++]));
    v->seq = b.seq;
  }
  if (grip && c == FG_ROBOT_PICK)
    FG_TRY(robot_plan_gripper(svc, &greq, "gripper_close", 255, &v->steps[n++]));
  if (grip && (c == FG_ROBOT_PLACE || c == FG_ROBOT_OPEN)) {
    FG_TRY(robot_open_position(svc, req, &pos));
    FG_TRY(robot_plan_gripper(svc, &greq, "gripper_open", pos, &v->steps[n++]));
  }
  if (grip && c == FG_ROBOT_CLOSE)
    FG_TRY(robot_plan_gripper(svc, &greq, "gripper_close", 255, &v->steps[n++]));
  if (split_retreat) {
    /* the retreat as a move of its own, once the gripper has acted */
    double pre[3];
    fg_pose_block rb = b;
    rb.seq = fg_seq_next(b.seq);
    rb.command = FG_ROBOT_MOVE;
    rb.approach_m = rb.retreat_m = 0;
    fg_motion_path(req->p_world_m, req->q_wxyz, 0, retreat, rk, pre, rb.p_world_m);
    FG_TRY(plan_robot_step(svc, "robot_retreat", &rb, &v->steps[n++]));
  }
  v->n_steps = n;
  /* the path, last, so that a refused dry run still shows what would have been sent */
  if (needs_pose)
    FG_TRY(fg_motion_check_pose(lim, req->p_world_m, req->q_wxyz, approach, retreat, rk,
                                &v->violation));
  return 0;
}

int fg_robot_plan(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v) {
  fg_motion_limits lim;
  robot_limits_now(svc, &lim);
  pthread_mutex_lock(&svc->lock);
  int rc = robot_plan_locked(svc, &lim, req, v);
  pthread_mutex_unlock(&svc->lock);
  return rc;
}

