#include "robot.h"

#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <errno.h>
#include <unistd.h>

#include <jansson.h>

#include "cmd_ids.h"
#include "core/error.h"
#include "core/clock.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/pose.h"
#include "modbus/devices.h"
#include "modbus/peer.h"

#define MAX_RECORDS 1000
#define DEFAULT_FORCE_N 40.0
#define ROBOT_IDLE_MS 1000
#define GRIPPER_IDLE_MS 500

typedef struct rec {
  fg_robot_cmd_view v;
  int refs; /* guarded by svc->lock */
  struct fg_robot_svc *svc;
} rec;

struct fg_robot_svc {
  fg_mb_peer *robot, *gripper; /* NULL when not configured */
  fg_robot_profile rp;
  int robot_unit, gripper_unit;
  const fg_robotiq_model *model;
  int motion_timeout_ms;

  pthread_mutex_t lock; /* guards everything below */
  pthread_cond_t cond;  /* records changed */
  rec *recs[MAX_RECORDS]; /* ring of the newest records, oldest at head */
  size_t n_recs, head;
  uint64_t next_id;      /* one past the last id handed out */
  fg_cmd_ids *ids;       /* where ids come from; NULL: from 1 at each start */
  rec *active;          /* the command running, or NULL */
  int stopping;
  /* robot: written by its worker */
  uint16_t last_seq;
  unsigned gen_seen;    /* link generation whose ack last_seq was read from */
  int ack, status;
  /* gripper: written by its worker */
  int g_have;
  fg_robotiq_status g_status;
  unsigned g_gen;       /* link generation of g_status */
  uint64_t by_state[FG_CMD_STATES];
  void (*on_finish)(void *ctx, const fg_robot_cmd_view *v); /* set before any command */
  void *on_finish_ctx;
  /* motion limits and path defaults (fg_robot_svc_configure) */
  fg_motion_limits lim;  /* the box only when box_from_conf */
  int box_from_conf;
  double margin_m, speed_mps, approach_m, retreat_m;
  fg_robot_workspace_fn ws_fn; /* set before any command */
  void *ws_ctx;
  /* the latch, and what is still to be written for it */
  fg_robot_latch latch;
  char *latch_path;     /* <state>/robot/latch.json */
  int stop_requested;   /* the running command's waits end: it is being stopped */
  int gripper_busy;     /* a gripper action runs */
  int latch_stop;       /* the latch wants the stop register at 1 (a stop, not an outcome) */
};

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

static int latch_sync(fg_robot_svc *svc, fg_mb_link *l);
static void limits_now(fg_robot_svc *svc, fg_motion_limits *lim);

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
  return latch_sync(svc, l);
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

/* ---------------------------------------------------------------- the latch */

/* Latches (under the lock) with reason and the command that caused it; the first cause is
 * kept while latched. stop: the stop register is to hold 1. */
static void latch_set_locked(fg_robot_svc *svc, const char *reason, uint64_t command,
                             int stop) {
  fg_robot_latch *l = &svc->latch;
  if (!l->latched) {
    l->latched = 1;
    snprintf(l->reason, sizeof l->reason, "%.500s", reason);
    l->at_s = fg_real_s();
    l->command = command;
  }
  if (stop) {
    svc->latch_stop = 1;
    l->stop_written = 0;
  }
  l->clear_pending = 1;
}

/* Writes the latch to its file (atomically), so that a restarted daemon is latched too. A
 * failure is logged: the latch holds in memory either way. */
static void latch_persist(fg_robot_svc *svc) {
  if (!svc->latch_path) return;
  pthread_mutex_lock(&svc->lock);
  json_t *o = json_pack("{s:s, s:f, s:I, s:b}", "reason", svc->latch.reason, "at",
                        svc->latch.at_s, "command", (json_int_t)svc->latch.command, "stop",
                        svc->latch_stop);
  pthread_mutex_unlock(&svc->lock);
  char *text = o ? json_dumps(o, JSON_COMPACT) : NULL;
  json_decref(o);
  if (!text || fg_write_file_atomic(svc->latch_path, text, strlen(text)) < 0)
    fg_error("robot: the latch could not be written to %s (%s); it holds until this daemon "
             "stops", svc->latch_path, text ? fg_error_detail() : "out of memory");
  free(text);
}

/* Reads the latch file of an earlier run, if any. */
static void latch_load(fg_robot_svc *svc) {
  char *buf = NULL;
  size_t len = 0;
  if (fg_read_file(svc->latch_path, 1 << 16, &buf, &len) < 0) return; /* none: not latched */
  json_t *o = json_loadb(buf, len, 0, NULL);
  free(buf);
  const char *reason = "latched before the daemon restarted";
  json_t *jr = json_object_get(o, "reason"), *jc = json_object_get(o, "command");
  if (json_is_string(jr)) reason = json_string_value(jr);
  latch_set_locked(svc, reason, json_is_integer(jc) ? (uint64_t)json_integer_value(jc) : 0,
                   json_is_true(json_object_get(o, "stop")));
  double at = json_real_value(json_object_get(o, "at"));
  if (at > 0) svc->latch.at_s = at;
  json_decref(o);
  fg_warn("robot: latched since an earlier run (%s); motion is refused until POST "
          "/v1/robot/reset", svc->latch.reason);
}

/* A no-op block under a new seq: a robot program that finds a block it has not run yet
 * runs this instead. Clears clear_pending once written. */
static int clear_block(fg_robot_svc *svc, fg_mb_link *l) {
  pthread_mutex_lock(&svc->lock);
  uint16_t seq = fg_seq_next(svc->last_seq);
  if (seq == svc->ack) seq = fg_seq_next(seq);
  svc->last_seq = seq;
  pthread_mutex_unlock(&svc->lock);
  const fg_pose_block b = {.seq = seq, .command = FG_ROBOT_NOOP};
  uint16_t w[FG_POSE_MAX_WORDS];
  FG_TRY(fg_pose_block_encode(&b, svc->rp.encoding, w));
  FG_TRY(fg_robot_write(l, &svc->rp, w));
  pthread_mutex_lock(&svc->lock);
  svc->latch.clear_pending = 0;
  pthread_mutex_unlock(&svc->lock);
  fg_info("robot: wrote a no-op block (seq %u) so that nothing stays armed", seq);
  return 0;
}

/* Writes what the latch still owes the robot: the stop word, the no-op block. */
static int latch_sync(fg_robot_svc *svc, fg_mb_link *l) {
  pthread_mutex_lock(&svc->lock);
  const int stop = svc->latch.latched && svc->latch_stop && !svc->latch.stop_written;
  const int clear = svc->latch.latched && svc->latch.clear_pending;
  pthread_mutex_unlock(&svc->lock);
  if (stop) {
    FG_TRY(fg_robot_write_stop(l, &svc->rp, 1));
    pthread_mutex_lock(&svc->lock);
    svc->latch.stop_written = 1;
    pthread_mutex_unlock(&svc->lock);
  }
  if (clear) FG_TRY(clear_block(svc, l));
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
  latch_load(svc);
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

void fg_robot_limits_get(fg_robot_svc *svc, fg_motion_limits *out) { limits_now(svc, out); }

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

/* ---------------------------------------------------------------- planning */

/* A gripper step moving to position at the request's speed and force. */
static int plan_gripper(fg_robot_svc *svc, const fg_robot_request *req, const char *name,
                        int position, fg_robot_step *st) {
  memset(st, 0, sizeof *st);
  st->kind = FG_STEP_GRIPPER;
  st->name = name;
  st->position = position;
  const fg_robotiq_model *m = svc->model;
  FG_TRY(fg_robotiq_speed_to_byte(m, req->has_speed ? req->speed_mps : m->speed_max_mps,
                                  &st->speed));
  FG_TRY(fg_robotiq_force_to_byte(m, req->has_force ? req->force_n : DEFAULT_FORCE_N,
                                  &st->force));
  fg_robotiq_request(FG_ROBOTIQ_ACT | FG_ROBOTIQ_GTO, position, st->speed, st->force, st->words);
  st->n_words = FG_ROBOTIQ_WORDS;
  st->address = FG_ROBOTIQ_REQUEST_ADDR;
  return 0;
}

/* The position of the request's width, or fully open without one. */
static int open_position(fg_robot_svc *svc, const fg_robot_request *req, int *position) {
  if (!req->has_width) {
    *position = 0;
    return 0;
  }
  return fg_robotiq_width_to_position(svc->model, req->width_m, position);
}

/* The limits in force: [robot]'s, with the box of the scenes' workspaces (grown by the
 * margin) when [robot] sets none. Takes the lock itself; the workspace source runs
 * outside it. */
static void limits_now(fg_robot_svc *svc, fg_motion_limits *lim) {
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

/* Plans req under the lock with the limits lim (limits_now). The steps, in order:
 *   pick:  gripper_open, robot (approach, descend), gripper_close, robot_retreat (lift)
 *   place: robot (approach, descend), gripper_open, robot_retreat (back out)
 *   move:  robot; open / close: the gripper (or the robot block without a gripper).
 * Without a gripper of its own the robot program actuates the tool and retreats itself: the
 * block carries the retreat and no robot_retreat step follows. */
static int plan_locked(fg_robot_svc *svc, const fg_motion_limits *lim,
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
  const double force = req->has_force ? req->force_n : DEFAULT_FORCE_N;
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
    FG_TRY(open_position(svc, req, &pos));
    FG_TRY(plan_gripper(svc, &greq, "gripper_open", pos, &v->steps[n++]));
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
    FG_TRY(plan_gripper(svc, &greq, "gripper_close", 255, &v->steps[n++]));
  if (grip && (c == FG_ROBOT_PLACE || c == FG_ROBOT_OPEN)) {
    FG_TRY(open_position(svc, req, &pos));
    FG_TRY(plan_gripper(svc, &greq, "gripper_open", pos, &v->steps[n++]));
  }
  if (grip && c == FG_ROBOT_CLOSE)
    FG_TRY(plan_gripper(svc, &greq, "gripper_close", 255, &v->steps[n++]));
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
  limits_now(svc, &lim);
  pthread_mutex_lock(&svc->lock);
  int rc = plan_locked(svc, &lim, req, v);
  pthread_mutex_unlock(&svc->lock);
  return rc;
}

/* ---------------------------------------------------------------- execution */

/* Ends r with an outcome (under no lock); wakes the waiters. */
static void finish(rec *r, fg_cmd_state state, int http, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));
static void finish(rec *r, fg_cmd_state state, int http, const char *code, const char *fmt,
                   ...) {
  fg_robot_svc *svc = r->svc;
  pthread_mutex_lock(&svc->lock);
  r->v.state = state;
  r->v.http_status = http;
  snprintf(r->v.code, sizeof r->v.code, "%s", code ? code : "");
  if (fmt) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(r->v.message, sizeof r->v.message, fmt, ap);
    va_end(ap);
  }
  r->v.finished_s = fg_real_s();
  r->v.stage = "finished";
  svc->by_state[state]++;
  const int latch = state == FG_CMD_UNKNOWN;
  if (latch) {
    /* before the command lets go of the robot, so that no other starts in between */
    char reason[sizeof svc->latch.reason + 64];
    snprintf(reason, sizeof reason, "command %llu (%s) ended unknown: %.400s",
             (unsigned long long)r->v.id, command_names[r->v.command], r->v.message);
    latch_set_locked(svc, reason, r->v.id, 0);
  }
  if (svc->active == r) svc->active = NULL;
  pthread_cond_broadcast(&svc->cond);
  pthread_mutex_unlock(&svc->lock);
  if (state != FG_CMD_DONE)
    fg_warn("robot: command %llu (%s, seq %u) ended %s: %s", (unsigned long long)r->v.id,
            command_names[r->v.command], r->v.seq, state_names[state], r->v.message);
  if (svc->on_finish) svc->on_finish(svc->on_finish_ctx, &r->v);
  if (latch) latch_persist(svc); /* held in memory already: the answer goes first */
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

/* The HTTP answer for a failed gripper call. */
static void gripper_outcome(int rc, int *http, const char **code) {
  *http = rc == FG_EUNAVAIL ? 503 : rc == FG_ETIMEDOUT ? 504 : 502;
  if (rc == FG_EPERM || rc == FG_EBUSY) *http = 409;
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
  int http;
  const char *code;
  gripper_outcome(rc, &http, &code);
  finish(r, robot_moved ? FG_CMD_FAILED : FG_CMD_ERROR, http, code, "%s: %s",
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
  finish(r, FG_CMD_STOPPED, 409, "robot_stopped", "stopped %s during %s; POST "
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
  finish(r, FG_CMD_UNKNOWN, rc == FG_ETIMEDOUT ? 504 : 502, code,
         "%s; the robot is stopped until POST /v1/robot/reset", msg);
  if (latch_sync(r->svc, l) < 0)
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
    finish(r, not_sent, 503, "robot_disconnected", "%s: nothing was sent: %s", st->name,
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
    finish(r, not_sent, 502, "modbus_exception", "the robot refused the pose write: %s",
           fg_error_detail());
    return rc;
  }
  if (rc < 0 && !fg_mb_link_maybe_sent(l)) {
    pthread_mutex_lock(&svc->lock);
    if (svc->last_seq == seq) svc->last_seq = (uint16_t)(seq == 1 ? 65535 : seq - 1);
    pthread_mutex_unlock(&svc->lock);
    finish(r, not_sent, 503, "robot_disconnected", "%s: nothing was sent: %s", st->name,
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
  if (rc < 0)
    return unknown(r, l, rc, rc == FG_ETIMEDOUT ? "robot_timeout" : "robot_unknown",
                   "seq %u was acknowledged but its end was not seen: %s", seq,
                   fg_error_detail());
  if (status == FG_ROBOT_STOPPED) {
    /* stopped by someone else (the robot's own stop register, a pendant): latch too */
    pthread_mutex_lock(&svc->lock);
    latch_set_locked(svc, "the robot reported a command stopped (status 4)", r->v.id, 0);
    pthread_mutex_unlock(&svc->lock);
    latch_persist(svc);
    return stopped(r, NULL, st->name, 1);
  }
  if (status == FG_ROBOT_FAILED) {
    finish(r, FG_CMD_FAILED, 502, "robot_failed", "the robot reported seq %u failed (status 3)",
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
  finish(r, FG_CMD_DONE, 200, NULL, NULL);
  return 0;
}

/* Gripper-only commands run on the gripper's worker directly. */
static int run_gripper_command(fg_mb_link *l, void *arg) {
  rec *r = arg;
  for (int i = 0; i < r->v.n_steps; i++) FG_TRY(run_gripper_step(r, i, 0, l));
  finish(r, FG_CMD_DONE, 200, NULL, NULL);
  return 0;
}

static void job_done(void *arg, int rc) {
  rec *r = arg;
  fg_robot_svc *svc = r->svc;
  pthread_mutex_lock(&svc->lock);
  const int open = r->v.finished_s == 0;
  pthread_mutex_unlock(&svc->lock);
  if (open) /* cancelled before it ran */
    finish(r, FG_CMD_ERROR, 503, "shutting_down", "the daemon is stopping; nothing was sent");
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
  limits_now(svc, &lim);
  pthread_mutex_lock(&svc->lock);
  if (svc->stopping) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return fg_fail(FG_EBUSY, "the daemon is stopping");
  }
  if (svc->active) {
    const fg_robot_cmd_view *a = &svc->active->v;
    int rc = fg_fail(FG_EBUSY, "command %llu (%s) is still running (stage %s); wait for it: GET "
                     "/v1/robot/commands/%llu", (unsigned long long)a->id,
                     command_names[a->command], a->stage, (unsigned long long)a->id);
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return rc;
  }
  if (svc->gripper_busy) {
    pthread_mutex_unlock(&svc->lock);
    free(r);
    return fg_fail(FG_EBUSY, "a gripper action is running; wait for its answer");
  }
  int rc = plan_locked(svc, &lim, req, &r->v);
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
    finish(r, FG_CMD_ERROR, 503, "busy", "%s", fg_error_detail());
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
  if (v->finished_s == 0) v->http_status = 202;
  rec_unref_locked(r);
  pthread_mutex_unlock(&svc->lock);
  return 0;
}

int fg_robot_execute(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v) {
  const int c = req->command;
  const int gripper_only = svc->gripper && (c == FG_ROBOT_OPEN || c == FG_ROBOT_CLOSE);
  if (!gripper_only && !svc->robot)
    return fg_fail(FG_EUNAVAIL, "no robot is configured: set [robot] transport = tcp (host, "
                   "port) or rtu (device) in the configuration file and restart the daemon");
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
  limits_now(svc, &lim);
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
  if (rc == 0 && r.command == FG_ROBOT_OPEN) rc = open_position(svc, &r, &pos);
  if (rc == 0)
    rc = plan_gripper(svc, &r, r.command == FG_ROBOT_OPEN ? "gripper_open" : "gripper_close",
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
    return fg_fail(FG_EUNAVAIL, "no gripper is configured: set [gripper.modbus] transport = "
                   "rtu (device, baud) or tcp (host, port) and restart the daemon");
  pthread_mutex_lock(&svc->lock);
  if (svc->active) {
    /* not between the steps of a pick or place */
    const fg_robot_cmd_view *a = &svc->active->v;
    rc = fg_fail(FG_EBUSY, "command %llu (%s) is running (stage %s); the gripper is part of "
                 "it: wait for it: GET /v1/robot/commands/%llu", (unsigned long long)a->id,
                 command_names[a->command], a->stage, (unsigned long long)a->id);
  } else if (svc->gripper_busy) {
    rc = fg_fail(FG_EBUSY, "another gripper action is running; wait for its answer");
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
    v->http_status = 200;
  } else {
    const char *code;
    gripper_outcome(rc, &v->http_status, &code);
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
  return robot_idle(l, svc); /* reads ack, then latch_sync writes what the latch owes */
}

int fg_robot_stop(fg_robot_svc *svc, const char *reason, int *written, uint64_t *stopped_id) {
  *written = 0;
  *stopped_id = 0;
  if (!svc->robot)
    return fg_fail(FG_EUNAVAIL, "no robot is configured ([robot] transport = none): there is "
                   "nothing to stop");
  pthread_mutex_lock(&svc->lock);
  if (svc->active) *stopped_id = svc->active->v.id;
  latch_set_locked(svc, reason, *stopped_id, 1);
  svc->stop_requested = 1;
  pthread_mutex_unlock(&svc->lock);
  latch_persist(svc);
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
    rc = fg_fail(FG_EBUSY, "a command is still running; wait for it to end, then reset");
  const int latched = svc->latch.latched;
  pthread_mutex_unlock(&svc->lock);
  if (rc < 0) return rc;
  if (svc->robot && (rc = fg_mb_peer_call(svc->robot, reset_run, svc)) < 0)
    return fg_fail(FG_EUNAVAIL, "the robot could not be reached to clear its stop register "
                   "(%s); the stop stays latched", fg_error_detail());
  if (latched && unlink(svc->latch_path) < 0 && errno != ENOENT)
    return fg_fail(FG_EIO, "cannot remove %s (%s); the stop stays latched", svc->latch_path,
                   strerror(errno));
  pthread_mutex_lock(&svc->lock);
  memset(&svc->latch, 0, sizeof svc->latch);
  svc->latch_stop = 0;
  pthread_mutex_unlock(&svc->lock);
  if (latched) fg_info("robot: reset; motion is allowed again");
  return 0;
}

void fg_robot_latch_get(fg_robot_svc *svc, fg_robot_latch *out) {
  pthread_mutex_lock(&svc->lock);
  *out = svc->latch;
  pthread_mutex_unlock(&svc->lock);
}

/* ---------------------------------------------------------------- state and metrics */

/* The connection part of a peer's state; p may be NULL (not configured). */
static void peer_view(fg_mb_peer *p, int unit_id, fg_peer_view *v) {
  memset(v, 0, sizeof *v);
  v->configured = p != NULL;
  v->unit_id = unit_id;
  if (!p) return;
  fg_mb_link_state ls;
  fg_mb_peer_state(p, &ls);
  v->connected = ls.connected;
  snprintf(v->address, sizeof v->address, "%s", fg_mb_peer_address(p));
  memcpy(v->last_error, ls.last_error, sizeof v->last_error);
  v->last_error_s = ls.last_error_s;
  v->requests = ls.requests;
  v->errors = ls.errors;
  v->timeouts = ls.timeouts;
  v->exceptions = ls.exceptions;
  v->reconnects = ls.reconnects;
  v->generation = ls.generation;
}

void fg_robot_state_get(fg_robot_svc *svc, fg_robot_state *st) {
  memset(st, 0, sizeof *st);
  peer_view(svc->robot, svc->robot_unit, &st->peer);
  st->base = svc->rp.base;
  st->encoding = svc->rp.encoding;
  pthread_mutex_lock(&svc->lock);
  st->last_seq = svc->last_seq;
  st->ack = svc->ack;
  st->status = svc->status;
  st->busy = svc->active != NULL;
  st->last_command = svc->next_id - 1;
  pthread_mutex_unlock(&svc->lock);
}

void fg_gripper_state_get(fg_robot_svc *svc, fg_gripper_state *st) {
  memset(st, 0, sizeof *st);
  peer_view(svc->gripper, svc->gripper_unit, &st->peer);
  st->model = svc->model->name;
  st->width_m = NAN;
  if (!svc->gripper) return;
  pthread_mutex_lock(&svc->lock);
  /* a status of an earlier connection is not this one's: the gripper may have been power
   * cycled (and lost its activation) in between */
  st->have_status = svc->g_have && st->peer.connected && svc->g_gen == st->peer.generation;
  st->status = svc->g_status;
  pthread_mutex_unlock(&svc->lock);
  if (st->have_status) st->width_m = fg_robotiq_position_to_width(svc->model, st->status.position);
}

/* Appends printf output to buf at *len, never past size. */
static void append(char *buf, size_t size, size_t *len, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void append(char *buf, size_t size, size_t *len, const char *fmt, ...) {
  if (*len + 1 >= size) return;
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(buf + *len, size - *len, fmt, ap);
  va_end(ap);
  if (n > 0) *len += (size_t)n < size - *len ? (size_t)n : size - *len - 1;
}

size_t fg_robot_metrics(fg_robot_svc *svc, char *buf, size_t size) {
  fg_mb_peer *peers[2] = {svc->robot, svc->gripper};
  static const char *const names[2] = {"robot", "gripper"};
  fg_mb_link_state ls[2] = {{0}, {0}};
  for (int i = 0; i < 2; i++)
    if (peers[i]) fg_mb_peer_state(peers[i], &ls[i]);
  size_t len = 0;
  buf[0] = '\0';
  append(buf, size, &len, "# HELP fieldgrip_modbus_connected Whether the Modbus peer is "
         "connected (absent: not configured).\n# TYPE fieldgrip_modbus_connected gauge\n");
  for (int i = 0; i < 2; i++)
    if (peers[i])
      append(buf, size, &len, "fieldgrip_modbus_connected{peer=\"%s\"} %d\n", names[i],
             ls[i].connected);
  append(buf, size, &len, "# HELP fieldgrip_modbus_requests_total Modbus requests sent.\n"
         "# TYPE fieldgrip_modbus_requests_total counter\n");
  for (int i = 0; i < 2; i++)
    if (peers[i])
      append(buf, size, &len, "fieldgrip_modbus_requests_total{peer=\"%s\"} %llu\n", names[i],
             (unsigned long long)ls[i].requests);
  /* Four distinct causes: no answer in time, an exception reply, a request that failed on the
   * wire (the connection dropped or was reset, or the reply was garbled), and an attempt to
   * open the connection that failed. */
  append(buf, size, &len, "# HELP fieldgrip_modbus_errors_total Modbus errors by kind: timeout "
         "(no reply in time), exception (an exception reply), transport (a request failed on "
         "the wire: connection lost or reply garbled), connect (a connection attempt failed)."
         "\n# TYPE fieldgrip_modbus_errors_total counter\n");
  for (int i = 0; i < 2; i++) {
    if (!peers[i]) continue;
    const fg_mb_link_state *l = &ls[i];
    append(buf, size, &len,
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"timeout\"} %llu\n"
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"exception\"} %llu\n"
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"transport\"} %llu\n"
           "fieldgrip_modbus_errors_total{peer=\"%s\",kind=\"connect\"} %llu\n",
           names[i], (unsigned long long)l->timeouts, names[i],
           (unsigned long long)l->exceptions, names[i],
           (unsigned long long)(l->errors - l->timeouts - l->exceptions), names[i],
           (unsigned long long)l->connect_failures);
  }
  append(buf, size, &len, "# HELP fieldgrip_modbus_reconnects_total Connections made after "
         "the first.\n# TYPE fieldgrip_modbus_reconnects_total counter\n");
  for (int i = 0; i < 2; i++)
    if (peers[i])
      append(buf, size, &len, "fieldgrip_modbus_reconnects_total{peer=\"%s\"} %llu\n",
             names[i], (unsigned long long)ls[i].reconnects);
  uint64_t by[FG_CMD_STATES];
  pthread_mutex_lock(&svc->lock);
  memcpy(by, svc->by_state, sizeof by);
  pthread_mutex_unlock(&svc->lock);
  append(buf, size, &len, "# HELP fieldgrip_robot_commands_total Robot and gripper commands "
         "finished, by outcome.\n# TYPE fieldgrip_robot_commands_total counter\n");
  for (int s = FG_CMD_DONE; s < FG_CMD_STATES; s++)
    append(buf, size, &len, "fieldgrip_robot_commands_total{state=\"%s\"} %llu\n",
           state_names[s], (unsigned long long)by[s]);
  return len;
}
