/* Camera intrinsics: parsing of model names, validation and the forward distortion model. */
#include "io/camera.h"
#include "core/error.h"

#include <math.h>
#include <string.h>

/* Beyond this a size is a typo or an attack rather than a camera. */
#define CAMERA_MAX_SIDE 32768

int fg_camera_model_parse(const char *name, fg_camera_model *out) {
  if (!name) return fg_fail(FG_EINVAL, "camera_model is missing; use \"PINHOLE\" or \"OPENCV\"");
  if (strcmp(name, "PINHOLE") == 0) {
    *out = FG_CAMERA_PINHOLE;
    return 0;
  }
  if (strcmp(name, "OPENCV") == 0) {
    *out = FG_CAMERA_OPENCV;
    return 0;
  }
  return fg_fail(FG_EINVAL, "unknown camera_model \"%s\"; supported models are PINHOLE and OPENCV",
                 name);
}

const char *fg_camera_model_name(fg_camera_model m) {
  return m == FG_CAMERA_OPENCV ? "OPENCV" : "PINHOLE";
}

/* A PINHOLE camera with non-zero coefficients is refused rather than silently treated as
 * undistorted: the caller most likely forgot camera_model "OPENCV", and ignoring the
 * coefficients would bend every ray of the frame. */
int fg_camera_validate(const fg_camera *cam) {
  if (!cam) return fg_fail(FG_EINVAL, "no camera given");
  if (!isfinite(cam->fl_x) || !isfinite(cam->fl_y) || cam->fl_x <= 0 || cam->fl_y <= 0)
    return fg_fail(FG_EINVAL,
                   "focal lengths must be finite and positive pixels, got fl_x %g fl_y %g",
                   cam->fl_x, cam->fl_y);
  if (cam->w <= 0 || cam->h <= 0 || cam->w > CAMERA_MAX_SIDE || cam->h > CAMERA_MAX_SIDE)
    return fg_fail(FG_EINVAL, "camera size must be 1..%d pixels per side, got %dx%d",
                   CAMERA_MAX_SIDE, cam->w, cam->h);
  if (!isfinite(cam->cx) || !isfinite(cam->cy))
    return fg_fail(FG_EINVAL, "principal point must be finite, got cx %g cy %g", cam->cx, cam->cy);
  if (cam->model != FG_CAMERA_PINHOLE && cam->model != FG_CAMERA_OPENCV)
    return fg_fail(FG_EINVAL, "unknown camera model %d; use PINHOLE or OPENCV", (int)cam->model);
  const double k[5] = {cam->k1, cam->k2, cam->k3, cam->p1, cam->p2};
  static const char *const names[5] = {"k1", "k2", "k3", "p1", "p2"};
  for (int i = 0; i < 5; i++) {
    if (!isfinite(k[i]))
      return fg_fail(FG_EINVAL, "distortion coefficient %s is not a finite number", names[i]);
    if (cam->model == FG_CAMERA_PINHOLE && k[i] != 0)
      return fg_fail(FG_EINVAL,
                     "camera_model is PINHOLE but %s is %g; set camera_model to \"OPENCV\" for a "
                     "distorted camera or drop the coefficients",
                     names[i], k[i]);
  }
  return 0;
}

int fg_camera_is_distorted(const fg_camera *cam) {
  return cam->k1 != 0 || cam->k2 != 0 || cam->k3 != 0 || cam->p1 != 0 || cam->p2 != 0;
}

void fg_camera_distort_normalized(const fg_camera *cam, double x, double y, double *xd,
                                  double *yd) {
  double r2 = x * x + y * y;
  double radial = 1 + r2 * (cam->k1 + r2 * (cam->k2 + r2 * cam->k3));
  *xd = x * radial + 2 * cam->p1 * x * y + cam->p2 * (r2 + 2 * x * x);
  *yd = y * radial + cam->p1 * (r2 + 2 * y * y) + 2 * cam->p2 * x * y;
}
