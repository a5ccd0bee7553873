/* fieldgrip-sim's shared state (sim.c): the configuration, the robot block that the robot
 * program reads (robot.c) and the Robotiq gripper (gripper.c). Times are nanoseconds of the
 * monotonic clock. */
#ifndef FG_SIM_H
#define FG_SIM_H

#include <math.h>
#include <modbus.h>
#include <stdint.h>
#include <stdio.h>

#include "camera.h"
#include "cell.h"

#define SIM_NEVER INT64_MAX

/* Robotiq register addresses (proto/modbus.md "Profile robotiq-2f"). */
#define SIM_RQ_OUT 0x03E8
#define SIM_RQ_IN 0x07D0
#define SIM_RQ_FLT_NOT_ACTIVATED 0x07
#define SIM_RQ_FLT_ACTION_DELAYED 0x05

typedef struct {
  char host[256];          /* without brackets; "" = any address */
  int ipv6;                /* host was given as [v6] */
  char service[8];         /* port as text, "0" = pick a free one */
  const char *port_file;   /* NULL: none */
  const char *log_path;    /* NULL: no request log */
  const char *events_path; /* NULL: no log of the robot's motions and stops */
  double time_scale;       /* motions take their length / speed times this (default 1) */
  int robot_unit, gripper_unit;
  int base;                /* first holding register of the robot block */
  int tcp_base;            /* first of the six TCP pose registers (regs.h); -1: none */
  int float32;             /* 0 int16 layout (12 registers), 1 float32 layout (19) */
  int ack_init;
  int ack_delay_ms, done_delay_ms;
  int never_ack, fail;
  int exception;           /* 0 none, else the exception code for robot-block writes */
  long drop_after;         /* 0 none, else the 1-based request number to drop */
  int activation_ms, stroke_ms;
  double object_width_mm;  /* < 0: no object */
  double stroke_mm;
  const char *rtu_device;  /* also serve the gripper unit on this serial line; NULL: none */
  const char *report_path; /* the physics cell's report; NULL: none */
  sim_cell_config cell;    /* cell.scene_path != NULL: the physics mode */
  sim_camera_config camera; /* camera.on: the camera on the tool (physics mode only) */
} sim_config;

/* The robot block, its pending acknowledgement, and the TCP that the robot program moves:
 * along a straight path from where it is to the pre-pose (approach back along the tool's -z),
 * down to the pose, then to the retreat point, at the block's speed. */
typedef struct {
  modbus_mapping_t *map;   /* holding registers base .. base + n_regs - 1 */
  int n_regs, ack_off, status_off, stop_off;
  int pending;             /* an acknowledgement of pending_seq is scheduled */
  uint16_t pending_seq;
  int64_t ack_due_ns;      /* SIM_NEVER when none */
  int64_t done_due_ns;     /* SIM_NEVER when none */
  int stopped;             /* the stop register holds 1 */
  modbus_mapping_t *tcp_map; /* the TCP pose registers, or NULL */
  double tcp[3];           /* TCP position (metres) when not moving */
  double q[4];             /* TCP orientation (w, x, y, z) when not moving */
  double q0[4], qt[4];     /* the motion's: from, to (turned along the way to its first
                            * waypoint) */
  double way[4][3];        /* the path of the command in progress */
  int n_way;
  int moving;              /* between the ack and done_due_ns */
  int64_t move_t0_ns;      /* the motion's start (the ack) */
  double speed_mps;
  uint16_t seq;            /* the command in progress */
  FILE *log;               /* the request log, or NULL */
  sim_cell *cell;          /* the physics mode's cell, or NULL */
} sim_robot;

/* The gripper: status bits, finger position and the motion in progress. */
typedef struct {
  modbus_mapping_t *map;   /* holding 0x03E8..0x03EA, input 0x07D0..0x07D2 */
  int act, gto, sta, obj, flt, pr, cu;
  double pos;              /* finger position, 0 open .. 255 closed, when not moving */
  int64_t act_due_ns;      /* end of the activation in progress; SIM_NEVER when none */
  int moving;              /* a motion from p0 (at t0_ns) toward stop is in progress */
  int contact;             /* the motion ends on the object */
  int force;               /* rFR of the motion in progress */
  int64_t t0_ns, arrive_ns;
  double p0, stop;
  double rate;             /* position units per ms */
  int obj_pos;             /* finger position at the object; -1 without an object */
  sim_cell *cell;          /* the physics mode's cell (which moves the fingers), or NULL */
} sim_gripper;

static inline int64_t sim_ms_to_ns(double ms) { return (int64_t)llround(ms * 1e6); }

/* The robot block (robot.c): its registers, then before every request sim_robot_advance to
 * now; sim_robot_on_write after a write that reached the block. 0, or -1 out of memory. */
int sim_robot_init(sim_robot *r, const sim_config *cfg);
void sim_robot_advance(sim_robot *r, const sim_config *cfg, int64_t now);
void sim_robot_on_write(sim_robot *r, const sim_config *cfg, int64_t now);

/* The TCP pose now (moving or not; the hand's in the physics mode), and the TCP pose
 * registers set to it before they are read. */
void sim_robot_tcp_pose(const sim_robot *r, const sim_config *cfg, int64_t now, double p[3],
                        double q[4]);
void sim_robot_publish_tcp(sim_robot *r, const sim_config *cfg, int64_t now);

/* The gripper (gripper.c), the same way; sim_gripper_publish writes its status registers. */
int sim_gripper_init(sim_gripper *g, const sim_config *cfg);
void sim_gripper_advance(sim_gripper *g, const sim_config *cfg, int64_t now);
void sim_gripper_on_write(sim_gripper *g, const sim_config *cfg, int64_t now);
void sim_gripper_publish(sim_gripper *g, int64_t now);

#endif
