/* The robot controller that fieldgrip-sim plays (robot.c): the robot block and the TCP that
 * its program moves. */
#ifndef FG_SIM_ROBOT_H
#define FG_SIM_ROBOT_H

#include <modbus.h>
#include <stdint.h>
#include <stdio.h>

#include "config.h"

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

#endif
