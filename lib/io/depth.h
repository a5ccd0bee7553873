/* Depth maps from RGB-D cameras: z-depth along the camera's optical axis (not the distance
 * along the ray), in metres, aligned with a frame's image (same camera; the same size or a
 * smaller size on the same pixel grid). A value of 0 marks an invalid pixel; NaN in the input
 * is read as invalid and stored as 0.
 *
 * Accepted encodings:
 *   - PNG or TIFF, one channel, 16-bit unsigned integers: metres = value * scale (RealSense,
 *     Azure Kinect and nerfstudio's depth files: millimetres, scale 0.001);
 *   - OpenEXR or TIFF, one channel, floating point: metres (scale ignored);
 *   - .npy float32 of shape [h, w] or [h, w, 1]: metres (scale ignored).
 * Refused with FG_EINVAL and a detail a user can act on: an 8-bit image (depth needs 16 bits),
 * more than one channel (a colour image sent as depth), negative or infinite metres, a scale
 * that is not finite and > 0. Truncated or corrupt data is FG_EFORMAT. */
#ifndef FG_IO_DEPTH_H
#define FG_IO_DEPTH_H

#include <stddef.h>

#include "io/npy.h"

#define FG_DEPTH_DEFAULT_SCALE 0.001 /* metres per unit of integer depth: millimetres */

typedef struct fg_depth_map {
  int w, h;
  float *m; /* [h][w] metres, 0 where invalid; owned (fg_depth_release) */
} fg_depth_map;

void fg_depth_release(fg_depth_map *d);

/* Decodes an encoded depth image (PNG, TIFF, OpenEXR; see above) through OpenImageIO. Only
 * programs that link OpenImageIO may call it; the daemon goes through its decoder processes
 * (fg_decoder_decode_depth). On success the caller owns out->m. */
int fg_depth_decode(const void *bytes, size_t len, double scale, fg_depth_map *out);

/* A depth map from a parsed .npy (float32, [h, w] or [h, w, 1], metres). Copies the data. */
int fg_depth_from_npy(const fg_npy *npy, fg_depth_map *out);

/* Either of the two above, chosen by the bytes (the .npy magic, else an image). Needs
 * OpenImageIO like fg_depth_decode. */
int fg_depth_read(const void *bytes, size_t len, double scale, fg_depth_map *out);

/* Checks that a w x h depth map lies on the pixel grid of an img_w x img_h image: the image
 * is k times the depth map's size in both directions for one integer k >= 1. */
int fg_depth_check_grid(int w, int h, int img_w, int img_h);

/* Share of valid (> 0) pixels, in [0, 1]. */
double fg_depth_valid_fraction(const float *m, size_t n);

#endif
