#include "query/heatmap_view.h"

#include <math.h>
#include <stdlib.h>

#include "core/error.h"
#include "field/image.h"
#include "io/camera.h"
#include "query/colormap.h"

int fg_heatmap_render_view(const fg_field *f, const double T_world_cam[16],
                           const struct fg_camera *cam, const fg_query *q, const float bg[3],
                           int n_threads, uint8_t *out) {
  if (!f || !T_world_cam || !q || !out)
    return fg_fail(FG_EINVAL, "render: no field, pose, query or image");
  if (fg_camera_validate(cam) != 0) return FG_EINVAL;
  const int D = f->cfg.feature_dim;
  const int64_t n = (int64_t)cam->w * cam->h;
  const int64_t chunk = n < FG_HEATMAP_VIEW_CHUNK ? n : FG_HEATMAP_VIEW_CHUNK;
  float *o = malloc((size_t)chunk * 3 * sizeof *o), *d = malloc((size_t)chunk * 3 * sizeof *d);
  float *feat = malloc((size_t)chunk * (size_t)(D > 0 ? D : 1) * sizeof *feat); /* (chunk, D) */
  float *alpha = malloc((size_t)chunk * sizeof *alpha);
  float *rgb = malloc((size_t)n * 3 * sizeof *rgb);   /* (n, 3) */
  float *scores = malloc((size_t)n * sizeof *scores); /* (n) */
  int rc = (o && d && feat && alpha && rgb && scores) ? 0 : fg_fail(FG_ENOMEM, "out of memory");
  for (int64_t start = 0; rc == 0 && start < n; start += chunk) {
    const int64_t m = n - start < chunk ? n - start : chunk;
    fg_camera_pixel_rays(T_world_cam, cam, start, m, o, d, NULL);
    rc = fg_field_render_rays(f, o, d, m, bg, rgb + 3 * start, NULL, alpha, feat, n_threads);
    if (rc == 0)
      rc = fg_query_score_features(q, feat, m, D, alpha, FG_HEATMAP_VIEW_MIN_OPACITY,
                                   scores + start, n_threads);
  }
  if (rc == 0) fg_heatmap_blend(rgb, scores, n, NAN, NAN, out);
  free(o), free(d), free(feat), free(alpha), free(rgb), free(scores);
  return rc;
}
