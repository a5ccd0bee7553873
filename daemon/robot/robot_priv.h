/* What the robot service's files share (robot.h is the service's contract): the service's
 * state, a command's record, and the functions one part calls in another. robot.c: set-up,
 * execution, gripper actions; robot_plan.c: planning against the limits; robot_latch.c:
 * the latch, stop and reset; robot_state.c: state and metrics. Not for other files. */
#ifndef FG_DAEMON_ROBOT_PRIV_H
#define FG_DAEMON_ROBOT_PRIV_H

#include <pthread.h>
#include <stdint.h>

#include "cmd_ids.h"
#include "modbus/devices.h"
#include "modbus/peer.h"
#include "robot.h"

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
  int tcp_base;          /* [robot] tcp_pose_base; -1 none (or no robot) */
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
  fg_robot_tcp tcp;      /* robot_tcp.c */
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

/* ---- robot_tcp.c */

/* Reads the TCP pose on the robot's worker and keeps it (a failure only as its error), when
 * [robot] publishes one. */
void robot_tcp_refresh(fg_robot_svc *svc, fg_mb_link *l);

/* ---- robot_plan.c */

/* The limits in force: [robot]'s, with the box of the scenes' workspaces (grown by the
 * margin) when [robot] sets none. Takes the lock itself; the workspace source runs outside
 * it. */
void robot_limits_now(fg_robot_svc *svc, fg_motion_limits *lim);

/* Plans req under the lock with the limits lim into *v (robot.h, fg_robot_plan). */
int robot_plan_locked(fg_robot_svc *svc, const fg_motion_limits *lim,
                      const fg_robot_request *req, fg_robot_cmd_view *v);

/* A gripper step moving to position at the request's speed and force, and the position of
 * the request's width (fully open without one). */
int robot_plan_gripper(fg_robot_svc *svc, const fg_robot_request *req, const char *name,
                       int position, fg_robot_step *st);
int robot_open_position(fg_robot_svc *svc, const fg_robot_request *req, int *position);

/* ---- robot_latch.c */

/* Latches (under the lock) with reason and the command that caused it; the first cause is
 * kept while latched. stop: the stop register is to hold 1. */
void robot_latch_set_locked(fg_robot_svc *svc, const char *reason, uint64_t command, int stop);

/* Writes the latch to its file; loads an earlier run's. */
void robot_latch_persist(fg_robot_svc *svc);
void robot_latch_load(fg_robot_svc *svc);

/* Writes what the latch still owes the robot: the stop word, the no-op block. */
int robot_latch_sync(fg_robot_svc *svc, fg_mb_link *l);

#endif
