/* The field's extent from a capture's frames (extent.h). */
#include "field/extent.h"

#include <math.h>
#include <string.h>

/* The smallest field scale whose cube (model.h: centred on the workspace, side scale times
 * the largest extent) holds p, unbounded above. */
static double scale_to_hold(const double centre[3], double extent, const double p[3]) {
  double far = 0.0;
  for (int k = 0; k < 3; k++) far = fmax(far, fabs(p[k] - centre[k]));
  return 2.0 * far / extent;
}

/* The power of two from 2 to 64 at or above s (64 for anything beyond, NaN included). */
static double power_of_two_at_least(double s) {
  double p = FG_FIELD_EXTENT_DEFAULT_SCALE;
  while (p < FG_FIELD_EXTENT_MAX_SCALE && !(s <= p)) p *= 2.0;
  return p;
}

/* Scales of the points to histogram bins 0..6 (2, 4, ..., 64, beyond). */
#define N_BINS 7
static int bin_of(double s) {
  int b = 0;
  for (double p = FG_FIELD_EXTENT_DEFAULT_SCALE; b < N_BINS - 1 && !(s <= p); p *= 2.0) b++;
  return b;
}

static void add_depth_hits(const fg_frame *f, const double centre[3], double extent,
                           size_t hist[N_BINS]) {
  const double *T = f->T_world_cam;
  for (int v = FG_FIELD_EXTENT_STRIDE / 2; v < f->depth_h; v += FG_FIELD_EXTENT_STRIDE)
    for (int u = FG_FIELD_EXTENT_STRIDE / 2; u < f->depth_w; u += FG_FIELD_EXTENT_STRIDE) {
      const double z = f->depth[(size_t)v * (size_t)f->depth_w + (size_t)u];
      if (!(z > 0) || !isfinite(z)) continue;
      /* OpenGL camera: x right, y up, looking along -z */
      const double c[3] = {z * (u + 0.5 - f->cam.cx) / f->cam.fl_x,
                           -z * (v + 0.5 - f->cam.cy) / f->cam.fl_y, -z};
      double w[3];
      for (int k = 0; k < 3; k++)
        w[k] = T[4 * k] * c[0] + T[4 * k + 1] * c[1] + T[4 * k + 2] * c[2] + T[4 * k + 3];
      hist[bin_of(scale_to_hold(centre, extent, w))]++;
    }
}

void fg_field_extent_choose(const double ws_min[3], const double ws_max[3],
                            const fg_frame *frames, size_t n, fg_field_extent *out) {
  memset(out, 0, sizeof *out);
  double centre[3], extent = 0.0;
  for (int k = 0; k < 3; k++) {
    centre[k] = 0.5 * (ws_min[k] + ws_max[k]);
    extent = fmax(extent, ws_max[k] - ws_min[k]);
  }
  size_t hist[N_BINS] = {0};
  for (size_t i = 0; i < n; i++)
    if (frames[i].depth) {
      out->from_depth = 1;
      add_depth_hits(&frames[i], centre, extent, hist);
    }
  if (!out->from_depth) {
    double need = 0.0;
    for (size_t i = 0; i < n; i++) {
      const double *T = frames[i].T_world_cam, p[3] = {T[3], T[7], T[11]};
      const double s = scale_to_hold(centre, extent, p);
      need = fmax(need, isfinite(s) ? s : INFINITY);
      hist[bin_of(s)]++;
    }
    out->points = n;
    out->outside_share = n ? (double)(n - hist[0]) / (double)n : 0.0;
    out->learn_background = !(need <= FG_FIELD_EXTENT_DEFAULT_SCALE);
    out->field_scale = power_of_two_at_least(need);
    return;
  }
  for (int b = 0; b < N_BINS; b++) out->points += hist[b];
  const double far = FG_FIELD_EXTENT_FAR_SHARE * (double)out->points;
  out->outside_share = out->points ? (double)(out->points - hist[0]) / (double)out->points : 0;
  out->field_scale = FG_FIELD_EXTENT_DEFAULT_SCALE;
  if ((double)(out->points - hist[0]) <= FG_FIELD_EXTENT_NEED_SHARE * (double)out->points)
    return;
  out->learn_background = 1;
  size_t inside = 0;
  for (int b = 0; b < N_BINS - 1; b++) {
    inside += hist[b];
    if ((double)(out->points - inside) <= far || b == N_BINS - 2) break;
    out->field_scale *= 2.0;
  }
}
