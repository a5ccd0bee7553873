/* Images of a field from a pinhole camera, in the pixel formats the render endpoint encodes:
 * colour as 8-bit sRGB, depth as 16-bit millimetres along the optical axis, surface normals
 * as 8-bit RGB. The camera is OpenGL's (+x right, +y up, looking along -z; pose T_world_cam
 * camera-to-world, metres, row-major 4x4); ray (u, v) goes through the pixel centre
 * (u + 0.5, v + 0.5), rays in row-major pixel order. Images are rendered in chunks of
 * FG_FIELD_IMAGE_CHUNK rays, so that a render's memory stays near 40 bytes a pixel whatever
 * its size. Threads as fg_field_render_rays (model.h): bit-identical for any count. */
#ifndef FG_FIELD_IMAGE_H
#define FG_FIELD_IMAGE_H

#include <stdint.h>

#include "field/model.h"

struct fg_camera;

/* Rays rendered per call of fg_field_render_rays. */
#define FG_FIELD_IMAGE_CHUNK 65536
/* Pixels less opaque than this have no depth (0) and no normal (black). */
#define FG_FIELD_SURFACE_MIN_OPACITY 0.5f

typedef enum fg_field_image_kind {
  FG_FIELD_IMAGE_RGB,    /* uint8 [h][w][3]: round(255 clamp(rgb, 0, 1)), NaN as 0 */
  FG_FIELD_IMAGE_DEPTH,  /* uint16 [h][w]: z = depth / opacity * cos(ray, optical axis) in mm,
                          * rounded, saturating at 65535; 0 where opacity is below
                          * FG_FIELD_SURFACE_MIN_OPACITY */
  FG_FIELD_IMAGE_NORMAL, /* uint8 [h][w][3]: round(127.5 (n + 1)) of the unit world-frame normal
                          * (fg_field_render_normals at +-normal_step_m); black (0, 0, 0) where
                          * opacity is below FG_FIELD_SURFACE_MIN_OPACITY or the density has no
                          * gradient */
} fg_field_image_kind;

/* Rays of pixels start .. start + m - 1 (row-major) of cam at pose T_world_cam: origins o (m,3)
 * and unit directions d (m,3) in the world frame, and, when cos_axis is not NULL, each ray's
 * cosine to the optical axis (m). The direction is normalised in the camera frame, then
 * rotated. */
void fg_camera_pixel_rays(const double T_world_cam[16], const struct fg_camera *cam,
                          int64_t start, int64_t m, float *o, float *d, float *cos_axis);

/* Renders cam's whole image of f at T_world_cam through fg_field_render_rays, with its
 * outputs as there (each NULL when not wanted) in row-major pixel order, all at once. */
int fg_field_render_camera(const fg_field *f, const double T_world_cam[16],
                           const struct fg_camera *cam, const float bg[3], float *rgb,
                           float *depth, float *opacity, float *feat, int n_threads);

/* Renders cam's whole image of f at T_world_cam into out (the caller's buffer, of the size
 * the kind gives), with background bg (3) where the field is empty. normal_step_m is used by
 * FG_FIELD_IMAGE_NORMAL only. FG_EINVAL for a camera fg_camera_validate refuses and as
 * fg_field_render_rays and fg_field_render_normals; FG_ENOMEM. */
int fg_field_render_image(const fg_field *f, const double T_world_cam[16],
                          const struct fg_camera *cam, fg_field_image_kind kind,
                          const float bg[3], float normal_step_m, int n_threads, void *out);

#endif
