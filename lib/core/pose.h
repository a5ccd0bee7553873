/* Rigid poses in the world (robot base) frame: metres, right-handed, +z up. The one home of
 * pose math: every module that composes, inverts, applies or converts poses calls this.
 *
 * A pose is a 4x4 row-major double matrix T_a_b that maps points from frame b to frame a
 * (p_a = T_a_b * p_b); its rotation R_a_b is the 3x3 row-major top-left block. Names carry
 * their frames: T_world_gripper * T_gripper_cam = T_world_cam. Quaternions are [w, x, y, z],
 * unit, scalar first (SPEC.md); a rotation vector is axis * angle in radians. Every function
 * allows its output to alias an input unless it says otherwise. */
#ifndef FG_CORE_POSE_H
#define FG_CORE_POSE_H

#include <stddef.h>

/* Largest |R^T R - I| entry and |det R - 1| accepted as a rotation. */
#define FG_POSE_ORTHO_TOL 1e-3

/* Camera axis conventions of a camera-to-world matrix. */
typedef enum {
  FG_CONV_OPENGL = 0, /* +x right, +y up, looks along -z (nerfstudio, instant-ngp) */
  FG_CONV_OPENCV = 1, /* +x right, +y down, looks along +z */
} fg_convention;

/* Parses "opengl" or "opencv"; FG_EINVAL with a detail otherwise. */
int fg_convention_parse(const char *name, fg_convention *out);
const char *fg_convention_name(fg_convention c);

/* Checks that T is finite, its last row is [0 0 0 1] (within the tolerance) and its
 * rotation is orthonormal and right-handed within FG_POSE_ORTHO_TOL. FG_EINVAL with a
 * detail naming the first problem. */
int fg_pose_validate(const double T[16]);

/* Rewrites a camera-to-world matrix of the OpenCV convention into the OpenGL one, in place
 * (negates the camera's y and z axes). Its own inverse. */
void fg_pose_flip_yz(double T_world_cam[16]);

/* Builds T from a position (metres) and a unit quaternion [w,x,y,z]. A norm within
 * FG_POSE_ORTHO_TOL of 1 is rounding and is normalised away; anything further from unit
 * length (a scaled or garbled quaternion) or not finite is FG_EINVAL. */
int fg_pose_from_quat(const double p[3], const double q_wxyz[4], double T[16]);

/* Extracts position and a unit quaternion with w >= 0 from a rigid T. */
void fg_pose_to_quat(const double T[16], double p[3], double q_wxyz[4]);

/* ---- rigid transforms ---- */

/* The identity pose. */
void fg_pose_identity(double T[16]);

/* T_a_c = T_a_b * T_b_c: the pose of frame c in frame a. */
void fg_pose_compose(const double T_a_b[16], const double T_b_c[16], double T_a_c[16]);

/* T_b_a = T_a_b^-1 of a rigid T_a_b: [R^T, -R^T t]. Exact for rigid input only (no general
 * matrix inverse). */
void fg_pose_inverse(const double T_a_b[16], double T_b_a[16]);

/* p_a = T_a_b * p_b for one point (metres). */
void fg_pose_apply(const double T_a_b[16], const double p_b[3], double p_a[3]);

/* p_a = T_a_b * p_b for n points: p_b (n, 3) and p_a (n, 3) float, row-major; p_a may be p_b
 * (in place). Computed in double, rounded to float once. */
void fg_pose_apply_points(const double T_a_b[16], const float *p_b, size_t n, float *p_a);

/* v_a = R_a_b * v_b: a direction (no translation). */
void fg_pose_rotate(const double T_a_b[16], const double v_b[3], double v_a[3]);

/* The rotation block R_a_b (3x3, row-major) of T_a_b, and T_a_b from R_a_b and the position
 * p_a (metres) of b's origin. */
void fg_pose_get_rotmat(const double T_a_b[16], double R_a_b[9]);
void fg_pose_from_rotmat(const double R_a_b[9], const double p_a[3], double T_a_b[16]);

/* The pose T_world_frame of a frame at eye whose +z points at target (a camera looking at it,
 * OpenCV's convention), its x level (x = z x world up, normalised; -world y when z is
 * straight up or down) and its y = z x x (towards world -z: the image's down is the world's),
 * then turned by roll_rad about its z. eye must differ from target. */
void fg_pose_look_at(const double eye[3], const double target[3], double roll_rad, double T[16]);

/* ---- rotations: quaternion, 3x3 matrix, rotation vector ---- */

/* R (3x3 row-major) of a unit quaternion [w, x, y, z]; q is normalised first, so any
 * non-zero q gives a rotation. */
void fg_rotmat_from_quat(const double q_wxyz[4], double R[9]);

/* The unit quaternion with w >= 0 of a rotation matrix R (3x3 row-major); numerically stable
 * at every angle (Shepperd's branches). */
void fg_quat_from_rotmat(const double R[9], double q_wxyz[4]);

/* The rotation vector (axis x angle, radians, angle in [0, pi]) of a unit quaternion
 * [w, x, y, z]; a quaternion with w < 0 is taken as its negation (the same rotation). */
void fg_rotvec_from_quat(const double q_wxyz[4], double rotvec_rad[3]);

/* The unit quaternion of a rotation vector (axis x angle, radians); exact near 0 (series). */
void fg_quat_from_rotvec(const double rotvec_rad[3], double q_wxyz[4]);

/* R (3x3 row-major) of a rotation vector, and the rotation vector (angle in [0, pi]) of R. */
void fg_rotmat_from_rotvec(const double rotvec_rad[3], double R[9]);
void fg_rotvec_from_rotmat(const double R[9], double rotvec_rad[3]);

/* q_a_c = q_a_b * q_b_c (Hamilton product; the quaternion of R_a_b * R_b_c). */
void fg_quat_multiply(const double q_a_b[4], const double q_b_c[4], double q_a_c[4]);

/* The rotation a fraction s (0..1) of the way from q_a to q_b along the shorter arc (unit
 * quaternions; q_b and -q_b give the same result). */
void fg_quat_slerp(const double q_a[4], const double q_b[4], double s, double q_out[4]);

/* The geodesic angle (radians, [0, pi]) between two rotations: the angle of the rotation
 * that takes one onto the other, |rotvec(R_a^T R_b)|. Accurate near 0 and near pi. */
double fg_rotmat_angle_rad(const double R_a[9], const double R_b[9]);
double fg_quat_angle_rad(const double q_a[4], const double q_b[4]);

/* The same between the rotations of two poses (their positions are ignored). */
double fg_pose_angle_rad(const double T_a[16], const double T_b[16]);

#endif
