/* Pinhole and OpenCV (Brown-Conrady) camera intrinsics, in pixels.
 *
 * Pixel coordinates follow the nerfstudio / instant-ngp / OpenCV continuous convention: the
 * image spans [0, w] x [0, h] and the centre of pixel (u, v) is at (u + 0.5, v + 0.5).
 * Distortion, when present, maps normalised undistorted coordinates (x, y) to distorted ones:
 *   r2 = x^2 + y^2, radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
 *   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2),  yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
 * exactly as OpenCV's five-coefficient model. */
#ifndef FG_IO_CAMERA_H
#define FG_IO_CAMERA_H

typedef enum {
  FG_CAMERA_PINHOLE = 0,
  FG_CAMERA_OPENCV = 1,
} fg_camera_model;

typedef struct fg_camera {
  double fl_x, fl_y; /* focal lengths, pixels */
  double cx, cy;     /* principal point, pixels */
  int w, h;          /* image size, pixels */
  fg_camera_model model;
  double k1, k2, k3, p1, p2; /* OPENCV only; zero for PINHOLE */
} fg_camera;

/* Parses "PINHOLE" or "OPENCV"; FG_EINVAL naming the supported models otherwise. */
int fg_camera_model_parse(const char *name, fg_camera_model *out);
const char *fg_camera_model_name(fg_camera_model m);

/* Checks finite positive focal lengths, a positive size up to 32768, a finite principal point
 * and finite distortion coefficients. FG_EINVAL with a detail. */
int fg_camera_validate(const fg_camera *cam);

/* True when the camera has non-zero distortion coefficients. */
int fg_camera_is_distorted(const fg_camera *cam);

/* Applies the distortion model to normalised coordinates (see above). */
void fg_camera_distort_normalized(const fg_camera *cam, double x, double y, double *xd, double *yd);

#endif
