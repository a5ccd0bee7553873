/* Camera and hand-eye calibration from ChArUco views (charuco.h), with OpenCV 4.6's
 * calibrateCameraCharuco, solvePnP and calibrateHandEye. Poses are 4x4 row-major rigid
 * transforms (core/pose.h), metres, named T_a_b: b's frame in a's. Cameras are OpenCV's (+z
 * along the optical axis, +y down); intrinsics are OpenCV's (pixel centres at integers) with
 * the OPENCV distortion k1 k2 p1 p2 (k3 fixed at 0, as SPEC.md's camera_model OPENCV has it).
 *
 * Every function returns 0 or a negative FG_E* code with a detail that says what to change
 * (FG_EINVAL: not enough views or corners, a degenerate motion); no C++ exception crosses this
 * header. */
#ifndef FG_CALIB_CALIBRATE_H
#define FG_CALIB_CALIBRATE_H

#include "calib/charuco.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The corners found in one image: ids[k] and px[2k], px[2k+1] for k < n (borrowed). */
typedef struct fg_calib_view {
  int n;
  const int *ids;
  const double *px;
} fg_calib_view;

typedef struct fg_intrinsics {
  int w, h;
  double fx, fy, cx, cy;
  double k[4]; /* k1 k2 p1 p2 */
} fg_intrinsics;

/* Views with fewer corners than this, or whose corners lie on one line (a quarter of a square
 * across it at most), are left out of a calibration (and reported). */
#define FG_CALIB_MIN_CORNERS 6
/* The fewest views an intrinsic calibration takes, and a hand-eye calibration. */
#define FG_CALIB_MIN_VIEWS_INTRINSICS 4
#define FG_CALIB_MIN_VIEWS_HAND_EYE 8

/* Intrinsics of a w x h camera from n views of board b: *out, the RMS reprojection error
 * (pixels) over all corners in *rms_px, and per view (per_view_rms[i], NAN for a view left
 * out for having fewer than FG_CALIB_MIN_CORNERS corners or all on one line; may be NULL). FG_EINVAL when fewer
 * than FG_CALIB_MIN_VIEWS_INTRINSICS views are usable. */
int fg_calibrate_intrinsics(const fg_charuco_board *b, const fg_calib_view *views, int n, int w,
                            int h, fg_intrinsics *out, double *rms_px, double *per_view_rms);

/* The board's pose in the camera (T_cam_board) from one view's corners and the intrinsics;
 * *rms_px its reprojection error. FG_EINVAL with fewer than FG_CALIB_MIN_CORNERS corners, or
 * corners all on one line. */
int fg_calib_board_pose(const fg_charuco_board *b, const fg_calib_view *view,
                        const fg_intrinsics *in, double T_cam_board[16], double *rms_px);

/* Hand-eye methods of OpenCV, in its order. */
enum { FG_HAND_EYE_TSAI, FG_HAND_EYE_PARK, FG_HAND_EYE_HORAUD, FG_HAND_EYE_ANDREFF,
       FG_HAND_EYE_DANIILIDIS, FG_HAND_EYE_METHODS };
const char *fg_hand_eye_method_name(int method);

/* One method's answer, and how well it explains the views: the fixed frame's pose (the
 * board's in the base for a camera on the hand; the board's in the tool for a fixed camera)
 * computed from each view, and its spread over the views (RMS distance from their mean, mm
 * and degrees). */
typedef struct fg_hand_eye_result {
  int method;
  int ok;                  /* 0: the method failed (a NaN result); the rest is unset */
  double T[16];            /* T_tcp_cam (hand) or T_base_cam (fixed) */
  double T_fixed[16];      /* the mean T_base_board (hand) or T_tcp_board (fixed) */
  double spread_mm, spread_deg;
} fg_hand_eye_result;

/* Hand-eye calibration from n pairs of a robot pose (T_base_tcp[i], 16 doubles each) and the
 * board's pose in the camera at it (T_cam_board[i]). fixed = 0: the camera is on the tool and
 * the board lies still (T_tcp_cam is solved); fixed = 1: the camera stands still and the tool
 * holds the board (T_base_cam). Every method's result in results[FG_HAND_EYE_METHODS]; the
 * index of the one with the smallest spread in *best. FG_EINVAL with fewer than
 * FG_CALIB_MIN_VIEWS_HAND_EYE pairs, or when the robot's rotations leave the solution
 * unobservable (all about one axis, or too small): the detail says which. */
int fg_calibrate_hand_eye(const double *T_base_tcp, const double *T_cam_board, int n, int fixed,
                          fg_hand_eye_result results[FG_HAND_EYE_METHODS], int *best);

/* How well a mount T (as fg_calibrate_hand_eye's) explains n views: the fixed frame computed
 * from each view, its mean (*T_fixed) and its RMS spread about it (mm, degrees). */
void fg_hand_eye_spread(const double *T_base_tcp, const double *T_cam_board, int n, int fixed,
                        const double T[16], double T_fixed[16], double *spread_mm,
                        double *spread_deg);

/* Refines a hand-eye calibration by what the images say: the mount (*T, as
 * fg_calibrate_hand_eye's T) and the fixed frame (*T_fixed), and with refine_intrinsics the
 * intrinsics *in too, by Levenberg-Marquardt on the reprojection error of every corner of
 * every view, the robot's poses taken as they were read. The robot's poses pin every view's
 * camera to two unknown poses, so this uses all the corners at once, where the closed-form
 * methods see one board pose per view. views[i] belongs to T_base_tcp[i]; *rms_px is the
 * final RMS reprojection error. */
int fg_calibrate_hand_eye_refine(const fg_charuco_board *b, const fg_calib_view *views,
                                 const double *T_base_tcp, int n, int fixed,
                                 int refine_intrinsics, fg_intrinsics *in, double T[16],
                                 double T_fixed[16], double *rms_px);

#ifdef __cplusplus
}
#endif

#endif
