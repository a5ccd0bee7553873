/* Small maths of the physics cell and its report (poses as MuJoCo keeps them: quaternions
 * w, x, y, z). */
#ifndef SIM_MATHS_H
#define SIM_MATHS_H

#include <math.h>

static inline double clampd(double x, double lo, double hi) {
  return x < lo ? lo : x > hi ? hi : x;
}

static inline void quat_from_rv(const double rv[3], double q[4]) {
  const double th = sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
  if (th < 1e-12) {
    q[0] = 1;
    q[1] = q[2] = q[3] = 0;
    return;
  }
  const double s = sin(th / 2) / th;
  q[0] = cos(th / 2);
  for (int k = 0; k < 3; k++) q[1 + k] = rv[k] * s;
}

/* The angle between two orientations, radians. */
static inline double quat_angle(const double a[4], const double b[4]) {
  double dot = fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
  return 2 * acos(clampd(dot, 0, 1));
}

/* The tool's +z of orientation q (w, x, y, z). */
static inline void quat_z(const double q[4], double z[3]) {
  z[0] = 2 * (q[1] * q[3] + q[0] * q[2]);
  z[1] = 2 * (q[2] * q[3] - q[0] * q[1]);
  z[2] = 1 - 2 * (q[1] * q[1] + q[2] * q[2]);
}

static inline double dist3(const double a[3], const double b[3]) {
  return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
              (a[2] - b[2]) * (a[2] - b[2]));
}

#endif
