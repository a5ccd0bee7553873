/* A query's heatmap seen from a camera: the field's colour with the turbo map of every
 * pixel's score blended over it (colormap.h), as the render endpoint's "heatmap" output.
 * Camera and rays as field/image.h. */
#ifndef FG_QUERY_HEATMAP_VIEW_H
#define FG_QUERY_HEATMAP_VIEW_H

#include <stdint.h>

#include "field/model.h"
#include "query/query.h"

struct fg_camera;

/* Rays of a heatmap view per call: their (chunk, D) features stay at 8 MB for D = 512. */
#define FG_HEATMAP_VIEW_CHUNK 4096
/* Pixels less opaque than this show the field's colour without a score. */
#define FG_HEATMAP_VIEW_MIN_OPACITY 0.5f

/* Renders colour and features of cam at T_world_cam, scores every pixel's feature with q
 * (fg_query_score_features; pixels below FG_HEATMAP_VIEW_MIN_OPACITY show no score) and
 * blends the scores over the colour (fg_heatmap_blend, over the image's own score range) into
 * out, uint8 RGB [h][w][3]. Memory stays near 16 bytes a pixel whatever D. FG_EINVAL for a
 * camera fg_camera_validate refuses, a field without features, and as
 * fg_query_score_features; FG_ENOMEM. */
int fg_heatmap_render_view(const fg_field *f, const double T_world_cam[16],
                           const struct fg_camera *cam, const fg_query *q, const float bg[3],
                           int n_threads, uint8_t *out);

#endif
