#include "field/image.h"

#include <math.h>
#include <stdlib.h>

#include "core/error.h"
#include "io/camera.h"

void fg_camera_pixel_rays(const double T_world_cam[16], const struct fg_camera *cam,
                          int64_t start, int64_t m, float *o, float *d, float *cos_axis) {
  const double *T = T_world_cam;
  for (int64_t i = 0; i < m; i++) {
    const int64_t p = start + i;
    double u = (double)(p % cam->w) + 0.5, v = (double)(p / cam->w) + 0.5;
    double x = (u - cam->cx) / cam->fl_x, y = -(v - cam->cy) / cam->fl_y, z = -1.0;
    const double len = sqrt(x * x + y * y + z * z);
    x /= len, y /= len, z /= len;
    for (int k = 0; k < 3; k++) {
      d[3 * i + k] = (float)(T[4 * k] * x + T[4 * k + 1] * y + T[4 * k + 2] * z);
      o[3 * i + k] = (float)T[4 * k + 3];
    }
    if (cos_axis) cos_axis[i] = (float)(1.0 / len);
  }
}

int fg_field_render_camera(const fg_field *f, const double T_world_cam[16],
                           const struct fg_camera *cam, const float bg[3], float *rgb,
                           float *depth, float *opacity, float *feat, int n_threads) {
  if (!f || !T_world_cam) return fg_fail(FG_EINVAL, "render: no field or no pose");
  if (fg_camera_validate(cam) != 0) return FG_EINVAL;
  const int64_t R = (int64_t)cam->w * cam->h;
  float *o = malloc((size_t)R * 3 * sizeof(float)), *d = malloc((size_t)R * 3 * sizeof(float));
  int rc = o && d ? 0 : fg_fail(FG_ENOMEM, "cannot allocate %lld rays", (long long)R);
  if (rc == 0) {
    fg_camera_pixel_rays(T_world_cam, cam, 0, R, o, d, NULL);
    rc = fg_field_render_rays(f, o, d, R, bg, rgb, depth, opacity, feat, n_threads);
  }
  free(d);
  free(o);
  return rc;
}

/* One rendered chunk's pixels m, from pixel start, into out in the kind's format. */
static void encode(fg_field_image_kind kind, int64_t start, int64_t m, const float *rgb,
                   const float *depth, const float *alpha, const float *cos_axis, void *out) {
  for (int64_t i = 0; i < m; i++) {
    const int64_t p = start + i;
    if (kind == FG_FIELD_IMAGE_NORMAL) { /* rgb holds the normals */
      const float *nv = rgb + 3 * i;
      const int none = !(alpha[i] >= FG_FIELD_SURFACE_MIN_OPACITY) ||
                       (nv[0] == 0.0f && nv[1] == 0.0f && nv[2] == 0.0f);
      for (int k = 0; k < 3; k++) {
        float x = 127.5f * (nv[k] + 1.0f);
        x = x > 0 ? (x < 255.0f ? x : 255.0f) : 0; /* NaN goes to 0 */
        ((uint8_t *)out)[3 * p + k] = none ? 0 : (uint8_t)lroundf(x);
      }
    } else if (kind == FG_FIELD_IMAGE_DEPTH) {
      uint16_t mm = 0;
      if (alpha[i] >= FG_FIELD_SURFACE_MIN_OPACITY) {
        const double v = (double)depth[i] / (double)alpha[i] * (double)cos_axis[i] * 1000.0;
        mm = !(v > 0) ? 0 : v >= 65535.0 ? 65535 : (uint16_t)lround(v);
      }
      ((uint16_t *)out)[p] = mm;
    } else {
      for (int k = 0; k < 3; k++) {
        float x = rgb[3 * i + k];
        x = x > 0 ? (x < 1 ? x : 1) : 0; /* NaN goes to 0 */
        ((uint8_t *)out)[3 * p + k] = (uint8_t)lrintf(x * 255.0f);
      }
    }
  }
}

int fg_field_render_image(const fg_field *f, const double T_world_cam[16],
                          const struct fg_camera *cam, fg_field_image_kind kind,
                          const float bg[3], float normal_step_m, int n_threads, void *out) {
  if (!f || !T_world_cam || !out) return fg_fail(FG_EINVAL, "render: no field, pose or image");
  if (fg_camera_validate(cam) != 0) return FG_EINVAL;
  const int64_t n = (int64_t)cam->w * cam->h;
  const int64_t chunk = n < FG_FIELD_IMAGE_CHUNK ? n : FG_FIELD_IMAGE_CHUNK;
  float *o = malloc((size_t)chunk * 3 * sizeof *o), *d = malloc((size_t)chunk * 3 * sizeof *d);
  float *rgb = malloc((size_t)chunk * 3 * sizeof *rgb);
  float *depth = malloc((size_t)chunk * sizeof *depth), *alpha = malloc((size_t)chunk * sizeof *alpha);
  float *cos_axis = malloc((size_t)chunk * sizeof *cos_axis);
  int rc = (o && d && rgb && depth && alpha && cos_axis) ? 0 : fg_fail(FG_ENOMEM, "out of memory");
  for (int64_t start = 0; rc == 0 && start < n; start += chunk) {
    const int64_t m = n - start < chunk ? n - start : chunk;
    fg_camera_pixel_rays(T_world_cam, cam, start, m, o, d, cos_axis);
    if (kind == FG_FIELD_IMAGE_NORMAL)
      rc = fg_field_render_normals(f, o, d, m, normal_step_m, rgb, alpha, n_threads);
    else if (kind == FG_FIELD_IMAGE_DEPTH)
      rc = fg_field_render_rays(f, o, d, m, bg, NULL, depth, alpha, NULL, n_threads);
    else
      rc = fg_field_render_rays(f, o, d, m, bg, rgb, NULL, NULL, NULL, n_threads);
    if (rc == 0) encode(kind, start, m, rgb, depth, alpha, cos_axis, out);
  }
  free(o), free(d), free(rgb), free(depth), free(alpha), free(cos_axis);
  return rc;
}
