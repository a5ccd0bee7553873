/* fieldgrip-sim's configuration (sim.c reads it from the command line) and what its parts
 * share: the time base (nanoseconds of the monotonic clock) and the Robotiq register
 * addresses. */
#ifndef FG_SIM_CONFIG_H
#define FG_SIM_CONFIG_H

#include <math.h>
#include <stdint.h>

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

static inline int64_t sim_ms_to_ns(double ms) { return (int64_t)llround(ms * 1e6); }

#endif
