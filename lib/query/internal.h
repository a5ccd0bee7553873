/* Private helpers shared by the files of lib/query. */
#ifndef FG_QUERY_INTERNAL_H
#define FG_QUERY_INTERNAL_H

#include <stddef.h>

#include "query/heatmap.h"

/* Centres of flat voxel indices [i0, i0 + n) of g as float into p_world (n, 3). */
void fg_query_grid_centres_range(const fg_voxel_grid *g, size_t i0, size_t n, float *p_world);

/* a . b over n floats, summed in a fixed order (8 lanes), the same for any thread count. */
float fg_query_dot(const float *a, const float *b, int n);

#endif
