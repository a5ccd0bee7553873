/* Image format sniffing, resampling and undistortion: argument checks in C, OpenCV behind
 * shim.h. Decoding and encoding (OpenImageIO) live in image_codec.c, a separate object so that
 * a program that never decodes (the daemon, which hands that to fieldgrip-decode) links
 * without OpenImageIO.
 *
 * Pixel convention: fg_camera uses continuous coordinates (pixel (u, v) has its centre at
 * (u + 0.5, v + 0.5)); OpenCV puts pixel centres at integers. The conversion (a half-pixel
 * shift of the principal point and of point coordinates) happens here, at the boundary. */
#include "io/image.h"
#include "core/error.h"
#include "io/shim.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void fg_image_release(fg_image *img) {
  if (!img) return;
  free(img->rgb);
  memset(img, 0, sizeof *img);
}

/* ---- format sniffing ---------------------------------------------------------------- */

/* Recognises the format by its magic bytes. Decoding itself lives in image_codec.c, which
 * maps the name back to the reader it needs. */
const char *fg_image_sniff(const void *bytes, size_t len) {
  const uint8_t *b = bytes;
  if (!b) return NULL;
  if (len >= 4 && memcmp(b, "\x89PNG", 4) == 0) return "PNG";
  if (len >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF) return "JPEG";
  if (len >= 4 && memcmp(b, "\x76\x2f\x31\x01", 4) == 0) return "OpenEXR";
  if (len >= 4 && (memcmp(b, "II*\0", 4) == 0 || memcmp(b, "MM\0*", 4) == 0)) return "TIFF";
  return NULL;
}

int fg_image_check_size(const char *what, int w, int h) {
  if (w <= 0 || h <= 0 || w > FG_IMAGE_MAX_SIDE || h > FG_IMAGE_MAX_SIDE ||
      (size_t)w * (size_t)h > (size_t)FG_IMAGE_MAX_PIXELS)
    return fg_fail(FG_EINVAL, "%s: size %dx%d is outside 1..%d pixels per side", what, w, h,
                   FG_IMAGE_MAX_SIDE);
  return 0;
}

/* ---- resampling --------------------------------------------------------------------- */

int fg_image_resize_area(const float *src, int sw, int sh, int c, float *dst, int dw, int dh) {
  if (!src || !dst) return fg_fail(FG_EINVAL, "fg_image_resize_area: no source or destination");
  FG_TRY(fg_image_check_size("resize source", sw, sh));
  FG_TRY(fg_image_check_size("resize destination", dw, dh));
  if (c < 1 || c > 512) /* OpenCV's channel limit (CV_CN_MAX) */
    return fg_fail(FG_EINVAL, "resize: channels must be 1..512, got %d", c);
  if (sw == dw && sh == dh) {
    if (src != dst) memmove(dst, src, (size_t)sw * (size_t)sh * (size_t)c * sizeof(float));
    return 0;
  }
  return fg_cv_resize_area(src, sw, sh, c, dst, dw, dh);
}

/* ---- undistortion ------------------------------------------------------------------- */

/* fg_camera (continuous pixels) -> OpenCV intrinsics (integer pixel centres). */
static void to_cv(const fg_camera *cam, fg_cv_intrinsics *in) {
  in->K[0] = cam->fl_x;
  in->K[1] = cam->fl_y;
  in->K[2] = cam->cx - 0.5;
  in->K[3] = cam->cy - 0.5;
  in->dist[0] = cam->k1;
  in->dist[1] = cam->k2;
  in->dist[2] = cam->p1;
  in->dist[3] = cam->p2;
  in->dist[4] = cam->k3;
}

int fg_image_undistort(const float *src, const fg_camera *cam, float *dst, fg_camera *out_cam) {
  if (!src || !dst || !out_cam) return fg_fail(FG_EINVAL, "fg_image_undistort: null argument");
  FG_TRY(fg_camera_validate(cam));
  FG_TRY(fg_image_check_size("undistort", cam->w, cam->h));
  fg_camera nc = *cam;
  nc.model = FG_CAMERA_PINHOLE;
  nc.k1 = nc.k2 = nc.k3 = nc.p1 = nc.p2 = 0;
  if (!fg_camera_is_distorted(cam)) { /* nothing to do: same rays, same intrinsics */
    if (src != dst) memmove(dst, src, (size_t)cam->w * (size_t)cam->h * 3 * sizeof(float));
    *out_cam = nc;
    return 0;
  }
  fg_cv_intrinsics in;
  to_cv(cam, &in);
  double nk[4];
  FG_TRY(fg_cv_undistort(src, cam->w, cam->h, &in, dst, nk));
  for (int i = 0; i < 4; i++)
    if (!isfinite(nk[i]) || (i < 2 && nk[i] <= 0))
      return fg_fail(FG_EINVAL, "undistortion produced an invalid camera; check that the "
                                "distortion coefficients belong to this image");
  nc.fl_x = nk[0];
  nc.fl_y = nk[1];
  nc.cx = nk[2] + 0.5;
  nc.cy = nk[3] + 0.5;
  *out_cam = nc;
  return 0;
}

int fg_camera_undistort_points(const fg_camera *cam, const fg_camera *new_cam, double *xy, int n) {
  if (!cam || !new_cam || (n > 0 && !xy))
    return fg_fail(FG_EINVAL, "fg_camera_undistort_points: null argument");
  if (n < 0) return fg_fail(FG_EINVAL, "fg_camera_undistort_points: negative count %d", n);
  fg_cv_intrinsics in;
  to_cv(cam, &in);
  double nk[4] = {new_cam->fl_x, new_cam->fl_y, new_cam->cx - 0.5, new_cam->cy - 0.5};
  for (int i = 0; i < 2 * n; i++) xy[i] -= 0.5;
  int rc = fg_cv_undistort_points(&in, nk, xy, n);
  for (int i = 0; i < 2 * n; i++) xy[i] += 0.5;
  return rc;
}
