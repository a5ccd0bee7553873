/* The robot service (robot.h): set-up, running commands on the peers' workers, gripper
 * actions, the stop and the reset. Planning is robot_plan.c, the latch robot_latch.c (set,
 * kept and synced), state and metrics robot_state.c. */
#include "robot_priv.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"

void fg_robot_svc_set_ids(fg_robot_svc *svc, fg_cmd_ids *ids) { svc->ids = ids; }

void fg_robot_svc_on_finish(fg_robot_svc *svc, void (*fn)(void *ctx, const fg_robot_cmd_view *v),
                            void *ctx) {
  svc->on_finish = fn;
  svc->on_finish_ctx = ctx;
}

static const char *const command_names[] = {"?", "pick", "place", "open", "close", "move"};

static const char *const state_names[FG_CMD_STATES] = {
    "pending", "acknowledged", "done", "failed", "unknown", "error", "stopped"};

const char *fg_cmd_state_name(fg_cmd_state s) {
  return s >= 0 && s < FG_CMD_STATES ? state_names[s] : "?";
}

/* ---------------------------------------------------------------- idle jobs */

/* The robot's idle job (a job fn of peer.h): reads ack and status, then writes what the
 * latch still owes the robot. */
static int robot_idle(fg_mb_link *l, void *arg) {
  fg_robot_svc *svc = arg;
  uint16_t ack;
  int status;
  FG_TRY(fg_robot_read_ack(l, &svc->rp, &ack, &status));
  pthread_mutex_lock(&svc->lock);
  svc->ack = ack;
  svc->status = status;
  if (svc->gen_seen == 0) {
    /* the first connection: continue after the number the robot saw last (a restarted
     * daemon must not reuse it); later ones keep counting, so that a seq that was sent but
     * never acknowledged is not given to another command */
    svc->last_seq = ack;
  }
  if (svc->gen_seen != fg_mb_link_generation(l))
    svc->latch.stop_written = 0; /* a new connection: the robot may have restarted */
  svc->gen_seen = fg_mb_link_generation(l);
  pthread_mutex_unlock(&svc->lock);
  robot_tcp_refresh(svc, l);
  return robot_latch_sync(svc, l);
}

/* Stores a gripper status read on link l. */
static void gripper_store(fg_robot_svc *svc, fg_mb_link *l, const fg_robotiq_status *s) {
  pthread_mutex_lock(&svc->lock);
  svc->g_status = *s;
  svc->g_have = 1;
  svc->g_gen = fg_mb_link_generation(l);
  pthread_mutex_unlock(&svc->lock);
}

static int gripper_idle(fg_mb_link *l, void *arg) {
  fg_robot_svc *svc = arg;
  fg_robotiq_status s;
  FG_TRY(fg_gripper_read(l, &s));
  gripper_store(svc, l, &s);
  return 0;
}

/* ---------------------------------------------------------------- set-up */

static int peer_config(const fg_conf_modbus *m, const char *name, fg_mb_link_config *lc) {
  memset(lc, 0, sizeof *lc);
  lc->name = name;
  lc->transport = m->transport == FG_TRANSPORT_TCP ? FG_MB_TCP : FG_MB_RTU;
  lc->host = m->host;
  lc->port = m->port;
  lc->device = m->device;
  lc->baud = m->baud;
  lc->parity = m->parity;
  lc->unit_id = m->unit_id;
  lc->timeout_ms = m->timeout_ms;
  return m->transport != FG_TRANSPORT_NONE;
}

int fg_robot_svc_new(fg_robot_svc **out, const fg_conf *conf) {
  *out = NULL;
  fg_robot_svc *svc = calloc(1, sizeof *svc);
  if (!svc) return FG_ENOMEM;
  pthread_mutex_init(&svc->lock, NULL);
  pthread_cond_init(&svc->cond, NULL);
  svc->next_id = 1;
  svc->ack = svc->status = -1;
  svc->rp = (fg_robot_profile){
      .base = conf->robot.base,
      .encoding = conf->robot.encoding == FG_ENCODING_FLOAT32 ? FG_POSE_FLOAT32 : FG_POSE_INT16,
      .ack_timeout_ms = conf->robot.ack_timeout_ms,
      .done_timeout_ms = conf->robot.done_timeout_ms,
  };
  svc->tcp_base = conf->robot.transport != FG_TRANSPORT_NONE ? conf->robot.tcp_pose_base : -1;
  svc->robot_unit = conf->robot.unit_id;
  svc->gripper_unit = conf->gripper_modbus.unit_id;
  svc->model = conf->gripper_model == FG_GRIPPER_ROBOTIQ_2F140 ? &fg_robotiq_2f140
                                                                : &fg_robotiq_2f85;
  svc->motion_timeout_ms = conf->gripper_modbus.motion_timeout_ms;
  fg_robot_svc_configure(svc, conf);
  char *dir = fg_path_join(conf->state_dir, "robot");
  svc->latch_path = dir ? fg_path_join(dir, "latch.json") : NULL;
  free(dir);
  if (!svc->latch_path) {
    fg_robot_svc_free(svc);
    return FG_ENOMEM;
  }
  robot_latch_load(svc);
  fg_mb_link_config lc;
  int rc = 0;
  if (peer_config(&conf->robot, "robot", &lc))
    rc = fg_mb_peer_new(&svc->robot, &lc, ROBOT_IDLE_MS, robot_idle, svc);
  if (rc == 0 && peer_config(&conf->gripper_modbus, "gripper", &lc)) {
    if (conf->gripper_model == FG_GRIPPER_PANDA)
      fg_warn("[gripper.modbus] drives a Robotiq 2F but [gripper] model is panda; using the "
              "2F-85's stroke, speeds and forces (set model = robotiq-2f85 or robotiq-2f140)");
    rc = fg_mb_peer_new(&svc->gripper, &lc, GRIPPER_IDLE_MS, gripper_idle, svc);
  }
  if (rc < 0) {
    fg_robot_svc_free(svc);
    return rc;
  }
  *out = svc;
  return 0;
}

static void rec_unref_locked(rec *r) {
  if (r && --r->refs == 0) free(r);
}

void fg_robot_svc_stop(fg_robot_svc *svc) {
  if (!svc) return;
  pthread_mutex_lock(&svc->lock);
  svc->stopping = 1;
  pthread_mutex_unlock(&svc->lock);
}

void fg_robot_svc_free(fg_robot_svc *svc) {
  if (!svc) return;
  fg_robot_svc_stop(svc);
  fg_mb_peer_free(svc->robot);
  fg_mb_peer_free(svc->gripper);
  for (size_t i = 0; i < svc->n_recs; i++)
    rec_unref_locked(svc->recs[(svc->head + i) % MAX_RECORDS]);
  pthread_cond_destroy(&svc->cond);
  pthread_mutex_destroy(&svc->lock);
  free(svc->latch_path);
  free(svc);
}

void fg_robot_svc_configure(fg_robot_svc *svc, const fg_conf *conf) {
  const fg_conf_motion *m = &conf->motion;
  const fg_robotiq_model *model =
      conf->gripper_model == FG_GRIPPER_ROBOTIQ_2F140 ? &fg_robotiq_2f140 : &fg_robotiq_2f85;
  const double stroke = fg_gripper_spec_get(conf->gripper_model)->stroke_m;
  pthread_mutex_lock(&svc->lock);
  svc->lim = (fg_motion_limits){
      .has_box = m->has_box,
      .reach_m = m->reach_m,
      .cone_rad = m->approach_cone_deg * (M_PI / 180),
      .max_force_n = m->max_force_n > 0 ? m->max_force_n : model->force_max_n,
      .max_speed_mps = m->max_speed_mps,
      .max_width_m = stroke,
  };
  memcpy(svc->lim.box_min_m, m->limit_min, sizeof m->limit_min);
  memcpy(svc->lim.box_max_m, m->limit_max, sizeof m->limit_max);
  svc->box_from_conf = m->has_box;
  svc->margin_m = m->limit_margin_m;
  svc->speed_mps = m->speed_mps;
  svc->approach_m = m->approach_m;
  svc->retreat_m = m->retreat_m;
  pthread_mutex_unlock(&svc->lock);
}

void fg_robot_svc_set_workspace_source(fg_robot_svc *svc, fg_robot_workspace_fn fn, void *ctx) {
  svc->ws_fn = fn;
  svc->ws_ctx = ctx;
}

void fg_robot_limits_get(fg_robot_svc *svc, fg_motion_limits *out) { robot_limits_now(svc, out); }

void fg_robot_path_defaults(fg_robot_svc *svc, double *approach_m, double *retreat_m,
                            double *speed_mps) {
  pthread_mutex_lock(&svc->lock);
  *approach_m = svc->approach_m;
  *retreat_m = svc->retreat_m;
  *speed_mps = svc->speed_mps;
  pthread_mutex_unlock(&svc->lock);
}

int fg_robot_svc_has_robot(const fg_robot_svc *svc) { return svc->robot != NULL; }
int fg_robot_svc_has_gripper(const fg_robot_svc *svc) { return svc->gripper != NULL; }

/* ---------------------------------------------------------------- execution */

/* Ends r with an outcome (under no lock); wakes the waiters. The end goes to on_finish (the
 * audit log, and the answer a retry of the command's Idempotency-Key gets) before anyone can
 * see it: a client that saw the command end and then retried its key got the answer of its
 * acknowledgement once (a stressed CI run caught it in robot_faults). */
static void finish(rec *r, fg_cmd_state state, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void finish(rec *r, fg_cmd_state state, const char *code, const char *fmt, ...) {
  fg_robot_svc *svc = r->svc;
  pthread_mutex_lock(&svc->lock);
  fg_robot_cmd_view end = r->v;
  pthread_mutex_unlock(&svc->lock);
  end.state = state;
  snprintf(end.code, sizeof end.code, "%s", code ? code : "");
  if (fmt) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(end.message, sizeof end.message, fmt, ap);
    va_end(ap);
  }
  end.finished_s = fg_real_s();
  end.stage = "finished";
  if (svc->on_finish) svc->on_finish(svc->on_finish_ctx, &end);
  pthread_mutex_lock(&svc->lock);
  r->v.state = end.state;
  memcpy(r->v.code, end.code, sizeof r->v.code);
  memcpy(r->v.message, end.message, sizeof r->v.message);
  r->v.finished_s = end.finished_s;
  r->v.stage = end.stage;
  svc->by_state[state]++;
  const int latch = state == FG_CMD_UNKNOWN;
  if (latch) {
    /* before the command lets go of the robot, so that no other starts in between */
    char reason[sizeof svc->latch.reason + 64];
    snprintf(reason, sizeof reason, "command %llu (%s) ended unknown: %.400s",
             (unsigned long long)r->v.id, command_names[r->v.command], r->v.message);
    robot_latch_set_locked(svc, reason, r->v.id, 0);
  }
  if (svc->active == r) svc->active = NULL;
  pthread_cond_broadcast(&svc->cond);
  pthread_mutex_unlock(&svc->lock);
  if (state != FG_CMD_DONE)
    fg_warn("robot: command %llu (%s, seq %u) ended %s: %s", (unsigned long long)end.id,
            command_names[end.command], end.seq, state_names[state], end.message);
  if (latch) robot_latch_persist(svc); /* held in memory already: the answer went first */
}

static void set_stage(rec *r, const char *stage) {
  pthread_mutex_lock(&r->svc->lock);
  r->v.stage = stage;
  pthread_mutex_unlock(&r->svc->lock);
}

/* Ends a wait on the robot: the daemon stops, or the command is being stopped. */
static int cancelled(void *arg) {
  fg_robot_svc *svc = arg;
  pthread_mutex_lock(&svc->lock);
  int s = svc->stopping || svc->stop_requested;
  pthread_mutex_unlock(&svc->lock);
  return s;
}

static int stop_requested(fg_robot_svc *svc) {
  pthread_mutex_lock(&svc->lock);
  int s = svc->stop_requested;
  pthread_mutex_unlock(&svc->lock);
  return s;
}

/* A gripper step on the gripper's worker: activate first when needed, then move. */
typedef struct grip_job {
  fg_robot_svc *svc;
  const fg_robot_step *step;
  fg_robotiq_status status;
  int activate_only;
  int may_activate;   /* a gripper that is not activated may be activated first */
  int allow_drop;     /* activate_only: even while it holds an object */
} grip_job;

/* An activation resets the gripper, which opens it: whatever it holds falls. So it never
 * happens while an object is detected unless the caller said so, and never in the middle
 * of a command (the fingers at the grasp). */
static int grip_run(fg_mb_link *l, void *arg) {
  grip_job *g = arg;
  fg_robot_svc *svc = g->svc;
  FG_TRY(fg_gripper_read(l, &g->status));
  gripper_store(svc, l, &g->status);
  const int holding = g->status.act && fg_robotiq_object_detected(&g->status);
  if (g->activate_only && holding && !g->allow_drop)
    return fg_fail(FG_EPERM, "the gripper holds an object (gOBJ %d) and an activation opens "
                   "it: place the object first, or send \"allow_drop\": true to drop it",
                   g->status.obj);
  if (!g->activate_only && (g->status.sta != 3 || !g->status.act)) {
    if (!g->may_activate)
      return fg_fail(FG_EBUSY, "the gripper is not activated (gSTA %d) and is not activated "
                     "in the middle of a command; POST /v1/gripper/activate, then retry",
                     g->status.sta);
    if (holding)
      return fg_fail(FG_EPERM, "the gripper is not activated but reports an object (gOBJ "
                     "%d); activating it would open it: POST /v1/gripper/activate with "
                     "\"allow_drop\": true once that is safe", g->status.obj);
  }
  if (g->activate_only || g->status.sta != 3 || !g->status.act) {
    int rc = fg_gripper_activate(l, svc->motion_timeout_ms, &g->status);
    gripper_store(svc, l, &g->status);
    if (rc < 0 || g->activate_only) return rc;
  }
  int rc = fg_gripper_move(l, g->step->position, g->step->speed, g->step->force,
                           svc->motion_timeout_ms, &g->status);
  gripper_store(svc, l, &g->status);
  return rc;
}

/* The code of a failed gripper call (the API answers each code with its status). */
static void gripper_outcome(int rc, const char **code) {
  *code = rc == FG_EUNAVAIL    ? "gripper_disconnected"
          : rc == FG_ETIMEDOUT ? "gripper_timeout"
          : rc == FG_EPEER     ? "gripper_fault"
          : rc == FG_EPERM     ? "gripper_holding"
          : rc == FG_EBUSY     ? "gripper_not_activated"
                               : "gripper_error";
}

/* Runs gripper step i of r: directly on link gl when the caller is the gripper's worker,
 * else through the gripper's queue. 0, or finishes r (state: error before the robot moved,
 * failed after) and returns the error. */
static int run_gripper_step(rec *r, int i, int robot_moved, fg_mb_link *gl) {
  fg_robot_svc *svc = r->svc;
  set_stage(r, r->v.steps[i].name);
  /* only the first step may activate: later ones act with the arm at the object */
  grip_job g = {.svc = svc, .step = &r->v.steps[i], .status.position = -1,
                .may_activate = i == 0};
  int rc = gl ? grip_run(gl, &g) : fg_mb_peer_call(svc->gripper, grip_run, &g);
  pthread_mutex_lock(&svc->lock);
  if (g.status.position >= 0) /* a status was read */
    r->v.gripper_width_m = fg_robotiq_position_to_width(svc->model, g.status.position);
  if (rc == 0 && strcmp(r->v.steps[i].name, "gripper_close") == 0)
    r->v.object_detected = fg_robotiq_object_detected(&g.status);
  pthread_mutex_unlock(&svc->lock);
  if (rc == 0) return 0;
  const char *code;
  gripper_outcome(rc, &code);
  finish(r, robot_moved ? FG_CMD_FAILED : FG_CMD_ERROR, code, "%s: %s",
         r->v.steps[i].name, fg_error_detail());
  return rc;
}

/* Ends r as stopped: the robot's waits were cancelled by fg_robot_stop. The stop word goes
 * out from here, at once, rather than after the command's job has ended. */
static int stopped(rec *r, fg_mb_link *l, const char *stage, int by_robot) {
  fg_robot_svc *svc = r->svc;
  if (l && fg_robot_write_stop(l, &svc->rp, 1) == 0) {
    pthread_mutex_lock(&svc->lock);
    svc->latch.stop_written = 1;
    pthread_mutex_unlock(&svc->lock);
  }
  finish(r, FG_CMD_STOPPED, "robot_stopped", "stopped %s during %s; POST "
         "/v1/robot/reset once the cell is safe", by_robot ? "by the robot (status 4)"
                                                           : "by POST /v1/robot/stop", stage);
  return FG_ECANCELED;
}

/* Ends r as unknown (which latches) and disarms the block if the link lets us. */
static int unknown(rec *r, fg_mb_link *l, int rc, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));
static int unknown(rec *r, fg_mb_link *l, int rc, const char *code, const char *fmt, ...) {
  char msg[400];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  finish(r, FG_CMD_UNKNOWN, code,
         "%s; the robot is stopped until POST /v1/robot/reset", msg);
  if (robot_latch_sync(r->svc, l) < 0)
    fg_warn("robot: the no-op block is written once the robot answers: %s", fg_error_detail());
  return rc;
}

/* A robot step: write once, wait for ack, then for done. 0, or finishes r. robot_moved: an
 * earlier step moved the robot, so a failure now is `failed`, not `error`. */
static int run_robot_step(rec *r, fg_mb_link *l, int i, int robot_moved) {
  fg_robot_svc *svc = r->svc;
  fg_robot_step *st = &r->v.steps[i];
  const fg_cmd_state not_sent = robot_moved ? FG_CMD_FAILED : FG_CMD_ERROR;
  set_stage(r, st->name);
  int rc = fg_mb_link_ensure(l);
  if (rc == 0 && svc->gen_seen != fg_mb_link_generation(l)) rc = robot_idle(l, svc);
  if (rc < 0) {
    finish(r, not_sent, "robot_disconnected", "%s: nothing was sent: %s", st->name,
           fg_error_detail());
    return rc;
  }
  pthread_mutex_lock(&svc->lock);
  uint16_t seq = fg_seq_next(svc->last_seq);
  if (seq == svc->ack) seq = fg_seq_next(seq);
  svc->last_seq = seq;
  st->words[0] = seq;
  if (!r->v.seq) r->v.seq = seq;
  pthread_mutex_unlock(&svc->lock);

  const double t0 = (fg_mono_s() * 1e3);
  rc = fg_robot_write(l, &svc->rp, st->words);
  if (rc == FG_EPEER) {
    finish(r, not_sent, "modbus_exception", "the robot refused the pose write: %s",
           fg_error_detail());
    return rc;
  }
  if (rc < 0 && !fg_mb_link_maybe_sent(l)) {
    pthread_mutex_lock(&svc->lock);
    if (svc->last_seq == seq) svc->last_seq = (uint16_t)(seq == 1 ? 65535 : seq - 1);
    pthread_mutex_unlock(&svc->lock);
    finish(r, not_sent, "robot_disconnected", "%s: nothing was sent: %s", st->name,
           fg_error_detail());
    return rc;
  }
  if (rc < 0)
    return unknown(r, l, rc, rc == FG_ETIMEDOUT ? "robot_timeout" : "robot_unknown",
                   "the pose write of seq %u may have reached the robot but was not confirmed "
                   "(%s); it is not sent again", seq, fg_error_detail());
  int status = -1;
  rc = fg_robot_wait_ack(l, &svc->rp, seq, &status, cancelled, svc);
  if (rc == FG_ECANCELED && stop_requested(svc)) return stopped(r, l, st->name, 0);
  if (rc < 0)
    return unknown(r, l, rc, rc == FG_ETIMEDOUT ? "ack_timeout" : "robot_unknown",
                   "%s; the command's outcome is unknown and it is not sent again",
                   fg_error_detail());
  pthread_mutex_lock(&svc->lock);
  svc->ack = seq;
  svc->status = status;
  if (r->v.ack_ms < 0) r->v.ack_ms = (fg_mono_s() * 1e3) - t0;
  r->v.robot_status = status;
  r->v.state = FG_CMD_ACKNOWLEDGED;
  pthread_cond_broadcast(&svc->cond);
  pthread_mutex_unlock(&svc->lock);

  /* the status read with the ack may already be the end (a quick robot) */
  if (status != FG_ROBOT_DONE && status != FG_ROBOT_FAILED && status != FG_ROBOT_STOPPED)
    rc = fg_robot_wait_done(l, &svc->rp, seq, &status, cancelled, svc);
  if (rc == FG_ECANCELED && stop_requested(svc)) return stopped(r, l, st->name, 0);
  pthread_mutex_lock(&svc->lock);
  if (rc == 0) svc->status = r->v.robot_status = status;
  pthread_mutex_unlock(&svc->lock);
  if (rc == 0) robot_tcp_refresh(svc, l); /* where the motion ended */
  if (rc < 0)
    return unknown(r, l, rc, rc == FG_ETIMEDOUT ? "robot_timeout" : "robot_unknown",
                   "seq %u was acknowledged but its end was not seen: %s", seq,
                   fg_error_detail());
  if (status == FG_ROBOT_STOPPED) {
    /* stopped by someone else (the robot's own stop register, a pendant): latch too */
    pthread_mutex_lock(&svc->lock);
    robot_latch_set_locked(svc, "the robot reported a command stopped (status 4)", r->v.id, 0);
    pthread_mutex_unlock(&svc->lock);
    robot_latch_persist(svc);
    return stopped(r, NULL, st->name, 1);
  }
  if (status == FG_ROBOT_FAILED) {
    finish(r, FG_CMD_FAILED, "robot_failed", "the robot reported seq %u failed (status 3)",
           seq);
    return FG_EPEER;
  }
  return 0;
}

/* The robot worker's job: every step in order; a stop ends it between steps too. */
static int run_command(fg_mb_link *l, void *arg) {
  rec *r = arg;
  int robot_moved = 0;
  for (int i = 0; i < r->v.n_steps; i++) {
    if (stop_requested(r->svc)) return stopped(r, l, r->v.steps[i].name, 0);
    const int rc = r->v.steps[i].kind == FG_STEP_GRIPPER
                       ? run_gripper_step(r, i, robot_moved, NULL)
                       : run_robot_step(r, l, i, robot_moved);
    if (rc < 0) return rc;
    robot_moved |= r->v.steps[i].kind == FG_STEP_ROBOT;
  }
  finish(r, FG_CMD_DONE, NULL, NULL);
  return 0;
}

/* Gripper-only commands run on the gripper's worker directly. */
static int run_gripper_command(fg_mb_link *l, void *arg) {
  rec *r = arg;
  for (int i = 0; i < r->v.n_steps; i++) FG_TRY(run_gripper_step(r, i, 0, l));
  finish(r, FG_CMD_DONE, NULL, NULL);
  return 0;
}

static void job_done(void *arg, int rc) {
  rec *r = arg;
  fg_robot_svc *svc = r->svc;
  pthread_mutex_lock(&svc->lock);
  const int open = r->v.finished_s == 0;
  pthread_mutex_unlock(&svc->lock);
  if (open) /* cancelled before it ran */
    finish(r, FG_CMD_ERROR, "shutting_down", "the daemon is stopping; nothing was sent");
  (void)rc;
  pthread_mutex_lock(&svc->lock);
  rec_unref_locked(r);
  pthread_mutex_unlock(&svc->lock);
}

/* Adds r to the ring (taking one reference), dropping the oldest record. Under the lock. */
static void remember_locked(fg_robot_svc *svc, rec *r) {
  if (svc->n_recs == MAX_RECORDS) {
    rec_unref_locked(svc->recs[svc->head]);
    svc->recs[svc->head] = r;
    svc->head = (svc->head + 1) % MAX_RECORDS;
  } else {
    svc->recs[(svc->head + svc->n_recs++) % MAX_RECORDS] = r;
  }
  r->refs++;
}

/* Starts a planned record on peer p with job fn and waits as req asks. */
static int start_and_wait(fg_robot_svc *svc, const fg_robot_request *req, fg_mb_peer *p,
                          fg_mb_job_fn fn, fg_robot_cmd_view *v) {
  rec *r = calloc(1, sizeof *r);
  if (!r) return FG_ENOMEM;
  fg_motion_limits lim;
  robot_limits_now(svc, &lim);
  pthread_mutex_lock(&svc->lock);
  if (svc->stopping) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return fg_fail_as(FG_EBUSY, "robot_busy", "the daemon is stopping");
  }
  if (svc->active) {
    const fg_robot_cmd_view *a = &svc->active->v;
    int rc = fg_fail_as(FG_EBUSY, "robot_busy", "command %llu (%s) is still running (stage "
                        "%s); wait for it: GET /v1/robot/commands/%llu", (unsigned long long)a->id,
                        command_names[a->command], a->stage, (unsigned long long)a->id);
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return rc;
  }
  if (svc->gripper_busy) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return fg_fail_as(FG_EBUSY, "robot_busy", "a gripper action is running; wait for its answer");
  }
  int rc = robot_plan_locked(svc, &lim, req, &r->v);
  if (rc < 0) {
    pthread_mutex_unlock(&svc->lock);
    *v = r->v; /* the plan so far and the violation, for the refusal */
    free(r);
    return rc;
  }
  uint64_t id = svc->next_id;
  if (svc->ids && (rc = fg_cmd_ids_next(svc->ids, &id)) < 0) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return rc;
  }
  r->svc = svc;
  r->v.id = id;
  svc->next_id = id + 1;
  r->v.created_s = fg_real_s();
  r->v.state = FG_CMD_PENDING;
  r->v.seq = 0;
  r->refs = 2; /* this call and the job */
  remember_locked(svc, r);
  svc->active = r;
  pthread_mutex_unlock(&svc->lock);
  if (fg_mb_peer_post(p, fn, r, job_done) < 0) {
    finish(r, FG_CMD_ERROR, "busy", "%s", fg_error_detail());
    pthread_mutex_lock(&svc->lock);
    rec_unref_locked(r);
    pthread_mutex_unlock(&svc->lock);
  }
  /* the longest a command can honestly take, and then some */
  double budget_ms = svc->rp.ack_timeout_ms + svc->rp.done_timeout_ms +
                     3.0 * 2 * svc->motion_timeout_ms + 10000;
  struct timespec until;
  clock_gettime(CLOCK_REALTIME, &until);
  until.tv_sec += (time_t)(budget_ms / 1000) + 1;
  pthread_mutex_lock(&svc->lock);
  while (r->v.finished_s == 0 && !(!req->wait && r->v.state == FG_CMD_ACKNOWLEDGED))
    if (pthread_cond_timedwait(&svc->cond, &svc->lock, &until) != 0) break;
  *v = r->v;
  rec_unref_locked(r);
  pthread_mutex_unlock(&svc->lock);
  return 0;
}

int fg_robot_execute(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v) {
  const int c = req->command;
  const int gripper_only = svc->gripper && (c == FG_ROBOT_OPEN || c == FG_ROBOT_CLOSE);
  if (!gripper_only && !svc->robot)
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "no robot is configured: set [robot] "
                      "transport = tcp (host, port) or rtu (device) in the configuration file "
                      "and restart the daemon");
  return start_and_wait(svc, req, gripper_only ? svc->gripper : svc->robot,
                        gripper_only ? run_gripper_command : run_command, v);
}

int fg_robot_command_get(fg_robot_svc *svc, uint64_t id, fg_robot_cmd_view *v) {
  int rc = fg_fail(FG_ENOENT, "no command %llu (the newest %d are kept)",
                   (unsigned long long)id, MAX_RECORDS);
  pthread_mutex_lock(&svc->lock);
  for (size_t i = 0; i < svc->n_recs; i++) {
    rec *r = svc->recs[(svc->head + i) % MAX_RECORDS];
    if (r->v.id == id) {
      *v = r->v;
      rc = 0;
      break;
    }
  }
  pthread_mutex_unlock(&svc->lock);
  return rc;
}

/* ---------------------------------------------------------------- gripper actions */

int fg_gripper_action(fg_robot_svc *svc, const char *action, const fg_robot_request *req,
                      fg_robot_cmd_view *v) {
  if (strcmp(action, "move") == 0 && !req->has_width)
    return fg_fail(FG_EINVAL, "move needs \"width\" in metres (0 .. %g for the %s)",
                   svc->model->stroke_m, svc->model->name);
  if (strcmp(action, "close") == 0 && req->has_width)
    return fg_fail(FG_EINVAL, "close takes no width (it closes until the fingers meet an "
                   "object); use move for a width");
  fg_robot_request r = *req;
  r.command = strcmp(action, "close") == 0 ? FG_ROBOT_CLOSE : FG_ROBOT_OPEN;
  r.has_pose = 0;
  fg_motion_limits lim;
  robot_limits_now(svc, &lim);
  pthread_mutex_lock(&svc->lock);
  memset(v, 0, sizeof *v);
  v->gripper_unit = svc->gripper_unit;
  v->command = r.command;
  v->req = r;
  int rc = 0, pos = 255;
  if (svc->latch.latched)
    rc = fg_fail(FG_ESTOPPED, "the robot is stopped (%s); the gripper does not move either "
                 "until POST /v1/robot/reset", svc->latch.reason);
  if (rc == 0)
    rc = fg_motion_check_values(&lim, r.has_force ? r.force_n : -1, -1,
                                r.has_width ? r.width_m : -1, &v->violation);
  if (rc == 0 && r.command == FG_ROBOT_OPEN) rc = robot_open_position(svc, &r, &pos);
  if (rc == 0)
    rc = robot_plan_gripper(svc, &r, r.command == FG_ROBOT_OPEN ? "gripper_open" : "gripper_close",
                      pos, &v->steps[0]);
  pthread_mutex_unlock(&svc->lock);
  if (rc < 0) return rc;
  v->n_steps = 1;
  v->command = r.command;
  v->req = r;
  v->object_detected = -1;
  v->gripper_width_m = NAN;
  v->robot_status = -1;
  v->ack_ms = -1;
  v->stage = "queued";
  const int activate = strcmp(action, "activate") == 0;
  if (activate) { /* the write that starts it (after a reset to all zeros) */
    v->steps[0].name = "gripper_activate";
    v->steps[0].position = v->steps[0].speed = v->steps[0].force = 0;
    fg_robotiq_request(FG_ROBOTIQ_ACT, 0, 0, 0, v->steps[0].words);
  }
  if (req->dry_run) return 0;
  if (!svc->gripper)
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "no gripper is configured: set "
                      "[gripper.modbus] transport = rtu (device, baud) or tcp (host, port) and "
                      "restart the daemon");
  pthread_mutex_lock(&svc->lock);
  if (svc->active) {
    /* not between the steps of a pick or place */
    const fg_robot_cmd_view *a = &svc->active->v;
    rc = fg_fail_as(FG_EBUSY, "robot_busy", "command %llu (%s) is running (stage %s); the "
                    "gripper is part of it: wait for it: GET /v1/robot/commands/%llu",
                    (unsigned long long)a->id, command_names[a->command], a->stage,
                    (unsigned long long)a->id);
  } else if (svc->gripper_busy) {
    rc = fg_fail_as(FG_EBUSY, "robot_busy", "another gripper action is running; wait for its "
                    "answer");
  } else if (svc->latch.latched) { /* latched since the plan */
    rc = fg_fail(FG_ESTOPPED, "the robot is stopped (%s); POST /v1/robot/reset first",
                 svc->latch.reason);
  } else {
    svc->gripper_busy = 1; /* robot commands wait for this action: one thing moves at once */
  }
  pthread_mutex_unlock(&svc->lock);
  if (rc < 0) return rc;
  grip_job g = {.svc = svc, .step = &v->steps[0], .activate_only = activate,
                .status.position = -1, .may_activate = 1, .allow_drop = req->allow_drop};
  v->created_s = fg_real_s();
  rc = fg_mb_peer_call(svc->gripper, grip_run, &g);
  pthread_mutex_lock(&svc->lock);
  svc->gripper_busy = 0;
  pthread_mutex_unlock(&svc->lock);
  v->finished_s = fg_real_s();
  v->stage = "finished";
  if (g.status.position >= 0)
    v->gripper_width_m = fg_robotiq_position_to_width(svc->model, g.status.position);
  if (r.command == FG_ROBOT_CLOSE && rc == 0)
    v->object_detected = fg_robotiq_object_detected(&g.status);
  if (rc == 0) {
    v->state = FG_CMD_DONE;
  } else {
    const char *code;
    gripper_outcome(rc, &code);
    v->state = FG_CMD_ERROR;
    snprintf(v->code, sizeof v->code, "%s", code);
    snprintf(v->message, sizeof v->message, "%s", fg_error_detail());
  }
  pthread_mutex_lock(&svc->lock);
  svc->by_state[v->state]++;
  pthread_mutex_unlock(&svc->lock);
  return 0;
}

/* ---------------------------------------------------------------- stop and reset */

/* On the robot's worker, after the running command (if any) has ended: the stop word and a
 * no-op block, read back through the ack first so that the no-op's seq is a new one. */
static int stop_run(fg_mb_link *l, void *arg) {
  fg_robot_svc *svc = arg;
  FG_TRY(fg_mb_link_ensure(l));
  return robot_idle(l, svc); /* reads ack, then robot_latch_sync writes what the latch owes */
}

int fg_robot_stop(fg_robot_svc *svc, const char *reason, int *written, uint64_t *stopped_id) {
  *written = 0;
  *stopped_id = 0;
  if (!svc->robot)
    return fg_fail_as(FG_EUNAVAIL, "not_configured", "no robot is configured ([robot] "
                      "transport = none): there is nothing to stop");
  pthread_mutex_lock(&svc->lock);
  if (svc->active) *stopped_id = svc->active->v.id;
  robot_latch_set_locked(svc, reason, *stopped_id, 1);
  svc->stop_requested = 1;
  pthread_mutex_unlock(&svc->lock);
  robot_latch_persist(svc);
  /* queued behind the running command, whose waits end at their next poll */
  const int rc = fg_mb_peer_call(svc->robot, stop_run, svc);
  pthread_mutex_lock(&svc->lock);
  svc->stop_requested = 0;
  *written = svc->latch.stop_written;
  pthread_mutex_unlock(&svc->lock);
  if (rc < 0)
    fg_warn("robot: the stop could not be written yet (%s); motion stays refused and the "
            "stop is written when the robot answers", fg_error_detail());
  return 0;
}

/* On the robot's worker: the stop register back to 0, after what the latch still owes (a
 * no-op block must be in place before the robot may run again). */
static int reset_run(fg_mb_link *l, void *arg) {
  fg_robot_svc *svc = arg;
  FG_TRY(fg_mb_link_ensure(l));
  FG_TRY(robot_idle(l, svc));
  return fg_robot_write_stop(l, &svc->rp, 0);
}

int fg_robot_reset(fg_robot_svc *svc) {
  pthread_mutex_lock(&svc->lock);
  int rc = 0;
  if (svc->active || svc->gripper_busy)
    rc = fg_fail_as(FG_EBUSY, "robot_busy", "a command is still running; wait for it to end, "
                    "then reset");
  const int latched = svc->latch.latched;
  pthread_mutex_unlock(&svc->lock);
  if (rc < 0) return rc;
  if (svc->robot && (rc = fg_mb_peer_call(svc->robot, reset_run, svc)) < 0)
    return fg_fail_as(FG_EUNAVAIL, "robot_disconnected", "the robot could not be reached to "
                      "clear its stop register (%s); the stop stays latched", fg_error_detail());
  if (latched && unlink(svc->latch_path) < 0 && errno != ENOENT)
    return fg_fail_as(FG_EIO, "state_unavailable", "cannot remove %s (%s); the stop stays "
                      "latched", svc->latch_path, strerror(errno));
  pthread_mutex_lock(&svc->lock);
  memset(&svc->latch, 0, sizeof svc->latch);
  svc->latch_stop = 0;
  pthread_mutex_unlock(&svc->lock);
  if (latched) fg_info("robot: reset; motion is allowed again");
  return 0;
}
