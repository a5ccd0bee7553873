/* Ground truth of a scenegen tabletop on a voxel grid and in the containers' cavities, shared
 * by the quality tests and benchmarks that judge a trained field's geometry.
 *
 * Voxel v belongs to object k when k's solid comes within half a voxel of v's centre, i.e.
 * meets the ball inscribed in v (tested on a lattice of voxel_size / 8, finer than any wall).
 * For the box and the ball that is the centre-inside voxelisation plus the boundary voxels
 * whose centre lies within 5 mm of the surface; for the 4.5-6.6 mm walls of the mug and the
 * bowl it is a closed band one to two voxels thick (the 26-separating surface voxelisation of
 * Huang et al., 1998). The empty interior of the mug and of the bowl is not the object's: it
 * is its cavity. */
#ifndef SG_GTVOX_H
#define SG_GTVOX_H

#include <stddef.h>

#include "gt.h"
#include "query/grid.h"

#define SG_GT_LATTICE_PER_VOXEL 8

/* 1 when p_world lies in the open interior of a mug (above its floor, below its rim) or of a
 * bowl (inside its inner sphere, below its rim); 0 elsewhere and for the box and the ball. */
int sg_gt_in_cavity(const sg_shape *s, const double p_world[3]);

/* 1 when object k's solid meets the ball of radius radius_m around p_world, tested on a
 * lattice of spacing voxel_size / SG_GT_LATTICE_PER_VOXEL. */
int sg_gt_solid_meets_ball(const sg_gt *gt, int k, const double p_world[3], double radius_m,
                           double voxel_size);

/* Ground truth of grid g: owner (nz, ny, nx) the object whose solid meets the voxel's
 * inscribed ball, or -1; cavity (nz, ny, nx) the container whose cavity holds the centre of a
 * voxel that is not its own, or -1. Objects stand at least 2 cm apart, so no voxel is within
 * half a voxel of two. Both arrays are the caller's. */
void sg_gt_voxelise(const sg_gt *gt, const fg_voxel_grid *g, signed char *owner,
                    signed char *cavity);

/* Points of container k's cavity, on a lattice of the given spacing, that lie at least
 * clearance metres inside it: no solid within clearance (walls, floor, handle) and still in
 * the cavity clearance above (below the rim by that much). A malloc'd (n, 3) array of world
 * points the caller frees; NULL with *n = 0 for an object that has no cavity. */
double *sg_gt_cavity_points(const sg_gt *gt, int k, double clearance, double spacing,
                            size_t *n);

#endif
