#include "gtvox.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int sg_gt_in_cavity(const sg_shape *s, const double p_world[3]) {
  double p[3];
  sg_xform_point(s->T_obj_world, p_world, p);
  const double r2 = p[0] * p[0] + p[1] * p[1], h2 = s->height / 2;
  if (s->type == SG_SHAPE_MUG)
    return r2 < s->inner_radius * s->inner_radius && p[2] > -h2 + s->bottom && p[2] <= h2;
  if (s->type == SG_SHAPE_BOWL) {
    const double dz = p[2] - s->sphere_center_z;
    return r2 + dz * dz < s->inner_radius * s->inner_radius && p[2] <= h2;
  }
  return 0;
}

int sg_gt_solid_meets_ball(const sg_gt *gt, int k, const double p_world[3], double radius_m,
                           double voxel_size) {
  const double h = voxel_size / SG_GT_LATTICE_PER_VOXEL;
  const int m = (int)floor(radius_m / h + 1e-9);
  for (int dz = -m; dz <= m; dz++)
    for (int dy = -m; dy <= m; dy++)
      for (int dx = -m; dx <= m; dx++) {
        if ((dx * dx + dy * dy + dz * dz) * h * h > radius_m * radius_m * (1 + 1e-9)) continue;
        const double p[3] = {p_world[0] + dx * h, p_world[1] + dy * h, p_world[2] + dz * h};
        if (sg_gt_inside(gt, k, p)) return 1;
      }
  return 0;
}

void sg_gt_voxelise(const sg_gt *gt, const fg_voxel_grid *g, signed char *owner,
                    signed char *cavity) {
  const size_t N = fg_voxel_grid_count(g);
  memset(owner, -1, N);
  memset(cavity, -1, N);
  for (int k = 0; k < gt->n_objects; k++) {
    const sg_gt_object *ob = &gt->objects[k];
    int lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
      const int na = a == 0 ? g->nx : a == 1 ? g->ny : g->nz;
      lo[a] = (int)floor((ob->aabb_min[a] - g->min[a]) / g->voxel_size) - 1;
      hi[a] = (int)floor((ob->aabb_max[a] - g->min[a]) / g->voxel_size) + 1;
      lo[a] = lo[a] < 0 ? 0 : lo[a];
      hi[a] = hi[a] >= na ? na - 1 : hi[a];
    }
#pragma omp parallel for schedule(dynamic, 1)
    for (int iz = lo[2]; iz <= hi[2]; iz++)
      for (int iy = lo[1]; iy <= hi[1]; iy++)
        for (int ix = lo[0]; ix <= hi[0]; ix++) {
          const size_t i = ((size_t)iz * (size_t)g->ny + (size_t)iy) * (size_t)g->nx + (size_t)ix;
          double c[3];
          fg_voxel_grid_centre(g, ix, iy, iz, c);
          if (sg_gt_solid_meets_ball(gt, k, c, g->voxel_size / 2, g->voxel_size))
            owner[i] = (signed char)k;
          else if (sg_gt_in_cavity(&ob->shape, c))
            cavity[i] = (signed char)k;
        }
  }
}

double *sg_gt_cavity_points(const sg_gt *gt, int k, double clearance, double spacing,
                            size_t *n) {
  *n = 0;
  const sg_gt_object *ob = &gt->objects[k];
  if (ob->shape.type != SG_SHAPE_MUG && ob->shape.type != SG_SHAPE_BOWL) return NULL;
  int m[3];
  for (int a = 0; a < 3; a++) m[a] = (int)ceil((ob->aabb_max[a] - ob->aabb_min[a]) / spacing) + 1;
  const size_t cap = (size_t)m[0] * (size_t)m[1] * (size_t)m[2];
  double *pts = malloc(cap * 3 * sizeof *pts);
  if (!pts) return NULL;
  /* the solid is tested at clearance / 4: fine enough for a 6 mm clearance against the
   * thinnest (4.5 mm) wall */
  const double lattice = clearance / 4 * SG_GT_LATTICE_PER_VOXEL;
  for (int iz = 0; iz < m[2]; iz++)
    for (int iy = 0; iy < m[1]; iy++)
      for (int ix = 0; ix < m[0]; ix++) {
        const double p[3] = {ob->aabb_min[0] + ix * spacing, ob->aabb_min[1] + iy * spacing,
                             ob->aabb_min[2] + iz * spacing};
        const double up[3] = {p[0], p[1], p[2] + clearance};
        if (!sg_gt_in_cavity(&ob->shape, p) || !sg_gt_in_cavity(&ob->shape, up) ||
            sg_gt_solid_meets_ball(gt, k, p, clearance, lattice))
          continue;
        memcpy(pts + 3 * *n, p, sizeof p);
        (*n)++;
      }
  return pts;
}
