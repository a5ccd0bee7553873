/* What the robot may be asked to do: the motion limits every command, gripper action, grasp
 * execution and scan passes before a word reaches the robot, and that grasp search applies
 * to the poses it returns. No I/O: the daemon's robot service holds one fg_motion_limits and
 * checks each planned command with these functions.
 *
 * A pose is the TCP's (SPEC.md's gripper frame: +z the approach direction, from the palm
 * towards the object) in the world (robot base) frame, metres. The robot program of
 * proto/modbus.md reaches it along a path of three points, all of which must lie in the
 * position box:
 *   pre-pose  = the pose moved back along the tool's -z by approach_m,
 *   pose,
 *   retreat   = after a pick the pose lifted along world +z by retreat_m; after a place
 *               the pose moved back along the tool's -z by retreat_m.
 * With a reach, each of them must also lie within reach_m of the base frame's origin.
 * The approach cone bounds the angle between the tool's +z and straight down (world -z):
 * 0 admits only vertical approaches from above, pi/2 horizontal ones too, and anything
 * beyond pi/2 comes from below. */
#ifndef FG_MOTION_LIMITS_H
#define FG_MOTION_LIMITS_H

typedef struct fg_motion_limits {
  int has_box;           /* 0: no position box is known; every pose is refused */
  double box_min_m[3];   /* TCP positions allowed, world frame, metres (inclusive) */
  double box_max_m[3];
  double reach_m;        /* > 0: TCP positions within this of the base frame's origin (the
                          * arm's reach); 0: not checked */
  double cone_rad;       /* tool +z within this of world -z; >= pi admits every direction */
  double max_force_n;    /* grip or contact force, newtons */
  double max_speed_mps;  /* TCP speed, m/s */
  double max_width_m;    /* gripper opening (the model's stroke), metres */
} fg_motion_limits;

/* Where the path of a command ends after its tool action. */
typedef enum {
  FG_RETREAT_NONE = 0,   /* move: no retreat */
  FG_RETREAT_UP,         /* pick: along world +z */
  FG_RETREAT_BACK,       /* place: back along the tool's -z */
} fg_retreat_kind;

/* A refusal: which limit, the offending value and the bound, for the error's JSON. */
typedef struct fg_motion_violation {
  const char *limit;     /* "position_box", "reach", "approach_cone", "max_force", "max_speed",
                          * "width", or NULL when nothing was violated */
  double value, bound;   /* in the limit's unit: m, degrees, N, m/s, m */
} fg_motion_violation;

/* The pre-pose and the retreat point of a path (metres, world), as described above. */
void fg_motion_path(const double p_world_m[3], const double q_wxyz[4], double approach_m,
                    double retreat_m, fg_retreat_kind retreat, double pre_m[3],
                    double after_m[3]);

/* Angle (radians, 0..pi) between the tool's +z of rotation q_wxyz and straight down. */
double fg_motion_approach_angle(const double q_wxyz[4]);

/* Checks the path of a pose (pre-pose, pose, retreat point) against the position box and
 * the pose's direction against the cone. 0, or FG_ELIMIT with a detail naming the limit,
 * the point, its value and the bound, and *v filled (v may be NULL). */
int fg_motion_check_pose(const fg_motion_limits *lim, const double p_world_m[3],
                         const double q_wxyz[4], double approach_m, double retreat_m,
                         fg_retreat_kind retreat, fg_motion_violation *v);

/* Checks a force (N), a speed (m/s) and a width (m) against their limits; a negative value
 * stands for "not given" and passes. 0 or FG_ELIMIT with a detail and *v (may be NULL). */
int fg_motion_check_values(const fg_motion_limits *lim, double force_n, double speed_mps,
                           double width_m, fg_motion_violation *v);

#endif
