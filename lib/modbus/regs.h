/* Register maps of proto/modbus.md as plain encoders and decoders: the `pose-registers`
 * block a robot controller reads, and the Robotiq 2F gripper's request and status words.
 * No I/O here: link.h moves the words. */
#ifndef FG_MODBUS_REGS_H
#define FG_MODBUS_REGS_H

#include <stdint.h>

/* ---------------------------------------------------------------- pose-registers */

typedef enum { FG_POSE_INT16 = 0, FG_POSE_FLOAT32 = 1 } fg_pose_encoding;

typedef enum {
  FG_ROBOT_NOOP = 0,  /* acknowledge and do nothing: disarms a block left by a command whose
                       * outcome was not confirmed */
  FG_ROBOT_PICK = 1,  /* go to pose, close */
  FG_ROBOT_PLACE = 2, /* go to pose, open */
  FG_ROBOT_OPEN = 3,
  FG_ROBOT_CLOSE = 4,
  FG_ROBOT_MOVE = 5, /* move only */
} fg_robot_command;

/* Robot-written status word. Stopped: the stop register halted the command's motion. */
enum {
  FG_ROBOT_IDLE = 0,
  FG_ROBOT_BUSY = 1,
  FG_ROBOT_DONE = 2,
  FG_ROBOT_FAILED = 3,
  FG_ROBOT_STOPPED = 4
};

/* Words fieldgrip writes in one request (offsets 0 .. n-1); ack, status and the stop
 * register follow them. */
#define FG_POSE_WORDS_INT16 13
#define FG_POSE_WORDS_FLOAT32 23
#define FG_POSE_MAX_WORDS 23
#define FG_POSE_BLOCK_SPAN 26 /* registers of the whole float32 block: ack, status, stop too */

/* One command as the robot sees it. */
typedef struct fg_pose_block {
  uint16_t seq;         /* 1..65535 */
  int command;          /* fg_robot_command */
  double p_world_m[3];  /* TCP position, metres, world (robot base) frame */
  double rotvec_rad[3]; /* TCP orientation as a rotation vector, radians (core/pose.h) */
  double width_m;       /* opening before the approach, metres, >= 0 */
  int force_n;          /* newtons, 0..65535 */
  double approach_m;    /* pick/place/move: start this far back along the tool's -z and come
                         * in along +z; metres, >= 0 */
  double retreat_m;     /* after the tool action: pick lifts along world +z, place backs out
                         * along the tool's -z, by this much; metres, >= 0 (0: stay) */
  double speed_mps;     /* Cartesian speed of the TCP, m/s, > 0 (0 only in a no-op) */
} fg_pose_block;

/* Words of one command for encoding e: FG_POSE_WORDS_INT16 or FG_POSE_WORDS_FLOAT32. */
int fg_pose_block_words(fg_pose_encoding e);

/* Offset of `ack` from the base (13 or 23); `status` is the next register, then `stop`. */
int fg_pose_ack_offset(fg_pose_encoding e);

/* Offset of the `stop` register from the base (15 or 25): 1 halts the robot's motion and
 * keeps it from starting another command, 0 lets it run. */
int fg_pose_stop_offset(fg_pose_encoding e);

/* Encodes b into words[0 .. fg_pose_block_words(e)-1] (words has room for
 * FG_POSE_MAX_WORDS). Returns 0, or FG_ERANGE with a detail naming the field, its value and
 * its range when a value does not fit (never wraps or clamps), FG_EINVAL for seq 0, an
 * unknown command or a value that is not finite. words is unspecified on failure. */
int fg_pose_block_encode(const fg_pose_block *b, fg_pose_encoding e, uint16_t *words);

/* Decodes words (as written by fg_pose_block_encode) back into *b, for simulators and tests;
 * int16 values come back at their 0.1 mm / mrad resolution. */
void fg_pose_block_decode(const uint16_t *words, fg_pose_encoding e, fg_pose_block *b);

/* A quaternion becomes rotvec_rad with fg_rotvec_from_quat (core/pose.h). */

/* The sequence number after s: 1..65535, then 1 again; never 0. */
uint16_t fg_seq_next(uint16_t s);

/* IEEE 754 binary32 of v as two registers, high word first ("ABCD"), and back. */
void fg_float32_to_words(float v, uint16_t w[2]);
float fg_float32_from_words(const uint16_t w[2]);

/* ---------------------------------------------------------------- TCP pose (read back) */

/* Where the robot reports its TCP: six holding registers, as a Universal Robots controller's
 * Modbus server publishes them at 400-405: x y z in 0.1 mm, then rx ry rz (rotation vector)
 * in mrad, signed 16-bit, in the base frame. Read only. */
#define FG_TCP_POSE_BASE_DEFAULT 400
#define FG_TCP_POSE_WORDS 6

/* The pose (metres; rotation vector in radians) as the six words, rounded to the registers'
 * resolution: FG_ERANGE naming the value that does not fit, FG_EINVAL when one is not
 * finite. For simulators and tests. */
int fg_tcp_pose_encode(const double p_m[3], const double rotvec_rad[3], uint16_t w[6]);

/* The six words as a pose. FG_EPEER (reason tcp_pose_invalid) with a detail giving the
 * words when they are not a pose a controller reports: a rotation vector longer than pi by more than the registers'
 * rounding (a controller's is at most pi). */
int fg_tcp_pose_decode(const uint16_t w[6], double p_m[3], double rotvec_rad[3]);

/* ---------------------------------------------------------------- robotiq-2f */

#define FG_ROBOTIQ_REQUEST_ADDR 0x03E8
#define FG_ROBOTIQ_STATUS_ADDR 0x07D0
#define FG_ROBOTIQ_WORDS 3

/* A gripper model's ranges; bytes map linearly onto them (proto/modbus.md "Units"). */
typedef struct fg_robotiq_model {
  const char *name;
  double stroke_m;           /* width at position 0; position 255 is 0 m */
  double speed_min_mps, speed_max_mps; /* at speed byte 0 and 255 */
  double force_min_n, force_max_n;     /* at force byte 0 and 255 */
} fg_robotiq_model;

extern const fg_robotiq_model fg_robotiq_2f85, fg_robotiq_2f140;

/* Action request bits (high byte of the first request register). */
enum { FG_ROBOTIQ_ACT = 1 << 0, FG_ROBOTIQ_GTO = 1 << 3, FG_ROBOTIQ_ATR = 1 << 4 };

/* Request words: action bits, position 0..255, speed 0..255, force 0..255. */
void fg_robotiq_request(int action, int position, int speed, int force, uint16_t w[3]);

/* The status words, decoded. */
typedef struct fg_robotiq_status {
  int act, gto;  /* gACT, gGTO */
  int sta;       /* gSTA: 0 reset, 1 activating, 3 activated */
  int obj;       /* gOBJ: 0 moving, 1 contact opening, 2 contact closing, 3 at position */
  int flt, kflt; /* gFLT, kFLT */
  int echo;      /* gPR, the position request echoed */
  int position;  /* gPO, 0 open .. 255 closed */
  int current;   /* gCU, x 10 mA */
} fg_robotiq_status;

void fg_robotiq_status_decode(const uint16_t w[3], fg_robotiq_status *s);

/* gOBJ says the fingers stopped on an object (1 or 2). */
int fg_robotiq_object_detected(const fg_robotiq_status *s);

/* A fault's name for messages ("overcurrent"); "no fault" for 0, "fault 0xNN" otherwise
 * unknown (static storage per thread). */
const char *fg_robotiq_fault_name(int flt);

/* Width (metres) to position byte, speed (m/s) and force (N) to their bytes. FG_ERANGE with
 * a detail giving the model's range when the value lies outside it (or is not finite). */
int fg_robotiq_width_to_position(const fg_robotiq_model *m, double width_m, int *position);
int fg_robotiq_speed_to_byte(const fg_robotiq_model *m, double speed_mps, int *byte);
int fg_robotiq_force_to_byte(const fg_robotiq_model *m, double force_n, int *byte);

/* The width (metres) that position byte p stands for. */
double fg_robotiq_position_to_width(const fg_robotiq_model *m, int position);

#endif
