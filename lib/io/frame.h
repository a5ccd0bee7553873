/* A training frame as the state dir keeps it: one camera, its undistorted, downscaled RGB
 * image and, optionally, its dense feature grid, in one binary file (".fgf") that training
 * loads without decoding anything.
 *
 * File layout (little-endian):
 *   header  struct fg_frame_file_header (FG_FRAME_HEADER_SIZE bytes, magic "FGFRAME\0";
 *           512 bytes in versions 1 and 2)
 *   pixels  uint16 [h][w][3], sRGB-encoded, 0..65535
 *   feats   feat_dtype [feat_h][feat_w][feat_d] (absent when feat_d is 0)
 *   depth   float32 [depth_h][depth_w], z-depth in metres, 0 where invalid (absent when
 *           depth_w is 0; version 2 only)
 *   crc     uint32, zlib crc32 of everything before it
 * Version 3 adds the capture the frame belongs to and the robot's TCP pose it was taken at
 * (a header of 1024 bytes); versions 1 and 2 (no depth fields in 1) are still read, their
 * frames in capture 1 without a robot pose. The depth map, when there is one, is
 * stored at the image's stored size, pixel for pixel (see fg_frame_prepare_image_depth).
 * A reader refuses a wrong magic, an unknown version, sizes that disagree with the file's
 * length, and a CRC mismatch. */
#ifndef FG_IO_FRAME_H
#define FG_IO_FRAME_H

#include <stddef.h>
#include <stdint.h>

#include "io/camera.h"
#include "io/depth.h"
#include "io/image.h"
#include "io/npy.h"

#define FG_FRAME_VERSION 3
#define FG_FRAME_HEADER_SIZE 1024 /* version 3; 512 before */
#define FG_FRAME_SOURCE_MAX 256
#define FG_FRAME_MAX_FEAT_D 4096

typedef struct fg_frame {
  double T_world_cam[16];  /* camera-to-world, OpenGL convention, metres, row-major */
  fg_camera cam;           /* PINHOLE, sized to the stored image */
  int src_w, src_h;        /* size of the image as received */
  int undistorted;         /* 1 if an OPENCV camera was undistorted on ingest */
  int64_t created_ms;      /* Unix time of ingest, milliseconds */
  char source[FG_FRAME_SOURCE_MAX]; /* file name or upload name, for listings */
  uint16_t *rgb;           /* [cam.h][cam.w][3]; owned; NULL after fg_frame_load_header */
  int feat_h, feat_w, feat_d;
  fg_dtype feat_dtype;     /* FG_DTYPE_NONE when the frame has no features */
  void *feat;              /* [feat_h][feat_w][feat_d]; owned; NULL when none or header only */
  int depth_w, depth_h;    /* == cam.w, cam.h when the frame has depth, else 0 */
  double depth_valid;      /* share of depth pixels that are valid, [0, 1] */
  float *depth;            /* [depth_h][depth_w] z-depth in metres, 0 where invalid; owned;
                              NULL when none or header only */
  int64_t capture;         /* the capture (one scan or upload session) the frame belongs
                              to, >= 1; 0 until its scene gives it one (the store writes
                              0 as is, and reads files of versions 1-2 as capture 1) */
  int has_robot_pose;      /* 1 when T_world_tcp holds the robot's TCP pose at the frame */
  double T_world_tcp[16];  /* that pose (world frame, metres, row-major); else zero */
} fg_frame;

/* Options of fg_frame_prepare. */
typedef struct fg_ingest_opts {
  float background_rgb[3]; /* alpha is composited on this, [0,1] */
  int max_image_side;      /* long side after downscaling; 0 keeps the size */
} fg_ingest_opts;

/* Builds a frame from an encoded image, its camera and pose, and optional features:
 *  - decodes (fg_image_decode) and composites alpha on the background;
 *  - checks that cam->w/h equal the decoded size (FG_EINVAL naming both sizes otherwise);
 *  - undistorts an OPENCV camera (intrinsics replaced by the undistorted pinhole ones) and
 *    resamples the feature grid through the same mapping (bilinear at feature-cell centres);
 *  - downscales with the area filter so the long side is at most max_image_side, scaling the
 *    intrinsics by the exact size ratios;
 *  - validates the pose (fg_pose_validate) and copies features ([h, w, D], f32 or f16, D in
 *    1..FG_FRAME_MAX_FEAT_D, else FG_EINVAL); features keep their dtype.
 * T_world_cam must already be in the OpenGL convention. On success the caller owns *out and
 * frees it with fg_frame_clear; on failure *out holds nothing to free. */
int fg_frame_prepare(fg_frame *out, const void *image, size_t image_len, const fg_camera *cam,
                     const double T_world_cam[16], const fg_npy *features,
                     const fg_ingest_opts *opts);

/* fg_frame_prepare_image with an aligned depth map (io/depth.h) of the image as received:
 * depth->w x depth->h must lie on the image's pixel grid (fg_depth_check_grid, FG_EINVAL
 * otherwise). The map goes through the image's own undistortion and downscaling by nearest
 * sampling (each stored pixel takes the depth pixel under its centre, so no value is ever an
 * average across an edge) and is stored at the stored image's size. z-depth is unchanged by
 * undistortion and scaling: the camera's centre and axis stay. NaN is read as invalid;
 * negative or infinite values are FG_EINVAL. depth may be NULL. */
int fg_frame_prepare_image_depth(fg_frame *out, const fg_image *img, const fg_camera *cam,
                                 const double T_world_cam[16], const fg_npy *features,
                                 const fg_depth_map *depth, const fg_ingest_opts *opts);

/* fg_frame_prepare for an image the caller has already decoded (with fg_image_decode, alpha
 * composited), e.g. to learn its size before finishing the camera. img is only read; it stays
 * the caller's. opts->background_rgb is unused here. Same checks, same ownership of *out. */
int fg_frame_prepare_image(fg_frame *out, const fg_image *img, const fg_camera *cam,
                           const double T_world_cam[16], const fg_npy *features,
                           const fg_ingest_opts *opts);

/* The feature checks of fg_frame_prepare alone: shape [h, w, D], f32 or f16, D in
 * 1..FG_FRAME_MAX_FEAT_D, every value finite. 0 or FG_EINVAL with a detail. */
int fg_frame_check_features(const fg_npy *features);

/* Writes a frame atomically (fsutil) to path. */
int fg_frame_save(const fg_frame *frame, const char *path);

/* Reads a whole frame, verifying its CRC. The caller owns *out (fg_frame_clear). */
int fg_frame_load(const char *path, fg_frame *out);

/* Reads only the header fields (rgb and feat stay NULL), checking the file's length against
 * the sizes it declares but not the CRC: cheap enough for listings. */
int fg_frame_load_header(const char *path, fg_frame *out);

/* Frees pixels, features and depth; safe on a zeroed frame. */
void fg_frame_clear(fg_frame *frame);

#endif
