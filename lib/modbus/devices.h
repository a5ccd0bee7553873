/* The two profiles of proto/modbus.md as operations on a link (link.h), run on the link's
 * thread: the robot's pose-registers handshake and the Robotiq 2F gripper's activation and
 * moves. Each returns 0 or a negative FG_E* code with a detail for the user. */
#ifndef FG_MODBUS_DEVICES_H
#define FG_MODBUS_DEVICES_H

#include <stdint.h>

#include "modbus/link.h"
#include "modbus/regs.h"

/* How often status registers are read while waiting: every 0.25 ms for the first
 * FG_MB_FAST_MS of a wait, then every FG_MB_POLL_MS. */
#define FG_MB_FAST_MS 10
#define FG_MB_POLL_MS 2

/* Returns 1 to stop a wait early (e.g. shutting down); checked at every poll. */
typedef int (*fg_mb_cancel_fn)(void *arg);

/* ---------------------------------------------------------------- robot */

typedef struct fg_robot_profile {
  int base;                  /* first holding register */
  fg_pose_encoding encoding;
  int ack_timeout_ms;        /* for ack = seq */
  int done_timeout_ms;       /* for status done / failed */
} fg_robot_profile;

/* Reads ack and status (one request). */
int fg_robot_read_ack(fg_mb_link *l, const fg_robot_profile *rp, uint16_t *ack, int *status);

/* Writes the words of one command (fg_pose_block_encode) in one function-16 request. */
int fg_robot_write(fg_mb_link *l, const fg_robot_profile *rp, const uint16_t *words);

/* Writes the stop register (proto/modbus.md): 1 halts the robot, 0 lets it run again. */
int fg_robot_write_stop(fg_mb_link *l, const fg_robot_profile *rp, int stop);

/* Polls until ack = seq: 0, FG_ETIMEDOUT ("no acknowledgement of seq N within T ms; ack is
 * A"), a link error, or FG_ECANCELED. *status is the status read with the ack. */
int fg_robot_wait_ack(fg_mb_link *l, const fg_robot_profile *rp, uint16_t seq, int *status,
                      fg_mb_cancel_fn cancel, void *cancel_arg);

/* Polls until status is done, failed or stopped (with ack still = seq): 0 with *status set,
 * FG_ETIMEDOUT, FG_EINVAL when the robot moved on to another seq, a link error or
 * FG_ECANCELED. */
int fg_robot_wait_done(fg_mb_link *l, const fg_robot_profile *rp, uint16_t seq, int *status,
                       fg_mb_cancel_fn cancel, void *cancel_arg);

/* Reads the TCP pose the robot reports at its six registers from base (regs.h, TCP pose):
 * metres and a rotation vector in radians, base frame. A link error, or FG_EPEER when the
 * words hold no pose. */
int fg_robot_read_tcp(fg_mb_link *l, int base, double p_m[3], double rotvec_rad[3]);

/* ---------------------------------------------------------------- gripper */

/* Reads the status words. */
int fg_gripper_read(fg_mb_link *l, fg_robotiq_status *s);

/* Reset, rACT = 1, then waits for gSTA = 3 within timeout_ms. FG_ETIMEDOUT or FG_EPEER
 * (a fault during activation) with the gripper's state in the detail. *s is the last status. */
int fg_gripper_activate(fg_mb_link *l, int timeout_ms, fg_robotiq_status *s);

/* Moves to position (0..255) at the speed and force bytes and waits until the echo matches
 * and the motion is over (gOBJ != 0), within timeout_ms. FG_EPEER for a fault (named),
 * FG_EBUSY when the gripper is not activated (gSTA != 3), FG_ETIMEDOUT. *s: last status. */
int fg_gripper_move(fg_mb_link *l, int position, int speed, int force, int timeout_ms,
                    fg_robotiq_status *s);

#endif
