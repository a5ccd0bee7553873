/* Private helpers shared by the files of lib/query. */
#ifndef FG_QUERY_INTERNAL_H
#define FG_QUERY_INTERNAL_H

#include <stddef.h>

#include "query/grid.h"

/* Centres of flat voxel indices [i0, i0 + n) of g as float into p_world (n, 3). */
void fg_query_grid_centres_range(const fg_voxel_grid *g, size_t i0, size_t n, float *p_world);

/* a . b over n floats, summed in a fixed order (8 lanes), the same for any thread count. */
float fg_query_dot(const float *a, const float *b, int n);

struct fg_field;

/* Sub-samples per axis of a voxel (voxsample.c). */
#define FG_QUERY_VOXEL_SUBSAMPLES 4

/* Opacities alpha (n) of voxels [i0, i0 + n) of g in field f (voxsample.c): 1 - exp(-mean
 * sigma * voxel_size), the mean over the centres of each voxel's S^3 sub-cells (S =
 * FG_QUERY_VOXEL_SUBSAMPLES) with sigma 0 where the field's occupancy grid is empty or the
 * density is NaN or negative. FG_ENOMEM, or the field's error. */
int fg_query_voxel_sample(const struct fg_field *f, const fg_voxel_grid *g, size_t i0, size_t n,
                          float *alpha, int n_threads);

#endif
