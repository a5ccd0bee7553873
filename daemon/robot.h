/* The robot and gripper of the cell: the [robot] (pose-registers) and [gripper.modbus]
 * (robotiq-2f) peers of proto/modbus.md, each owned by its Modbus worker thread, and the
 * commands that run over them one at a time.
 *
 * A command is planned from a request (which steps, which words), then executed on the
 * robot's worker: open the gripper, write the pose block, wait for ack = seq, wait for
 * done, close the gripper, as the command needs. HTTP threads wait on the command's record
 * until it is acknowledged or finished; it runs to its end even when nobody waits. A
 * command whose acknowledgement or completion is not confirmed ends `unknown` and is never
 * sent again. */
#ifndef FG_DAEMON_ROBOT_H
#define FG_DAEMON_ROBOT_H

#include <stddef.h>
#include <stdint.h>

#include "conf.h"
#include "modbus/regs.h"

typedef struct fg_robot_svc fg_robot_svc;

/* A request of POST /v1/robot/commands (or a gripper action), checked by the caller for
 * types, by fg_robot_plan for ranges. */
typedef struct fg_robot_request {
  int command;          /* fg_robot_command */
  int has_pose;
  double p_world_m[3];  /* TCP position, world frame */
  double q_wxyz[4];     /* TCP orientation, unit quaternion */
  int has_width, has_force, has_speed;
  double width_m;       /* opening before the approach (pick), after it (place) */
  double force_n;       /* whole newtons for the robot block; the gripper's grip force */
  double speed_mps;     /* gripper finger speed */
  int dry_run, wait;
  char key[204];        /* the request's Idempotency-Key, "" when none (for on_finish) */
} fg_robot_request;

typedef enum {
  FG_CMD_PENDING = 0,  /* accepted, not yet acknowledged */
  FG_CMD_ACKNOWLEDGED, /* ack = seq; the robot is moving */
  FG_CMD_DONE,
  FG_CMD_FAILED,       /* the robot reported failure, or a gripper step after the motion failed */
  FG_CMD_UNKNOWN,      /* sent, but neither acknowledgement nor completion confirmed */
  FG_CMD_ERROR,        /* stopped before the robot got it: nothing was sent to the robot */
  FG_CMD_STATES
} fg_cmd_state;

const char *fg_cmd_state_name(fg_cmd_state s);

/* One step of a command. */
typedef enum { FG_STEP_GRIPPER = 1, FG_STEP_ROBOT } fg_step_kind;

typedef struct fg_robot_step {
  fg_step_kind kind;
  const char *name;     /* "gripper_open", "robot", "gripper_close" */
  uint16_t words[FG_POSE_MAX_WORDS]; /* robot: seq in words[0] once sent; gripper: 3 words */
  int n_words;
  int address;          /* first register */
  int position, speed, force; /* gripper bytes */
} fg_robot_step;

#define FG_ROBOT_MAX_STEPS 3

/* A command's record, as copied out by fg_robot_command_get. */
typedef struct fg_robot_cmd_view {
  uint64_t id;
  int command;
  fg_robot_request req;
  fg_robot_step steps[FG_ROBOT_MAX_STEPS];
  int n_steps;
  uint16_t seq;          /* 0 until the robot step is sent (or for gripper-only commands) */
  fg_cmd_state state;
  const char *stage;     /* the step running or last run; "queued", "finished" */
  int robot_status;      /* last status word read, -1 before */
  int object_detected;   /* pick with a gripper: 0/1 after the close; -1 otherwise */
  double gripper_width_m; /* after the last gripper step; NaN without one */
  int http_status;       /* the answer for this outcome (200, 202, 4xx, 5xx) */
  char code[40];         /* error code when http_status >= 400 */
  char message[512];
  double created_s, finished_s; /* CLOCK_REALTIME; finished 0 while running */
  double ack_ms;         /* write to acknowledgement, -1 before */
  int robot_unit, robot_base, gripper_unit;
  fg_pose_encoding encoding;
} fg_robot_cmd_view;

/* Creates the service for conf's [robot], [gripper] and [gripper.modbus]; peers with
 * transport none are left out. Peers that are down are fine: the workers keep trying.
 * 0, or FG_EINVAL/FG_ENOMEM with a detail; *out NULL on failure. */
int fg_robot_svc_new(fg_robot_svc **out, const fg_conf *conf);

/* Ends waits: a command that is waiting for the robot or the gripper ends at its next
 * poll (unknown), new commands are refused. NULL is fine. */
void fg_robot_svc_stop(fg_robot_svc *svc);

/* Stops the workers (after fg_robot_svc_stop, if not called before) and frees. NULL is
 * fine. */
void fg_robot_svc_free(fg_robot_svc *svc);

/* Calls fn(ctx, v) on the worker each time a command of fg_robot_execute ends, with its
 * final record, after the waiters are woken (the daemon keeps Idempotency-Key answers
 * current with it). Set before the first command. */
void fg_robot_svc_on_finish(fg_robot_svc *svc, void (*fn)(void *ctx, const fg_robot_cmd_view *v),
                            void *ctx);

/* Whether [robot] / [gripper.modbus] are configured (transport != none). */
int fg_robot_svc_has_robot(const fg_robot_svc *svc);
int fg_robot_svc_has_gripper(const fg_robot_svc *svc);

/* Plans req into *v (steps and words; seq is the one the next command would get) without
 * sending anything: what a dry run returns. FG_ERANGE/FG_EINVAL with a detail for values
 * the encodings or the gripper cannot take; FG_EUNAVAIL when the command needs a peer that
 * is not configured (the detail says which section to set). */
int fg_robot_plan(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v);

/* Plans and starts req, then waits until it is acknowledged (req->wait = 0) or finished,
 * and copies its record to *v. 0 when it ran (its outcome is in v->state/http_status), or:
 * the plan's errors, FG_EBUSY when another command is running (detail names it). */
int fg_robot_execute(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v);

/* Takes command ids from ids (kept by the caller, freed after svc), so that they stay
 * unique across restarts; call before any command. Without, ids count from 1. */
struct fg_cmd_ids;
void fg_robot_svc_set_ids(fg_robot_svc *svc, struct fg_cmd_ids *ids);

/* The record of command id (the newest 1000 are kept): 0 or FG_ENOENT. */
int fg_robot_command_get(fg_robot_svc *svc, uint64_t id, fg_robot_cmd_view *v);

/* What both peers report of their connection. */
typedef struct fg_peer_view {
  int configured, connected;
  char address[300];
  int unit_id;
  char last_error[256]; /* "" when none */
  double last_error_s;  /* CLOCK_REALTIME */
  uint64_t requests, errors, timeouts, exceptions, reconnects;
  unsigned generation;  /* the number of the last connection, 0 before the first */
} fg_peer_view;

/* The robot peer's state for GET /v1/robot. */
typedef struct fg_robot_state {
  fg_peer_view peer;
  int base;
  fg_pose_encoding encoding;
  uint16_t last_seq;     /* the last seq sent, 0 when none */
  int ack, status;       /* last read, -1 before any read */
  int busy;              /* a command is running */
  uint64_t last_command; /* id of the newest command, 0 when none */
} fg_robot_state;

void fg_robot_state_get(fg_robot_svc *svc, fg_robot_state *st);

/* The gripper's state for GET /v1/gripper. */
typedef struct fg_gripper_state {
  fg_peer_view peer;
  const char *model;     /* robotiq-2f85 / robotiq-2f140 */
  int have_status;       /* a status was read since the connection */
  fg_robotiq_status status;
  double width_m;        /* from gPO */
} fg_gripper_state;

void fg_gripper_state_get(fg_robot_svc *svc, fg_gripper_state *st);

/* Gripper actions of /v1/gripper/...: action "open" (to width, else fully), "close", "move"
 * (to width), "activate". Plans like fg_robot_plan, runs on the gripper's worker and waits;
 * req->dry_run returns the plan only. 0 when it ran (outcome in *v as for commands); the
 * plan's errors otherwise, FG_EBUSY while a command runs (the gripper may be one of its
 * steps). */
int fg_gripper_action(fg_robot_svc *svc, const char *action, const fg_robot_request *req,
                      fg_robot_cmd_view *v);

/* Appends Prometheus lines for both peers and the commands to buf (at most size bytes);
 * returns the length written. */
size_t fg_robot_metrics(fg_robot_svc *svc, char *buf, size_t size);

#endif
