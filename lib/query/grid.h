/* The voxel grid of a scene's workspace, on which heatmaps and grasps are computed.
 *
 * Voxel grid. The workspace [ws_min, ws_max] (world frame, metres) is cut into voxels of side
 * voxel_size starting at ws_min: n_a = ceil((ws_max[a] - ws_min[a]) / voxel_size - 1e-9) per
 * axis (at least 1), voxel (ix, iy, iz) has its centre at ws_min + (i + 0.5) * voxel_size, so the
 * voxels cover the workspace and the last centre lies at most half a voxel beyond ws_max.
 * Dense arrays are [nz][ny][nx] (x fastest), flat index (iz * ny + iy) * nx + ix. At most
 * FG_QUERY_MAX_VOXELS voxels (256^3); larger grids are FG_ERANGE. */
#ifndef FG_QUERY_GRID_H
#define FG_QUERY_GRID_H

#include <stddef.h>

#define FG_QUERY_MAX_VOXELS ((size_t)256 * 256 * 256)

typedef struct fg_voxel_grid {
  double min[3];     /* ws_min, world frame, metres */
  double max[3];     /* ws_max, world frame, metres */
  double voxel_size; /* metres */
  int nx, ny, nz;
} fg_voxel_grid;

/* Fills *g for the workspace [ws_min, ws_max] (metres) at voxel_size (metres) as described
 * above. FG_EINVAL (with a detail) for non-finite values, ws_max <= ws_min on an axis or
 * voxel_size <= 0; FG_ERANGE when the grid would exceed FG_QUERY_MAX_VOXELS. */
int fg_voxel_grid_init(fg_voxel_grid *g, const double ws_min[3], const double ws_max[3],
                       double voxel_size);

/* nx * ny * nz. */
size_t fg_voxel_grid_count(const fg_voxel_grid *g);

/* Centre of voxel (ix, iy, iz) in the world frame, metres, into p_world (3). */
void fg_voxel_grid_centre(const fg_voxel_grid *g, int ix, int iy, int iz, double p_world[3]);

/* Centres of all voxels as float (nx*ny*nz, 3) in flat-index order into p_world, which the
 * caller allocates. */
void fg_voxel_grid_centres(const fg_voxel_grid *g, float *p_world);

#endif
