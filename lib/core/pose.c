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
  double R[9];
  fg_rotmat_from_quat(q, R);
  fg_pose_from_rotmat(R, p, T);
  return 0;
}

void fg_pose_to_quat(const double T[16], double p[3], double q[4]) {
  double R[9];
  fg_pose_get_rotmat(T, R);
  for (int i = 0; i < 3; i++) p[i] = T[i * 4 + 3];
  fg_quat_from_rotmat(R, q);
}

/* ---------------------------------------------------------------- rigid transforms */

void fg_pose_identity(double T[16]) {
  memset(T, 0, 16 * sizeof *T);
  T[0] = T[5] = T[10] = T[15] = 1;
}

void fg_pose_compose(const double T_a_b[16], const double T_b_c[16], double T_a_c[16]) {
  double out[16];
  for (int r = 0; r < 4; r++)
    for (int c = 0; c < 4; c++) {
      double sum = 0;
      for (int k = 0; k < 4; k++) sum += T_a_b[r * 4 + k] * T_b_c[k * 4 + c];
      out[r * 4 + c] = sum;
    }
  memcpy(T_a_c, out, sizeof out);
}

void fg_pose_inverse(const double T_a_b[16], double T_b_a[16]) {
  double out[16];
  for (int r = 0; r < 3; r++) {
    double t = 0;
    for (int c = 0; c < 3; c++) {
      out[r * 4 + c] = T_a_b[c * 4 + r];
      t -= T_a_b[c * 4 + r] * T_a_b[c * 4 + 3];
    }
    out[r * 4 + 3] = t;
  }
  out[12] = out[13] = out[14] = 0;
  out[15] = 1;
  memcpy(T_b_a, out, sizeof out);
}

void fg_pose_apply(const double T_a_b[16], const double p_b[3], double p_a[3]) {
  double out[3];
  for (int r = 0; r < 3; r++)
    out[r] = T_a_b[r * 4] * p_b[0] + T_a_b[r * 4 + 1] * p_b[1] + T_a_b[r * 4 + 2] * p_b[2] +
             T_a_b[r * 4 + 3];
  memcpy(p_a, out, sizeof out);
}

void fg_pose_apply_points(const double T_a_b[16], const float *p_b, size_t n, float *p_a) {
  for (size_t i = 0; i < n; i++) {
    double in[3] = {p_b[3 * i], p_b[3 * i + 1], p_b[3 * i + 2]}, out[3];
    fg_pose_apply(T_a_b, in, out);
    for (int k = 0; k < 3; k++) p_a[3 * i + k] = (float)out[k];
  }
}

void fg_pose_rotate(const double T_a_b[16], const double v_b[3], double v_a[3]) {
  double out[3];
  for (int r = 0; r < 3; r++)
    out[r] = T_a_b[r * 4] * v_b[0] + T_a_b[r * 4 + 1] * v_b[1] + T_a_b[r * 4 + 2] * v_b[2];
  memcpy(v_a, out, sizeof out);
}

void fg_pose_get_rotmat(const double T_a_b[16], double R_a_b[9]) {
  double out[9];
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) out[r * 3 + c] = T_a_b[r * 4 + c];
  memcpy(R_a_b, out, sizeof out);
}

void fg_pose_from_rotmat(const double R_a_b[9], const double p_a[3], double T_a_b[16]) {
  double out[16];
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) out[r * 4 + c] = R_a_b[r * 3 + c];
    out[r * 4 + 3] = p_a[r];
  }
  out[12] = out[13] = out[14] = 0;
  out[15] = 1;
  memcpy(T_a_b, out, sizeof out);
}

void fg_pose_look_at(const double eye[3], const double target[3], double roll_rad, double T[16]) {
  double z[3], x[3], y[3], n = 0;
  for (int k = 0; k < 3; k++) {
    z[k] = target[k] - eye[k];
    n += z[k] * z[k];
  }
  for (int k = 0; k < 3; k++) z[k] /= sqrt(n);
  x[0] = z[1], x[1] = -z[0], x[2] = 0; /* z x (0, 0, 1) */
  n = hypot(x[0], x[1]);
  if (n < 1e-9) /* straight up or down: any heading will do */
    x[0] = 0, x[1] = -1, n = 1;
  x[0] /= n, x[1] /= n;
  y[0] = z[1] * x[2] - z[2] * x[1];
  y[1] = z[2] * x[0] - z[0] * x[2];
  y[2] = z[0] * x[1] - z[1] * x[0];
  const double c = cos(roll_rad), s = sin(roll_rad);
  double R[9];
  for (int r = 0; r < 3; r++) {
    R[3 * r] = c * x[r] + s * y[r];
    R[3 * r + 1] = -s * x[r] + c * y[r];
    R[3 * r + 2] = z[r];
  }
  fg_pose_from_rotmat(R, eye, T);
}

/* ---------------------------------------------------------------- rotations */

void fg_rotmat_from_quat(const double q[4], double R[9]) {
  double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(n > 0)) n = 1;
  double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
  const double out[9] = {
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
    2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y),
  };
  memcpy(R, out, sizeof out);
}

void fg_quat_from_rotmat(const double R[9], double q[4]) {
  double m00 = R[0], m01 = R[1], m02 = R[2], m10 = R[3], m11 = R[4], m12 = R[5], m20 = R[6],
         m21 = R[7], m22 = R[8];
  double trace = m00 + m11 + m22;
  double w, x, y, z;
  if (trace > 0) {
    double s = sqrt(trace + 1.0) * 2;
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

void fg_rotvec_from_quat(const double q_wxyz[4], double rotvec_rad[3]) {
  const double s = q_wxyz[0] < 0 ? -1.0 : 1.0;
  const double w = s * q_wxyz[0], x = s * q_wxyz[1], y = s * q_wxyz[2], z = s * q_wxyz[3];
  const double n = sqrt(x * x + y * y + z * z);
  /* angle / n, with its small-angle limit 2 / w (w is then close to 1) */
  const double k = n > 1e-12 ? 2.0 * atan2(n, w) / n : 2.0 / (w > 0 ? w : 1.0);
  rotvec_rad[0] = k * x;
  rotvec_rad[1] = k * y;
  rotvec_rad[2] = k * z;
}

void fg_quat_from_rotvec(const double rotvec_rad[3], double q_wxyz[4]) {
  const double angle = sqrt(rotvec_rad[0] * rotvec_rad[0] + rotvec_rad[1] * rotvec_rad[1] +
                            rotvec_rad[2] * rotvec_rad[2]);
  /* sin(angle / 2) / angle, with its series below 1e-4 rad (error < 1e-17) */
  const double k = angle > 1e-4 ? sin(0.5 * angle) / angle : 0.5 - angle * angle / 48.0;
  const double out[4] = {cos(0.5 * angle), k * rotvec_rad[0], k * rotvec_rad[1],
                         k * rotvec_rad[2]};
  memcpy(q_wxyz, out, sizeof out);
}

void fg_rotmat_from_rotvec(const double rotvec_rad[3], double R[9]) {
  double q[4];
  fg_quat_from_rotvec(rotvec_rad, q);
  fg_rotmat_from_quat(q, R);
}

void fg_rotvec_from_rotmat(const double R[9], double rotvec_rad[3]) {
  double q[4];
  fg_quat_from_rotmat(R, q);
  fg_rotvec_from_quat(q, rotvec_rad);
}

void fg_quat_multiply(const double a[4], const double b[4], double q_a_c[4]) {
  const double out[4] = {
    a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
    a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
    a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
    a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
  };
  memcpy(q_a_c, out, sizeof out);
}

void fg_quat_slerp(const double a[4], const double b0[4], double s, double out[4]) {
  double b[4], dot = 0;
  for (int k = 0; k < 4; k++) dot += a[k] * b0[k];
  for (int k = 0; k < 4; k++) b[k] = dot < 0 ? -b0[k] : b0[k];
  dot = fabs(dot);
  double wa = 1 - s, wb = s;
  if (dot < 0.9995) { /* nearer, the linear blend renormalised is as accurate */
    const double th = acos(dot), st = sin(th);
    wa = sin((1 - s) * th) / st;
    wb = sin(s * th) / st;
  }
  double n = 0;
  for (int k = 0; k < 4; k++) {
    out[k] = wa * a[k] + wb * b[k];
    n += out[k] * out[k];
  }
  n = sqrt(n);
  for (int k = 0; k < 4; k++) out[k] /= n;
}

double fg_quat_angle_rad(const double q_a[4], const double q_b[4]) {
  /* the relative rotation conj(q_a) * q_b; 2 atan2(|v|, |w|) stays accurate at 0 and pi,
   * where acos of the dot product loses half the digits */
  double na = sqrt(q_a[0] * q_a[0] + q_a[1] * q_a[1] + q_a[2] * q_a[2] + q_a[3] * q_a[3]);
  double nb = sqrt(q_b[0] * q_b[0] + q_b[1] * q_b[1] + q_b[2] * q_b[2] + q_b[3] * q_b[3]);
  if (!(na > 0)) na = 1;
  if (!(nb > 0)) nb = 1;
  const double conj_a[4] = {q_a[0] / na, -q_a[1] / na, -q_a[2] / na, -q_a[3] / na};
  const double unit_b[4] = {q_b[0] / nb, q_b[1] / nb, q_b[2] / nb, q_b[3] / nb};
  double rel[4];
  fg_quat_multiply(conj_a, unit_b, rel);
  double v = sqrt(rel[1] * rel[1] + rel[2] * rel[2] + rel[3] * rel[3]);
  return 2.0 * atan2(v, fabs(rel[0]));
}

double fg_rotmat_angle_rad(const double R_a[9], const double R_b[9]) {
  double q_a[4], q_b[4];
  fg_quat_from_rotmat(R_a, q_a);
  fg_quat_from_rotmat(R_b, q_b);
  return fg_quat_angle_rad(q_a, q_b);
}

double fg_pose_angle_rad(const double T_a[16], const double T_b[16]) {
  double R_a[9], R_b[9];
  fg_pose_get_rotmat(T_a, R_a);
  fg_pose_get_rotmat(T_b, R_b);
  return fg_rotmat_angle_rad(R_a, R_b);
}
