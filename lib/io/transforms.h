/* instant-ngp / nerfstudio data sets: a transforms.json beside (or above) its images.
 *
 * Camera keys may stand at the top level and be overridden per frame: camera_angle_x,
 * camera_angle_y (radians), fl_x, fl_y, cx, cy, w, h, camera_model ("PINHOLE", "OPENCV";
 * absent = OPENCV when any of k1 k2 k3 p1 p2 is non-zero, else PINHOLE), k1, k2, k3, p1, p2.
 * Each frame has file_path (relative to the transforms file's folder, with or without the
 * image's extension), transform_matrix (4x4 camera-to-world, OpenGL convention) and optionally
 * features_path (a .npy, same rules as file_path) and depth_file_path (nerfstudio's key: a
 * depth map aligned with the image, io/depth.h; same rules) with depth_unit_scale_factor
 * (metres per unit of an integer depth image; top level or per frame, default 0.001). Keys of the wider formats that do not
 * concern us (aabb_scale, scale, offset, rotation, colmap_im_id, ...) are ignored.
 *
 * This is a file format reader: it parses JSON internally, and nothing JSON-shaped crosses
 * this header. */
#ifndef FG_IO_TRANSFORMS_H
#define FG_IO_TRANSFORMS_H

#include <stddef.h>

#include "io/camera.h"

typedef struct fg_transforms_frame {
  char *image_path;    /* resolved path of the image file; NULL when no file was found */
  char *file_path;     /* file_path exactly as written in the JSON */
  char *features_path; /* resolved .npy path, or NULL when the frame names none */
  char *depth_path;    /* resolved depth file, or NULL when the frame names none or it is
                          missing (depth_missing) */
  int depth_missing;   /* 1 when depth_file_path names no file: the frame imports without */
  double depth_scale;  /* depth_unit_scale_factor, > 0 */
  double T_world_cam[16];
  fg_camera cam;       /* w/h may be 0 when neither the file nor camera_angle gave them:
                          fill them from the decoded image (see fg_transforms_complete_camera) */
  int has_size;        /* 1 when w and h came from the JSON */
  double camera_angle_x, camera_angle_y; /* radians, 0 when absent; used to finish cam */
  /* Private to transforms.c: which of cam's values the JSON gave in pixels, so that
   * fg_transforms_complete_camera fills only the others. */
  int has_fl_x, has_fl_y, has_cx, has_cy;
} fg_transforms_frame;

/* Makes f the frame of a camera known in full (its size and every intrinsic, in pixels, in
 * fg_camera's convention), as a transforms file that gives them all would: nothing of it is
 * filled in from the image later (fg_transforms_complete_camera only checks the size). */
void fg_transforms_frame_set_camera(fg_transforms_frame *f, const fg_camera *cam);

typedef struct fg_transforms {
  fg_transforms_frame *frames; /* owned */
  size_t n_frames;
  size_t n_missing;            /* frames whose image file does not exist (image_path NULL) */
  size_t n_depth_missing;      /* frames with an image whose depth file does not exist */
} fg_transforms;

/* Parses the transforms file at path. Paths are resolved against its folder. A frame whose
 * image is missing is kept with image_path NULL and counted in n_missing; a frame whose
 * features_path names a missing file is an error (FG_ENOENT) unless its image is missing too
 * (the frame will be skipped anyway); a missing depth file is not (see depth_missing). A
 * depth_unit_scale_factor that is not a number > 0 is FG_EFORMAT. Malformed JSON (with line and column), a missing or
 * non-4x4 transform_matrix, a value of the wrong type, a non-finite number, no focal length
 * (none of fl_x, fl_y, camera_angle_x, camera_angle_y), an unsupported camera_model:
 * FG_EFORMAT with a detail that names the file and the frame index. A missing transforms file
 * is FG_ENOENT. On success the caller owns *out (fg_transforms_free); on failure *out is
 * zeroed and owns nothing.
 *
 * Focal lengths resolve per axis, the frame's keys before the top level's, fl_* before
 * camera_angle_*; an axis given neither way takes the other axis's focal length (square
 * pixels). file_path and features_path may also be absolute or climb out with "..": a caller
 * that must confine reads to a folder checks image_path / features_path itself. */
int fg_transforms_load(const char *path, fg_transforms *out);

/* Fills a frame's camera once the image's size is known: w/h if the JSON lacked them,
 * fl_x/fl_y from camera_angle_x/y, cx/cy at the centre when absent, then checks it with
 * fg_camera_validate. FG_EINVAL if the JSON's w/h disagree with the image's. Calling it again
 * (with the same size) is harmless. */
int fg_transforms_complete_camera(fg_transforms_frame *f, int image_w, int image_h);

void fg_transforms_free(fg_transforms *t);

#endif
