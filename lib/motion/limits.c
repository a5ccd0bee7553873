#include "motion/limits.h"

#include <math.h>
#include <stddef.h>

#include "core/error.h"
#include "core/pose.h"

static const double RAD_TO_DEG = 57.29577951308232;

/* The tool's +z axis in the world: the third column of R. */
static void tool_z(const double q_wxyz[4], double z[3]) {
  double R[9];
  fg_rotmat_from_quat(q_wxyz, R);
  z[0] = R[2];
  z[1] = R[5];
  z[2] = R[8];
}

void fg_motion_path(const double p[3], const double q_wxyz[4], double approach_m,
                    double retreat_m, fg_retreat_kind retreat, double pre[3], double after[3]) {
  double z[3];
  tool_z(q_wxyz, z);
  for (int i = 0; i < 3; i++) {
    pre[i] = p[i] - approach_m * z[i];
    after[i] = p[i];
    if (retreat == FG_RETREAT_BACK) after[i] -= retreat_m * z[i];
  }
  if (retreat == FG_RETREAT_UP) after[2] += retreat_m;
}

double fg_motion_approach_angle(const double q_wxyz[4]) {
  double z[3];
  tool_z(q_wxyz, z);
  const double c = -z[2];
  return acos(c > 1 ? 1 : c < -1 ? -1 : c);
}

static int refuse(fg_motion_violation *v, const char *limit, double value, double bound) {
  if (v) *v = (fg_motion_violation){limit, value, bound};
  return FG_ELIMIT;
}

/* Checks one point of the path against the box and the reach; name says which point. */
static int check_point(const fg_motion_limits *lim, const double p[3], const char *name,
                       fg_motion_violation *v) {
  static const char axes[] = "xyz";
  for (int i = 0; i < 3; i++) {
    if (!(p[i] >= lim->box_min_m[i] - 1e-9 && p[i] <= lim->box_max_m[i] + 1e-9)) {
      const double bound = p[i] < lim->box_min_m[i] ? lim->box_min_m[i] : lim->box_max_m[i];
      fg_fail(FG_ELIMIT, "the %s at (%.4f, %.4f, %.4f) m lies outside the robot's position "
              "box ([robot] limit_min .. limit_max: %c from %.4f to %.4f m; %c = %.4f m)",
              name, p[0], p[1], p[2], axes[i], lim->box_min_m[i], lim->box_max_m[i], axes[i],
              p[i]);
      return refuse(v, "position_box", p[i], bound);
    }
  }
  const double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
  if (lim->reach_m > 0 && !(r <= lim->reach_m + 1e-9)) {
    fg_fail(FG_ELIMIT, "the %s at (%.4f, %.4f, %.4f) m is %.4f m from the robot's base, "
            "beyond its reach ([robot] reach_m = %.4f m)", name, p[0], p[1], p[2], r,
            lim->reach_m);
    return refuse(v, "reach", r, lim->reach_m);
  }
  return 0;
}

int fg_motion_check_pose(const fg_motion_limits *lim, const double p_world_m[3],
                         const double q_wxyz[4], double approach_m, double retreat_m,
                         fg_retreat_kind retreat, fg_motion_violation *v) {
  if (v) *v = (fg_motion_violation){NULL, 0, 0};
  if (!lim->has_box) {
    fg_fail(FG_ELIMIT, "no position box is known, so no motion is allowed: declare a scene "
            "(its workspace, grown by [robot] limit_margin, is the box) or set [robot] "
            "limit_min and limit_max");
    return refuse(v, "position_box", NAN, NAN);
  }
  const double angle = fg_motion_approach_angle(q_wxyz);
  if (lim->cone_rad < M_PI && angle > lim->cone_rad + 1e-9) {
    fg_fail(FG_ELIMIT, "the tool's approach direction (+z) is %.1f degrees from straight "
            "down; [robot] approach_cone_deg allows %.1f", angle * RAD_TO_DEG,
            lim->cone_rad * RAD_TO_DEG);
    return refuse(v, "approach_cone", angle * RAD_TO_DEG, lim->cone_rad * RAD_TO_DEG);
  }
  double pre[3], after[3];
  fg_motion_path(p_world_m, q_wxyz, approach_m, retreat_m, retreat, pre, after);
  int rc = check_point(lim, p_world_m, "pose", v);
  if (rc == 0 && approach_m > 0) rc = check_point(lim, pre, "approach start (pre-grasp)", v);
  if (rc == 0 && retreat != FG_RETREAT_NONE && retreat_m > 0)
    rc = check_point(lim, after, "retreat end", v);
  return rc;
}

int fg_motion_check_values(const fg_motion_limits *lim, double force_n, double speed_mps,
                           double width_m, fg_motion_violation *v) {
  if (v) *v = (fg_motion_violation){NULL, 0, 0};
  if (force_n > lim->max_force_n) {
    fg_fail(FG_ELIMIT, "force = %g N exceeds [robot] max_force_n = %g N", force_n,
            lim->max_force_n);
    return refuse(v, "max_force", force_n, lim->max_force_n);
  }
  if (speed_mps > lim->max_speed_mps) {
    fg_fail(FG_ELIMIT, "speed = %g m/s exceeds [robot] max_speed_mps = %g m/s", speed_mps,
            lim->max_speed_mps);
    return refuse(v, "max_speed", speed_mps, lim->max_speed_mps);
  }
  if (width_m > lim->max_width_m + 1e-9) {
    fg_fail(FG_ELIMIT, "width = %g m exceeds the gripper's stroke of %g m", width_m,
            lim->max_width_m);
    return refuse(v, "width", width_m, lim->max_width_m);
  }
  return 0;
}
