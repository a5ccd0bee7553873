/* Rigid poses in the world (robot base) frame: metres, right-handed, +z up.
 *
 * A pose is a 4x4 row-major double matrix T_a_b that maps points from frame b to frame a
 * (p_a = T_a_b * p_b). Quaternions are [w, x, y, z], unit, scalar first (SPEC.md). */
#ifndef FG_CORE_POSE_H
#define FG_CORE_POSE_H

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

#endif
