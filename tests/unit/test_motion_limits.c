/* Unit tests of lib/motion/limits: the path a command takes (pre-pose, retreat), the approach
 * angle, and which limit refuses what, with the value and the bound it reports. */
#include "test.h"

#include "core/error.h"
#include "motion/limits.h"

#include <math.h>
#include <stddef.h>

/* A tabletop box, approaches within 60 degrees of straight down, the 2F-85's numbers. */
static fg_motion_limits table(void) {
  return (fg_motion_limits){.has_box = 1,
                            .box_min_m = {0.1, -0.45, 0.0},
                            .box_max_m = {0.8, 0.45, 0.5},
                            .cone_rad = 60 * M_PI / 180,
                            .max_force_n = 235,
                            .max_speed_mps = 0.25,
                            .max_width_m = 0.085};
}

static const double k_down[4] = {0, 1, 0, 0}; /* a half turn about x: the tool's +z is -z */

static void test_path(void) {
  const double p[3] = {0.4, 0.1, 0.05};
  double pre[3], after[3];
  fg_motion_path(p, k_down, 0.1, 0.2, FG_RETREAT_UP, pre, after);
  ASSERT_NEAR(pre[2], 0.15, 1e-12); /* back along the tool's -z: up */
  ASSERT_NEAR(pre[0], 0.4, 1e-12);
  ASSERT_NEAR(after[2], 0.25, 1e-12); /* a pick lifts along world +z */
  /* a tool tilted 90 degrees (its +z along world +x): place backs out along world -x */
  const double q_x[4] = {cos(M_PI / 4), 0, sin(M_PI / 4), 0};
  fg_motion_path(p, q_x, 0.1, 0.05, FG_RETREAT_BACK, pre, after);
  ASSERT_NEAR(pre[0], 0.3, 1e-12);
  ASSERT_NEAR(after[0], 0.35, 1e-12);
  ASSERT_NEAR(after[2], 0.05, 1e-12);
  fg_motion_path(p, q_x, 0.1, 0.05, FG_RETREAT_UP, pre, after);
  ASSERT_NEAR(after[0], 0.4, 1e-12);
  ASSERT_NEAR(after[2], 0.10, 1e-12);
  ASSERT_NEAR(fg_motion_approach_angle(k_down), 0, 1e-9);
  ASSERT_NEAR(fg_motion_approach_angle(q_x), M_PI / 2, 1e-9);
  const double up[4] = {1, 0, 0, 0};
  ASSERT_NEAR(fg_motion_approach_angle(up), M_PI, 1e-9);
}

static void test_pose_limits(void) {
  const fg_motion_limits lim = table();
  fg_motion_violation v;
  const double ok[3] = {0.4, 0.0, 0.05};
  ASSERT_OK(fg_motion_check_pose(&lim, ok, k_down, 0.1, 0.1, FG_RETREAT_UP, &v));
  ASSERT(v.limit == NULL);

  /* the pose itself outside: the value is the coordinate, the bound the face it crossed */
  const double far[3] = {3.2, -3.2, -2.5};
  ASSERT_ERR(fg_motion_check_pose(&lim, far, k_down, 0, 0, FG_RETREAT_NONE, &v), FG_ELIMIT,
             "position box");
  ASSERT_STREQ(v.limit, "position_box");
  ASSERT_NEAR(v.value, 3.2, 1e-12);
  ASSERT_NEAR(v.bound, 0.8, 1e-12);

  /* inside, but its approach starts above the box's top */
  const double high[3] = {0.4, 0.0, 0.45};
  ASSERT_ERR(fg_motion_check_pose(&lim, high, k_down, 0.1, 0, FG_RETREAT_NONE, &v), FG_ELIMIT,
             "approach start");
  ASSERT_NEAR(v.value, 0.55, 1e-12);
  /* or its retreat ends there */
  ASSERT_ERR(fg_motion_check_pose(&lim, high, k_down, 0, 0.1, FG_RETREAT_UP, &v), FG_ELIMIT,
             "retreat end");
  /* below the floor of the box */
  const double low[3] = {0.4, 0.0, -0.3};
  ASSERT_ERR(fg_motion_check_pose(&lim, low, k_down, 0, 0, FG_RETREAT_NONE, &v), FG_ELIMIT,
             "z = -0.3000");

  /* the cone: 60 degrees passes, 61 does not, from below never */
  const double a60 = 60 * M_PI / 180, a61 = 61 * M_PI / 180;
  /* a rotation by pi - a about x turns +z to (0, -sin, cos(pi - a)) = a from straight down */
  const double q60[4] = {cos((M_PI - a60) / 2), sin((M_PI - a60) / 2), 0, 0};
  const double q61[4] = {cos((M_PI - a61) / 2), sin((M_PI - a61) / 2), 0, 0};
  ASSERT_NEAR(fg_motion_approach_angle(q60), a60, 1e-9);
  ASSERT_OK(fg_motion_check_pose(&lim, ok, q60, 0, 0, FG_RETREAT_NONE, &v));
  ASSERT_ERR(fg_motion_check_pose(&lim, ok, q61, 0, 0, FG_RETREAT_NONE, &v), FG_ELIMIT,
             "61.0 degrees");
  ASSERT_STREQ(v.limit, "approach_cone");
  ASSERT_NEAR(v.value, 61, 1e-6);
  ASSERT_NEAR(v.bound, 60, 1e-9);
  fg_motion_limits any = lim;
  any.cone_rad = M_PI;
  const double up[4] = {1, 0, 0, 0};
  ASSERT_OK(fg_motion_check_pose(&any, ok, up, 0, 0, FG_RETREAT_NONE, &v));

  /* a reach: each point of the path within it of the base's origin */
  fg_motion_limits reach = lim;
  reach.reach_m = 0.45;
  ASSERT_OK(fg_motion_check_pose(&reach, ok, k_down, 0.1, 0.1, FG_RETREAT_UP, &v));
  const double edge[3] = {0.45, 0.0, 0.05}; /* 0.4528 m out */
  ASSERT_ERR(fg_motion_check_pose(&reach, edge, k_down, 0, 0, FG_RETREAT_NONE, &v), FG_ELIMIT,
             "beyond its reach");
  ASSERT_STREQ(v.limit, "reach");
  ASSERT_NEAR(v.value, sqrt(0.45 * 0.45 + 0.05 * 0.05), 1e-12);
  ASSERT_NEAR(v.bound, 0.45, 1e-12);
  /* the pose within it, its approach's start (0.15 m up) not */
  const double near[3] = {0.40, 0.0, 0.10};
  ASSERT_OK(fg_motion_check_pose(&reach, near, k_down, 0, 0, FG_RETREAT_NONE, &v));
  ASSERT_ERR(fg_motion_check_pose(&reach, near, k_down, 0.15, 0, FG_RETREAT_NONE, &v),
             FG_ELIMIT, "approach start");
  ASSERT_STREQ(v.limit, "reach");

  /* no box known: nothing moves */
  fg_motion_limits none = lim;
  none.has_box = 0;
  ASSERT_ERR(fg_motion_check_pose(&none, ok, k_down, 0, 0, FG_RETREAT_NONE, &v), FG_ELIMIT,
             "no position box");
  ASSERT_STREQ(v.limit, "position_box");
}

static void test_value_limits(void) {
  const fg_motion_limits lim = table();
  fg_motion_violation v;
  ASSERT_OK(fg_motion_check_values(&lim, -1, -1, -1, &v));
  ASSERT_OK(fg_motion_check_values(&lim, 235, 0.25, 0.085, &v));
  ASSERT_ERR(fg_motion_check_values(&lim, 65535, -1, -1, &v), FG_ELIMIT, "force = 65535 N");
  ASSERT_STREQ(v.limit, "max_force");
  ASSERT_NEAR(v.bound, 235, 0);
  ASSERT_ERR(fg_motion_check_values(&lim, -1, 0.3, -1, &v), FG_ELIMIT, "max_speed_mps");
  ASSERT_STREQ(v.limit, "max_speed");
  ASSERT_ERR(fg_motion_check_values(&lim, -1, -1, 0.1, &v), FG_ELIMIT, "stroke");
  ASSERT_STREQ(v.limit, "width");
  ASSERT_NEAR(v.value, 0.1, 0);
}

int main(void) {
  test_path();
  test_pose_limits();
  test_value_limits();
  printf("motion_limits: ok\n");
  return 0;
}
