/* Unit tests of lib/core/pose: compose and inverse, points, and the conversions between
 * quaternions, rotation matrices and rotation vectors, on many random rotations and at the
 * edges (angle near 0 and near pi). */
#include "test.h"

#include "core/error.h"
#include "core/pose.h"

#include <math.h>
#include <stdint.h>

#define N_RANDOM 2000

/* splitmix64: a reproducible stream without libc's rand. */
static uint64_t rng_state = 0x9e3779b97f4a7c15ull;
static double uniform(void) {
  uint64_t z = (rng_state += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  z ^= z >> 31;
  return (double)(z >> 11) * (1.0 / 9007199254740992.0); /* [0, 1) */
}

/* A uniformly random unit quaternion (Shoemake), either sign. */
static void random_quat(double q[4]) {
  double u1 = uniform(), u2 = 2 * M_PI * uniform(), u3 = 2 * M_PI * uniform();
  q[0] = sqrt(1 - u1) * sin(u2);
  q[1] = sqrt(1 - u1) * cos(u2);
  q[2] = sqrt(u1) * sin(u3);
  q[3] = sqrt(u1) * cos(u3);
}

static void random_pose(double T[16]) {
  double q[4], p[3] = {uniform() * 2 - 1, uniform() * 2 - 1, uniform() * 2 - 1};
  random_quat(q);
  ASSERT_OK(fg_pose_from_quat(p, q, T));
}

static double max_abs_diff(const double *a, const double *b, int n) {
  double m = 0;
  for (int i = 0; i < n; i++) m = fmax(m, fabs(a[i] - b[i]));
  return m;
}

/* |q_a . q_b| = 1: the same rotation (q and -q). */
static void assert_same_rotation_quat(const double q_a[4], const double q_b[4], double tol) {
  double dot = q_a[0] * q_b[0] + q_a[1] * q_b[1] + q_a[2] * q_b[2] + q_a[3] * q_b[3];
  ASSERT_NEAR(fabs(dot), 1.0, tol);
}

static void test_quat_rotmat_round_trip(void) {
  for (int i = 0; i < N_RANDOM; i++) {
    double q[4], R[9], q_back[4], R_back[9];
    random_quat(q);
    fg_rotmat_from_quat(q, R);
    /* R is a rotation: the pose built from it validates */
    double T[16], p0[3] = {0, 0, 0};
    fg_pose_from_rotmat(R, p0, T);
    ASSERT_OK(fg_pose_validate(T));
    fg_quat_from_rotmat(R, q_back);
    ASSERT(q_back[0] >= 0);
    assert_same_rotation_quat(q, q_back, 1e-12);
    fg_rotmat_from_quat(q_back, R_back);
    ASSERT(max_abs_diff(R, R_back, 9) < 1e-12);
    /* the 4x4 forms agree with the 3x3 ones */
    double p[3] = {0.1, -0.2, 0.3}, p_back[3], q4[4];
    ASSERT_OK(fg_pose_from_quat(p, q, T));
    double R_of_T[9];
    fg_pose_get_rotmat(T, R_of_T);
    ASSERT(max_abs_diff(R, R_of_T, 9) < 1e-15);
    fg_pose_to_quat(T, p_back, q4);
    ASSERT(max_abs_diff(p, p_back, 3) == 0);
    assert_same_rotation_quat(q, q4, 1e-12);
  }
}

static void test_rotvec_round_trip(void) {
  for (int i = 0; i < N_RANDOM; i++) {
    double q[4], r[3], q_back[4], R[9], r_from_R[3], R_from_r[9];
    random_quat(q);
    fg_rotvec_from_quat(q, r);
    double angle = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    ASSERT(angle <= M_PI + 1e-12);
    fg_quat_from_rotvec(r, q_back);
    assert_same_rotation_quat(q, q_back, 1e-12);
    fg_rotmat_from_quat(q, R);
    fg_rotvec_from_rotmat(R, r_from_R);
    /* away from a half turn the rotation vector is unique */
    if (angle < M_PI - 1e-6) ASSERT(max_abs_diff(r, r_from_R, 3) < 1e-9);
    fg_rotmat_from_rotvec(r, R_from_r);
    ASSERT(max_abs_diff(R, R_from_r, 9) < 1e-12);
    ASSERT_NEAR(fg_quat_angle_rad(q, q_back), 0.0, 1e-7);
  }
}

static void test_rotvec_edges(void) {
  /* identity, either sign */
  double id[4] = {1, 0, 0, 0}, nid[4] = {-1, 0, 0, 0}, r[3], q[4];
  fg_rotvec_from_quat(id, r);
  ASSERT(r[0] == 0 && r[1] == 0 && r[2] == 0);
  fg_rotvec_from_quat(nid, r);
  ASSERT(r[0] == 0 && r[1] == 0 && r[2] == 0);
  /* tiny angles: exact to first order, no 0/0 */
  for (double angle = 1e-15; angle < 1e-2; angle *= 10) {
    double rv[3] = {angle, -2 * angle, 0.5 * angle}, back[3], R[9];
    fg_quat_from_rotvec(rv, q);
    ASSERT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-15);
    fg_rotvec_from_quat(q, back);
    ASSERT(max_abs_diff(rv, back, 3) < 1e-15 + 1e-12 * angle);
    fg_rotmat_from_rotvec(rv, R);
    fg_rotvec_from_rotmat(R, back);
    ASSERT(max_abs_diff(rv, back, 3) < 1e-15);
  }
  /* a zero rotation vector */
  double zero[3] = {0, 0, 0};
  fg_quat_from_rotvec(zero, q);
  ASSERT(q[0] == 1 && q[1] == 0 && q[2] == 0 && q[3] == 0);
  /* half turns: |r| = pi about each axis and a diagonal, and just below */
  const double axes[4][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.6, -0.8, 0}};
  for (int a = 0; a < 4; a++) {
    for (double below = 0; below <= 1e-6; below += 1e-7) {
      double angle = M_PI - below, rv[3], back[3], R[9], R_back[9];
      for (int k = 0; k < 3; k++) rv[k] = axes[a][k] * angle;
      fg_rotmat_from_rotvec(rv, R);
      fg_rotvec_from_rotmat(R, back);
      ASSERT_NEAR(sqrt(back[0] * back[0] + back[1] * back[1] + back[2] * back[2]), angle, 1e-9);
      fg_rotmat_from_rotvec(back, R_back);
      ASSERT(fg_rotmat_angle_rad(R, R_back) < 1e-9);
      /* r and -r are the same half turn */
      if (below == 0) {
        for (int k = 0; k < 3; k++) back[k] = -rv[k];
        fg_rotmat_from_rotvec(back, R_back);
        ASSERT(fg_rotmat_angle_rad(R, R_back) < 1e-9);
      }
    }
  }
  /* the sign of a half-turn quaternion picks the sign of its rotation vector */
  double hx[4] = {0, 1, 0, 0}, hxn[4] = {0, -1, 0, 0};
  fg_rotvec_from_quat(hx, r);
  ASSERT_NEAR(r[0], M_PI, 1e-15);
  fg_rotvec_from_quat(hxn, r);
  ASSERT_NEAR(r[0], -M_PI, 1e-15);
}

static void test_compose_inverse(void) {
  double I[16];
  fg_pose_identity(I);
  for (int i = 0; i < N_RANDOM / 4; i++) {
    double T_a_b[16], T_b_c[16], T_a_c[16], T_b_a[16], T[16];
    random_pose(T_a_b);
    random_pose(T_b_c);
    /* T * T^-1 = T^-1 * T = I */
    fg_pose_inverse(T_a_b, T_b_a);
    fg_pose_compose(T_a_b, T_b_a, T);
    ASSERT(max_abs_diff(T, I, 16) < 1e-12);
    fg_pose_compose(T_b_a, T_a_b, T);
    ASSERT(max_abs_diff(T, I, 16) < 1e-12);
    /* (T^-1)^-1 = T; T * I = T */
    fg_pose_inverse(T_b_a, T);
    ASSERT(max_abs_diff(T, T_a_b, 16) < 1e-12);
    fg_pose_compose(T_a_b, I, T);
    ASSERT(max_abs_diff(T, T_a_b, 16) == 0);
    /* (T_a_b T_b_c)^-1 = T_b_c^-1 T_a_b^-1 */
    fg_pose_compose(T_a_b, T_b_c, T_a_c);
    ASSERT_OK(fg_pose_validate(T_a_c));
    double T_c_a[16], T_c_b[16], T2[16];
    fg_pose_inverse(T_a_c, T_c_a);
    fg_pose_inverse(T_b_c, T_c_b);
    fg_pose_compose(T_c_b, T_b_a, T2);
    ASSERT(max_abs_diff(T_c_a, T2, 16) < 1e-12);
    /* points: p_a = T_a_b (T_b_c p_c) = T_a_c p_c, and back through the inverse */
    double p_c[3] = {uniform(), uniform(), uniform()}, p_b[3], p_a[3], p_a2[3], p_back[3];
    fg_pose_apply(T_b_c, p_c, p_b);
    fg_pose_apply(T_a_b, p_b, p_a);
    fg_pose_apply(T_a_c, p_c, p_a2);
    ASSERT(max_abs_diff(p_a, p_a2, 3) < 1e-12);
    fg_pose_apply(T_c_a, p_a, p_back);
    ASSERT(max_abs_diff(p_c, p_back, 3) < 1e-12);
    /* quaternion of a composition = product of the quaternions */
    double p[3], q_a_b[4], q_b_c[4], q_a_c[4], q_prod[4];
    fg_pose_to_quat(T_a_b, p, q_a_b);
    fg_pose_to_quat(T_b_c, p, q_b_c);
    fg_pose_to_quat(T_a_c, p, q_a_c);
    fg_quat_multiply(q_a_b, q_b_c, q_prod);
    assert_same_rotation_quat(q_a_c, q_prod, 1e-12);
    /* directions ignore the translation */
    double v_b[3] = {1, 2, 3}, v_a[3], o[3] = {0, 0, 0}, o_a[3], tip_a[3];
    fg_pose_rotate(T_a_b, v_b, v_a);
    fg_pose_apply(T_a_b, o, o_a);
    fg_pose_apply(T_a_b, v_b, tip_a);
    for (int k = 0; k < 3; k++) ASSERT_NEAR(tip_a[k] - o_a[k], v_a[k], 1e-12);
  }
  /* n float points, in place as well */
  double T[16];
  random_pose(T);
  float pts[4 * 3] = {0, 0, 0, 1, 0, 0, 0, -1, 0.5f, 0.25f, 0.125f, -2};
  float out[4 * 3];
  fg_pose_apply_points(T, pts, 4, out);
  for (int i = 0; i < 4; i++) {
    double in[3] = {pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]}, want[3];
    fg_pose_apply(T, in, want);
    for (int k = 0; k < 3; k++) ASSERT_NEAR(out[3 * i + k], want[k], 1e-6);
  }
  fg_pose_apply_points(T, pts, 4, pts);
  for (int i = 0; i < 12; i++) ASSERT(pts[i] == out[i]);
}

static void test_angle(void) {
  double I[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  ASSERT(fg_rotmat_angle_rad(I, I) == 0);
  const double angles[] = {1e-9, 1e-4, 0.1, M_PI / 6, M_PI / 2, 2.0, M_PI - 1e-6, M_PI};
  for (size_t i = 0; i < sizeof angles / sizeof angles[0]; i++) {
    double rv[3] = {0, 0, angles[i]}, R[9];
    fg_rotmat_from_rotvec(rv, R);
    ASSERT_NEAR(fg_rotmat_angle_rad(I, R), angles[i], 1e-9 + 1e-12 * angles[i]);
    ASSERT_NEAR(fg_rotmat_angle_rad(R, I), angles[i], 1e-9 + 1e-12 * angles[i]);
  }
  /* 90 degrees about x against 90 degrees about y: 120 degrees apart */
  double qx[4] = {cos(M_PI / 4), sin(M_PI / 4), 0, 0}, qy[4] = {cos(M_PI / 4), 0, sin(M_PI / 4), 0};
  ASSERT_NEAR(fg_quat_angle_rad(qx, qy), 2 * M_PI / 3, 1e-12);
  /* q and -q: no angle */
  double qn[4] = {-qx[0], -qx[1], -qx[2], -qx[3]};
  ASSERT_NEAR(fg_quat_angle_rad(qx, qn), 0.0, 1e-12);
  /* invariant under a common rotation, equal to |rotvec| of the relative one */
  for (int i = 0; i < N_RANDOM / 4; i++) {
    double T_a[16], T_b[16], T_c[16], T_ca[16], T_cb[16], T_rel[16], T_a_inv[16], R_rel[9], r[3];
    random_pose(T_a);
    random_pose(T_b);
    random_pose(T_c);
    fg_pose_compose(T_c, T_a, T_ca);
    fg_pose_compose(T_c, T_b, T_cb);
    double angle = fg_pose_angle_rad(T_a, T_b);
    ASSERT(angle >= 0 && angle <= M_PI);
    ASSERT_NEAR(fg_pose_angle_rad(T_ca, T_cb), angle, 1e-9);
    fg_pose_inverse(T_a, T_a_inv);
    fg_pose_compose(T_a_inv, T_b, T_rel);
    fg_pose_get_rotmat(T_rel, R_rel);
    fg_rotvec_from_rotmat(R_rel, r);
    ASSERT_NEAR(sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]), angle, 1e-9);
  }
}

/* Slerp: the ends, the middle of a quarter turn, the shorter arc for -q, and constant speed. */
static void test_slerp(void) {
  const double I[4] = {1, 0, 0, 0}, qz[4] = {cos(M_PI / 4), 0, 0, sin(M_PI / 4)};
  const double qzn[4] = {-qz[0], -qz[1], -qz[2], -qz[3]};
  double q[4];
  fg_quat_slerp(I, qz, 0, q);
  ASSERT_NEAR(fg_quat_angle_rad(q, I), 0, 1e-12);
  fg_quat_slerp(I, qz, 1, q);
  ASSERT_NEAR(fg_quat_angle_rad(q, qz), 0, 1e-12);
  fg_quat_slerp(I, qzn, 0.5, q);
  ASSERT_NEAR(q[0], cos(M_PI / 8), 1e-12);
  ASSERT_NEAR(q[3], sin(M_PI / 8), 1e-12);
  for (int i = 0; i <= 10; i++) {
    fg_quat_slerp(I, qz, i / 10.0, q);
    ASSERT_NEAR(fg_quat_angle_rad(I, q), M_PI / 2 * i / 10.0, 1e-12);
  }
  /* nearly equal: still unit, and between them */
  const double qs[4] = {cos(1e-5), 0, sin(1e-5), 0};
  fg_quat_slerp(I, qs, 0.5, q);
  ASSERT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1, 1e-15);
  ASSERT_NEAR(fg_quat_angle_rad(I, q), 1e-5, 1e-9);
}

/* A camera looking at a point: z at it, x level, y with the world's down, roll about z. */
static void test_look_at(void) {
  const double eye[3] = {0.4, -0.3, 0.5}, target[3] = {0.5, 0.1, 0.02};
  double T[16], R[9], d[3], n = 0;
  for (int k = 0; k < 3; k++) d[k] = target[k] - eye[k], n += d[k] * d[k];
  n = sqrt(n);
  fg_pose_look_at(eye, target, 0, T);
  fg_pose_get_rotmat(T, R);
  for (int k = 0; k < 3; k++) {
    ASSERT_NEAR(T[4 * k + 3], eye[k], 0);
    ASSERT_NEAR(R[3 * k + 2], d[k] / n, 1e-12); /* z at the target */
  }
  ASSERT_NEAR(R[6], 0, 1e-15);  /* x level */
  ASSERT(R[7] < 0);             /* y has the world's down */
  double RtR = 0; /* orthonormal, right-handed */
  for (int a = 0; a < 3; a++)
    for (int b = 0; b < 3; b++) {
      double dot = 0;
      for (int k = 0; k < 3; k++) dot += R[3 * k + a] * R[3 * k + b];
      RtR = fmax(RtR, fabs(dot - (a == b)));
    }
  ASSERT(RtR < 1e-12);
  const double det = R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) +
                     R[2] * (R[3] * R[7] - R[4] * R[6]);
  ASSERT_NEAR(det, 1, 1e-12);
  /* rolled 30 degrees: the same z, x turned 30 degrees towards the unrolled y */
  double T2[16], R2[9];
  fg_pose_look_at(eye, target, M_PI / 6, T2);
  fg_pose_get_rotmat(T2, R2);
  double cx = 0, cz = 0;
  for (int k = 0; k < 3; k++) cx += R[3 * k] * R2[3 * k], cz += R[3 * k + 2] * R2[3 * k + 2];
  ASSERT_NEAR(cx, cos(M_PI / 6), 1e-12);
  ASSERT_NEAR(cz, 1, 1e-12);
  double xy = 0;
  for (int k = 0; k < 3; k++) xy += R2[3 * k] * R[3 * k + 1];
  ASSERT_NEAR(xy, sin(M_PI / 6), 1e-12);
  /* straight down: a heading all the same, still a rotation */
  const double above[3] = {0.5, 0.1, 0.6};
  fg_pose_look_at(above, target, 0, T);
  fg_pose_get_rotmat(T, R);
  ASSERT_NEAR(R[8], -1, 1e-12);
  ASSERT_NEAR(R[8] * (R[0] * R[4] - R[1] * R[3]), 1, 1e-12); /* det, with z straight down */
}

int main(void) {
  test_look_at();
  test_quat_rotmat_round_trip();
  test_rotvec_round_trip();
  test_rotvec_edges();
  test_compose_inverse();
  test_angle();
  test_slerp();
  printf("pose: ok\n");
  return 0;
}
