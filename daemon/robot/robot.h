/* The robot and gripper of the cell: the [robot] (pose-registers) and [gripper.modbus]
 * (robotiq-2f) peers of proto/modbus.md, each owned by its Modbus worker thread, and the
 * commands that run over them one at a time.
 *
 * A command is planned from a request (which steps, which words), then executed on the
 * robot's worker: open the gripper, write the pose block, wait for ack = seq, wait for
 * done, close the gripper, as the command needs. HTTP threads wait on the command's record
 * until it is acknowledged or finished; it runs to its end even when nobody waits. A
 * command whose acknowledgement or completion is not confirmed ends `unknown` and is never
 * sent again.
 *
 * This is the one gate to the robot and the gripper: every command and gripper action is
 * planned here, and the plan refuses (FG_ELIMIT, nothing written) what the motion limits of
 * [robot] do not allow (motion/limits.h): a pose, its approach and its retreat outside the
 * position box, an approach outside the cone, a force, speed or width above its limit.
 *
 * The latch. POST /v1/robot/stop (fg_robot_stop) writes the robot's stop register, ends the
 * running command as `stopped` and latches; so does any command that ends `unknown`, after
 * writing a no-op block so that a robot program that comes back later finds nothing armed.
 * While latched every motion is refused (FG_ESTOPPED) until an operator calls
 * fg_robot_reset. The latch is kept in a file under the state dir, so a restart keeps it. */
#ifndef FG_DAEMON_ROBOT_H
#define FG_DAEMON_ROBOT_H

#include <stddef.h>
#include <stdint.h>

#include "conf/conf.h"
#include "modbus/regs.h"
#include "motion/limits.h"

typedef struct fg_robot_svc fg_robot_svc;

/* A request of POST /v1/robot/commands (or a gripper action), checked by the caller for
 * types, by fg_robot_plan for ranges. */
typedef struct fg_robot_request {
  int command;          /* fg_robot_command */
  int has_pose;
  double p_world_m[3];  /* TCP position, world frame */
  double q_wxyz[4];     /* TCP orientation, unit quaternion */
  int has_width, has_force, has_speed, has_approach, has_retreat;
  double width_m;       /* opening before the approach (pick), after it (place) */
  double force_n;       /* whole newtons for the robot block; the gripper's grip force */
  double speed_mps;     /* commands: the TCP's speed; gripper actions: the fingers' */
  double approach_m;    /* pick/place/move: come in along the tool's +z from this far back */
  double retreat_m;     /* pick: lift this much after the grip; place: back out this much */
  int allow_drop;       /* gripper activate: go ahead although an object is held */
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
  FG_CMD_STOPPED,      /* halted by POST /v1/robot/stop */
  FG_CMD_STATES
} fg_cmd_state;

const char *fg_cmd_state_name(fg_cmd_state s);

/* One step of a command. */
typedef enum { FG_STEP_GRIPPER = 1, FG_STEP_ROBOT } fg_step_kind;

typedef struct fg_robot_step {
  fg_step_kind kind;
  const char *name;     /* "gripper_open", "robot", "gripper_close", "robot_retreat" */
  uint16_t words[FG_POSE_MAX_WORDS]; /* robot: seq in words[0] once sent; gripper: 3 words */
  int n_words;
  int address;          /* first register */
  int position, speed, force; /* gripper bytes */
} fg_robot_step;

#define FG_ROBOT_MAX_STEPS 4

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
  char code[40];         /* what went wrong when state is not done: "robot_timeout", ... */
  fg_motion_violation violation; /* the limit a plan refused (FG_ELIMIT); limit NULL else */
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

/* Where the position box comes from when [robot] sets none: fn fills the union of the
 * scenes' workspaces (world frame, metres) and returns 1, or returns 0 when there is no
 * scene. Called without the service's lock held, at each plan. Set before the first
 * command. */
typedef int (*fg_robot_workspace_fn)(void *ctx, double min_m[3], double max_m[3]);
void fg_robot_svc_set_workspace_source(fg_robot_svc *svc, fg_robot_workspace_fn fn, void *ctx);

/* Takes the motion keys of conf's [robot] (limits, speed, approach and retreat): at start
 * and at each reload; the next plan uses them. */
void fg_robot_svc_configure(fg_robot_svc *svc, const fg_conf *conf);

/* The limits in force now (the box from [robot] or from the scenes). */
void fg_robot_limits_get(fg_robot_svc *svc, fg_motion_limits *out);

/* The path defaults in force: approach and retreat distances (m) and the default speed. */
void fg_robot_path_defaults(fg_robot_svc *svc, double *approach_m, double *retreat_m,
                            double *speed_mps);

/* Whether [robot] / [gripper.modbus] are configured (transport != none). */
int fg_robot_svc_has_robot(const fg_robot_svc *svc);
int fg_robot_svc_has_gripper(const fg_robot_svc *svc);

/* Plans req into *v (steps and words; seq is the one the next command would get) without
 * sending anything: what a dry run returns. FG_ERANGE/FG_EINVAL with a detail for values
 * the encodings or the gripper cannot take; FG_ELIMIT (v->violation names the limit) for a
 * motion the limits refuse; FG_ESTOPPED while latched; FG_EUNAVAIL when the command needs
 * a peer that is not configured (the detail says which section to set). On FG_ELIMIT *v
 * still holds the steps planned so far. */
int fg_robot_plan(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v);

/* Plans and starts req, then waits until it is acknowledged (req->wait = 0) or finished,
 * and copies its record to *v. 0 when it ran (its outcome is in v->state and v->code), or:
 * the plan's errors, FG_EBUSY when another command is running (detail names it). */
int fg_robot_execute(fg_robot_svc *svc, const fg_robot_request *req, fg_robot_cmd_view *v);

/* Stops the robot: latches (with reason, a static or caller-kept text copied in), ends the
 * running command's wait as `stopped`, then writes the stop register and a no-op block on
 * the robot's worker and waits for that. *written is 1 when the robot got the stop word, 0
 * when it could not be written (the robot unreachable: the latch holds, and the word is
 * written when the robot is back); *stopped_id the command that was running, 0 if none. 0,
 * or FG_EUNAVAIL without a robot. */
int fg_robot_stop(fg_robot_svc *svc, const char *reason, int *written, uint64_t *stopped_id);

/* Clears the latch: writes 0 to the stop register first. 0; FG_EBUSY while a command runs;
 * FG_EUNAVAIL (the latch stays) when the robot cannot be reached; FG_EIO when the latch
 * file cannot be removed (the latch stays). */
int fg_robot_reset(fg_robot_svc *svc);

/* The latch for GET /v1/robot. */
typedef struct fg_robot_latch {
  int latched;
  char reason[512];
  double at_s;          /* CLOCK_REALTIME */
  uint64_t command;     /* the command that caused it, 0 for a stop with none running */
  int stop_written;     /* the stop register holds 1 (as far as the daemon knows) */
  int clear_pending;    /* the no-op block is still to be written */
} fg_robot_latch;

void fg_robot_latch_get(fg_robot_svc *svc, fg_robot_latch *out);

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

/* The TCP pose the robot reports ([robot] tcp_pose_base, proto/modbus.md). */
typedef struct fg_robot_tcp {
  int have;             /* a pose was read (since the start) */
  double p_m[3];        /* base frame, metres */
  double q_wxyz[4];
  int64_t read_ms;      /* CLOCK_REALTIME of that read */
  unsigned generation;  /* the connection it was read on */
  char error[256];      /* why the last read failed; "" when it did not */
} fg_robot_tcp;

/* The last pose read (at the idle poll, every second, and after each motion). */
void fg_robot_tcp_get(fg_robot_svc *svc, fg_robot_tcp *out);

/* Reads the pose now, for a frame taken at it: 0, or FG_EUNAVAIL (not_configured: no robot
 * or tcp_pose_base none; robot_disconnected), FG_EBUSY (robot_busy: a command is moving the
 * robot), FG_EPEER (modbus_exception; tcp_pose_invalid: the words are no pose),
 * FG_ETIMEDOUT (robot_timeout). The last good pose is kept on failure. */
int fg_robot_tcp_read(fg_robot_svc *svc, fg_robot_tcp *out);

/* The robot peer's state for GET /v1/robot. */
typedef struct fg_robot_state {
  fg_peer_view peer;
  int base;
  fg_pose_encoding encoding;
  uint16_t last_seq;     /* the last seq sent, 0 when none */
  int ack, status;       /* last read, -1 before any read */
  int busy;              /* a command is running */
  uint64_t last_command; /* id of the newest command, 0 when none */
  int tcp_pose_base;     /* -1: none */
  fg_robot_tcp tcp;
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
 * plan's errors otherwise, FG_EBUSY while a command or another action runs (the gripper
 * may be one of its steps). An activation (which opens the fingers fully) while the
 * gripper holds an object ends 409 gripper_holding unless req->allow_drop; an action
 * activates a gripper that is not activated only when it holds nothing. */
int fg_gripper_action(fg_robot_svc *svc, const char *action, const fg_robot_request *req,
                      fg_robot_cmd_view *v);

/* Appends Prometheus lines for both peers and the commands to buf (at most size bytes);
 * returns the length written. */
size_t fg_robot_metrics(fg_robot_svc *svc, char *buf, size_t size);

#endif
