/* How well a field trained on a scenegen tabletop knows the scene's geometry (issue 13's
 * numbers), for the quality test and the geometry benchmark:
 *  - depth: the field's z-depth against the data set's depth maps on the held-out views'
 *    object pixels (mask 2..5) and table pixels (mask 1), where the render's opacity is at
 *    least 0.5 (z = the expected distance over the opacity, times the ray's cosine to the
 *    optical axis); median and 90th percentile of |error|;
 *  - cavities: for the mug and the bowl, the share of points at least 6 mm inside the cavity
 *    (gtvox.h, 4 mm lattice) whose own density sigma gives 1 - exp(-sigma voxel_size) below
 *    0.1, the query's occupancy threshold (free space to a grasp search);
 *  - container IoU (issue 5's measure, with the cavity counted): the occupied voxels (alpha
 *    >= 0.1 at 1 cm) scoring >= 0.5 for the object's class embedding with every other class
 *    as negatives, against the object's voxels (gtvox.h); only when the field has features;
 *  - solid recall: per object, the share of its voxels that are occupied at all (the voxel
 *    cache's alpha >= 0.1), what heatmaps and grasp collision checks can see of it. */
#ifndef SG_GEOMEVAL_H
#define SG_GEOMEVAL_H

#include <stddef.h>

#include "field/model.h"
#include "gt.h"
#include "io/frame.h"

#define SG_GEOM_CLEARANCE 0.006   /* metres inside a cavity */
#define SG_GEOM_VOXEL 0.01        /* the scene's voxel size */
#define SG_GEOM_MAX_OBJECTS 8

typedef struct sg_geom_eval {
  size_t n_object_px, n_table_px;     /* evaluated pixels */
  double depth_object_median_mm, depth_object_p90_mm;
  double depth_table_median_mm;
  int n_containers;                   /* mug and bowl: 2 */
  int container[2];                   /* object index of each */
  size_t cavity_points[2];
  double cavity_free[2];              /* share of points with alpha < 0.1 */
  double iou[2];                      /* with the cavity counted; NaN without features */
  int n_objects;
  double solid_recall[SG_GEOM_MAX_OBJECTS]; /* per object: share of its voxels (gtvox.h) that
                                               are occupied (the cache's alpha >= 0.1) */
} sg_geom_eval;

/* Evaluates field f trained on frames[0..n) of the data set in dir (fieldgrip-scenegen with
 * --holdout 0, usually with --depth: frame i is view i) on the views i with
 * i % holdout_every == 0; without depth maps the depth numbers are NaN over 0 pixels. 0, or a
 * negative FG_E* code with a detail. */
int sg_geom_evaluate(const sg_gt *gt, const char *dir, const fg_field *f,
                     const fg_frame *frames, size_t n, int holdout_every, int n_threads,
                     sg_geom_eval *out);

#endif
