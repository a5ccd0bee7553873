/* instant-ngp / nerfstudio data sets: a transforms.json beside (or above) its images.
 *
 * Camera keys may stand at the top level and be overridden per frame: camera_angle_x,
 * camera_angle_y (radians), fl_x, fl_y, cx, cy, w, h, camera_model ("PINHOLE", "OPENCV";
 * absent = OPENCV when any of k1 k2 k3 p1 p2 is non-zero, else PINHOLE), k1, k2, k3, p1, p2.
 * Each frame has file_path (relative to the transforms file's folder, with or without the
 * image's extension), transform_matrix (4x4 camera-to-world, OpenGL convention) and optionally
 * features_path (a .npy, same rules as file_path). Keys of the wider formats that do not
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
  double T_world_cam[16];
  fg_camera cam;       /* w/h may be 0 when neither the file nor camera_angle gave them:
                          fill them from the decoded image (see fg_transforms_complete_camera) */
  int has_size;        /* 1 when w and h came from the JSON */
  double camera_angle_x, camera_angle_y; /* radians, 0 when absent; used to finish cam */
} fg_transforms_frame;

typedef struct fg_transforms {
  fg_transforms_frame *frames; /* owned */
  size_t n_frames;
  size_t n_missing;            /* frames whose image file does not exist (image_path NULL) */
} fg_transforms;

/* Parses the transforms file at path. Paths are resolved against its folder. A frame whose
 * image is missing is kept with image_path NULL and counted in n_missing; a frame whose
 * features_path names a missing file is an error. Malformed JSON (with line and column),
 * a missing or non-4x4 transform_matrix, a non-finite number, focal length given neither as
 * fl_x nor camera_angle_x, an unknown camera_model: FG_EINVAL or FG_EFORMAT with a detail that
 * names the frame index. The caller owns *out (fg_transforms_free). */
int fg_transforms_load(const char *path, fg_transforms *out);

/* Fills a frame's camera once the image's size is known: w/h if the JSON lacked them,
 * fl_x/fl_y from camera_angle_x/y, cx/cy at the centre when absent. FG_EINVAL if the JSON's
 * w/h disagree with the image's. */
int fg_transforms_complete_camera(fg_transforms_frame *f, int image_w, int image_h);

void fg_transforms_free(fg_transforms *t);

#endif
