/* Image decode and encode through OpenImageIO, resampling and undistortion through OpenCV.
 * The C++ lives in oiio_shim.cpp and cv_shim.cpp; nothing C++ crosses this header. */
#ifndef FG_IO_IMAGE_H
#define FG_IO_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#include "io/camera.h"

/* An RGB image of floats in [0, 1], sRGB-encoded, row-major [h][w][3]. */
typedef struct fg_image {
  int w, h;
  float *rgb; /* owned; free with fg_image_release */
} fg_image;

void fg_image_release(fg_image *img);

/* Longest side accepted by the decoder, and the largest w*h. */
#define FG_IMAGE_MAX_SIDE 16384
#define FG_IMAGE_MAX_PIXELS (64u * 1024u * 1024u)

/* Recognises an encoded image by its magic bytes: returns "PNG", "JPEG", "OpenEXR" or
 * "TIFF" (static strings), or NULL for anything fg_image_decode would refuse as unknown. */
const char *fg_image_sniff(const void *bytes, size_t len);

/* Checks an image size against FG_IMAGE_MAX_SIDE and FG_IMAGE_MAX_PIXELS; what names the
 * caller in the FG_EINVAL detail. */
int fg_image_check_size(const char *what, int w, int h);

/* Decodes PNG (8 or 16 bit), JPEG, OpenEXR or TIFF from memory, recognised by their magic
 * bytes. Grey images are expanded to RGB; an alpha channel is composited over background_rgb
 * (floats in [0,1]); linear formats (EXR, float TIFF) are converted to sRGB encoding and
 * clamped to [0, 1]. Truncated or corrupt data is FG_EFORMAT, an unknown format FG_EFORMAT
 * with a detail listing the supported ones. On success the caller owns out->rgb. */
int fg_image_decode(const void *bytes, size_t len, const float background_rgb[3], fg_image *out);

/* Encodes an image to PNG in a malloc'd buffer the caller owns. channels is 1, 3 or 4;
 * bits is 8 or 16; pixels are [h][w][channels] in the given bit depth
 * (uint8_t or uint16_t). */
int fg_image_encode_png(const void *pixels, int w, int h, int channels, int bits, uint8_t **out,
                        size_t *out_len);

/* Writes an image file in the format its extension names (.png, .jpg, .exr, .tif), for tests
 * and tools. pixels are float [h][w][channels]. */
int fg_image_write_file(const char *path, const float *pixels, int w, int h, int channels);

/* Resizes with OpenCV's area filter (INTER_AREA). src and dst are float [h][w][c]. */
int fg_image_resize_area(const float *src, int sw, int sh, int c, float *dst, int dw, int dh);

/* Undistorts an OPENCV-model image into a pinhole image of the same size.
 * The new intrinsics come from OpenCV's getOptimalNewCameraMatrix with alpha 0 (every output
 * pixel sees the scene; no black borders); out_cam receives them with model PINHOLE.
 * src and dst are float [h][w][3]; dst is allocated by the caller. */
int fg_image_undistort(const float *src, const fg_camera *cam, float *dst, fg_camera *out_cam);

/* OpenCV's undistortPoints for n pixel coordinates (u, v) of the distorted camera, mapped to
 * pixel coordinates of new_cam (the pinhole camera fg_image_undistort produced). Exposed for
 * tests that check undistortion against OpenCV itself. xy is [n][2], in place. */
int fg_camera_undistort_points(const fg_camera *cam, const fg_camera *new_cam, double *xy, int n);

#endif
