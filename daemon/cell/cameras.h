/* The cameras of [camera NAME] (SPEC.md "The cell around the field"): each one's calibration,
 * kept in <state>/cameras/NAME.json (atomic rewrite; a calibration that is refused leaves the
 * previous one), and captures: an image (and a depth image) fetched from the camera's source
 * with the robot's TCP pose read before and after it, and the camera's pose in the base frame
 * when the camera is calibrated. */
#ifndef FG_DAEMON_CELL_CAMERAS_H
#define FG_DAEMON_CELL_CAMERAS_H

#include <stddef.h>
#include <stdint.h>

#include "calib/calibrate.h"
#include "conf/conf.h"
#include "robot/robot.h"

typedef struct fg_cameras fg_cameras;

/* What is known of one camera. Poses are OpenCV's camera frame (+z optical axis). */
typedef struct fg_camera_calib {
  int has_intrinsics;
  fg_intrinsics in;
  double intrinsics_rms_px;  /* reprojection error of the calibration */
  int intrinsics_views;
  int64_t intrinsics_ms;     /* when (CLOCK_REALTIME); 0: never */
  int has_mount;
  double T_mount[16];        /* T_tcp_cam (a hand camera) or T_base_cam (a fixed one) */
  char method[16];           /* the hand-eye method it came from */
  double spread_mm, spread_deg; /* the board's pose over the views, after refinement */
  double mount_rms_px;
  int mount_views;
  int64_t mount_ms;
} fg_camera_calib;

/* Loads the calibrations kept under state_dir/cameras. 0, FG_ENOMEM, or FG_EIO when the
 * folder cannot be made; a file that does not parse is reported and left out. */
int fg_cameras_new(fg_cameras **out, const char *state_dir);
void fg_cameras_free(fg_cameras *c);

/* The calibration of camera name (all zeros when it has none). */
void fg_cameras_calib_get(fg_cameras *c, const char *name, fg_camera_calib *out);

/* Keeps a new calibration of name, written to its file before it is used. 0, or the write's
 * FG_EIO / FG_ENOSPC (the previous one stays). */
int fg_cameras_calib_set(fg_cameras *c, const char *name, const fg_camera_calib *calib);

/* A capture. The images are as the source served them (PNG or JPEG; depth a 16-bit PNG). */
typedef struct fg_capture {
  uint8_t *image;
  size_t image_len;
  uint8_t *depth;          /* NULL without a depth source */
  size_t depth_len;
  uint8_t *features;       /* the patch features (.npy); NULL without a features source */
  size_t features_len;
  int has_robot_pose;      /* the robot's TCP pose was read (always for a hand camera) */
  double T_base_tcp[16];
  int has_camera_pose;     /* calibrated (and, on the hand, with the robot's pose) */
  double T_base_cam[16];   /* OpenCV camera frame */
  fg_camera_calib calib;
} fg_capture;

/* Captures from cam: reads the TCP pose (a hand camera with a robot; for a fixed camera when
 * it can be read), fetches the image and, unless image_only (a calibration view needs no
 * more), the depth image and the features (a .npy; their shape is checked when they are
 * stored), reads the pose again and refuses (robot_moved) when it changed by more than 0.5 mm
 * or 0.1 degree. Failures: the robot's (fg_robot_tcp_read), camera_unavailable (the source
 * did not answer, answered an error, or sent no image: 502 / 504), robot_moved. */
int fg_camera_capture(fg_cameras *c, fg_robot_svc *robot, const fg_conf_camera *cam,
                      int image_only, fg_capture *out);
void fg_capture_release(fg_capture *cap);

/* ---- calibration.c: views kept from captures, and calibrating on them */

/* Most views a camera keeps for its next calibration. */
#define FG_CAMERA_MAX_VIEWS 100

/* Decodes a capture's image (in the decoder's children), finds board b in it and, when it
 * shows FG_CALIB_MIN_CORNERS corners or more, keeps its corners (with the capture's robot
 * pose) as the camera's next calibration view. *corners: how many were found; *kept: 0 or
 * the number of views now kept. FG_ERANGE (too_many_views) past FG_CAMERA_MAX_VIEWS. */
struct fg_decoder;
int fg_cameras_view_add(fg_cameras *c, struct fg_decoder *dec, const fg_charuco_board *b,
                        const fg_conf_camera *cam, const fg_capture *cap, int *corners,
                        int *kept);

/* Views kept for name; forgets them. */
int fg_cameras_views_count(fg_cameras *c, const char *name);
void fg_cameras_views_clear(fg_cameras *c, const char *name);

/* Bounds a calibration must meet to be kept. */
#define FG_CALIB_MAX_RMS_PX 1.0      /* reprojection error, intrinsics and mount */
#define FG_CALIB_MAX_SPREAD_MM 2.0   /* the fixed frame's spread over the views */
#define FG_CALIB_MAX_SPREAD_DEG 0.5

/* What to calibrate: the intrinsics, the mount (hand-eye) on intrinsics calibrated before, or
 * both on the same views (the intrinsics first; kept only when both meet the bounds). */
typedef enum {
  FG_CALIBRATE_INTRINSICS,
  FG_CALIBRATE_HAND_EYE,
  FG_CALIBRATE_BOTH
} fg_calibrate_kind;

/* What a calibration found, kept or not. */
typedef struct fg_calibration_report {
  int views, views_used;          /* both: views_used is the mount's */
  fg_camera_calib calib;          /* the new calibration (the kind's part) */
  fg_hand_eye_result methods[FG_HAND_EYE_METHODS]; /* hand_eye: each closed-form method */
  int best;                       /* hand_eye: the method refined */
} fg_calibration_report;

/* Calibrates cam's intrinsics, mount or both on its kept views (consumed when the calibration is
 * kept) with board b, and keeps the result (the other part of the calibration stays).
 * hand_eye needs the camera's intrinsics (kept as calibrated: refining them with the mount
 * would absorb the robot's pose errors, tests/bench/bench_calibration) and a robot pose with
 * every view. Refusals: too few views (FG_EINVAL, not_enough_views), a
 * degenerate motion (FG_EINVAL, degenerate_motion), residuals past the bounds above
 * (FG_ERANGE, calibration_rejected, with the numbers; *report holds them too); the previous
 * calibration then stays. */
int fg_camera_calibrate(fg_cameras *c, const fg_charuco_board *b, const fg_conf_camera *cam,
                        fg_calibrate_kind kind, fg_calibration_report *report);

/* ---- snapshot.c */

/* A source that names a V4L2 device: v4l2:/dev/videoN. */
#define FG_SOURCE_V4L2 "v4l2:"

/* Fetches one image from source within timeout_ms, at most max_bytes: an http(s):// URL's
 * answer, or for v4l2:DEVICE a frame (PNG) the program grabber (fieldgrip-grab) writes, run
 * as `grabber DEVICE` and killed at the timeout. FG_ETIMEDOUT (camera_timeout) or FG_EUNAVAIL
 * (camera_unavailable) with what went wrong (for a grabber, the last line it printed). */
int fg_snapshot_fetch(const char *grabber, const char *source, int timeout_ms, size_t max_bytes,
                      uint8_t **out,
                      size_t *len);

#endif
