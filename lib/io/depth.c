/* Depth maps (io/depth.h) in plain C: from parsed .npy arrays, the value and size checks that
 * every encoding shares, and the grid check against a frame's image. Decoding of depth
 * images lives in image_codec.c with the other OpenImageIO users, so that a program taking
 * only .npy depth (the daemon) does not link it. */
#include "io/depth.h"
#include "core/error.h"
#include "core/half.h"
#include "io/depth_priv.h"
#include "io/image.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void fg_depth_release(fg_depth_map *d) {
  if (!d) return;
  free(d->m);
  memset(d, 0, sizeof *d);
}

int fg_depth_check_size(const char *what, size_t w, size_t h) {
  if (w == 0 || h == 0)
    return fg_fail(FG_EINVAL, "%s is empty (%zux%zu pixels)", what, w, h);
  if (w > FG_IMAGE_MAX_SIDE || h > FG_IMAGE_MAX_SIDE || w * h > (size_t)FG_IMAGE_MAX_PIXELS)
    return fg_fail(FG_ERANGE,
                   "%s is %zux%zu; the largest accepted is %d pixels per side and %u pixels "
                   "in all, so downscale it first",
                   what, w, h, FG_IMAGE_MAX_SIDE, FG_IMAGE_MAX_PIXELS);
  return 0;
}

int fg_depth_clean_metres(float *m, int w, int h) {
  for (int y = 0; y < h; y++) {
    float *row = m + (size_t)y * (size_t)w;
    for (int x = 0; x < w; x++) {
      float v = row[x];
      if (v > 0 && v <= FLT_MAX) continue; /* the common case: one test for finite and > 0 */
      if (isnan(v) || v == 0) {
        row[x] = 0; /* also turns -0 into 0 */
        continue;
      }
      return fg_fail(FG_EINVAL,
                     "depth pixel [row %d, col %d] is %g metres; depth must be finite and >= 0 "
                     "(0 or NaN marks a pixel without a reading)",
                     y, x, (double)v);
    }
  }
  return 0;
}

/* ---- .npy ---------------------------------------------------------------------------- */

/* "(480, 640, 3)" for messages. */
static void format_shape(const fg_npy *npy, char *buf, size_t len) {
  size_t used = (size_t)snprintf(buf, len, "(");
  for (int i = 0; i < npy->ndim && used < len; i++)
    used += (size_t)snprintf(buf + used, len - used, "%s%zu", i ? ", " : "", npy->shape[i]);
  if (used < len) snprintf(buf + used, len - used, npy->ndim == 1 ? ",)" : ")");
}

/* Element i of little-endian float32 or float16 data, which need not be aligned. */
static float npy_value(fg_dtype t, const uint8_t *data, size_t i) {
  if (t == FG_DTYPE_F16) {
    const uint8_t *p = data + 2 * i;
    return fg_half_to_float((uint16_t)(p[0] | p[1] << 8));
  }
  const uint8_t *p = data + 4 * i;
  uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
  float v;
  memcpy(&v, &u, sizeof v);
  return v;
}

int fg_depth_from_npy(const fg_npy *npy, fg_depth_map *out) {
  if (!out) return fg_fail(FG_EINVAL, "fg_depth_from_npy: no output depth map");
  memset(out, 0, sizeof *out);
  if (!npy) return fg_fail(FG_EINVAL, "fg_depth_from_npy: no array");
  if (npy->dtype != FG_DTYPE_F32 && npy->dtype != FG_DTYPE_F16)
    return fg_fail(FG_EINVAL, "the depth .npy is not float32; save metres as float32, e.g. "
                              "np.save(f, depth.astype(np.float32))");
  char shape[128];
  format_shape(npy, shape, sizeof shape);
  if (npy->ndim != 2 && !(npy->ndim == 3 && npy->shape[2] == 1))
    return fg_fail(FG_EINVAL, "the depth .npy has shape %s; depth takes one value per pixel, "
                              "shape [h, w] or [h, w, 1] of float32 metres",
                   shape);
  size_t h = npy->shape[0], w = npy->shape[1];
  FG_TRY(fg_depth_check_size("the depth .npy", w, h));
  if (npy->count != w * h || !npy->data)
    return fg_fail(FG_EINVAL, "fg_depth_from_npy: the array holds %zu values for shape %s",
                   npy->count, shape);
  float *m = malloc(w * h * sizeof(float));
  if (!m) return fg_fail(FG_ENOMEM, "out of memory reading a %zux%zu depth map", w, h);
  for (size_t i = 0; i < w * h; i++) m[i] = npy_value(npy->dtype, npy->data, i);
  int rc = fg_depth_clean_metres(m, (int)w, (int)h);
  if (rc != 0) {
    free(m);
    return rc;
  }
  out->w = (int)w;
  out->h = (int)h;
  out->m = m;
  return 0;
}

/* ---- alignment with the image -------------------------------------------------------- */

int fg_depth_check_grid(int w, int h, int img_w, int img_h) {
  if (w <= 0 || h <= 0 || img_w <= 0 || img_h <= 0)
    return fg_fail(FG_EINVAL, "depth grid check: sizes must be positive, got a %dx%d depth map "
                              "for a %dx%d image",
                   w, h, img_w, img_h);
  if (img_w % w == 0 && img_h % h == 0 && img_w / w == img_h / h) return 0;
  char half[48] = "";
  if (img_w % 2 == 0 && img_h % 2 == 0)
    snprintf(half, sizeof half, " or %dx%d", img_w / 2, img_h / 2);
  return fg_fail(FG_EINVAL,
                 "the depth map is %dx%d but its image is %dx%d; depth must be the image's size "
                 "or that size divided by one whole number in both directions (%dx%d%s, ...), "
                 "from the same camera",
                 w, h, img_w, img_h, img_w, img_h, half);
}

double fg_depth_valid_fraction(const float *m, size_t n) {
  if (!m || n == 0) return 0.0;
  size_t valid = 0;
  for (size_t i = 0; i < n; i++) valid += m[i] > 0;
  return (double)valid / (double)n;
}
