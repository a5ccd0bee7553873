#include "core/pose.h"
#include "core/error.h"

#include <math.h>
#include <string.h>

int fg_convention_parse(const char *name, fg_convention *out) {
  if (strcmp(name, "opengl") == 0) *out = FG_CONV_OPENGL;
  else if (strcmp(name, "opencv") == 0) *out = FG_CONV_OPENCV;
  else return fg_fail(FG_EINVAL, "convention must be \"opengl\" or \"opencv\", got \"%s\"", name);
  return 0;
}

const char *fg_convention_name(fg_convention c) { return c == FG_CONV_OPENCV ? "opencv" : "opengl"; }

int fg_pose_validate(const double T[16]) {
  for (int i = 0; i < 16; i++)
    if (!isfinite(T[i]))
      return fg_fail(FG_EINVAL, "matrix entry [%d][%d] is not a finite number", i / 4, i % 4);
  static const double last[4] = {0, 0, 0, 1};
  for (int j = 0; j < 4; j++)
    if (fabs(T[12 + j] - last[j]) > FG_POSE_ORTHO_TOL)
      return fg_fail(FG_EINVAL, "last row of the matrix must be [0, 0, 0, 1], entry %d is %g", j,
                     T[12 + j]);
  for (int a = 0; a < 3; a++) {
    for (int b = a; b < 3; b++) {
      double dot = 0;
      for (int k = 0; k < 3; k++) dot += T[k * 4 + a] * T[k * 4 + b];
      double want = a == b ? 1.0 : 0.0;
      if (fabs(dot - want) > FG_POSE_ORTHO_TOL)
        return fg_fail(FG_EINVAL,
                       "rotation part is not orthonormal: column %d . column %d = %.6f, expected %g "
                       "(tolerance %g); poses must be rigid, without scale",
                       a, b, dot, want, FG_POSE_ORTHO_TOL);
    }
  }
  double det = T[0] * (T[5] * T[10] - T[6] * T[9]) - T[1] * (T[4] * T[10] - T[6] * T[8]) +
               T[2] * (T[4] * T[9] - T[5] * T[8]);
  if (fabs(det - 1.0) > FG_POSE_ORTHO_TOL)
    return fg_fail(FG_EINVAL, "rotation part has determinant %.6f; a right-handed rotation has 1",
                   det);
  return 0;
}

void fg_pose_flip_yz(double T[16]) {
  for (int r = 0; r < 3; r++) {
    T[r * 4 + 1] = -T[r * 4 + 1];
    T[r * 4 + 2] = -T[r * 4 + 2];
  }
}

int fg_pose_from_quat(const double p[3], const double q[4], double T[16]) {
  double n = 0;
  for (int i = 0; i < 4; i++) {
    if (!isfinite(q[i])) return fg_fail(FG_EINVAL, "quaternion entry %d is not finite", i);
    n += q[i] * q[i];
  }
  for (int i = 0; i < 3; i++)
    if (!isfinite(p[i])) return fg_fail(FG_EINVAL, "position entry %d is not finite", i);
  n = sqrt(n);
  if (fabs(n - 1.0) > FG_POSE_ORTHO_TOL)
    return fg_fail(FG_EINVAL, "quaternion [w, x, y, z] must have unit length, its norm is %.6g",
                   n);
  double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
  double R[9] = {
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
    2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y),
  };
  memset(T, 0, 16 * sizeof *T);
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) T[r * 4 + c] = R[r * 3 + c];
    T[r * 4 + 3] = p[r];
  }
  T[15] = 1;
  return 0;
}

void fg_pose_to_quat(const double T[16], double p[3], double q[4]) {
  for (int i = 0; i < 3; i++) p[i] = T[i * 4 + 3];
  double m00 = T[0], m01 = T[1], m02 = T[2], m10 = T[4], m11 = T[5], m12 = T[6], m20 = T[8],
         m21 = T[9], m22 = T[10];
  double tr = m00 + m11 + m22;
  double w, x, y, z;
  if (tr > 0) {
    double s = sqrt(tr + 1.0) * 2;
    w = 0.25 * s, x = (m21 - m12) / s, y = (m02 - m20) / s, z = (m10 - m01) / s;
  } else if (m00 > m11 && m00 > m22) {
    double s = sqrt(1.0 + m00 - m11 - m22) * 2;
    w = (m21 - m12) / s, x = 0.25 * s, y = (m01 + m10) / s, z = (m02 + m20) / s;
  } else if (m11 > m22) {
    double s = sqrt(1.0 + m11 - m00 - m22) * 2;
    w = (m02 - m20) / s, x = (m01 + m10) / s, y = 0.25 * s, z = (m12 + m21) / s;
  } else {
    double s = sqrt(1.0 + m22 - m00 - m11) * 2;
    w = (m10 - m01) / s, x = (m02 + m20) / s, y = (m12 + m21) / s, z = 0.25 * s;
  }
  double n = sqrt(w * w + x * x + y * y + z * z);
  if (w < 0) n = -n;
  q[0] = w / n, q[1] = x / n, q[2] = y / n, q[3] = z / n;
}
